"""The headline comparison and the sensitivity map of the controllers (same code as ``roadload benchmark headline``
and ``roadload benchmark sensitivity``).

Usage: python scripts/headline.py headline --out DIR [--vehicles car,truck_15t,truck_25t,truck_40t] [--seeds 10]
       python scripts/headline.py sensitivity --out DIR [--vehicles car,truck_40t] [--seeds 4]
       (either with --quick for a tiny run: car only, 2 seeds; --scheduler tcp://host:8786 for Dask)
       python scripts/headline.py --quick   (both at their tiny size, into ./headline_quick and ./sensitivity_quick)
       python scripts/headline.py headline --help   (all options of a command)
"""

import sys

from roadload.experiments.cli import main

if __name__ == "__main__":
    args = sys.argv[1:]
    if args == ["--quick"]:  # CI smoke run: both commands at their tiny size
        for command in ("headline", "sensitivity"):
            sys.argv = ["roadload", "benchmark", command, "--quick", "--out", f"{command}_quick", "--workers", "1"]
            try:
                main()
            except SystemExit as exc:
                if exc.code:
                    raise
        sys.exit(0)
    if args and args[0] in ("-h", "--help"):
        print(__doc__)
        sys.exit(0)
    if not args or args[0] not in ("headline", "sensitivity"):
        sys.exit("usage: python scripts/headline.py headline|sensitivity --out DIR [options] (see --help)")
    sys.argv = ["roadload", "benchmark", *args]
    main()
