"""roadload/EcoDrive-v0: spaces, determinism, reward bookkeeping, termination, configuration errors."""

import warnings

import gymnasium as gym
import numpy as np
import pytest

import roadload  # noqa: F401  (registers the ids)
from roadload.gym.config import GymConfigError
from roadload.gym.ecodrive import EcoDriveEnv, RouteTable, cut_profile, observation_layout
from roadload.road_profiles import load_profile

SHORT = dict(route_length=400.0)


def _rollout(env, seed, n, action_seed=0):
    rng = np.random.default_rng(action_seed)
    obs, _ = env.reset(seed=seed)
    out = [obs]
    rewards = []
    for _ in range(n):
        obs, r, te, tr, info = env.step(rng.uniform(-1, 1, 1).astype(np.float32))
        out.append(obs)
        rewards.append(r)
        if te or tr:
            break
    return np.array(out), np.array(rewards)


@pytest.mark.parametrize("mode", ["state", "can", "can+estimates"])
def test_checkers_pass(mode):
    from gymnasium.utils.env_checker import check_env
    from stable_baselines3.common.env_checker import check_env as sb3_check_env

    env = gym.make("roadload/EcoDrive-v0", observation=mode, **SHORT)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no checker warning either
        check_env(env.unwrapped)
        sb3_check_env(env.unwrapped)


@pytest.mark.parametrize("mode", ["state", "can"])
def test_same_seed_same_episode(mode):
    env = gym.make("roadload/EcoDrive-v0", observation=mode, **SHORT)
    o1, r1 = _rollout(env, seed=7, n=300)
    o2, r2 = _rollout(env, seed=7, n=300)
    env2 = gym.make("roadload/EcoDrive-v0", observation=mode, **SHORT)
    o3, r3 = _rollout(env2, seed=7, n=300)
    assert np.array_equal(o1, o2) and np.array_equal(r1, r2)
    assert np.array_equal(o1, o3) and np.array_equal(r1, r3)
    o4, _ = _rollout(env, seed=8, n=300)
    assert o4.shape != o1.shape or not np.array_equal(o1, o4)


def test_reward_is_weighted_sum_of_reported_terms_and_reweights():
    env = gym.make("roadload/EcoDrive-v0", road="city", route_length=1500.0)
    env.reset(seed=3)
    w = env.unwrapped.config.reward
    rng = np.random.default_rng(1)
    total_energy = 0.0
    for _ in range(400):
        obs, r, te, tr, info = env.step(rng.uniform(-0.2, 1.0, 1).astype(np.float32))
        t = info["terms"]
        expect = -w.scale * (w.energy * t["energy"] + w.time * t["time"] + w.speeding * t["speeding"]
                             + w.lateral * t["lateral"] + w.stop * t["stop"] + w.jerk * t["jerk"]
                             - w.progress * t["progress"])
        assert r == pytest.approx(expect, rel=1e-12, abs=1e-15)
        total_energy += t["energy"]
        if te or tr:
            break
    # the energy terms add up to the simulator's source-energy ledger
    assert total_energy == pytest.approx(info["source_energy_total"], rel=1e-9)
    assert info["return_costs"]["energy"] == pytest.approx(w.energy * total_energy, rel=1e-9)
    # a user re-weighting: doubling the time weight changes each reward by exactly scale * time * dt
    env_b = gym.make("roadload/EcoDrive-v0", road="city", route_length=1500.0, reward={"time": 2 * w.time})
    env.reset(seed=5)
    env_b.reset(seed=5)
    a = np.array([0.5], dtype=np.float32)
    _, r_a, *_ = env.step(a)
    _, r_b, *_ = env_b.step(a)
    assert r_a - r_b == pytest.approx(w.scale * w.time * 0.1, rel=1e-9)


