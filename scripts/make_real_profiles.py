"""Build real road profiles (grade + curvature over distance) from the real logs of ../shared/data into
road-profiles/real/ (roadload.experiments.real_profiles).

    python scripts/make_real_profiles.py [--out DIR] [--bmw TripA01 TripA06] [--quick]
"""

import sys
from pathlib import Path

from roadload.experiments.real_profiles import main

if __name__ == "__main__":
    sys.exit(main(repo=Path(__file__).resolve().parents[1]))
