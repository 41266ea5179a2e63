"""Property-based contract check: 2,400 inputs generated from the schemas (Trip, trip metadata, exports, effects,
gym configs, controller settings, road profiles and route files), counted by outcome
(roadload.experiments.contracts).

    python scripts/contracts.py                  # 2,400 inputs, seed 0
    python scripts/contracts.py --inputs 5000 --seed 3
    python scripts/contracts.py --quick          # CI: 240 inputs
"""

import sys

from roadload.experiments.contracts import main

if __name__ == "__main__":
    sys.exit(main())
