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
                          "shield_steps": [0, 60, 0], "mechanical_kWh": [-0.01, 0.0, 0.002]})
    s = summarise_traffic(table, mechanical_weight=0.9).set_index("policy")
    assert s.loc["a", "energy_Wh_per_km"] == pytest.approx(100.0) and s.loc["a", "crashes"] == 1
    # speed used up is charged at 0.9 of its energy, speed gained credited
    assert s.loc["a", "net_energy_Wh_per_km"] == pytest.approx((0.15 + 0.009) * 1e6 / 1500.0)
    assert s.loc["b", "net_energy_Wh_per_km"] == pytest.approx((0.2 - 0.0018) * 1e6 / 800.0)
    assert s.loc["a", "mean_speed_kmh"] == pytest.approx(1500.0 / 60.0 * 3.6)
    assert s.loc["a", "shielded_steps"] == pytest.approx(0.1)
    seeds = pd.DataFrame({"backend": "native", "energy_Wh_per_km": [70.0, 72.0, 74.0], "net_energy_Wh_per_km": 80.0,
                          "mean_speed_kmh": 75.0, "mean_return": 45.0, "crashes": 0})
    ci = seed_intervals(seeds).iloc[0]
    assert ci.energy_Wh_per_km == 72.0
    assert ci.energy_Wh_per_km_ci95 == pytest.approx(stats.t.ppf(0.975, 2) * 2.0 / np.sqrt(3))


def test_short_ppo_run_trains_saves_and_is_evaluated(tmp_path, monkeypatch):
    import tempfile

    system_tmp = tmp_path / "system_tmp"
    system_tmp.mkdir()
    monkeypatch.setattr(tempfile, "tempdir", str(system_tmp))
    res = train_traffic(2048, tmp_path, seed=0, n_envs=8, env_config={"vehicles_count": 8, "duration": 4.0})
    assert res["path"].is_file() and res["timesteps"] >= 2048 and res["cpu_seconds"] > 0
    # SB3's default logger would leave an empty SB3-<date> folder in the system's temporary folder per run
    assert not list(system_tmp.glob("SB3-*"))
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


def test_step_distances_add_up_to_each_episodes_distance_across_same_step_autoresets():
    from roadload.experiments.rl.traffic_objective import EpisodeAccumulator, step_distance
    from roadload.gym.traffic import EcoTrafficVectorEnv

    env = EcoTrafficVectorEnv(3, config={"vehicles_count": 8, "duration": 2.0}, autoreset_mode="same_step")
    env.reset(seed=7)
    episodes = EpisodeAccumulator(3, 0.1)
    driven, finished = np.zeros(3), []
    for step in range(45):  # two episodes of 20 steps each and a few steps of a third
        if step == 3:
            env.step(np.full((3, 1), 0.2, np.float32))  # not counted: the accumulator starts over at its reset
            episodes.reset()
            env.reset(seed=7)
            driven[:] = 0.0
        _, _, term, trunc, info = env.step(np.full((3, 1), 0.2, np.float32))
        done = term | trunc
        dx = episodes.add(info, done)
        assert np.array_equal(dx, step_distance(info, done))
        driven += dx
        if done.any():
            finished += [(driven[i], info["final_info"]["s"][i]) for i in np.flatnonzero(done)]
            driven[done] = 0.0
    assert len(finished) == 6
    for got, expected in finished:
        assert expected > 40.0 and got == pytest.approx(expected, rel=1e-12)
    # the accumulator's ended episodes: per sub-env, in order, each the env's own distance over its 2 s
    assert [len(e) for e in episodes.ended] == [2, 2, 2]
    for i in range(3):
        for k, (distance, time) in enumerate(episodes.ended[i]):
            assert distance == pytest.approx(finished[3 * k + i][1], rel=1e-12) and time == pytest.approx(2.0)
    with pytest.raises(RLError, match=r"expected num_envs >= 1 and step_time > 0 s, got 2, 0.0"):
        EpisodeAccumulator(2, 0.0)


