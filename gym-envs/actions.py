"""Action validation for the roadload gymnasium environments (EcoDrive-v0, EcoHighway-v0, vectorised forms).

:func:`validate_action` checks one action against the env's action space before anything is simulated: the
shape (a scalar stands for a shape-(1,) Box), a numeric dtype, finite values and the bounds. A bad action is a
``ValueError`` naming the expected shape and bounds and what was given, never an error deep inside numpy or a
silently truncated action. :func:`validate_actions` is the batch form for n environments stepped at once
(leading axis n).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from gymnasium import spaces

__all__ = ["validate_action", "validate_actions", "describe_space", "BOUND_TOLERANCE"]

#: values this far outside a Box's bounds (float32 rounding of a clipped policy output) are clipped, not refused
BOUND_TOLERANCE = 1e-6


def describe_space(space: spaces.Space) -> str:
    """'shape (1,) with values in [-1, 1]' / 'an integer in [0, 3)' / a dict of those."""
    if isinstance(space, spaces.Box):
        lo, hi = np.unique(space.low), np.unique(space.high)
        bounds = (f"[{lo[0]:g}, {hi[0]:g}]" if lo.size == 1 and hi.size == 1
                  else f"[{space.low.tolist()}, {space.high.tolist()}]")
        return f"a float array of shape {space.shape} with values in {bounds}"
    if isinstance(space, spaces.Discrete):
        return f"an integer in [{int(space.start)}, {int(space.start + space.n)})"
    if isinstance(space, spaces.Dict):
        return "a dict {" + ", ".join(f"{k!r}: {describe_space(s)}" for k, s in space.spaces.items()) + "}"
    return repr(space)


def _box(action: Any, space: spaces.Box, name: str, batch: int | None) -> np.ndarray:
    want = space.shape if batch is None else (batch, *space.shape)
    if action is None or isinstance(action, (str, bytes, dict)):
        raise ValueError(f"{name}: expected {describe_space(space)}" + (f" for each of {batch} envs" if batch else "")
                         + f", got {type(action).__name__} {action!r}")
    try:
        arr = np.asarray(action)
    except (ValueError, TypeError) as exc:
        raise ValueError(f"{name}: expected {describe_space(space)}, got an unreadable value ({exc})") from None
    if arr.dtype.kind not in "fiu":
        raise ValueError(f"{name}: expected {describe_space(space)}, got an array of dtype {arr.dtype}")
    if batch is None and arr.ndim == 0 and space.shape == (1,):
        arr = arr.reshape(1)
    if arr.shape != want:
        raise ValueError(f"{name}: expected {describe_space(space)}"
                         + (f" stacked for {batch} envs, i.e. shape {want}" if batch is not None else "")
                         + f", got shape {arr.shape}")
    arr = arr.astype(np.float64)
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name}: expected {describe_space(space)}, got non-finite values {arr.tolist()}")
    low, high = space.low.astype(np.float64), space.high.astype(np.float64)
    if np.any(arr < low - BOUND_TOLERANCE) or np.any(arr > high + BOUND_TOLERANCE):
        raise ValueError(f"{name}: expected {describe_space(space)}, got {arr.tolist()} (outside the bounds)")
    return np.clip(arr, low, high).astype(space.dtype)


def _discrete(action: Any, space: spaces.Discrete, name: str) -> int:
    arr = np.asarray(action) if action is not None and not isinstance(action, (str, bytes)) else None
    if arr is None or arr.dtype.kind not in "iu" or arr.size != 1:
        raise ValueError(f"{name}: expected {describe_space(space)}, got {action!r}")
    value = int(arr.reshape(()))
    if not space.start <= value < space.start + space.n:
        raise ValueError(f"{name}: expected {describe_space(space)}, got {value}")
    return value


def validate_action(action: Any, space: spaces.Space, name: str = "action") -> Any:
    """The action as the space's type (Box: array of its dtype and shape; Discrete: int; Dict: dict), or a
    ValueError naming the expected shape and bounds."""
    if isinstance(space, spaces.Box):
        return _box(action, space, name, None)
    if isinstance(space, spaces.Discrete):
        return _discrete(action, space, name)
    if isinstance(space, spaces.Dict):
        if not isinstance(action, dict):
            raise ValueError(f"{name}: expected {describe_space(space)}, got {type(action).__name__}")
        if set(action) != set(space.spaces):
            raise ValueError(f"{name}: expected the keys {sorted(space.spaces)}, got {sorted(map(str, action))}")
        return {k: validate_action(action[k], s, f"{name}[{k!r}]") for k, s in space.spaces.items()}
    if not space.contains(action):
        raise ValueError(f"{name}: expected {describe_space(space)}, got {action!r}")
    return action


def validate_actions(actions: Any, space: spaces.Box, n_envs: int, name: str = "actions") -> np.ndarray:
    """Batch form for a vectorised env: a (n_envs, *space.shape) array (a (n_envs,) array for shape-(1,) spaces)."""
    if not isinstance(space, spaces.Box):
        raise TypeError(f"{name}: the batch form needs a Box action space, got {type(space).__name__}")
    if space.shape == (1,) and np.ndim(actions) == 1 and not isinstance(actions, (str, bytes)):
        actions = np.asarray(actions).reshape(-1, 1)
    return _box(actions, space, name, n_envs)