def test_full_throttle_terminates_at_route_end():
    env = gym.make("roadload/EcoDrive-v0", road="motorway", route_length=300.0)
    env.reset(seed=0)
    for _ in range(2000):
        _, _, te, tr, info = env.step(np.array([1.0], dtype=np.float32))
        if te or tr:
            break
    assert te and not tr
    assert info["s"] >= 300.0
    # the progress credit sums to exactly progress * route length on arrival (potential-based shaping)
    w = env.unwrapped.config.reward
    assert info["return_costs"]["progress"] == pytest.approx(-w.progress * 300.0, rel=1e-12)


def test_standing_still_truncates_without_progress_credit():
    env = gym.make("roadload/EcoDrive-v0", road="motorway", route_length=300.0, time_limit=5.0)
    env.reset(seed=0)
    n = 0
    while True:
        _, r, te, tr, info = env.step(np.array([-1.0], dtype=np.float32))
        n += 1
        if te or tr:
            break
    assert tr and not te and n == 50  # 5 s / 0.1 s
    assert info["s"] < 1.0
    w = env.unwrapped.config.reward
    assert info["return_costs"]["progress"] == pytest.approx(-w.progress * info["s"], abs=1e-9)
    assert info["return_costs"]["time"] == pytest.approx(w.time * 5.0)


def test_state_preview_matches_the_road_profile():
    cfg = dict(road="hilly", road_seed=11, route_length=3000.0, obs_scaling="si")
    env = gym.make("roadload/EcoDrive-v0", **cfg)
    obs, _ = env.reset(seed=0)
    for _ in range(150):
        obs, *_ = env.step(np.array([0.6], dtype=np.float32))
    info_s = env.unwrapped.simulator.state.s
    names = [row[0] for row in env.unwrapped.layout]
    prof = cut_profile(load_profile("hilly", seed=11), 3000.0)
    for d in (0.0, 100.0, 400.0):
        at = prof.at(info_s + d)
        assert obs[names.index(f"grade@{d:g}m")] == pytest.approx(at["grade"], abs=2e-5)
        assert obs[names.index(f"speed_limit@{d:g}m")] == pytest.approx(at["speed_limit"], abs=1e-3)
        assert obs[names.index(f"curvature@{d:g}m")] == pytest.approx(at["curvature"], abs=1e-5)
    assert obs[names.index("remaining_distance")] == pytest.approx(3000.0 - info_s, abs=1e-2)
    assert obs[names.index("v")] == pytest.approx(env.unwrapped.simulator.state.v, rel=1e-6)


def test_schedule_time_deficit_is_analytic_on_a_constant_road():
    from roadload.road_profiles import RoadProfile

    s = np.linspace(0.0, 1000.0, 11)
    prof = RoadProfile("flat", s, np.zeros(11), np.zeros(11), np.zeros(11), np.full(11, 20.0))
    table = RouteTable(prof, np.array([0.0, 50.0]), fraction=0.5, lateral_limit=3.0)
    assert table.route_time == pytest.approx(1000.0 / 10.0)
    assert table.look_ahead(300.0)[RouteTable.SCHEDULE, 0] == pytest.approx(30.0)


def test_can_mode_reads_noisy_channels_and_dead_reckons_position():
    env = gym.make("roadload/EcoDrive-v0", observation="can", obs_scaling="si", road="motorway",
                   route_length=2000.0)
    obs, _ = env.reset(seed=2)
    names = [row[0] for row in env.unwrapped.layout]
    for _ in range(300):
        obs, *_ , info = env.step(np.array([0.4], dtype=np.float32))
    v_true = env.unwrapped.simulator.state.v
    assert obs[names.index("can_vehicle_speed")] == pytest.approx(v_true, rel=0.03)
    s_true = info["s"]
    s_hat = 2000.0 - obs[names.index("remaining_distance")]
    assert abs(s_hat - s_true) < 0.02 * s_true + 2.0
    assert "v" not in names


def test_bad_configuration_fails_at_construction():
    bad = [dict(foo=1), dict(vehicle="tesla"), dict(road="wltc3"), dict(road="nonexistent_road"),
           dict(control_period=0.015), dict(preview_distances=(100.0, 50.0)), dict(reward={"energy": -1.0}),
           dict(effects={"wind": {"speed": 3.0}}), dict(observation="pixels"), dict(route_length=-5.0),
           dict(route_length=1e5, road="city")]
    for kw in bad:
        with pytest.raises(GymConfigError) as err:
            gym.make("roadload/EcoDrive-v0", **kw)
        key = next(iter(kw))
        assert key.split("_")[0] in str(err.value), (kw, str(err.value))


