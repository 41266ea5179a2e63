"""Effects added for the robustness testbed: outlier bursts, single-channel dropouts, wind / parameter ramps and
long cruise stretches."""

import numpy as np
import pytest

from roadload.envs import EffectsError, SensorConfigError, Simulator, simulate


def runs(mask):
    """Lengths of the runs of True in a boolean array."""
    d = np.diff(np.concatenate([[0], mask.astype(int), [0]]))
    return np.flatnonzero(d == -1) - np.flatnonzero(d == 1)


def test_outlier_bursts_have_the_requested_length_on_the_selected_channel(straight_road):
    sim = Simulator("gt_rwd", straight_road(4000.0),
                    effects="sensor_outliers:rate=0.001,magnitude=5,burst_length=25,channel=drive_torque", seed=3)
    for _ in range(900):  # step API: observe() must equal the trip's rows, also across chunk boundaries
        sim.step(None)
    obs = sim.observe()
    sim.run()
    trip = sim.to_trip()
    clean = simulate("gt_rwd", straight_road(4000.0), seed=3)
    n = min(len(trip), len(clean))
    dev = np.abs(trip.measured["drive_torque"].to_numpy()[:n] - clean.measured["drive_torque"].to_numpy()[:n])
    lengths = runs(dev > 1e-9)
    assert lengths.size >= 5
    assert lengths.min() == 25 and np.mean(lengths == 25) > 0.8  # overlapping bursts merge into longer runs
    # every other channel untouched
    for ch in ("vehicle_speed", "accel_x", "brake_pressure_front"):
        np.testing.assert_array_equal(trip.measured[ch].to_numpy()[:n], clean.measured[ch].to_numpy()[:n])
    row = trip.measured.iloc[8999]  # 900 steps x 10 substeps
    assert obs["drive_torque"] == row["drive_torque"]
    # burst_length 1 is the old behaviour, bit for bit
    a = simulate("gt_rwd", straight_road(1500.0), effects="sensor_outliers:rate=0.01", seed=4)
    b = simulate("gt_rwd", straight_road(1500.0), effects="sensor_outliers:rate=0.01,burst_length=1", seed=4)
    np.testing.assert_array_equal(a.measured.to_numpy(), b.measured.to_numpy())


def test_dropouts_on_a_single_channel_and_clear_errors(straight_road):
    t = simulate("gt_rwd", straight_road(3000.0), effects="sensor_dropouts:rate=600,channel=accel_x", seed=5)
    nan = t.measured.isna()
    assert 0.02 < nan["accel_x"].mean() < 0.3
    assert not nan.drop(columns=["accel_x"]).any().any()
    two = simulate("gt_rwd", straight_road(1500.0), effects="sensor_dropouts:rate=600,channel=accel_x+yaw_rate", seed=5)
    assert two.measured["accel_x"].isna().any() and two.measured["yaw_rate"].isna().any()
    assert not two.measured["vehicle_speed"].isna().any()
    with pytest.raises(SensorConfigError, match="no_such_channel"):
        Simulator("gt_rwd", straight_road(), effects="sensor_dropouts:channel=no_such_channel")
    with pytest.raises(SensorConfigError, match="mode 'nan'"):
        Simulator("gt_rwd", straight_road(), effects="sensor_dropouts:channel=accel_x,mode=missing")
    with pytest.raises(SensorConfigError, match="whole number"):
        Simulator("gt_rwd", straight_road(), effects="sensor_outliers:burst_length=2.5")
    with pytest.raises(EffectsError, match="burst_length"):
        Simulator("gt_rwd", straight_road(), effects="sensor_outliers:burst_length=0")


