"""Metrics and scenario generators of the robustness testbed on analytic cases."""

import numpy as np
import pytest

from roadload.experiments.robustness import (
    RobustnessError, breakdown_point, excitation_condition, inject_ab_outliers, recommended,
    recovery_time, relative_parameter_error, spread, synthetic_regression, windup_indicators,
)


def test_synthetic_regression_reproduces_experiment_3_3_structure():
    d = synthetic_regression(10_000, seed=1, unexcited=(1, 1000, 5000), step=(0, 5000, 1.5))
    assert d.A.shape == (10_000, 3) and d.B.shape == (10_000,)
    stretch = (d.t >= 1000) & (d.t < 6000)
    assert np.all(d.A[stretch, 1] == 0) and np.any(d.A[~stretch, 1] != 0)
    assert np.all(d.X_true[d.t < 5000, 0] == 1.0) and np.all(d.X_true[d.t >= 5000, 0] == 1.5)
    # B = Ā ⊙ X̄ summed plus white noise of variance 0.1
    resid = d.B - np.einsum("ij,ij->i", d.A_true, d.X_true)
    assert abs(np.var(resid) - 0.1) < 0.01
    # same seed -> same data; other seed -> other noise
    assert np.array_equal(d.B, synthetic_regression(10_000, seed=1, unexcited=(1, 1000, 5000),
                                                    step=(0, 5000, 1.5)).B)
    assert not np.array_equal(d.B, synthetic_regression(10_000, seed=2).B)


def test_ramp_and_input_noise():
    d = synthetic_regression(1000, seed=0, ramp=(2, 200, 400, 5.0), input_noise_var=(0, 0.01, 0.04))
    assert d.X_true[199, 2] == 3.0 and d.X_true[-1, 2] == 5.0
    assert abs(d.X_true[299, 2] - 4.0) < 0.02
    noise = d.A - d.A_true
    assert np.all(noise[:, 0] == 0)
    assert abs(np.var(noise[:, 2]) / np.var(noise[:, 1]) - 4.0) < 1.0


@pytest.mark.parametrize("pattern", ["isolated", "burst"])
def test_outlier_injection_counts_and_targets(pattern):
    d = synthetic_regression(2000, seed=0, output_noise_var=0.0)
    o = inject_ab_outliers(d, 0.1, magnitude=4.0, target="output", pattern=pattern, burst_length=25, seed=3)
    assert o.outlier_mask.sum() == 200
    assert np.array_equal(o.A, d.A)                     # output only
    changed = o.B != d.B
    assert np.array_equal(changed, o.outlier_mask)
    assert np.max(np.abs(o.B - d.B)) <= 4.0 * np.std(d.B_true) + 1e-12
    if pattern == "burst":   # bursts: far fewer run starts than corrupted samples
        starts = np.sum(np.diff(o.outlier_mask.astype(int)) == 1)
        assert starts <= 200 / 25 + 1
    i = inject_ab_outliers(d, 0.05, target="input", seed=3)
    assert np.array_equal(i.B, d.B) and np.sum(np.any(i.A != d.A, axis=1)) == 100
    assert np.array_equal(inject_ab_outliers(d, 0.0, target="both").B, d.B)


def test_outlier_injection_rejects_bad_spec():
    d = synthetic_regression(100, seed=0)
    with pytest.raises(RobustnessError, match="fraction"):
        inject_ab_outliers(d, 0.7)
    with pytest.raises(RobustnessError, match="target"):
        inject_ab_outliers(d, 0.1, target="speed")
    with pytest.raises(RobustnessError, match="pattern"):
        inject_ab_outliers(d, 0.1, pattern="clustered")


def test_relative_parameter_error():
    X = np.array([[1.0, 100.0], [1.0, 100.0]])
    err = relative_parameter_error(np.array([[1.1, 100.0], [np.nan, 100.0]]), X)
    assert err[0] == pytest.approx(np.sqrt(0.01 / 2))
    assert err[1] == np.inf
    with pytest.raises(RobustnessError, match="shape"):
        relative_parameter_error(np.zeros((2, 3)), X)


def test_recovery_time():
    t = np.arange(100.0)
    err = np.full(100, 0.01)
    err[50:70] = 1.0           # error rises after a step at t=50, back below the bound at t=70
    assert recovery_time(t, err, 50.0, bound=0.1) == 20.0
    err[75] = 1.0              # a one-sample relapse: with a 10 s hold the recovery counts from t=76
    assert recovery_time(t, err, 50.0, bound=0.1, hold=10.0) == 26.0
    assert recovery_time(t, err, 50.0, bound=0.1, hold=0.0) == 20.0
    assert recovery_time(t, np.full(100, 0.01), 50.0, bound=0.1) == 0.0
    never = np.r_[np.full(50, 0.01), np.full(50, 1.0)]
    assert recovery_time(t, never, 50.0, bound=0.1) == np.inf
    with pytest.raises(RobustnessError, match="after the end"):
        recovery_time(t, err, 500.0, bound=0.1)


