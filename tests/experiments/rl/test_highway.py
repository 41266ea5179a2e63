"""EcoHighway-v0 RL harness: the IDM and cruise baselines act as their formulas say on the observation, and one
episode's metrics are consistent with the env's own energy ledger."""

import numpy as np
import pytest

from roadload.experiments.rl.highway import cruise_policy, idm_policy, run_highway_episode
from roadload.gym.config import EcoHighwayConfig, make_config
from roadload.gym.highway import highway_observation_layout


def _obs(cfg, **si):
    layout = highway_observation_layout(cfg)
    x = np.zeros(len(layout), dtype=np.float32)
    for k, (name, _unit, scale) in enumerate(layout):
        if name in si:
            x[k] = si[name] / scale
    return x


def test_idm_brakes_when_closing_in_and_accelerates_on_a_free_road():
    cfg = make_config(EcoHighwayConfig, {})
    idm = idm_policy(cfg)
    assert idm(_obs(cfg, v=25.0, front_gap=15.0, front_closing_speed=5.0))[0] < -0.3
    assert idm(_obs(cfg, v=15.0, front_gap=200.0, front_closing_speed=0.0))[0] > 0.3
    at_target = idm(_obs(cfg, v=25.0, front_gap=200.0, front_closing_speed=0.0))[0]
    assert at_target == pytest.approx(0.08, abs=0.02)  # the cruise feed-forward, IDM's free-road term ~0
    cruise = cruise_policy(cfg)
    assert cruise(_obs(cfg, v=20.0))[0] == pytest.approx(min(1.0, 0.08 + 0.5 * 5.0))
    assert cruise(_obs(cfg, v=27.0))[0] == pytest.approx(0.08 - 1.0)


def test_episode_metrics_follow_the_energy_ledger():
    cfg = {"vehicles_count": 3, "duration": 5.0}
    m = run_highway_episode(idm_policy(make_config(EcoHighwayConfig, cfg)), cfg, seed=50_000)
    assert not m["crashed"] and 100.0 < m["distance_m"] < 200.0  # 5 s at ~25 m/s
    assert m["energy_Wh_per_km"] == pytest.approx(m["energy_kWh"] * 1e3 / (m["distance_m"] / 1e3))
    assert m["mean_speed_kmh"] == pytest.approx(m["distance_m"] / 5.0 * 3.6, rel=0.02)
