"""Where the IDM follower brakes on ``roadload/EcoTraffic-v0``'s held-out episodes, and how early its observation
could have told it: the braking runs by cause, and for each cut-in the warning each signal gives.

    python scripts/traffic_cutins.py --config '{"vehicles_density": 2.0, "spawn": "stopping-gap"}'
    python scripts/traffic_cutins.py --quick            # CI smoke run (3 short episodes)

Per held-out episode (the PPO evaluation's: episode and road seed 50000 + k, safety layer on) the follower is
driven and the vehicles' rows recorded every step. A braking run is a stretch of steps where the follower
decelerates faster than ``BRAKING`` [m/s^2]; its cause is a **cut-in** when, in the 2 s before it starts, the
follower's leader on its lane (roadload.gym.traffic_model.neighbours) became a vehicle that was on another lane the
step before; else **spawn closing** when it starts in the first 3 s (the traffic, spawned at highway-env's
spacing, closes up), else **leader slows**. Per run: its hardest deceleration, the kinetic energy it shed
0.5 m (v_start^2 - v_end^2) [Wh] and the leader's mean acceleration in the 0.5 s before it.

Per cut-in, the warning [s] before the vehicle became the leader given by: its MOBIL decision (target lane the
ego's), its lateral motion (|v_y| > 0.2 m/s), and MOBIL's acceptance of the ego's lane evaluated at every step
(roadload.gym.traffic_model.cut_in_time < cap, the ``cut_in_time`` neighbour feature); its rank among the vehicles
the Kinematics block sorts by |dx| when it decided (rank < kinematics_rows - 1: observed).
"""

from __future__ import annotations

import argparse
import time
from typing import Any

import numpy as np
import pandas as pd

from roadload.gym import traffic_model as tm
from roadload.gym.config import EcoTrafficConfig, make_config
from roadload.gym.traffic import EcoTrafficEnv
from roadload.presets import get_preset
from roadload.tables import markdown_table

from .common import json_object_option
from .highway import idm_policy
from .traffic_training import TRAFFIC_HELD_OUT, TRAFFIC_TRAIN_CONFIG

BRAKING = 1.0
"""Deceleration [m/s^2] beyond which a step belongs to a braking run."""
CAUSE_WINDOW = 2.0
"""A leader change this long [s] before a braking run makes it a cut-in."""
SPAWN_TIME = 3.0
"""Braking runs starting before this time [s] without a cut-in are the spawn's closing up."""


def record_episode(env: EcoTrafficEnv, policy, seed: int) -> np.ndarray:
    """(steps + 1, m, N_V) vehicle rows of the follower's episode ``seed`` (episode and road seed)."""
    obs, _ = env.reset(seed=seed, options={"road_seed": seed})
    rows = [env.vehicles]
    done = False
    while not done:
        obs, _, terminated, truncated, _ = env.step(policy(obs))
        rows.append(env.vehicles)
        done = terminated or truncated
    return np.array(rows)


def observed_rank(veh: np.ndarray, k: int) -> int:
    """Rank of vehicle k in the Kinematics block's order (|dx| from the ego, vehicles within reach and not more
    than 2 lengths behind), or m when it is not listed."""
    dx = veh[1:, tm.V_X] - veh[0, tm.V_X]
    dy = veh[1:, tm.V_Y] - veh[0, tm.V_Y]
    listed = [j + 1 for j in np.argsort(np.abs(dx), kind="stable")
              if np.hypot(dx[j], dy[j]) < tm.PERCEPTION_DISTANCE and dx[j] > -2.0 * tm.LENGTH]
    return listed.index(k) if k in listed else veh.shape[0]


def cut_in_warnings(V: np.ndarray, t: int, k: int, cfg: EcoTrafficConfig, dt: float) -> dict[str, Any]:
    """Warnings [s] of the cut-in of vehicle k, the follower's leader from step t on (module docstring)."""
    lane = int(V[t, 0, tm.V_LANE])
    m = V.shape[1]
    d = t
    while d > 0 and int(V[d - 1, k, tm.V_TARGET_LANE]) == lane:
        d -= 1
    vy = V[:, k, tm.V_SPEED] * np.sin(V[:, k, tm.V_HEADING])
    lateral = next((u for u in range(d, t + 1) if abs(vy[u]) > 0.2), t)
    beh = tm.behaviour_array(cfg.traffic)
    cap = 2.0 * cfg.traffic.lane_change_delay
    members, counts = tm.lane_index_arrays(m, cfg.lanes_count)
    w = t
    while w > 0:
        veh = V[w - 1].copy()
        tm.index_lanes(veh, m, cfg.lanes_count, members, counts)
        if tm.cut_in_time(veh, members, counts, beh, cfg.speed_limit, k, lane, cap) >= cap:
            break
        w -= 1
    return {"from_side": "left" if int(V[d, k, tm.V_LANE]) < lane else "right",
            "warning_decision_s": (t - d) * dt, "warning_lateral_s": (t - lateral) * dt,
            "warning_mobil_s": (t - w) * dt, "rank_at_decision": observed_rank(V[d], k),
            "gap_m": float(V[t, k, tm.V_X] - V[t, 0, tm.V_X] - tm.LENGTH),
            "closing_m_per_s": float(V[t, 0, tm.V_SPEED] - V[t, k, tm.V_SPEED])}


