"""Rollouts on EcoDrive-v0: a policy or a controller baseline driven over one road, with its metrics."""

from __future__ import annotations

from typing import Any, Callable

import numpy as np
import pandas as pd

from roadload.controllers.closed_loop import crossing, run_metrics
from roadload.controllers.drive import DriveSettings, drive
from roadload.gym.config import EcoDriveConfig, make_config
from roadload.gym.ecodrive import EcoDriveEnv
from .common import RLError, _route


# --------------------------------------------------------------------------------------------- rollouts
def run_policy(policy: Callable[[np.ndarray], np.ndarray], env_config: dict[str, Any], road_seed: int,
               seed: int = 0) -> tuple[dict[str, Any], pd.DataFrame]:
    """One episode of EcoDrive-v0 on road ``road_seed`` driven by ``policy(obs) -> action``; returns the
    controllers' metrics (roadload.controllers.closed_loop.run_metrics: violations, jerk) plus energy, time and
    the return, and the per-step log (t, s, v, a, speed_limit, energy)."""
    import gymnasium as gym

    env = gym.make("roadload/EcoDrive-v0", config={**env_config, "road_seed": int(road_seed)})
    obs, info = env.reset(seed=seed)
    rows = []
    ret = 0.0
    energy = 0.0
    done = False
    truncated = False
    while not done:
        t0, s0, v0, lim0 = info["t"], info["s"], info["v"], info["speed_limit"]
        obs, r, terminated, truncated, info = env.step(policy(obs))
        ret += float(r)
        energy += info["terms"]["energy"]
        rows.append((t0, s0, v0, info["a"], lim0, energy))
        done = terminated or truncated
    log = pd.DataFrame(rows, columns=["t", "s", "v", "a", "speed_limit", "energy"])
    eco_env = env.unwrapped
    if not isinstance(eco_env, EcoDriveEnv):
        raise RLError(f"roadload/EcoDrive-v0 made a {type(eco_env).__name__}, expected EcoDriveEnv")
    metrics = _metrics(log, eco_env.config.control_period, arrived=not truncated)
    # the crossing of the route end inside the last step, as for the controllers (closed_loop.crossing)
    track = (np.append(log["t"].to_numpy(float), info["t"]), np.append(log["s"].to_numpy(float), info["s"]),
             np.append(log["v"].to_numpy(float), info["v"]), np.concatenate([[0.0], log["energy"].to_numpy(float)]))
    t_arr, e_arr, v_arr = crossing(track, float(info["route_length"])) if not truncated else (float("nan"),) * 3
    metrics.update(arrival_time=t_arr, arrival_energy_J=e_arr, arrival_speed=v_arr)
    metrics.update(energy_J=float(energy), energy_kWh=float(energy) / 3.6e6,
                   trip_time=float(info["t"]) if not truncated else float("nan"), episode_return=float(ret),
                   stop_violations=int(round(info["return_costs"]["stop"] / max(eco_env.config.reward.stop,
                                                                                 1e-300))))
    env.close()
    return metrics, log


def _metrics(log: pd.DataFrame, dt: float, arrived: bool) -> dict[str, Any]:

    return run_metrics(log, dt, arrived=arrived)


def random_policy(action_space, seed: int = 0) -> Callable[[np.ndarray], np.ndarray]:
    rng = np.random.default_rng(seed)
    return lambda obs: rng.uniform(action_space.low, action_space.high).astype(np.float32)


def sb3_policy(model) -> Callable[[np.ndarray], np.ndarray]:
    return lambda obs: model.predict(obs, deterministic=True)[0]


CONTROLLER_BASELINES = {"cruise": ("cruise", "abc"), "mpc": ("mpc", "oracle"), "mpc_online": ("mpc", "online")}
"""Baseline name -> (controller, force model) of roadload.controllers.drive."""


def run_controller(name: str, env_config: dict[str, Any], road_seed: int, seed: int = 0,
                   logs: dict[str, pd.DataFrame] | None = None) -> dict[str, Any]:
    """A controllers baseline on the same road (cut to route_length), vehicle and effects, in the controllers'
    closed loop on the simulator (:func:`roadload.controllers.drive.drive`): 'cruise' (PI cruise control, abc
    force model), 'mpc' (the spatial MPC with the oracle force model) or 'mpc_online' (the MPC with the online
    RRLM force model). The MPC's time weight is the reward's, so both optimise energy + lambda * time."""

    if name not in CONTROLLER_BASELINES:
        raise RLError(f"unknown baseline {name!r}; choose from {sorted(CONTROLLER_BASELINES)}")
    controller, force_model = CONTROLLER_BASELINES[name]
    cfg = make_config(EcoDriveConfig, env_config, road_seed=int(road_seed))
    road = _route(cfg, road_seed)
    settings = DriveSettings(controller=controller, force_model=force_model, time_weight=cfg.reward.time,
                             dt=cfg.control_period)
    result, _ = drive(cfg.vehicle, road, effects=cfg.effects, seed=seed, settings=settings)
    if logs is not None:
        logs[name] = result.log
    m = dict(result.metrics)
    out = {k: m.get(k) for k in ("arrived", "energy_kWh", "trip_time", "speed_violations", "violation_time",
                                 "max_excess_kmh", "rms_jerk", "max_abs_accel", "distance", "mean_speed_kmh")}
    if controller == "mpc":  # plans that could not meet a stop or cap within the comfort limits, and the fallback
        out.update(relaxed_plans=int(m.get("ctl_relaxed_plans", 0)), infeasible_plans=int(m.get(
            "ctl_infeasible_plans", 0)), fallback_brakes=int(m.get("ctl_fallback_brake", 0)),
            worst_violation=str(m.get("ctl_worst_violation", "")))
    return out
