"""The recursive kernel against direct transcriptions of the chapter-3 algorithms, closed forms and invariants."""

from __future__ import annotations

import numpy as np
import pytest

from roadload.estimators import (CATALOG, EstimatorConfig, EstimatorConfigError, EstimatorInputError,
                                 RecursiveEstimator, chapter5_settings, make_config, make_estimator, run,
                                 run_many, weight)


def reference_run(cfg: EstimatorConfig, A, B, Z=None):
    """Plain numpy transcription of Algorithms 3.1-3.4, 3.9-3.20 (one iteration per step), for comparison."""
    arr = cfg.kernel_arrays
    n = cfg.n_params
    X = arr["x0"].copy()
    P = arr["P0"].copy()
    sig2, q = cfg.scale0 ** 2, cfg.quantile0
    hist = []
    out = []
    for t in range(len(B)):
        a, b = A[t], B[t]
        if cfg.instruments == "user":
            z = Z[t]
        elif cfg.instruments == "delayed" and len(hist) >= cfg.instrument_delay:
            z = hist[-cfg.instrument_delay]
        else:
            z = a
        r = b - a @ X
        w = 1.0 if cfg.psi == "l2" else float(weight(r / np.sqrt(sig2), cfg.psi, cfg.psi_params))
        c = cfg.forgetting if cfg.covariance == "forgetting" else cfg.output_noise
        Lg = w * P @ z / (c + w * a @ P @ z)
        if cfg.covariance == "forgetting":
            Pn = (np.eye(n) - np.outer(Lg, a)) @ P / cfg.forgetting
        elif cfg.covariance == "kalman":
            Pn = (np.eye(n) - np.outer(Lg, a)) @ P + arr["Q"]
        else:
            Pd = arr["Pd"]
            Qt = w * np.outer(Pd @ z, a @ Pd) / (cfg.output_noise + w * a @ Pd @ z)
            Pn = (np.eye(n) - np.outer(Lg, a)) @ P + Qt
        if cfg.regularisation != "none":
            Pn = Pn @ np.linalg.inv(np.eye(n) + cfg.kappa * Pn)
        Xn = X + Lg * r
        if cfg.regularisation == "tikhonov":
            Xn = Xn - cfg.kappa * Pn @ X
        Xn = np.clip(Xn, arr["xmin"], arr["xmax"])
        X, P = Xn, Pn
        if cfg.robust_scale:
            rp = b - a @ X
            q = q + cfg.learn_rate * abs(np.sign(rp ** 2 - q)) * (np.sign(rp ** 2 - q) + 2 * cfg.quantile_p - 1)
            q = max(q, 0.0)
            sig2 = cfg.scale_forgetting * sig2 + (1 - cfg.scale_forgetting) * cfg.scale_factor * q
        hist.append(a)
        out.append(X.copy())
    return np.array(out), P, sig2


def sine_data(T=400, seed=0, n=4, outliers=0.0):
    rng = np.random.default_rng(seed)
    t = np.arange(1, T + 1)
    freqs = [0.006, 0.012, 0.014, 0.02, 0.03][:n]
    A = np.column_stack([np.sin(2 * np.pi * t * f) * np.sin(2 * np.pi * t * f / 3.3) for f in freqs])
    A[:, -1] += 0.5
    Xtrue = np.arange(1.0, n + 1)
    B = A @ Xtrue + rng.normal(0, 0.1, T)
    if outliers:
        idx = rng.random(T) < outliers
        B[idx] = rng.uniform(-4, 4, idx.sum())
    return A, B, Xtrue


PD = [1e-4, 1e-5, 1e-5, 1e-4]
SETTINGS = dict(scale0=0.3, quantile0=0.05, p0=10.0)
EXTRA = {"KF": dict(process_noise=1e-5), "MKF": dict(process_noise=1e-5), "RMKF": dict(process_noise=1e-5),
         "IVKF": dict(process_noise=1e-5), "IVMKF": dict(process_noise=1e-5), "RIVMKF": dict(process_noise=1e-5),
         "SGMKF": dict(desired_covariance=PD), "SGIVMKF": dict(desired_covariance=PD)}


