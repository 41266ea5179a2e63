"""PPO (stable-baselines3) on ``roadload/EcoTraffic-v0``'s native vector env, its evaluation on held-out episodes
against the IDM follower, and the transfer of the same policy to the highway-env backend (EcoHighway-v0 in
EcoTraffic-v0's layout, roadload.gym.traffic_reference). Command line: :func:`main` (``scripts/train_traffic.py``).

    OMP_WAIT_POLICY=PASSIVE python scripts/train_traffic.py --seeds 0,1,2 --timesteps 1000000 --out out/rl_traffic
    python scripts/train_traffic.py --evaluate-only --seeds 0,1,2 --out out/rl_traffic     # re-evaluate
    python scripts/train_traffic.py --quick             # CI smoke run (4k steps, 2 + 1 held-out episodes)

Training: ``n_envs`` sub-envs of the native vector env behind the SB3 adapter (same-step autoreset), episodes and
roads drawn by the env (road seeds in the config's ``road_seed_range``, default [0, 100)). The default config of
training and evaluation turns the safety layer on (``shield.enabled``) and spawns the ego outside its braking
envelope (``spawn='outside-envelope'``; highway-env's spawn puts it inside on about half the episodes, and the
layer's forced braking there cost the IDM follower 16 Wh/km). Every policy, the IDM follower included, runs on it.

Held-out evaluation: episode k (k < episodes) is reset with seed 50000 + k and road seed 50000 + k, outside the
training range, on the same config; every policy drives the same episodes. Per episode: crashed, distance [m],
source energy [kWh], time [s], return; the summary gives energy per km = total energy / total distance [Wh/km],
mean speed = total distance / total time [km/h], crashes, mean return. Over training seeds: the mean and a 95 %
t-interval of each seed's summary.

Transfer: the same episode seeds and road seeds on the highway-env backend; highway-env's road is straight, so the
configuration there has ``curvature=False`` (the native policy was trained with curvature).
"""

from __future__ import annotations

import argparse
import json
import math
import tempfile
import time
from pathlib import Path
from typing import Any, Callable

import gymnasium as gym
import numpy as np
import pandas as pd

from roadload.gym.config import EcoHighwayReward, EcoTrafficConfig, make_config
from roadload.gym.sb3 import SB3VecEnv
from roadload.gym.traffic import EcoTrafficEnv, EcoTrafficVectorEnv
from roadload.tables import markdown_table, write_csv

from .common import RLError, _atomic_write_bytes, json_object_option, silent_logger
from .highway import idm_policy
from .traffic_objective import PairedFollower, SpeedBand, SpeedConstraint, TripEnd, reference_speed, speed_band
from .training import _curve_callback

MECHANICAL_WEIGHT = EcoHighwayReward().mechanical_energy
"""Battery-equivalent value of a joule of the ego's mechanical energy (the reward's credit), for net energy."""
TRAFFIC_HELD_OUT = 50_000
"""First episode seed and road seed of the held-out evaluation (training roads are in [0, 100))."""
TRAFFIC_TRAIN_CONFIG: dict[str, Any] = {"shield": {"enabled": True}, "spawn": "outside-envelope"}
"""The training and evaluation configuration: EcoTraffic-v0's defaults with the safety layer on and the ego spawned
outside its envelope (module docstring)."""
TRAFFIC_PPO: dict[str, Any] = dict(n_steps=256, batch_size=512, n_epochs=10, learning_rate=3e-4, gamma=0.99,
                                   gae_lambda=0.95, clip_range=0.2, ent_coef=0.0,
                                   policy_kwargs={"log_std_init": -1.0})
"""PPO settings: 32 sub-envs x 256 steps = 8192 samples per update; gamma 0.99 (a 10 s horizon at 10 Hz)."""
EPISODE_COLUMNS = ["policy", "backend", "seed", "crashed", "distance_m", "energy_kWh", "time_s", "episode_return",
                   "steps", "shield_steps", "mechanical_kWh"]


