"""Effects (drifting parameters, disturbances, sensor faults), sensors and the built-in driver."""

import numpy as np
import pytest

from roadload.envs import Action, DriverConfig, Simulator, get_preset, simulate
from roadload.road_profiles import DriveCycle
from roadload.units import G


def test_wind_statistics_and_headwind_drag(straight_road):
    r = straight_road(6000.0)
    calm = simulate("gt_rwd", r, seed=1)
    windy = simulate("gt_rwd", r, effects="wind:mean_speed=6,gust_std=1.5,direction=3.14159,direction_std=0", seed=1)
    ws = windy.true("wind_speed")
    assert ws.mean() == pytest.approx(6.0, abs=0.6)
    assert ws.std() == pytest.approx(1.5, rel=0.35)
    assert np.all(np.abs(np.cos(windy.true("wind_angle"))) > 0.99)  # straight road: pure headwind
    # eq. 2.8a: u_x = v - v_w cos(psi_w) = v + v_w for a headwind, F_a = rho/2 c_x A u_x |u|
    spec = get_preset("gt_rwd")
    tr = windy.truth
    v_force = tr["speed"].shift(1)  # forces act on the speed at the start of each 10-ms step
    expected = 0.5 * tr["air_density"] * spec.aero.drag_area * (v_force + ws) ** 2
    sel = tr["speed"] > 5
    assert np.allclose(tr["aero_force"][sel], expected[sel], rtol=1e-6)
    assert windy.meta["energy"]["aero_loss"] > 1.2 * calm.meta["energy"]["aero_loss"]


def test_drag_area_winter_wet_and_bank_truth(straight_road):
    spec = get_preset("gt_rwd")
    curvy = straight_road(3000.0, curvature=lambda s: 0.004 * np.sin(s / 300.0))
    t = simulate(spec, curvy, effects="drag_area:roof_box=0.25,toggle_rate=0;winter_tires;wet_road;road_bank",
                 seed=2)
    assert np.allclose(t.true("drag_area"), spec.aero.drag_area * 1.25)
    assert np.allclose(t.true("rolling_resistance_f0"), spec.tires.rolling_resistance_f0 * 1.15 * 1.1)
    assert np.allclose(t.true("rolling_resistance_f1"), spec.tires.rolling_resistance_f1 * 1.15 * 1.1 + 1e-4)
    assert np.allclose(t.true("cornering_stiffness_front"), spec.tires.cornering_stiffness_front * 0.85)
    bank = t.true("bank")
    curv = t.true("curvature")
    assert np.allclose(bank, np.clip(15.0 * curv, -0.06, 0.06))
    # the lateral accelerometer senses tire forces: a_y - g sin(bank) (+ body roll)
    tr = t.truth
    roll = spec.body.roll_gradient * tr["lateral_acceleration"]
    sensed = tr["lateral_acceleration"] - G * np.sin(bank) * np.cos(tr["grade"]) + G * np.sin(roll)
    assert np.allclose(tr["specific_force_y"], sensed, atol=1e-9)
    # superelevation lowers the side force, hence the cornering resistance
    flat = simulate(spec, curvy, effects="drag_area:roof_box=0.25,toggle_rate=0;winter_tires;wet_road", seed=2)
    assert t.meta["energy"]["cornering_loss"] < 0.9 * flat.meta["energy"]["cornering_loss"]


def test_drag_area_toggles_are_recorded(straight_road):
    t = simulate("bmw_i3", straight_road(8000.0), effects="drag_area:toggle_rate=200", seed=3)
    f = t.true("drag_area_factor")
    assert set(np.round(np.unique(f), 6)) <= {1.0, 1.02, 1.05, 1.07}
    assert len(np.unique(f)) >= 3


def test_oil_temperature_warms_and_losses_fall(straight_road):
    r = straight_road(12000.0, limit=30.0)
    cold = simulate("gt_rwd", r, effects="oil_temperature", seed=4)
    warm = simulate("gt_rwd", r, seed=4)
    oil = cold.true("oil_temperature")
    phi = cold.true("drivetrain_loss_factor")
    assert oil[0] == pytest.approx(293.15, abs=0.1) and oil[-1] > oil[0] + 10.0
    assert phi[0] == pytest.approx(1.6, abs=1e-3) and phi[-1] < phi[0]
    e_cold, e_warm = cold.meta["energy"], warm.meta["energy"]
    assert e_cold["gearbox_loss"] > 1.2 * e_warm["gearbox_loss"]
    assert np.all(warm.true("drivetrain_loss_factor") == 1.0)


