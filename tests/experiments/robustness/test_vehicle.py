"""Robustness testbed on simulated trips: faults injected by the simulator's sensor layer, A/B from the pipeline."""

import numpy as np
import pytest

from roadload.experiments.robustness import (
    VEHICLE_SWEEPS, RobustnessError, Scenario, build_vehicle, default_estimators, run_scenario,
    simulate_scenario, true_parameters, vehicle_effects, vehicle_sensors,
)

DURATION = 300.0


def test_fault_specs_map_onto_the_simulator_sensor_layer():
    sc = Scenario("vehicle", "outliers", "drive_torque/x10", 0.05, 0, DURATION)
    assert vehicle_effects(sc) == {"sensor_outliers": {"rate": 0.05, "magnitude": 10.0, "channels": "all"}}
    spec = vehicle_sensors(sc)
    assert spec.channels["drive_torque"].outlier_scale == 80.0
    assert all(ch.outlier_scale == 0.0 for n, ch in spec.channels.items() if n != "drive_torque")
    bias = vehicle_sensors(Scenario("vehicle", "bias", "accel_x", 4.0, 0, DURATION))
    assert bias.channels["accel_x"].bias == pytest.approx(0.2)          # 4 x the 0.05 m/s^2 reference
    lat = vehicle_sensors(Scenario("vehicle", "latency", "drive_torque", 0.2, 0, DURATION))
    assert lat.channels["drive_torque"].latency == pytest.approx(0.03 + 0.2)
    assert vehicle_effects(Scenario("vehicle", "outliers", "accel_x/x1", 0.0, 0, DURATION)) == {}
    with pytest.raises(RobustnessError, match="variant"):
        vehicle_effects(Scenario("vehicle", "outliers", "yaw_rate/x1", 0.1, 0, DURATION))
    assert set(VEHICLE_SWEEPS) == {"outliers", "dropouts", "excitation", "drift", "bias", "latency", "wind", "ramps"}


def test_outliers_hit_only_the_target_channel_and_truth_parameters_are_the_presets():
    clean = simulate_scenario(Scenario("vehicle", "outliers", "drive_torque/x10", 0.0, 1, DURATION))
    hit = simulate_scenario(Scenario("vehicle", "outliers", "drive_torque/x10", 0.05, 1, DURATION))
    d_torque = np.abs(hit.channel("drive_torque") - clean.channel("drive_torque"))
    assert np.mean(d_torque > 700.0) == pytest.approx(0.05, abs=0.01)   # ±800 (1 + |N|) N m at 5 % of samples
    assert np.array_equal(hit.channel("accel_x"), clean.channel("accel_x"))
    t = clean.true("t")[::1000]
    X = true_parameters(clean, "M4", t)
    assert np.allclose(X[:, 1], 1900.0) and np.allclose(X[:, 0], 1900.0 * 0.009)
    assert np.allclose(X[:, 2], 0.5 * clean.true("air_density")[0] * 0.6844, rtol=1e-3)
    assert np.allclose(X[:, 3], 1900.0 ** 2 / clean.true("cornering_stiffness")[0])


@pytest.mark.parametrize("sweep, variant, level", [
    ("outliers", "drive_torque/x10", 0.3), ("outliers", "accel_x/x1", 0.3), ("dropouts", "all", 0.3),
    ("bias", "accel_x", 10.0), ("latency", "drive_torque", 0.5)])
def test_no_estimator_returns_nan_or_inf_on_faulty_trips(sweep, variant, level):
    rows = run_scenario(Scenario("vehicle", sweep, variant, level, 2, DURATION))
    assert {r["model"] for r in rows} == {"M3", "M4"}
    assert sorted({r["estimator"] for r in rows}) == sorted(default_estimators())
    for r in rows:
        assert r["finite"], r
        assert np.isfinite(r["rel_error"]) and np.isfinite(r["medse"]), r
    if sweep == "dropouts":   # the NaN runs are bridged or dropped by the pipeline, and counted when dropped
        assert all(r["n_pipeline_dropped"] >= 0 for r in rows)


def test_payload_step_is_detected_and_recovery_measured():
    sc = Scenario("vehicle", "drift", "payload/step", 500.0, 0, 1200.0)
    data = dict((m, d) for m, d, _ in build_vehicle(sc))
    d = data["M3"]
    te = d.meta["event_time"]
    assert 0.2 * 1200 < te < 0.8 * 1200                 # the stop placed at about mid-trip
    assert np.allclose(d.X_true[d.t < te - 1, 1], 1900.0) and np.allclose(d.X_true[d.t > te + 1, 1], 2400.0)
    rows = run_scenario(sc, ["RLS", "SGMKF"])
    rec = {(r["model"], r["estimator"]): r["recovery_time"] for r in rows}
    assert all(v >= 0 for v in rec.values())
    assert np.isfinite(rec[("M3", "RLS")])             # λ = 0.999 RLS follows a 500 kg step within the trip


def test_rls_breaks_down_before_rlm_and_rrlm_on_vehicle_data_with_outliers_in_b():
    """The text's claim on vehicle data, outliers put into B after the chapter-5 pipeline (A/B-level layer)."""
    import pandas as pd

    from roadload.experiments.robustness import breakdown_table, scenarios

    rows = []
    for sc in scenarios("vehicle", "outliers", [0, 1], DURATION, variants=["output/ab"], levels=(0.0, 0.02, 0.1, 0.3)):
        rows += run_scenario(sc, ["RLS", "RLM", "RRLM"])
    bd = breakdown_table(pd.DataFrame(rows)).set_index(["model", "estimator"])["breakdown"]
    for model in ("M3", "M4"):
        assert bd[(model, "RLS")] <= 0.1
        assert bd[(model, "RLM")] > bd[(model, "RLS")] and bd[(model, "RRLM")] > bd[(model, "RLS")]


def test_windup_on_vehicle_cruise_and_stenlund_gustafsson_bounds_it():
    """Motorway trips with long constant-speed stretches (simulator option 'poor_excitation')."""
    growth, stretch = {}, {}
    for level in (0.0, 600.0):
        for r in run_scenario(Scenario("vehicle", "excitation", "cruise", level, 0, 1200.0),
                              ["RLS", "RLM", "RRLM", "SGMKF", "SGIVMKF"]):
            if r["model"] == "M3":
                growth[(r["estimator"], level)] = r["trace_P_growth"]
                stretch[level] = r["longest_stretch"]
    assert stretch[600.0] > 2 * stretch[0.0]              # the option lengthens the unexcited stretches
    for name in ("RLS", "RLM"):                           # trace(P) grows more in the longer stretches
        assert growth[(name, 600.0)] > 1.5 and growth[(name, 600.0)] > growth[(name, 0.0)] + 0.3
    for name in ("SGMKF", "SGIVMKF"):                     # Stenlund-Gustafsson keeps P at its desired value
        assert growth[(name, 0.0)] < 1.01 and growth[(name, 600.0)] < 1.01
    # finding: with the chapter-5 κ = 1e-5 the Levenberg-Marquardt regularisation of RRLM does not bound the
    # wind-up on vehicle data (it does with the κ = 0.1 of experiment 3.3, see test_claims.py)
    assert abs(growth[("RRLM", 600.0)] - growth[("RLM", 600.0)]) < 0.05 * growth[("RLM", 600.0)]
