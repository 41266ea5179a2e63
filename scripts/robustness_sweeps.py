"""Run the estimator robustness sweeps with >= 20 seeds and print the breakdown points, rankings and the check
against the decision tree of figure 3.17 (roadload.experiments.robustness.campaign).

    python scripts/robustness_sweeps.py --backend synthetic --out /tmp/robustness_synthetic
    python scripts/robustness_sweeps.py --backend vehicle --out /tmp/robustness_vehicle
    python scripts/robustness_sweeps.py --quick
"""

from roadload.experiments.robustness.campaign import main

if __name__ == "__main__":
    main()
