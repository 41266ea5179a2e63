"""RL on ``roadload/EcoHighway-v0``: PPO (stable-baselines3) on highway-env traffic around a roadload ego, and
its evaluation on held-out episodes against two rule-based baselines driving the same force command.

Baselines (policies of the observation, the same action as the agent):

- ``cruise``: speed hold at ``target_speed`` (P control on the speed error plus a cruise feed-forward), blind to
  the traffic.
- ``idm``: the Intelligent Driver Model (Treiber et al. 2000; what highway-env's traffic vehicles drive) on the
  ego's front gap and closing speed, its desired acceleration turned into the normalised force command with the
  ego's drive scales (roadload.gym.ecodrive.DriveScales).

Metrics per episode: distance [m], source energy [kWh] and per distance [Wh/km], mean speed [km/h], crashed,
headway deficit (the integral of (h_min - h)+ [s^2]) and the return.
"""

from __future__ import annotations

import json
import math
import time
from pathlib import Path
from typing import Any, Callable

import numpy as np
import pandas as pd

from roadload.fileio import save_figure
from roadload.gym.config import EcoHighwayConfig, EcoTrafficConfig, make_config
from roadload.gym.ecodrive import DriveScales
from roadload.gym.highway import EcoHighwayEnv, highway_observation_layout
from roadload.gym.traffic import traffic_observation_layout
from roadload.presets import get_preset
from roadload.tables import write_csv

from .common import RLError, _atomic_write_bytes, silent_logger
from .training import _curve_callback

HIGHWAY_ENV_ID = "roadload:roadload/EcoHighway-v0"
HIGHWAY_HELD_OUT_SEEDS = tuple(range(50_000, 50_010))
"""Episode seeds of the held-out evaluation (traffic and road drawn from them; training draws from its own RNG)."""
HIGHWAY_PPO: dict[str, Any] = dict(n_steps=256, batch_size=256, n_epochs=10, learning_rate=3e-4, gamma=0.99,
                                   gae_lambda=0.95, clip_range=0.2, ent_coef=0.0, policy_kwargs={"log_std_init": -1.0})
"""PPO settings: gamma 0.99 (an 80-step episode at 2 Hz), the rest as EcoDrive's."""
HIGHWAY_COLUMNS = ["controller", "seed", "crashed", "distance_m", "energy_kWh", "energy_Wh_per_km", "mean_speed_kmh",
                   "headway_deficit", "episode_return"]


# --------------------------------------------------------------------------------------------- baselines
def _indices(cfg: EcoHighwayConfig | EcoTrafficConfig) -> dict[str, tuple[int, float]]:
    """name -> (index, scale) of the observation of EcoHighway-v0 or EcoTraffic-v0 (both carry v, front_gap and
    front_closing_speed)."""
    layout = (traffic_observation_layout(cfg) if isinstance(cfg, EcoTrafficConfig)
              else highway_observation_layout(cfg))
    return {name: (k, scale) for k, (name, _unit, scale) in enumerate(layout)}


def cruise_policy(cfg: EcoHighwayConfig | EcoTrafficConfig, target_speed: float | None = None,
                  gain: float = 0.5, feed_forward: float = 0.08) -> Callable[[np.ndarray], np.ndarray]:
    """Speed hold at target_speed [m/s] (default: the config's initial speed): u = feed_forward + gain * (v* - v)
    with gain in 1/(m/s), clipped to [-1, 1]; ignores the traffic."""
    idx = _indices(cfg)
    kv, sv = idx["v"]
    v_set = cfg.initial_speed if target_speed is None else target_speed

    def policy(obs: np.ndarray) -> np.ndarray:
        v = float(obs[kv]) * sv
        return np.array([np.clip(feed_forward + gain * (v_set - v), -1.0, 1.0)], dtype=np.float32)
    return policy


