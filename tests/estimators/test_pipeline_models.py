"""Model structures M0/M3/M4, the model registry, the drive-train and steering models of the estimating side."""

import numpy as np

from roadload.envs.coast_down import neutral_road_load
import pytest

from roadload.estimators.models import (M0, M3, M4, ModelError, NominalParameters, Term, fit_coast_down,
                                        get_model, model_names, register_model)
from roadload.estimators.pipeline import DrivetrainModel, PipelineError, SteeringGeometry
from roadload.units import G, air_density


def _states(T=4000):
    t = np.arange(T) * 0.1
    v = 20 + 8 * np.sin(t / 23) + 3 * np.sin(t / 7)
    return {
        "t": t,
        "speed": v,
        "acceleration": np.gradient(v, t),
        "gradient_angle": 0.04 * np.sin(t / 31),
        "path_curvature": 0.01 * np.sin(t / 11) ** 3,
    }


def test_m3_m4_regressors_follow_eq_5_5_and_5_6():
    s = _states()
    A3 = M3.regressors({**s, "tractive_force": np.zeros_like(s["t"])})
    assert A3.shape == (s["t"].size, 3)
    np.testing.assert_allclose(A3[:, 0], G * np.cos(s["gradient_angle"]))
    np.testing.assert_allclose(A3[:, 1], G * np.sin(s["gradient_angle"]) + s["acceleration"])
    np.testing.assert_allclose(A3[:, 2], s["speed"] ** 2)
    A4 = M4.regressors(s | {"tractive_force": 0 * s["t"]})
    np.testing.assert_allclose(A4[:, :3], A3)
    np.testing.assert_allclose(A4[:, 3], s["speed"] ** 4 * s["path_curvature"] ** 2 / 4)
    assert M4.parameter_names == ["m_V f_r0", "m_V", "rho_a/2 A_V c_x", "m_V^2/c_yW"]
    np.testing.assert_allclose(M4.random_walk_variances(), [5e-5, 1e-6, 1e-8, 1e-6])  # section 5.5.3


def test_least_squares_recovers_m4_parameters_from_exact_force():
    s = _states()
    X = np.array([1800 * 0.011, 1800.0, 0.5 * 1.2 * 0.62, 1800 ** 2 / 60000])
    B = M4.regressors(s | {"tractive_force": 0 * s["t"]}) @ X
    st = s | {"tractive_force": B}
    A = M4.regressors(st)
    X_hat, *_ = np.linalg.lstsq(A, M4.output(st), rcond=None)
    np.testing.assert_allclose(X_hat, X, rtol=1e-8)
    np.testing.assert_allclose(M4.predict(st, X), B)


def test_nominal_parameters_give_initial_x_and_m0_needs_coast_down():
    nom = NominalParameters.from_physical(mass=1900.0, rolling_resistance_coefficient=0.01, drag_area=0.62,
                            cornering_stiffness=5e4, air_density=1.2)
    np.testing.assert_allclose(M4.nominal_parameters(nom), [19.0, 1900.0, 0.372, 1900 ** 2 / 5e4])
    with pytest.raises(ModelError, match="coast-down"):
        M0.nominal_parameters(nom)
    nom0 = NominalParameters.from_physical(1900.0, 0.01, 0.62, 5e4, coast_down=(180.0, 2.0, 0.4))
    np.testing.assert_allclose(M0.nominal_parameters(nom0), [180.0, 2.0, 0.4, 1900.0])
    assert M0.white_box and not M3.white_box
    with pytest.raises(ModelError, match="mass"):
        NominalParameters.from_physical(mass=-1.0, rolling_resistance_coefficient=0.01, drag_area=0.6,
                                        cornering_stiffness=1.0)


def test_m0_prediction_is_eq_5_4():
    s = _states()
    nom = NominalParameters.from_physical(1900.0, 0.01, 0.62, 5e4, coast_down=(180.0, 2.0, 0.4))
    st = s | {"tractive_force": 0 * s["t"]}
    th, v, dv = s["gradient_angle"], s["speed"], s["acceleration"]
    expected = 180 * np.cos(th) + 2.0 * np.cos(th) * v + 0.4 * v ** 2 + (G * np.sin(th) + dv) * 1900
    np.testing.assert_allclose(M0.predict(st, M0.nominal_parameters(nom)), expected)