# --------------------------------------------------------------------------------------------- evaluation
def traffic_episode(env: Any, policy: Callable[[np.ndarray], np.ndarray], seed: int) -> dict[str, Any]:
    """One held-out episode (episode and road seed ``seed``) of either backend under ``policy``."""
    obs, info = env.reset(seed=int(seed), options={"road_seed": int(seed)})
    e0 = info["source_energy_total"]
    ret, shielded, steps, mechanical, done = 0.0, 0, 0, 0.0, False
    while not done:
        obs, r, terminated, truncated, info = env.step(policy(obs))
        steps += 1
        ret += float(r)
        shielded += int(info.get("shield_active", False))
        mechanical += float(info["terms"]["mechanical"])
        done = terminated or truncated
    return {"crashed": bool(info["crashed"]), "distance_m": float(info["s"]),
            "energy_kWh": float(info["source_energy_total"] - e0) / 3.6e6, "time_s": float(info["t"]),
            "episode_return": ret, "steps": steps, "shield_steps": shielded, "mechanical_kWh": mechanical / 3.6e6}


def make_backend_env(backend: str, cfg: EcoTrafficConfig) -> Any:
    """The native env or its highway-env reference (straight road) for the configuration."""
    if backend == "native":
        return EcoTrafficEnv(cfg)
    if backend == "highway-env":
        from roadload.gym.traffic_reference import HighwayTrafficEnv

        return HighwayTrafficEnv(cfg.model_copy(update={"curvature": False}))
    raise RLError(f"backend: expected 'native' or 'highway-env', got {backend!r}")


def evaluate_traffic(policies: dict[str, Callable[[np.ndarray], np.ndarray]], env_config: dict[str, Any],
                     episodes: int = 50, backend: str = "native",
                     progress: Callable[[str], None] | None = None) -> pd.DataFrame:
    """Per-episode rows of every policy on the held-out episodes of one backend."""
    cfg = make_config(EcoTrafficConfig, env_config)
    env = make_backend_env(backend, cfg)
    rows = []
    for name, policy in policies.items():
        for k in range(episodes):
            rows.append({"policy": name, "backend": backend, "seed": TRAFFIC_HELD_OUT + k,
                         **traffic_episode(env, policy, TRAFFIC_HELD_OUT + k)})
        if progress:
            progress(f"{backend}: {name} done")
    env.close()
    return pd.DataFrame(rows, columns=EPISODE_COLUMNS)


def summarise_traffic(table: pd.DataFrame, mechanical_weight: float = MECHANICAL_WEIGHT) -> pd.DataFrame:
    """Per policy and backend: episodes, crashes, energy per km, net energy per km (source energy less
    ``mechanical_weight`` x the mechanical energy gained over the episode: speed or height left at the end is
    credited, speed used up is charged, as the reward does), mean speed, mean return, share of shielded steps."""
    out = []
    for (name, backend), g in table.groupby(["policy", "backend"], sort=False):
        dist = g.distance_m.sum()
        net = g.energy_kWh.sum() - mechanical_weight * g.mechanical_kWh.sum()
        out.append({"policy": name, "backend": backend, "episodes": len(g), "crashes": int(g.crashed.sum()),
                    "energy_Wh_per_km": g.energy_kWh.sum() * 1e6 / max(dist, 1e-9),
                    "net_energy_Wh_per_km": net * 1e6 / max(dist, 1e-9),
                    "mean_speed_kmh": dist / max(g.time_s.sum(), 1e-9) * 3.6,
                    "mean_return": float(g.episode_return.mean()),
                    "shielded_steps": float(g.shield_steps.sum() / max(g.steps.sum(), 1))})
    return pd.DataFrame(out)