def test_speed_constraint_adds_the_priced_progress_and_its_multiplier_follows_the_pi_rule():
    from roadload.experiments.rl.traffic_objective import SpeedConstraint, step_distance
    from roadload.gym.traffic import EcoTrafficVectorEnv

    config = {"vehicles_count": 8, "duration": 2.0}
    plain = EcoTrafficVectorEnv(2, config=config, autoreset_mode="same_step")
    wrapped = SpeedConstraint(EcoTrafficVectorEnv(2, config=config, autoreset_mode="same_step"), reference=20.0,
                              price=0.1, step_time=0.1, window=10_000, margin=0.01, k_p=10.0, k_i=5.0)
    wrapped.multiplier = 0.5
    plain.reset(seed=3)
    wrapped.reset(seed=3)
    for _ in range(25):
        a = np.full((2, 1), 0.1, np.float32)
        _, r_p, term, trunc, info = plain.step(a)
        _, r_w, *_ = wrapped.step(a)
        assert r_w == pytest.approx(r_p + 0.5 * 0.1 * step_distance(info, term | trunc), abs=1e-12)
    # PI on e = (1.01 * 20 - v) / 20: 1 m/s short -> e = 0.05, I = 0.25, lambda = 0.5 + 0.25
    assert wrapped.update(19.2) == pytest.approx(0.75)
    # back on target: the proportional part vanishes, the integral holds
    assert wrapped.update(20.2) == pytest.approx(0.25)
    # 1.8 m/s too fast: e = -0.09, the integral and the multiplier floor at zero
    assert wrapped.update(22.0) == 0.0 and wrapped.integral == 0.0
    with pytest.raises(RLError, match="reference speed"):
        SpeedConstraint(plain, reference=0.0, price=0.1, step_time=0.1, window=10)
    with pytest.raises(RLError, match="margin"):
        SpeedConstraint(plain, reference=20.0, price=0.1, step_time=0.1, window=10, margin=0.5)


def test_the_multiplier_is_updated_from_the_mean_speed_of_the_episodes_ended_in_the_window():
    from roadload.experiments.rl.traffic_objective import SpeedConstraint
    from roadload.gym.traffic import EcoTrafficVectorEnv

    env = SpeedConstraint(EcoTrafficVectorEnv(2, config={"vehicles_count": 8, "duration": 2.0},
                                              autoreset_mode="same_step"),
                          reference=40.0, price=0.1, step_time=0.1, window=8, k_p=20.0, k_i=20.0)
    env.reset(seed=1)
    ended = []
    for _ in range(30):
        _, _, term, trunc, info = env.step(np.zeros((2, 1), np.float32))
        if (term | trunc).any():
            ended.append(info["final_info"]["s"].copy())
    # windows of 8 steps: none ends an episode before step 20, where both 2 s episodes end (one update); the next
    # episodes end at step 40
    assert len(ended) == 1 and len(env.history) == 1
    speed = float(ended[0].sum()) / (2 * 2.0)
    assert env.history[0][0] == pytest.approx(speed, rel=1e-9) and 20.0 < speed < 30.0
    assert env.multiplier == pytest.approx(40.0 * (40.0 - speed) / 40.0)  # (k_p + k_i) e, e = (40 - v) / 40


