"""Reinforcement learning on ``roadload/EcoDrive-v0``: training (PPO / SAC from stable-baselines3 on vectorised
envs), evaluation on held-out roads against cruise control and the MPC (the controllers' metrics), and the
environment speed benchmark. CLI: ``roadload train`` and ``roadload benchmark gym``; scripts/train_rl.py and
scripts/bench_gym.py call the same functions.

Road seeds: training episodes draw roads from ``road_seed_range`` (default [0, 10000)); the learning-curve
evaluation uses VALIDATION_SEEDS and the final table HELD_OUT_SEEDS, both outside the training range.
"""

from __future__ import annotations

import json
import math
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable

import numpy as np
import pandas as pd
import typer

from roadload.fileio import atomic_path
from roadload.controllers.closed_loop import run_metrics
from roadload.controllers.drive import DriveSettings, drive
from roadload.gym.config import EcoDriveConfig, make_config
from roadload.gym.ecodrive import EcoDriveEnv, cut_profile
from roadload.road_profiles import RoadProfile, load_profile

ENV_ID = "roadload:roadload/EcoDrive-v0"
VALIDATION_SEEDS = (40_000, 40_001, 40_002)
HELD_OUT_SEEDS = (50_000, 50_001, 50_002, 50_003, 50_004)

ALGO_DEFAULTS: dict[str, dict[str, Any]] = {
    # gamma 0.999: a horizon of ~1000 control steps (100 s), about one episode, so that the (undiscounted)
    # progress credit of the reward adds nearly the same constant to every arrival and biases speed little
    # log_std_init -1: initial exploration noise std 0.37 instead of 1 (full-range random forces mostly buy jerk,
    # speeding and regen-braking rewards that teach the agent to stand still)
    "ppo": dict(n_steps=1024, batch_size=256, n_epochs=10, learning_rate=3e-4, gamma=0.999, gae_lambda=0.95,
                clip_range=0.2, ent_coef=0.0, policy_kwargs={"log_std_init": -1.0}),
    # 64x64 networks (as PPO's): SB3's default 256x256 runs ~4x slower per gradient step on one CPU thread
    "sac": dict(learning_rate=3e-4, buffer_size=200_000, learning_starts=5_000, batch_size=256, gamma=0.999,
                tau=0.005, train_freq=1, gradient_steps=1, policy_kwargs={"net_arch": [64, 64]}),
}


class RLError(ValueError):
    """Bad training / evaluation input (unknown algorithm, bad counts, unreadable policy file)."""


# --------------------------------------------------------------------------------------------- helpers
def _atomic_write_bytes(path: Path, writer: Callable[[Path], object]) -> None:
    with atomic_path(path) as tmp:
        writer(tmp)


def _route(cfg: EcoDriveConfig, road_seed: int) -> RoadProfile:
    """The environment's route: the first ``cfg.route_length`` m of road profile ``cfg.road``."""
    profile = load_profile(cfg.road, seed=int(road_seed))
    if not isinstance(profile, RoadProfile):
        raise RLError(f"road: {cfg.road!r} is a drive cycle, not a road profile")
    return cut_profile(profile, cfg.route_length)


def _algo_class(algo: str):
    from stable_baselines3 import PPO, SAC

    classes = {"ppo": PPO, "sac": SAC}
    if algo.lower() not in classes:
        raise RLError(f"unknown algorithm {algo!r}; choose from {sorted(classes)}")
    return classes[algo.lower()]


VEC_MODES = ("native", "dummy", "subproc")


