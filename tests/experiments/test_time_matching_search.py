"""The equal-trip-time search and its energy read-outs on analytic trip-time curves (no closed loop): the bracket,
the secant steps, the run budget, what is flagged unmatched, and the energy at exactly the target time."""

import math
from types import SimpleNamespace

import numpy as np
import pytest

from roadload.experiments.time_matching import MatchedRun, fit_energy_at_time, match_trip_time


def curve(calls, slope=20.0, t0=300.0, lam_ref=1000.0):
    """Trip time T(lambda) = t0 - slope ln(lambda / lam_ref) [s], energy E = 1e6 (2 - ln(...)/10) [J]."""
    def run(lam):
        calls.append(lam)
        x = math.log(lam / lam_ref)
        return SimpleNamespace(metrics={"trip_time": t0 - slope * x, "energy_J": 1e6 * (2.0 - x / 10.0),
                                        "arrival": t0 - slope * x + 7.0, "kWh": 2.0 - x / 10.0})
    return run


def test_secant_search_meets_the_tolerance_on_a_log_linear_curve():
    calls = []
    m = match_trip_time(curve(calls), 280.0, tol=0.001)
    assert m.matched and abs(m.time_error) <= 0.001 and m.target_time == 280.0
    assert calls[0] == 8000.0 and m.runs == len(calls) == len(m.history) <= 10
    assert m.time_weight == pytest.approx(1000.0 * math.e, rel=0.02)  # T = 280 s at ln(lam/1000) = 1
    assert m.history[0] == (8000.0, pytest.approx(300.0 - 20.0 * math.log(8.0)),
                            pytest.approx(1e6 * (2.0 - math.log(8.0) / 10.0)))
    assert m.result.metrics["trip_time"] == pytest.approx(280.0, rel=0.001)


def test_bracket_grows_by_the_step_factor_in_the_right_direction():
    calls = []
    # T(8000) = 258.4 s is below the 290 s target: lambda must fall, by the factor ``step`` each run
    match_trip_time(curve(calls), 290.0, tol=0.001, step=2.0)
    assert calls[:3] == [8000.0, pytest.approx(4000.0), pytest.approx(2000.0)]
    calls.clear()
    # above the target: lambda rises
    match_trip_time(curve(calls, t0=400.0), 300.0, tol=0.001, step=3.0)
    assert calls[:2] == [8000.0, pytest.approx(24000.0)]


def test_first_run_inside_the_tolerance_ends_the_search():
    calls = []
    m = match_trip_time(curve(calls), 258.5, tol=0.01)  # T(8000) = 258.41 s
    assert calls == [8000.0] and m.matched and m.runs == 1


def test_secant_step_stays_inside_the_bracket():
    calls = []
    match_trip_time(curve(calls), 250.0, tol=1e-4, lam0=1000.0, step=100.0)  # target at lambda ~ 12182
    # 1000 (300 s) -> 100000 (207.9 s): the next step is interpolated inside [ln 1000, ln 100000]
    assert calls[:2] == [1000.0, pytest.approx(100000.0)]
    x1, x2 = math.log(1000.0), math.log(100000.0)
    assert x1 + 0.1 * (x2 - x1) - 1e-9 <= math.log(calls[2]) <= x2 - 0.1 * (x2 - x1) + 1e-9
    assert math.log(calls[2]) == pytest.approx(x1 + 50.0 / 92.1034 * (x2 - x1), rel=1e-3)  # the secant itself


def test_an_unreachable_target_is_flagged_with_the_closest_run():
    calls = []
    m = match_trip_time(curve(calls), 100.0, tol=0.01, lam_max=2e5)  # T = 100 s needs lambda ~ 2.2e7
    assert not m.matched and max(calls) <= 2e5 and calls[-1] == pytest.approx(128000.0)  # 8000 * 4^2: next leaves
    assert m.time_weight == calls[-1]  # the fastest run is the closest
    calls.clear()
    m = match_trip_time(curve(calls), 500.0, tol=0.01, lam_min=1000.0)
    assert not m.matched and min(calls) >= 1000.0 and calls == [8000.0, pytest.approx(2000.0)]


