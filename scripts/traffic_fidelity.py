"""Fidelity of roadload/EcoTraffic-v0 (native) against roadload/EcoHighway-v0 (highway-env) on the same scenario,
both egos driven by the IDM follower (roadload.experiments.rl.traffic_fidelity): headway, speed and lane-change
figures of the traffic, the IDM egos' collision rate and energy per km, each with its relative difference and 95 %
bootstrap interval.

    python scripts/traffic_fidelity.py --episodes 100 --out docs/results/traffic     # ~25 min (highway-env side)
    python scripts/traffic_fidelity.py --quick                                       # CI smoke run (2 episodes)
"""

from roadload.experiments.rl.traffic_fidelity import main

if __name__ == "__main__":
    main()
