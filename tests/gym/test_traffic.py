"""roadload/EcoTraffic-v0: the compiled, batched traffic env with roadload's powertrain (roadload.gym.traffic),
its gymnasium contracts, the single and vector forms, the ego's physics, the reward, the safety layer and the
reference backend on highway-env (roadload.gym.traffic_reference)."""

import warnings

import gymnasium as gym
import numpy as np
import pytest

import roadload  # noqa: F401
from roadload.gym import traffic_model as tm
from roadload.gym.config import GymConfigError
from roadload.gym.ecodrive import DriveScales
from roadload.gym.traffic import TERM_NAMES, EcoTrafficEnv, EcoTrafficVectorEnv, traffic_observation_layout
from roadload.envs.simulator import Simulator

FAST = dict(vehicles_count=10, duration=8.0)


@pytest.mark.parametrize("mode", ["off", "box"])
def test_checkers_pass(mode):
    from gymnasium.utils.env_checker import check_env
    from stable_baselines3.common.env_checker import check_env as sb3_check_env

    env = gym.make("roadload/EcoTraffic-v0", lane_changes=mode, **FAST)
    check_env(env.unwrapped)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        sb3_check_env(env.unwrapped)
    assert not caught, [str(w.message) for w in caught]
    assert env.observation_space.shape == (len(traffic_observation_layout(env.unwrapped.config)),)


def test_make_vec_gives_the_native_vector_env_and_checks_its_arguments():
    envs = gym.make_vec("roadload/EcoTraffic-v0", num_envs=3, vectorization_mode="vector_entry_point", **FAST)
    assert isinstance(envs, EcoTrafficVectorEnv)
    obs, info = envs.reset(seed=0)
    assert obs.shape == (3, envs.single_observation_space.shape[0]) and envs.observation_space.contains(obs)
    assert info["_speed"].all() and np.allclose(info["speed"], 25.0)
    with pytest.raises(GymConfigError, match="num_envs"):
        EcoTrafficVectorEnv(0)
    with pytest.raises(GymConfigError, match="autoreset_mode"):
        EcoTrafficVectorEnv(2, autoreset_mode="sometimes")
    with pytest.raises(GymConfigError, match="threads"):
        EcoTrafficVectorEnv(2, threads=0)
    with pytest.raises(GymConfigError, match="kinematics_rows"):
        EcoTrafficVectorEnv(2, kinematics_rows=1)
    with pytest.raises(GymConfigError, match="reset options .*lanes_count"):
        envs.reset(options={"lanes_count": 4})
    with pytest.raises(GymConfigError, match="reset options .*min_time_headway"):
        envs.reset(options={"min_time_headway": 2.0})  # a batch-wide field
    envs.reset(seed=1, options={"road_seed": 77, "initial_speed": 20.0})  # per sub-env fields are taken
    assert np.allclose(envs.vehicles[:, 0, tm.V_SPEED], 20.0)
    with pytest.raises(ValueError, match="non-finite"):
        envs.step(np.array([[np.nan], [0.0], [0.0]], dtype=np.float32))
    with pytest.raises(ValueError, match="shape"):
        envs.step(np.zeros((2, 1), dtype=np.float32))


def test_bad_config_and_actions_are_refused_with_the_field():
    with pytest.raises(GymConfigError, match="vehicles_count"):
        EcoTrafficEnv(vehicles_count=-1)
    with pytest.raises(GymConfigError, match="unknown key"):
        EcoTrafficEnv(lanes=3)
    with pytest.raises(GymConfigError, match="whole multiple"):
        EcoTrafficEnv(policy_frequency=3.0)
    with pytest.raises(GymConfigError, match="delta_range"):
        EcoTrafficEnv(traffic={"delta_range": (5.0, 4.0)})
    with pytest.raises(GymConfigError, match="unknown vehicle"):
        EcoTrafficEnv(vehicle="bicycle")
    env = EcoTrafficEnv(**FAST)
    env.reset(seed=0)
    with pytest.raises(ValueError, match="non-finite"):
        env.step(np.array([np.inf], dtype=np.float32))
    with pytest.raises(ValueError, match="outside the bounds"):
        env.step(np.array([1.5], dtype=np.float32))


