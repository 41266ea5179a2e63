"""Train PPO (stable-baselines3) on roadload/EcoTraffic-v0's native vector env (safety layer on), one policy per
seed, and compare them with the IDM follower on held-out episodes, natively and on the highway-env backend
(roadload.experiments.rl.traffic_training).

    OMP_WAIT_POLICY=PASSIVE python scripts/train_traffic.py --seeds 0,1,2 --timesteps 2000000 --out out/rl_traffic
    python scripts/train_traffic.py --evaluate-only --seeds 0,1,2 --out out/rl_traffic     # re-evaluate
    python scripts/train_traffic.py --quick             # CI smoke run (4k steps, 2 + 1 held-out episodes)
"""

import os

os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")  # before torch loads libgomp (roadload.gym.vector)

from roadload.experiments.rl.traffic_training import main  # noqa: E402

if __name__ == "__main__":
    main()
