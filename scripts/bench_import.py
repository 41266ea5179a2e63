"""Import throughput of the MF4 + DBC path (roadload.io) on the CANedge logs of ../shared/data, per stage
(roadload.experiments.benchmarks.log_import).

    python scripts/bench_import.py [--repeat 5] [--cantools] [--quick]
"""

import sys

from roadload.experiments.benchmarks.log_import import main

if __name__ == "__main__":
    sys.exit(main())