def _vector_rollout(venv: EcoTrafficVectorEnv, seed: int, actions: np.ndarray) -> list[tuple[np.ndarray, np.ndarray]]:
    """(observation, reward) after the reset seeded ``seed`` and after each step of ``actions`` (steps, n, d)."""
    obs, _ = venv.reset(seed=seed)
    out = [(obs, np.zeros(venv.num_envs))]
    for a in actions:
        obs, r, te, tr, _ = venv.step(a)
        out.append((obs, r))
    return out


SAME_SEED_CASE = dict(n=4, steps=70, config=dict(lane_changes="box", vehicles_count=12, duration=3.0))


@pytest.mark.slow  # the first compile of the parallel step kernel: ~30 s of CPU that no other CI test needs
def test_two_threads_give_the_one_thread_traffic_to_the_bit():
    """The work split over 2 threads gives the 1-thread vector env's observations and rewards exactly, with the
    default observation and with the neighbour features."""
    n, steps, config = SAME_SEED_CASE["n"], SAME_SEED_CASE["steps"], SAME_SEED_CASE["config"]
    actions = np.random.default_rng(0).uniform(-1, 1, (steps, n, 2)).astype(np.float32)
    for extra in ({}, NEIGHBOURS):
        runs = [_vector_rollout(EcoTrafficVectorEnv(n, {**config, **extra}, threads=threads), 11, actions)
                for threads in (1, 2)]
        for (o1, r1), (o2, r2) in zip(*runs):
            assert np.array_equal(o1, o2) and np.array_equal(r1, r2)


def test_same_seed_same_episode_and_single_equals_vector_to_1e9():
    """Sub-env i of the vector env seeded s equals the single env seeded s + i, through autoresets (next-step
    rule); the 2-thread split is the slow test above."""
    n, steps, config = SAME_SEED_CASE["n"], SAME_SEED_CASE["steps"], SAME_SEED_CASE["config"]
    actions = np.random.default_rng(0).uniform(-1, 1, (steps, n, 2)).astype(np.float32)
    runs = [_vector_rollout(EcoTrafficVectorEnv(n, config, threads=1), 11, actions)]
    resets = 0
    for i in range(n):
        env = EcoTrafficEnv(config)
        obs, _ = env.reset(seed=11 + i)
        assert np.abs(obs - runs[0][0][0][i]).max() <= 1e-9
        done = False
        for k in range(steps):
            if done:
                obs, _ = env.reset()
                r, done = 0.0, False
                resets += 1
            else:
                obs, r, te, tr, _ = env.step(actions[k, i])
                done = te or tr
            assert np.abs(obs - runs[0][k + 1][0][i]).max() <= 1e-9
            assert abs(r - runs[0][k + 1][1][i]) <= 1e-9
    assert resets >= n  # the comparison went through autoresets
    other = EcoTrafficEnv(config)
    assert not np.array_equal(other.reset(seed=12)[0], EcoTrafficEnv(config).reset(seed=11)[0])


def test_same_step_autoreset_reports_the_final_observation():
    venv = EcoTrafficVectorEnv(2, dict(vehicles_count=5, duration=0.3), autoreset_mode="same_step")
    venv.reset(seed=0)
    for _ in range(2):
        obs, r, te, tr, info = venv.step(np.zeros((2, 1), dtype=np.float32))
        assert not (te | tr).any()
    obs, r, te, tr, info = venv.step(np.zeros((2, 1), dtype=np.float32))
    assert tr.all() and info["_final_obs"].all() and not np.array_equal(info["final_obs"], obs)
    assert np.allclose(info["t"], 0.0)  # the fresh episodes' info; the finished ones' is in final_info
    assert np.allclose(info["final_info"]["t"], 0.3)


