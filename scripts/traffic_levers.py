"""Rule-based variants of the IDM follower on roadload/EcoTraffic-v0, one physical lever each (coasting, the
grade, pulse and glide, the follower's settings), paired with the follower on the PPO evaluation's held-out
episodes (roadload.experiments.rl.traffic_levers).

    python scripts/traffic_levers.py --episodes 50
    python scripts/traffic_levers.py --quick             # CI smoke run (2 episodes)
"""

from roadload.experiments.rl.traffic_levers import main

if __name__ == "__main__":
    main()
