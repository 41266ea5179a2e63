"""The covariance safety net of the recursive kernel: P stays finite, symmetric, positive
definite and bounded under any input, overflow-scale samples are skipped and counted, ignored settings are
rejected."""

from __future__ import annotations

import numpy as np
import pytest
from roadload.estimators import (
    CATALOG,
    EstimatorConfigError,
    make_config,
    make_estimator,
)

TRUTH = np.array([1.0, -2.0, 0.5, 3.0])
NOISE = 0.01  # output noise standard deviation [unit of B]


def _settings(name: str) -> dict:
    """Catalog defaults plus the noise level of the data (σ̂_0, Q̂_0, R¹) and Q / P_d where required."""
    cov = CATALOG[name].parts.get("covariance", "forgetting")
    s: dict = {"n_params": 4, "scale0": NOISE, "quantile0": NOISE ** 2}
    if cov == "kalman":
        s.update(process_noise=1e-9, output_noise=NOISE ** 2)
    elif cov == "stenlund_gustafsson":
        s.update(desired_covariance=1e-6, output_noise=NOISE ** 2)
    return s


def _excited(T: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """Three sines (correlated over a few samples, so delayed instruments work) and a constant."""
    t = np.arange(T, dtype=float)
    A = np.column_stack([np.sin(2 * np.pi * f * t + ph) for f, ph in ((0.011, 0.0), (0.017, 1.0), (0.023, 2.0))]
                        + [np.ones(T)])
    return A, A @ TRUTH + np.random.default_rng(seed).normal(0.0, NOISE, T)


def _check_p(est, name: str, where: str) -> None:
    P = est.p
    assert np.all(np.isfinite(P)), f"{name}: P not finite {where}"
    bound = est.config.covariance_bound_ratio * np.max(np.diag(est.config.kernel_arrays["P0"]))
    assert np.all(np.diag(P) > 0.0) and np.max(np.diag(P)) <= bound, f"{name}: diag P {np.diag(P)} {where}"
    if est.config.instruments == "none":
        assert np.array_equal(P, P.T), f"{name}: P not symmetric {where}"
        assert np.min(np.linalg.eigvalsh(P)) > 0.0, f"{name}: P not positive definite {where}"
    else:  # instruments: P = (Σ 𝔄ᵀ a)⁻¹ is not symmetric in exact arithmetic; its eigenvalues stay positive
        assert np.min(np.linalg.eigvals(P).real) > 0.0, f"{name}: P has eigenvalues <= 0 {where}"


def _constant_then_excited(name: str, n_constant: int, chunk: int = 1_000_000):
    est = make_estimator(name, **_settings(name))
    A_const = np.ones((min(chunk, n_constant), 4))
    B_const = A_const @ TRUTH + np.random.default_rng(0).normal(0.0, NOISE, A_const.shape[0])
    for k in range(n_constant // A_const.shape[0]):
        est.run(A_const, B_const, store="final")
        _check_p(est, name, f"after {(k + 1) * A_const.shape[0]} constant-regressor samples")
    A, B = _excited(100_000, 1)
    est.run(A, B, store="final")
    _check_p(est, name, "after 1e5 excited samples")
    np.testing.assert_allclose(est.x, TRUTH, rtol=0.01, err_msg=f"{name} did not recover from the wind-up")
    return est


@pytest.mark.parametrize("name", list(CATALOG))
def test_every_estimator_survives_1e6_constant_regressors(name):
    est = _constant_then_excited(name, 1_000_000)
    st = est.state
    if CATALOG[name].parts.get("covariance", "forgetting") == "forgetting" and "kappa" not in CATALOG[name].parts:
        # exponential forgetting without regularisation winds up: P reaches the bound and is reset, reported
        assert st.n_p_resets >= 10 and st.blowup_at >= 0
        assert 1e9 < st.p_diag_max <= 1e10 * (1 + 1e-9) * 1.01


@pytest.mark.slow
@pytest.mark.parametrize("name", list(CATALOG))
def test_every_estimator_survives_1e7_constant_regressors(name):
    _constant_then_excited(name, 10_000_000)


@pytest.mark.parametrize("name", ["RLS", "RIV", "SGMKF", "SGIVMKF"])
def test_overflow_scale_samples_are_skipped_and_counted(name):
    est = make_estimator(name, **_settings(name))
    huge = np.full((50, 4), 1e200)
    res = est.run(huge, np.full(50, 1e200), store="full")
    assert res.n_skipped == 50 and np.all(res.skipped)
    np.testing.assert_array_equal(est.x, np.zeros(4))
    A, B = _excited(20_000, 3)
    est.run(A, B, store="final")
    np.testing.assert_allclose(est.x, TRUTH, rtol=0.01)


def test_corrupt_update_is_rolled_back_and_p_reset():
    """A finite but absurd P (P_22 = 1.797e308) overflows in P/λ: the update is rolled back, P ← P_0, counted."""
    est = make_estimator("RLS", n_params=4, covariance_bound_ratio=1e306)
    st = est.state
    st.p = np.diag([1.0, 1.797e308, 1.0, 1.0])
    est.set_state(st)
    x_before = est.x
    res = est.run(np.array([[1.0, 0.0, 0.0, 0.0]]), np.array([3.0]), store="full")
    assert res.n_rolled_back == 1 and res.n_p_resets == 1 and res.p_blowup
    np.testing.assert_array_equal(est.x, x_before)
    np.testing.assert_array_equal(est.p, 100.0 * np.eye(4))


def test_p_above_the_bound_is_reset_and_reported():
    rng = np.random.default_rng(5)
    A = np.column_stack([rng.normal(size=3000), np.zeros(3000)])  # second regressor never excited
    B = A @ np.array([1.0, 2.0]) + rng.normal(0, 0.01, 3000)
    res = make_estimator("RLS", n_params=2, forgetting=0.99).run(A, B)
    # P_22 grows by 1/λ per sample: above the blow-up level 1e6 × 100 after ln(1e6)/ln(1/0.99) = 1375 samples,
    # above the bound 1e8 × 100 after 1833 samples, where it is reset to P_0 = 100
    assert res.n_p_resets == 1 and res.p_blowup and 1370 < res.p_blowup_at < 1380
    k = int(np.argmax(res.P_diag[:, 1]))
    assert 1825 < k < 1840 and 0.99e10 < res.p_diag_max <= 1.02e10
    assert res.P_diag[k + 1, 1] == pytest.approx(100.0, rel=0.05) and res.P_diag[:, 1].max() <= 1e10


@pytest.mark.parametrize("name, setting, value", [
    ("SGMKF", "forgetting", 0.99), ("KF", "forgetting", 0.99), ("RLS", "output_noise", 0.5),
    ("RLS", "process_noise", 1e-5), ("KF", "desired_covariance", 1e-6), ("RLS", "instrument_delay", 3),
])
def test_settings_a_composition_ignores_are_rejected(name, setting, value):
    extra = {"process_noise": 1e-5} if name == "KF" else {}
    with pytest.raises(EstimatorConfigError, match=f"{setting} = {value!r} is not used by estimator '{name}'"):
        make_config(name, n_params=4, **{setting: value}, **extra)
