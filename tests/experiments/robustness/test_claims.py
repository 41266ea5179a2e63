"""The text's qualitative claims pinned on the synthetic (A/B-level) sweeps of the robustness testbed.

Few seeds and short records keep this fast; the >= 20-seed sweeps run in scripts/robustness_sweeps.py.
"""

import numpy as np
import pandas as pd
import pytest

from roadload.estimators import run
from roadload.experiments.robustness import (
    Scenario, breakdown_table, build_synthetic, default_estimators, run_scenario, scenarios,
    synthetic_regression, synthetic_settings,
)

SEEDS = 3


def _sweep(sweep, variant, levels, estimators, duration=3000.0):
    rows = []
    for sc in scenarios("synthetic", sweep, SEEDS, duration, variants=[variant], levels=levels):
        rows += run_scenario(sc, estimators)
    return pd.DataFrame(rows)


@pytest.mark.parametrize("variant", ["output/isolated", "both/isolated"])
def test_rls_breaks_down_at_lower_outlier_fraction_than_rlm_and_rrlm(variant):
    res = _sweep("outliers", variant, (0.0, 0.01, 0.02, 0.05, 0.1, 0.2, 0.3), ["RLS", "RLM", "RRLM"])
    bd = breakdown_table(res, bound=0.1).set_index("estimator")["breakdown"]
    assert bd["RLS"] <= 0.1                   # RLS: breakdown point near 0 % (section 3.4)
    assert bd["RLM"] > bd["RLS"] and bd["RRLM"] > bd["RLS"]
    # and per seed, not only in the median
    for seed, g in res.groupby("seed"):
        b = breakdown_table(g, bound=0.1).set_index("estimator")["breakdown"]
        assert b["RLM"] > b["RLS"] and b["RRLM"] > b["RLS"], f"seed {seed}: {b.to_dict()}"


def test_covariance_winds_up_without_regularisation_and_lm_or_sg_bound_it():
    res = _sweep("excitation", "column2", (0.0, 500.0, 1500.0), ["RLS", "RLM", "RRLM", "SGMKF"])
    growth = res.groupby(["estimator", "level"])["trace_P_growth"].median().unstack()
    # without regularisation trace(P) grows with the length of the unexcited stretch (λ^-t in the unexcited
    # direction: e^{0.005·1500} ≈ 1.8e3 for λ = 0.995)
    for name in ("RLS", "RLM"):
        assert growth.loc[name, 500.0] > 2.0
        assert growth.loc[name, 1500.0] > 50 * growth.loc[name, 500.0]
    # Levenberg-Marquardt regularisation and Stenlund-Gustafsson keep it bounded, whatever the length
    for name in ("RRLM", "SGMKF"):
        assert growth.loc[name].max() < 3.0
    cond = res[res["level"] == 1500.0].groupby("estimator")["cond_P_max"].median()
    assert cond["RLM"] > 100 * cond["RRLM"] and cond["RLM"] > 100 * cond["SGMKF"]


@pytest.mark.parametrize("iv, oe", [("RIV", "RLS"), ("RRIVM", "RRLM"), ("IVKF", "KF"), ("RIVMKF", "RMKF")])
def test_instrumental_variables_reduce_parameter_bias_under_input_noise(iv, oe):
    res = _sweep("input_noise", "columns2-3", (0.0, 0.02), [iv, oe])
    err = res.groupby(["estimator", "level"])["rel_error"].median().unstack()
    assert err.loc[oe, 0.02] > 2.0 * err.loc[iv, 0.02]     # the OE estimator is biased, IV much less
    assert err.loc[iv, 0.02] < 0.06
    # without input noise the two are about equally accurate (the IV gain is not free accuracy)
    assert err.loc[iv, 0.0] < 2.0 * err.loc[oe, 0.0] + 0.01


def _faulty(seed=0):
    d = synthetic_regression(2000, seed=seed)
    assert len(default_estimators()) == 15       # every catalog parameter estimator (all but the PKS)
    A, B = d.A.copy(), d.B.copy()
    A[100:150] = np.nan            # dropout of all inputs
    B[300] = np.inf                # inf in the output
    A[400, 1] = -np.inf            # inf in one input
    B[500] = 1e200                 # absurd output value
    A[600, 2] = 1e200              # absurd input value (bad leverage point)
    B[700:720] = 1e15              # burst of gross output outliers
    A[800:1200] = 0.0              # no excitation at all
    return d, A, B


@pytest.mark.parametrize("name", default_estimators())
def test_no_estimator_returns_nan_or_inf_for_injected_faults_and_faults_are_reported(name):
    _, A, B = _faulty()
    s = synthetic_settings(name)
    s.pop("n_params")
    res = run(name, A, B, **s)
    assert np.all(np.isfinite(res.X)), f"{name} returned non-finite estimates"
    assert np.all(np.isfinite(res.P_diag))
    # every non-finite sample is skipped and counted, and so is the 1e200 input in the recursive kernel's
    # compositions: a P aᵀ overflows there (RGTLS has its own kernel)
    bad = ~np.all(np.isfinite(A), axis=1) | ~np.isfinite(B)
    bad[600] = name != "RGTLS"
    assert res.n_skipped == int(bad.sum()) == 52 + (name != "RGTLS")
    assert np.array_equal(res.skipped, bad)


@pytest.mark.parametrize("name", ["RLM", "RRLM", "MKF"])
def test_m_estimators_resist_gross_output_outliers_but_not_bad_leverage_points(name):
    """Section 3.4.2 / figure 3.6: M-estimators handle outliers in B, but a bad leverage point in A breaks them."""
    d = synthetic_regression(2000, seed=0)
    s = synthetic_settings(name)
    s.pop("n_params")
    after = slice(601, 700)
    A, B = d.A.copy(), d.B.copy()
    B[600] = 1e3                                   # gross output outlier
    out = run(name, A, B, **s)
    A, B = d.A.copy(), d.B.copy()
    A[600, 2] = 1e3                                # the same magnitude as a bad leverage point
    lev = run(name, A, B, **s)
    clean = run(name, d.A, d.B, **s)
    err = {k: np.median(np.abs(r.X[after] - d.X_true[after]).max(axis=1) / 3.0) for k, r in
           [("out", out), ("lev", lev), ("clean", clean)]}
    assert err["out"] < 2 * err["clean"] + 0.01
    assert err["lev"] > 10 * err["out"]
    rls = run("RLS", d.A, np.where(np.arange(2000) == 600, 1e3, d.B), forgetting=0.995)
    assert np.median(np.abs(rls.X[after] - d.X_true[after]).max(axis=1) / 3.0) > 10 * err["out"]


def test_sweep_rows_carry_fault_reports():
    sc = Scenario("synthetic", "outliers", "output/isolated", 0.05, 0, 2000.0)
    rows = run_scenario(sc, ["RLS", "RLM"])
    assert [r["estimator"] for r in rows] == ["RLS", "RLM"]
    for r in rows:
        assert r["finite"] and r["n_skipped"] == 0 and r["model"] == "synthetic" and r["level"] == 0.05
    data = build_synthetic(sc)
    assert data.outlier_mask.sum() == 100