def test_ego_is_roadloads_simulator_without_traffic():
    """No traffic: the ego's speed, distance and energy equal a standalone Simulator run on the same road with the
    same wheel forces (the EcoDrive command mapping) to 1e-9, grade and curvature included."""
    env = EcoTrafficEnv(vehicles_count=0, duration=20.0, road="motorway", road_seed=4, initial_speed=20.0)
    env.reset(seed=1)
    x0 = env.vehicles[0, tm.V_X]
    road = env.road_profile
    assert np.abs(road.curvature).max() > 1e-4 and np.abs(road.grade).max() > 0.005  # a real road
    ref = Simulator("bmw_i3", road, None, None, 0, initial_speed=20.0)
    scales = DriveScales.from_spec(ref.vehicle)
    energy = 0.0
    for u in [1.0, 1.0, 0.4, 0.0, -0.3, -0.05, 0.2, 0.6] * 5:
        _, _, te, tr, info = env.step(np.array([u], dtype=np.float32))
        st = ref.step(scales.wheel_force(float(np.float32(u)), ref.state.v), 10)
        energy += info["terms"]["energy"]
        assert info["speed"] == pytest.approx(st.v, abs=1e-9)
        assert info["s"] == pytest.approx(st.s, abs=1e-9)
        assert info["terms"]["progress"] > 0
    assert energy == pytest.approx(st.source_energy_total, rel=1e-9)
    # the ego kept its lane: its position along the lane is the distance its powertrain drove
    assert env.vehicles[0, tm.V_X] - x0 == pytest.approx(st.s, abs=1e-9)


def test_reward_is_the_sum_of_its_weighted_terms_and_a_collision_terminates():
    env = EcoTrafficEnv(vehicles_count=20, vehicles_density=2.0, duration=40.0)
    w = env.config.reward
    obs, info = env.reset(seed=2)
    crashed = False
    for _ in range(400):
        obs, r, te, tr, info = env.step(np.array([1.0], dtype=np.float32))  # full throttle into the traffic
        t = info["terms"]
        expected = w.scale * (w.progress * t["progress"] - w.energy * t["energy"]
                              + w.mechanical_energy * t["mechanical"] - w.collision * t["collision"]
                              - w.headway * t["headway"] - w.jerk * t["jerk"] - w.lane_change * t["lane_change"])
        assert r == pytest.approx(expected, rel=1e-12, abs=1e-12)
        assert set(t) == set(TERM_NAMES)
        if te:
            crashed = True
            break
    assert crashed and info["crashed"] and t["collision"] == 1.0 and r < -50
    assert t["headway"] > 0  # it closed in below 1 s of headway first


def test_safety_layer_prevents_rear_end_collisions_at_full_throttle():
    """Full throttle into the default traffic (and 1.5 x denser) crashes every episode; with the shield none."""
    crashes = {}
    for shield in (False, True):
        n = 0
        for seed in range(8):
            env = EcoTrafficEnv(vehicles_density=1.0 + 0.5 * (seed % 2), duration=15.0, shield={"enabled": shield})
            env.reset(seed=seed)
            for _ in range(150):
                _, _, te, tr, info = env.step(np.array([1.0], dtype=np.float32))
                if te or tr:
                    break
            n += int(info["crashed"])
        crashes[shield] = n
    assert crashes[False] == 8 and crashes[True] == 0


def test_reference_backend_runs_the_same_layout_on_highway_env():
    from gymnasium.utils.env_checker import check_env

    from roadload.gym.traffic_reference import HighwayTrafficEnv

    with pytest.raises(GymConfigError, match="curvature"):
        HighwayTrafficEnv(**FAST)
    env = HighwayTrafficEnv(curvature=False, **FAST)
    # built directly (no registry spec), so the checker cannot re-make it in another render mode and would only warn;
    # its rendering is highway-env's own, not this wrapper's
    check_env(env, skip_render_check=True)
    native = EcoTrafficEnv(curvature=False, **FAST)
    assert env.observation_space == native.observation_space and env.layout == native.layout
    obs, info = env.reset(seed=0)
    idx = {name: k for k, (name, _, _) in enumerate(env.layout)}
    assert obs[idx["ego_presence"]] == 1.0 and obs[idx["v"]] == pytest.approx(25.0 / 30.0)
    assert obs[idx["curvature@0m"]] == 0.0
    for _ in range(5):
        obs, r, te, tr, info = env.step(np.array([0.3], dtype=np.float32))
    assert obs[idx["command"]] == pytest.approx(0.3, abs=1e-6)
    assert obs[idx["source_power"]] * 50e3 == pytest.approx(info["terms"]["energy"] * 10.0, rel=1e-9)
    assert set(info) >= {"speed", "crashed", "lane", "s", "t", "source_energy_total", "front_gap", "shield_active"}


