"""Train PPO (stable-baselines3) on roadload/EcoHighway-v0 and compare it on held-out episodes with a cruise
speed hold, an IDM follower and random actions (roadload.experiments.rl.highway_runs).

    python scripts/train_rl_highway.py --timesteps 75000 --n-envs 4 --out out/rl_highway
    python scripts/train_rl_highway.py --quick          # tiny run for CI (512 steps, 2 held-out episodes)
"""

from roadload.experiments.rl.highway_runs import main_train

if __name__ == "__main__":
    main_train()
