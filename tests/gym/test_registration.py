"""Registration: ids resolve as "roadload:roadload/<Env>-v0" (module import) and in spawned SubprocVecEnv workers."""

import gymnasium as gym
import numpy as np
import pytest

import roadload  # noqa: F401

IDS = ["roadload/EcoDrive-v0", "roadload/EcoHighway-v0"]


def test_ids_registered_on_import_with_string_entry_points():
    for env_id in IDS:
        spec = gym.spec(env_id)
        assert isinstance(spec.entry_point, str) and spec.entry_point.startswith("roadload.gym.")


def test_module_prefixed_id_resolves():
    env = gym.make("roadload:roadload/EcoDrive-v0", route_length=300.0)
    obs, _ = env.reset(seed=0)
    assert obs.shape == env.observation_space.shape


@pytest.mark.parametrize("start_method", ["spawn", pytest.param("forkserver", marks=pytest.mark.slow)])
def test_subproc_vec_env_with_fresh_interpreters(start_method):
    from stable_baselines3.common.vec_env import SubprocVecEnv

    # the worker is a fresh interpreter: the id resolves only because "roadload:" imports the package there (one
    # worker: each costs a whole interpreter's imports, torch's included)
    venv = SubprocVecEnv([lambda: gym.make("roadload:roadload/EcoDrive-v0", route_length=300.0)],
                         start_method=start_method)
    try:
        venv.seed(3)
        obs = venv.reset()
        assert obs.shape == (1, gym.make("roadload/EcoDrive-v0").observation_space.shape[0])
        obs, rew, done, info = venv.step(np.full((1, 1), 0.5, dtype=np.float32))
        assert np.all(np.isfinite(rew)) and info[0]["t"] == pytest.approx(0.1)
    finally:
        venv.close()
