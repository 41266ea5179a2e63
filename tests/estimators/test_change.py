"""The CUSUM change detector and its covariance reset on a recursive estimator (roadload.estimators.change)."""

import math

import numpy as np
import pytest

from roadload.estimators import make_estimator
from roadload.estimators.change import (ChangeDetection, ChangeDetectionError, CusumDetector, gain_constant,
                                        reset_covariance)

G = 9.81
TRUE = np.array([12.8, 0.42])  # m_V f_r0 [kg] and rho_a/2 A_V c_x [kg/m] of a car
NOISE = 80.0  # [N] output noise of the tractive force


def regression(n=6000, step_at=3000, factor=1.3, seed=1):
    """B = g m_V f_r0 + v^2 c (a road-load regression), speeds 5-30 m/s; m_V f_r0 steps by ``factor`` at
    ``step_at`` (tyres warming or a payload added)."""
    rng = np.random.default_rng(seed)
    v = 17.5 + 12.5 * np.sin(np.arange(n) / 150.0) * np.cos(np.arange(n) / 37.0)
    A = np.column_stack([np.full(n, G), v ** 2])
    truth = np.tile(TRUE, (n, 1))
    truth[step_at:, 0] *= factor
    return A, np.sum(A * truth, axis=1) + rng.normal(0.0, NOISE, n), truth


def estimate(A, B, detection=None):
    """RRLM (lambda 0.999, section 5.5) on the rows, with the change detector the online force model runs."""
    est = make_estimator("RRLM", n_params=2, x0=TRUE.copy(), forgetting=0.999, kappa=1e-5, psi="huber",
                         robust_scale=True)
    det = None if detection is None else CusumDetector(detection)
    diagonal = None if detection is None else detection.reset_diagonal(["m_V f_r0", "rho_a/2 A_V c_x"])
    xs = np.empty_like(A)
    for k, (a, b) in enumerate(zip(A, B)):
        if det is not None and det.update(float(b - a @ est.x)):
            reset_covariance(est, diagonal, det.scale)
        est.update(a, b)
        xs[k] = est.x
    return xs, det


def test_a_reset_raises_the_covariance_by_the_variance_over_the_noise():
    """P is the covariance over sigma^2 / lambda: a 25 kg^2 step at sigma = 100 N adds 0.999 * 25 / 1e4 to P."""
    est = make_estimator("RRLM", n_params=2, x0=TRUE.copy(), forgetting=0.999)
    before = est.state.p.copy()
    reset_covariance(est, np.array([25.0, 0.0]), 100.0)
    np.testing.assert_allclose(est.state.p - before, np.diag([0.999 * 25.0 / 1e4, 0.0]))
    assert gain_constant(make_estimator("KF", n_params=2, process_noise=[1e-3, 1e-6], output_noise=0.8)) == 0.8
    with pytest.raises(ChangeDetectionError, match=r"noise_scale must be a finite scale > 0 \[unit of B\]"):
        reset_covariance(est, np.array([25.0, 0.0]), 0.0)


def test_the_detector_waits_for_its_scale_then_fires_on_a_persistent_shift():
    det = CusumDetector(ChangeDetection())
    assert det.settling == 100
    assert not any(det.update(500.0) for _ in range(100))  # the scale has not settled: no alarm at all
    rng = np.random.default_rng(0)
    det.reset()
    quiet = [det.update(r) for r in rng.normal(0.0, NOISE, 2000)]
    assert sum(quiet) <= 2  # white noise: next to no false alarms in 2000 residuals
    shifted = [det.update(r) for r in rng.normal(1.5 * NOISE, NOISE, 60)]
    assert any(shifted) and det.alarms >= 1


def test_cusum_follows_a_step_without_jumping_past_it():
    """m_V f_r0 steps by 30 % (3.8 kg): with the detector the estimate is within 1.2 kg of the new value 400
    samples later, where the long-memory RRLM alone has not got there; and it never strays further from the truth
    than the step itself (a reset fitting one noisy sample moved it by tens of kg)."""
    A, B, truth = regression()
    plain, _ = estimate(A, B)
    cusum, det = estimate(A, B, ChangeDetection())
    assert det is not None and det.alarms >= 1
    after = slice(3400, 3600)
    err_cusum = np.abs(cusum[after, 0] - truth[after, 0]).mean()
    err_plain = np.abs(plain[after, 0] - truth[after, 0]).mean()
    assert err_cusum < 1.2 and err_cusum < 0.6 * err_plain, (err_cusum, err_plain)
    step = truth[-1, 0] - truth[0, 0]
    assert np.abs(cusum[500:, 0] - truth[500:, 0]).max() < step
    assert np.abs(cusum[500:, 1] - truth[500:, 1]).max() < 0.3 * TRUE[1]
    assert math.isfinite(det.scale) and abs(det.scale - NOISE) < 0.3 * NOISE


def test_block_and_dwell_settings_are_checked_and_the_dwell_holds_the_test_quiet():
    for bad in ({"window": 0}, {"window": 2.5}, {"dwell": -1}, {"window": True}):
        with pytest.raises(ChangeDetectionError, match=r"an integer >= [01] \[residuals\]"):
            ChangeDetection(**bad)
    # a persistent shift of 2 sigma: without a dwell the test fires again and again, with it at most once per dwell
    rng = np.random.default_rng(3)
    noise, shifted = rng.normal(0.0, NOISE, 2000), rng.normal(2.0 * NOISE, NOISE, 1000)
    counts = {}
    for dwell in (0, 400):
        det = CusumDetector(ChangeDetection(window=10, scale_forgetting=0.9, threshold=8.0, dwell=dwell))
        quiet = sum(det.update(r) for r in noise)
        fired = [k for k, r in enumerate(shifted) if det.update(r)]
        assert quiet == 0 and fired and fired[0] < 200, (quiet, fired)  # blocks of 10: fires within 20 blocks
        assert det.blocks == 299 and det.samples == 3000  # the first block mean starts the scale
        counts[dwell] = fired
    assert all(b - a >= 400 for a, b in zip(counts[400], counts[400][1:]))
    assert len(counts[0]) > len(counts[400])