def paired_differences(table: pd.DataFrame, reference: str = "IDM follower") -> pd.DataFrame:
    """Per policy and backend, against ``reference`` on the same held-out episodes (paired by seed): the mean
    per-episode difference of energy per km [Wh/km], net energy per km [Wh/km] (summarise_traffic) and mean speed
    [km/h], each with its 95 % t-interval half-width over episodes, and the episodes where the policy was at least
    as fast."""
    from scipy import stats

    per = table.assign(e=table.energy_kWh * 1e6 / table.distance_m.clip(lower=1e-9),
                       n=(table.energy_kWh - MECHANICAL_WEIGHT * table.mechanical_kWh) * 1e6
                       / table.distance_m.clip(lower=1e-9),
                       v=table.distance_m / table.time_s.clip(lower=1e-9) * 3.6)
    rows = []
    for backend, b in per.groupby("backend", sort=False):
        ref = b[b.policy == reference].set_index("seed")
        for name, g in b[b.policy != reference].groupby("policy", sort=False):
            both = g.set_index("seed").join(ref[["e", "n", "v"]].add_suffix("_ref"), how="inner")
            k = len(both)
            if k == 0:
                continue
            t = stats.t.ppf(0.975, k - 1) / math.sqrt(k) if k > 1 else float("nan")
            row: dict[str, Any] = {"policy": name, "backend": backend, "episodes": k}
            for col, label in (("e", "d_energy_Wh_per_km"), ("n", "d_net_energy_Wh_per_km"),
                               ("v", "d_speed_kmh")):
                d = (both[col] - both[f"{col}_ref"]).to_numpy()
                row[label] = float(d.mean())
                row[f"{label}_ci95"] = float(t * d.std(ddof=1)) if k > 1 else float("nan")
            row["at_least_as_fast"] = int((both.v >= both.v_ref).sum())
            rows.append(row)
    return pd.DataFrame(rows)


PAIRED_COLUMNS = ("d_energy_Wh_per_km", "d_net_energy_Wh_per_km", "d_speed_kmh")
"""The paired differences (:func:`paired_differences`) whose interval over training seeds is reported."""


def seed_intervals(summaries: pd.DataFrame, columns=("energy_Wh_per_km", "net_energy_Wh_per_km", "mean_speed_kmh",
                                                      "mean_return", "crashes")) -> pd.DataFrame:
    """Mean and 95 % t-interval (Student t, n - 1 degrees of freedom) over training seeds, per backend."""
    from scipy import stats

    rows = []
    for backend, g in summaries.groupby("backend", sort=False):
        n = len(g)
        row: dict[str, Any] = {"backend": backend, "seeds": n}
        for c in columns:
            x = g[c].astype(float).to_numpy()
            half = stats.t.ppf(0.975, n - 1) * x.std(ddof=1) / math.sqrt(n) if n > 1 else float("nan")
            row[c] = float(x.mean())
            row[f"{c}_ci95"] = float(half)
        rows.append(row)
    return pd.DataFrame(rows)


# --------------------------------------------------------------------------------------------- training
def sb3_predict(model) -> Callable[[np.ndarray], np.ndarray]:
    return lambda obs: model.predict(obs, deterministic=True)[0]


def residual_command(base_u: np.ndarray, action: np.ndarray, scale: float, floor: float | None) -> np.ndarray:
    """u = clip(base + scale a, -1, 1), and with a speed floor f (>= 0) at least base - f: the agent may add up to
    ``scale`` to the base command but take at most f off it, so it cannot fall back behind the base's driving by
    coasting (the reward and the shield are unchanged)."""
    u = np.clip(base_u + scale * np.asarray(action, dtype=np.float32), -1.0, 1.0)
    if floor is not None:
        u = np.maximum(u, np.clip(base_u - floor, -1.0, 1.0))
    return u.astype(np.float32)


def _check_residual(scale: float, floor: float | None) -> None:
    if not 0 < scale <= 2:
        raise RLError(f"residual scale: expected 0 < scale <= 2 (command units), got {scale}")
    if floor is not None and not 0 <= floor <= scale:
        raise RLError(f"speed floor: expected 0 <= floor <= the residual scale {scale} (command units), got {floor}")


