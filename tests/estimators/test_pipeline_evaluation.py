"""Cross-validation (section 5.8), MEDSE, McGill notches and mass NMSE after the convergence test (section 5.9)."""

import importlib.util
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from roadload.estimators.evaluation import (Estimate, EvaluationError, convergence_index, cross_validate,
                                            default_combinations, estimator_settings, evaluate_states,
                                            mass_nmse, notch_table, significantly_different)
from roadload.estimators.models import M3, M4

_spec = importlib.util.spec_from_file_location("handmade", Path(__file__).with_name("test_pipeline_stages.py"))
hm = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(hm)


def _estimate(n=3000, seed=1):
    rng = np.random.default_rng(seed)
    A = np.column_stack([np.ones(n), rng.normal(size=n)])
    x = np.array([10.0, 2.0])
    B = A @ x
    X = np.tile(x, (n, 1))
    return Estimate("M3", "RLS", np.arange(n) * 0.1, A, B, X, None, np.zeros(n), ["a", "b"])


def test_cross_validation_freezes_parameters_at_the_split():
    est = _estimate()
    n = est.B.size
    # parameters go wrong after the split of k = 300: the frozen X̂_{split-1} must still predict perfectly
    est.X[n - 300:] = [0.0, 0.0]
    cv = cross_validate(est, horizons=(300,), min_training=100)
    assert cv[300] == 0.0
    # a wrong parameter before the split: MEDSE equals the median squared offset
    est.X[:] = [11.0, 2.0]
    assert cross_validate(est, horizons=(300, 900), min_training=100) == {300: 1.0, 900: 1.0}
    # too little training data for the horizon -> NaN (trip too short to split)
    cv = cross_validate(est, horizons=(2500, 5000), min_training=600)
    assert np.isnan(cv[2500]) and np.isnan(cv[5000])


def test_notch_table_matches_mcgill_formula_and_significance():
    rng = np.random.default_rng(0)
    a = rng.normal(10, 1, 60)
    b = rng.normal(10.1, 1, 60)
    c = rng.normal(20, 1, 60)
    df = pd.DataFrame({"combination": ["a"] * 60 + ["b"] * 60 + ["c"] * 60 + ["c"],
                       "medse": np.concatenate([a, b, c, [np.nan]])})
    tab = notch_table(df).set_index("combination")
    q25, med, q75 = np.percentile(a, [25, 50, 75])
    assert tab.loc["a", "median"] == pytest.approx(med)
    assert tab.loc["a", "notch_low"] == pytest.approx(med - 1.57 * (q75 - q25) / np.sqrt(60))
    assert tab.loc["c", "m"] == 60                            # the NaN (trip too short) is not counted
    assert not significantly_different(tab.loc["a"], tab.loc["b"])
    assert significantly_different(tab.loc["a"], tab.loc["c"])
    with pytest.raises(EvaluationError, match="no column"):
        notch_table(df, value="nmse")


def test_convergence_index_and_mass_nmse():
    P = np.full((100, 3), 100.0)
    P[40:, :] = 0.5
    P[40:45, 1] = 2.0                                         # one entry still above P_max
    assert convergence_index(P, p_max=1.0) == 45
    assert convergence_index(np.full((10, 3), 5.0), p_max=1.0) == -1
    assert convergence_index(None) == -1
    m = np.full(50, 1800.0 * 1.05)                           # 5 % error -> NMSE = 1 - 0.05^2
    assert mass_nmse(m, 1800.0) == pytest.approx(1 - 0.05 ** 2)


def test_settings_follow_section_5_5_and_user_models():
    s = estimator_settings(M4, "SGMKF", M4.nominal_parameters(hm._knowledge().nominal))
    assert s["p0"] == 100.0 and s["n_params"] == 4
    np.testing.assert_allclose(s["desired_covariance"], [5e-5, 1e-6, 1e-8, 1e-6])
    assert estimator_settings(M3, "SGIVMKF", np.ones(3))["instrument_delay"] == 4
    assert estimator_settings(M3, "RRLM", np.ones(3))["kappa"] == 1e-5
    wide = M3.extend("M3_eval_extra", M4.terms[3])
    s = estimator_settings(wide, "SGMKF", np.ones(4))
    assert s["n_params"] == 4 and len(s["desired_covariance"]) == 4
    with pytest.raises(EvaluationError, match="no chapter-5 settings"):
        estimator_settings(M3, "KF", np.ones(3))
    assert len(default_combinations()) == 11


def test_evaluate_states_on_exact_data_ranks_m4_first_and_recovers_mass():
    res = hm.run_pipeline(hm.handmade_trip(duration=1500.0, events=False), hm._knowledge())
    ev = evaluate_states("h", res.states, hm._knowledge(), true_mass=hm.X_TRUE[1], min_training=600)
    df = pd.DataFrame(ev.medse)
    assert set(df["combination"]) == {c if e is None else f"{c}-{e}" for c, e in default_combinations()}
    k900 = df[df["horizon"] == 900].set_index("combination")["medse"]
    # the data are exactly M4: every M4 combination predicts (almost) perfectly, far better than M3 and M0
    assert k900.filter(like="M4-").max() < 1e-2 * k900.filter(like="M3-").min()
    assert k900["M0"] > k900.filter(like="M4-").max()
    mass = pd.DataFrame(ev.mass).set_index("combination")
    assert (mass.loc[mass["model"] == "M4", "nmse"] > 1 - 1e-5).all()
    assert (mass["converged_at"] >= 0).all()
    assert set(ev.timing) == {"estimation", "evaluation"}