def make_vec_env(n_envs: int, seed: int, env_config: dict[str, Any] | None = None, vec: str = "subproc",
                 start_method: str | None = None, threads: int = 1):
    """n_envs EcoDrive-v0 copies for stable-baselines3: 'native' = the batched vector env
    (roadload.gym.vector, one compiled call per step, ``threads`` numba threads) behind the SB3 adapter
    (roadload.gym.sb3; observation 'state' only), or Monitor-wrapped copies in a DummyVecEnv ('dummy') or
    SubprocVecEnv ('subproc'; the workers resolve the id through the "roadload:" prefix, so spawn / forkserver
    work)."""
    from stable_baselines3.common.env_util import make_vec_env as sb3_make_vec_env
    from stable_baselines3.common.vec_env import DummyVecEnv, SubprocVecEnv

    if n_envs < 1:
        raise RLError(f"n_envs must be >= 1, got {n_envs}")
    if vec not in VEC_MODES:
        raise RLError(f"vec must be one of {VEC_MODES}, got {vec!r}")
    if vec == "native":
        from roadload.gym.sb3 import SB3VecEnv  # needs stable-baselines3 (optional dependency), hence here
        from roadload.gym.vector import EcoDriveVectorEnv

        venv = SB3VecEnv(EcoDriveVectorEnv(n_envs, config=dict(env_config or {}), autoreset_mode="same_step",
                                           threads=threads))
        venv.seed(seed)
        return venv
    cls = SubprocVecEnv if vec == "subproc" else DummyVecEnv
    kwargs = {"start_method": start_method} if (vec == "subproc" and start_method) else None
    return sb3_make_vec_env(ENV_ID, n_envs=n_envs, seed=seed, env_kwargs={"config": dict(env_config or {})},
                            vec_env_cls=cls, vec_env_kwargs=kwargs)


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
    return {k: m.get(k) for k in ("arrived", "energy_kWh", "trip_time", "speed_violations", "violation_time",
                                  "max_excess_kmh", "rms_jerk", "max_abs_accel", "distance", "mean_speed_kmh")}


# --------------------------------------------------------------------------------------------- training
@dataclass
class TrainResult:
    algo: str
    model_path: Path
    curve: pd.DataFrame  # columns: timesteps, kind ('train' episode return | 'validation' mean return), value
    seconds: float
    timesteps: int
    extra: dict[str, Any] = field(default_factory=dict)


def _curve_callback(env_config: dict[str, Any], eval_every: int, progress: Callable[[int], None] | None):
    from stable_baselines3.common.callbacks import BaseCallback

    class CurveCallback(BaseCallback):
        def __init__(self) -> None:
            super().__init__()
            self.rows: list[tuple[int, str, float]] = []
            self._next_eval = eval_every

        def _validate(self) -> None:
            rets = [run_policy(sb3_policy(self.model), env_config, s)[0]["episode_return"] for s in VALIDATION_SEEDS]
            self.rows.append((self.num_timesteps, "validation", float(np.mean(rets))))

        def _on_training_start(self) -> None:
            if eval_every > 0:
                self._validate()

        def _on_step(self) -> bool:
            for info in self.locals.get("infos", []):
                ep = info.get("episode")
                if ep is not None:
                    self.rows.append((self.num_timesteps, "train", float(ep["r"])))
            if eval_every > 0 and self.num_timesteps >= self._next_eval:
                self._next_eval += eval_every
                self._validate()
            if progress is not None:
                progress(self.num_timesteps)
            return True

    return CurveCallback()


