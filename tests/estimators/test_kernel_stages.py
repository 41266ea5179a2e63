"""The named inline stages of the estimator's compiled record loop (roadload.estimators.kernel) against the
equations of chapter 3, called directly (an ``inline="always"`` numba function is also an ordinary compiled
function)."""

from __future__ import annotations

import numpy as np
import pytest
from roadload.estimators import kernel as K


def _spd(n, seed, cond=1e3):
    rng = np.random.default_rng(seed)
    q, _ = np.linalg.qr(rng.normal(size=(n, n)))
    return q @ np.diag(np.geomspace(1.0, cond, n)) @ q.T


@pytest.mark.parametrize("sym", [True, False])
def test_regularise_is_eq_3_34(sym):
    P = _spd(4, 1)
    kappa = 0.3
    out = P.copy()
    assert K.regularise(out, kappa, np.empty(4), np.empty(4), 4, sym)
    np.testing.assert_allclose(out, P @ np.linalg.inv(np.eye(4) + kappa * P), rtol=1e-10, atol=1e-12)


def test_gain_and_forgetting_covariance_are_algorithm_3_1():
    P = _spd(4, 2)
    a = np.array([0.3, -1.0, 0.5, 1.0])
    lam, w = 0.99, 0.7
    Pz = P @ a
    s = a @ Pz
    L = np.empty(4)
    K.gain(Pz, w, s, lam, L, 4)
    np.testing.assert_allclose(L, w * P @ a / (lam + w * a @ P @ a), rtol=1e-13)
    out = np.empty((4, 4))
    K.covariance_forgetting(out, P, L, Pz, Pz, 1.0 / lam, 4, True)
    np.testing.assert_allclose(out, (P - np.outer(L, a) @ P) / lam, rtol=1e-12, atol=1e-14)


def test_covariance_health_classifies_indefinite_bounded_and_healthy_p():
    work = np.empty((3, 3))
    x = np.zeros(3)
    healthy = _spd(3, 3)
    assert K.covariance_health(x, healthy, work, 1e6, 3, True, True)[0] == K.P_HEALTHY
    # positive diagonal, but indefinite (eigenvalues 3, -1, 1): only the LDLᵀ factorisation sees it
    indefinite = np.array([[1.0, 2.0, 0.0], [2.0, 1.0, 0.0], [0.0, 0.0, 1.0]])
    assert K.covariance_health(x, indefinite, work, 1e6, 3, True, True)[0] == K.P_CORRUPT
    assert K.covariance_health(x, indefinite, work, 1e6, 3, True, False)[0] == K.P_HEALTHY
    negative = np.diag([1.0, -4.5e307, 1.0])  # a P that once overflowed to -4.5e307: |diag| is what is reported
    status, pmax = K.covariance_health(x, negative, work, 1e6, 3, True, False)
    assert status == K.P_CORRUPT and pmax == 4.5e307
    assert K.covariance_health(x, 1e7 * healthy, work, 1e6, 3, True, True)[0] == K.P_ABOVE_BOUND
    nan_x = np.array([0.0, np.nan, 0.0])
    assert K.covariance_health(nan_x, healthy, work, 1e6, 3, True, False)[0] == K.P_CORRUPT
