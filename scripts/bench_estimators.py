"""Samples per second of the recursive estimators (4 parameters) against a hand-written compiled RLS loop measured
in the same run (roadload.experiments.benchmarks.estimators).

    python scripts/bench_estimators.py [--samples 20000] [--repeats 30] [--trips 8] [--quick]
    python scripts/bench_estimators.py --compare main [--rounds 3]   # old commit vs working tree
"""

from pathlib import Path

from roadload.experiments.benchmarks.estimators import main

if __name__ == "__main__":
    main(repo=Path(__file__).resolve().parents[1])