def test_registry_unknown_duplicate_and_user_model_with_extra_regressor():
    assert {"M0", "M3", "M4"} <= set(model_names())
    assert get_model("M3") is M3
    with pytest.raises(ModelError, match="unknown model 'M9'"):
        get_model("M9")
    with pytest.raises(ModelError, match="already registered"):
        register_model(M3)
    # a candidate effect: headwind-like term v (user-defined) -> a 4-parameter structure, nothing else changed
    wind = Term("v", "k_w", "N s/m", lambda s: np.asarray(s["speed"], float), ("speed",), lambda n: 0.0, 1e-6)
    m = register_model(M3.extend("M3_test_wind", wind), replace_existing=True)
    assert get_model("M3_test_wind").n_params == 4 and m.parameter_names[-1] == "k_w"
    s = _states()
    X = np.array([20.0, 1800.0, 0.4, 7.5])
    B = m.regressors(s | {"tractive_force": 0 * s["t"]}) @ X
    X_hat, *_ = np.linalg.lstsq(m.regressors(s | {"tractive_force": B}), B, rcond=None)
    np.testing.assert_allclose(X_hat, X, rtol=1e-8)


def test_missing_state_is_a_clear_error():
    s = _states()
    del s["path_curvature"]
    with pytest.raises(ModelError, match=r"M4.*path_curvature"):
        M4.regressors(s | {"tractive_force": 0 * s["t"]})
    s["path_curvature"] = np.full_like(s["t"], np.nan)   # present but all NaN (no steering signal)
    with pytest.raises(ModelError, match="path_curvature"):
        M4.regressors(s | {"tractive_force": 0 * s["t"]})
    M3.regressors(s | {"tractive_force": 0 * s["t"]})  # M3 does not need it


def test_coast_down_fit_recovers_road_load_polynomial():
    a, b, c, m_eff = 200.0, 3.0, 0.42, 2050.0
    # analytic-free check: integrate m_eff dv/dt = -(a + b v + c v^2) finely, fit on a subsample
    dt = 0.001
    v = [36.0]
    while v[-1] > 3.0:
        vv = v[-1]
        v.append(vv - dt * (a + b * vv + c * vv ** 2) / m_eff)
    v = np.array(v)[::100]
    t = np.arange(v.size) * 0.1
    np.testing.assert_allclose(fit_coast_down(t, v, m_eff), (a, b, c), rtol=2e-3, atol=0.05)
    with pytest.raises(ModelError, match="NaN"):
        fit_coast_down(t, np.where(t > 5, np.nan, v), m_eff)


def _dt_model(**kw):
    base = dict(gear_ratios=(3.0, 2.0), final_drive=3.5, wheel_radius=0.33, wheel_inertia=4.0,
                reduced_inertia=(6.0, 3.0), gearbox_efficiency=(0.95, 0.97), gearbox_drag=(1.0, 1.0),
                differential_efficiency=0.98)
    base.update(kw)
    return DrivetrainModel(**base)


def test_drivetrain_losses_oppose_power_flow_and_neutral_has_no_rim_torque():
    m = _dt_model()
    T_E = np.array([100.0, -50.0, 100.0, 80.0])
    gear = np.array([1, 1, 0, 2])
    acc = np.array([2.0, 2.0, 2.0, 0.0])
    tr = m.rim_torque(T_E, gear, acc)
    # traction: (100*3*0.95 - 1*3) * 3.5 * 0.98 - 6*2
    assert tr[0] == pytest.approx((100 * 3 * 0.95 - 3.0) * 3.5 * 0.98 - 12.0)
    # overrun: losses make the wheel torque more negative than the ideal -50*3*3.5
    assert tr[1] == pytest.approx((-50 * 3 / 0.95 - 3.0) * 3.5 / 0.98 - 12.0)
    assert np.isnan(tr[2])
    assert tr[3] == pytest.approx((80 * 2 * 0.97 - 2.0) * 3.5 * 0.98)
    assert m.tractive_force(np.array([330.0]), np.array([0.0]))[0] == pytest.approx(1000.0)
    with pytest.raises(PipelineError, match="one value per gear"):
        _dt_model(reduced_inertia=(6.0,))


