"""Robust statistics for the diagnosis: blocks of correlated samples, block bootstrap, McGill notches, the
cluster-robust (block) covariance of a linear fit, and robust summaries of a residual.

Samples of a trip at 10 Hz are strongly autocorrelated, so every significance statement here resamples or
counts *blocks* (contiguous stretches of one trip, default 10 s) instead of samples.
"""

from __future__ import annotations

import numpy as np

from roadload.estimators.evaluation import NOTCH_FACTOR

from .errors import DiagnosisError


def block_ids(trip_index: np.ndarray, t: np.ndarray, block_length: float) -> np.ndarray:
    """Integer id of the contiguous block (``block_length`` [s] of one trip) every sample belongs to."""
    trip_index = np.asarray(trip_index)
    t = np.asarray(t, dtype=float)
    if trip_index.shape != t.shape:
        raise DiagnosisError(f"trip index and time differ in shape: {trip_index.shape} vs {t.shape}")
    if not block_length > 0:
        raise DiagnosisError(f"block length must be > 0 s, got {block_length}")
    _, trip_code = np.unique(trip_index, return_inverse=True)
    start = np.zeros_like(t)
    for k in np.unique(trip_code):
        sel = trip_code == k
        start[sel] = np.min(t[sel])
    within = np.floor((t - start) / block_length).astype(np.int64)
    key = trip_code.astype(np.int64) * (int(within.max(initial=0)) + 1) + within
    _, ids = np.unique(key, return_inverse=True)
    return ids.astype(np.int64)


def notch_interval(values: np.ndarray, n_effective: int | None = None) -> tuple[float, float, float]:
    """(median, low, high) of McGill's notch median ± 1.57 IQR/√m; m = ``n_effective`` (e.g. the number of
    independent blocks) when given, else the number of finite values."""
    x = np.asarray(values, dtype=float)
    x = x[np.isfinite(x)]
    if x.size == 0:
        return float("nan"), float("nan"), float("nan")
    q25, med, q75 = np.percentile(x, [25, 50, 75])
    m = max(int(n_effective if n_effective is not None else x.size), 1)
    half = NOTCH_FACTOR * (q75 - q25) / np.sqrt(m)
    return float(med), float(med - half), float(med + half)


def block_bootstrap_median(values: np.ndarray, blocks: np.ndarray, rng: np.random.Generator,
                           n_boot: int = 200, level: float = 0.95) -> tuple[float, float, float, float]:
    """Median of ``values`` with a block-bootstrap confidence interval and two-sided p-value of median = 0.

    Resamples whole blocks with replacement; returns (median, low, high, p). With one block only, the interval
    is infinite and p = 1 (no evidence)."""
    x = np.asarray(values, dtype=float)
    b = np.asarray(blocks)
    ok = np.isfinite(x)
    x, b = x[ok], b[ok]
    if x.size == 0:
        return float("nan"), float("nan"), float("nan"), 1.0
    med = float(np.median(x))
    ub, inv = np.unique(b, return_inverse=True)
    nb = ub.size
    if nb < 2:
        return med, -np.inf, np.inf, 1.0
    order = np.argsort(x, kind="stable")
    xs, bs = x[order], inv[order]
    meds = np.empty(n_boot)
    chunk = max(1, int(4_000_000 // max(x.size, 1)))
    for s0 in range(0, n_boot, chunk):
        k = min(chunk, n_boot - s0)
        mult = np.stack([np.bincount(rng.integers(0, nb, nb), minlength=nb) for _ in range(k)])  # (k, nb)
        cw = np.cumsum(mult[:, bs], axis=1)                                                       # (k, n)
        half = cw[:, -1:] / 2.0
        pos = np.argmax(cw >= half, axis=1)   # weighted median: first sorted sample reaching half the weight
        meds[s0:s0 + k] = xs[pos]
    alpha = (1.0 - level) / 2.0
    lo, hi = np.quantile(meds, [alpha, 1.0 - alpha])
    p = 2.0 * min(float(np.mean(meds <= 0.0)), float(np.mean(meds >= 0.0)))
    return med, float(lo), float(hi), float(min(1.0, max(p, 1.0 / n_boot)))


def block_bootstrap_mean_difference(loss_a: np.ndarray, loss_b: np.ndarray, blocks: np.ndarray,
                                    rng: np.random.Generator, n_boot: int = 400,
                                    level: float = 0.95) -> tuple[float, float, float]:
    """Mean of loss_a - loss_b (paired per sample) with a block-bootstrap interval: (mean, low, high).

    Used to test whether a held-out loss reduction (a = before, b = after) is significant: low > 0."""
    d = np.asarray(loss_a, dtype=float) - np.asarray(loss_b, dtype=float)
    bl = np.asarray(blocks)
    ok = np.isfinite(d)
    d, bl = d[ok], bl[ok]
    if d.size == 0:
        return float("nan"), float("nan"), float("nan")
    ub, inv = np.unique(bl, return_inverse=True)
    sums = np.bincount(inv, weights=d, minlength=ub.size)
    counts = np.bincount(inv, minlength=ub.size).astype(float)
    mean = float(sums.sum() / counts.sum())
    if ub.size < 2:
        return mean, -np.inf, np.inf
    pick = rng.integers(0, ub.size, size=(n_boot, ub.size))
    boot = sums[pick].sum(axis=1) / counts[pick].sum(axis=1)
    alpha = (1.0 - level) / 2.0
    lo, hi = np.quantile(boot, [alpha, 1.0 - alpha])
    return mean, float(lo), float(hi)


def cluster_covariance(A: np.ndarray, residual: np.ndarray, blocks: np.ndarray,
                       weights: np.ndarray | None = None) -> np.ndarray:
    """Cluster-robust (block sandwich) covariance of a (weighted) least-squares X̂:
    (AᵀWA)⁻¹ [Σ_blocks (AᵀW r)_b (AᵀW r)_bᵀ] (AᵀWA)⁻¹ — honest about autocorrelated residuals."""
    A = np.asarray(A, dtype=float)
    r = np.asarray(residual, dtype=float)
    w = np.ones_like(r) if weights is None else np.asarray(weights, dtype=float)
    _, inv = np.unique(np.asarray(blocks), return_inverse=True)
    bread = np.linalg.pinv((A * w[:, None]).T @ A)
    scores = A * (w * r)[:, None]
    per_block = np.zeros((inv.max() + 1, A.shape[1]))
    np.add.at(per_block, inv, scores)
    meat = per_block.T @ per_block
    nb = per_block.shape[0]
    n, k = A.shape
    corr = (nb / max(nb - 1, 1)) * ((n - 1) / max(n - k, 1))   # small-sample correction (CR1)
    return corr * bread @ meat @ bread