@pytest.mark.parametrize("name", list(CATALOG))
def test_every_catalog_entry_matches_the_transcribed_algorithm(name):
    A, B, _ = sine_data(300, seed=1, outliers=0.03)
    extra = dict(SETTINGS, **EXTRA.get(name, {}))
    if "instrument_delay" in CATALOG[name].parts:
        extra["instrument_delay"] = 2
    if CATALOG[name].parts.get("covariance", "forgetting") == "forgetting":
        extra["forgetting"] = 0.98  # λ is rejected by the Kalman family (it would be ignored there)
    cfg = make_config(name, n_params=4, kappa=1e-3 if "kappa" in CATALOG[name].parts else 0.0, **extra)
    Xref, Pref, sig2 = reference_run(cfg, A, B)
    res = RecursiveEstimator(cfg).run(A, B)
    np.testing.assert_allclose(res.X, Xref, rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(res.state.p, Pref, rtol=1e-8, atol=1e-12)
    assert res.state.scale == pytest.approx(np.sqrt(sig2), rel=1e-10)


def test_tikhonov_and_constraints_and_user_instruments_match_reference():
    A, B, _ = sine_data(300, seed=2)
    Z = np.vstack([A[:3], A[:-3]])
    cfg = EstimatorConfig(n_params=4, psi="myriad", robust_scale=True, scale0=0.3, quantile0=0.05,
                          covariance="stenlund_gustafsson", desired_covariance=PD, output_noise=0.05,
                          regularisation="tikhonov", kappa=1e-2, instruments="user", x_min=[0, 0, 0, 0],
                          x_max=[1.5, 10, 10, 3.5], p0=10.0)
    Xref, _, _ = reference_run(cfg, A, B, Z)
    res = RecursiveEstimator(cfg).run(A, B, instruments=Z)
    np.testing.assert_allclose(res.X, Xref, rtol=1e-9, atol=1e-9)
    assert res.X[:, 0].max() <= 1.5 and res.X[:, 3].max() <= 3.5 and res.X.min() >= 0.0


def test_rls_without_forgetting_is_the_regularised_least_squares_solution():
    A, B, _ = sine_data(500, seed=3)
    p0, x0 = 50.0, np.array([0.5, -1, 0, 2])
    est = make_estimator("RLS", n_params=4, forgetting=1.0, p0=p0, x0=x0)
    res = est.run(A, B)
    info = np.eye(4) / p0 + A.T @ A
    X_batch = np.linalg.solve(info, x0 / p0 + A.T @ B)
    np.testing.assert_allclose(res.X[-1], X_batch, rtol=1e-9)
    np.testing.assert_allclose(est.p, np.linalg.inv(info), rtol=1e-7, atol=1e-12)


def test_regularised_covariance_is_the_information_recursion():
    """P_t^-1 = λ P_{t-1}^-1 + a aᵀ + κ I for RRLM with L2 weights (eq. 3.33a with κ condensed, 3.34)."""
    A, B, _ = sine_data(200, seed=4)
    lam, kappa = 0.99, 0.05
    est = make_estimator("RRLM", n_params=4, forgetting=lam, kappa=kappa, psi="l2", robust_scale=False, p0=10.0)
    info = np.eye(4) / 10.0
    for t in range(200):
        est.update(A[t], B[t])
        info = lam * info + np.outer(A[t], A[t]) + kappa * np.eye(4)
    np.testing.assert_allclose(np.linalg.inv(est.p), info, rtol=1e-8)


def test_online_batch_and_many_trips_are_identical():
    A, B, _ = sine_data(600, seed=5, outliers=0.05)
    for name, extra in (("RRLM", dict(kappa=1e-4, forgetting=0.99)), ("SGIVMKF", dict(desired_covariance=PD,
                                                                                      instrument_delay=3))):
        kw = dict(n_params=4, scale0=0.3, quantile0=0.05, **extra)
        online = make_estimator(name, **kw)
        X_online = np.array([online.update(A[t], B[t]) for t in range(len(B))])
        batch = make_estimator(name, **kw).run(A, B)
        assert np.max(np.abs(X_online - batch.X)) <= 1e-12
        # split record continues exactly
        split = make_estimator(name, **kw)
        r1, r2 = split.run(A[:250], B[:250]), split.run(A[250:], B[250:])
        assert np.max(np.abs(np.vstack([r1.X, r2.X]) - batch.X)) <= 1e-12
        B2 = np.vstack([B, B[::-1], B + 0.1])
        A2 = np.stack([A, A[::-1], A])
        many = run_many(make_config(name, **kw), A2, B2)
        for k in range(3):
            single = make_estimator(name, **kw).run(A2[k], B2[k])
            assert np.max(np.abs(many.X[k] - single.X)) <= 1e-12
            assert np.max(np.abs(many.scale[k] - single.scale)) <= 1e-12


def test_nan_and_inf_samples_are_skipped_counted_and_not_propagated():
    A, B, _ = sine_data(400, seed=6)
    Ab, Bb = A.copy(), B.copy()
    Ab[10, 2] = np.nan
    Bb[50] = np.inf
    Bb[300] = np.nan
    est = make_estimator("RRLM", n_params=4, scale0=0.3, quantile0=0.05, forgetting=0.99)
    res = est.run(Ab, Bb)
    assert res.n_skipped == 3 and res.state.n_skipped == 3
    assert res.skipped.sum() == 3 and res.skipped[[10, 50, 300]].all()
    assert np.all(np.isfinite(res.X)) and np.all(np.isfinite(res.P_diag))
    np.testing.assert_array_equal(res.X[10], res.X[9])
    # removing the bad rows gives the same estimate
    keep = np.ones(400, bool)
    keep[[10, 50, 300]] = False
    clean = make_estimator("RRLM", n_params=4, scale0=0.3, quantile0=0.05, forgetting=0.99).run(A[keep], B[keep])
    np.testing.assert_allclose(res.X[-1], clean.X[-1], rtol=1e-12)
    x_before = est.x
    assert np.array_equal(est.update([np.nan, 0, 0, 0], 1.0), x_before)
    assert est.state.n_skipped == 4


def test_covariance_stays_exactly_symmetric_and_blowup_is_reported():
    rng = np.random.default_rng(7)
    T = 6000
    A = np.column_stack([np.sin(np.arange(T) * 0.05), rng.normal(size=T), np.ones(T)])
    A[1000:, 1] = 0.0  # second regressor unexcited from t = 1000
    B = A @ np.array([1.0, 2.0, 0.5]) + rng.normal(0, 0.1, T)
    res = run("RLS", A, B, forgetting=0.995)
    P = res.state.p
    assert np.array_equal(P, P.T)
    assert res.p_blowup and 1000 < res.p_blowup_at < T
    assert res.p_diag_max > 1e6 * 100
    reg = run("RRLM", A, B, forgetting=0.995, kappa=0.1, psi="l2", robust_scale=False)
    assert not reg.p_blowup and reg.p_diag_max <= 100.0 + 1e-9
    assert np.array_equal(reg.state.p, reg.state.p.T)


def test_kalman_joseph_form_equals_standard_form_and_stays_symmetric():
    A, B, _ = sine_data(400, seed=8)
    std = run("MKF", A, B, process_noise=1e-5, output_noise=0.05, scale0=0.3, quantile0=0.05)
    jos = run("MKF", A, B, process_noise=1e-5, output_noise=0.05, scale0=0.3, quantile0=0.05, joseph=True)
    np.testing.assert_allclose(jos.X, std.X, rtol=1e-8, atol=1e-10)
    P = jos.state.p
    assert np.array_equal(P, P.T) and np.all(np.linalg.eigvalsh(P) > 0)


def test_robust_estimators_survive_outliers_where_rls_breaks():
    A, B, Xtrue = sine_data(4000, seed=9, outliers=0.05)
    rls = run("RLS", A, B, forgetting=0.995)
    rrlm = run("RRLM", A, B, forgetting=0.995, kappa=1e-3, scale0=1.0, quantile0=0.5)
    sevn_rls = np.sum((rls.X[2000:] - Xtrue) ** 2, axis=1).mean()
    sevn_rrlm = np.sum((rrlm.X[2000:] - Xtrue) ** 2, axis=1).mean()
    assert sevn_rrlm < 0.05 and sevn_rls > 10 * sevn_rrlm
    # the robust scale converges near the text's consistency: σ̂² -> 1.483 · median(ΔB²) of the clean noise
    assert 0.04 < np.median(rrlm.scale[2000:]) < 0.2
    assert np.mean(rrlm.weights[2000:] < 0.5) > 0.03  # outliers are down-weighted


def test_iterated_time_step_converges_to_fixed_point():
    A, B, _ = sine_data(300, seed=10, outliers=0.05)
    one = run("RLM", A, B, forgetting=0.99, scale0=0.3, quantile0=0.05)
    it = run("RLM", A, B, forgetting=0.99, scale0=0.3, quantile0=0.05, scale_iterations=50, iteration_tol=1e-13)
    assert not np.allclose(one.X, it.X)
    # at the fixed point the weight of step t is the weight of the a posteriori correction
    w_post = weight(it.residual_post / np.concatenate([[0.3], it.scale[:-1]]), "huber")
    np.testing.assert_allclose(it.weights[1:], w_post[1:], atol=1e-6)


def test_state_is_copyable_and_restorable():
    A, B, _ = sine_data(300, seed=11)
    est = make_estimator("SGIVMKF", n_params=4, desired_covariance=PD, scale0=0.3, quantile0=0.05)
    est.run(A[:100], B[:100])
    snap = est.state
    twin = est.copy()
    x1 = est.run(A[100:], B[100:]).X
    x2 = twin.run(A[100:], B[100:]).X
    np.testing.assert_array_equal(x1, x2)
    est.set_state(snap)
    np.testing.assert_array_equal(est.run(A[100:], B[100:]).X, x1)


@pytest.mark.parametrize("kwargs, match", [
    (dict(forgetting=1.5), "forgetting must lie in"),
    (dict(forgettin=0.9), "unknown setting"),
    (dict(psi="gauss"), "unknown influence function"),
    (dict(kappa=-1.0), "kappa must lie in"),
    (dict(regularisation="ridge"), "regularisation 'ridge' unknown"),
    (dict(covariance="kalman"), "needs process_noise"),
    (dict(psi="huber", psi_params=(-1,)), "tuning constant"),
    (dict(instrument_delay=0, instruments="delayed"), "instrument_delay must be an integer"),
    (dict(x_min=[1, 1, 1, 1], x_max=[0, 0, 0, 0]), "x_min <= x_max"),
    (dict(p0=[1, 2]), "expected 4 diagonal entries"),
    (dict(joseph=True), "Kalman family"),
])
def test_bad_settings_raise_clear_errors(kwargs, match):
    with pytest.raises(EstimatorConfigError, match=match):
        make_estimator("RLS", n_params=4, **kwargs)


def test_bad_names_and_data_raise_clear_errors():
    with pytest.raises(EstimatorConfigError, match="unknown estimator 'RLX'"):
        make_estimator("RLX", n_params=2)
    with pytest.raises(EstimatorConfigError, match="needs desired_covariance"):
        make_estimator("SGMKF", n_params=2)
    est = make_estimator("RLS", n_params=3)
    with pytest.raises(EstimatorInputError, match=r"shape \(T, 3\)"):
        est.run(np.zeros((10, 2)), np.zeros(10))
    with pytest.raises(EstimatorInputError, match="a_t must have 3 entries"):
        est.update([1.0, 2.0], 1.0)
    with pytest.raises(EstimatorInputError, match="instruments given"):
        est.run(np.zeros((10, 3)), np.zeros(10), instruments=np.zeros((10, 3)))


def test_chapter5_settings_build():
    for model, n in (("M3", 3), ("M4", 4)):
        s = chapter5_settings(model)
        assert set(s) == {"RLS", "RRLM", "SGMKF", "RGTLS", "SGIVMKF"}
        for name in ("RLS", "RRLM", "SGMKF", "SGIVMKF"):
            est = make_estimator(name, **s[name])
            assert est.n_params == n and np.allclose(est.p, 100 * np.eye(n))
        assert make_config("SGIVMKF", **s["SGIVMKF"]).instrument_delay == 4
        assert make_config("RRLM", **s["RRLM"]).kappa == 1e-5


def test_single_parameter_rls_is_the_running_mean():
    rng = np.random.default_rng(12)
    B = 2.0 + rng.normal(size=500)
    res = run("RLS", np.ones((500, 1)), B, forgetting=1.0, p0=1e4)
    t = np.arange(1, 501)
    np.testing.assert_allclose(res.X[:, 0], np.cumsum(B) / (1e-4 + t), rtol=1e-10)
    np.testing.assert_allclose(res.P_diag[:, 0], 1.0 / (1e-4 + t), rtol=1e-10)