def _lane_leader_gap(veh: np.ndarray) -> tuple[float, float] | None:
    """(bumper-to-bumper gap [m], leader speed [m/s]) of the nearest vehicle ahead on the ego's lane, or None."""
    ahead = [k for k in range(1, veh.shape[0])
             if veh[k, tm.V_LANE] == veh[0, tm.V_LANE] and veh[k, tm.V_X] >= veh[0, tm.V_X]]
    if not ahead:
        return None
    k = min(ahead, key=lambda j: veh[j, tm.V_X])
    return veh[k, tm.V_X] - veh[0, tm.V_X] - tm.LENGTH, veh[k, tm.V_SPEED]


def test_safety_envelope_is_the_braking_bound_and_its_gap_inverts_it():
    """v_safe from the cap solves v T + v^2 / (2 b) = gap - margin + v_l^2 / (2 b_l) (the ego reacting after T and
    braking at b stops margin behind a leader braking at b_l), and at envelope_gap(v, v_l) the cap is exactly 0."""
    from roadload.gym.ecodrive import SHIELD_GAIN
    from roadload.gym.traffic import envelope_command, envelope_gap

    rng = np.random.default_rng(3)
    for _ in range(200):
        gap, v, v_l = rng.uniform(5, 120), rng.uniform(0, 35), rng.uniform(0, 35)
        t, b, b_l, margin = rng.uniform(0, 1), rng.uniform(2, 6), rng.uniform(3, 9), rng.uniform(0, 4)
        v_safe = envelope_command(gap, v, v_l, t, b, b_l, margin) / SHIELD_GAIN + v
        room = gap - margin + v_l ** 2 / (2 * b_l)
        if room > 0:
            assert v_safe * t + v_safe ** 2 / (2 * b) == pytest.approx(room, rel=1e-9)
        need = envelope_gap(v, v_l, t, b, b_l, margin)
        if need > 0:
            assert envelope_command(need, v, v_l, t, b, b_l, margin) == pytest.approx(0.0, abs=1e-9)
            assert envelope_command(need - 1.0, v, v_l, t, b, b_l, margin) < 0.0  # closer: the layer brakes
    # the default layer at highway-env's spawn: 25 m/s, 18 m behind a 22 m/s leader -> ~19 m/s allowed
    assert envelope_command(18.0, 25.0, 22.0, 0.3, 3.5, 6.0, 2.0) / SHIELD_GAIN + 25.0 == pytest.approx(18.8, abs=0.1)


