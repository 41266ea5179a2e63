"""Where the IDM follower brakes on roadload/EcoTraffic-v0's held-out episodes (cut-ins, the spawn's closing up,
the leader slowing) and how early each signal announces a cut-in (roadload.experiments.rl.cut_in_diagnosis).

    python scripts/traffic_cutins.py --config '{"vehicles_density": 2.0, "spawn": "stopping-gap"}'
    python scripts/traffic_cutins.py --quick            # CI smoke run (3 short episodes)
"""

from roadload.experiments.rl.cut_in_diagnosis import main

if __name__ == "__main__":
    main()
