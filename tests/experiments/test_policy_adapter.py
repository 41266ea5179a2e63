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
