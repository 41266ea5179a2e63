"""Every controller against the full-route optimum at its own trip time (same code as ``roadload benchmark optimum``).

Usage: python scripts/benchmark_optimum.py --out DIR [--vehicles car,truck_15t,truck_40t] [--seeds 10]
       [--policies DIR] [--breakdown] [--episode-cost] [--scheduler tcp://host:8786]
       python scripts/benchmark_optimum.py --quick   (CI: car, 2 seeds of a 1.2 km road, cruise control and the
                                                     oracle MPC, into a temporary folder)
"""

import sys
import tempfile

from roadload.experiments.cli import main

if __name__ == "__main__":
    args = sys.argv[1:]
    if "--quick" in args and "--out" not in args:
        args += ["--out", tempfile.mkdtemp(prefix="roadload-optimum-"), "--workers", "1"]
    sys.argv = ["roadload", "benchmark", "optimum", *args]
    main()
