"""The headline comparison and the sensitivity map of issue 14 (same code as ``roadload benchmark headline`` and
``roadload benchmark sensitivity``).

Usage: python scripts/headline.py headline --out DIR [--vehicles car,truck_15t,truck_25t,truck_40t] [--seeds 10]
       python scripts/headline.py sensitivity --out DIR [--vehicles car,truck_40t] [--seeds 4]
       (either with --quick for a tiny run: car only, 2 seeds; --scheduler tcp://host:8786 for Dask)
"""

import sys

from roadload.experiments.cli import main

if __name__ == "__main__":
    if len(sys.argv) < 2 or sys.argv[1] not in ("headline", "sensitivity"):
        sys.exit("usage: python scripts/headline.py headline|sensitivity --out DIR [options] (see --help)")
    sys.argv = ["roadload", "benchmark", *sys.argv[1:]]
    main()