def test_paired_differences_compare_each_episode_with_the_reference_on_the_same_seed():
    from roadload.experiments.rl.traffic_training import MECHANICAL_WEIGHT, paired_differences

    rows = []
    for seed, (d_ref, d_pol) in enumerate([(800.0, 810.0), (900.0, 880.0), (1000.0, 1000.0)]):
        rows.append({"policy": "IDM follower", "backend": "native", "seed": seed, "distance_m": d_ref,
                     "energy_kWh": 0.08, "time_s": 40.0, "mechanical_kWh": 0.0})
        rows.append({"policy": "PPO seed 0", "backend": "native", "seed": seed, "distance_m": d_pol,
                     "energy_kWh": 0.07, "time_s": 40.0, "mechanical_kWh": -0.01})
    p = paired_differences(pd.DataFrame(rows)).iloc[0]
    d_e = np.array([70e3 / 810 - 80e3 / 800, 70e3 / 880 - 80e3 / 900, 70e3 / 1000 - 80e3 / 1000])
    d_n = d_e + MECHANICAL_WEIGHT * 10e3 / np.array([810.0, 880.0, 1000.0])
    d_v = np.array([10.0, -20.0, 0.0]) / 40.0 * 3.6
    assert p.episodes == 3 and p.at_least_as_fast == 2
    assert p.d_energy_Wh_per_km == pytest.approx(d_e.mean())
    assert p.d_net_energy_Wh_per_km == pytest.approx(d_n.mean())
    assert p.d_speed_kmh == pytest.approx(d_v.mean())
    assert p.d_speed_kmh_ci95 == pytest.approx(stats.t.ppf(0.975, 2) * d_v.std(ddof=1) / np.sqrt(3))


def test_the_trip_end_turns_the_time_limit_into_a_terminal_step():
    from roadload.experiments.rl.traffic_objective import TripEnd
    from roadload.gym.traffic import EcoTrafficVectorEnv

    config = {"vehicles_count": 8, "duration": 1.0}
    plain = EcoTrafficVectorEnv(2, config=config, autoreset_mode="same_step")
    wrapped = TripEnd(EcoTrafficVectorEnv(2, config=config, autoreset_mode="same_step"))
    plain.reset(seed=5)
    wrapped.reset(seed=5)
    ends = 0
    for _ in range(25):  # two 1 s trips
        a = np.full((2, 1), 0.1, np.float32)
        _, r_p, term_p, trunc_p, _ = plain.step(a)
        _, r_w, term_w, trunc_w, _ = wrapped.step(a)
        assert np.array_equal(r_p, r_w) and not trunc_w.any()
        assert np.array_equal(term_w, term_p | trunc_p)
        ends += int(trunc_p.sum())
    assert ends == 4


def test_lever_policies_keep_the_followers_mean_command_or_only_drop_its_braking():
    """Pulse and glide drives the follower's mean command (sigma-delta) with only 0 and the pulse; coasting only
    replaces braking by 0; the grade lever takes the grade force off the command (uphill: less)."""
    from roadload.experiments.rl.highway import _indices, idm_policy
    from roadload.experiments.rl.traffic_levers import coast_policy, grade_policy, pulse_glide_policy
    from roadload.gym.config import EcoTrafficConfig

    cfg = EcoTrafficConfig(shield={"enabled": True}, spawn="outside-envelope")
    idx = _indices(cfg)
    obs = np.zeros(len(idx), dtype=np.float32)
    obs[idx["v"][0]], obs[idx["front_gap"][0]] = 21.0 / 30.0, 60.0 / 100.0  # 21 m/s, 60 m behind an equal-speed car
    u = float(idm_policy(cfg)(obs)[0])
    assert 0.0 < u < 0.2
    glide = pulse_glide_policy(cfg, 0.2)
    commands = np.array([float(glide(obs)[0]) for _ in range(1000)])
    assert set(np.round(commands, 6)) == {0.0, 0.2} and commands.mean() == pytest.approx(u, abs=2e-4)
    close = obs.copy()
    close[idx["front_gap"][0]] = 0.3  # 30 m: the follower brakes
    assert float(idm_policy(cfg)(close)[0]) < 0.0 and float(coast_policy(cfg)(close)[0]) == 0.0
    assert float(coast_policy(cfg, 5.0)(close)[0]) == float(idm_policy(cfg)(close)[0])  # inside the envelope's reach
    assert float(coast_policy(cfg)(obs)[0]) == u
    uphill = obs.copy()
    uphill[idx["grade@0m"][0]] = 0.02 / 0.05
    assert float(grade_policy(cfg, 1.0)(uphill)[0]) < float(idm_policy(cfg)(uphill)[0]) - 0.03


