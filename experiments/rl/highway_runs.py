"""PPO on roadload/EcoHighway-v0 from the command line: train it and compare it on held-out episodes with a cruise
speed hold, an IDM follower and random actions (:func:`main_train`, ``scripts/train_rl_highway.py``), and
evaluate saved policies under the current reward next to the IDM follower (:func:`main_evaluate`,
``scripts/eval_rl_highway.py``): e.g. the policy trained on the first reward, which braked to recover the start's
kinetic energy, against the one trained with the mechanical-energy credit.

    python scripts/train_rl_highway.py --timesteps 75000 --n-envs 4 --out out/rl_highway
    python scripts/train_rl_highway.py --quick          # tiny run for CI (512 steps, 2 held-out episodes)
    python scripts/eval_rl_highway.py \\
        --policy "first reward=out/rl_highway_first_reward/ppo_ecohighway.zip" \\
        --policy "mechanical-energy credit=examples/policies/ppo_ecohighway_energy_credit.zip" \\
        --config '{"simulation_frequency": 4.0, "policy_frequency": 2.0, "vehicles_count": 10}'
    python scripts/eval_rl_highway.py --quick      # CI smoke run (the credit policy, 1 short episode)
"""

from __future__ import annotations

import argparse
import json
import tempfile
from pathlib import Path

from stable_baselines3 import PPO

from roadload.experiments.rl.highway import (HIGHWAY_HELD_OUT_SEEDS, highway_evaluation, highway_summary,
                                             idm_policy, train_highway)
from roadload.gym.config import EcoHighwayConfig, make_config

REPO = Path(__file__).resolve().parents[2]
"""The source tree of an editable install; the scripts pass their own repository instead."""
SHIPPED_POLICY = "examples/policies/ppo_ecohighway_energy_credit.zip"
"""The reference policy that :func:`main_evaluate` evaluates by default, relative to the repository (its
provenance: ``examples/policies/README.md``)."""


def _policy(model):
    return lambda obs: model.predict(obs, deterministic=True)[0]


def main_train(argv: list[str] | None = None) -> None:
    """Train PPO on EcoHighway-v0 and print the held-out comparison (``scripts/train_rl_highway.py``)."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--timesteps", type=int, default=75_000, help="environment steps (0.5 s of driving each)")
    ap.add_argument("--n-envs", type=int, default=4, help="environments in the DummyVecEnv")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--episodes", type=int, default=len(HIGHWAY_HELD_OUT_SEEDS), help="held-out episodes")
    ap.add_argument("--config", default=None, help="EcoHighway-v0 config as JSON text")
    ap.add_argument("--out", type=Path, default=Path("out/rl_highway"))
    ap.add_argument("--quick", action="store_true", help="tiny run (512 steps, 2 episodes, 5 traffic vehicles)")
    a = ap.parse_args(argv)
    config = json.loads(a.config) if a.config else {}
    if a.quick:
        a.timesteps, a.episodes, a.n_envs = 512, 2, 2
        config = {"vehicles_count": 5, "duration": 10.0, **config}
        if a.out == Path("out/rl_highway"):
            a.out = Path(tempfile.mkdtemp(prefix="roadload-rl-highway-"))
    res = train_highway(a.timesteps, a.out, n_envs=a.n_envs, seed=a.seed, env_config=config,
                        seeds=HIGHWAY_HELD_OUT_SEEDS[:a.episodes])
    print(f"PPO on EcoHighway-v0: {res['timesteps']} steps in {res['seconds']:.0f} s "
          f"({res['timesteps'] / res['seconds']:.0f} steps/s)")
    print(res["summary"].to_string(index=False, float_format=lambda x: f"{x:.3g}"))
    print(f"tables and learning curve in {res['out_dir']}")


def main_evaluate(argv: list[str] | None = None, repo: Path = REPO) -> None:
    """Evaluate saved PPO policies (default: the shipped one under ``repo``) next to the IDM follower on the
    held-out episodes (``scripts/eval_rl_highway.py``)."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--policy", action="append", default=None, help="NAME=PATH of a saved PPO zip (repeatable)")
    ap.add_argument("--config", default=None, help="EcoHighway-v0 config as JSON text")
    ap.add_argument("--episodes", type=int, default=len(HIGHWAY_HELD_OUT_SEEDS), help="held-out episodes")
    ap.add_argument("--quick", action="store_true", help="1 episode of 5 s with 5 traffic vehicles")
    a = ap.parse_args(argv)
    config = json.loads(a.config) if a.config else {}
    if a.quick:
        a.episodes = 1
        config = {**config, "vehicles_count": 5, "duration": 5.0}
    policies = {}
    for item in a.policy or [f"PPO={repo / SHIPPED_POLICY}"]:
        name, sep, path = item.partition("=")
        if not sep or not Path(path).is_file():
            ap.error(f"--policy: expected NAME=PATH of an existing .zip, got {item!r}")
        policies[name] = _policy(PPO.load(path, device="cpu"))
    policies["idm"] = idm_policy(make_config(EcoHighwayConfig, config))
    table = highway_evaluation(policies, config, HIGHWAY_HELD_OUT_SEEDS[:a.episodes])
    print(highway_summary(table).to_string(index=False, float_format=lambda x: f"{x:.3g}"))
