"""How fast the ``roadload`` command answers, against ``python -c "import numpy, pandas"`` in the same run: --help,
refused bad inputs, peak RSS, a 1-hour simulate whose peak RSS must stay <= 250 MB
(roadload.experiments.benchmarks.cli_startup).

    python scripts/bench_cli_startup.py                 # 7 interleaved rounds + the 1-hour simulate
    python scripts/bench_cli_startup.py --quick         # CI: 1 round + a 20-minute simulate, RSS checked
"""

from roadload.experiments.benchmarks.cli_startup import main

if __name__ == "__main__":
    main()
