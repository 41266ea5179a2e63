"""Training with stable-baselines3 (PPO / SAC), learning curves and speed-profile figures."""

from __future__ import annotations

import json
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable

import numpy as np
import pandas as pd

from roadload.gym.config import EcoDriveConfig, make_config
from roadload.fileio import save_figure

from .common import ALGO_DEFAULTS, RLError, VALIDATION_SEEDS, _algo_class, _atomic_write_bytes, _route, make_vec_env
from .rollouts import run_policy, sb3_policy


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
                 torch_threads: int = 1, threads: int = 1) -> TrainResult:
    """Train PPO or SAC on EcoDrive-v0 with ``n_envs`` vectorised envs (``threads`` numba threads of the native
    vector env); saves ``<algo>_ecodrive.zip`` (atomic) and returns the learning curve (training episode returns
    + validation returns every ``eval_every``)."""
    import torch

    if timesteps < 1:
        raise RLError(f"timesteps must be >= 1, got {timesteps}")
    cls = _algo_class(algo)
    algo = algo.lower()
    torch.set_num_threads(torch_threads)
    env_config = dict(env_config or {})
    if threads != 1 and vec != "native":
        raise RLError(f"threads: only the native vector env (vec='native') splits its vehicles over threads, got "
                      f"threads={threads} with vec={vec!r}")
    venv = make_vec_env(n_envs, seed, env_config, vec=vec, threads=threads)
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
            "threads": threads,
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


def plot_learning_curves(results: list[TrainResult], path: Path) -> Path | None:
    """PNG: training episode returns (rolling mean over 20 episodes) and validation returns vs timesteps; None (and
    no file) when no run has a point to plot -- a short run without a finished episode or validation."""
    if not any(len(res.curve) for res in results):
        return None
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(8, 4.5))
    for res in results:
        c = res.curve
        tr = c[c.kind == "train"]
        if len(tr):
            line, = ax.plot(tr.timesteps, tr.value.rolling(20, min_periods=1).mean(), "-" if len(tr) > 1 else "o",
                            lw=1.2, alpha=0.8, label=f"{res.algo.upper()} training episodes (rolling mean 20)")
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
    save_figure(fig, path, dpi=120, format="png")
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
    save_figure(fig, path, dpi=120, format="png")
    return Path(path)
