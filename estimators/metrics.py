"""Performance indices of section 3.2.1 (eq. 3.2-3.4) and the median squared error used in chapter 5.

All take arrays in the units of the signal; NaN entries are ignored (e.g. skipped samples) unless stated.
"""

from __future__ import annotations

import numpy as np


class MetricError(ValueError):
    """Inputs of a performance index do not fit (shapes, no finite samples)."""


def _pair(measured, estimated) -> tuple[np.ndarray, np.ndarray]:
    b = np.asarray(measured, dtype=float)
    e = np.asarray(estimated, dtype=float)
    if b.shape != e.shape:
        raise MetricError(f"measured and estimated must have the same shape, got {b.shape} and {e.shape}")
    ok = np.isfinite(b) & np.isfinite(e)
    if b.ndim > 1:
        ok = np.all(ok.reshape(b.shape[0], -1), axis=1)
        if not ok.any():
            raise MetricError("no sample where both inputs are finite")
        return b[ok], e[ok]
    if not ok.any():
        raise MetricError("no sample where both inputs are finite")
    return b[ok], e[ok]


def sevn(true_params, estimated_params) -> np.ndarray:
    """Squared error vector norm SEVN_t = ||X̄_t - X̂_t||² (eq. 3.2) per time step; inputs (T×n) or (n,)."""
    x = np.asarray(true_params, dtype=float)
    xh = np.asarray(estimated_params, dtype=float)
    x = np.broadcast_to(x, xh.shape) if x.ndim < xh.ndim else x
    if x.shape != xh.shape:
        raise MetricError(f"true and estimated parameters differ in shape: {x.shape} vs {xh.shape}")
    return np.sum((x - xh) ** 2, axis=-1)


def mse(measured, estimated) -> float:
    """Mean squared error (eq. 3.3a): ||B - B̂||² / m."""
    b, e = _pair(measured, estimated)
    return float(np.mean((b - e) ** 2))


def medse(measured, estimated) -> float:
    """Median squared error: med (B - B̂)² — robust against outliers (used in section 5.7)."""
    b, e = _pair(measured, estimated)
    return float(np.median((b - e) ** 2))


def nmse(measured, estimated) -> float:
    """Normalised MSE goodness of fit (eq. 3.3b): 1 - ||B - B̂||² / ||B||² (1 = perfect, -inf = bad)."""
    b, e = _pair(measured, estimated)
    den = float(np.sum(b ** 2))
    if den == 0.0:
        raise MetricError("NMSE undefined: the measured signal is identically zero")
    return 1.0 - float(np.sum((b - e) ** 2)) / den


def nrmse(measured, estimated) -> float:
    """Normalised RMSE goodness of fit (eq. 3.3c): 1 - ||B - B̂|| / ||B - mean(B)||."""
    b, e = _pair(measured, estimated)
    den = float(np.linalg.norm(b - np.mean(b)))
    if den == 0.0:
        raise MetricError("NRMSE undefined: the measured signal is constant")
    return 1.0 - float(np.linalg.norm(b - e)) / den


def residual_correlation(residual, other=None, max_lag: int = 20) -> np.ndarray:
    """R_τ = (1/m) Σ_t ΔB_t · Y_{t-τ} for τ = 0 … max_lag (eq. 3.4a with Y = A column(s), 3.4b with Y = ΔB).

    residual (m,), other None (auto-correlation) or (m,) / (m×n); returns (max_lag+1,) or (max_lag+1, n)."""
    r = np.asarray(residual, dtype=float)
    y = r if other is None else np.asarray(other, dtype=float)
    if y.shape[0] != r.shape[0]:
        raise MetricError("residual and other must have the same number of samples")
    m = r.shape[0]
    if not (0 <= max_lag < m):
        raise MetricError(f"max_lag must lie in 0..{m - 1}")
    lags = []
    for tau in range(max_lag + 1):
        prod = r[tau:, None] * (y[:m - tau] if y.ndim > 1 else y[:m - tau, None])
        lags.append(np.nansum(prod, axis=0) / m)
    out = np.array(lags)
    return out[:, 0] if y.ndim == 1 else out
