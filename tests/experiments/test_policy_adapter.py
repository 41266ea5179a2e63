"""A trained EcoDrive-v0 policy driving the optimum benchmark's roads (experiments.optimum_benchmark.policy_episode)."""

import numpy as np
import pytest

from roadload.experiments.optimum_benchmark import OptimumBenchmarkError, OptimumTask, benchmark_road, policy_episode
from roadload.experiments.rl.rollouts import run_policy


def steady(obs):
    """Half throttle: under the speed shield it settles below each limit (no learnt policy needed)."""
    return np.array([0.5], dtype=np.float32)


def test_the_policy_drives_the_benchmarks_road_not_the_envs_own():
    # city seed 0: the benchmark's road has 5 stops; EcoDrive-v0's own 'city' of seed 0 (another length) has 6
    road = benchmark_road("city", 0)
    out = policy_episode(steady, {"speed_shield": True}, road, seed=0)
    assert out["arrived"] and np.isfinite(out["segment_time"])
    assert out["stop_violations"] == road.stops.size == 5  # it never stops: each stop line crossed too fast
    assert out["speed_violations"] == 0


def test_on_the_envs_own_route_the_file_road_is_the_same_episode():
    """'route' is EcoDrive-v0's route of the seed: through the written road file the episode is bit for bit the
    one on the env's own generated road."""
    seed = 50001
    own, _ = run_policy(steady, {"speed_shield": True, "road": "hilly", "route_length": 2000.0}, seed)
    out = policy_episode(steady, {"speed_shield": True}, benchmark_road("route", seed), seed)
    assert out["segment_energy_J"] == own["arrival_energy_J"]
    assert out["segment_time"] == own["arrival_time"] and out["arrival_speed"] == own["arrival_speed"]


def test_policies_drive_the_car_only_from_standstill():
    OptimumTask("car", "motorway_short", 0, controllers=("ppo",))  # every car road now
    with pytest.raises(OptimumBenchmarkError, match="car only"):
        OptimumTask("car", "hilly", 0, controllers=("ppo",), warmup=500.0)


def test_a_saved_sac_policy_drives_a_benchmark_road_through_the_adapter(tmp_path):
    """A SAC zip (trained a few steps, then its actor fixed at a constant 0.5 command) is loaded by the benchmark's
    adapter as SAC and drives a benchmark road exactly as the same constant command does, to the road's end under
    the speed shield; its training made one gradient step per environment step with 4 sub-envs."""
    import torch

    from roadload.experiments.optimum_benchmark import _policy_run
    from roadload.experiments.rl.training import load_policy, train_policy
    from roadload.gym.ecodrive import cut_profile

    torch.set_num_threads(1)
    res = train_policy("sac", 200, tmp_path, n_envs=4, vec="dummy", env_config={"speed_shield": True,
                       "route_length": 300.0}, hyperparams={"learning_starts": 100, "batch_size": 32})
    model = res.extra["model"]
    assert model._n_updates == 200 - 100  # gradient_steps 1 made 25 (one per step of the whole vector env)
    with torch.no_grad():  # the actor's mean layer: tanh(atanh(0.5)) = 0.5 whatever the observation
        model.actor.mu.weight.zero_()
        model.actor.mu.bias.fill_(float(np.arctanh(0.5)))
    model.save(str(res.model_path))
    loaded = load_policy(res.model_path)
    assert type(loaded).__name__ == "SAC"
    action = loaded.predict(np.zeros(loaded.observation_space.shape, np.float32), deterministic=True)[0]
    assert action == pytest.approx([0.5], abs=1e-6)

    road = cut_profile(benchmark_road("hilly", 0), 500.0)
    task = OptimumTask("car", "hilly", 0, controllers=("sac",), policies=str(tmp_path))
    out = _policy_run(task, "sac", road)
    same = policy_episode(lambda obs: action, {"speed_shield": True}, road, seed=0)
    assert out["arrived"] and out["speed_violations"] == 0
    assert out["segment_energy_J"] == same["segment_energy_J"] and out["segment_time"] == same["segment_time"]
    with pytest.raises(OptimumBenchmarkError, match="ppo: no trained policy"):
        _policy_run(OptimumTask("car", "hilly", 0, controllers=("ppo",), policies=str(tmp_path)), "ppo", road)