def test_cut_in_regeneration_and_cah_levers_change_the_command_only_where_they_should():
    """A neighbour ahead on the next lane moving towards the ego's lane within the horizon becomes the leader (IDM
    brakes for it; the coasting variant only lifts off); one moving away or too slowly does not. Regeneration-limited
    braking floors the command at the regeneration force (about -0.29 at 25 m/s: 50 kW / 25 m/s over 0.5 m g); the
    CAH brakes less than IDM for a large closing speed at a gap that needs no hard braking."""
    from roadload.experiments.rl.highway import _indices, idm_policy
    from roadload.experiments.rl.traffic_levers import anticipation_policy, cah_policy, regen_limited_policy
    from roadload.gym.config import EcoTrafficConfig

    cfg = EcoTrafficConfig(shield={"enabled": True}, spawn="outside-envelope")
    idx = _indices(cfg)
    obs = np.zeros(len(idx), dtype=np.float32)
    obs[idx["v"][0]], obs[idx["front_gap"][0]] = 21.0 / 30.0, 80.0 / 100.0  # 21 m/s, 80 m behind an equal-speed car
    obs[idx["veh1_presence"][0]] = 1.0
    obs[idx["veh1_x"][0]] = 25.0 / 200.0  # 25 m ahead (20 m bumper to bumper), on the lane to the right (+4 m)
    obs[idx["veh1_y"][0]] = 4.0 / 12.0
    obs[idx["veh1_vy"][0]] = -1.5 / 80.0  # moving left, towards the ego's lane at 1.5 m/s: 2 m to go, 1.33 s
    follower = float(idm_policy(cfg)(obs)[0])
    assert follower > 0.0
    assert float(anticipation_policy(cfg, 2.0)(obs)[0]) < -0.1  # 20 m at 21 m/s: IDM brakes for it
    assert float(anticipation_policy(cfg, 1.0)(obs)[0]) == pytest.approx(follower)  # not within 1 s
    assert float(anticipation_policy(cfg, 2.0, coast=True)(obs)[0]) == 0.0
    away = obs.copy()
    away[idx["veh1_vy"][0]] = 1.5 / 80.0
    assert float(anticipation_policy(cfg, 4.0)(away)[0]) == pytest.approx(follower)
    fast = obs.copy()
    fast[idx["v"][0]], fast[idx["front_gap"][0]] = 25.0 / 30.0, 0.2  # 25 m/s, 20 m behind: the follower brakes hard
    assert float(idm_policy(cfg)(fast)[0]) == -1.0
    assert float(regen_limited_policy(cfg)(fast)[0]) == pytest.approx(-50e3 / 25.0 / (0.5 * 9.81 * 1400.0), rel=0.02)
    assert float(regen_limited_policy(cfg)(obs)[0]) == pytest.approx(follower)
    approach = obs.copy()
    approach[idx["v"][0]], approach[idx["front_gap"][0]] = 25.0 / 30.0, 0.55  # 55 m behind a car at 21 m/s
    approach[idx["front_closing_speed"][0]] = 4.0 / 30.0
    u_idm, u_cah = float(idm_policy(cfg)(approach)[0]), float(cah_policy(cfg)(approach)[0])
    assert u_idm < u_cah < 0.0


@pytest.mark.parametrize("bad", ["{bad", "[1, 2]"])
def test_lever_script_refuses_a_config_that_is_not_a_json_object(bad, capsys):
    from roadload.experiments.rl.traffic_levers import main

    with pytest.raises(SystemExit) as exc:
        main(["--config", bad])
    assert exc.value.code == 2
    assert "--config: expected a JSON object of EcoTraffic-v0 options" in capsys.readouterr().err


