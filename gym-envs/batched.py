"""The gymnasium 1.x vector-env conventions the native batched envs share: argument checks, seeds per sub-env and
the reset mask (used by roadload.gym.traffic; roadload.gym.vector follows the same rules)."""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np

from roadload.gym.config import GymConfigError

_MODES = {"next_step": gym.vector.AutoresetMode.NEXT_STEP, "same_step": gym.vector.AutoresetMode.SAME_STEP}


def check_counts(num_envs: Any, threads: Any) -> tuple[int, int]:
    """(num_envs, threads) as ints >= 1, or GymConfigError naming the bad one."""
    for name, value in (("num_envs", num_envs), ("threads", threads)):
        if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 1:
            raise GymConfigError(f"{name}: expected an integer >= 1, got {value!r}")
    return int(num_envs), int(threads)


def autoreset_mode(value: str | gym.vector.AutoresetMode) -> gym.vector.AutoresetMode:
    """'next_step' / 'same_step' (or the AutoresetMode itself), else GymConfigError."""
    mode = _MODES.get(str(value).lower())
    if mode is None and isinstance(value, gym.vector.AutoresetMode) and value in _MODES.values():
        mode = value
    if mode is None:
        raise GymConfigError(f"autoreset_mode: expected 'next_step' or 'same_step' (or the AutoresetMode), got "
                             f"{value!r}")
    return mode


def sub_env_seeds(seed: int | list[int | None] | None, n: int) -> list[int | None]:
    """One seed per sub-env: None -> none; an int s -> s + i (as SyncVectorEnv); a list of n seeds as given."""
    if seed is None:
        return [None] * n
    if isinstance(seed, bool):
        raise ValueError(f"seed: expected an int or a list of {n} seeds, got {seed!r}")
    if isinstance(seed, (int, np.integer)):
        return [int(seed) + i for i in range(n)]
    seeds = list(seed)
    if len(seeds) != n:
        raise ValueError(f"seed: expected an int or a list of {n} seeds, got {len(seeds)}")
    return seeds


def reset_mask(options: dict[str, Any] | None, n: int) -> tuple[np.ndarray, dict[str, Any] | None]:
    """(which sub-envs to reset, the other options): ``options['reset_mask']`` (all when absent)."""
    opts = dict(options or {})
    mask = opts.pop("reset_mask", None)
    mask = np.ones(n, dtype=bool) if mask is None else np.asarray(mask, dtype=bool)
    if mask.shape != (n,):
        raise ValueError(f"options['reset_mask']: expected a boolean array of shape ({n},), got {mask.shape}")
    return mask, (opts or None)


__all__ = ["check_counts", "autoreset_mode", "sub_env_seeds", "reset_mask"]
