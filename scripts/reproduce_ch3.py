"""Reproduce the experiments of chapter 3 (Rhode 2018) over many seeds; print tables, write figures
(roadload.experiments.ch3_reproduction).

    python scripts/reproduce_ch3.py [--seeds 20] [--out out/ch3] [--only 3.3,3.4] [--quick]
"""

from roadload.experiments.ch3_reproduction import main

if __name__ == "__main__":
    main()
