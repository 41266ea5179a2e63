"""The chapter-5 pipeline on a hand-made Trip built from known parameters (analytic truth)."""

import numpy as np
import pandas as pd
import pytest

from roadload.estimators.models import NominalParameters
from roadload.estimators.pipeline import (DrivetrainModel, PipelineError, PipelineSettings, SteeringGeometry,
                                          VehicleKnowledge, model_data, run_pipeline)
from roadload.trip import Trip
from roadload.units import G

X_TRUE = np.array([1850 * 0.0105, 1850.0, 0.5 * 1.2 * 0.64, 1850 ** 2 / 40000.0])   # M4 parameters
R_W, I_W, I_RED, I_D = 0.34, 4.4, (9.0, 4.0), 3.2
RATIOS = (3.1, 1.9)


def _knowledge():
    dt = DrivetrainModel(gear_ratios=RATIOS, final_drive=I_D, wheel_radius=R_W, wheel_inertia=I_W,
                         reduced_inertia=I_RED, gearbox_efficiency=(1.0, 1.0), gearbox_drag=(0.0, 0.0),
                         differential_efficiency=1.0)
    steer = SteeringGeometry(wheelbase=2.95, rear_axle_distance=1.45, steering_wheel_angle=(-9.0, 0.0, 9.0),
                             wheel_angle=(-0.6, 0.0, 0.6))
    nom = NominalParameters.from_physical(mass=1800.0, rolling_resistance_coefficient=0.012, drag_area=0.6,
                            cornering_stiffness=45000.0, coast_down=(200.0, 1.0, 0.4))
    return VehicleKnowledge("handmade", nom, dt, steer)


def invert_drivetrain(dt, wheel_torque, gear):
    """Engine torque T_E that makes the estimating side's drive-train model deliver `wheel_torque` (after the
    differential, before the reduced inertia) — the exact inverse of DrivetrainModel.rim_torque's loss model."""
    i_g = np.asarray(dt.gear_ratios)[gear - 1]
    eta_g = np.asarray(dt.gearbox_efficiency)[gear - 1]
    drag_g = np.asarray(dt.gearbox_drag)[gear - 1]
    t_w1 = wheel_torque + dt.differential_drag * dt.final_drive
    t_w1 = np.where(t_w1 >= 0, t_w1 / dt.differential_efficiency, t_w1 * dt.differential_efficiency)
    t_d = t_w1 / dt.final_drive + drag_g * i_g
    t_g = np.where(t_d >= 0, t_d / eta_g, t_d * eta_g)
    return t_g / i_g


def handmade_trip(duration=900.0, rate=100.0, events=True, knowledge=None, gears=(1, 2)):
    """100 Hz CAN channels whose tractive force is exactly A X_TRUE of eq. 5.6, made through the inverse of the
    estimating side's drive-train model (default: the lossless one of _knowledge())."""
    k = knowledge or _knowledge()
    dtm, geo = k.drivetrain, k.steering
    t = np.arange(0, duration, 1 / rate)
    v = 19 + 7 * np.sin(2 * np.pi * t / 97) + 3 * np.sin(2 * np.pi * t / 23 + 1)
    dv = 7 * 2 * np.pi / 97 * np.cos(2 * np.pi * t / 97) + 3 * 2 * np.pi / 23 * np.cos(2 * np.pi * t / 23 + 1)
    theta = 0.05 * np.sin(2 * np.pi * t / 151) + 0.02 * np.sin(2 * np.pi * t / 41)
    kappa = 0.012 * np.sin(2 * np.pi * t / 37) ** 3
    l, l34 = geo.wheelbase, geo.rear_axle_distance
    tan_dw = kappa * l / np.sqrt(1 - (kappa * l34) ** 2)       # eq. 5.3 solved for tan δ_W
    delta_s = np.interp(np.arctan(tan_dw), geo.wheel_angle, geo.steering_wheel_angle)
    force = (X_TRUE[0] * G * np.cos(theta) + X_TRUE[1] * (G * np.sin(theta) + dv) + X_TRUE[2] * v ** 2
             + X_TRUE[3] * v ** 4 * kappa ** 2 / 4)
    gear = np.where(v < 17.0, gears[0], gears[1])
    r_w = dtm.wheel_radius
    wheel_acc = dv / r_w
    i_red = np.asarray(dtm.reduced_inertia)[gear - 1]
    ratio = np.asarray(dtm.gear_ratios)[gear - 1] * dtm.final_drive
    drive_torque = invert_drivetrain(dtm, force * r_w + dtm.wheel_inertia * wheel_acc + i_red * wheel_acc, gear)
    wheel = v / r_w
    engine = wheel * ratio
    brake = np.zeros_like(t)
    clutch = np.ones_like(t)
    if events:
        brake[(t >= 300) & (t < 302)] = 30e5                  # braking 2 s
        engine[(t >= 400) & (t < 403)] *= 1.3                 # clutch slipping 3 s
        gear = gear.copy()
        gear[(t >= 500) & (t < 502)] = 0                      # neutral 2 s
    measured = pd.DataFrame({
        "t": t, "vehicle_speed": v, "accel_x": dv + G * np.sin(theta), "drive_torque": drive_torque,
        "engine_speed": engine, "gear": gear.astype(float), "clutch": clutch, "steering_wheel_angle": delta_s,
        "wheel_speed_fl": wheel, "wheel_speed_fr": wheel, "wheel_speed_rl": wheel, "wheel_speed_rr": wheel,
        "brake_pressure_front": brake, "brake_pressure_rear": 0.5 * brake,
    })
    units = {"t": "s", "vehicle_speed": "m/s", "accel_x": "m/s^2", "drive_torque": "N*m", "engine_speed": "rad/s",
             "gear": "1", "clutch": "1", "steering_wheel_angle": "rad", "brake_pressure_front": "Pa",
             "brake_pressure_rear": "Pa", **{f"wheel_speed_{w}": "rad/s" for w in ("fl", "fr", "rl", "rr")}}
    truth = pd.DataFrame({"t": t, "grade": theta, "curvature": kappa, "tractive_force": force, "acceleration": dv})
    tu = {"t": "s", "grade": "rad", "curvature": "1/m", "tractive_force": "N", "acceleration": "m/s^2"}
    return Trip(measured, units, {"name": "handmade"}, truth, tu)