class ResidualActions(gym.vector.VectorWrapper):
    """Residual policy learning on a vector env: the agent's action a in [-1, 1] corrects a base policy,
    u = clip(base(obs) + scale a, -1, 1), at least base - floor with a speed floor (:func:`residual_command`; the
    base sees the observation the agent sees). With the IDM follower as the base, PPO starts from the follower's
    driving instead of from random forces."""

    def __init__(self, env: gym.vector.VectorEnv, base: Callable[[np.ndarray], np.ndarray], scale: float,
                 floor: float | None = None) -> None:
        _check_residual(scale, floor)
        super().__init__(env)
        self.base = base
        self.scale = scale
        self.floor = floor
        self._obs: np.ndarray | None = None

    def reset(self, **kwargs):
        obs, info = self.env.reset(**kwargs)
        self._obs = obs
        return obs, info

    def step(self, actions):
        if self._obs is None:
            raise RLError("ResidualActions: step before reset")
        u = residual_command(self.base(self._obs), actions, self.scale, self.floor)
        obs, reward, terminated, truncated, info = self.env.step(u)
        self._obs = obs  # same-step autoreset: already the next episode's first observation where one ended
        return obs, reward, terminated, truncated, info


def residual_policy(model, base: Callable[[np.ndarray], np.ndarray], scale: float, floor: float | None = None
                    ) -> Callable[[np.ndarray], np.ndarray]:
    """The deployed residual policy: :func:`residual_command` of the agent's deterministic action."""
    return lambda obs: residual_command(base(obs), model.predict(obs, deterministic=True)[0], scale, floor)


