"""Shared pieces of the RL experiments: ids, road seeds, errors, routes, algorithms, vectorised environments."""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any, Callable


from roadload.fileio import atomic_path
from roadload.gym.config import EcoDriveConfig
from roadload.gym.ecodrive import cut_profile
from roadload.road_profiles import RoadProfile, load_profile
from roadload.gym.sb3 import SB3VecEnv
from roadload.gym.vector import EcoDriveVectorEnv



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
    # gradient_steps -1: one gradient step per environment step collected (train_freq counts steps of the whole
    # vector env, so gradient_steps 1 with the native env's 16 sub-envs made 1 update per 16 samples)
    "sac": dict(learning_rate=3e-4, buffer_size=200_000, learning_starts=5_000, batch_size=256, gamma=0.999,
                tau=0.005, train_freq=1, gradient_steps=-1, policy_kwargs={"net_arch": [64, 64]}),
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


def silent_logger(model: Any) -> Any:
    """``model`` (an SB3 algorithm) with a logger that writes nothing. Without one, every ``learn()`` at verbose 0
    and without a tensorboard folder makes an empty folder ``SB3-<date>`` in the system's temporary folder (SB3's
    default logger); roadload records its own training curves."""
    from stable_baselines3.common.logger import Logger

    model.set_logger(Logger(folder=None, output_formats=[]))
    return model


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

        venv = SB3VecEnv(EcoDriveVectorEnv(n_envs, config=dict(env_config or {}), autoreset_mode="same_step",
                                           threads=threads))
        venv.seed(seed)
        return venv
    cls = SubprocVecEnv if vec == "subproc" else DummyVecEnv
    kwargs = {"start_method": start_method} if (vec == "subproc" and start_method) else None
    return sb3_make_vec_env(ENV_ID, n_envs=n_envs, seed=seed, env_kwargs={"config": dict(env_config or {})},
                            vec_env_cls=cls, vec_env_kwargs=kwargs)


def json_object_option(ap: argparse.ArgumentParser, text: str | None, option: str = "--config",
                       what: str = "of EcoTraffic-v0 options") -> dict[str, Any]:
    """The JSON object given to a command-line ``option`` ({} without), or the parser's error naming it and what
    the object holds (``what``)."""
    if not text:
        return {}
    try:
        value = json.loads(text)
    except json.JSONDecodeError as exc:
        ap.error(f"{option}: expected a JSON object {what}, got {text!r} ({exc})")
    if not isinstance(value, dict):
        ap.error(f"{option}: expected a JSON object {what}, got {text!r}")
    return value