def test_spawn_outside_envelope_moves_only_the_ego_back_to_the_envelope_gap():
    """highway-env's spawn puts the ego inside the safety layer's envelope on about half the episodes (its first
    command is then capped, at full braking at most); 'outside-envelope' never does: the ego is moved back to the
    envelope gap exactly where it was closer, left where it was not, and the traffic is the same vehicle for
    vehicle."""
    from roadload.gym.traffic import envelope_gap

    sh = {"enabled": True}
    spawns = {mode: EcoTrafficVectorEnv(64, shield=sh, spawn=mode, vehicles_density=1.5)
              for mode in ("highway-env", "outside-envelope")}
    for env in spawns.values():
        env.reset(seed=11)
    before, after = spawns["highway-env"].vehicles, spawns["outside-envelope"].vehicles
    np.testing.assert_array_equal(before[:, 1:], after[:, 1:])
    np.testing.assert_array_equal(before[:, 0, 1:], after[:, 0, 1:])  # all but the ego's x
    inside = moved = 0
    for i in range(64):
        lead0, lead1 = _lane_leader_gap(before[i]), _lane_leader_gap(after[i])
        if lead0 is None:
            assert after[i, 0, tm.V_X] == before[i, 0, tm.V_X]
            continue
        need = envelope_gap(25.0, lead0[1], 0.3, 3.5, 6.0, 2.0)
        assert lead1 is not None and lead1[0] >= need - 1e-9
        if lead0[0] < need:
            inside += 1
            moved += int(lead1[0] == pytest.approx(need, abs=1e-9))
        else:
            assert after[i, 0, tm.V_X] == before[i, 0, tm.V_X]
    assert inside >= 16 and moved == inside
    # the first step at full throttle: capped (at -1 at most) in the highway-env spawn, free outside the envelope
    throttle = np.ones((64, 1), dtype=np.float32)
    _, _, _, _, info = spawns["highway-env"].step(throttle)
    assert info["shield_active"].sum() >= inside
    _, _, _, _, info = spawns["outside-envelope"].step(np.zeros((64, 1), dtype=np.float32))
    assert not info["shield_active"].any()
    single = EcoTrafficEnv(shield=sh, **FAST)
    idx = {name: k for k, (name, _, _) in enumerate(single.layout)}
    for seed in range(20):
        single.reset(seed=seed)
        obs, _, _, _, info = single.step(np.array([1.0], dtype=np.float32))
        assert obs[idx["command"]] >= -1.0 and (info["shield_active"] or obs[idx["command"]] == 1.0)
    with pytest.raises(GymConfigError, match="spawn"):
        EcoTrafficEnv(spawn="behind")


def test_stopping_gap_spawn_puts_the_ego_at_its_stopping_distance_and_the_traffic_start_forces_no_braking():
    """'outside-envelope' leaves the ego exactly at the envelope of the leader's spawn speed, and the traffic,
    spawned at highway-env's spacing, brakes in its first seconds: a coasting ego is then capped. 'stopping-gap'
    moves it back to the envelope behind a vehicle at rest, margin + v T + v^2 / (2 b) = 2 + 7.5 + 625 / 7 m at
    25 m/s, where it was closer (untouched where not, the traffic vehicle for vehicle the same): coasting for the
    first 2 s is then never capped at the default density (it is on 43 of these 64 episodes after the
    'outside-envelope' spawn; denser traffic cuts in and brakes harder, which no spawn rule removes)."""
    stop_gap = 2.0 + 25.0 * 0.3 + 25.0 ** 2 / (2.0 * 3.5)
    sh = {"enabled": True}
    spawns = {mode: EcoTrafficVectorEnv(64, shield=sh, spawn=mode)
              for mode in ("highway-env", "outside-envelope", "stopping-gap")}
    for env in spawns.values():
        env.reset(seed=11)
    before, after = spawns["highway-env"].vehicles, spawns["stopping-gap"].vehicles
    np.testing.assert_array_equal(before[:, 1:], after[:, 1:])
    np.testing.assert_array_equal(before[:, 0, 1:], after[:, 0, 1:])
    moved = 0
    for i in range(64):
        lead0, lead1 = _lane_leader_gap(before[i]), _lane_leader_gap(after[i])
        if lead0 is not None and lead0[0] < stop_gap:
            assert lead1 is not None and lead1[0] == pytest.approx(stop_gap, abs=1e-9)
            moved += 1
        else:
            assert after[i, 0, tm.V_X] == before[i, 0, tm.V_X]
    assert moved >= 40
    coast = np.zeros((64, 1), dtype=np.float32)
    capped = {mode: 0 for mode in spawns}
    for _ in range(20):
        for mode, env in spawns.items():
            capped[mode] += int(env.step(coast)[4]["shield_active"].sum())
    assert capped["stopping-gap"] == 0 and capped["outside-envelope"] >= 100


