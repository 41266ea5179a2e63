"""Training with stable-baselines3 (PPO / SAC), learning curves and speed-profile figures."""

from __future__ import annotations

import hashlib
import json
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable

import numpy as np
import pandas as pd

from roadload.gym.config import EcoDriveConfig, make_config
from roadload.fileio import save_figure

from .common import (ALGO_DEFAULTS, RLError, VALIDATION_SEEDS, _algo_class, _atomic_write_bytes, _route, make_vec_env,
                     silent_logger)
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


# --------------------------------------------------------------------------------------------- checkpoints
def _sha256(path: Path) -> str:
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


def checkpoint_paths(out_dir: Path, algo: str) -> dict[str, Path]:
    """The files of an unfinished training: the model (SB3 zip), SAC's replay buffer, and the JSON that holds the
    run's identity, the steps done, the learning-curve rows so far and the SHA-256 of the other two."""
    out_dir = Path(out_dir)
    return {"model": out_dir / f"{algo}_checkpoint.zip", "replay": out_dir / f"{algo}_checkpoint_replay.pkl",
            "state": out_dir / f"{algo}_checkpoint.json"}


def load_checkpoint(out_dir: Path, algo: str, identity: dict[str, Any]) -> tuple[dict[str, Any] | None, str]:
    """(state, '') of a valid checkpoint of this very run, else (None, why it is not used: missing, another run,
    or corrupt -- a corrupt checkpoint is never trusted)."""
    paths = checkpoint_paths(out_dir, algo)
    if not paths["state"].exists():
        return None, "no checkpoint"
    try:
        state = json.loads(paths["state"].read_text())
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        return None, f"checkpoint {paths['state']} is unreadable ({exc})"
    if not isinstance(state, dict) or state.get("identity") != json.loads(json.dumps(identity, default=str)):
        return None, f"checkpoint {paths['state']} belongs to another training run"
    for key in ("model", "replay"):
        expected = state.get(f"{key}_sha256")
        if expected is not None and (not paths[key].exists() or _sha256(paths[key]) != expected):
            return None, f"checkpoint {paths[key]} is missing or does not match its checksum"
    return state, ""


def _save_checkpoint(model, out_dir: Path, algo: str, identity: dict[str, Any], rows: list, next_eval: int) -> None:
    """Model (and replay buffer) first, the state JSON with their checksums last: a kill in between leaves a state
    whose checksums no longer match, which :func:`load_checkpoint` refuses."""
    paths = checkpoint_paths(out_dir, algo)
    _atomic_write_bytes(paths["model"], lambda tmp: model.save(str(tmp)))
    state: dict[str, Any] = {"identity": identity, "timesteps": int(model.num_timesteps), "rows": rows,
                             "next_eval": int(next_eval), "model_sha256": _sha256(paths["model"])}
    if hasattr(model, "save_replay_buffer"):
        _atomic_write_bytes(paths["replay"], lambda tmp: model.save_replay_buffer(str(tmp)))
        state["replay_sha256"] = _sha256(paths["replay"])
    _atomic_write_bytes(paths["state"], lambda tmp: tmp.write_text(json.dumps(state, default=str)))


def _curve_callback(env_config: dict[str, Any], eval_every: int, progress: Callable[[int], None] | None,
                    checkpoint: Callable[[Any, list, int], None] | None = None, checkpoint_every: int = 0):
    from stable_baselines3.common.callbacks import BaseCallback

    class CurveCallback(BaseCallback):
        def __init__(self) -> None:
            super().__init__()
            self.rows: list[tuple[int, str, float]] = []
            self._next_eval = eval_every
            self._next_checkpoint = checkpoint_every

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
            if checkpoint is not None and checkpoint_every > 0 and self.num_timesteps >= self._next_checkpoint:
                self._next_checkpoint = (self.num_timesteps // checkpoint_every + 1) * checkpoint_every
                checkpoint(self.model, self.rows, self._next_eval)
            if progress is not None:
                progress(self.num_timesteps)
            return True

    return CurveCallback()


def train_policy(algo: str, timesteps: int, out_dir: Path, n_envs: int = 2, seed: int = 0,
                 env_config: dict[str, Any] | None = None, vec: str = "subproc", eval_every: int = 0,
                 hyperparams: dict[str, Any] | None = None, progress: Callable[[int], None] | None = None,
                 torch_threads: int = 1, threads: int = 1, checkpoint_every: int = 0) -> TrainResult:
    """Train PPO or SAC on EcoDrive-v0 with ``n_envs`` vectorised envs (``threads`` numba threads of the native
    vector env); saves ``<algo>_ecodrive.zip`` (atomic) and returns the learning curve (training episode returns
    + validation returns every ``eval_every``).

    ``checkpoint_every`` [steps] > 0: the model (SAC: and its replay buffer), the steps done and the curve so far
    are saved that often (:func:`checkpoint_paths`); a training of the same settings started again in the same
    ``out_dir`` after a crash or SIGKILL continues from there instead of repeating those steps (its environments
    restart their episodes, so the continuation is not bit-identical to an uninterrupted run). A checkpoint of
    other settings, or one that fails its checksum, is not used (said in ``extra['resume']``). The checkpoint is
    removed once the final policy is saved."""
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
    if checkpoint_every < 0:
        raise RLError(f"checkpoint_every: must be >= 0 steps, got {checkpoint_every}")
    identity = {"algo": algo, "timesteps": timesteps, "n_envs": n_envs, "seed": seed, "vec": vec,
                "threads": threads, "eval_every": eval_every, "env_config": env_config, "hyperparams": params}
    state, why = load_checkpoint(Path(out_dir), algo, identity) if checkpoint_every > 0 else (None, "off")
    paths = checkpoint_paths(Path(out_dir), algo)
    callback = _curve_callback(env_config, eval_every, progress,
                               lambda m, rows, nxt: _save_checkpoint(m, Path(out_dir), algo, identity, rows, nxt),
                               checkpoint_every)
    if state is not None:
        model = silent_logger(cls.load(str(paths["model"]), env=venv, device="cpu"))
        if "replay_sha256" in state:
            model.load_replay_buffer(str(paths["replay"]))
        callback.rows = [tuple(r) for r in state["rows"]]
        callback._next_eval = int(state["next_eval"])
        callback._next_checkpoint = (int(state["timesteps"]) // checkpoint_every + 1) * checkpoint_every
        resume = f"resumed at {int(state['timesteps'])} of {timesteps} steps from {paths['state']}"
    else:
        model = silent_logger(cls("MlpPolicy", venv, seed=seed, device="cpu", verbose=0, **params))
        resume = why
    t0 = time.perf_counter()
    try:
        model.learn(total_timesteps=max(timesteps - int(model.num_timesteps), 0), callback=callback,
                    reset_num_timesteps=state is None)
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
    for leftover in paths.values():  # the final policy is written: the checkpoint has served
        leftover.unlink(missing_ok=True)
    return TrainResult(algo, path, curve, seconds, int(model.num_timesteps), {"model": model, "resume": resume})


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