def test_windup_indicators_full_and_diagonal():
    P = np.stack([np.diag([1.0, 1.0]), np.diag([4.0, 0.5]), np.array([[2.0, 1.0], [1.0, 2.0]])])
    full = windup_indicators(P)
    assert full["trace_P_max"] == pytest.approx(4.5)
    assert full["cond_P_max"] == pytest.approx(8.0)
    assert windup_indicators(P, window=np.array([True, False, True]))["cond_P_max"] == pytest.approx(3.0)
    diag = windup_indicators(np.array([[1.0, 1.0], [4.0, 0.5]]))
    assert diag["trace_P_max"] == pytest.approx(4.5) and diag["cond_P_lower_bound_max"] == pytest.approx(8.0)
    blown = windup_indicators(np.array([[1.0, np.inf]]))
    assert blown["trace_P_max"] == np.inf


def test_excitation_condition_flags_unexcited_stretch():
    d = synthetic_regression(3000, seed=0, unexcited=(1, 1000, 1000))
    c = excitation_condition(d.A, window=200)
    assert np.all(np.isnan(c[:199]))
    assert np.nanmax(c[(d.t > 500) & (d.t < 1000)]) < 100
    assert np.all(np.isinf(c[(d.t > 1250) & (d.t < 2000)]))


def test_breakdown_point_and_spread():
    levels = [0.0, 0.05, 0.1, 0.2, 0.3]
    assert breakdown_point(levels, [0.01, 0.02, 0.5, 0.9, 1.0], bound=0.1) == 0.1
    assert breakdown_point(levels, [0.01, 0.02, 0.03, np.nan, 0.0], bound=0.1) == 0.2
    assert breakdown_point(levels, [0.01] * 5, bound=0.1) == np.inf
    # relative to the fault-free error: a biased but stable estimator does not "break down"
    assert breakdown_point(levels, [0.3, 0.32, 0.35, 0.45, 0.6], bound=0.1, baseline=0.3) == 0.2
    with pytest.raises(RobustnessError, match="increasing"):
        breakdown_point([0.1, 0.0], [0, 0], 0.1)
    s = spread([1.0, 2.0, 3.0, 4.0, np.nan])
    assert s["median"] == 2.5 and s["n"] == 4
    assert spread([0.1, 0.2, np.inf])["q75"] == np.inf


def test_decision_tree_lookup():
    assert recommended("prediction", True, True) == ("RRLM", "RMKF", "SGMKF")
    assert "RIV" in recommended("parameters", False, False)
    with pytest.raises(RobustnessError, match="aim"):
        recommended("speed", False, False)


def test_breakdown_table_rank_and_decision_tree_checks_on_a_handmade_sweep():
    import pandas as pd

    from roadload.experiments.robustness import SYNTHETIC_SWEEPS, breakdown_table, decision_tree_checks, rank

    levels = [0.0, 0.05, 0.1, 0.2]
    err = {"RLS": [0.30, 0.35, 0.45, 0.9], "RLM": [0.30, 0.30, 0.31, 0.32], "RRLM": [0.31, 0.31, 0.33, 0.5],
           "KF": [0.2, 0.5, 0.6, 0.7]}
    rows = [{"backend": "synthetic", "sweep": "outliers", "variant": "output/isolated", "model": "synthetic",
             "estimator": e, "level": lv, "seed": s, "rel_error": v + 0.001 * s}
            for e, vals in err.items() for lv, v in zip(levels, vals) for s in range(3)]
    res = pd.DataFrame(rows)
    bd = breakdown_table(res, bound=0.1).set_index("estimator")["breakdown"]
    # excess over the level-0 error: RLS +0.15 at 0.1, RLM never, RRLM +0.19 at 0.2, KF +0.3 at 0.05
    assert bd.to_dict() == {"KF": 0.05, "RLM": np.inf, "RLS": 0.1, "RRLM": 0.2}
    ranking = rank(res, SYNTHETIC_SWEEPS["outliers"], bound=0.1)
    assert list(ranking.sort_values("rank")["estimator"]) == ["RLM", "RRLM", "RLS", "KF"]
    checks = decision_tree_checks(res, SYNTHETIC_SWEEPS["outliers"], bound=0.1)
    group = [c for c in checks if c["metric"] == "breakdown"][0]
    assert group["agrees"] is True and group["group_median"] > group["others_median"]
    pairs = {c["metric"]: c["agrees"] for c in checks if " vs " in c["metric"]}
    assert pairs == {"RLM vs RLS": True, "RRLM vs RLS": True}
    tie = res.copy()
    tie.loc[tie["estimator"] == "RLS", "rel_error"] = 0.3      # RLS never breaks down either: a tie
    pairs = {c["metric"]: c["agrees"] for c in decision_tree_checks(tie, SYNTHETIC_SWEEPS["outliers"], 0.1)
             if " vs " in c["metric"]}
    assert pairs["RLM vs RLS"] is None and pairs["RRLM vs RLS"] is False