def test_the_two_sided_multipliers_rise_above_the_band_and_fall_below_it():
    from roadload.experiments.rl.traffic_objective import SpeedBand, SpeedConstraint
    from roadload.gym.traffic import EcoTrafficVectorEnv

    env = SpeedConstraint.band(EcoTrafficVectorEnv(2, config={"vehicles_count": 8, "duration": 2.0},
                                                   autoreset_mode="same_step"),
                               reference=20.0, price=0.1, step_time=0.1, window=10,
                               band=SpeedBand(lower=0.001, upper=0.004, k_p=10.0, k_i=5.0))
    # band 20.02 ... 20.08 m/s. 1 m/s too fast: excess (21 - 20.08) / 20 = 0.046, mu = 10 * 0.046 + 5 * 0.046
    assert env.update(21.0) == pytest.approx(-0.69) and env.multiplier == 0.0
    assert env.update(21.0) == pytest.approx(-(0.46 + 0.46))  # the integral keeps rising while too fast
    # inside the band near its top the ceiling is slack by 0.0015: mu eases off, lambda stays 0
    assert env.update(20.05) == pytest.approx(-(10 * -0.0015 + 0.46 - 5 * 0.0015))
    # 1 m/s too slow: e = (20.02 - 19.02) / 20 = 0.05 raises lambda; the ceiling's slack 0.053 empties mu
    assert env.update(19.02) == pytest.approx(10 * 0.05 + 5 * 0.05)
    assert env.upper_multiplier == 0.0 and env.upper_integral == pytest.approx(0.4525 - 5 * 0.053)
    assert env.integral == pytest.approx(0.25)
    assert [v for v, _, _ in env.history] == [21.0, 21.0, 20.05, 19.02]


def test_at_the_net_multiplier_minus_one_the_training_reward_is_the_reward_without_progress_pay():
    """Where the ceiling's multiplier cancels the pay for metres, the policy is trained on energy (and the
    mechanical-energy credit and penalties) alone: the same reward as an env whose progress weight is 0."""
    from roadload.experiments.rl.traffic_objective import SpeedConstraint
    from roadload.gym.traffic import EcoTrafficVectorEnv

    config = {"vehicles_count": 8, "duration": 2.0}
    energy_only = EcoTrafficVectorEnv(2, config={**config, "reward": {"progress": 0.0}}, autoreset_mode="same_step")
    wrapped = SpeedConstraint(EcoTrafficVectorEnv(2, config=config, autoreset_mode="same_step"), reference=20.0,
                              price=1e-4 * 1000.0, step_time=0.1, window=10_000, margin=0.001, upper=0.004)
    wrapped.upper_multiplier = 1.0
    energy_only.reset(seed=4)
    wrapped.reset(seed=4)
    paid = 0.0
    for k in range(30):  # across an autoreset
        a = np.full((2, 1), 0.3 if k < 15 else -0.2, np.float32)
        _, r_e, *_ = energy_only.step(a)
        _, r_w, *_ = wrapped.step(a)
        assert r_w == pytest.approx(r_e, abs=1e-9)
        paid += float(np.abs(r_e).sum())
    assert paid > 0.1  # the energy terms are not zero on this drive


@pytest.mark.parametrize("bad, message", [
    ('{"lower": 0.004, "upper": 0.001}', "must be below upper"),
    ('{"lower": -0.5}', "lower: Input should be greater than or equal to -0.2 (got -0.5)"),
    ('{"upper": 0.01, "k_p": -1}', "k_p: Input should be greater than or equal to 0"),
    ('{"upper": NaN}', "upper"),
    ('{"uper": 0.01}', "uper: unknown key"),
    ('{"integral_max": 0}', "integral_max: Input should be greater than 0 (got 0)"),
    ("[0.001, 0.004]", "must be a SpeedBand or a dict"),
    ("0.001,0.004", "expected JSON text"),
])
def test_a_bad_speed_band_is_refused_naming_the_field_value_and_range(bad, message, capsys):
    from roadload.experiments.rl.traffic_objective import speed_band
    from roadload.experiments.rl.traffic_training import main

    with pytest.raises(RLError) as err:
        speed_band(bad)
    assert message in str(err.value)
    with pytest.raises(SystemExit) as exit_:
        main(["--speed-band", bad, "--out", "/nonexistent/never-written"])
    assert exit_.value.code == 2 and message in capsys.readouterr().err


