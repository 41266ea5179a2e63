"""The headline controller comparison (same code as ``roadload benchmark controllers``).

Usage: python scripts/compare_controllers.py --out DIR [--roads hilly,motorway,city,i3_munich]
       [--conditions all] [--scheduler tcp://host:8786] [--workers 2] [--solver ipopt|osqp]
       python scripts/compare_controllers.py --quick     # tiny run for CI: 2 seeds of a short hilly road
Prints the Markdown table and writes comparison.md/.csv, summary.csv and PNG figures into DIR.
The same paired comparison (confidence intervals, the optimum) as ``scripts/headline.py``, over roads x conditions.
"""

import sys
import tempfile

from roadload.experiments.cli import main

QUICK = ["--quick", "--workers", "1"]

if __name__ == "__main__":
    args = sys.argv[1:]
    if "--quick" in args:
        args = QUICK + [a for a in args if a != "--quick"]
        if "--out" not in args:
            args += ["--out", tempfile.mkdtemp(prefix="roadload-controllers-")]
    sys.argv = ["roadload", "benchmark", "controllers", *args]
    main()
