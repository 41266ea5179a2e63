"""The traffic experiments: the fidelity measurements (headways, lane changes, KS distance, bootstrap table), the
held-out evaluation's summaries and the interval over training seeds, and a short PPO run on EcoTraffic-v0."""

import numpy as np
import pandas as pd
import pytest
from scipy import stats

from roadload.experiments.rl.traffic_fidelity import (EpisodeSamples, fidelity_table, figures, ks_distance,
                                                      time_headways)
from roadload.experiments.rl.traffic_training import (evaluate_traffic, seed_intervals, summarise_traffic,
                                                      train_traffic)
from roadload.experiments.rl.common import RLError
from roadload.gym.traffic_model import LENGTH


def test_time_headway_is_the_bumper_gap_over_speed_to_the_leader_on_the_lane():
    # x, y, speed, lane: vehicle 1 follows vehicle 2 (30 m centre to centre) at 20 m/s; vehicle 3 has nobody ahead
    # on its lane; vehicle 4 sits 2.5 m off its lane's centre and still counts on lane 0 for vehicle 5 behind it
    state = np.array([[0.0, 8.0, 20.0, 2], [100.0, 0.0, 20.0, 0], [130.0, 0.0, 18.0, 0], [120.0, 4.0, 25.0, 1],
                      [160.0, 2.5, 22.0, 0], [140.0, 0.0, 10.0, 0]])
    h = time_headways(state, lanes=3)
    # vehicle 1 -> 2 (130 m); 2 -> 5 (140 m); 3 (lane 1) -> 4, which is within 3 m of lane 1's centre too (160 m);
    # 4 has nobody ahead; 5 -> 4
    expected = [(130 - 100 - LENGTH) / 20.0, (140 - 130 - LENGTH) / 18.0, (160 - 120 - LENGTH) / 25.0,
                (160 - 140 - LENGTH) / 10.0]
    assert np.allclose(sorted(h), sorted(expected))


def test_ks_distance_equals_scipys_and_figures_pool_the_episodes():
    rng = np.random.default_rng(0)
    a, b = rng.normal(0, 1, 300), rng.normal(0.3, 1, 200)
    assert ks_distance(a, b) == pytest.approx(stats.ks_2samp(a, b).statistic, abs=1e-12)
    one = EpisodeSamples(speeds=[np.array([20.0, 22.0])], headways=[np.array([1.0, 3.0])], lane_changes=2,
                         vehicle_minutes=1.0, energy_J=3.6e5, distance_m=1000.0, duration_s=40.0)
    two = EpisodeSamples(speeds=[np.array([24.0])], headways=[np.array([2.0])], lane_changes=0, vehicle_minutes=1.0,
                         crashed=True, energy_J=0.0, distance_m=1000.0, duration_s=40.0)
    f = figures([one, two])
    assert f["speed_median_mps"] == 22.0 and f["headway_median_s"] == 2.0
    assert f["lane_changes_per_vehicle_min"] == 1.0 and f["ego_collision_rate"] == 0.5
    assert f["ego_energy_Wh_per_km"] == pytest.approx(50.0) and f["ego_mean_speed_kmh"] == pytest.approx(90.0)
    table = fidelity_table([one, two], [one, one], n_boot=50).set_index("figure")
    assert table.loc["speed_median_mps", "rel_diff"] == pytest.approx(22.0 / 21.0 - 1.0)
    assert table.loc["ego_energy_Wh_per_km", "met"] == False  # noqa: E712  (50 against 100 Wh/km)
    assert table.loc["headway_median_s", "met"] == True  # noqa: E712


def test_summary_and_seed_interval():
    table = pd.DataFrame({"policy": ["a", "a", "b"], "backend": "native", "crashed": [False, True, False],
                          "distance_m": [1000.0, 500.0, 800.0], "energy_kWh": [0.1, 0.05, 0.2],
                          "time_s": [40.0, 20.0, 40.0], "episode_return": [1.0, 3.0, 2.0], "steps": [400, 200, 400],
                          "shield_steps": [0, 60, 0]})
    s = summarise_traffic(table).set_index("policy")
    assert s.loc["a", "energy_Wh_per_km"] == pytest.approx(100.0) and s.loc["a", "crashes"] == 1
    assert s.loc["a", "mean_speed_kmh"] == pytest.approx(1500.0 / 60.0 * 3.6)
    assert s.loc["a", "shielded_steps"] == pytest.approx(0.1)
    seeds = pd.DataFrame({"backend": "native", "energy_Wh_per_km": [70.0, 72.0, 74.0], "mean_speed_kmh": 75.0,
                          "mean_return": 45.0, "crashes": 0})
    ci = seed_intervals(seeds).iloc[0]
    assert ci.energy_Wh_per_km == 72.0
    assert ci.energy_Wh_per_km_ci95 == pytest.approx(stats.t.ppf(0.975, 2) * 2.0 / np.sqrt(3))