def test_a_floor_and_a_band_together_are_refused(tmp_path, capsys):
    from roadload.experiments.rl.traffic_objective import SpeedBand, SpeedConstraint
    from roadload.experiments.rl.traffic_training import main
    from roadload.gym.traffic import EcoTrafficVectorEnv

    default = SpeedBand()  # at or above the follower's pace, within +0.5 %
    assert 0.0 <= default.lower < default.upper <= 0.005
    with pytest.raises(SystemExit):
        main(["--speed-band", "{}", "--speed-constraint", "0.01", "--out", str(tmp_path / "run")])
    assert "give one (a floor or a band)" in capsys.readouterr().err and not (tmp_path / "run").exists()
    with pytest.raises(RLError, match="not both"):
        train_traffic(100, tmp_path / "run", speed_constraint=0.01, band=SpeedBand())
    assert not (tmp_path / "run").exists()
    with pytest.raises(RLError, match="margin < upper"):
        SpeedConstraint(EcoTrafficVectorEnv(2, config={"vehicles_count": 8}), reference=20.0, price=0.1,
                        step_time=0.1, window=10, margin=0.01, upper=0.01)



@pytest.mark.parametrize("module", ["traffic_fidelity", "traffic_training", "traffic_limit", "cut_in_diagnosis"])
def test_every_traffic_script_refuses_a_config_that_is_not_a_json_object(module, capsys):
    """One parser of the traffic scripts' --config: a clean usage error (exit 2) naming the option, not a traceback."""
    import importlib

    main = importlib.import_module(f"roadload.experiments.rl.{module}").main
    for bad in ("{bad", "[1, 2]"):
        with pytest.raises(SystemExit) as exc:
            main(["--config", bad])
        assert exc.value.code == 2
        assert "--config: expected a JSON object of EcoTraffic-v0 options" in capsys.readouterr().err


def _paired(policy_env_actions_base: bool, n_follower: int = 2, **kwargs):
    from roadload.experiments.rl.highway import idm_policy
    from roadload.experiments.rl.traffic_objective import PairedFollower, SpeedBand, SpeedConstraint
    from roadload.experiments.rl.traffic_training import ResidualActions
    from roadload.gym.config import EcoTrafficConfig, make_config
    from roadload.gym.traffic import EcoTrafficVectorEnv

    config = {"vehicles_count": 8, "duration": 2.0}
    idm = idm_policy(make_config(EcoTrafficConfig, config))
    env = EcoTrafficVectorEnv(2, config=config, autoreset_mode="same_step")
    if policy_env_actions_base:
        env = ResidualActions(env, idm, 0.3)
    follower = PairedFollower(EcoTrafficVectorEnv(n_follower, config=config, autoreset_mode="same_step"), idm, 0.1)
    band = SpeedBand(lower=0.001, upper=0.004, k_p=10.0, k_i=5.0)
    return SpeedConstraint.band(env, reference=40.0, price=0.1, step_time=0.1, window=8, band=band,
                                follower=follower, **kwargs), idm, config