def test_brake_pad_friction_fades_with_disc_temperature(straight_road):
    downhill = straight_road(4000.0, grade=-0.08, limit=15.0)
    t = simulate("gt_rwd", downhill, effects="brake_pad_drift:random_walk_std=0", seed=5)
    disc = t.true("brake_disc_temperature")
    mu = t.true("brake_friction_coefficient")
    assert disc.max() > disc[0] + 40.0
    expected = 0.4 * (1 - 6e-4 * (disc[:-1] - 323.15))  # friction from the disc temperature at the step start
    assert np.allclose(mu[1:], expected, rtol=1e-9)
    # nominal pressure -> the true brake force is lower when the pads fade
    tr = t.truth
    hot = (tr["brake_pressure_front"] > 2e5) & (disc > 340)
    assert hot.sum() > 100


def test_barometric_pressure_and_auxiliary_load(straight_road):
    hill = straight_road(4000.0, grade=0.06, limit=20.0)
    t = simulate("bmw_i3", hill, effects="barometric;auxiliary_load:power=2000", seed=6)
    h = t.true("elevation")
    assert np.allclose(t.true("air_pressure"), 101325.0 * np.exp(-h / 8434.5))
    base = simulate("bmw_i3", hill, seed=6)
    extra = t.meta["energy"]["source"] - base.meta["energy"]["source"]
    assert extra == pytest.approx(2000.0 * t.duration, rel=0.05)  # battery chemical energy incl. R I^2


def test_accelerometer_reads_grade_as_in_eq_5_2(straight_road):
    spec = get_preset("gt_rwd").replace(**{"body.pitch_gradient": 0.0})
    hill = straight_road(3000.0, grade=lambda s: 0.05 * np.sin(s / 300.0))
    t = simulate(spec, hill, seed=7)
    tr = t.truth
    theta = np.arcsin(np.clip((tr["specific_force_x"] - tr["acceleration"]) / G, -1, 1))
    assert np.allclose(theta, tr["grade"], atol=1e-9)
    # measured accel_x = that reading + noise, quantised (no bias without the effect)
    m = t.measured
    err = m["accel_x"].to_numpy() - np.interp(m["t"], tr["t"] + 0.02, tr["specific_force_x"])
    assert abs(np.mean(err)) < 0.01 and np.std(err) == pytest.approx(0.08, rel=0.25)


def test_sensor_outliers_dropouts_latency_bias_and_torque_error(straight_road):
    r = straight_road(4000.0)
    clean = simulate("gt_rwd", r, seed=8)
    sim = Simulator("gt_rwd", r, effects="sensor_outliers:rate=0.01,channels=outputs;sensor_dropouts:rate=600;"
                    "sensor_latency:extra=0.1;torque_model_error:gain_error=0.1,offset=20;sensor_bias", seed=8)
    sim.run()
    faulty = sim.to_trip()
    n = min(len(clean), len(faulty))
    # outliers only in the output channels, at about the configured rate
    tq = faulty.measured["drive_torque"].to_numpy()[:n]
    te = faulty.true("engine_torque")
    lat = int(round((0.03 + 0.1) / 0.01))
    model = np.concatenate([np.full(lat, te[0]), te[:-lat]])[:n] * 1.1 + 20.0
    dev = np.abs(tq - model)
    valid = np.isfinite(dev)
    rate = np.mean(dev[valid] > 40.0)
    assert 0.006 < rate < 0.014
    assert np.median(dev[valid]) < 3.0  # gain/offset error and latency modelled exactly
    # dropouts: NaN runs in every channel at the same samples
    nan = faulty.measured["vehicle_speed"].isna().to_numpy()
    assert 0.02 < nan.mean() < 0.2
    assert np.array_equal(nan, faulty.measured["accel_x"].isna().to_numpy())
    # bias: the mean accelerometer error is the (seeded, random) bias of the sensor model
    ax_err = (faulty.measured["accel_x"] - np.interp(faulty.t, faulty.truth["t"] + 0.12,
                                                      faulty.truth["specific_force_x"])).dropna()
    bias = sim.sensor_model.bias[sim.sensor_model.names.index("accel_x")]
    assert bias != 0.0 and ax_err.mean() == pytest.approx(bias, abs=0.004)
    assert np.all(sim.sensor_model.bias[[sim.sensor_model.names.index(c) for c in ("accel_y", "yaw_rate")]] != 0)
    # inputs are clean of outliers
    vs = faulty.measured["vehicle_speed"].to_numpy()
    v_true = np.interp(faulty.t, faulty.truth["t"] + 0.13, faulty.truth["speed"]) * 1.003
    assert np.nanmax(np.abs(vs - v_true)) < 0.5


