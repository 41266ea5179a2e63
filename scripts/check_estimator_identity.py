"""Are the estimators' outputs bitwise those of another commit? Every catalogue composition, RGTLS, the PKS and
the batch references on fixed seeded data, and the section-5.5 estimators on the chapter-5 pipeline of a
simulated trip: whole parameter and covariance histories (roadload.experiments.estimator_identity).

    python scripts/check_estimator_identity.py --ref main      # the working tree against commit main
    python scripts/check_estimator_identity.py --quick         # CI smoke run: HEAD, short records, no trip

Prints how many arrays and values were compared and how many differ; exit status 1 when any differs.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _refcompare import export_commit  # noqa: E402

from roadload.experiments.estimator_identity import check  # noqa: E402

if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--ref", default="HEAD", help="git commit to compare the working tree with (default HEAD)")
    ap.add_argument("--quick", action="store_true", help="short records, no simulated trip (CI smoke run)")
    args = ap.parse_args()
    sys.exit(check(args.ref, args.quick, export_commit))
