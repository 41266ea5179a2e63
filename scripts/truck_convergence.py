"""Online M4-RRLM estimate vs distance on the trucks: how long a warm-up the online MPC needs
(roadload.experiments.truck_convergence).

    python scripts/truck_convergence.py --out DIR [--seeds 3] [--length 16000] [--workers 2]
    python scripts/truck_convergence.py --quick   (15 t and 40 t, 1 seed, 3 km)
"""

import sys

from roadload.experiments.truck_convergence import main

if __name__ == "__main__":
    sys.exit(main())