def braking_runs(V: np.ndarray, cfg: EcoTrafficConfig, mass: float, seed: int) -> list[dict[str, Any]]:
    """The follower's braking runs of one recorded episode, their cause and (cut-ins) warnings."""
    dt = 1.0 / cfg.policy_frequency
    m = V.shape[1]
    lead = np.array([tm.neighbours(v, m, 0, int(v[0, tm.V_LANE]))[0] for v in V])
    v0 = V[:, 0, tm.V_SPEED]
    acc = np.diff(v0) / dt
    runs, t = [], 0
    while t < acc.size:
        if acc[t] >= -BRAKING:
            t += 1
            continue
        end = t
        while end < acc.size and acc[end] < -BRAKING:
            end += 1
        lane = int(V[t, 0, tm.V_LANE])
        cut = next((b for b in range(t, max(t - int(CAUSE_WINDOW / dt), 0), -1)
                    if lead[b] >= 0 and lead[b] != lead[b - 1] and int(V[b - 1, lead[b], tm.V_LANE]) != lane), None)
        cause = "cut-in" if cut is not None else ("spawn closing" if t * dt < SPAWN_TIME else "leader slows")
        k = lead[t]
        before = V[max(t - int(0.5 / dt), 0):t + 1, k, tm.V_SPEED] if k >= 0 else np.zeros(1)
        row = {"seed": seed, "start_s": t * dt, "duration_s": (end - t) * dt, "cause": cause,
               "hardest_m_per_s2": float(-acc[t:end].min()),
               "kinetic_energy_shed_Wh": 0.5 * mass * (v0[t] ** 2 - v0[end] ** 2) / 3600.0,
               "leader_acc_before_m_per_s2": float((before[-1] - before[0]) / max((before.size - 1) * dt, dt))}
        if cut is not None:
            row.update(cut_in_warnings(V, cut, int(lead[cut]), cfg, dt))
        runs.append(row)
        t = end
    return runs


def diagnose(env_config: dict[str, Any] | None = None, episodes: int = 50) -> pd.DataFrame:
    """The braking runs of the follower over ``episodes`` held-out episodes (module docstring)."""
    cfg = make_config(EcoTrafficConfig, {**TRAFFIC_TRAIN_CONFIG, **(env_config or {})})
    env = EcoTrafficEnv(cfg)
    policy = idm_policy(cfg)
    mass = get_preset(cfg.vehicle).body.mass
    rows = []
    for e in range(episodes):
        rows += braking_runs(record_episode(env, policy, TRAFFIC_HELD_OUT + e), cfg, mass, TRAFFIC_HELD_OUT + e)
    return pd.DataFrame(rows)


def summary(runs: pd.DataFrame, rows: int) -> tuple[pd.DataFrame, pd.DataFrame]:
    """(per cause: runs, episodes, hardest and mean hardest deceleration, kinetic energy shed and its share,
    the leader's acceleration before; per cut-in warning signal: mean, min, max [s]), the rank test against
    ``rows`` Kinematics rows in the second table."""
    by = runs.groupby("cause").agg(runs=("seed", "size"), episodes=("seed", "nunique"),
                                   hardest=("hardest_m_per_s2", "max"), mean_hardest=("hardest_m_per_s2", "mean"),
                                   kinetic_energy_shed_Wh=("kinetic_energy_shed_Wh", "sum"),
                                   leader_acc_before=("leader_acc_before_m_per_s2", "mean")).reset_index()
    by["share"] = by.kinetic_energy_shed_Wh / by.kinetic_energy_shed_Wh.sum()
    cuts = runs[runs.cause == "cut-in"]
    warn = []
    for col in ("warning_decision_s", "warning_lateral_s", "warning_mobil_s"):
        if col in cuts:
            x = cuts[col].to_numpy(float)
            warn.append({"signal": col, "cut-ins": x.size, "mean": x.mean() if x.size else np.nan,
                         "min": x.min() if x.size else np.nan, "max": x.max() if x.size else np.nan})
    if "rank_at_decision" in cuts:
        seen = int((cuts.rank_at_decision < rows - 1).sum())
        warn.append({"signal": f"observed at the decision with kinematics_rows {rows}", "cut-ins": seen,
                     "mean": np.nan, "min": cuts.rank_at_decision.min(), "max": cuts.rank_at_decision.max()})
    return by, pd.DataFrame(warn)


def main(argv: list[str] | None = None) -> None:
    """Print the braking runs by cause and the cut-ins' warnings (``scripts/traffic_cutins.py``)."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--episodes", type=int, default=50, help="held-out episodes")
    ap.add_argument("--config", default=None, help="EcoTraffic-v0 config as JSON text over the evaluation's")
    ap.add_argument("--csv", default=None, help="write the braking runs here")
    ap.add_argument("--quick", action="store_true", help="tiny run for CI")
    a = ap.parse_args(argv)
    config = json_object_option(ap, a.config)
    if a.quick:
        a.episodes = 3  # the third holds a cut-in at 0.6 s
        config = {"vehicles_density": 2.0, "spawn": "stopping-gap", **config, "duration": 5.0}
    if a.episodes < 1:
        ap.error(f"--episodes: expected >= 1, got {a.episodes}")
    c0 = time.process_time()
    runs = diagnose(config, a.episodes)
    if a.csv:
        runs.to_csv(a.csv, index=False)
    rows = make_config(EcoTrafficConfig, {**TRAFFIC_TRAIN_CONFIG, **config}).kinematics_rows
    if runs.empty:
        print(f"no braking run beyond {BRAKING:g} m/s^2 in {a.episodes} episodes")
        return
    by, warn = summary(runs, rows)
    print(markdown_table(by, floatfmt=".3g"))
    print(markdown_table(warn, floatfmt=".3g"))
    print(f"{a.episodes} episodes, {time.process_time() - c0:.0f} s CPU")
