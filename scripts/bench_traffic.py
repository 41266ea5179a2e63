"""Env steps per second of roadload/EcoTraffic-v0 (native, compiled, batched) against highway-env in the same run
(roadload.experiments.benchmarks.traffic: interleaved rounds, wall and CPU rates, load average per row).

    python scripts/bench_traffic.py                       # N = 256, threads 1 and 2, 2 rounds of 5 s per row
    python scripts/bench_traffic.py --vehicles 10 --threads 2 --rounds 3
    python scripts/bench_traffic.py --quick               # CI smoke run (N = 16, 0.5 s per row, one round)
"""

import os

# libgomp reads OMP_WAIT_POLICY once, when it is loaded (numba's thread pool, or torch): set before any import
os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")

from roadload.experiments.benchmarks.traffic import main  # noqa: E402

if __name__ == "__main__":
    main()