def train_traffic(timesteps: int, out_dir: Path, seed: int = 0, n_envs: int = 32,
                  env_config: dict[str, Any] | None = None, threads: int = 1, torch_threads: int = 1,
                  hyperparams: dict[str, Any] | None = None, progress: Callable[[str], None] | None = None,
                  report_every: int = 100_000, residual: float = 0.0,
                  speed_floor: float | None = None, speed_constraint: float | None = None,
                  trip_end: bool = False, band: SpeedBand | None = None,
                  paired_reference: bool = False, relative_reward: bool = False) -> dict[str, Any]:
    """PPO on the native vector env (``residual`` > 0: a correction of that scale on the IDM follower,
    :class:`ResidualActions`, at most ``speed_floor`` below it when given; ``speed_constraint`` = margin: trained on
    the reward with a Lagrange multiplier holding the mean speed at (1 + margin) x the IDM follower's;
    ``trip_end``: the time limit is terminal in training; ``band``: two multipliers holding the mean speed inside
    the band around the follower's, instead of ``speed_constraint``'s floor; ``paired_reference``: the constraint
    holds the speed relative to the IDM follower driving the same training episodes in lockstep,
    :class:`PairedFollower`; ``relative_reward``: with the paired follower, trained on the reward less the
    follower's reward of the same step, ``SpeedConstraint``'s ``relative``;
    roadload.experiments.rl.traffic_objective). Saves
    ``ppo_traffic_seed<seed>.zip`` / ``.json`` and the learning curve (training episode returns) to ``out_dir``;
    returns the model, its path, wall and CPU seconds."""
    import torch
    from stable_baselines3 import PPO

    if timesteps < 1 or n_envs < 1:
        raise RLError(f"timesteps and n_envs must be >= 1, got {timesteps}, {n_envs}")
    if band is not None and speed_constraint is not None:
        raise RLError("speed constraint: give either a floor margin (--speed-constraint) or a band (--speed-band), "
                      "not both")
    if paired_reference and band is None and speed_constraint is None:
        raise RLError("paired reference: applies to a speed constraint (give a band, --speed-band, or a floor, "
                      "--speed-constraint)")
    if relative_reward and not paired_reference:
        raise RLError("relative reward: subtracts the paired follower's reward, give the paired reference too "
                      "(--paired-reference)")
    torch.set_num_threads(torch_threads)
    env_config = dict(env_config if env_config is not None else TRAFFIC_TRAIN_CONFIG)
    make_config(EcoTrafficConfig, env_config)  # a bad key fails before any training
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    native: gym.vector.VectorEnv = EcoTrafficVectorEnv(n_envs, config=env_config, autoreset_mode="same_step",
                                                       threads=threads)
    if speed_floor is not None and residual <= 0:
        raise RLError("speed floor: applies to a residual policy (give --residual > 0)")
    if residual > 0:
        native = ResidualActions(native, idm_policy(make_config(EcoTrafficConfig, env_config)), residual,
                                 speed_floor)
    params: dict[str, Any] = {**TRAFFIC_PPO, **(hyperparams or {})}
    params["n_steps"] = max(8, min(params["n_steps"], max(timesteps // n_envs, 8)))
    params["batch_size"] = min(params["batch_size"], params["n_steps"] * n_envs)
    c_start = time.process_time()
    objective = band if band is not None else speed_constraint
    constraint = None if objective is None else _speed_constraint(native, env_config, n_envs, params["n_steps"],
                                                                  objective, paired_reference,
                                                                  threads, relative_reward)
    trained: gym.vector.VectorEnv = native if constraint is None else constraint
    venv = SB3VecEnv(TripEnd(trained) if trip_end else trained)
    venv.seed(seed)
    model = silent_logger(PPO("MlpPolicy", venv, seed=seed, device="cpu", verbose=0, **params))
    t0, c0 = time.perf_counter(), c_start
    reported = [0]

    def report(steps: int) -> None:
        if progress is None or steps - reported[0] < report_every:
            return
        reported[0] = steps
        recent = [v for _, kind, v in callback.rows[-200:] if kind == "train"]
        progress(f"seed {seed}: {steps} steps, {time.perf_counter() - t0:.0f} s wall, "
                 f"{time.process_time() - c0:.0f} s CPU, mean return of the last {len(recent)} episodes "
                 f"{np.mean(recent) if recent else float('nan'):.2f}")

    callback = _curve_callback(env_config, eval_every=0, progress=report)
    try:
        model.learn(total_timesteps=timesteps, callback=callback)
    finally:
        venv.close()
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    stem = f"ppo_traffic_seed{seed}"
    _atomic_write_bytes(out_dir / f"{stem}.zip", lambda tmp: model.save(str(tmp)))
    meta = {"algo": "ppo", "env": "EcoTraffic-v0", "timesteps": int(model.num_timesteps), "n_envs": n_envs,
            "seed": seed, "env_config": env_config, "hyperparams": params, "wall_seconds": wall,
            "cpu_seconds": cpu, "threads": threads, "residual_scale": residual, "speed_floor": speed_floor,
            "trip_end_terminal": trip_end,
            "speed_constraint": None if constraint is None else {
                "margin": speed_constraint if band is None else band.lower,
                "upper": None if band is None else band.upper, "reference_speed_mps": constraint.reference,
                "paired": paired_reference, "relative_reward": relative_reward, "k_p": constraint.k_p,
                "k_i": constraint.k_i,
                "integral_max": None if band is None else band.integral_max,
                "history": [{"mean_speed_mps": v, "reference_mps": ref, "multiplier": lam}
                            for v, ref, lam in constraint.history]}}
    _atomic_write_bytes(out_dir / f"{stem}.json", lambda tmp: tmp.write_text(json.dumps(meta, indent=1, default=str)))
    curve = pd.DataFrame([(t, v) for t, kind, v in callback.rows if kind == "train"],
                         columns=["timesteps", "episode_return"])
    write_csv(out_dir / f"{stem}_curve.csv", curve)
    return {"model": model, "path": out_dir / f"{stem}.zip", "wall_seconds": wall, "cpu_seconds": cpu,
            "timesteps": int(model.num_timesteps), "meta": meta, "curve": curve}


def _speed_constraint(env: gym.vector.VectorEnv, env_config: dict[str, Any], n_envs: int, window: int,
                      objective: float | SpeedBand, paired: bool = False, threads: int = 1,
                      relative: bool = False) -> SpeedConstraint:
    """The constraint wrapper on ``env`` (a floor margin or a band): the reference is the IDM follower's mean speed
    on training episodes of the same configuration (its CPU time counts as training time); with ``paired`` the
    follower's on the same training episodes, driven in lockstep (its CPU time counts too)."""
    cfg = make_config(EcoTrafficConfig, env_config)
    v_ref = reference_speed(idm_policy(cfg), env_config, n_envs)
    price = cfg.reward.scale * cfg.reward.progress
    step_time = 1.0 / cfg.policy_frequency
    follower = PairedFollower(EcoTrafficVectorEnv(n_envs, config=env_config, autoreset_mode="same_step",
                                                  threads=threads), idm_policy(cfg), step_time) if paired else None
    if isinstance(objective, SpeedBand):
        return SpeedConstraint.band(env, v_ref, price, step_time, window, objective, follower, relative)
    return SpeedConstraint(env, v_ref, price, step_time, window, objective, follower=follower, relative=relative)


def load_traffic_policy(path: Path):
    from stable_baselines3 import PPO

    path = Path(path)
    if not path.is_file():
        raise RLError(f"policy file not found: {path}")
    return PPO.load(str(path), device="cpu")


def run_traffic_experiment(seeds: tuple[int, ...], timesteps: int, out_dir: Path, episodes: int = 50,
                           transfer_episodes: int = 20, n_envs: int = 32, env_config: dict[str, Any] | None = None,
                           threads: int = 1, evaluate_only: bool = False,
                           progress: Callable[[str], None] | None = None,
                           train_config: dict[str, Any] | None = None,
                           hyperparams: dict[str, Any] | None = None, residual: float = 0.0,
                           speed_floor: float | None = None, speed_constraint: float | None = None,
                           trip_end: bool = False, band: SpeedBand | None = None,
                           paired_reference: bool = False, relative_reward: bool = False) -> dict[str, Any]:
    """Train one PPO per seed (or load them with ``evaluate_only``), evaluate each with the IDM follower on
    ``episodes`` held-out native episodes and ``transfer_episodes`` on highway-env; write episodes.csv,
    summary.csv, intervals.csv and the learning curves to ``out_dir``. ``env_config`` is the evaluation's (and
    training's) configuration; ``train_config`` overrides fields for training only (e.g. the shield off in
    training, on when deployed)."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    env_config = {**TRAFFIC_TRAIN_CONFIG, **(env_config or {})}
    cfg = make_config(EcoTrafficConfig, env_config)
    trained_on = {**env_config, **(train_config or {})}
    make_config(EcoTrafficConfig, trained_on)
    models, times, scales, floors = {}, {}, {}, {}
    for s in seeds:
        if evaluate_only:
            models[s] = load_traffic_policy(out_dir / f"ppo_traffic_seed{s}.zip")
            meta = json.loads((out_dir / f"ppo_traffic_seed{s}.json").read_text())
            times[s] = (meta["wall_seconds"], meta["cpu_seconds"], meta["timesteps"])
            scales[s] = float(meta.get("residual_scale", 0.0))
            floors[s] = meta.get("speed_floor")
        else:
            res = train_traffic(timesteps, out_dir, s, n_envs, trained_on, threads, hyperparams=hyperparams,
                                progress=progress, residual=residual, speed_floor=speed_floor,
                                speed_constraint=speed_constraint, trip_end=trip_end, band=band,
                                paired_reference=paired_reference, relative_reward=relative_reward)
            models[s] = res["model"]
            times[s] = (res["wall_seconds"], res["cpu_seconds"], res["timesteps"])
            scales[s] = residual
            floors[s] = speed_floor
        if progress:
            progress(f"seed {s}: {times[s][2]} steps, {times[s][0]:.0f} s wall, {times[s][1]:.0f} s CPU")
    # the IDM follower on the same configuration (its shield too) and without the shield
    unshielded = {**env_config, "shield": {"enabled": False}}
    tables = []
    for backend, n_ep in (("native", episodes), ("highway-env", transfer_episodes)):
        if n_ep < 1:
            continue
        pols = {f"PPO seed {s}": residual_policy(m, idm_policy(cfg), scales[s], floors[s]) if scales[s] > 0
                else sb3_predict(m) for s, m in models.items()}
        pols["IDM follower"] = idm_policy(cfg)
        tables.append(evaluate_traffic(pols, env_config, n_ep, backend, progress))
        tables.append(evaluate_traffic({"IDM follower (no shield)": idm_policy(cfg)}, unshielded, n_ep, backend,
                                       progress))
    table = pd.concat(tables, ignore_index=True)
    summary = summarise_traffic(table)
    ppo = summary[summary.policy.str.startswith("PPO")]
    intervals = seed_intervals(ppo) if len(ppo) else pd.DataFrame()
    paired = paired_differences(table)
    paired_ppo = paired[paired.policy.str.startswith("PPO")] if len(paired) else paired
    paired_intervals = seed_intervals(paired_ppo, PAIRED_COLUMNS) if len(paired_ppo) else pd.DataFrame()
    write_csv(out_dir / "episodes.csv", table)
    write_csv(out_dir / "summary.csv", summary)
    write_csv(out_dir / "intervals.csv", intervals)
    write_csv(out_dir / "paired.csv", paired)
    write_csv(out_dir / "paired_intervals.csv", paired_intervals)
    (out_dir / "training_times.json").write_text(json.dumps(
        {str(s): {"wall_seconds": w, "cpu_seconds": c, "timesteps": n} for s, (w, c, n) in times.items()}, indent=1))
    return {"table": table, "summary": summary, "intervals": intervals, "paired": paired,
            "paired_intervals": paired_intervals, "times": times, "out_dir": out_dir}


def main(argv: list[str] | None = None) -> None:
    """Train, evaluate and print the tables (``scripts/train_traffic.py``; module docstring)."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seeds", default="0,1,2", help="training seeds, comma-separated")
    ap.add_argument("--timesteps", type=int, default=2_000_000, help="env steps per seed (0.1 s of driving each)")
    ap.add_argument("--n-envs", type=int, default=32, help="sub-envs of the native vector env")
    ap.add_argument("--threads", type=int, default=1, help="numba threads of the vector env")
    ap.add_argument("--episodes", type=int, default=50, help="held-out episodes on the native backend")
    ap.add_argument("--transfer-episodes", type=int, default=20, help="held-out episodes on highway-env (0: none)")
    ap.add_argument("--config", default=None, help="EcoTraffic-v0 config as JSON text over the default (shield on, "
                                                         "spawn outside its envelope)")
    ap.add_argument("--train-config", default=None, help="fields overriding --config in training only, JSON text "
                                                         "(e.g. '{\"shield\": {\"enabled\": false}}')")
    ap.add_argument("--hyperparams", default=None, help="PPO settings overriding TRAFFIC_PPO, JSON text")
    ap.add_argument("--residual", type=float, default=0.0, help="> 0: PPO learns a correction of this scale [command "
                                                                "units] on the IDM follower (0: the command itself)")
    ap.add_argument("--speed-floor", type=float, default=None,
                    help="with --residual: the command stays at most this far [command units] below the IDM "
                         "follower's, so PPO cannot fall back behind the follower by coasting")
    ap.add_argument("--speed-constraint", type=float, default=None, metavar="MARGIN",
                    help="train on the reward with a Lagrange multiplier that holds the mean speed at (1 + MARGIN) x "
                         "the IDM follower's (e.g. 0.005; roadload.experiments.rl.traffic_objective)")
    ap.add_argument("--speed-band", default=None, metavar="JSON",
                    help="train on the reward with two Lagrange multipliers holding the mean speed between (1 + lower) "
                         "and (1 + upper) x the IDM follower's, JSON text of SpeedBand (e.g. '{\"lower\": 0.001, "
                         "\"upper\": 0.004}', gains k_p, k_i; roadload.experiments.rl.traffic_objective)")
    ap.add_argument("--paired-reference", action="store_true",
                    help="with --speed-band or --speed-constraint: hold the mean speed relative to the IDM follower "
                         "driving the same training episodes in lockstep (paired per episode) instead of its mean "
                         "speed on separate reference episodes")
    ap.add_argument("--relative-reward", action="store_true",
                    help="with --paired-reference: train on the reward less the paired IDM follower's reward of the "
                         "same step (independent of the policy's actions: the same optimum, the traffic's share of "
                         "the return's scatter cancelled; roadload.experiments.rl.traffic_objective)")
    ap.add_argument("--trip-end", action="store_true",
                    help="train with the time limit as the trip's end (terminal, no bootstrap of the value beyond it)")
    ap.add_argument("--out", type=Path, default=Path("out/rl_traffic"))
    ap.add_argument("--evaluate-only", action="store_true", help="load the policies saved in --out")
    ap.add_argument("--quick", action="store_true", help="tiny run for CI")
    a = ap.parse_args(argv)
    try:
        seeds = tuple(int(s) for s in a.seeds.split(",") if s.strip())
    except ValueError:
        ap.error(f"--seeds: expected comma-separated integers, got {a.seeds!r}")
    config = json_object_option(ap, a.config)
    if a.quick:
        seeds, a.timesteps, a.n_envs, a.episodes, a.transfer_episodes = (0,), 4096, 8, 2, 1
        config = {"duration": 5.0, "vehicles_count": 10, **config}
        if a.out == Path("out/rl_traffic"):
            a.out = Path(tempfile.mkdtemp(prefix="roadload-rl-traffic-"))
    if not seeds or a.timesteps < 1 or a.episodes < 1:
        ap.error("--seeds, --timesteps and --episodes must be given and >= 1")
    try:
        band = None if a.speed_band is None else speed_band(a.speed_band)
    except RLError as exc:
        ap.error(f"--speed-band: {exc}")
    if band is not None and a.speed_constraint is not None:
        ap.error("--speed-constraint and --speed-band: give one (a floor or a band), not both")
    if a.paired_reference and band is None and a.speed_constraint is None and not a.evaluate_only:
        ap.error("--paired-reference: applies to a speed constraint, give --speed-band or --speed-constraint")
    if a.relative_reward and not a.paired_reference and not a.evaluate_only:
        ap.error("--relative-reward: subtracts the paired follower's reward, give --paired-reference too")
    res = run_traffic_experiment(seeds, a.timesteps, a.out, a.episodes, a.transfer_episodes, a.n_envs, config,
                                 a.threads, a.evaluate_only, progress=lambda m: print(m, flush=True),
                                 train_config=json.loads(a.train_config) if a.train_config else None,
                                 hyperparams=json.loads(a.hyperparams) if a.hyperparams else None,
                                 residual=a.residual, speed_floor=a.speed_floor,
                                 speed_constraint=a.speed_constraint, trip_end=a.trip_end, band=band,
                                 paired_reference=a.paired_reference, relative_reward=a.relative_reward)
    print(markdown_table(res["summary"], floatfmt=".4g"))
    for key in ("intervals", "paired", "paired_intervals"):
        if len(res[key]):
            print(markdown_table(res[key], floatfmt=".4g"))
    print(f"tables and policies in {res['out_dir']}")
