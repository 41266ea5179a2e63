"""Per-step solve time of the spatial MPC: IPOPT warm-started and the OSQP sequential-QP path, for the car and the
heavy truck (roadload.experiments.benchmarks.mpc).

    python scripts/bench_mpc.py [--roads hilly,city] [--length 6000] [--vehicle bmw_i3] [--out bench_mpc.csv]
    python scripts/bench_mpc.py --vehicle bmw_i3,truck_40t --roads hilly,long_grades [--quick]
"""

from roadload.experiments.benchmarks.mpc import main

if __name__ == "__main__":
    main()