def test_the_paired_reference_is_the_followers_mean_speed_on_the_same_episodes():
    """The follower env replays the training env's episodes: its speed in the history equals the IDM follower's
    driven alone on single envs seeded like the sub-envs (seed + i), and the policy's speed is its own drive's."""
    from roadload.gym.traffic import EcoTrafficEnv

    env, idm, config = _paired(False)
    env.reset(seed=5)
    own = 0.0
    for _ in range(20):  # both 2 s episodes end at step 20: one update
        _, _, term, trunc, info = env.step(np.full((2, 1), -0.3, np.float32))  # a light brake
        if (term | trunc).any():
            own = float(info["final_info"]["s"].sum())
    alone_distance, alone_time = 0.0, 0.0
    for i in range(2):
        single = EcoTrafficEnv(config)
        obs, _ = single.reset(seed=5 + i)
        done = False
        while not done:
            obs, _, term, trunc, info = single.step(idm(obs))
            alone_time += 0.1
            done = term or trunc
        alone_distance += float(info["s"])
    assert len(env.history) == 1
    speed, reference, net = env.history[0]
    assert reference == pytest.approx(alone_distance / alone_time, rel=1e-9)
    assert speed == pytest.approx(own / 4.0, rel=1e-9)
    # the fixed command runs 10 % ahead of the follower, which closes on its leader: above the band's ceiling
    # (1.004), mu = (k_p + k_i) x excess of the paired ratio, lambda 0
    excess = speed / reference - 1.004
    assert excess > 0.05 and net == pytest.approx(-(10.0 + 5.0) * excess, rel=1e-9)


def test_the_multipliers_act_on_the_paired_difference_not_on_the_fixed_reference():
    """The residual policy with a zero correction drives exactly as the follower: the paired relative speed is 0,
    so lambda = (k_p + k_i) x lower, although the window's speed is half the fixed reference of 40 m/s."""
    env, _, _ = _paired(True)
    env.reset(seed=[11, 12])
    for _ in range(20):
        env.step(np.zeros((2, 1), np.float32))
    (speed, reference, net), = env.history
    assert speed == reference and speed < 30.0
    assert net == pytest.approx((10.0 + 5.0) * 0.001, rel=1e-9) and env.upper_multiplier == 0.0


def test_a_bad_paired_reference_is_refused_naming_the_field_and_value(tmp_path, capsys):
    from roadload.experiments.rl.highway import idm_policy
    from roadload.experiments.rl.traffic_objective import PairedFollower
    from roadload.experiments.rl.traffic_training import main
    from roadload.gym.config import EcoTrafficConfig
    from roadload.gym.traffic import EcoTrafficVectorEnv

    with pytest.raises(RLError, match=r"follower num_envs: expected the training env's 2 sub-envs .*got 3"):
        _paired(False, n_follower=3)
    env, _, _ = _paired(False)
    with pytest.raises(RLError, match=r"reset seed: expected an integer seed for every sub-env .*got None"):
        env.reset()
    with pytest.raises(RLError, match=r"autoreset_mode: expected 'same_step'"):
        PairedFollower(EcoTrafficVectorEnv(2, config={"vehicles_count": 8}), idm_policy(EcoTrafficConfig()), 0.1)
    with pytest.raises(RLError, match="paired reference: applies to a speed constraint"):
        train_traffic(100, tmp_path / "run", paired_reference=True)
    with pytest.raises(SystemExit) as exc:
        main(["--paired-reference", "--out", str(tmp_path / "run")])
    assert exc.value.code == 2 and "--paired-reference: applies to a speed constraint" in capsys.readouterr().err
    assert not (tmp_path / "run").exists()


