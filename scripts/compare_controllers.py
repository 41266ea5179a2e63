"""The headline controller comparison (same code as ``roadload benchmark controllers``).

Usage: python scripts/compare_controllers.py --out DIR [--roads hilly,motorway,city,i3_munich]
       [--conditions all] [--scheduler tcp://host:8786] [--workers 2] [--solver ipopt|osqp]
Prints the Markdown table and writes comparison.md/.csv, summary.csv and PNG figures into DIR.
"""

import sys

from roadload.experiments.cli import main

if __name__ == "__main__":
    sys.argv = ["roadload", "benchmark", "controllers", *sys.argv[1:]]
    main()
