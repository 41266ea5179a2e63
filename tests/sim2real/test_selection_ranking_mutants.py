"""The selector's ranking and forward selection figure by figure against the same quantities written out: the shape
profile and out-of-fold losses with the selector's own robust fit and reference, the pick of a forward step (the
largest gain of the pool, whatever the pool's order), the explained share, the information criteria of the ranking,
and the final fit's braking mask (synthetic force tables of ``test_core``, no simulator)."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import numpy as np
import pytest

from roadload.sim2real.catalog import get_candidate
from roadload.sim2real.selection import Selector, cv_predict, design, fit_linear, make_split


# the synthetic force tables of test_core (one definition of the test world)
_SPEC = importlib.util.spec_from_file_location("sim2real_core_tables", Path(__file__).with_name("test_core.py"))
assert _SPEC is not None and _SPEC.loader is not None
CORE = importlib.util.module_from_spec(_SPEC)
_SPEC.loader.exec_module(CORE)
D_TRUE = 2500.0  # [m] the tire warm-up's decay distance


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
    ranked, _ = sel.rank(("mass_offset", "drag_area", "rolling_scale", "torque_scale"))
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
    steps = sel.forward(sel.rank(("mass_offset", "drag_area", "rolling_scale", "torque_scale"))[0])
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
    again = at_rank.rank(("mass_offset", "drag_area", "rolling_scale", "torque_scale"))[0]
    assert again[0].name == top.name and again[0].null_p == top.null_p and again[0].significant
    at_step = selector(alpha=first.null_p)
    step = at_step.forward(ranked)[0]
    assert step.null_p == first.null_p and step.accepted and step.reason == "accepted"
