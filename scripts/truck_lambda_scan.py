"""Trip time and energy of the truck's closed-loop MPC over a fine grid of time weights lambda
(roadload.experiments.truck_lambda_scan).

    python scripts/truck_lambda_scan.py --case truck_15t --seed 0 --lams 100000:200000:11 --out scan.json
    python scripts/truck_lambda_scan.py --quick
"""

from roadload.experiments.truck_lambda_scan import main

if __name__ == "__main__":
    main()