def test_reference_backend_spawns_outside_the_envelope_too():
    from roadload.gym.traffic import envelope_gap
    from roadload.gym.traffic_reference import HighwayTrafficEnv

    for spawn in ("outside-envelope", "stopping-gap"):
        env = HighwayTrafficEnv(curvature=False, spawn=spawn, shield={"enabled": True}, **FAST)
        for seed in range(4):
            env.reset(seed=seed)
            ego = env.vehicle
            front, _ = env.road.neighbour_vehicles(ego, ego.lane_index)
            if front is not None:
                gap = ego.lane_distance_to(front) - tm.LENGTH
                v_lead = 0.0 if spawn == "stopping-gap" else front.speed
                assert gap >= envelope_gap(ego.speed, v_lead, 0.3, 3.5, 6.0, 2.0) - 1e-9
            _, _, _, _, info = env.step(np.array([0.0], dtype=np.float32))
            assert not info["shield_active"]


NEIGHBOURS = dict(neighbour_features=("ax", "lane_change", "cut_in_time"))


def _built_road(ego_to_b: float) -> np.ndarray:
    """Ego on lane 1 at 25 m/s; A on lane 2 turning into lane 1 (target 1); B on lane 0 at 25 m/s, 15 m behind a
    10 m/s car C and ``ego_to_b`` ahead of the ego, lane 1 empty ahead of it, its decision timer at 0.3 s."""
    veh = np.zeros((4, tm.N_V))
    for j, (x, lane, v, acc) in enumerate([(100.0, 1, 25.0, 0.0), (130.0, 2, 22.0, 0.7),
                                           (100.0 + ego_to_b, 0, 25.0, -1.5), (100.0 + ego_to_b + 20.0, 0, 10.0, 0.2)]):
        veh[j, tm.V_X], veh[j, tm.V_Y], veh[j, tm.V_SPEED], veh[j, tm.V_ACC] = x, 4.0 * lane, v, acc
        veh[j, tm.V_LANE] = veh[j, tm.V_TARGET_LANE] = lane
        veh[j, tm.V_TARGET_SPEED], veh[j, tm.V_DELTA] = max(v, 25.0), 4.0
    veh[1, tm.V_TARGET_LANE] = 1
    veh[2, tm.V_TIMER] = 0.3
    return veh


def test_neighbour_features_on_a_built_road():
    """Each observed vehicle's acceleration command, target lane - lane and time to cut into the ego's lane, in the
    Kinematics block's order. A (30 m ahead, turning in): 0 s. B (lane 0, a 10 m/s car 20 m ahead of its centre,
    lane 1 empty ahead, its timer at 0.3 s): MOBIL's own gain is huge, so the ego as its new follower decides. At
    70 m the ego's IDM behind B (traffic constants, dv = 0, d* = 10 + 25 x 1.5 = 47.5 m) is
    3 (0 - (47.5 / 70)^2) = -1.38 m/s^2, safe (> -2): the change is accepted and comes at B's next decision,
    delay - timer = 0.7 s. At 50 m it is 3 (0 - (47.5 / 50)^2) = -2.71 m/s^2: refused, the cap 2 s. C: cap."""
    from roadload.gym.traffic import neighbour_block

    env = EcoTrafficEnv(vehicles_count=3, kinematics_rows=5, **NEIGHBOURS)
    c = env.unwrapped._batch.constants
    expected = {70.0: [(0.7, -1, 0.0), (-1.5, 0, 0.7), (0.2, 0, 2.0)],  # A at 30 m, B at 70 m, C at 90 m
                50.0: [(0.7, -1, 0.0), (-1.5, 0, 2.0), (0.2, 0, 2.0)]}
    for ego_to_b, rows in expected.items():
        veh = _built_road(ego_to_b)
        order, key = np.zeros(4, np.int64), np.zeros(4)
        buf = np.zeros(5 * 5 + 4 * 3)
        tm.kinematics_block(veh, 4, 3, 5, False, order, key, buf)
        members, counts = tm.lane_index_arrays(4, 3)
        neighbour_block(veh, 4, 5, order, c, members, counts, buf, 25)
        got = buf[25:].reshape(4, 3)
        assert np.array_equal(got[:3], np.array(rows, float)), (ego_to_b, got)
        assert np.array_equal(got[3], [0.0, 0.0, 2.0])  # the missing row: nobody to cut in
    names = [n for n, _, _ in traffic_observation_layout(env.config)]
    assert names[-12:-9] == ["veh1_ax", "veh1_lane_change", "veh1_cut_in_time"]
    assert len(names) == 25 + 15 + 12  # Kinematics, powertrain, 4 rows x 3 features


