"""Batch reference estimators of chapter 3: LS (3.20), WLS (3.23), iteratively reweighted M-estimation
(3.12-3.14), TLS with covariance (Algorithm 3.5), GTLS (Algorithm 3.6) and the high-breakdown LMS (3.10) and
LTS (3.11) by subset sampling.

A is (m×n), B is (m,); X̂ is returned in units of B per unit of A. Non-finite rows are rejected with a
:class:`BatchInputError` (batch references do not skip silently).
"""

from __future__ import annotations

from dataclasses import dataclass
from itertools import combinations
from math import comb

import numpy as np

from .influence import MAD_CONSISTENCY, PSI_KINDS, _resolve, _weight_vec


class BatchInputError(ValueError):
    """Bad input to a batch estimator (shapes, non-finite values, settings); the message names it."""


def _check(A, B) -> tuple[np.ndarray, np.ndarray]:
    A = np.asarray(A, dtype=float)
    B = np.asarray(B, dtype=float)
    if A.ndim == 1:
        A = A[:, None]
    if A.ndim != 2 or B.ndim != 1 or A.shape[0] != B.shape[0]:
        raise BatchInputError(f"need A (m x n) and B (m,), got {A.shape} and {B.shape}")
    if A.shape[0] < A.shape[1]:
        raise BatchInputError(f"underdetermined: {A.shape[0]} samples for {A.shape[1]} parameters")
    bad = ~(np.all(np.isfinite(A), axis=1) & np.isfinite(B))
    if bad.any():
        raise BatchInputError(f"non-finite values in rows {np.flatnonzero(bad)[:10].tolist()}")
    return A, B


@dataclass
class BatchResult:
    """X̂, its covariance (where the method gives one), residuals B - A X̂, weights (M-estimation), scale σ̂."""

    X: np.ndarray
    cov: np.ndarray | None = None
    residual: np.ndarray | None = None
    weights: np.ndarray | None = None
    scale: float | None = None
    iterations: int = 0


def least_squares(A, B) -> BatchResult:
    """LS (3.20) with P = σ̂² (AᵀA)⁻¹, σ̂² = ΔBᵀΔB / (m - n)."""
    return weighted_least_squares(A, B, None)


def weighted_least_squares(A, B, W=None) -> BatchResult:
    """WLS (3.23): X̂ = (Aᵀ W A)⁻¹ Aᵀ W B with diagonal weights W (m,) (None: LS)."""
    A, B = _check(A, B)
    m, n = A.shape
    w = np.ones(m) if W is None else np.asarray(W, dtype=float)
    if w.shape != (m,) or np.any(~np.isfinite(w)) or np.any(w < 0):
        raise BatchInputError(f"W must be {m} finite non-negative weights")
    sw = np.sqrt(w)
    X, *_ = np.linalg.lstsq(A * sw[:, None], B * sw, rcond=None)
    r = B - A @ X
    dof = max(m - n, 1)
    s2 = float(np.sum(w * r ** 2) / dof)
    try:
        cov = s2 * np.linalg.inv((A * w[:, None]).T @ A)
    except np.linalg.LinAlgError:
        cov = None
    return BatchResult(X, cov, r, w, float(np.sqrt(s2)))


def mad_scale(residual) -> float:
    """σ̂_MAD = 1.483 med |ΔB - med ΔB| (eq. 3.14, :data:`~.influence.MAD_CONSISTENCY`)."""
    r = np.asarray(residual, dtype=float)
    return MAD_CONSISTENCY * float(np.median(np.abs(r - np.median(r))))