def test_the_run_budget_is_kept():
    calls = []
    m = match_trip_time(curve(calls), 281.0, tol=1e-9, max_runs=2)
    assert len(calls) == 2 and m.runs == 2 and not m.matched
    assert m.time_weight == pytest.approx(2000.0)  # T(2000) = 286.1 s is closer to 281 s than T(8000) = 258.4 s


def test_other_metric_keys():
    calls = []
    m = match_trip_time(curve(calls), 287.0, tol=0.001, time_key="arrival", energy_key="kWh")
    assert m.matched and m.result.metrics["arrival"] == pytest.approx(287.0, rel=0.001)
    assert m.history[0][1:] == (pytest.approx(307.0 - 20.0 * math.log(8.0)), pytest.approx(2.0 - math.log(8.0) / 10))
    assert m.time_key == "arrival" and abs(m.time_error) <= 0.001


def test_a_run_without_a_finite_time_counts_as_too_slow():
    def run(lam):
        return SimpleNamespace(metrics={"trip_time": float("nan") if lam < 10000 else 200.0, "energy_J": 1.0})
    m = match_trip_time(run, 200.0)
    assert m.matched and m.time_weight == pytest.approx(32000.0) and math.isnan(m.history[0][1])


@pytest.mark.parametrize("kwargs,message", [
    ({"target_time": 0.0}, "target_time must be a positive finite number, got 0.0"),
    ({"target_time": float("inf")}, "target_time must be a positive finite number, got inf"),
    ({"target_time": float("nan")}, "target_time must be a positive finite number, got nan"),
    ({"target_time": 100.0, "tol": 0.0}, r"tol must be in \(0, 1\), got 0.0"),
    ({"target_time": 100.0, "tol": 1.0}, r"tol must be in \(0, 1\), got 1.0"),
])
def test_bad_search_settings_are_refused(kwargs, message):
    with pytest.raises(ValueError, match=message):
        match_trip_time(curve([]), **kwargs)


def _matched(history, target=100.0):
    return MatchedRun(SimpleNamespace(metrics={"trip_time": 101.0}), 1.0, target, True, len(history), history)


def test_local_fit_window_curvature_and_read_outs():
    def energy(t):
        x = t / 200.0 - 1.0
        return 100e6 * (1.0 - 2.0 * x + 5.0 * x * x)

    times = (190.0, 196.0, 200.5, 204.0, 208.0)
    runs = {"oracle": [(t, energy(t)) for t in times] + [(260.0, 1.0), (float("nan"), 1.0)], "none": [(400.0, 1.0)]}
    fit = fit_energy_at_time(runs, 200.0)
    assert fit.n_points == 5  # 260 s is outside the 6 % window, NaN dropped, "none" has no run inside
    assert fit.energy["oracle"] == pytest.approx(100e6, rel=1e-9) and math.isnan(fit.energy["none"])
    e_ref = energy(200.5)  # the median energy of the runs used
    assert fit.slope == pytest.approx(-2.0 * 100e6 / e_ref, rel=1e-6)
    assert fit.curvature == pytest.approx(5.0 * 100e6 / e_ref, rel=1e-6)
    assert fit.residual_std == pytest.approx(0.0, abs=1e-9)
    assert fit.nearest["oracle"] == pytest.approx(0.0025) and fit.spanned == {"oracle": True, "none": False}
    assert fit.nearest["none"] == pytest.approx(1.0)
    narrow = fit_energy_at_time(runs, 200.0, window=0.021)
    assert narrow.n_points == 3  # 196, 200.5, 204: 190 and 208 lie 5 % and 4 % away
    linear = fit_energy_at_time(runs, 200.0, quadratic=False)
    assert linear.curvature == 0.0 and linear.residual_std > 1e-4  # a line through a parabola leaves residuals
    assert linear.energy["oracle"] > fit.energy["oracle"]  # a line through a convex curve passes above its minimum


