"""The least energy any drive could use at the IDM follower's speed on roadload/EcoTraffic-v0's held-out
episodes (same trip, time and end speed; the traffic relaxed, or ahead as a hard wall), against the follower's own
drive in the same model (roadload.experiments.rl.traffic_limit).

    python scripts/traffic_limit.py --episodes 50
    python scripts/traffic_limit.py --quick             # CI smoke run (2 short episodes)
"""

from roadload.experiments.rl.traffic_limit import main

if __name__ == "__main__":
    main()
