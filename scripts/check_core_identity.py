"""Are the simulator core's trajectories bitwise those of another commit? Exit status 1 when any array differs
(roadload.experiments.benchmarks.core_identity).

    python scripts/check_core_identity.py --ref 8efaaad          # the working tree against commit 8efaaad
    python scripts/check_core_identity.py --quick                 # CI smoke run: HEAD, one short simulator run
"""

import sys
from pathlib import Path

from roadload.experiments.benchmarks.core_identity import main

if __name__ == "__main__":
    sys.exit(main(repo=Path(__file__).resolve().parents[1]))
