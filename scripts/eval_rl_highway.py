"""Evaluate saved EcoHighway-v0 PPO policies on the held-out episodes under the current reward, next to the IDM
follower (roadload.experiments.rl.highway_runs).

    python scripts/eval_rl_highway.py --policy "NAME=PATH.zip" [--policy ...] [--config JSON] [--episodes N]
    python scripts/eval_rl_highway.py --quick      # CI smoke run (the shipped policy, 1 short episode)
"""

from pathlib import Path

from roadload.experiments.rl.highway_runs import main_evaluate

if __name__ == "__main__":
    main_evaluate(repo=Path(__file__).resolve().parents[1])