def test_local_fit_without_runs_and_bad_target():
    fit = fit_energy_at_time({"a": [(500.0, 1.0)]}, 200.0)
    assert fit.n_points == 0 and math.isnan(fit.energy["a"]) and fit.spanned == {"a": False}
    assert math.isnan(fit.slope) and math.isnan(fit.curvature) and math.isnan(fit.nearest["a"])
    with pytest.raises(ValueError, match="target_time must be > 0 s, got 0.0"):
        fit_energy_at_time({}, 0.0)
    few = fit_energy_at_time({"a": [(198.0, 99.0), (202.0, 101.0)]}, 200.0)  # 2 runs: no curvature term
    assert few.curvature == 0.0 and few.energy["a"] == pytest.approx(100.0) and few.n_points == 2


def test_local_fit_boundaries_are_inclusive():
    # a run exactly on the window edge counts (250 / 200 - 1 = 0.25 exactly)
    edge = fit_energy_at_time({"a": [(250.0, 7.0), (150.0, 3.0)]}, 200.0, window=0.25)
    assert edge.n_points == 2 and edge.energy["a"] == pytest.approx(5.0)
    # a run at exactly the target time spans it and is nearest at 0
    at = fit_energy_at_time({"a": [(200.0, 4.0)]}, 200.0)
    assert at.spanned == {"a": True} and at.nearest == {"a": 0.0} and at.energy == {"a": 4.0}
    assert at.n_points == 1 and math.isnan(at.residual_std) and math.isnan(at.slope) and math.isnan(at.curvature)
    # without time spread, a run exactly min_spread away still counts as close
    close = fit_energy_at_time({"a": [(250.0, 6.0), (250.0, 8.0)]}, 200.0, window=0.3, min_spread=0.25)
    assert close.energy == {"a": 7.0} and close.n_points == 2 and close.spanned == {"a": False}
    assert close.nearest == {"a": 0.25}
    # and a model whose runs are all further than min_spread gets NaN, while another model's close runs count
    mixed = fit_energy_at_time({"far": [(210.0, 1.0)], "near": [(200.2, 2.0)]}, 200.0)
    assert math.isnan(mixed.energy["far"]) and mixed.energy["near"] == 2.0 and mixed.n_points == 2
    assert mixed.spanned == {"far": False, "near": False} and mixed.nearest["far"] == pytest.approx(0.05)
    assert fit_energy_at_time({"a": [(0.2, 1.0)]}, 0.2).energy == {"a": 1.0}  # any target > 0 s is valid


def test_local_fit_residual_scale_and_the_quadratic_threshold():
    times = (190.0, 195.0, 200.0, 205.0, 210.0)
    energies = (10.3, 10.0, 10.1, 9.7, 9.9)
    fit = fit_energy_at_time({"a": list(zip(times, energies))}, 200.0, quadratic=False)
    x = np.array(times) / 200.0 - 1.0
    y = np.array(energies) / np.median(energies)
    coef = np.polyfit(x, y, 1)
    resid = y - np.polyval(coef, x)
    assert fit.residual_std == pytest.approx(np.sqrt(np.sum(resid ** 2) / 3), rel=1e-9)  # 5 runs - 2 parameters
    assert fit.slope == pytest.approx(coef[0], rel=1e-9) and fit.energy["a"] == pytest.approx(coef[1] * 10.0)
    # one model needs 1 + 3 runs for the curvature term: with 4 it is fitted, with 3 it is not
    quad = fit_energy_at_time({"a": list(zip(times[:4], energies[:4]))}, 200.0)
    c2 = np.polyfit(x[:4], np.array(energies[:4]) / np.median(energies[:4]), 2)
    assert quad.curvature == pytest.approx(c2[0], rel=1e-9) and quad.residual_std > 0.0
    three = fit_energy_at_time({"a": list(zip(times[:3], energies[:3]))}, 200.0)
    assert three.curvature == 0.0
