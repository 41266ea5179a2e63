"""Simulator speed against a hand-written compiled reference loop measured in the same run: the compiled core, a
whole trip with all sensors and effects, the step API (roadload.experiments.benchmarks.simulator).

    python scripts/bench_simulator.py [--duration 3600] [--repeats 3] [--quick]
    python scripts/bench_simulator.py --compare main [--rounds 3] [--quick]   # old commit vs working tree
"""

from pathlib import Path

from roadload.experiments.benchmarks.simulator import main

if __name__ == "__main__":
    main(repo=Path(__file__).resolve().parents[1])