def test_neighbour_features_only_append_to_the_default_observation():
    """With the option the dynamics, rewards and every default observation entry are bit for bit the default's;
    the vector form with the option equals the single env to 1e-9 (through autoresets; its 2-thread split is the
    slow test above); bad values are refused naming the field."""
    n, steps = 3, 45
    config = dict(vehicles_count=15, duration=2.0, vehicles_density=2.0, spawn="stopping-gap", kinematics_rows=8)
    actions = np.random.default_rng(3).uniform(-1, 1, (steps, n, 1)).astype(np.float32)
    runs = [_vector_rollout(EcoTrafficVectorEnv(n, {**config, **extra}, threads=1), 5, actions)
            for extra in ({}, NEIGHBOURS)]
    n_default = runs[0][0][0].shape[1]
    assert runs[1][0][0].shape[1] == n_default + 7 * 3
    for (o0, r0), (o1, r1) in zip(*runs):
        assert np.array_equal(o0, o1[:, :n_default]) and np.array_equal(r0, r1)
    tail = np.concatenate([o[:, n_default:] for o, _ in runs[1]])
    assert (tail[:, 2::3] < 1.0).any() and (tail[:, 0::3] != 0).any()  # cut-in times and accelerations were seen
    env = EcoTrafficEnv({**config, **NEIGHBOURS})
    for i in range(n):
        obs, _ = env.reset(seed=5 + i)
        done = False
        for k in range(steps):
            if done:
                obs, _ = env.reset()
                done = False
            else:
                obs, r, te, tr, _ = env.step(actions[k, i])
                done = te or tr
            assert np.abs(obs - runs[1][k + 1][0][i]).max() <= 1e-9
    with pytest.raises(GymConfigError, match="neighbour_features"):
        EcoTrafficEnv(neighbour_features=("ay",))
    with pytest.raises(GymConfigError, match="neighbour_features.*at most once"):
        EcoTrafficEnv(neighbour_features=("ax", "ax"))
    with pytest.raises(GymConfigError, match="reset options .*neighbour_features"):
        env.reset(options={"neighbour_features": ()})


def test_neighbour_features_pass_the_checker_and_the_reference_backend_observes_them():
    """check_env with the option; highway-env's backend fills the same entries from its own vehicles (their
    acceleration command, target lane, MOBIL and timer) in the Kinematics block's order."""
    from gymnasium.utils.env_checker import check_env

    from roadload.gym.traffic_reference import HighwayTrafficEnv

    check_env(gym.make("roadload/EcoTraffic-v0", **FAST, **NEIGHBOURS).unwrapped)
    env = HighwayTrafficEnv(curvature=False, vehicles_density=2.0, **FAST, **NEIGHBOURS)
    assert env.layout == EcoTrafficEnv(curvature=False, **FAST, **NEIGHBOURS).layout
    idx = {name: k for k, (name, _, _) in enumerate(env.layout)}
    env.reset(seed=3)
    for _ in range(3):
        obs, *_ = env.step(np.array([0.0], dtype=np.float32))
    close = env.road.close_objects_to(env.vehicle, env.PERCEPTION_DISTANCE, count=4, see_behind=False,
                                      vehicles_only=True)
    assert len(close) == 4
    for r, v in enumerate(close, start=1):
        assert obs[idx[f"veh{r}_ax"]] == pytest.approx(v.action["acceleration"] / 6.0, abs=1e-6)
        assert obs[idx[f"veh{r}_lane_change"]] == v.target_lane_index[2] - v.lane_index[2]
        assert 0.0 <= obs[idx[f"veh{r}_cut_in_time"]] <= 1.0
