"""Robustness sweeps on the simulator's burst outliers, single-channel dropouts, headwind onset, parameter ramps
and held cruise stretches."""

import numpy as np
import pytest

from roadload.experiments.robustness import (
    OUTLIER_BURST_LENGTH, Scenario, build_vehicle, event_times, prediction_recovery_time, run_scenario,
    simulate_scenario, vehicle_effects,
)

DURATION = 300.0


def _runs(mask):
    d = np.diff(np.r_[0, mask.astype(int), 0])
    return np.flatnonzero(d == -1) - np.flatnonzero(d == 1)


def test_burst_outliers_and_single_channel_dropouts_hit_as_specified():
    clean = simulate_scenario(Scenario("vehicle", "outliers", "drive_torque/x10/burst", 0.0, 1, DURATION))
    hit = simulate_scenario(Scenario("vehicle", "outliers", "drive_torque/x10/burst", 0.05, 1, DURATION))
    bad = np.abs(hit.channel("drive_torque") - clean.channel("drive_torque")) > 1e-9
    assert bad.mean() == pytest.approx(0.05, abs=0.02)                  # share of samples hit = the level
    lengths = _runs(bad)
    assert lengths.min() == OUTLIER_BURST_LENGTH and np.mean(lengths == OUTLIER_BURST_LENGTH) > 0.7
    assert np.array_equal(hit.channel("accel_x"), clean.channel("accel_x"))
    drop = simulate_scenario(Scenario("vehicle", "dropouts", "accel_x", 0.1, 1, DURATION))
    nan = drop.measured.isna()
    assert nan["accel_x"].mean() == pytest.approx(0.1, abs=0.05)
    assert not nan.drop(columns=["accel_x"]).any().any()


def test_prediction_recovery_time_on_an_analytic_case():
    t = np.arange(0.0, 400.0, 0.1)
    A = np.ones((t.size, 1))
    B = np.where(t < 100.0, 1.0, 3.0) + 0.01  # constant residual 0.01 while the estimate is right
    X = np.where(t < 100.0, 1.0, np.where(t < 150.0, 1.0, 3.0))[:, None]  # the estimate catches up at 150 s
    rec = prediction_recovery_time(t, A, B, X, 100.0, tolerance=0.3, hold=10.0, window=5.0)
    assert rec == pytest.approx(50.0 + 2.5, abs=0.15)  # + half the running-median window
    assert prediction_recovery_time(t, A, B, np.full((t.size, 1), 3.0) * (t >= 100)[:, None] + (t < 100)[:, None],
                                    100.0, window=5.0) == pytest.approx(0.0, abs=0.2)
    never = np.ones((t.size, 1))
    assert prediction_recovery_time(t, A, B, never, 100.0, window=5.0) == np.inf


def test_headwind_onset_and_parameter_ramps_reach_the_truth_and_the_recovery_metrics():
    sc = Scenario("vehicle", "wind", "step", 10.0, 0, DURATION)
    onset, end = event_times(sc)
    assert onset == end == 0.5 * DURATION
    trip = simulate_scenario(sc)
    t, w = trip.true("t"), trip.true("wind_speed")
    assert np.all(w[t < onset - 0.01] == 0.0) and np.allclose(w[t > onset + 0.02], 10.0)
    rows = run_scenario(sc, ["RLS", "SGMKF"])
    assert all(r["prediction_recovery_time"] > 0 for r in rows)     # the headwind degrades every prediction
    ramp = Scenario("vehicle", "ramps", "mass/ramp", 0.2, 0, DURATION)
    onset, end = event_times(ramp)
    assert end - onset == 120.0 and vehicle_effects(ramp)["mass_ramp"]["magnitude"] == pytest.approx(380.0)
    data = dict((m, d) for m, d, _ in build_vehicle(ramp))["M3"]
    assert data.meta["event_time"] == end
    assert np.allclose(data.X_true[data.t < onset - 1, 1], 1900.0) and np.allclose(data.X_true[data.t > end + 1, 1],
                                                                                   2280.0)
    drag = Scenario("vehicle", "ramps", "drag_area/step", 0.4, 0, DURATION)
    rows = run_scenario(drag, ["RLS"])
    rec = {r["model"]: r["recovery_time"] for r in rows}
    assert np.isfinite(rec["M3"]) and rec["M3"] > 0                 # RLS (λ = 0.999) follows a +40 % drag step


def test_cruise_sweep_gives_held_stretches_of_the_requested_length():
    longest = {lv: build_vehicle(Scenario("vehicle", "excitation", "cruise", lv, 0, 1200.0))[0][1].meta[
        "longest_stretch"] for lv in (0.0, 600.0)}
    assert longest[600.0] >= 600.0 and longest[0.0] < 120.0