def m_estimate(A, B, psi: str = "huber", psi_params=None, max_iter: int = 100, tol: float = 1e-10,
               x_start=None) -> BatchResult:
    """M-estimation (3.12-3.13) by iteratively reweighted LS, W_ii = ψ(ΔB_i/σ̂)/(ΔB_i/σ̂), σ̂ = MAD (3.14)
    re-estimated every iteration; starts from LS (or ``x_start``); stops when X̂ changes < tol (relative)."""
    A, B = _check(A, B)
    if psi.lower().replace("-", "").replace("_", "") not in PSI_KINDS:
        raise BatchInputError(f"unknown influence function {psi!r}; choose one of {sorted(PSI_KINDS)}")
    code, c1, c2, c3 = _resolve(psi, psi_params)
    X = least_squares(A, B).X if x_start is None else np.asarray(x_start, dtype=float)
    w = np.ones(B.shape[0])
    s = 0.0
    it = 0
    for it in range(1, max_iter + 1):
        r = B - A @ X
        s = mad_scale(r)
        if s <= 0.0:  # more than half the points fit exactly
            s = max(float(np.std(r)), 1e-300)
        w = _weight_vec(code, r / s, c1, c2, c3)
        if np.sum(w > 0) < A.shape[1]:
            raise BatchInputError("M-estimation rejected too many samples (weights zero); try a softer psi")
        X_new = weighted_least_squares(A, B, w).X
        done = np.max(np.abs(X_new - X)) <= tol * (1.0 + np.max(np.abs(X_new)))
        X = X_new
        if done:
            break
    r = B - A @ X
    res = weighted_least_squares(A, B, w)
    return BatchResult(X, res.cov, r, w, s, it)


def total_least_squares(A, B) -> BatchResult:
    """TLS (Algorithm 3.5): X̂ = -V₁₂ V₂₂⁻¹ from svd([A B]); cov(X̂) ≈ (1 + ||X̂||²) σ̂² (AᵀA - m σ̂² I)⁻¹ with
    σ̂² = S_qq² / m (the text prints S_qq/m; the squared singular value is what makes the units and eq. 3.44
    agree, and is Van Huffel & Vandewalle's estimate)."""
    A, B = _check(A, B)
    m, n = A.shape
    Z = np.column_stack([A, B])
    _, S, Vt = np.linalg.svd(Z, full_matrices=False)
    V = Vt.T
    v22 = V[n, n]
    if abs(v22) < 1e-14 * np.max(np.abs(V[:, n])):
        raise BatchInputError("TLS solution is non-generic (V22 = 0)")
    X = -V[:n, n] / v22
    s2 = S[n] ** 2 / m
    try:
        cov = (1.0 + X @ X) * s2 * np.linalg.inv(A.T @ A - m * s2 * np.eye(n))
    except np.linalg.LinAlgError:
        cov = None
    return BatchResult(X, cov, B - A @ X, None, float(np.sqrt(s2)))


def generalized_total_least_squares(A, B, noise_cov, row_weights=None) -> BatchResult:
    """GTLS by data scaling (Algorithm 3.6): C = chol(P̃) (upper, P̃ = CᵀC), W_r = C⁻¹, TLS on √W_l [A B] W_r,
    X̂ = (W_r11 X̂' - W_r12) / W_r22 and cov(X̂) = W_r11 cov(X̂') W_r11ᵀ / W_r22² (the text writes
    W_r11ᵀ cov W_r11; for X̂ = W_r11 X̂'/W_r22 the propagated covariance has W_r11 on the left).

    noise_cov P̃: (n+1)×(n+1) positive definite covariance of [Ã B̃]; row_weights W_l (m,), e.g. λ^(m-i)."""
    A, B = _check(A, B)
    m, n = A.shape
    Pn = np.asarray(noise_cov, dtype=float)
    if Pn.ndim == 1:
        Pn = np.diag(Pn)
    if Pn.shape != (n + 1, n + 1):
        raise BatchInputError(f"noise_cov must be ({n + 1} x {n + 1}) or {n + 1} diagonal entries")
    try:
        C = np.linalg.cholesky(Pn).T  # upper: P̃ = Cᵀ C
    except np.linalg.LinAlgError:
        raise BatchInputError("noise_cov must be positive definite: data scaling cannot treat a noise-free "
                              "column (zero variance); use RLS/IV for partly noise-free inputs") from None
    Wr = np.linalg.inv(C)
    wl = np.ones(m) if row_weights is None else np.asarray(row_weights, dtype=float)
    if wl.shape != (m,) or np.any(wl < 0) or not np.all(np.isfinite(wl)):
        raise BatchInputError(f"row_weights must be {m} finite non-negative numbers")
    Zs = np.sqrt(wl)[:, None] * np.column_stack([A, B]) @ Wr
    inner = total_least_squares(Zs[:, :n], Zs[:, n])
    Wr11, Wr12, Wr22 = Wr[:n, :n], Wr[:n, n], Wr[n, n]
    X = (Wr11 @ inner.X - Wr12) / Wr22
    cov = None if inner.cov is None else Wr11 @ inner.cov @ Wr11.T / Wr22 ** 2
    return BatchResult(X, cov, B - A @ X, None, inner.scale)