@pytest.fixture(scope="module")
def result():
    return run_pipeline(handmade_trip(), _knowledge())


def test_stages_rates_and_known_delay(result):
    assert list(result.stages) == ["measured", "smoothed", "decimated", "states"]
    assert result.decimation == 10
    assert result.delay == pytest.approx(0.5)                  # w_r = 50 samples at 100 Hz
    st = result.states
    assert np.median(np.diff(st["t"])) == pytest.approx(0.1)
    # smoothed rows are aligned to the time they estimate: the smoothed speed matches the true speed there
    sm = result.stages["smoothed"]
    v_true = 19 + 7 * np.sin(2 * np.pi * sm["t"] / 97) + 3 * np.sin(2 * np.pi * sm["t"] / 23 + 1)
    err = np.abs(sm["vehicle_speed"] - v_true)[sm["t"] > 2]
    assert err.max() < 1e-2                                  # m/s, smoother bias on a fast-varying signal
    # only the run-to stage is computed
    part = run_pipeline(handmade_trip(duration=60.0), _knowledge(), until="decimated")
    assert list(part.stages) == ["measured", "smoothed", "decimated"]
    with pytest.raises(PipelineError, match="only to stage"):
        part.states


def test_states_match_analytic_truth(result):
    st = result.states
    trip = handmade_trip()
    tt = trip.truth
    sel = st["t"] > 3
    for col, truth in (("gradient_angle", "grade"), ("path_curvature", "curvature"),
                       ("acceleration", "acceleration"), ("tractive_force", "tractive_force")):
        ref = np.interp(st["t"][sel], tt["t"], tt[truth])
        ok = st["trigger"][sel].to_numpy()
        err = np.abs(st[col][sel].to_numpy() - ref)[ok]
        assert err.max() < 2e-2 * np.abs(ref).max(), col      # smoother bias on these fast sinusoids: < 2 %


def test_trigger_conditions(result):
    st = result.states
    t = st["t"].to_numpy()

    def off(cond, a, b):
        seg = (t >= a) & (t < b)
        return not st[f"trigger_{cond}"].to_numpy()[seg].any()

    assert off("no_brake", 300.0, 302.5)                       # braking plus 0.5 s after release
    assert st["trigger_no_brake"].to_numpy()[(t > 302.7) & (t < 310)].all()
    assert off("no_slip", 400.0, 403.0)                        # engine speed 30 % off the gear-shaft speed
    assert off("no_slip", 500.0, 502.0) and off("rim_torque_available", 500.0, 502.0)   # neutral
    assert st["trigger_moving"].to_numpy().all()               # speed never below 5.5 m/s here
    low = np.abs(st["drive_torque"].to_numpy()) <= 10
    assert not st["trigger"].to_numpy()[low].any()             # |T_E| > 10 N m
    assert st["trigger"].mean() > 0.6


def test_least_squares_on_pipeline_output_recovers_m3_and_m4(result):
    _, A4, B4 = model_data(result.states, "M4")
    X4, *_ = np.linalg.lstsq(A4, B4, rcond=None)
    np.testing.assert_allclose(X4, X_TRUE, rtol=0.02)
    # M3 on the same data misses the cornering resistance and must be worse in fit
    _, A3, B3 = model_data(result.states, "M3")
    X3, *_ = np.linalg.lstsq(A3, B3, rcond=None)
    assert np.median((B3 - A3 @ X3) ** 2) > 10 * np.median((B4 - A4 @ X4) ** 2)


