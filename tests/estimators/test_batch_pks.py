"""Batch references, PKS, RGTLS, influence functions and metrics of chapter 3."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.signal import savgol_filter

import roadload.estimators as E
from roadload.estimators.influence import psi, rho, weight
from roadload.estimators.synthetic import linear_miso, straight_line


@pytest.mark.parametrize("name", ["l2", "huber", "myriad", "cauchy", "tukey", "hampel", "l1l2"])
def test_psi_is_the_derivative_of_rho_and_weight_is_psi_over_u(name):
    u = np.linspace(-9.7, 9.7, 2001)
    h = 1e-6
    np.testing.assert_allclose(psi(u, name), (rho(u + h, name) - rho(u - h, name)) / (2 * h), atol=1e-5)
    np.testing.assert_allclose(weight(u, name) * u, psi(u, name), atol=1e-12)
    assert rho(0.0, name) == 0.0 and weight(0.0, name) == 1.0


def test_huber_and_myriad_match_the_text():
    assert psi(5.0, "huber") == pytest.approx(1.345)  # (3.15b) saturates at δ
    assert psi(0.5, "huber") == pytest.approx(0.5)
    assert psi(3.0, "myriad", (2.0,)) == pytest.approx(4 * 3 / (4 + 9))  # (3.17b)
    with pytest.raises(E.InfluenceError, match="unknown influence function"):
        weight(1.0, "welsch")


def test_straight_line_breakdown_behaviour():
    """Experiments 3.1/3.2: LS breaks on an output outlier, M-estimators survive it; a far bad leverage point
    breaks LS and the M-estimators, LMS survives (20 noise seeds, medians)."""
    def med_err(case, fn, **kw):
        return np.median([abs(fn(*straight_line(case, s, **kw)[:2]).X[0] - 3.0) for s in range(20)])
    huber = lambda A, B: E.m_estimate(A, B, "huber")
    myriad = lambda A, B: E.m_estimate(A, B, "myriad")
    assert med_err("outlier", E.least_squares) > 3 * med_err("outlier", huber)
    assert med_err("outlier", E.least_squares) > 3 * med_err("outlier", myriad)
    for fn in (E.least_squares, huber, myriad):
        assert med_err("bad_leverage", fn, bad_leverage_at=50.0) > 2.0
    assert med_err("bad_leverage", E.least_median_of_squares, bad_leverage_at=50.0) < 0.3
    assert med_err("bad_leverage", E.least_trimmed_squares, bad_leverage_at=50.0) < 0.3
    assert med_err("good_leverage", E.least_squares) < 0.1


def test_tls_and_gtls_recover_parameters_with_input_noise():
    rng = np.random.default_rng(0)
    m = 20000
    At = rng.normal(size=(m, 2)) * [1.0, 2.0]
    X = np.array([1.5, -0.7])
    Bt = At @ X
    noise_cov = np.diag([0.3, 0.1, 0.2])
    A = At + rng.normal(size=(m, 2)) * np.sqrt([0.3, 0.1])
    B = Bt + rng.normal(size=m) * np.sqrt(0.2)
    ls = E.least_squares(A, B).X
    g = E.generalized_total_least_squares(A, B, noise_cov)
    assert np.max(np.abs(g.X - X)) < 0.03 < np.max(np.abs(ls - X))  # LS is attenuated by input noise
    # equal noise: TLS itself, covariance formula of Alg. 3.5 against the spread over repetitions
    est = []
    for s in range(40):
        r = np.random.default_rng(s + 1)
        A2 = At[:2000] + r.normal(size=(2000, 2)) * 0.3
        B2 = Bt[:2000] + r.normal(size=2000) * 0.3
        res = E.total_least_squares(A2, B2)
        est.append(res.X)
    spread = np.var(np.array(est), axis=0)
    assert np.all(np.abs(np.diag(res.cov) / spread - 1) < 0.6)
    with pytest.raises(E.BatchInputError, match="positive definite"):
        E.generalized_total_least_squares(A, B, np.diag([0.0, 0.1, 0.2]))


def test_pks_reproduces_polynomials_exactly_with_known_delay():
    T = 1500
    t = np.arange(T, dtype=float)
    sig = 2e-9 * (t - 700) ** 4 + 0.01 * t
    out = E.pks_bank({"s": sig, "c": np.full(T, 3.0)}, dt=0.01, derivatives=2, window=20, order=4)
    assert out.delay == 20 and out.delay_s == pytest.approx(0.2)
    np.testing.assert_allclose(out.value["s"][300:], sig[300 - 20:T - 20], rtol=1e-9, atol=1e-6)
    d1 = (8e-9 * (t - 700) ** 3 + 0.01) / 0.01
    np.testing.assert_allclose(out.derivative["s"][300:], d1[280:T - 20], rtol=1e-7, atol=1e-6)
    np.testing.assert_allclose(out.value["c"][300:], 3.0, rtol=1e-10)
    # one PKS online gives the bank's numbers
    one = E.PolynomialKalmanSmoother(n_params=5, window_left=20, window_right=20)
    online = np.array([one.update(b) for b in sig[:400]])
    np.testing.assert_allclose(online, out.value["s"][:400], rtol=0, atol=1e-9 * np.max(np.abs(sig)))


def test_pks_beats_moving_average_on_section_356_output():
    """Experiment 3.7 in small: PKS (λ = 0.9, w = 20, 5 parameters) has lower MSE than the 41-tap mean."""
    d = linear_miso(seed=3, m=4000, outlier_fraction=0.0)
    out = E.pks_bank({"B": d.B}, window=20, order=4, forgetting=0.9)
    pks = out.aligned("B")
    fir = np.convolve(d.B, np.ones(41) / 41, mode="same")
    sl = slice(200, 3900)
    assert E.mse(d.B_true[sl], pks[sl]) < 0.5 * E.mse(d.B_true[sl], fir[sl])
    sgf = savgol_filter(d.B, 41, 4)
    assert E.mse(d.B_true[sl], sgf[sl]) < E.mse(d.B_true[sl], fir[sl])


def test_pks_nan_samples_keep_alignment():
    t = np.arange(600, dtype=float)
    sig = 0.001 * t ** 2
    noisy = sig.copy()
    noisy[[100, 101, 250]] = np.nan
    out = E.pks_bank(noisy[:, None], order=2, window=10)
    np.testing.assert_allclose(out.value["0"][400:], sig[390:590], rtol=1e-9)


def test_rgtls_with_and_without_nce_removes_input_noise_bias():
    d = linear_miso(seed=4, m=10000, input_noise_var=(0.0, 0.005, 0.01), output_noise_var=0.02,
                    outlier_fraction=0.0)
    late = slice(8000, None)
    rls = E.run("RLS", d.A, d.B, forgetting=0.999)
    fixed = E.run("RGTLS", d.A, d.B, forgetting=0.999, noise_covariance=[1e-4, 0.005, 0.01, 0.02])
    nce = E.run("RGTLS", d.A, d.B, forgetting=0.999, nce=True, noise_covariance=[1e-4, 0.005, 0.01, 0.02])
    s_rls = E.sevn(d.X_true[late], rls.X[late]).mean()
    assert E.sevn(d.X_true[late], fixed.X[late]).mean() < 0.2 * s_rls
    assert E.sevn(d.X_true[late], nce.X[late]).mean() < 0.2 * s_rls
    est = E.make_estimator("RGTLS", n_params=3, forgetting=0.999, nce=True)
    online = np.array([est.update(d.A[t], d.B[t]) for t in range(300)])
    batch = E.run("RGTLS", d.A[:300], d.B[:300], forgetting=0.999, nce=True)
    assert np.max(np.abs(online - batch.X)) <= 1e-12


def test_metrics():
    b = np.array([1.0, 2.0, 3.0, np.nan])
    e = np.array([1.0, 2.0, 5.0, 0.0])
    assert E.mse(b, e) == pytest.approx(4 / 3)
    assert E.medse(b, e) == 0.0
    assert E.nmse(b, e) == pytest.approx(1 - 4 / 14)
    assert E.nrmse(b[:3], b[:3]) == 1.0
    assert np.array_equal(E.sevn([1.0, 2.0], np.array([[1.0, 2.0], [2.0, 0.0]])), [0.0, 5.0])
    r = np.sin(np.arange(100))
    rc = E.residual_correlation(r, max_lag=3)
    assert rc[0] == pytest.approx(np.mean(r ** 2))
    with pytest.raises(E.MetricError, match="same shape"):
        E.mse([1.0, 2.0], [1.0])


def test_pks_equals_exponentially_weighted_polynomial_fit_evaluated_at_the_window_centre():
    rng = np.random.default_rng(5)
    B = np.cumsum(rng.normal(size=1500)) * 0.1
    out = E.pks_bank({"B": B}, window=20, order=4, forgetting=0.9)
    k = np.arange(600)
    w = 0.9 ** k
    V = np.vander(41.0 - k, 5, increasing=True)
    for t in (900, 1200, 1499):
        c, *_ = np.linalg.lstsq(V * np.sqrt(w)[:, None], B[t - k] * np.sqrt(w), rcond=None)
        assert out.value["B"][t] == pytest.approx(np.polyval(c[::-1], 21.0), rel=1e-8, abs=1e-9)
