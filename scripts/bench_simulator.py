"""Simulator speed: simulated seconds per wall-clock (and CPU) second at 100 Hz with all sensors and effects on,
peak memory of that run, and step-API throughput. Prints the figures (no files).

    python scripts/bench_simulator.py [--duration 3600] [--repeats 3]

Target (issue 2): >= 1000x real time, i.e. a one-hour trip in under 3.6 s on one core.
"""

from __future__ import annotations

import argparse

from roadload.experiments.bench_simulator import report

if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--duration", type=float, default=3600.0, help="simulated seconds per run")
    ap.add_argument("--repeats", type=int, default=3, help="runs per vehicle (best is reported)")
    args = ap.parse_args()
    print(report(args.duration, args.repeats))