def test_headwind_ramp_in_truth_and_tractive_force(straight_road):
    r = straight_road(6000.0)
    t = simulate("gt_rwd", r, effects="wind_ramp:onset=100,ramp=30,final_speed=8", seed=6, duration=180.0)
    tr = t.truth
    time, w = tr["t"].to_numpy(), tr["wind_speed"].to_numpy()
    assert np.all(w[time <= 100.0 - 0.01] == 0.0)
    assert np.allclose(w[time >= 130.01], 8.0)
    mid = (time > 101.0) & (time < 129.0)  # linear in between (one substep late: applied at the substep start)
    assert np.allclose(w[mid], 8.0 * (time[mid] - 0.01 - 100.0) / 30.0, atol=1e-9)
    assert np.allclose(np.cos(tr["wind_angle"].to_numpy()[time > 131]), -1.0, atol=1e-3)  # straight road: headwind
    # the aerodynamic force is the analytic headwind drag 0.5 rho c_x A (v + v_w)^2 ...
    v_prev = np.concatenate([[0.0], tr["speed"].to_numpy()[:-1]])
    drag = 0.5 * tr["air_density"] * tr["drag_area"] * (v_prev + w) ** 2
    after = time > 131.0
    np.testing.assert_allclose(tr["aero_force"][after], drag[after], rtol=1e-9)
    # ... and the tractive force rises by the drag difference of the wind (driver holds the speed)
    before = (time > 60.0) & (time < 98.0)
    late = (time > 140.0) & (time < 178.0)
    fx = tr["tractive_force"].to_numpy()
    rise = fx[late].mean() - fx[before].mean()
    calm = 0.5 * tr["air_density"] * tr["drag_area"] * v_prev ** 2
    expected = drag[late].mean() - calm[before].mean()
    assert expected > 150.0 and rise == pytest.approx(expected, rel=0.1)


def test_parameter_ramps_in_truth_and_step_api_equals_run(straight_road):
    eff = ("mass_ramp:onset=1000,onset_unit=m,ramp=500,magnitude=300;drag_area_ramp:onset=40,ramp=0,magnitude=0.25;"
           "rolling_resistance_ramp:onset=20,ramp=40,magnitude=-0.3")
    sim = Simulator("gt_rwd", straight_road(3000.0), effects=eff, seed=7)
    sim.run(duration=100.0)
    tr = sim.to_trip().truth
    m0 = sim.vehicle.body.mass
    pos, time = tr["position"].to_numpy(), tr["t"].to_numpy()
    m = tr["mass"].to_numpy()
    assert np.all(m[pos < 999.0] == m0) and np.allclose(m[pos > 1502.0], m0 + 300.0)
    mid = (pos > 1100) & (pos < 1400)
    pos_prev = np.concatenate([[0.0], pos[:-1]])
    np.testing.assert_allclose(m[mid], m0 + 300.0 * (pos_prev[mid] - 1000.0) / 500.0)
    cxa = tr["drag_area"].to_numpy()
    assert np.all(cxa[time < 39.99] == cxa[0]) and np.allclose(cxa[time > 40.02], 1.25 * cxa[0])
    f0 = tr["rolling_resistance_f0"].to_numpy()
    assert np.allclose(f0[time > 60.02], 0.7 * f0[0]) and np.isclose(f0[np.searchsorted(time, 40.01)], 0.85 * f0[0])
    # the step API applies the same schedule: identical truth
    step = Simulator("gt_rwd", straight_road(3000.0), effects=eff, seed=7)
    for _ in range(1000):
        step.step(None)
    np.testing.assert_array_equal(step.to_trip().truth.to_numpy(), tr.to_numpy())
    # reset restores the unscheduled parameters
    step.reset()
    assert step.true_parameters()["mass"] == m0 and step.true_parameters()["drag_area"] == pytest.approx(cxa[0])


def longest_steady(trip, a_max=0.05):
    """Longest time [s] with |dv/dt| < a_max (truth acceleration) at speed > 5 m/s."""
    tr = trip.truth
    ok = (np.abs(tr["acceleration"].to_numpy()) < a_max) & (tr["speed"].to_numpy() > 5.0)
    return runs(ok).max() * 0.01 if ok.any() else 0.0


def test_cruise_holds_one_speed_for_600_s_despite_limit_changes(straight_road):
    limits = lambda s: np.where((s // 2000) % 2 == 0, 22.0, 27.0)  # noqa: E731 - limit changes every 2 km
    r = straight_road(17000.0, limit=limits, stops=(9000.0,))
    eff = "poor_excitation:fraction=1,stretch_length=16000,hold_speed=yes"
    held = simulate("gt_rwd", r, effects=eff, seed=8, duration=760.0)
    plain = simulate("gt_rwd", r, effects="poor_excitation:fraction=1,stretch_length=16000", seed=8, duration=760.0)
    assert longest_steady(held) >= 600.0
    assert longest_steady(plain) < 250.0
    tr = held.truth
    steady = (tr["t"] > 60.0) & (tr["t"] < 660.0)
    assert tr["speed"][steady].std() < 0.1 and tr["speed"][steady].min() > 20.0  # no stop at 9 km
    assert abs(tr["speed"][steady].mean() - (22.0 - 0.5)) < 0.3  # lowest limit minus the driver's margin
