"""RGTLS as a composition: its own stages against Algorithm 3.8 and eq. 3.43b, and the whole record loop against
the closed form it has when P̌ picks the output direction (then RGTLS is exponentially weighted least squares)."""

import numpy as np
import pytest

from roadload import estimators as E
from roadload.estimators import rgtls as R


def test_generalised_inverse_iteration_is_algorithm_3_8_lines_5_to_7():
    rng = np.random.default_rng(3)
    n = 3
    M = rng.normal(size=(n + 1, n + 1))
    P = M @ M.T + np.eye(n + 1)
    noise = np.diag([0.1, 0.2, 0.3, 0.5])
    X = np.array([1.0, -2.0, 0.5])
    V_expected = P @ (noise @ np.append(X, -1.0))
    ok = R.generalised_inverse_iteration(X, P, noise, np.empty(n + 1), np.empty(n + 1), n)
    assert ok
    np.testing.assert_allclose(X, -V_expected[:n] / V_expected[n], rtol=1e-13)
    # V'_q = 0 (no information on the output direction): X̂ is kept and the step reported as failed
    X0 = X.copy()
    assert not R.generalised_inverse_iteration(X, np.zeros((n + 1, n + 1)), noise, np.empty(n + 1),
                                               np.empty(n + 1), n)
    assert np.array_equal(X, X0)


def test_noise_covariance_update_is_eq_3_43b_and_skips_rows_without_estimate():
    cov = np.diag([1.0, 2.0, 3.0])
    row = np.array([0.5, -1.0, 2.0])
    R.noise_covariance_update(cov, row, 0.9, 3)
    np.testing.assert_allclose(cov, 0.9 * np.diag([1.0, 2.0, 3.0]) + 0.1 * np.outer(row, row), rtol=1e-15)
    before = cov.copy()
    R.noise_covariance_update(cov, np.array([0.1, np.nan, 0.3]), 0.9, 3)
    assert np.array_equal(cov, before)


@pytest.mark.parametrize("lam", [1.0, 0.995])
def test_rgtls_with_the_output_direction_is_weighted_least_squares(lam):
    """P̌ = e_q e_qᵀ: V' = -P_t e_q, so X̂_t = -P_t[:n, q] / P_t[q, q] with P_t⁻¹ = λ^t P_0⁻¹ + Σ λ^(t-i) Z_iᵀ Z_i,
    which is (Aᵀ W A + λ^t/p0 I)⁻¹ Aᵀ W B with W = diag(λ^(t-i)): the catalogue's covariance stages on Z_t must
    reproduce it at every sample."""
    rng = np.random.default_rng(5)
    T, n, p0 = 400, 3, 1e3
    A = rng.normal(size=(T, n))
    B = A @ np.array([1.0, -2.0, 0.5]) + rng.normal(0.0, 0.1, T)
    res = E.run("RGTLS", A, B, forgetting=lam, noise_covariance=[0.0, 0.0, 0.0, 1.0], p0=p0)
    for t in (n, 50, T - 1):
        w = lam ** np.arange(t, -1, -1.0)
        lhs = (A[:t + 1] * w[:, None]).T @ A[:t + 1] + lam ** (t + 1) / p0 * np.eye(n)
        expected = np.linalg.solve(lhs, (A[:t + 1] * w[:, None]).T @ B[:t + 1])
        np.testing.assert_allclose(res.X[t], expected, rtol=1e-8, atol=1e-10)
    assert res.n_skipped == 0 and res.n_rolled_back == 0
    assert np.array_equal(res.weights, np.ones(T))


def test_rgtls_skips_non_finite_samples_and_reports_nan_weights_there():
    rng = np.random.default_rng(6)
    A = rng.normal(size=(200, 2))
    B = A @ np.array([1.0, 2.0])
    A[50, 1] = np.nan
    B[120] = np.inf
    res = E.run("RGTLS", A, B)
    assert res.n_skipped == 2
    assert np.array_equal(np.flatnonzero(res.skipped), [50, 120])
    assert np.isnan(res.weights[[50, 120]]).all() and np.all(res.weights[~res.skipped] == 1.0)
    assert np.array_equal(res.X[50], res.X[49])
