"""roadload/EcoHighway-v0: highway-env traffic around an ego with roadload's longitudinal dynamics."""

import os
import warnings

import gymnasium as gym
import numpy as np
import pytest

import roadload  # noqa: F401
from roadload.gym.config import GymConfigError
from roadload.gym.ecodrive import DriveScales
from roadload.envs.simulator import Simulator

FAST = dict(vehicles_count=8, duration=10.0)


@pytest.mark.parametrize("mode", ["off", "box", "dict"])
def test_checkers_pass(mode):
    from gymnasium.utils.env_checker import check_env
    from stable_baselines3.common.env_checker import check_env as sb3_check_env

    env = gym.make("roadload/EcoHighway-v0", lane_changes=mode, **FAST)
    check_env(env.unwrapped)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        sb3_check_env(env.unwrapped)
    # SB3 only warns that it cannot train a Dict action space (the 'box' form is the trainable one)
    assert all("not based off a numpy array" in str(w.message) for w in caught) and (bool(caught) == (mode == "dict"))


def test_same_seed_same_episode():
    def run(seed):
        env = gym.make("roadload/EcoHighway-v0", lane_changes="box", **FAST)
        rng = np.random.default_rng(0)
        obs, _ = env.reset(seed=seed)
        out = [obs]
        for _ in range(12):
            obs, r, te, tr, _ = env.step(rng.uniform(-1, 1, 2).astype(np.float32))
            out.append(np.append(obs, r))
            if te or tr:
                break
        return out

    a, b, c = run(5), run(5), run(6)
    assert len(a) == len(b) and all(np.array_equal(x, y) for x, y in zip(a, b))
    assert not (len(a) == len(c) and all(np.array_equal(x, y) for x, y in zip(a, c)))


def test_ego_speed_and_energy_are_roadloads_simulator():
    """Without traffic the ego's speed and energy equal a standalone Simulator run with the same commands."""
    env = gym.make("roadload/EcoHighway-v0", vehicles_count=0, duration=20.0, road="motorway", road_seed=3,
                   initial_speed=20.0)
    env.reset(seed=1)
    sim_env = env.unwrapped.simulator
    ref = Simulator("bmw_i3", sim_env.road, None, None, sim_env.seed, initial_speed=20.0)
    scales = DriveScales.from_spec(ref.vehicle)
    x0 = env.unwrapped.vehicle.position[0]
    frames = env.unwrapped.typed_config.frames_per_action
    commands = [1.0, 1.0, 0.4, 0.0, -0.3, -0.05, 0.2, 0.6]
    energy = 0.0
    for u in commands:
        _, _, te, tr, info = env.step(np.array([u], dtype=np.float32))
        u = float(np.float32(u))
        for _ in range(frames):
            st = ref.step(scales.wheel_force(u, ref.state.v), 10)
        energy += info["terms"]["energy"]
        assert info["speed"] == pytest.approx(st.v, rel=1e-12)
        assert info["s"] == pytest.approx(st.s, rel=1e-12)
    assert energy == pytest.approx(st.source_energy_total, rel=1e-9)
    # highway-env moved the ego in the plane by (nearly) the same distance: explicit Euler at 10 Hz
    dx = env.unwrapped.vehicle.position[0] - x0
    assert dx == pytest.approx(st.s, rel=0.02)
    # the speed went up under full traction, down under braking: a roadload EV (~1.4 t, 125 kW), not a kinematic car
    assert st.v > 20.0


def test_collision_terminates_with_penalty_and_headway_is_penalised():
    env = gym.make("roadload/EcoHighway-v0", vehicles_count=20, vehicles_density=2.0, duration=40.0)
    env.reset(seed=0)
    w = env.unwrapped.typed_config.reward
    headway = 0.0
    for _ in range(80):
        _, r, te, tr, info = env.step(np.array([1.0], dtype=np.float32))  # full throttle into traffic
        headway += info["terms"]["headway"]
        if te or tr:
            break
    assert te and info["crashed"] and info["terms"]["collision"] == 1.0
    assert r < -w.scale * w.collision * 0.9
    assert headway > 0


def test_lane_change_modes():
    env = gym.make("roadload/EcoHighway-v0", lane_changes="box", vehicles_count=0, lanes_count=3, duration=20.0)
    env.reset(seed=2)
    lane0 = env.unwrapped.vehicle.lane_index[2]
    direction = 1.0 if lane0 < 2 else -1.0
    _, _, _, _, info = env.step(np.array([0.1, direction], dtype=np.float32))
    assert info["terms"]["lane_change"] == 1.0
    for _ in range(6):
        _, _, _, _, info = env.step(np.array([0.1, 0.0], dtype=np.float32))
        assert info["terms"]["lane_change"] == 0.0
    assert info["lane"] == lane0 + int(direction)
    env_d = gym.make("roadload/EcoHighway-v0", lane_changes="dict", vehicles_count=0, duration=20.0)
    env_d.reset(seed=2)
    lane0 = env_d.unwrapped.vehicle.lane_index[2]
    for _ in range(6):
        _, _, _, _, info = env_d.step({"force": np.array([0.1], dtype=np.float32), "lane_change": 1 if lane0 else 2})
    assert info["lane"] != lane0


