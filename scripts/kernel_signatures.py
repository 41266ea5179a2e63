"""Parameter count of every numba kernel in the simulator and gym sources, and the largest one; exit 1 above the
limit (roadload.experiments.benchmarks.kernel_signatures, reads the sources, compiles nothing).

    python scripts/kernel_signatures.py [--folders envs gym-envs] [--limit 12]
    python scripts/kernel_signatures.py --folders all                            # every package folder
    python scripts/kernel_signatures.py --quick                                  # CI smoke run: the ten largest
"""

import sys
from pathlib import Path

from roadload.experiments.benchmarks.kernel_signatures import main

if __name__ == "__main__":
    sys.exit(main(repo=Path(__file__).resolve().parents[1]))