def idm_policy(cfg: EcoHighwayConfig | EcoTrafficConfig, target_speed: float | None = None, max_accel: float = 1.5,
               comfort_decel: float = 2.0, time_gap: float = 1.5, min_gap: float = 5.0,
               feed_forward: float = 0.08) -> Callable[[np.ndarray], np.ndarray]:
    """IDM: a = a_max (1 - (v / v0)^4 - (s*(v, dv) / gap)^2), s* = s0 + v T + v dv / (2 sqrt(a_max b)) [m/s^2],
    turned into the command u = feed_forward + a m / F(v) with F the traction force available at v (a >= 0) or
    the full brake force (a < 0), clipped to [-1, 1]. The returned policy takes one observation or a batch
    (n, observation size) and returns shape (1,) or (n, 1)."""
    idx = _indices(cfg)
    (kv, sv), (kg, sg), (kc, sc) = idx["v"], idx["front_gap"], idx["front_closing_speed"]
    v0 = max(cfg.initial_speed if target_speed is None else target_speed, 0.1)
    spec = get_preset(cfg.vehicle)
    drive = DriveScales.from_spec(spec)
    mass = spec.body.mass
    sqrt_ab = 2.0 * math.sqrt(max_accel * comfort_decel)

    def policy(obs: np.ndarray) -> np.ndarray:
        obs = np.asarray(obs, dtype=np.float64)
        v = obs[..., kv] * sv
        gap = np.maximum(obs[..., kg] * sg, 0.1)
        dv = obs[..., kc] * sc
        s_star = min_gap + np.maximum(0.0, v * time_gap + v * dv / sqrt_ab)
        a = max_accel * (1.0 - (v / v0) ** 4 - (s_star / gap) ** 2)
        force = np.where(a >= 0, np.minimum(drive.peak_traction_force, drive.peak_power / np.maximum(v, 1.0)),
                         drive.full_brake_force)
        return np.clip(feed_forward + a * mass / force, -1.0, 1.0)[..., None].astype(np.float32)
    return policy


# --------------------------------------------------------------------------------------------- rollouts
def run_highway_episode(policy: Callable[[np.ndarray], np.ndarray], env_config: dict[str, Any],
                        seed: int) -> dict[str, Any]:
    """One EcoHighway-v0 episode (reset with ``seed``) driven by ``policy(obs) -> action``; its metrics."""
    env = EcoHighwayEnv(config=dict(env_config))
    obs, info = env.reset(seed=int(seed))
    ret, headway, done = 0.0, 0.0, False
    e0 = info["source_energy_total"]
    while not done:
        obs, r, terminated, truncated, info = env.step(policy(obs))
        ret += float(r)
        headway += float(info["terms"]["headway"])
        done = terminated or truncated
    energy = (info["source_energy_total"] - e0) / 3.6e6
    dist = float(info["s"])
    env.close()
    return {"crashed": bool(info["crashed"]), "distance_m": dist, "energy_kWh": energy,
            "energy_Wh_per_km": energy * 1e3 / max(dist / 1e3, 1e-9), "mean_speed_kmh": dist / max(info["t"], 1e-9)
            * 3.6, "headway_deficit": headway, "episode_return": ret}


def highway_evaluation(policies: dict[str, Callable[[np.ndarray], np.ndarray]], env_config: dict[str, Any],
                       seeds=HIGHWAY_HELD_OUT_SEEDS) -> pd.DataFrame:
    """Per-episode rows of every policy on the same held-out episode seeds."""
    rows = [{"controller": name, "seed": s, **run_highway_episode(p, env_config, s)}
            for name, p in policies.items() for s in seeds]
    return pd.DataFrame(rows, columns=HIGHWAY_COLUMNS)


def highway_summary(table: pd.DataFrame) -> pd.DataFrame:
    """Mean per controller (crashed = share of crashed episodes)."""
    cols = [c for c in HIGHWAY_COLUMNS if c not in ("controller", "seed")]
    out = table.assign(crashed=table.crashed.astype(float)).groupby("controller", sort=False)[cols].mean()
    return out.reset_index()


