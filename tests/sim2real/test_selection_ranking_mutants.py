"""The selector's ranking and forward selection figure by figure against the same quantities written out: the shape
profile and out-of-fold losses with the selector's own robust fit and reference, the pick of a forward step (the
largest gain of the pool, whatever the pool's order), the explained share, the information criteria of the ranking,
and the final fit's braking mask (synthetic force tables of ``test_core``, no simulator)."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from roadload.sim2real.catalog import get_candidate
from roadload.sim2real.errors import DiagnosisError
from roadload.estimators.batch import m_estimate
from roadload.sim2real.robust import robust_target, step_statistics
from roadload.sim2real.selection import (Selector, cv_predict, design, fit_linear, fitted_parameters,
                                         information_criteria, make_split)
from roadload.sim2real.stats import block_ids, cluster_covariance


# the synthetic force tables of test_core (one definition of the test world)
_SPEC = importlib.util.spec_from_file_location("sim2real_core_tables", Path(__file__).with_name("test_core.py"))
assert _SPEC is not None and _SPEC.loader is not None
CORE = importlib.util.module_from_spec(_SPEC)
_SPEC.loader.exec_module(CORE)
D_TRUE = 2500.0  # [m] the tire warm-up's decay distance
NAMES = ("mass_offset", "drag_area", "rolling_scale", "torque_scale")


def _warm(tab):
    """Cold tires: rolling resistance +40 % decaying over D_TRUE [N]."""
    th, v = tab.gradient_angle.to_numpy(), tab.speed.to_numpy()
    return 0.4 * CORE.MODEL.mass * 9.81 * np.cos(th) * CORE.MODEL.rolling_resistance_coefficient(v) * np.exp(
        -tab.distance.to_numpy() / D_TRUE)


@pytest.fixture(scope="module")
def contaminated():
    """Tire warm-up plus gross outliers (+2 kN every 10th row between 3 and 6 km): Huber and least squares
    profile the decay distance differently here."""
    tab = CORE.synth(_warm, n_trips=2, duration=400.0, noise=5.0)
    y = tab.residual.to_numpy().copy()
    dist = tab.distance.to_numpy()
    y[np.flatnonzero((dist > 3000.0) & (dist < 6000.0))[::10]] += 2000.0
    return tab, y, make_split(tab, n_folds=4)


def _profile(A_of, y, rows, robust, grid):
    """The grid value with the smallest training SSE of the fit (the first on a tie)."""
    sse = []
    for sh in grid:
        A = A_of(sh)
        X = fit_linear(A, y, rows, robust).X
        sse.append(float(np.sum((y[rows] - A[rows] @ X) ** 2)))
    return grid[int(np.argmin(sse))]


def test_shape_profile_uses_the_selectors_robust_fit(contaminated):
    tab, y, split = contaminated
    cand = get_candidate("tire_warmup")
    grid = list(cand.shape_grid)
    chosen = {}
    for robust in (True, False):
        sel = Selector(tab, y, split, CORE.MODEL, robust=robust)
        expected = _profile(lambda sh: design([(cand, sh)], CORE.MODEL, sel.cols).A, y, split.train, robust, grid)
        chosen[robust] = sel.choose_shape(cand)
        assert chosen[robust] == expected
    assert chosen[True] != chosen[False]  # the world tells the two fits apart


def test_shape_profile_keeps_the_first_of_equal_fits():
    tab = CORE.synth(lambda t: np.zeros(len(t)), n_trips=2, duration=300.0, noise=0.0)
    sel = Selector(tab, np.zeros(len(tab)), make_split(tab, n_folds=4), CORE.MODEL)
    cand = get_candidate("tire_warmup")
    assert sel.choose_shape(cand) == cand.shape_grid[0]  # every shape fits a zero residual exactly


def test_out_of_fold_loss_uses_the_selectors_robust_fit_and_the_reference(contaminated):
    tab, y, split = contaminated
    choice = [(get_candidate("tire_warmup"), D_TRUE)]
    A = design(choice, CORE.MODEL, Selector(tab, y, split, CORE.MODEL).cols).A
    for robust in (True, False):
        sel = Selector(tab, y, split, CORE.MODEL, robust=robust)
        for reference in (False, True):
            pred = cv_predict(A, y, tab, split, robust, reference)
            loss = np.where(split.train, (y - np.nan_to_num(pred)) ** 2, np.nan)
            mse, got = sel.evaluate(choice, reference=reference)
            assert mse == pytest.approx(float(np.nanmean(loss)), rel=1e-12)
            np.testing.assert_allclose(got, loss, rtol=1e-12)
    sel = Selector(tab, y, split, CORE.MODEL, robust=True)
    plain, ref = sel.evaluate(choice)[0], sel.evaluate(choice, reference=True)[0]
    lsq = Selector(tab, y, split, CORE.MODEL, robust=False).evaluate(choice)[0]
    assert ref != pytest.approx(plain, rel=1e-6) and lsq != pytest.approx(plain, rel=1e-6)
    # no choice: the prediction is 0 (and the reference alone with reference=True)
    assert sel.evaluate([])[0] == pytest.approx(float(np.mean(y[split.train] ** 2)), rel=1e-12)
    ref_only = cv_predict(None, y, tab, split, True, True)
    assert sel.evaluate([], reference=True)[0] == pytest.approx(
        float(np.mean((y[split.train] - ref_only[split.train]) ** 2)), rel=1e-12)


@pytest.fixture(scope="module")
def mass_world():
    tab = CORE.synth(CORE.mass_extra, n_trips=2, duration=500.0)
    split = make_split(tab, seed=0, n_folds=4)

    def selector(**kw):
        return Selector(tab, tab.residual.to_numpy(), split, CORE.MODEL, robust=False, n_boot=150, seed=0, **kw)

    sel = selector()
    ranked, _ = sel.rank(NAMES)
    return tab, split, selector, ranked


def test_a_forward_step_takes_the_largest_gain_whatever_the_pools_order(mass_world):
    _, _, selector, ranked = mass_world
    significant = [r for r in ranked if r.significant]
    assert len(significant) >= 2 and significant[0].name == "mass_offset"
    sel = selector()
    steps = sel.forward(list(reversed(ranked)))  # the best candidate last in the pool
    assert steps[0].effect == "mass_offset" and steps[0].accepted


def test_a_steps_explained_share_is_its_gain_over_the_removable_part(mass_world):
    _, _, selector, ranked = mass_world
    steps = selector().forward(ranked)
    for s in steps:
        removable = s.robust_loss_before - min(s.reference_robust_loss, s.robust_loss_after)
        expected = min(s.gain_of_original / removable, 1.0) if removable > 0 else 0.0
        assert s.explained_fraction == pytest.approx(expected, rel=1e-12, abs=1e-15)
    assert steps[0].explained_fraction > 0.5


def test_a_step_that_loses_explains_nothing():
    """No gap, the significance rules switched off (alpha 1, any gain): after the first step the candidates
    only lose (gain < 0) and the reference is no better than the sim, so nothing is removable: each such step
    explains 0 (not the ratio of two negative numbers) and is a partial fit."""
    tab = CORE.synth(lambda t: np.zeros(len(t)), n_trips=2, duration=500.0)
    sel = Selector(tab, tab.residual.to_numpy(), make_split(tab, seed=0, n_folds=4), CORE.MODEL, robust=False,
                   n_boot=150, seed=0, alpha=1.0, min_gain=-1.0)
    steps = sel.forward(sel.rank(NAMES)[0])
    losing = [s for s in steps if s.gain_of_original < 0]
    assert losing and all(s.reference_robust_loss >= s.robust_loss_before for s in losing)
    for s in losing:
        assert s.explained_fraction == 0.0 and not s.accepted
        assert s.reason == f"partial fit: explains 0.00 of the removable remainder (< {sel.min_explained})"


def test_a_p_value_equal_to_alpha_passes(mass_world):
    """The level is inclusive (p <= alpha), in the ranking and in a forward step: with alpha set to the p-values
    the first run found, the same candidate is significant and the same step accepted."""
    _, _, selector, ranked = mass_world
    first = selector().forward(ranked)[0]
    top = ranked[0]
    assert first.accepted and top.significant and top.null_p > 0 and first.null_p > 0
    at_rank = selector(alpha=top.null_p)
    again = at_rank.rank(NAMES)[0]
    assert again[0].name == top.name and again[0].null_p == top.null_p and again[0].significant
    at_step = selector(alpha=first.null_p)
    step = at_step.forward(ranked)[0]
    assert step.null_p == first.null_p and step.accepted and step.reason == "accepted"



def _statistics(sel, choices):
    """The robust step statistics of ``choices`` (each with every shape variant) over the sim as is."""
    variants = [[sel.candidate_columns(c, sh) for sh in c.shapes()] for c in choices]
    return step_statistics(np.zeros((len(sel.table), 0)), variants, sel.target, sel.signs)


def test_ranking_figures_are_the_step_statistics_and_fits_written_out(mass_world):
    tab, split, selector, _ = mass_world
    sel = selector()
    names = NAMES + ("tire_warmup",)  # one candidate with a shape grid (its shape counts as a parameter)
    ranked, skipped = sel.rank(names)
    assert skipped == {}
    cands = [get_candidate(n) for n in names]
    stats = _statistics(sel, cands)
    y, tr = sel.residual, split.train
    m = int(tr.sum())
    aic0, bic0 = information_criteria(float(np.sum(y[tr] ** 2)), m, 0)
    info = sel.baseline_info
    ref_loss = info.reference_robust_loss
    assert (info.robust_loss, info.aic, info.bic) == (1.0, aic0, bic0)
    assert info.null.draws == sel.n_null and info.null.alpha == sel.alpha
    assert [r.improvement for r in ranked] == sorted((r.improvement for r in ranked), reverse=True)
    aics, bics = [aic0], [bic0]
    for r in ranked:
        j = names.index(r.name)
        cand = cands[j]
        gain = float(stats.observed[j])
        null_j = stats.null[:, j]
        assert r.improvement == gain and r.cv_mse == 1.0 - gain and r.baseline_cv_mse == 1.0
        assert r.shape == cand.shapes()[int(stats.variant[j])]
        assert r.gain == (gain, float(np.quantile(null_j, 1 - sel.alpha)), float(null_j.max()))
        assert r.null_p == stats.marginal_p(j)
        d, fit = sel.final_fit([(cand, r.shape)])
        sse = float(np.sum((y[tr] - d.A[tr] @ fit.X) ** 2))
        assert (r.aic, r.bic) == information_criteria(sse, m, d.A.shape[1] + (1 if cand.shape_grid else 0))
        aics.append(r.aic)
        bics.append(r.bic)
        explainable = 1.0 - min(ref_loss, 1.0 - gain)
        assert r.explained_fraction == pytest.approx(min(gain / explainable, 1.0) if explainable > 0 else 0.0,
                                                     rel=1e-12)
        assert r.size == sel.effect_size(d, fit, cand.name)
        assert r.significant == (r.null_p <= sel.alpha and gain >= sel.min_gain and r.size >= sel.min_size)
        assert (r.description, r.shape_name, r.regime_hint, r.sim_effect) == (
            cand.description, cand.shape_name, cand.regime_hint, cand.sim_effect)
        values, errors, units = fitted_parameters(d, fit, cand.name)
        assert (r.parameters, r.std_errors, r.units) == (values, errors, units)
        assert all(np.isfinite(e) and e > 0 for e in errors.values())  # block-robust errors of the final fit
    for r in ranked:
        assert (r.delta_aic, r.delta_bic) == (r.aic - min(aics), r.bic - min(bics))
    assert (info.delta_aic, info.delta_bic) == (aic0 - min(aics), bic0 - min(bics))
    assert ranked[0].delta_aic == 0.0 and info.delta_aic > 0  # the mass offset is the best model here


def test_forward_step_figures_are_the_step_statistics_written_out(mass_world):
    _, _, selector, ranked = mass_world
    sel = selector()
    step = sel.forward(ranked)[0]
    pool = [get_candidate(r.name) for r in ranked if r.significant]
    stats = _statistics(sel, pool)
    j = int(np.argmax(stats.observed))
    gain = float(stats.observed[j])
    null_q = float(np.quantile(stats.null.max(axis=1), 1 - sel.alpha))
    assert (step.effect, step.gain_of_original, step.null_p) == (pool[j].name, gain, stats.p_value(j))
    assert step.robust_loss_before == stats.loss_before and step.robust_loss_after == stats.loss_before - gain
    assert step.null_quantile == null_q and step.gain[:2] == [gain, null_q]
    assert step.relative_gain == gain / stats.loss_before
    d, fit = sel.final_fit([(pool[j], step.shape)])
    assert step.size_rms == sel.effect_size(d, fit, pool[j].name)


def test_forward_rejection_reasons_name_their_figures(mass_world):
    _, _, selector, ranked = mass_world
    sel = selector()
    steps = sel.forward(ranked)
    by_p = [s for s in steps if s.null_p > sel.alpha]
    assert by_p
    for s in by_p:
        assert s.reason == f"held-out gain not beyond the null (p = {s.null_p:.3f} > {sel.alpha})"
    first = steps[0]
    # the gain and explained-share floors are inclusive too
    for kw in ({"min_gain": first.gain_of_original}, {"min_explained": first.explained_fraction}):
        again = selector(**kw).forward(ranked)[0]
        assert again.accepted and again.reason == "accepted", kw
    high = selector(min_gain=first.gain_of_original + 1e-9).forward(ranked)[0]
    floor = first.gain_of_original + 1e-9
    assert high.reason == f"gain {first.gain_of_original:.3f} of the original gap, below {floor}"


def test_each_rejection_names_the_first_rule_it_fails_and_the_floors_are_inclusive(mass_world):
    _, _, selector, ranked = mass_world
    first = selector().forward(ranked)[0]
    gain, p, size = first.gain_of_original, first.null_p, first.size_rms
    # p exactly at the level passes that rule: the gain rule is the one named
    step = selector(alpha=p, min_gain=gain + 1e-9).forward(ranked)[0]
    assert step.reason.startswith(f"gain {gain:.3f} of the original gap, below ") and step.accepted is False
    # the gain exactly at its floor passes: the explained-share rule is the one named
    step = selector(min_gain=gain, min_explained=1.5).forward(ranked)[0]
    assert step.reason == f"partial fit: explains {step.explained_fraction:.2f} of the removable remainder (< 1.5)"
    # a size exactly at its floor passes; above the floor the step is rejected as too small (False, not falsy)
    assert selector(min_size=size).forward(ranked)[0].accepted is True
    step = selector(min_size=2 * size).forward(ranked)[0]
    assert step.accepted is False and step.implausible is None
    assert step.reason == f"too small: the fitted effect's RMS {size:.3g} is below {2 * size:g}"


def test_fitted_columns_and_effect_size_with_a_base_design():
    """With a base calibration's columns joined: braking rows zero the columns of effects that are not about the
    friction brake (the base's and the brake's stand), and an effect's size is its contribution net of what the
    other columns can take (least squares on the training rows)."""
    tab = CORE.synth(CORE.mass_extra, n_trips=2, duration=300.0)
    braking = (np.arange(len(tab)) % 500) < 40
    tab.loc[braking, "mode"] = "braking"
    tab.loc[braking, "brake_force"] = 800.0
    split = make_split(tab, seed=0, n_folds=4)
    base = np.column_stack([np.ones(len(tab)), tab.speed.to_numpy()])  # not zero on braking rows: left as given
    y = tab.residual.to_numpy()
    sel = Selector(tab, y, split, CORE.MODEL, robust=False, base_design=base)
    assert sel.target.braking[braking].all()
    d, fit = sel.final_fit([(get_candidate("mass_offset"), None), (get_candidate("friction_brake"), None)])
    assert d.owner[:2] == ["base", "base"] and set(d.owner[2:]) == {"mass_offset", "friction_brake"}
    assert d.names[:2] == ["base 0", "base 1"] and d.units[:2] == ["-", "-"] and len(d.names) == d.A.shape[1]
    np.testing.assert_array_equal(d.A[:, :2], base)
    cols = sel.fitted_columns(d)
    mass = np.array([o == "mass_offset" for o in d.owner])
    rows = sel.target.braking
    assert (cols[np.ix_(rows, mass)] == 0.0).all() and (cols[np.ix_(~rows, mass)] == d.A[np.ix_(~rows, mass)]).all()
    np.testing.assert_array_equal(cols[:, ~mass], d.A[:, ~mass])
    assert (d.A[np.ix_(rows, mass)] != 0.0).any()  # the design itself is full (for predicting everywhere)
    tr = split.train
    own, other = np.flatnonzero(mass), np.flatnonzero(~mass)
    contrib = cols[np.ix_(tr, own)] @ fit.X[own]
    B = cols[np.ix_(tr, other)]
    net = contrib - B @ np.linalg.lstsq(B, contrib, rcond=None)[0]
    size = sel.effect_size(d, fit, "mass_offset")
    assert size == pytest.approx(float(np.sqrt(np.mean(net ** 2))), rel=1e-9)
    assert 0.0 < size < float(np.sqrt(np.mean(contrib ** 2)))  # the base takes part of it
    assert sel.effect_size(d, fit, "wind") == 0.0  # no columns of its own
    plain = Selector(tab, y, split, CORE.MODEL, robust=False)
    d0, fit0 = plain.final_fit([(get_candidate("mass_offset"), None)])
    assert plain.effect_size(d0, fit0, "mass_offset") == pytest.approx(
        float(np.sqrt(np.mean((d0.A[tr] @ fit0.X) ** 2))), rel=1e-12)  # without a base: not netted


def test_split_defaults_and_its_seeded_phase():
    """Defaults: 60 s segments, every 3rd held out from a seeded random phase per trip, 5 folds, 10 s blocks."""
    tab = CORE.synth(lambda t: np.zeros(len(t)), n_trips=3, duration=720.0)
    split = make_split(tab)
    trip, t = tab["trip"].to_numpy(), tab["t"].to_numpy()
    np.testing.assert_array_equal(split.blocks, block_ids(trip, t, 10.0))
    np.testing.assert_array_equal(split.segments, block_ids(trip, t, 60.0))
    assert split.n_folds == 5 and set(np.unique(split.fold[split.train])) == set(range(5))
    rng = np.random.default_rng(0)  # the phase of each trip, in trip order, is the seed's first draws in [0, 3)
    for k in pd.unique(trip):
        phase = int(rng.integers(0, 3))
        segs = np.unique(split.segments[trip == k])
        held = [i for i, s in enumerate(segs) if split.test[split.segments == s].all()]
        assert held == [i for i in range(len(segs)) if (i + phase) % 3 == 0]
    assert any(not np.array_equal(make_split(tab, seed=s).test, split.test) for s in range(1, 8))


def test_split_reads_a_valid_flag_of_zeros_and_ones_as_booleans():
    tab = CORE.synth(lambda t: np.zeros(len(t)), n_trips=2, duration=600.0)
    tab.loc[100:700, "valid"] = False
    as_int = tab.assign(valid=tab["valid"].astype(int))
    a, b = make_split(tab, seed=2), make_split(as_int, seed=2)
    for field in ("valid", "test", "fold"):
        np.testing.assert_array_equal(getattr(a, field), getattr(b, field))
    assert b.valid.dtype == bool and not b.train[100:701].any() and b.train.sum() == a.train.sum() > 0


def test_a_consistency_rule_alone_rejects_a_step_with_its_reason(mass_world):
    _, _, selector, ranked = mass_world
    seen = []

    def consistent(cand, params, shape, size):
        seen.append((cand.name, dict(params), shape, size))
        return "the power side shows no such mass"

    sel = selector(consistent=consistent)
    step = sel.forward(ranked)[0]
    assert step.effect == "mass_offset" and step.accepted is False
    assert step.reason == "implausible: the power side shows no such mass"
    assert step.implausible == "the power side shows no such mass" and sel.chosen == []
    name, params, shape, size = seen[0]
    assert (name, shape, size) == ("mass_offset", None, step.size_rms) and set(params) == {"delta m_V"}
    # a rule that finds nothing wrong leaves the step accepted
    assert selector(consistent=lambda *a: None).forward(ranked)[0].accepted is True


def test_without_null_draws_the_intervals_collapse_to_the_gain():
    """n_null = 0: no bootstrap draws, so every p is 1, the ranking's interval is the gain itself and a step's
    null quantile is NaN (nothing to take it from); alpha 1 lets the steps run."""
    tab = CORE.synth(CORE.mass_extra, n_trips=2, duration=300.0)
    sel = Selector(tab, tab.residual.to_numpy(), make_split(tab, seed=0, n_folds=4), CORE.MODEL, robust=False,
                   n_null=0, alpha=1.0, seed=0)
    ranked = sel.rank(("mass_offset", "drag_area"))[0]
    for r in ranked:
        assert r.null_p == 1.0 and r.gain == (r.improvement, r.improvement, r.improvement)
    steps = sel.forward(ranked)
    assert steps and all(s.null_p == 1.0 and np.isnan(s.null_quantile) for s in steps)
    assert steps[0].relative_gain == pytest.approx(steps[0].gain_of_original / steps[0].robust_loss_before)


def test_with_a_base_design_every_step_is_judged_over_the_base_and_the_chosen_effects():
    tab = CORE.synth(CORE.mass_extra, n_trips=2, duration=400.0)
    split = make_split(tab, seed=0, n_folds=4)
    base = np.column_stack([np.ones(len(tab)), tab.speed.to_numpy()])
    sel = Selector(tab, tab.residual.to_numpy(), split, CORE.MODEL, robust=False, n_boot=150, seed=0,
                   base_design=base, alpha=1.0, min_gain=-1.0, min_explained=-1.0)
    names = ("mass_offset", "drag_area", "rolling_scale")
    ranked = sel.rank(names)[0]
    cands = [get_candidate(n) for n in names]
    variants = [[sel.candidate_columns(c, sh) for sh in c.shapes()] for c in cands]
    stats = step_statistics(base, variants, sel.target, sel.signs)
    for r in ranked:
        assert r.improvement == float(stats.observed[names.index(r.name)])
    steps = sel.forward(ranked)
    assert len(steps) == 3 and all(s.accepted for s in steps)
    first = get_candidate(steps[0].effect)
    rest = [c for c in cands if c.name != first.name]
    after_first = np.hstack([base, sel.candidate_columns(first, steps[0].shape)])
    stats2 = step_statistics(after_first, [[sel.candidate_columns(c, sh) for sh in c.shapes()] for c in rest],
                             sel.target, sel.signs)
    j = int(np.argmax(stats2.observed))
    assert (steps[1].effect, steps[1].robust_loss_before, steps[1].gain_of_original) == (
        rest[j].name, stats2.loss_before, float(stats2.observed[j]))


def test_forward_takes_at_most_four_effects_from_the_top_six_by_default():
    """Every rule switched off (alpha 1, any gain, any explained share): the steps stop at max_effects (4 by
    default) or when the pool of the six best-ranked significant candidates is used up."""
    tab = CORE.synth(lambda t: np.zeros(len(t)), n_trips=2, duration=300.0)
    sel = Selector(tab, tab.residual.to_numpy(), make_split(tab, seed=0, n_folds=4), CORE.MODEL, robust=False,
                   n_null=19, seed=0, alpha=1.0, min_gain=-1.0, min_explained=-1.0)
    ranked = sel.rank(("mass_offset", "drag_area", "rolling_scale", "torque_scale", "rolling_speed", "wind",
                       "accel_bias"))[0]
    assert len(ranked) == 7 and all(r.significant for r in ranked)
    steps = sel.forward(ranked)
    assert len(steps) == 4 and all(s.accepted for s in steps) and len(sel.chosen) == 4
    steps = sel.forward(ranked, max_effects=10)
    assert len(steps) == 6 and {s.effect for s in steps} == {r.name for r in ranked[:6]}


def test_design_zeroes_non_finite_regressor_values():
    tab = CORE.synth(lambda t: np.zeros(len(t)), n_trips=1, duration=60.0)
    tab.loc[[3, 5, 7], "acceleration"] = [np.nan, np.inf, -np.inf]
    sel = Selector(tab, tab.residual.to_numpy(), make_split(tab, n_folds=2, segment_length=10.0), CORE.MODEL)
    A = design([(get_candidate("mass_offset"), None)], CORE.MODEL, sel.cols).A
    assert (A[[3, 5, 7], 0] == 0.0).all() and np.isfinite(A).all() and (A[[2, 4, 6, 8], 0] != 0.0).all()


def test_a_robust_fits_block_covariance_uses_the_huber_weights():
    rng = np.random.default_rng(4)
    n = 600
    A = np.column_stack([np.ones(n), rng.normal(0.0, 2.0, n)])
    y = A @ np.array([1.0, 3.0]) + rng.normal(0.0, 0.5, n)
    y[::15] += 40.0  # outliers the Huber weights take down
    rows, blocks = np.ones(n, bool), np.arange(n) // 20
    fit = fit_linear(A, y, rows, True, blocks)
    scale = np.sqrt(np.mean(A ** 2, axis=0))
    weights = m_estimate(A / scale, y, "huber", max_iter=15, tol=1e-5).weights
    np.testing.assert_allclose(fit.cov, cluster_covariance(A, y - A @ fit.X, blocks, weights), rtol=1e-9)
    unweighted = cluster_covariance(A, y - A @ fit.X, blocks, None)
    assert not np.allclose(fit.cov, unweighted, rtol=1e-3)


def test_the_selector_passes_its_clip_to_the_robust_target_and_stores_a_float_residual():
    tab = CORE.synth(CORE.mass_extra, n_trips=2, duration=300.0)
    split = make_split(tab, seed=0, n_folds=4)
    y = tab.residual.to_numpy()
    for clip in (0.5, 5.0):
        sel = Selector(tab, y, split, CORE.MODEL, clip=clip)
        expected = robust_target(tab, y, split.train, split.blocks, split.fold, split.n_folds, clip=clip)
        np.testing.assert_array_equal(sel.target.r_w, expected.r_w)
    assert not np.array_equal(Selector(tab, y, split, CORE.MODEL, clip=0.5).target.r_w,
                              Selector(tab, y, split, CORE.MODEL).target.r_w)
    as_int = Selector(tab, np.round(y).astype(int), split, CORE.MODEL)
    assert as_int.residual.dtype == float


def test_reference_loss_with_a_base_design_and_chosen_effects():
    tab = CORE.synth(CORE.mass_extra, n_trips=2, duration=300.0)
    split = make_split(tab, seed=0, n_folds=4)
    base = np.column_stack([np.ones(len(tab)), tab.speed.to_numpy()])
    y = tab.residual.to_numpy()
    sel = Selector(tab, y, split, CORE.MODEL, robust=False, n_boot=150, seed=0, base_design=base, alpha=1.0,
                   min_gain=-1.0, min_explained=-1.0)  # every step accepted: the second sees the first's effect
    t = sel.target
    rows = t.segment >= 0
    norm = float(np.sum(t.weight[rows] * t.r_w[rows] ** 2))

    def loss_of(A):
        pred = cv_predict(A, y, tab, split, False, reference=True)
        return float(np.sum(t.weight[rows] * (t.r_w[rows] - np.nan_to_num(pred[rows])) ** 2)) / norm

    ranked = sel.rank(("mass_offset", "drag_area"))[0]
    assert sel.baseline_info.reference_robust_loss == pytest.approx(loss_of(base), rel=1e-12)
    steps = sel.forward(ranked)
    chosen = design([(get_candidate(steps[0].effect), steps[0].shape)], CORE.MODEL, sel.cols).A
    assert len(steps) >= 2 and steps[0].accepted
    assert steps[1].reference_robust_loss == pytest.approx(loss_of(np.hstack([base, chosen])), rel=1e-12)
    assert steps[1].reference_robust_loss != pytest.approx(steps[0].reference_robust_loss, rel=1e-6)


def test_a_zero_residual_has_no_reference_loss():
    tab = CORE.synth(lambda t: np.zeros(len(t)), n_trips=2, duration=300.0)
    sel = Selector(tab, np.zeros(len(tab)), make_split(tab, seed=0, n_folds=4), CORE.MODEL, robust=False, n_null=19)
    sel.rank(("mass_offset",))
    assert np.isnan(sel.baseline_info.reference_robust_loss)


def test_the_plausibility_rule_reads_the_fitted_shape():
    tab = CORE.synth(_warm, n_trips=2, duration=400.0, noise=5.0)
    seen = []
    sel = Selector(tab, tab.residual.to_numpy(), make_split(tab, n_folds=4), CORE.MODEL, robust=False, n_boot=150,
                   plausible=lambda cand, params, shape: seen.append((cand.name, shape)))
    steps = sel.forward(sel.rank(("tire_warmup", "mass_offset"))[0])
    assert steps[0].effect == "tire_warmup" and steps[0].accepted and steps[0].shape == D_TRUE
    assert seen[0] == ("tire_warmup", D_TRUE)


def test_a_step_whose_final_fit_fails_names_the_fits_error_and_the_next_candidate_is_tried(mass_world):
    _, _, selector, ranked = mass_world
    sel = selector()
    real_fit = sel.final_fit

    def final_fit(choices):
        if any(c.name == "mass_offset" for c, _ in choices):
            raise DiagnosisError("design matrix rank 3 of 4: mass_offset collinear with the base")
        return real_fit(choices)

    sel.final_fit = final_fit
    steps = sel.forward(ranked)
    first = steps[0]
    assert first.effect == "mass_offset" and first.accepted is False and first.implausible is None
    assert first.reason == "final fit failed: design matrix rank 3 of 4: mass_offset collinear with the base"
    assert np.isnan(first.size_rms) and all(c.name != "mass_offset" for c, _ in sel.chosen)
    assert len(steps) >= 2 and steps[1].effect != "mass_offset"  # the selection went on to the next candidate