def test_rgb_array_renders_headless():
    env = gym.make("roadload/EcoHighway-v0", render_mode="rgb_array", **FAST)
    env.reset(seed=0)
    env.step(np.array([0.2], dtype=np.float32))
    frame = env.render()
    cfg = env.unwrapped.typed_config
    assert frame.shape == (cfg.screen_height, cfg.screen_width, 3) and frame.dtype == np.uint8
    assert frame.std() > 10  # road, lane markings and vehicles drawn, not a blank frame
    assert os.environ["SDL_VIDEODRIVER"] in ("offscreen", "x11", "wayland")


def test_bad_configuration_fails_at_construction():
    for kw in (dict(lanes_count=0), dict(policy_frequency=3.0), dict(lane_changes="yes"), dict(vehicle="truck"),
               dict(colour="red"), dict(reward={"collision": -1.0}), dict(simulation_frequency=7.0)):
        with pytest.raises(GymConfigError):
            gym.make("roadload/EcoHighway-v0", **kw)
    env = gym.make("roadload/EcoHighway-v0", **FAST)
    with pytest.raises(GymConfigError, match="lane_changes"):
        env.reset(options={"lane_changes": "box"})
    _, info = env.reset(seed=0, options={"vehicle": "gt_awd", "road": None})
    assert env.unwrapped.simulator.vehicle.name == "gt_awd"
    assert np.all(env.unwrapped.simulator.road.grade == 0.0)



def _return_and_end(policy, road, reward=None):
    """Return, final speed [m/s], distance [m] of one 40 s episode without traffic (the light training config:
    4 Hz traffic frames, 2 Hz decisions) driven by ``policy(v)``; checks that the mechanical term telescopes."""
    cfg = dict(vehicles_count=0, duration=40.0, simulation_frequency=4.0, policy_frequency=2.0, road=road,
               road_seed=1)
    if reward is not None:
        cfg["reward"] = reward
    env = gym.make("roadload/EcoHighway-v0", config=cfg)
    _, info = env.reset(seed=0)
    sim = env.unwrapped.simulator
    v0, climb0 = info["speed"], sim.vehicle_state.climbing_work
    ret, mech, done = 0.0, 0.0, False
    while not done:
        _, r, te, tr, info = env.step(np.array([policy(info["speed"])], dtype=np.float32))
        ret += r
        mech += info["terms"]["mechanical"]
        done = te or tr
    assert not info["crashed"]
    m = sim.vehicle.body.mass
    # the episode sum is the final minus the initial mechanical energy (kinetic + climbing work)
    assert mech == pytest.approx(0.5 * m * (info["speed"] ** 2 - v0 ** 2) + sim.vehicle_state.climbing_work - climb0,
                                 rel=1e-9)
    return ret, info["speed"], info["s"]


@pytest.mark.parametrize("road", [None, "motorway"])
def test_braking_to_a_stop_to_recover_the_kinetic_energy_does_not_beat_cruising(road):
    """The exploit PPO found (docs/results/rl.md): brake from the 25 m/s start, regenerate the kinetic energy
    and cover less road. With the mechanical-energy credit, braking to a stop returns far less than a 25 m/s
    cruise; with the credit off (the first reward) it returned more, so this test catches the flaw."""
    cruise = lambda v: float(np.clip(0.08 + 0.5 * (25.0 - v), -1.0, 1.0))  # noqa: E731
    brakes = [lambda v, u=u: u if v > 0.5 else 0.0 for u in (-0.2, -0.4, -1.0)]
    r_cruise, v_cruise, s_cruise = _return_and_end(cruise, road)
    assert v_cruise == pytest.approx(25.0, abs=1.0) and s_cruise > 950.0
    old = {"mechanical_energy": 0.0}
    r_cruise_old = _return_and_end(cruise, road, old)[0]
    for brake in brakes:
        r_brake, v_brake, s_brake = _return_and_end(brake, road)
        assert v_brake < 1.0 and s_brake < 0.4 * s_cruise
        assert r_brake < r_cruise - 15.0, (r_brake, r_cruise)
    # the flaw the credit removes: under the first reward regenerating to a stop beat cruising
    assert _return_and_end(brakes[0], road, old)[0] > r_cruise_old + 5.0
