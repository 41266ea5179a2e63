"""Are the estimators' outputs bitwise those of another commit? Every catalogue composition, RGTLS, the PKS and
the batch references on fixed seeded data, and the section-5.5 estimators on the chapter-5 pipeline of a
simulated trip: whole parameter and covariance histories. Exit status 1 when any array differs
(roadload.experiments.benchmarks.estimator_identity).

    python scripts/check_estimator_identity.py --ref 8efaaad     # the working tree against commit 8efaaad
    python scripts/check_estimator_identity.py --quick            # CI smoke run: HEAD, short records, no trip
"""

import sys
from pathlib import Path

from roadload.experiments.benchmarks.estimator_identity import main

if __name__ == "__main__":
    sys.exit(main(repo=Path(__file__).resolve().parents[1]))