def test_path_curvature_eq_5_3():
    geo = SteeringGeometry(wheelbase=2.9, rear_axle_distance=1.4, steering_wheel_angle=(-8.0, 0.0, 8.0),
                           wheel_angle=(-0.5, 0.0, 0.5))      # constant ratio 16
    ds = np.array([0.0, 1.6, -1.6])
    dw = ds / 16
    r = np.sqrt((2.9 / np.tan(dw[1])) ** 2 + 1.4 ** 2)
    k = geo.path_curvature(ds)
    assert k[0] == 0.0
    assert k[1] == pytest.approx(1 / r) and k[2] == pytest.approx(-1 / r)
    with pytest.raises(PipelineError, match="l_34"):
        SteeringGeometry(2.9, 3.0, (-1.0, 1.0), (-0.1, 0.1))


def test_knowledge_from_a_preset_spec_and_its_simulated_coast_down():
    import roadload.presets as presets
    from roadload.estimators.models import coast_down_coefficients, published_coast_down, simulate_coast_down
    from roadload.estimators.pipeline import knowledge_from_spec

    spec = presets.get_preset("gt_rwd")
    t, v, m_eff = simulate_coast_down(spec)
    assert v[0] == pytest.approx(130 / 3.6) and v[-1] <= 15 / 3.6 and m_eff > spec.body.mass
    a, b, c = coast_down_coefficients(spec)
    # the fitted polynomial reproduces the simulator's road load it was coasting against (within 1 %)
    vv = np.linspace(6.0, 35.0, 20)
    np.testing.assert_allclose(a + b * vv + c * vv ** 2, neutral_road_load(spec, vv), rtol=0.01)
    k = knowledge_from_spec(spec, coast_down=(a, b, c))
    assert k.nominal.mass == spec.body.mass and k.nominal.coast_down == (a, b, c)
    assert k.drivetrain.n_gears == len(spec.drivetrain.gear_ratios)
    assert k.drivetrain.reduced_inertia[0] == pytest.approx(spec.drivetrain.reduced_inertia(1))
    assert k.steering.rear_axle_distance == pytest.approx(spec.body.cg_to_rear_axle)
    # the estimating side's loss table is a fit of the spec's maps at one speed: efficiencies of a real gearbox
    assert all(0.9 < e <= 1.0 for e in k.drivetrain.gearbox_efficiency)
    a0, b0, c0 = published_coast_down(spec)
    assert a0 == pytest.approx(spec.body.mass * G * spec.tires.rolling_resistance_f0)
    assert c0 == pytest.approx(0.5 * air_density(293.15, 101325.0) * spec.aero.drag_area)  # 20 degC, 1013.25 hPa


def test_trip_load_selected_channels(tmp_path):
    """Trip.load(channels=..., truth_channels=...) reads a subset (used by the fleet benchmark)."""
    import pandas as pd

    from roadload.trip import Trip

    t = np.arange(5) * 0.01
    trip = Trip(pd.DataFrame({"t": t, "vehicle_speed": t + 1, "accel_x": t * 2, "gear": np.ones(5)}),
                {"t": "s", "vehicle_speed": "m/s", "accel_x": "m/s^2", "gear": "1"}, {"name": "x"},
                pd.DataFrame({"t": t, "mass": np.full(5, 1900.0), "grade": t}),
                {"t": "s", "mass": "kg", "grade": "rad"})
    path = trip.save(tmp_path / "x.parquet")
    sub = Trip.load(path, channels=["gear", "vehicle_speed", "not_there"], truth_channels=["mass"])
    assert sub.channels == ["vehicle_speed", "gear"] and list(sub.truth.columns) == ["t", "mass"]
    assert sub.units == {"t": "s", "vehicle_speed": "m/s", "gear": "1"} and sub.meta == trip.meta
    np.testing.assert_array_equal(sub.channel("vehicle_speed"), trip.channel("vehicle_speed"))
    assert Trip.load(path).equals(trip)
