"""A gymnasium 1.x ``VectorEnv`` (e.g. the native :class:`roadload.gym.vector.EcoDriveVectorEnv`) as a
stable-baselines3 ``VecEnv``.

SB3 expects same-step autoreset (a finished sub-env returns its first new observation at once, the last one in
``infos[i]['terminal_observation']``) and a list of per-env info dicts with Monitor's ``'episode'`` statistics;
gymnasium's native vector envs report dicts of arrays. The adapter translates; it asks the vector env for
``autoreset_mode='same_step'``.

Other libraries: anything that takes a gymnasium ``VectorEnv`` uses the native env directly
(``gymnasium.make_vec("roadload/EcoDrive-v0", num_envs=N, vectorization_mode="vector_entry_point")``; CleanRL-style
loops, TorchRL's ``GymWrapper``, RLlib's ``gym.make_vec`` env runners); the SB3 path is
``SB3VecEnv(EcoDriveVectorEnv(N, config, autoreset_mode="same_step"))``.
"""

from __future__ import annotations

import time
from typing import Any, Sequence

import gymnasium as gym
import numpy as np
from stable_baselines3.common.vec_env.base_vec_env import VecEnv, VecEnvIndices, VecEnvStepReturn


class SB3VecEnv(VecEnv):
    """stable-baselines3 view of a same-step-autoreset gymnasium ``VectorEnv`` (module docstring)."""

    def __init__(self, venv: gym.vector.VectorEnv) -> None:
        mode = getattr(venv, "autoreset_mode", None) or venv.metadata.get("autoreset_mode")
        if mode != gym.vector.AutoresetMode.SAME_STEP:
            raise ValueError(f"venv: SB3 needs a vector env with autoreset_mode='same_step', got {mode!r}")
        self.venv = venv
        super().__init__(venv.num_envs, venv.single_observation_space, venv.single_action_space)
        n = venv.num_envs
        self._actions: np.ndarray | None = None
        self._ep_return = np.zeros(n)
        self._ep_length = np.zeros(n, dtype=np.int64)
        self._t0 = time.perf_counter()

    def reset(self) -> np.ndarray:
        seeds = self._seeds
        seed = None if all(s is None for s in seeds) else [None if s is None else int(s) for s in seeds]
        # gymnasium annotates VectorEnv.reset(seed: int | None); its vector envs take one seed per sub-env too
        obs, _ = self.venv.reset(seed=seed,  # type: ignore[arg-type]
                                 options=self._options[0] if self._options[0] else None)
        self._reset_seeds()
        self._reset_options()
        self._ep_return[:] = 0.0
        self._ep_length[:] = 0
        return obs

    def step_async(self, actions: np.ndarray) -> None:
        self._actions = np.asarray(actions, dtype=np.float32).reshape(self.num_envs, -1)

    def step_wait(self) -> VecEnvStepReturn:
        obs, reward, terminated, truncated, info = self.venv.step(self._actions)
        self._ep_return += reward
        self._ep_length += 1
        done = terminated | truncated
        infos: list[dict[str, Any]] = [{} for _ in range(self.num_envs)]
        if done.any():
            final = info["final_obs"]
            elapsed = round(time.perf_counter() - self._t0, 6)
            for i in np.flatnonzero(done):
                infos[i] = {"terminal_observation": final[i],
                            "TimeLimit.truncated": bool(truncated[i] and not terminated[i]),
                            "episode": {"r": float(self._ep_return[i]), "l": int(self._ep_length[i]), "t": elapsed}}
            self._ep_return[done] = 0.0
            self._ep_length[done] = 0
        return obs, reward.astype(np.float32), done, infos

    def close(self) -> None:
        self.venv.close()

    # SB3 asks these of sub-envs; the native env has one shared configuration
    def get_attr(self, attr_name: str, indices: VecEnvIndices = None) -> list[Any]:
        return [getattr(self.venv, attr_name) for _ in self._get_indices(indices)]

    def set_attr(self, attr_name: str, value: Any, indices: VecEnvIndices = None) -> None:
        setattr(self.venv, attr_name, value)

    def env_method(self, method_name: str, *method_args, indices: VecEnvIndices = None, **method_kwargs) -> list[Any]:
        return [getattr(self.venv, method_name)(*method_args, **method_kwargs) for _ in self._get_indices(indices)]

    def env_is_wrapped(self, wrapper_class: type, indices: VecEnvIndices = None) -> list[bool]:
        return [False for _ in self._get_indices(indices)]

    def _get_indices(self, indices: VecEnvIndices) -> Sequence[int]:
        if indices is None:
            return range(self.num_envs)
        if isinstance(indices, int):
            return [indices]
        return list(indices)