def test_missing_channels_and_bad_rates_are_clear_errors():
    trip = handmade_trip(duration=30.0, events=False)
    no_speed = Trip(trip.measured.drop(columns=["vehicle_speed"]),
                    {k: u for k, u in trip.units.items() if k != "vehicle_speed"}, {"name": "x"})
    with pytest.raises(PipelineError, match="vehicle_speed"):
        run_pipeline(no_speed, _knowledge())
    odd = Trip(trip.measured.iloc[::3].reset_index(drop=True), trip.units, {"name": "odd"})   # 33.3 Hz
    with pytest.raises(PipelineError, match="integer multiple"):
        run_pipeline(odd, _knowledge())
    with pytest.raises(PipelineError, match="unknown stage"):
        run_pipeline(trip, _knowledge(), until="estimated")
    no_gear = Trip(trip.measured.drop(columns=["gear"]), {k: u for k, u in trip.units.items() if k != "gear"},
                   {"name": "ng"})
    with pytest.raises(PipelineError, match="gear"):
        run_pipeline(no_gear, _knowledge())


def test_no_brake_channels_use_deceleration_proxy_and_no_steering_disables_m4():
    trip = handmade_trip(duration=120.0, events=False)
    drop = ["brake_pressure_front", "brake_pressure_rear", "steering_wheel_angle"]
    bare = Trip(trip.measured.drop(columns=drop), {k: u for k, u in trip.units.items() if k not in drop},
                {"name": "bare"})
    res = run_pipeline(bare, _knowledge(), PipelineSettings(brake_deceleration=-0.5))
    st = res.states
    assert any("brake" in n for n in res.notes) and any("curvature" in n for n in res.notes)
    assert not st["trigger"].to_numpy()[st["acceleration"].to_numpy() < -0.5].any()
    model_data(st, "M3")
    with pytest.raises(ValueError, match="path_curvature"):
        model_data(st, "M4")


def test_accelerometer_gravity_test():
    from roadload.estimators.pipeline import accelerometer_gravity_slope

    rng = np.random.default_rng(3)
    t = np.arange(0, 1200, 0.1)
    grade = 0.03 * np.sin(2 * np.pi * t / 300)
    dv = 0.3 * np.sin(2 * np.pi * t / 17)
    base = {"t": t, "vehicle_speed": np.full_like(t, 15.0), "vehicle_speed_derivative": dv,
            "grade": grade + 0.002 * rng.standard_normal(t.size)}
    with_g = pd.DataFrame(base | {"accel_x": dv + G * np.sin(grade) + 0.1 * rng.standard_normal(t.size)})
    without = pd.DataFrame(base | {"accel_x": dv + 0.1 * rng.standard_normal(t.size)})
    assert accelerometer_gravity_slope(with_g) == pytest.approx(1.0, abs=0.1)
    assert accelerometer_gravity_slope(without) == pytest.approx(0.0, abs=0.1)
    flat = pd.DataFrame(base | {"grade": np.zeros_like(t), "accel_x": dv})
    assert np.isnan(accelerometer_gravity_slope(flat))


def test_auto_gradient_source_follows_the_accelerometer_test():
    trip = handmade_trip(duration=900.0, events=False)
    theta = np.interp(trip.t, trip.truth["t"], trip.truth["grade"])
    m = trip.measured.assign(grade=theta)
    units = dict(trip.units, grade="rad")
    sees = Trip(m, units, {"name": "sees"})
    blind = Trip(m.assign(accel_x=m["accel_x"] - G * np.sin(theta)), units, {"name": "blind"})
    auto = PipelineSettings(gradient="auto")
    r1 = run_pipeline(sees, _knowledge(), auto)
    r2 = run_pipeline(blind, _knowledge(), auto)
    assert not any("grade channel" in n for n in r1.notes)
    assert any("does not see g sin" in n for n in r2.notes)
    ok = r2.states["trigger"].to_numpy()
    ref = np.interp(r2.states["t"], trip.truth["t"], trip.truth["grade"])
    assert np.max(np.abs(r2.states["gradient_angle"].to_numpy() - ref)[ok]) < 2e-3
    with pytest.raises(PipelineError, match="gradient"):
        PipelineSettings(gradient="gps")


def test_any_stage_can_be_plotted(tmp_path):
    from roadload.estimators.figures import plot_stage, save

    res = run_pipeline(handmade_trip(duration=60.0, events=False), _knowledge(), until="smoothed")
    fig = plot_stage(res, "smoothed", ["vehicle_speed", "vehicle_speed_derivative"])
    assert len(fig.axes) == 2
    assert save(fig, tmp_path / "s.png").stat().st_size > 1000
    with pytest.raises(PipelineError, match="was not run"):
        plot_stage(res, "states")
    with pytest.raises(PipelineError, match="none of the channels"):
        plot_stage(res, "smoothed", ["nope"])
