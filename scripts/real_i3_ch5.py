"""Chapter 5 on real data: the BMW i3 trips of ../shared/data/bmw_i3_tum through the chapter-5 pipeline, MEDSE
tables and mass against the payload notes (roadload.experiments.real_i3_ch5).

    python scripts/real_i3_ch5.py [--out out/real_i3] [--workers 2] [--limit N] [--quick]
"""

from roadload.experiments.real_i3_ch5 import main

if __name__ == "__main__":
    main()
