"""Train PPO and SAC (stable-baselines3) on roadload/EcoDrive-v0 with vectorised envs, save the policies, plot the
learning curve and evaluate on held-out roads against cruise control and the MPC.

    python scripts/train_rl.py --timesteps 300000 --out out/rl            # = roadload train ...
    python scripts/train_rl.py --evaluate-only --out out/rl               # re-evaluate saved policies

All options: python scripts/train_rl.py --help (the same as ``roadload train``).
"""

import typer

from roadload.experiments.rl import register

if __name__ == "__main__":
    app = typer.Typer(add_completion=False)
    register(app, typer.Typer())
    app(__import__("sys").argv[1:])  # the only command of this app: train
