"""The limit of a drive at the IDM follower's speed (roadload.experiments.rl.traffic_limit): the wall behind the
traffic, the follower's drive in the model, and the limit against analytic cases on a flat road."""

import numpy as np
import pytest

from roadload.experiments.rl.traffic_limit import FollowerTrip, earliest_times, episode_limit
from roadload.gym.config import EcoTrafficConfig

FLAT = EcoTrafficConfig(road=None, curvature=False, duration=20.0)


def _trip(v: np.ndarray, dt: float = 0.1, gap: np.ndarray | None = None) -> FollowerTrip:
    t = np.arange(v.size) * dt
    s = np.concatenate([[0.0], np.cumsum(0.5 * (v[1:] + v[:-1]) * dt)])
    return FollowerTrip(seed=7, t=t, s=s, v=v, gap=np.full(v.size, np.inf) if gap is None else gap,
                        energy_J=0.0, crashed=False)


def test_earliest_times_follow_the_wall_and_a_later_cut_in_binds_earlier_times():
    v = np.full(101, 20.0)  # 10 s at 20 m/s
    # a leader 30 m ahead at the ego's speed: the wall at s + 28 m; from t = 5 s a car cuts in 10 m ahead
    gap = np.where(np.arange(101) * 0.1 < 5.0, 30.0, 10.0)
    trip = _trip(v, gap=gap)
    nodes = np.array([10.0, 50.0, 109.0, 120.0, 190.0])
    lb = earliest_times(trip, nodes, 2.0)
    # before the cut-in the wall is s + 28 (node 50 m at 1.1 s); after it s + 8, and its running minimum reaches
    # back: from 4 s on the wall stays at s(5 s) + 8 = 108 m, so 109 m is open only at 5.1 s (not at 4.1 s, where
    # the wall of the first car alone would have been)
    np.testing.assert_allclose(lb, [0.0, 1.1, 5.1, 5.6, 9.1], atol=1e-9)
    # the follower itself is never earlier than the bound
    assert np.all(np.interp(nodes, trip.s, trip.t) >= lb - 1e-9)


def test_constant_speed_on_a_flat_road_has_no_headroom():
    """On a flat road at constant speed the constant-speed drive is the optimum (the energy is convex in speed):
    the limit equals the follower's own model energy."""
    res = episode_limit(FLAT, _trip(np.full(201, 22.0)))
    assert abs(res["grid_time_s"] - 20.0) < 1e-6
    assert res["headroom_free_Wh_per_km"] == pytest.approx(0.0, abs=0.02)
    assert res["headroom_behind_Wh_per_km"] == pytest.approx(0.0, abs=0.02)
    assert res["follower_accel_max"] == pytest.approx(0.0, abs=1e-9)


def test_a_speed_oscillation_costs_energy_the_limit_recovers_and_a_wall_ahead_takes_part_of_it_back():
    """A +-2 m/s oscillation at the same trip time and end speed draws more than the steady drive: the limit finds
    the difference (limit near the steady drive's energy). With the wall at the follower's own position the limit
    may never be ahead of it: where the follower leads the steady drive (speed 22 + 2 sin) the wall does not bind;
    where it lags (22 - 2 sin) the steady drive is cut off and less is left to save, never less than nothing."""
    t = np.arange(201) * 0.1
    steady = episode_limit(FLAT, _trip(np.full(201, 22.0)))
    for sign in (1.0, -1.0):
        wavy = _trip(22.0 + sign * 2.0 * np.sin(2 * np.pi * t / 10.0))
        free = episode_limit(FLAT, wavy)
        assert free["headroom_free_Wh_per_km"] > 5.0
        # same trip time, end speed and distance: the limit is the steady drive's energy
        assert free["limit_free_Wh_per_km"] == pytest.approx(steady["follower_model_Wh_per_km"], rel=0.01)
        assert free["headroom_behind_Wh_per_km"] == pytest.approx(free["headroom_free_Wh_per_km"], abs=0.02)
        wavy.gap = np.full(t.size, 2.0)  # the wall: the follower's own position
        walled = episode_limit(FLAT, wavy)
        assert walled["headroom_free_Wh_per_km"] == pytest.approx(free["headroom_free_Wh_per_km"], abs=1e-6)
        if sign > 0:
            assert walled["headroom_behind_Wh_per_km"] == pytest.approx(free["headroom_free_Wh_per_km"], abs=0.02)
        else:
            assert -0.02 < walled["headroom_behind_Wh_per_km"] < free["headroom_free_Wh_per_km"] - 2.0


def test_scenario_variant_config_is_checked_before_any_episode(capsys):
    """--config takes a scenario variant as JSON; malformed JSON, a non-object and an out-of-range field are
    refused before anything runs, each naming the option or field and its expected value with its unit."""
    from roadload.experiments.rl.traffic_limit import main
    from roadload.gym.config import GymConfigError

    for text in ("{duration: 100", "[100]"):
        with pytest.raises(SystemExit):
            main(["--episodes", "2", "--config", text])
        assert "--config: expected a JSON object" in capsys.readouterr().err
    with pytest.raises(GymConfigError, match=r"duration.*\[s\], > 0 and <= 3600"):
        main(["--episodes", "2", "--config", '{"duration": -100}'])
    with pytest.raises(GymConfigError, match=r"speed_limit.*\[m/s\]"):
        main(["--episodes", "2", "--config", '{"speed_limit": 0}'])
    with pytest.raises(SystemExit):  # --after beyond the variant's own duration
        main(["--episodes", "2", "--after", "60", "--config", '{"duration": 50}'])
    assert "[0, 50) s" in capsys.readouterr().err
