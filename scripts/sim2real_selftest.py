"""Sim-to-real selftest on its worlds: roadload's own simulator, FASTSim 3, an independent chapter-2 model
(:mod:`roadload.experiments.sim2real.selftest`; the same as ``roadload sim2real selftest``).

    python scripts/sim2real_selftest.py --world independent --seeds 0,1,2 [--vehicle bmw_i3] [--json out.json]
    python scripts/sim2real_selftest.py --world all --seeds 0 --png figs --markdown
    python scripts/sim2real_selftest.py --from-json out.json        # reprint the tables of saved runs
    python scripts/sim2real_selftest.py --quick                     # CI smoke run: one world, 240 s trips, 2 cases
"""

import sys

from roadload.experiments.sim2real.selftest import main

if __name__ == "__main__":
    sys.exit(main())