def test_short_ppo_run_trains_saves_and_is_evaluated(tmp_path):
    res = train_traffic(2048, tmp_path, seed=0, n_envs=8, env_config={"vehicles_count": 8, "duration": 4.0})
    assert res["path"].is_file() and res["timesteps"] >= 2048 and res["cpu_seconds"] > 0
    table = evaluate_traffic({"ppo": lambda obs: res["model"].predict(obs, deterministic=True)[0]},
                             {"vehicles_count": 8, "duration": 4.0, "shield": {"enabled": True}}, episodes=2)
    assert len(table) == 2 and (table.distance_m > 50).all() and not table.crashed.any()
    with pytest.raises(RLError, match="timesteps"):
        train_traffic(0, tmp_path)
    with pytest.raises(RLError, match="backend"):
        evaluate_traffic({}, {}, backend="carla")


def test_the_bootstraps_weighted_median_equals_the_median_of_the_resampled_pool():
    from roadload.experiments.rl.traffic_fidelity import _Pooled

    rng = np.random.default_rng(1)
    episodes = [EpisodeSamples(speeds=[rng.normal(20, 3, rng.integers(1, 30)) for _ in range(rng.integers(1, 4))])
                for _ in range(7)]
    pool = _Pooled(episodes, "speeds")
    for _ in range(100):
        idx = rng.integers(0, 7, 7)
        resampled = np.concatenate([a for k in idx for a in episodes[k].speeds])
        assert pool.median(np.bincount(idx, minlength=7)) == pytest.approx(np.median(resampled), abs=1e-12)


def test_residual_actions_add_the_agents_correction_to_the_idm_follower():
    from roadload.experiments.rl.highway import idm_policy
    from roadload.experiments.rl.traffic_training import ResidualActions
    from roadload.gym.config import EcoTrafficConfig
    from roadload.gym.traffic import EcoTrafficVectorEnv

    config = {"vehicles_count": 8, "duration": 3.0}
    follow = idm_policy(EcoTrafficConfig(**config))
    plain = EcoTrafficVectorEnv(3, config=config, autoreset_mode="same_step")
    wrapped = ResidualActions(EcoTrafficVectorEnv(3, config=config, autoreset_mode="same_step"), follow, 0.3)
    with pytest.raises(RLError, match="before reset"):
        wrapped.step(np.zeros((3, 1), np.float32))
    obs_p, _ = plain.reset(seed=4)
    obs_w, _ = wrapped.reset(seed=4)
    correction = np.array([[0.0], [1.0], [-1.0]], np.float32)
    for _ in range(40):  # past the 3 s episode end: the base follows the autoreset's first observation
        expected = np.clip(follow(obs_p) + 0.3 * correction, -1.0, 1.0).astype(np.float32)
        obs_p, r_p, *_ = plain.step(expected)
        obs_w, r_w, *_ = wrapped.step(correction)
        assert np.array_equal(obs_p, obs_w) and np.array_equal(r_p, r_w)
    with pytest.raises(RLError, match="scale"):
        ResidualActions(plain, follow, 0.0)


def test_the_speed_floor_keeps_the_command_within_its_distance_below_the_base():
    from roadload.experiments.rl.traffic_training import ResidualActions, residual_command

    base = np.array([[0.5], [0.5], [-0.98], [0.9]], np.float32)
    action = np.array([[-1.0], [1.0], [-1.0], [1.0]], np.float32)
    u = residual_command(base, action, 0.3, 0.05)
    # at most 0.05 taken off the base; up to 0.3 added, the command clipped to [-1, 1]
    assert u[:, 0] == pytest.approx([0.45, 0.8, -1.0, 1.0], abs=1e-7)
    assert np.array_equal(residual_command(base, action, 0.3, None),
                          np.clip(base + 0.3 * action, -1, 1).astype(np.float32))
    with pytest.raises(RLError, match="speed floor"):
        ResidualActions(None, lambda obs: obs, 0.3, 0.5)  # a floor wider than the residual is no floor