def test_reset_options_change_road_vehicle_effects_but_not_spaces():
    env = gym.make("roadload/EcoDrive-v0", **SHORT)
    env.reset(seed=0)
    assert env.unwrapped.simulator.vehicle.name == "bmw_i3"
    _, info = env.reset(seed=0, options={"vehicle": "gt_rwd", "road": "city", "road_seed": 4,
                                         "effects": {"wind": {"mean_speed": 6.0}}})
    sim = env.unwrapped.simulator
    assert sim.vehicle.name == "gt_rwd" and sim.effects.enabled("wind") and info["road_seed"] == 4
    assert env.unwrapped.route.name.startswith("city")
    with pytest.raises(GymConfigError, match="observation"):
        env.reset(options={"observation": "can"})
    with pytest.raises(GymConfigError, match="unknown key"):
        env.reset(options={"colour": "red"})
    with pytest.raises(GymConfigError, match="vehicle"):
        env.reset(options={"vehicle": "nope"})


def test_throttle_accelerates_and_braking_recovers_energy_on_the_ev():
    env = gym.make("roadload/EcoDrive-v0", road="motorway", route_length=3000.0, initial_speed=25.0)
    env.reset(seed=1)
    _, _, _, _, info = env.step(np.array([1.0], dtype=np.float32))
    assert info["a"] > 1.0 and info["terms"]["energy"] > 0
    _, _, _, _, info = env.step(np.array([-0.1], dtype=np.float32))  # within the regen limit
    assert info["a"] < -0.5 and info["terms"]["energy"] < 0  # battery charged


def test_observation_layout_documents_every_entry():
    env = EcoDriveEnv(observation="can", **SHORT)
    layout = observation_layout(env.config)
    assert len(layout) == env.observation_space.shape[0]
    assert all(unit and scale > 0 and lo < hi for _, unit, scale, lo, hi in layout)
    img = EcoDriveEnv(render_mode="rgb_array", **SHORT)
    img.reset(seed=0)
    frame = img.render()
    assert frame.dtype == np.uint8 and frame.shape == (160, 480, 3) and frame.min() < 255


def test_can_estimates_mode_runs_the_online_estimator():
    # 300 kg of payload the nominal model does not know about: the estimate must learn it
    env = gym.make("roadload/EcoDrive-v0", observation="can+estimates", obs_scaling="si", road="motorway",
                   route_length=2000.0, effects={"payload": {"initial_payload": 300.0, "change_std": 0.0}})
    obs, _ = env.reset(seed=0)
    names = [row[0] for row in env.unwrapped.layout]
    k = names.index("estimated_mass")
    assert names[k:] == ["estimated_mass", "estimated_c0", "estimated_c2"]
    nominal = obs[k:].copy()
    assert nominal[0] == pytest.approx(env.unwrapped.simulator.vehicle.body.mass, rel=0.05)
    for _ in range(350):  # 35 s: three estimator updates (every 10 s)
        v = obs[names.index("can_vehicle_speed")]
        obs, *_ = env.step(np.array([np.clip(0.3 * (25.0 - v), -1, 1)], dtype=np.float32))
    assert env.unwrapped.observation_type.estimator.updates >= 3 and env.unwrapped.observation_type.estimator.rows > 100
    assert not np.array_equal(obs[k:], nominal)  # the estimate moved
    truth = env.unwrapped.simulator.true_parameters()["mass"]
    assert truth == pytest.approx(nominal[0] + 300.0)
    # learning helped: the estimate (1658 kg measured) is within 5 % of the truth and its error is below a third of
    # the nominal's 300 kg (a frozen or diverging estimator fails both)
    assert obs[k] == pytest.approx(truth, rel=0.05)
    assert abs(obs[k] - truth) < abs(nominal[0] - truth) / 3.0
