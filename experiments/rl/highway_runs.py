"""Evaluate saved EcoHighway-v0 PPO policies on the held-out episodes under the current reward, next to the IDM
follower (roadload.experiments.rl.highway): e.g. the policy trained on the first reward, which braked to recover
the start's kinetic energy, against the one trained with the mechanical-energy credit.

    python scripts/eval_rl_highway.py \\
        --policy "first reward=docs/results/scale_rl/highway/ppo_ecohighway.zip" \\
        --policy "mechanical-energy credit=docs/results/scale_rl/highway_credit/ppo_ecohighway.zip" \\
        --config '{"simulation_frequency": 4.0, "policy_frequency": 2.0, "vehicles_count": 10}'
    python scripts/eval_rl_highway.py --quick      # CI smoke run (the credit policy, 1 short episode)
"""

import argparse
import json
from pathlib import Path

from stable_baselines3 import PPO

from roadload.experiments.rl.highway import (HIGHWAY_HELD_OUT_SEEDS, highway_evaluation, highway_summary,
                                             idm_policy)
from roadload.gym.config import EcoHighwayConfig, make_config

# the shipped policy, found from the repository wherever the script is run from
REPO = Path(__file__).resolve().parents[1]
DEFAULT_POLICY = f"PPO={REPO / 'docs/results/scale_rl/highway_credit/ppo_ecohighway.zip'}"


def _policy(model):
    return lambda obs: model.predict(obs, deterministic=True)[0]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--policy", action="append", default=None, help="NAME=PATH of a saved PPO zip (repeatable)")
    ap.add_argument("--config", default=None, help="EcoHighway-v0 config as JSON text")
    ap.add_argument("--episodes", type=int, default=len(HIGHWAY_HELD_OUT_SEEDS), help="held-out episodes")
    ap.add_argument("--quick", action="store_true", help="1 episode of 5 s with 5 traffic vehicles")
    a = ap.parse_args()
    config = json.loads(a.config) if a.config else {}
    if a.quick:
        a.episodes = 1
        config = {**config, "vehicles_count": 5, "duration": 5.0}
    policies = {}
    for item in a.policy or [DEFAULT_POLICY]:
        name, sep, path = item.partition("=")
        if not sep or not Path(path).is_file():
            ap.error(f"--policy: expected NAME=PATH of an existing .zip, got {item!r}")
        policies[name] = _policy(PPO.load(path, device="cpu"))
    policies["idm"] = idm_policy(make_config(EcoHighwayConfig, config))
    table = highway_evaluation(policies, config, HIGHWAY_HELD_OUT_SEEDS[:a.episodes])
    print(highway_summary(table).to_string(index=False, float_format=lambda x: f"{x:.3g}"))


if __name__ == "__main__":
    main()