def test_the_relative_reward_is_the_reward_less_the_followers_on_the_same_episode_and_step():
    """With ``relative`` the training reward is the env reward less the paired IDM follower's of the same step (the
    multipliers 0 until the first update): equal to r - r_follower of two separately driven envs, and exactly 0
    for a residual policy with zero correction, which drives as the follower does, across an autoreset."""
    from roadload.gym.traffic import EcoTrafficVectorEnv

    env, idm, config = _paired(False, relative=True)
    own = EcoTrafficVectorEnv(2, config=config, autoreset_mode="same_step")
    alone = EcoTrafficVectorEnv(2, config=config, autoreset_mode="same_step")
    env.reset(seed=[3, 4])
    own.reset(seed=[3, 4])
    obs_alone, _ = alone.reset(seed=[3, 4])
    brake = np.full((2, 1), -0.3, np.float32)
    for _ in range(20):  # one 2 s episode: no multiplier update before its end
        _, r_rel, *_ = env.step(brake)
        _, r_own, *_ = own.step(brake)
        obs_alone, r_idm, *_ = alone.step(idm(obs_alone))
        assert np.all(np.abs(r_own - r_idm) > 1e-6)
        assert r_rel == pytest.approx(r_own - r_idm, abs=1e-12)
    zero, _, _ = _paired(True, relative=True)
    zero.reset(seed=[11, 12])
    for _ in range(45):  # two updates (lambda = (k_p + k_i) x lower > 0 after the first) and an autoreset
        _, r_rel, *_ = zero.step(np.zeros((2, 1), np.float32))
        assert np.all(r_rel == 0.0)
    assert len(zero.history) == 2 and zero.multiplier > 0


def test_a_relative_reward_without_the_paired_follower_is_refused(tmp_path, capsys):
    from roadload.experiments.rl.traffic_objective import SpeedBand, SpeedConstraint
    from roadload.experiments.rl.traffic_training import main
    from roadload.gym.traffic import EcoTrafficVectorEnv

    with pytest.raises(RLError, match=r"relative reward: needs the paired follower .*got follower None"):
        SpeedConstraint(EcoTrafficVectorEnv(2, config={"vehicles_count": 8}, autoreset_mode="same_step"),
                        reference=20.0, price=0.1, step_time=0.1, window=10, relative=True)
    with pytest.raises(RLError, match=r"relative reward: .*give the paired reference too"):
        train_traffic(100, tmp_path / "run", band=SpeedBand(), relative_reward=True)
    with pytest.raises(SystemExit) as exc:
        main(["--speed-band", "{}", "--relative-reward", "--out", str(tmp_path / "run")])
    assert exc.value.code == 2 and "--relative-reward: subtracts the paired follower's reward, give " \
        "--paired-reference too" in capsys.readouterr().err
    assert not (tmp_path / "run").exists()


def test_the_integral_cap_stops_the_windup_and_the_multiplier_unwinds_at_once():
    """Ten windows 5 % under the floor: without a cap the integral holds 10 x k_i x 0.05 = 2.5, with the cap 1.0 it
    holds 1.0; one window 0.25 % above the floor (inside the band) then leaves lambda = k_p e + I: 2.4625 without,
    0.9625 with the cap. The ceiling's integral is capped alike."""
    from roadload.experiments.rl.traffic_objective import SpeedBand, SpeedConstraint
    from roadload.gym.traffic import EcoTrafficVectorEnv

    def constraint(cap):
        band = SpeedBand(lower=0.0, upper=0.004, k_p=10.0, k_i=5.0, integral_max=cap)
        return SpeedConstraint.band(EcoTrafficVectorEnv(2, config={"vehicles_count": 8}, autoreset_mode="same_step"),
                                    reference=20.0, price=0.1, step_time=0.1, window=10, band=band)

    free, capped = constraint(None), constraint(1.0)
    for env in (free, capped):
        for _ in range(10):
            env.update(19.0)
    assert free.integral == pytest.approx(2.5) and capped.integral == 1.0
    assert free.update(20.05) == pytest.approx(2.4625) and capped.update(20.05) == pytest.approx(0.9625)
    for _ in range(10):  # 10 % above: the ceiling's integral rises by 5 x 0.096 per window, to the cap
        capped.update(22.0)
    assert capped.upper_integral == 1.0 and capped.upper_multiplier == pytest.approx(10.0 * 0.096 + 1.0)
    with pytest.raises(RLError, match=r"integral_max: expected 0 < integral_max <= 1000 .* got -1.0"):
        SpeedConstraint(EcoTrafficVectorEnv(2, config={"vehicles_count": 8}, autoreset_mode="same_step"),
                        reference=20.0, price=0.1, step_time=0.1, window=10, integral_max=-1.0)
