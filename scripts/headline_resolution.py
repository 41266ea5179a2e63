"""Resolution study of the headline comparison: the same stored closed-loop runs matched with the raw and the net
arrival metric over time windows of the local fit (roadload.experiments.headline_resolution).

    python scripts/headline_resolution.py RUNS.json [RUNS.json ...] [--out table.csv] [--figure arrival.png]
    python scripts/headline_resolution.py --quick   # the tiny headline's ./headline_quick/runs.json (run if absent)
"""

import sys

from roadload.experiments.headline_resolution import main

if __name__ == "__main__":
    sys.exit(main())
