"""The sim's floor on synthetic frames (no simulator): the basis column by column, per-trip force rates, a fit
that recovers known coefficients, the sample-count guard, the energy floor and the reduced sim trip."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from roadload.sim2real.errors import DiagnosisError
from roadload.sim2real.floor import BASIS, RCOND, SimFloor, basis, reduce_channels
from roadload.trip import Trip
from roadload.units import G


def frame(n=400, seed=0, trips=2):
    rng = np.random.default_rng(seed)
    t = np.tile(np.arange(n // trips) * 0.1, trips)
    f = pd.DataFrame({
        "trip": np.repeat(np.arange(trips), n // trips), "t": t,
        "speed": rng.uniform(2.0, 30.0, n), "acceleration": rng.normal(0.0, 0.8, n),
        "gradient_angle": rng.normal(0.0, 0.03, n), "path_curvature": rng.normal(0.0, 0.004, n),
        "brake_force": np.where(rng.random(n) < 0.3, -rng.uniform(0, 2000, n), 0.0),
        "motor_speed": rng.uniform(50.0, 900.0, n), "drive_torque": rng.normal(40.0, 60.0, n)})
    return f, rng.normal(300.0, 900.0, n)


def test_basis_columns_by_name():
    f, sim = frame()
    f.loc[3, "path_curvature"] = np.nan
    f.loc[4, "brake_force"] = np.nan
    A = basis(f, sim)
    assert A.shape == (400, len(BASIS)) == (400, 10)
    v, fb = f.speed.to_numpy(), np.nan_to_num(f.brake_force.to_numpy())
    kappa = np.nan_to_num(f.path_curvature.to_numpy())
    drive = sim + fb
    np.testing.assert_array_equal(A[:, 0], 1.0)
    np.testing.assert_allclose(A[:, 1], v)
    np.testing.assert_allclose(A[:, 2], v ** 2)
    np.testing.assert_allclose(A[:, 3], f.acceleration)
    np.testing.assert_allclose(A[:, 4], G * np.sin(f.gradient_angle))
    np.testing.assert_allclose(A[:, 5], drive)
    np.testing.assert_allclose(A[:, 6], np.abs(drive))
    np.testing.assert_allclose(A[:, 8], v ** 4 * kappa ** 2)
    np.testing.assert_allclose(A[:, 9], fb)
    assert A[3, 8] == 0.0 and A[4, 9] == 0.0 and A[4, 5] == sim[4]  # missing curvature / brake force: 0
    # the force rate is taken within each trip on its own time axis
    first = f.trip.to_numpy() == 0
    np.testing.assert_allclose(A[first, 7], np.gradient(drive[first], f.t.to_numpy()[first]))
    np.testing.assert_allclose(A[~first, 7], np.gradient(drive[~first], f.t.to_numpy()[~first]))


def test_a_trip_of_two_samples_has_no_force_rate():
    f, sim = frame(n=6, trips=3)
    assert np.all(basis(f, sim)[:, 7] == 0.0)
    f, sim = frame(n=6, trips=2)  # three samples per trip: a rate
    assert np.any(basis(f, sim)[:, 7] != 0.0)


def test_fit_recovers_a_known_floor():
    f, sim = frame(n=2000, trips=4)
    A = basis(f, sim)
    truth = np.array([12.0, -0.8, 0.05, 30.0, 0.0, 0.02, -0.01, 0.0, 0.5, 0.03])
    noise = np.random.default_rng(9).normal(0.0, 2.0, len(f))
    valid = np.ones(len(f), bool)
    valid[:50] = False
    residual = A @ truth + noise
    residual[:50] = 1e6  # invalid rows are not fitted
    floor = SimFloor.fit(f, sim, residual, valid)
    assert floor.n == 1950 and not floor.is_none
    pred = floor.predict(f, sim)
    assert np.sqrt(np.mean((pred - A @ truth)[valid] ** 2)) < 0.5  # the floor itself, not the noise
    assert floor.scale == pytest.approx(2.0, rel=0.1)  # residual RMS of the fit: the noise
    assert floor.coefficients[0] == pytest.approx(12.0, abs=1.0)
    d = floor.to_dict()
    assert d["basis"] == list(BASIS) and d["n"] == 1950 and d["residual_rms"] == floor.scale
    assert d["coefficients"] == [float(c) for c in floor.coefficients] and len(d["coefficients"]) == 10
    # the energy floor: power_residual = 3 + 0.01 |p| fitted from the same frame
    p = f.drive_torque.to_numpy() * f.motor_speed.to_numpy()
    f["power_residual"] = 3.0 + 0.01 * np.abs(p)
    floor = SimFloor.fit(f, sim, residual, valid)
    np.testing.assert_allclose(floor.predict_power(f), 3.0 + 0.01 * np.abs(p), rtol=1e-6, atol=1e-6)
    assert floor.to_dict()["power_coefficients"] == pytest.approx([3.0, 0.0, 0.0, 0.01, 0.0], abs=1e-6)
    assert np.all(floor.predict_power(f.drop(columns=["motor_speed"])) == 0.0)


def test_energy_floor_needs_100_finite_samples():
    f, sim = frame(n=400)
    f["power_residual"] = np.nan
    f.loc[:98, "power_residual"] = 1.0
    valid = np.ones(len(f), bool)
    floor = SimFloor.fit(f, sim, np.zeros(len(f)), valid)
    assert floor.power_coefficients is None and np.all(floor.predict_power(f) == 0.0)
    assert floor.to_dict()["power_coefficients"] is None
    f.loc[:99, "power_residual"] = 1.0
    assert SimFloor.fit(f, sim, np.zeros(len(f)), valid).power_coefficients is not None


def test_fit_needs_ten_samples_per_basis_column():
    f, sim = frame(n=400)
    valid = np.zeros(len(f), bool)
    valid[:99] = True
    with pytest.raises(DiagnosisError, match=r"the sim's floor needs more valid samples of sim trips \(99\)"):
        SimFloor.fit(f, sim, np.zeros(len(f)), valid)
    valid[:100] = True
    assert SimFloor.fit(f, sim, np.zeros(len(f)), valid).n == 100


def test_a_constant_zero_column_does_not_break_the_scaled_fit():
    f, sim = frame(n=400)
    f["path_curvature"] = 0.0  # the v^4/r^2 column is all zero: its scale is taken as 1, not 0
    floor = SimFloor.fit(f, sim, np.full(len(f), 5.0), np.ones(len(f), bool))
    assert np.all(np.isfinite(floor.coefficients)) and floor.coefficients[8] == 0.0
    np.testing.assert_allclose(floor.predict(f, sim), 5.0, atol=1e-6)
    assert RCOND == 1e-4


def test_no_floor():
    none = SimFloor.none()
    assert none.is_none and none.n == 0 and np.isnan(none.scale) and np.all(none.coefficients == 0.0)
    f, sim = frame(n=20)
    assert np.all(none.predict(f, sim) == 0.0) and np.all(none.predict_power(f) == 0.0)


def test_reduced_sim_trip_keeps_only_the_recorded_channels():
    measured = pd.DataFrame({"t": [0.0, 0.1], "speed": [1.0, 2.0], "acceleration": [0.1, 0.2], "grade": [0.0, 0.0]})
    truth = pd.DataFrame({"t": [0.0, 0.1], "speed": [1.0, 2.0]})
    trip = Trip(measured, {"t": "s", "speed": "m/s", "acceleration": "m/s^2", "grade": "rad"}, {"vehicle": "x"},
                truth, {"t": "s", "speed": "m/s"})
    out = reduce_channels(trip, {"speed", "grade", "not_there"})
    assert list(out.measured.columns) == ["t", "speed", "grade"]
    assert out.units == {"t": "s", "speed": "m/s", "grade": "rad"} and out.meta == {"vehicle": "x"}
    assert out.truth is not None and list(out.truth.columns) == ["t", "speed"]
    out.measured.loc[0, "speed"] = 9.0
    assert trip.measured.loc[0, "speed"] == 1.0  # a copy