def _subsets(m: int, n: int, max_subsets: int, rng: np.random.Generator):
    if comb(m, n) <= max_subsets:
        yield from combinations(range(m), n)
    else:
        for _ in range(max_subsets):
            yield tuple(rng.choice(m, n, replace=False))


def least_median_of_squares(A, B, max_subsets: int = 3000, seed: int | np.random.Generator = 0) -> BatchResult:
    """LMS (3.10): min_X med (B - A X)², searched over exact fits of n-point subsets (all of them when
    C(m, n) <= max_subsets, else a random sample drawn with ``seed``)."""
    A, B = _check(A, B)
    m, n = A.shape
    rng = np.random.default_rng(seed)
    best, best_x = np.inf, None
    for idx in _subsets(m, n, max_subsets, rng):
        idx = list(idx)
        try:
            x = np.linalg.solve(A[idx], B[idx])
        except np.linalg.LinAlgError:
            continue
        crit = np.median((B - A @ x) ** 2)
        if crit < best:
            best, best_x = crit, x
    if best_x is None:
        raise BatchInputError("LMS: every subset was singular")
    # Rousseeuw & Leroy's finite-sample scale for LMS
    scale = 1.4826 * (1 + 5.0 / max(m - n, 1)) * np.sqrt(best)
    return BatchResult(best_x, None, B - A @ best_x, None, float(scale))


def least_trimmed_squares(A, B, h: int | None = None, max_subsets: int = 500, c_steps: int = 20,
                          seed: int | np.random.Generator = 0) -> BatchResult:
    """LTS (3.11): min_X Σ_{i≤h} sorted (ΔB_i)², h = ⌊(m + n + 1)/2⌋ by default; random n-subsets each refined
    by concentration steps (LS on the h smallest squared residuals until the set stops changing)."""
    A, B = _check(A, B)
    m, n = A.shape
    h = (m + n + 1) // 2 if h is None else int(h)
    if not (n <= h <= m):
        raise BatchInputError(f"LTS h must lie in {n}..{m}, got {h}")
    rng = np.random.default_rng(seed)
    best, best_x = np.inf, None
    for idx in _subsets(m, n, max_subsets, rng):
        try:
            x = np.linalg.solve(A[list(idx)], B[list(idx)])
        except np.linalg.LinAlgError:
            continue
        prev = None
        for _ in range(c_steps):
            keep = np.sort(np.argsort((B - A @ x) ** 2)[:h])
            if prev is not None and np.array_equal(keep, prev):
                break
            prev = keep
            x, *_ = np.linalg.lstsq(A[keep], B[keep], rcond=None)
        crit = np.sum(np.sort((B - A @ x) ** 2)[:h])
        if crit < best:
            best, best_x = crit, x
    if best_x is None:
        raise BatchInputError("LTS: every subset was singular")
    return BatchResult(best_x, None, B - A @ best_x, None, float(np.sqrt(best / h)))
