"""Effect of EcoDrive-v0's speed shield on a trained policy: the same policy on the held-out roads with the shield
on and off -- cost (energy + lambda * time), trip time, speed-violation episodes and the share of steps where the
shield capped the policy's command.

    python scripts/shield_effect.py --policy out/rl/ppo_ecodrive.zip   # saved by scripts/train_rl.py --out out/rl
    python scripts/shield_effect.py --quick                            # CI: full throttle, 1 road
"""

import argparse

import numpy as np

from roadload.experiments.rl import HELD_OUT_SEEDS, load_policy, run_policy, sb3_policy
from roadload.gym.config import EcoDriveConfig, make_config
from roadload.gym.ecodrive import observation_layout


def counted(policy, prev_index: int):
    """policy wrapped to count the steps where the applied command (the next observation's previous_command)
    is below the policy's own (clipped) command, i.e. where the shield capped it."""
    state = {"last": None, "capped": 0, "steps": 0}

    def wrapped(obs):
        if state["last"] is not None:
            state["steps"] += 1
            state["capped"] += int(float(obs[prev_index]) < state["last"] - 1e-6)
        action = policy(obs)
        state["last"] = float(np.clip(np.asarray(action).reshape(-1)[0], -1.0, 1.0))
        return action
    return wrapped, state


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--policy", default=None, help="a saved SB3 policy (ppo_ecodrive.zip); none = full throttle")
    ap.add_argument("--roads", type=int, default=len(HELD_OUT_SEEDS), help="held-out roads")
    ap.add_argument("--quick", action="store_true", help="full throttle on one road")
    a = ap.parse_args(argv)
    if a.quick:
        a.policy, a.roads = None, 1
    policy = sb3_policy(load_policy(a.policy)) if a.policy else (lambda obs: np.ones(1, dtype=np.float32))
    base = {"route_length": 2000.0}
    lam = make_config(EcoDriveConfig, base).reward.time
    prev = [row[0] for row in observation_layout(make_config(EcoDriveConfig, base))].index("previous_command")
    print("shield  road   cost_kJ  trip_s  violations  max_excess_kmh  capped_steps")
    for shield in (True, False):
        costs = []
        for seed in HELD_OUT_SEEDS[:a.roads]:
            wrapped, st = counted(policy, prev)
            m, _ = run_policy(wrapped, {**base, "speed_shield": shield}, seed)
            cost = (m["energy_J"] + lam * m["trip_time"]) / 1e3
            costs.append(cost)
            print(f"{'on ' if shield else 'off'}    {seed}  {cost:8.1f}  {m['trip_time']:6.1f}  "
                  f"{m['speed_violations']:10d}  {m['max_excess_kmh']:14.1f}  "
                  f"{st['capped'] / max(st['steps'], 1):11.1%}")
        print(f"shield {'on' if shield else 'off'}: mean cost {np.mean(costs):.1f} kJ")