# --------------------------------------------------------------------------------------------- training
def train_highway(timesteps: int, out_dir: Path, n_envs: int = 4, seed: int = 0,
                  env_config: dict[str, Any] | None = None, seeds=HIGHWAY_HELD_OUT_SEEDS,
                  torch_threads: int = 1) -> dict[str, Any]:
    """PPO on EcoHighway-v0 (``n_envs`` in a DummyVecEnv: highway-env's traffic is Python), then the held-out
    table against cruise / IDM / random; writes ppo_ecohighway.zip/.json, the learning curve CSV/PNG and the
    evaluation CSVs to ``out_dir``; returns paths, tables and the wall time."""
    import torch
    from stable_baselines3 import PPO
    from stable_baselines3.common.env_util import make_vec_env as sb3_make_vec_env
    from stable_baselines3.common.vec_env import DummyVecEnv

    if timesteps < 1 or n_envs < 1:
        raise RLError(f"timesteps and n_envs must be >= 1, got {timesteps}, {n_envs}")
    torch.set_num_threads(torch_threads)
    env_config = dict(env_config or {})
    cfg = make_config(EcoHighwayConfig, env_config)
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    venv = sb3_make_vec_env(HIGHWAY_ENV_ID, n_envs=n_envs, seed=seed, env_kwargs={"config": env_config},
                            vec_env_cls=DummyVecEnv)
    params: dict[str, Any] = dict(HIGHWAY_PPO)
    params["n_steps"] = max(16, min(params["n_steps"], max(timesteps // n_envs, 16)))
    params["batch_size"] = min(params["batch_size"], params["n_steps"] * n_envs)
    model = silent_logger(PPO("MlpPolicy", venv, seed=seed, device="cpu", verbose=0, **params))
    callback = _curve_callback(env_config, eval_every=0, progress=None)  # training episode returns only
    t0 = time.perf_counter()
    try:
        model.learn(total_timesteps=timesteps, callback=callback)
    finally:
        venv.close()
    seconds = time.perf_counter() - t0
    _atomic_write_bytes(out_dir / "ppo_ecohighway.zip", lambda tmp: model.save(str(tmp)))
    meta = {"algo": "ppo", "env": "EcoHighway-v0", "timesteps": int(model.num_timesteps), "n_envs": n_envs,
            "seed": seed, "env_config": env_config, "hyperparams": params, "seconds": seconds}
    _atomic_write_bytes(out_dir / "ppo_ecohighway.json",
                        lambda tmp: tmp.write_text(json.dumps(meta, indent=1, default=str)))
    curve = pd.DataFrame([(t, v) for t, kind, v in callback.rows if kind == "train"],
                         columns=["timesteps", "episode_return"])
    write_csv(out_dir / "ppo_ecohighway_curve.csv", curve)
    _plot_curve(curve, out_dir / "ppo_ecohighway_curve.png")
    rng = np.random.default_rng(seed)
    policies = {"PPO": lambda obs: model.predict(obs, deterministic=True)[0], "idm": idm_policy(cfg),
                "cruise": cruise_policy(cfg),
                "random": lambda obs: rng.uniform(-1.0, 1.0, 1).astype(np.float32)}
    table = highway_evaluation(policies, env_config, seeds)
    summary = highway_summary(table)
    write_csv(out_dir / "highway_evaluation.csv", table)
    write_csv(out_dir / "highway_evaluation_summary.csv", summary)
    return {"seconds": seconds, "timesteps": int(model.num_timesteps), "table": table, "summary": summary,
            "out_dir": out_dir}


def _plot_curve(curve: pd.DataFrame, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 4))
    if len(curve):
        ax.plot(curve.timesteps, curve.episode_return.rolling(50, min_periods=1).mean(), lw=1.2)
    ax.set_xlabel("environment steps (0.5 s each)")
    ax.set_ylabel("training episode return (rolling mean 50)")
    ax.set_title("EcoHighway-v0 PPO learning curve")
    ax.grid(alpha=0.3)
    fig.tight_layout()
    save_figure(fig, path, dpi=120, format="png")
