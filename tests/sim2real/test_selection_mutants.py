"""The selection's building blocks value by value: the segment split, the scaled (robust) linear fit with its block
covariance, out-of-fold prediction, AIC/BIC, fitted parameters with standard errors, and the clean errors."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from roadload.sim2real.errors import DiagnosisError
from roadload.sim2real.selection import (CandidateResult, Design, Fit, Split, cv_predict, fit_linear,
                                         fitted_parameters, information_criteria, make_split)
from roadload.sim2real.stats import block_ids, cluster_covariance


def _table(n_trips=2, duration=600.0, dt=1.0, invalid=()):
    frames = []
    for k in range(n_trips):
        t = np.arange(0.0, duration, dt)
        frames.append(pd.DataFrame({"trip": f"T{k}", "t": t, "valid": True}))
    tab = pd.concat(frames, ignore_index=True)
    for a, b in invalid:
        tab.loc[a:b, "valid"] = False
    return tab


# ------------------------------------------------------------------------------------------ split
def test_split_holds_out_every_kth_segment_of_each_trip_and_deals_the_rest_into_folds():
    tab = _table(invalid=[(0, 29)])
    split = make_split(tab, segment_length=60.0, test_fraction=1 / 3, n_folds=4, block_length=10.0, seed=5)
    seg = block_ids(tab["trip"].to_numpy(), tab["t"].to_numpy(), 60.0)
    np.testing.assert_array_equal(split.segments, seg)
    np.testing.assert_array_equal(split.blocks, block_ids(tab["trip"].to_numpy(), tab["t"].to_numpy(), 10.0))
    np.testing.assert_array_equal(split.valid, tab["valid"].to_numpy())
    assert not (split.test & ~split.valid).any() and not split.test[:30].any()
    np.testing.assert_array_equal(split.train, split.valid & ~split.test)
    for k in ("T0", "T1"):
        segs = np.unique(seg[tab["trip"].to_numpy() == k])
        test = [s for s in segs if split.test[seg == s].any()]
        assert len(test) in (3, 4)  # every 3rd of 10 segments, with a random phase
        assert np.all(np.diff(test) == 3)
        for s in test:  # whole segments (but the invalid rows)
            assert split.test[(seg == s) & split.valid].all()
    # every training row has a fold in 0..3, every other row -1; a segment lies in one fold
    assert set(np.unique(split.fold[split.train])) == {0, 1, 2, 3}
    assert (split.fold[~split.train] == -1).all()
    for s in np.unique(seg[split.train]):
        assert np.unique(split.fold[(seg == s) & split.train]).size == 1
    counts = np.bincount([split.fold[seg == s][split.train[seg == s]][0] for s in np.unique(seg[split.train])])
    assert counts.max() - counts.min() <= 1  # dealt round-robin after a shuffle
    assert split.n_folds == 4
    d = split.describe()
    assert (d.n_valid, d.n_train, d.n_test, d.n_folds) == (1170, int(split.train.sum()), int(split.test.sum()), 4)
    assert d.n_segments == 20 and d.n_test_segments == len(np.unique(seg[split.test]))
    assert d.n_train + d.n_test == d.n_valid
    # seeded: the same seed the same split, other seeds other phases
    again = make_split(tab, segment_length=60.0, test_fraction=1 / 3, n_folds=4, block_length=10.0, seed=5)
    np.testing.assert_array_equal(again.test, split.test)
    np.testing.assert_array_equal(again.fold, split.fold)
    assert any(not np.array_equal(make_split(tab, n_folds=4, seed=s).test, split.test) for s in range(6, 10))


@pytest.mark.parametrize("fraction, every", [(0.5, 2), (0.25, 4), (0.9, 2), (0.2, 5)])
def test_test_fraction_sets_the_holdout_period(fraction, every):
    tab = _table(n_trips=1, duration=1200.0)
    split = make_split(tab, test_fraction=fraction, n_folds=2, seed=1)
    test = np.unique(split.segments[split.test])
    assert np.all(np.diff(test) == every) and test[0] < every


@pytest.mark.parametrize("kwargs, drop, message", [
    ({}, "trip", r"the diagnosis table lacks the column 'trip'"),
    ({}, "t", r"lacks the column 't'"),
    ({}, "valid", r"lacks the column 'valid'"),
    ({"test_fraction": 0.0}, None, r"test_fraction must lie in \(0, 1\), got 0.0"),
    ({"test_fraction": 1.0}, None, r"test_fraction must lie in \(0, 1\), got 1.0"),
    ({"n_folds": 1}, None, r"n_folds must be >= 2, got 1"),
    ({"n_folds": 9}, None, r"too little valid data to split: \d+ training and \d+ test segments of 60 s \(need >= 9 "
                           r"and >= 1\); give longer trips"),
])
def test_bad_split_settings_are_refused(kwargs, drop, message):
    tab = _table(n_trips=1, duration=600.0)
    if drop:
        tab = tab.drop(columns=drop)
    with pytest.raises(DiagnosisError, match=message):
        make_split(tab, **kwargs)
    make_split(_table(n_trips=1, duration=600.0), n_folds=2)  # 10 segments: enough for 2 folds


def test_exactly_enough_training_segments_split():
    tab = _table(n_trips=1, duration=360.0)  # 6 segments: 2 held out, 4 for training
    split = make_split(tab, test_fraction=1 / 3, n_folds=4, seed=0)
    assert split.describe().n_segments == 6 and sorted(np.unique(split.fold[split.train])) == [0, 1, 2, 3]
    none_valid = _table(n_trips=1, duration=360.0)
    none_valid["valid"] = False
    with pytest.raises(DiagnosisError, match=r"0 training and 0 test segments"):
        make_split(none_valid, n_folds=2)


# ------------------------------------------------------------------------------------------ fitting
def _design(n=400, seed=0):
    rng = np.random.default_rng(seed)
    A = np.column_stack([np.ones(n), rng.normal(0, 1000.0, n), rng.normal(0, 1e-3, n)])  # wildly scaled columns
    X = np.array([3.0, 0.02, 500.0])
    return A, X, rng


def test_linear_fit_recovers_the_parameters_of_scaled_columns():
    A, X, rng = _design()
    y = A @ X
    rows = np.ones(len(y), bool)
    for robust in (False, True):
        np.testing.assert_allclose(fit_linear(A, y, rows, robust).X, X, rtol=1e-6)
    y_out = y + rng.normal(0, 0.1, len(y))
    y_out[::40] += 200.0  # gross outliers: Huber keeps the estimate, least squares not
    huber = fit_linear(A, y_out, rows, True).X
    ls = fit_linear(A, y_out, rows, False).X
    assert abs(huber[0] - 3.0) < 0.1 and abs(ls[0] - 3.0) > 4.0  # LS: the mean shift 200 / 40
    # only the given rows are fitted
    y_half = y.copy()
    y_half[200:] += 50.0
    half = np.arange(len(y)) < 200
    np.testing.assert_allclose(fit_linear(A, y_half, half, False).X, X, rtol=1e-6)
    # a column that is zero on the fitted rows gets scale 1, not a division by zero
    Az = A.copy()
    Az[:, 2] = 0.0
    Xz = fit_linear(Az, Az @ X, rows, False).X
    assert np.all(np.isfinite(Xz)) and Xz[:2] == pytest.approx(X[:2], rel=1e-6)
    assert fit_linear(A, y, rows, False).cov is None


def test_linear_fit_block_covariance_is_the_cluster_sandwich():
    A, X, rng = _design()
    y = A @ X + rng.normal(0, 1.0, len(A))
    rows = np.arange(len(A)) >= 50
    blocks = np.arange(len(A)) // 10
    fit = fit_linear(A, y, rows, False, blocks)
    expected = cluster_covariance(A[rows], y[rows] - A[rows] @ fit.X, blocks[rows], np.ones(rows.sum()))
    np.testing.assert_allclose(fit.cov, expected, rtol=1e-9)
    se = np.sqrt(np.diag(fit.cov))
    assert se[0] == pytest.approx(1.0 / np.sqrt(rows.sum()), rel=0.35)  # sigma / sqrt(n) for the intercept


def test_too_few_rows_or_a_bad_fit_are_refused():
    A, X, _ = _design(n=10)
    rows = np.zeros(10, bool)
    rows[:3] = True
    with pytest.raises(DiagnosisError, match=r"3 samples cannot determine 3 parameters"):
        fit_linear(A, A @ X, rows)
    rows[3] = True
    assert fit_linear(A, A @ X, rows, False).X == pytest.approx(X, rel=1e-6)  # 4 rows for 3 parameters
    y = A @ X
    y[0] = np.nan
    with pytest.raises(DiagnosisError, match=r"fit failed: "):
        fit_linear(A, y, np.ones(10, bool))


def test_cross_validated_prediction_is_out_of_fold_on_training_rows_only():
    n = 120
    fold = np.where(np.arange(n) < 100, np.arange(n) % 4, -1)
    test = np.arange(n) >= 100
    split = Split(np.ones(n, bool), test, fold, 4, np.arange(n) // 10, np.arange(n) // 30)
    A = np.column_stack([np.ones(n), np.arange(n, dtype=float)])
    y = 2.0 + 0.5 * np.arange(n)
    y[np.arange(n) % 4 == 1] += 8.0  # fold 1 is shifted: its prediction comes from the other folds only
    pred = cv_predict(A, y, pd.DataFrame(index=range(n)), split, robust=False)
    assert np.isnan(pred[test]).all() and np.isfinite(pred[~test]).all()
    others = fold >= 0
    for k in range(4):
        train = others & (fold != k)
        X = np.linalg.lstsq(A[train], y[train], rcond=None)[0]
        np.testing.assert_allclose(pred[fold == k], A[fold == k] @ X, rtol=1e-9)
    assert np.mean(y[fold == 1] - pred[fold == 1]) == pytest.approx(8.0, rel=1e-6)
    zero = cv_predict(None, y, pd.DataFrame(index=range(n)), split)
    assert (zero[~test] == 0.0).all() and np.isnan(zero[test]).all()
    # a fold without rows is skipped
    split3 = Split(np.ones(n, bool), test, np.where(fold == 3, 0, fold), 4, split.blocks, split.segments)
    assert np.isfinite(cv_predict(A, y, pd.DataFrame(index=range(n)), split3, robust=False)[~test]).all()


# ------------------------------------------------------------------------------------------ criteria, parameters
def test_information_criteria_are_eq_3_5b_and_3_6b():
    aic, bic = information_criteria(50.0, 100, 3)
    assert aic == pytest.approx(100 * np.log(0.5) + 6.0, rel=1e-12)
    assert bic == pytest.approx(100 * np.log(0.5) + 3 * np.log(100), rel=1e-12)
    aic0, bic0 = information_criteria(0.0, 10, 0)  # a perfect fit: floored, finite
    assert np.isfinite(aic0) and aic0 == bic0 == pytest.approx(10 * np.log(1e-300 / 10))
    assert isinstance(aic, float) and isinstance(bic, float)


def test_fitted_parameters_of_one_effect_with_standard_errors_and_units():
    d = Design(np.zeros((5, 3)), ["base 0", "delta m_V", "tau"], ["-", "kg", "s"], ["base", "mass", "mass"])
    fit = Fit(np.array([1.0, 120.0, 4.0]), np.diag([9.0, 16.0, -1e-12]))
    values, errors, units = fitted_parameters(d, fit, "mass")
    assert values == {"delta m_V": 120.0, "tau": 4.0} and units == {"delta m_V": "kg", "tau": "s"}
    assert errors == {"delta m_V": 4.0, "tau": 0.0}  # a tiny negative variance is clipped to zero
    _, no_cov, _ = fitted_parameters(d, Fit(fit.X, None), "mass")
    assert all(np.isnan(v) for v in no_cov.values()) and list(no_cov) == ["delta m_V", "tau"]
    assert fitted_parameters(d, fit, "wind") == ({}, {}, {})


def test_candidate_result_dictionary_names_every_figure():
    r = CandidateResult("wind", "headwind", 2.0, "tau", {"w": 1.5}, {"w": 0.1}, {"w": "m/s"}, 0.8, 1.0, 0.2,
                        (0.2, 0.05, 0.09), True, 10.0, 12.0, 0.0, 1.5, 0.7, "wind", {"mean_speed": 1.5}, "hint",
                        0.004, 35.0)
    d = r.to_dict()
    assert d == {"null_p": 0.004, "size_rms": 35.0, "name": "wind", "description": "headwind", "shape": 2.0,
                 "shape_name": "tau", "parameters": {"w": 1.5}, "std_errors": {"w": 0.1}, "units": {"w": "m/s"},
                 "cv_mse": 0.8, "baseline_cv_mse": 1.0, "heldout_improvement": 0.2,
                 "heldout_gain": [0.2, 0.05, 0.09], "significant": True, "aic": 10.0, "bic": 12.0,
                 "delta_aic": 0.0, "delta_bic": 1.5, "explained_fraction": 0.7, "sim_effect": "wind",
                 "sim_parameters": {"mean_speed": 1.5}, "regime_hint": "hint"}


# ------------------------------------------------------------------------------------------ the selector
def _core():
    """The synthetic force tables of test_core (one definition of the test world)."""
    import importlib.util
    from pathlib import Path

    spec = importlib.util.spec_from_file_location("sim2real_core_tables", Path(__file__).with_name("test_core.py"))
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_selector_refuses_a_residual_of_the_wrong_length_or_not_finite_on_valid_rows():
    from roadload.sim2real.selection import Selector

    core = _core()
    tab = core.synth(lambda t: np.zeros(len(t)), n_trips=2, duration=300.0)
    split = make_split(tab, n_folds=4)
    y = tab.residual.to_numpy()
    with pytest.raises(DiagnosisError, match=r"^residual and table differ in length$"):
        Selector(tab, y[:-1], split, core.MODEL)
    bad = y.copy()
    bad[[3, 7, 9]] = [np.nan, np.inf, -np.inf]
    with pytest.raises(DiagnosisError, match=r"^the residual is not finite on 3 valid rows$"):
        Selector(tab, bad, split, core.MODEL)
    tab.loc[[3, 7, 9], "valid"] = False  # rows outside the split may hold anything
    sel = Selector(tab, bad, make_split(tab, n_folds=4), core.MODEL)
    assert sel.residual.dtype == float and np.isnan(sel.baseline_loss[3])
    np.testing.assert_array_equal(sel.baseline_loss[sel.split.train], bad[sel.split.train] ** 2)
    assert np.isnan(sel.baseline_loss[~sel.split.train]).all()


def test_selector_names_the_candidates_it_cannot_fit_and_profiles_the_shape():
    from roadload.sim2real.catalog import get_candidate
    from roadload.sim2real.selection import Selector

    core = _core()
    d_true = 2500.0

    def warm(tab):  # cold tires: rolling resistance +40 % decaying over 2.5 km
        th, v = tab.gradient_angle.to_numpy(), tab.speed.to_numpy()
        return 0.4 * core.MODEL.mass * 9.81 * np.cos(th) * core.MODEL.rolling_resistance_coefficient(v) * np.exp(
            -tab.distance.to_numpy() / d_true)

    tab = core.synth(warm, n_trips=2, duration=400.0, noise=5.0).drop(columns="brake_force")
    sel = Selector(tab, tab.residual.to_numpy(), make_split(tab, n_folds=4), core.MODEL, robust=False)
    ok, skipped = sel.usable(["tire_warmup", "friction_brake", "auxiliary_power", "mass_offset"])
    assert [c.name for c in ok] == ["tire_warmup", "mass_offset"]  # the power side is not this selector's
    assert skipped == {"friction_brake": "needs ['brake_force'], which the trips do not provide"}
    assert sel.choose_shape(get_candidate("tire_warmup")) == d_true
    assert sel.choose_shape(get_candidate("mass_offset")) is None
    base, _ = sel.evaluate([])
    assert base == pytest.approx(np.mean(sel.residual[sel.split.train] ** 2), rel=1e-12)
    fitted, loss = sel.evaluate([(get_candidate("tire_warmup"), d_true)])
    assert fitted < 0.2 * base and np.isnan(loss[~sel.split.train]).all()


def test_forward_steps_report_consistent_figures_and_each_rejection_reason():
    """A mass offset in the synthetic trips: the first step accepts it with figures that agree with each other
    (losses as shares of the sim's original robust loss, the gain between them, the null quantile below the gain);
    later steps are rejected with the reason; a size floor above the effect leaves it insignificant, and a
    plausibility rule turns the step into a rejection naming the rule's reason."""
    from roadload.sim2real.selection import Selector

    core = _core()
    tab = core.synth(core.mass_extra, n_trips=2, duration=500.0)
    split = make_split(tab, seed=0, n_folds=4)

    def selector(**kw):
        return Selector(tab, tab.residual.to_numpy(), split, core.MODEL, robust=False, n_boot=150, seed=0, **kw)

    sel = selector()
    ranked, _ = sel.rank(("mass_offset", "drag_area", "rolling_scale"))
    steps = sel.forward(ranked)
    first = steps[0]
    assert (first.step, first.effect, first.shape, first.accepted, first.reason) == (1, "mass_offset", None, True,
                                                                                    "accepted")
    assert first.robust_loss_before == pytest.approx(1.0)
    assert first.robust_loss_after == pytest.approx(first.robust_loss_before - first.gain_of_original)
    assert first.relative_gain == pytest.approx(first.gain_of_original / first.robust_loss_before)
    assert first.gain[0] == first.gain_of_original and first.gain[1] == first.null_quantile
    assert np.isnan(first.gain[2]) and first.null_p <= sel.alpha
    assert 0.0 < first.null_quantile < first.gain_of_original
    assert 0.0 < first.reference_robust_loss < 1.0
    assert sel.min_explained <= first.explained_fraction <= 1.0 and first.implausible is None
    assert first.size_rms == pytest.approx(120.0 * np.sqrt(np.mean(((tab.acceleration + 9.81 * np.sin(
        tab.gradient_angle)) ** 2)[split.train])), rel=0.15)  # the RMS of 120 kg x (a + g sin theta) [N]
    assert sel.chosen[0][0].name == "mass_offset" and sel.robust_loss_after == first.robust_loss_after
    for s in steps[1:]:
        assert not s.accepted and s.step >= 2 and s.robust_loss_before == pytest.approx(first.robust_loss_after)
        assert s.reason.startswith(("held-out gain not beyond the null (p = ", "gain ", "partial fit: explains "))
    small = selector(min_size=1e9)  # a size floor above the effect: not significant, no step taken
    ranked_small = small.rank(("mass_offset",))[0]
    assert not ranked_small[0].significant and small.forward(ranked_small) == []
    odd = selector(plausible=lambda cand, params, shape: "payload beyond the vehicle's limit")
    steps = odd.forward(odd.rank(("mass_offset",))[0])
    assert not steps[0].accepted and steps[0].reason == "implausible: payload beyond the vehicle's limit"
    assert steps[0].implausible == "payload beyond the vehicle's limit" and odd.chosen == []
