"""Evaluation on held-out roads against cruise control and the MPC: the per-road table and its summary."""

from __future__ import annotations

from typing import Any, Callable

import numpy as np
import pandas as pd

from roadload.gym.config import EcoDriveConfig, make_config
from .common import HELD_OUT_SEEDS
from .rollouts import run_controller, run_policy


# --------------------------------------------------------------------------------------------- evaluation
TABLE_COLUMNS = ["controller", "road_seed", "arrived", "energy_kWh", "trip_time", "cost_kJ", "speed_violations",
                 "violation_time", "max_excess_kmh", "stop_violations", "rms_jerk", "episode_return"]
"""cost_kJ = (source energy + lambda * trip time) / 1000 with lambda the reward's time weight (= the MPC's):
the objective both the RL reward (up to its penalty and shaping terms) and the MPC minimise."""


def evaluation_table(policies: dict[str, Callable[[np.ndarray], np.ndarray]], env_config: dict[str, Any],
                     road_seeds=HELD_OUT_SEEDS, controllers: tuple[str, ...] = ("cruise", "mpc"),
                     progress: Callable[[str], None] | None = None,
                     logs: dict[str, pd.DataFrame] | None = None) -> tuple[pd.DataFrame, list[str]]:
    """Per-road rows for every policy (run in EcoDrive-v0) and controller (controllers' closed loop on the
    simulator, same road/vehicle/effects); returns (table, notes) where notes say what could not run. ``logs``
    (optional dict) receives each controller's time series on the first road."""
    rows, notes = [], []
    for name, policy in policies.items():
        for seed in road_seeds:
            m, log = run_policy(policy, env_config, seed)
            if logs is not None and seed == road_seeds[0]:
                logs[name] = log
            rows.append({"controller": name, "road_seed": seed, **m})
            if progress:
                progress(f"{name} road {seed}")
    for name in controllers:
        for seed in road_seeds:
            try:
                m = run_controller(name, env_config, seed, logs=logs if seed == road_seeds[0] else None)
            except Exception as exc:  # a baseline that fails is reported, not fatal for the RL table
                notes.append(f"{name} on road {seed}: failed ({type(exc).__name__}: {exc})")
                continue
            rows.append({"controller": name, "road_seed": seed, **m})
            if m.get("relaxed_plans") or m.get("infeasible_plans"):
                notes.append(f"{name} on road {seed}: {m['relaxed_plans']} relaxed and {m['infeasible_plans']} "
                             f"infeasible plans (a stop or speed cap out of reach within the comfort limits), "
                             f"{m['fallback_brakes']} fallback brakes; worst: {m['worst_violation']}")
            if progress:
                progress(f"{name} road {seed}")
    table = pd.DataFrame(rows)
    for col in TABLE_COLUMNS:
        if col not in table:
            table[col] = np.nan

    lam = make_config(EcoDriveConfig, env_config).reward.time
    table["cost_kJ"] = (table["energy_kWh"].astype(float) * 3.6e6 + lam * table["trip_time"].astype(float)) / 1e3
    return table[TABLE_COLUMNS], notes


def summarise(table: pd.DataFrame, outside_common: tuple[str, ...] = ("random",)) -> pd.DataFrame:
    """Mean per controller. Energy, trip time and cost are averaged over the *common* roads only -- the roads every
    controller except ``outside_common`` finished -- so the numbers compare like with like (NaN for a controller
    that did not finish one of them); the other columns are averaged over all roads; ``arrived`` is the share of
    roads finished and ``common_roads`` how many roads the like-for-like means use."""
    t = table.copy()
    t["arrived"] = t["arrived"].astype(bool)
    ranked = t[~t.controller.isin(outside_common)]
    common = sorted(set(ranked.road_seed) - set(ranked.loc[~ranked.arrived, "road_seed"]))
    out = []
    for name, g in t.groupby("controller", sort=False):
        row = {"controller": name, "arrived": float(g.arrived.mean()), "common_roads": len(common)}
        c = g[g.road_seed.isin(common)]
        finished = bool(len(c) == len(common) and c.arrived.all()) and len(common) > 0
        for col in ("energy_kWh", "trip_time", "cost_kJ"):
            row[col] = float(c[col].astype(float).mean()) if finished else float("nan")
        for col in ("speed_violations", "violation_time", "max_excess_kmh", "stop_violations", "rms_jerk",
                    "episode_return"):
            row[col] = float(g[col].astype(float).mean())
        out.append(row)
    return pd.DataFrame(out)
