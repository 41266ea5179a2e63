"""The diagnosis on the real BMW i3 trips (../shared/data/bmw_i3_tum): the heater and air conditioning withheld and
found as an auxiliary load against a calibration; effects injected into the logs and recovered; the speed of
calibrate + diagnose; the shipped preset as is (:mod:`roadload.experiments.sim2real.real`).

    python scripts/sim2real_i3.py hvac | inject | speed | all
    python scripts/sim2real_i3.py preset [--user-candidate] [--base-first] [--out out/sim2real_i3]
    python scripts/sim2real_i3.py --quick      # CI smoke run: two trips, one injected case (skips without the data)
"""

import sys

from roadload.experiments.sim2real.real import main

if __name__ == "__main__":
    sys.exit(main())