def train_policy(algo: str, timesteps: int, out_dir: Path, n_envs: int = 2, seed: int = 0,
                 env_config: dict[str, Any] | None = None, vec: str = "subproc", eval_every: int = 0,
                 hyperparams: dict[str, Any] | None = None, progress: Callable[[int], None] | None = None,
                 torch_threads: int = 1) -> TrainResult:
    """Train PPO or SAC on EcoDrive-v0 with ``n_envs`` vectorised envs; saves ``<algo>_ecodrive.zip`` (atomic)
    and returns the learning curve (training episode returns + validation returns every ``eval_every``)."""
    import torch

    if timesteps < 1:
        raise RLError(f"timesteps must be >= 1, got {timesteps}")
    cls = _algo_class(algo)
    algo = algo.lower()
    torch.set_num_threads(torch_threads)
    env_config = dict(env_config or {})
    venv = make_vec_env(n_envs, seed, env_config, vec=vec)
    params = {**ALGO_DEFAULTS[algo], **(hyperparams or {})}
    if algo == "ppo" and vec == "native" and "n_steps" not in (hyperparams or {}):
        # many batched envs: keep a rollout of ~4096 samples (as 2 envs x 2048) rather than n_envs x 1024
        params["n_steps"] = max(64, 4096 // n_envs)
    if algo == "ppo":
        params["n_steps"] = max(16, min(params["n_steps"], max(timesteps // n_envs, 16)))
        params["batch_size"] = min(params["batch_size"], params["n_steps"] * n_envs)
    model = cls("MlpPolicy", venv, seed=seed, device="cpu", verbose=0, **params)
    callback = _curve_callback(env_config, eval_every, progress)
    t0 = time.perf_counter()
    try:
        model.learn(total_timesteps=timesteps, callback=callback)
    finally:
        venv.close()
    seconds = time.perf_counter() - t0
    path = Path(out_dir) / f"{algo}_ecodrive.zip"
    _atomic_write_bytes(path, lambda tmp: model.save(str(tmp)))
    curve = pd.DataFrame(callback.rows, columns=["timesteps", "kind", "value"])
    meta = {"algo": algo, "timesteps": int(model.num_timesteps), "n_envs": n_envs, "seed": seed, "vec": vec,
            "env_config": env_config, "hyperparams": params, "seconds": seconds}
    _atomic_write_bytes(Path(out_dir) / f"{algo}_ecodrive.json",
                        lambda tmp: tmp.write_text(json.dumps(meta, indent=1, default=str)))
    return TrainResult(algo, path, curve, seconds, int(model.num_timesteps), {"model": model})


def load_policy(path: Path):
    """A saved SB3 policy (algorithm from the file name prefix ppo_/sac_)."""
    path = Path(path)
    if not path.is_file():
        raise RLError(f"policy file {path} does not exist")
    algo = path.name.split("_")[0].lower()
    return _algo_class(algo).load(str(path), device="cpu")


def plot_learning_curves(results: list[TrainResult], path: Path) -> Path:
    """PNG: training episode returns (rolling mean over 20 episodes) and validation returns vs timesteps."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(8, 4.5))
    for res in results:
        c = res.curve
        tr = c[c.kind == "train"]
        if len(tr):
            line, = ax.plot(tr.timesteps, tr.value.rolling(20, min_periods=1).mean(), lw=1.2, alpha=0.8,
                            label=f"{res.algo.upper()} training episodes (rolling mean 20)")
            color = line.get_color()
        else:
            color = None
        va = c[c.kind == "validation"]
        if len(va):
            ax.plot(va.timesteps, va.value, "o--", color=color, ms=4,
                    label=f"{res.algo.upper()} validation roads {VALIDATION_SEEDS[0]}..{VALIDATION_SEEDS[-1]}")
    ax.set_xlabel("environment steps (0.1 s each)")
    ax.set_ylabel("episode return")
    ax.set_title("EcoDrive-v0 learning curves")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    _atomic_write_bytes(Path(path), lambda tmp: fig.savefig(tmp, dpi=120, format="png"))
    plt.close(fig)
    return Path(path)


def plot_speed_profiles(logs: dict[str, pd.DataFrame], env_config: dict[str, Any], road_seed: int,
                        path: Path) -> Path:
    """PNG: speed over distance of every controller on one road, with the speed limit and the elevation."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt


    cfg = make_config(EcoDriveConfig, env_config)
    road = _route(cfg, road_seed)
    fig, (ax, ax2) = plt.subplots(2, 1, figsize=(9, 6), sharex=True, gridspec_kw={"height_ratios": [3, 1]})
    ax.plot(road.distance, road.speed_limit * 3.6, "k--", lw=1, label="speed limit")
    for name, log in logs.items():
        if name == "random":
            continue
        ax.plot(log["s"], log["v"] * 3.6, lw=1.3, label=name)
    ax.set_ylabel("speed [km/h]")
    ax.set_title(f"{cfg.vehicle} on {cfg.road} road {road_seed} (held out), first {road.length:.0f} m")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    ax2.plot(road.distance, road.elevation(), color="0.4")
    ax2.set_ylabel("elevation [m]")
    ax2.set_xlabel("distance [m]")
    ax2.grid(alpha=0.3)
    fig.tight_layout()
    _atomic_write_bytes(Path(path), lambda tmp: fig.savefig(tmp, dpi=120, format="png"))
    plt.close(fig)
    return Path(path)


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


# --------------------------------------------------------------------------------------------- speed benchmark
def _steps_per_second(step: Callable[[], None], seconds: float) -> tuple[float, int]:
    n = 0
    t0 = time.perf_counter()
    while True:
        step()
        n += 1
        if n % 64 == 0 and time.perf_counter() - t0 >= seconds:
            break
    return n / (time.perf_counter() - t0), n


def bench_single(env_id: str, seconds: float = 5.0, seed: int = 0, **kwargs) -> dict[str, Any]:
    """Single-process steps/s of ``env_id`` under uniformly random actions (resets included)."""
    import gymnasium as gym

    env = gym.make(env_id, **kwargs)
    env.reset(seed=seed)
    env.action_space.seed(seed)
    for _ in range(50):  # warm-up (numba cache load, first allocations)
        _, _, te, tr, _ = env.step(env.action_space.sample())
        if te or tr:
            env.reset()

    episodes = [0]

    def step() -> None:
        _, _, te, tr, _ = env.step(env.action_space.sample())
        if te or tr:
            env.reset()
            episodes[0] += 1

    rate, n = _steps_per_second(step, seconds)
    env.close()
    return {"env": env_id, "mode": "single process", "steps_per_s": rate, "steps": n, "episodes": episodes[0]}


def bench_vectorised(n_envs: int = 2, seconds: float = 5.0, vec: str = "subproc",
                     env_config: dict[str, Any] | None = None) -> dict[str, Any]:
    """Steps/s (summed over envs) of EcoDrive-v0 in an SB3 vectorised env with random actions."""
    venv = make_vec_env(n_envs, 0, env_config, vec=vec)
    try:
        venv.reset()
        rng = np.random.default_rng(0)
        acts = rng.uniform(-1, 1, (4096, n_envs, 1)).astype(np.float32)
        k = [0]

        def step() -> None:
            venv.step(acts[k[0] % 4096])
            k[0] += 1

        for _ in range(50):
            step()
        rate, n = _steps_per_second(step, seconds)
    finally:
        venv.close()
    return {"env": "roadload/EcoDrive-v0", "mode": f"{vec} x{n_envs}", "steps_per_s": rate * n_envs,
            "steps": n * n_envs, "episodes": None}


def _rates(step: Callable[[], None], seconds: float) -> tuple[float, float, int]:
    """(calls per wall second, calls per CPU second of this process, calls): CPU seconds make runs on a machine
    shared with other jobs comparable (wall rates there measure the share the scheduler gave us)."""
    n = 0
    t0, c0 = time.perf_counter(), time.process_time()
    while True:
        step()
        n += 1
        if n % 8 == 0 and time.perf_counter() - t0 >= seconds:
            break
    return n / (time.perf_counter() - t0), n / max(time.process_time() - c0, 1e-9), n


def bench_native(n_envs: int = 256, seconds: float = 5.0, threads: int = 1, bare: bool = False,
                 env_config: dict[str, Any] | None = None) -> dict[str, Any]:
    """Env steps/s (summed over sub-envs, wall and per CPU second) of the native vector env under random actions
    in [-1, 1] (autoresets included), or with ``bare`` only its batched physics (no reward / observation / info /
    autoreset): the reference the env step is compared with."""
    from roadload.gym.vector import EcoDriveVectorEnv

    venv = EcoDriveVectorEnv(n_envs, config=dict(env_config or {}), threads=threads)
    venv.reset(seed=0)
    acts = np.random.default_rng(0).uniform(-1, 1, (256, n_envs, 1)).astype(np.float32)
    k = [0]
    fn = venv.bare_physics_step if bare else venv.step

    def step() -> None:
        fn(acts[k[0] % 256])
        k[0] += 1

    for _ in range(3):
        step()
    wall, cpu, n = _rates(step, seconds)
    mode = f"{'bare batched physics' if bare else 'native vector env'} x{n_envs}, {threads} thread(s)"
    return {"env": "roadload/EcoDrive-v0", "mode": mode, "steps_per_s": wall * n_envs,
            "steps_per_cpu_s": cpu * n_envs, "steps": n * n_envs}


def run_native_benchmark(seconds: float = 5.0, n_envs: int = 256, n_dummy: int = 16,
                         progress: Callable[[str], None] | None = None) -> pd.DataFrame:
    """The batched-env table (same run): single env, SB3 DummyVecEnv x n_dummy, the native vector env x n_envs
    (1 and 2 threads) and its bare batched physics, as wall and per-CPU-second rates."""
    rows = []

    def add(row: dict[str, Any]) -> None:
        rows.append(row)
        if progress:
            progress(row["mode"])

    import gymnasium as gym

    env = gym.make("roadload/EcoDrive-v0")
    env.reset(seed=0)
    env.action_space.seed(0)

    def single() -> None:
        _, _, te, tr, _ = env.step(env.action_space.sample())
        if te or tr:
            env.reset()

    wall, cpu, n = _rates(single, seconds)
    add({"env": "roadload/EcoDrive-v0", "mode": "single process", "steps_per_s": wall, "steps_per_cpu_s": cpu,
         "steps": n})
    venv = make_vec_env(n_dummy, 0, None, vec="dummy")
    try:
        venv.reset()
        acts = np.random.default_rng(0).uniform(-1, 1, (256, n_dummy, 1)).astype(np.float32)
        k = [0]

        def dummy() -> None:
            venv.step(acts[k[0] % 256])
            k[0] += 1

        wall, cpu, n = _rates(dummy, seconds)
    finally:
        venv.close()
    add({"env": "roadload/EcoDrive-v0", "mode": f"dummy x{n_dummy}", "steps_per_s": wall * n_dummy,
         "steps_per_cpu_s": cpu * n_dummy, "steps": n * n_dummy})
    for threads in (1, 2):
        add(bench_native(n_envs, seconds, threads))
    add(bench_native(n_envs, seconds, 1, bare=True))
    return pd.DataFrame(rows)


def run_benchmark(seconds: float = 5.0, n_envs: int = 2, include_highway: bool = True,
                  progress: Callable[[str], None] | None = None) -> pd.DataFrame:
    """The speed table: EcoDrive-v0 (state and can observations) single process, vectorised (dummy and subproc
    x n_envs), EcoHighway-v0 and highway-env's highway-fast-v0 measured in the same run."""
    rows = []

    def note(msg):
        if progress:
            progress(msg)

    rows.append(bench_single("roadload/EcoDrive-v0", seconds))
    note("EcoDrive-v0 single")
    rows.append({**bench_single("roadload/EcoDrive-v0", seconds, observation="can"),
                 "env": "roadload/EcoDrive-v0 (observation=can)"})
    note("EcoDrive-v0 can")
    rows.append(bench_vectorised(n_envs, seconds, "dummy"))
    note("EcoDrive-v0 dummy")
    rows.append(bench_vectorised(n_envs, seconds, "subproc"))
    note("EcoDrive-v0 subproc")
    if include_highway:
        import highway_env
        import gymnasium as gym

        gym.register_envs(highway_env)
        rows.append(bench_single("roadload/EcoHighway-v0", seconds))
        note("EcoHighway-v0")
        rows.append(bench_single("highway-fast-v0", seconds))
        note("highway-fast-v0")
    table = pd.DataFrame(rows)
    step_time = {"roadload/EcoDrive-v0": 0.1, "roadload/EcoDrive-v0 (observation=can)": 0.1,
                 "roadload/EcoHighway-v0": 0.5, "highway-fast-v0": 1.0}
    table["simulated_s_per_step"] = table["env"].map(step_time)
    table["simulated_s_per_wall_s"] = table["steps_per_s"] * table["simulated_s_per_step"]
    return table


def speed_ratio(table: pd.DataFrame) -> float:
    """EcoDrive-v0 single-process steps/s divided by highway-fast-v0's (same run)."""
    eco = table[(table.env == "roadload/EcoDrive-v0") & (table["mode"] == "single process")].steps_per_s
    hw = table[table.env == "highway-fast-v0"].steps_per_s
    if eco.empty or hw.empty:
        return float("nan")
    return float(eco.iloc[0] / hw.iloc[0])


# --------------------------------------------------------------------------------------------- CLI
def _fail(msg: str) -> None:
    typer.secho(f"error: {msg}", fg=typer.colors.RED, err=True)
    raise typer.Exit(code=2)


def _parse_config(text: str | None) -> dict[str, Any]:
    if not text:
        return {}
    p = Path(text)
    try:
        raw = p.read_text() if p.suffix == ".json" and p.is_file() else text
        cfg = json.loads(raw)
    except (OSError, json.JSONDecodeError) as exc:
        raise RLError(f"--config: not a JSON object or JSON file ({exc})") from None
    if not isinstance(cfg, dict):
        raise RLError("--config: must be a JSON object")

    make_config(EcoDriveConfig, cfg)  # validate now: a bad key fails before any training
    return cfg


def print_table(console, table: pd.DataFrame, title: str, floatfmt: str = "{:.3g}") -> None:
    from rich.table import Table

    t = Table(title=title)
    for col in table.columns:
        t.add_column(str(col))
    for _, row in table.iterrows():
        t.add_row(*[floatfmt.format(v) if isinstance(v, (float, np.floating)) else str(v) for v in row])
    console.print(t)


def load_trained(algo: str, out_dir: Path) -> TrainResult:
    """A policy saved by train_policy in ``out_dir`` with its learning curve CSV and metadata."""
    out_dir = Path(out_dir)
    model = load_policy(out_dir / f"{algo}_ecodrive.zip")
    curve_path = out_dir / f"{algo}_learning_curve.csv"
    curve = pd.read_csv(curve_path) if curve_path.is_file() else pd.DataFrame(columns=["timesteps", "kind", "value"])
    meta_path = out_dir / f"{algo}_ecodrive.json"
    meta = json.loads(meta_path.read_text()) if meta_path.is_file() else {}
    return TrainResult(algo, out_dir / f"{algo}_ecodrive.zip", curve, float(meta.get("seconds", float("nan"))),
                       int(meta.get("timesteps", model.num_timesteps)), {"model": model, "meta": meta})


def train_and_evaluate(algos: list[str], timesteps: int, out_dir: Path, n_envs: int, seed: int,
                       env_config: dict[str, Any], vec: str, eval_every: int, road_seeds, console=None,
                       controllers: tuple[str, ...] = ("cruise", "mpc"), evaluate_only: bool = False,
                       skip_evaluation: bool = False) -> dict[str, Any]:
    """The whole workflow of ``roadload train`` / scripts/train_rl.py: train each algorithm (or, with
    ``evaluate_only``, load what an earlier run saved in ``out_dir``), write the learning curve PNG, evaluate on
    held-out roads with the baselines, write CSV tables; returns paths and tables."""
    from rich.console import Console
    from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn, TimeRemainingColumn

    console = console or Console()
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    results = []
    with Progress(TextColumn("{task.description}"), BarColumn(), TextColumn("{task.completed}/{task.total}"),
                  TimeElapsedColumn(), TimeRemainingColumn(), console=console) as bar:
        for algo in algos:
            if evaluate_only:
                res = load_trained(algo, out_dir)
                env_config = res.extra["meta"].get("env_config", env_config)
            else:
                task = bar.add_task(f"training {algo.upper()}", total=timesteps)
                res = train_policy(algo, timesteps, out_dir, n_envs=n_envs, seed=seed, env_config=env_config,
                                   vec=vec, eval_every=eval_every,
                                   progress=lambda n: bar.update(task, completed=n))
                curve = res.curve
                _atomic_write_bytes(out_dir / f"{algo}_learning_curve.csv", lambda tmp: curve.to_csv(tmp, index=False))
            results.append(res)
        curve_png = plot_learning_curves(results, out_dir / "learning_curve.png")
        if skip_evaluation:
            return {"results": results, "curve_png": curve_png, "table": None, "summary": None, "notes": [],
                    "table_path": None}
        n_eval = len(road_seeds) * (len(results) + 1 + len(controllers))
        task = bar.add_task("evaluating on held-out roads", total=n_eval)
        policies = {r.algo.upper(): sb3_policy(r.extra["model"]) for r in results}
        import gymnasium as gym

        space = gym.make("roadload/EcoDrive-v0", config=env_config).action_space
        policies["random"] = random_policy(space, seed)
        logs: dict[str, pd.DataFrame] = {}
        table, notes = evaluation_table(policies, env_config, road_seeds, controllers,
                                        progress=lambda _m: bar.advance(task), logs=logs)
        profiles_png = plot_speed_profiles(logs, env_config, road_seeds[0], out_dir / "speed_profiles.png")
    table_path = out_dir / "evaluation.csv"
    summary = summarise(table)
    _atomic_write_bytes(table_path, lambda tmp: table.to_csv(tmp, index=False))
    _atomic_write_bytes(out_dir / "evaluation_summary.csv", lambda tmp: summary.to_csv(tmp, index=False))
    return {"results": results, "curve_png": curve_png, "table": table, "summary": summary, "notes": notes,
            "table_path": table_path, "profiles_png": profiles_png}


def register(app: typer.Typer, benchmark_app: typer.Typer) -> None:
    @app.command("train")
    def train_cmd(
        algo: str = typer.Option("ppo,sac", help="algorithms, comma-separated: ppo, sac"),
        timesteps: int = typer.Option(200_000, help="environment steps per algorithm (0.1 s of driving each)"),
        n_envs: int = typer.Option(2, help="vectorised environments"),
        vec: str = typer.Option("native", help="'native' (batched vector env, observation 'state'), 'subproc' "
                                "(one process per env) or 'dummy' (in-process)"),
        seed: int = typer.Option(0, help="training seed"),
        config: str = typer.Option(None, help="EcoDrive-v0 config as JSON text or a .json file, e.g. "
                                   "'{\"vehicle\": \"gt_rwd\", \"road\": \"city\"}'"),
        eval_every: int = typer.Option(20_000, help="validation-road evaluation period [steps] (0 = off)"),
        held_out: int = typer.Option(len(HELD_OUT_SEEDS), help="number of held-out roads in the final table"),
        out: Path = typer.Option(Path("out/rl"), help="output folder (policies, learning_curve.png, CSV)"),
        baselines: str = typer.Option("cruise,mpc", help="controller baselines in the table: cruise (PI, abc model), "
                                      "mpc (oracle force model), mpc_online (online RRLM force model)"),
        evaluate_only: bool = typer.Option(False, help="no training: evaluate the policies saved in --out"),
        skip_evaluation: bool = typer.Option(False, help="train and plot only, no held-out evaluation"),
    ) -> None:
        """Train PPO / SAC on EcoDrive-v0, save the policies, and compare them on held-out roads with cruise
        control and the MPC (energy, time, violations)."""
        from rich.console import Console

        console = Console()
        try:
            algos = [a.strip().lower() for a in algo.split(",") if a.strip()]
            for a in algos:
                _algo_class(a)
            if held_out < 1:
                raise RLError("--held-out must be >= 1")
            env_config = _parse_config(config)
            seeds = tuple(HELD_OUT_SEEDS[0] + i for i in range(held_out))
            ctl = tuple(b.strip() for b in baselines.split(",") if b.strip())
            bad = [b for b in ctl if b not in CONTROLLER_BASELINES]
            if bad:
                raise RLError(f"--baselines: unknown {bad}; choose from {sorted(CONTROLLER_BASELINES)}")
            res = train_and_evaluate(algos, timesteps, out, n_envs, seed, env_config, vec, eval_every, seeds,
                                     console, controllers=ctl, evaluate_only=evaluate_only,
                                     skip_evaluation=skip_evaluation)
        except ValueError as exc:  # RLError, GymConfigError
            _fail(str(exc))
        for r in res["results"]:
            console.print(f"{r.algo.upper()}: {r.timesteps} steps in {r.seconds:.0f} s "
                          f"({r.timesteps / r.seconds:.0f} steps/s) -> {r.model_path}")
        if res["summary"] is not None:
            print_table(console, res["summary"], "held-out roads, mean per controller")
        for n in res["notes"]:
            console.print(f"[yellow]{n}")
        console.print(f"learning curve: {res['curve_png']}\nper-road table: {res['table_path']}")
        if res.get("profiles_png"):
            console.print(f"speed profiles on the first held-out road: {res['profiles_png']}")

    @benchmark_app.command("gym")
    def bench_cmd(
        seconds: float = typer.Option(5.0, help="measurement time per row [s]"),
        n_envs: int = typer.Option(2, help="vectorised environments"),
        highway: bool = typer.Option(True, help="also measure EcoHighway-v0 and highway-env's highway-fast-v0"),
    ) -> None:
        """Environment steps per second: EcoDrive-v0 single process and vectorised, EcoHighway-v0, and
        highway-env's highway-fast-v0 in the same run."""
        from rich.console import Console

        console = Console(width=max(150, Console().width))
        with console.status("measuring") as status:
            table = run_benchmark(seconds, n_envs, highway, progress=lambda m: status.update(f"done: {m}"))
        print_table(console, table.drop(columns=["episodes"]), "environment steps per second", "{:.1f}")
        ratio = speed_ratio(table)
        if math.isfinite(ratio):
            console.print(f"EcoDrive-v0 / highway-fast-v0 steps/s ratio: {ratio:.0f}x")
