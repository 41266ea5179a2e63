"""Train PPO on roadload/EcoDrive-v0 briefly and compare it with cruise control and the MPC on held-out roads.

    python examples/ppo_vs_mpc.py --quick            # 2048 steps, 500 m route, one road (< 1 min)
    python examples/ppo_vs_mpc.py --timesteps 50000  # a longer run: 2 km routes, three held-out roads

Prints a Markdown table (energy [kWh], trip time [s], speed-limit violations, RMS jerk [m/s^3]) per controller
and road, and writes it to OUT/evaluation.md. For the full 300 000-step study use ``roadload train``.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import gymnasium as gym
import pandas as pd
import torch
from stable_baselines3 import PPO

import roadload  # noqa: F401  (registers roadload/EcoDrive-v0)
from roadload.experiments.rl import HELD_OUT_SEEDS, run_controller, run_policy, sb3_policy
from roadload.fileio import write_text
from roadload.tables import markdown_table


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="2048 steps on a 500 m route, one held-out road")
    parser.add_argument("--timesteps", type=int, default=50_000, help="PPO training steps (without --quick)")
    parser.add_argument("--out", type=Path, default=Path("out/examples/ppo_vs_mpc"))
    args = parser.parse_args()
    torch.set_num_threads(1)
    timesteps = 2048 if args.quick else args.timesteps
    env_config = {"route_length": 500.0 if args.quick else 2000.0}
    roads = HELD_OUT_SEEDS[:1] if args.quick else HELD_OUT_SEEDS[:3]

    env = gym.make("roadload/EcoDrive-v0", config=env_config)
    model = PPO("MlpPolicy", env, n_steps=512 if args.quick else 1024, batch_size=128, n_epochs=4 if args.quick else 10,
                gamma=0.999, seed=0, device="cpu", policy_kwargs={"log_std_init": -1.0}, verbose=0)
    model.learn(total_timesteps=timesteps)

    rows = []
    for road_seed in roads:
        metrics, _ = run_policy(sb3_policy(model), env_config, road_seed=road_seed)
        rows.append({"road": road_seed, "controller": f"PPO ({timesteps} steps)", **metrics})
        for baseline in ("cruise", "mpc"):
            rows.append({"road": road_seed, "controller": baseline,
                         **run_controller(baseline, env_config, road_seed=road_seed)})
    table = pd.DataFrame(rows)[["road", "controller", "arrived", "energy_kWh", "trip_time", "speed_violations",
                                "rms_jerk"]]
    text = markdown_table(table, floatfmt=".3f")
    print(text)
    args.out.mkdir(parents=True, exist_ok=True)
    write_text(args.out / "evaluation.md", text + "\n")
    if not table["arrived"].all():
        print("note: a controller did not finish a road (arrived = False)")


if __name__ == "__main__":
    main()