def test_missing_samples_mode_removes_rows(straight_road):
    t = simulate("bmw_i3", straight_road(2000.0), effects="sensor_dropouts:rate=600,mode=missing", seed=9)
    dt = np.diff(t.t)
    assert dt.max() > 0.05 and np.isclose(np.median(dt), 0.01)
    assert not t.measured.isna().any().any()
    assert len(t.truth) > len(t)


def test_poor_excitation_cruise_stretches_hold_speed(straight_road):
    r = straight_road(20000.0, limit=25.0)
    t = simulate("gt_rwd", r, effects="poor_excitation:fraction=0.5,stretch_length=5000", seed=10)
    free = simulate("gt_rwd", r, seed=10)

    def spread(trip, lo, hi):
        tr = trip.truth
        sel = (tr["position"] > lo) & (tr["position"] < hi)
        return tr["speed"][sel].std()
    # compare the same stretch: one of the two 5-km stretches in the middle must be a cruise stretch
    cruise_std = min(spread(t, 5500, 9500), spread(t, 10500, 14500))
    free_std = min(spread(free, 5500, 9500), spread(free, 10500, 14500))
    assert cruise_std < 0.3 * free_std


def test_driver_respects_speed_limits_curves_and_stops(straight_road):
    cfg = DriverConfig(lateral_acceleration_limit=2.0)
    curvy = straight_road(6000.0, curvature=lambda s: np.where((s > 2000) & (s < 2600), 0.02, 0.0), limit=27.0,
                 stops=[4500.0])
    t = simulate("gt_rwd", curvy, driver=cfg, seed=11)
    tr = t.truth
    assert np.mean(tr["speed"] <= 27.0 + 0.3) > 0.999
    in_curve = (tr["position"] > 2050) & (tr["position"] < 2550)
    assert np.abs(tr["lateral_acceleration"][in_curve]).max() < 2.0 * 1.2
    assert tr["speed"][in_curve].max() < np.sqrt(2.0 / 0.02) * 1.1
    stopped = tr["position"][tr["speed"] < 0.01]
    assert np.any(np.abs(stopped - 4500.0) < 6.0)
    assert tr["position"].iloc[-1] >= 6000.0 - 1e-6
    # the path follows the road
    assert np.abs(tr["path_curvature"][in_curve] - 0.02).mean() < 0.002


def test_driver_follows_a_drive_cycle():
    time = np.arange(0.0, 201.0)
    speed = np.interp(time, [0, 10, 40, 80, 100, 130, 160, 190, 200], [0, 0, 15, 15, 25, 25, 8, 0, 0])
    cycle = DriveCycle("trapezoids", time, speed)
    t = simulate("bmw_i3", cycle, seed=12)
    tr = t.truth
    ref = np.interp(tr["t"], time, speed)
    assert t.duration == pytest.approx(200.0, abs=0.05)
    assert np.sqrt(np.mean((tr["speed"] - ref) ** 2)) < 0.4
    assert tr["position"].iloc[-1] == pytest.approx(cycle.distance, rel=0.02)


def test_external_steering_and_gear_requests(straight_road):
    sim = Simulator("gt_rwd", straight_road(3000.0), seed=0, initial_speed=20.0)
    for _ in range(20):
        r = sim.step(Action(traction_force=1200.0, gear=4), n_substeps=10)
    assert r.gear == 4
    for _ in range(30):
        r = sim.step(Action(gear=0), n_substeps=10)
    assert r.gear == 0 and r.clutch == 0.0
    assert abs(r.engine_speed - get_preset("gt_rwd").drivetrain.engine.idle_speed) < 5.0
