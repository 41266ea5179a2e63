"""The one numeric kernel of the recursive linear estimators of chapter 3 (Algorithms 3.1-3.4, 3.9-3.21).

A time step is the composition of interchangeable parts, selected by small integer codes (``codes``, the
``IP_*`` indices) and float settings (``settings``, the ``FP_*`` indices); see
:mod:`roadload.estimators.config` for the mapping from names to codes. Each step is one inline stage below:

1. :func:`read_sample` / :func:`predict`: skip a non-finite sample (a_t, b_t or the instrument), count it,
   leave the state as it was (apart from the prediction step X' = F X, P' = F P Fᵀ when a transition matrix
   is set, e.g. in the PKS);
2. :func:`prior_products`: a priori output correction ΔB_t = b_t - a_t X̂_{t-1} and s = a_t P 𝔄ᵀ; a sample
   whose products overflow (|a|, |b| ~ 1e200: s or ΔB not finite) is skipped and counted like a non-finite one;
3. :func:`weight`: W = ψ(ΔB/σ̂_{t-1})/(ΔB/σ̂_{t-1}) (``influence.weight_scalar``);
4. :func:`gain`: L = W P 𝔄ᵀ / (c + W a P 𝔄ᵀ) with c = λ (forgetting family) or R (Kalman family), 𝔄 = a_t,
   a delayed regressor or a user instrument;
5. :func:`covariance_forgetting` P = (P - L a P)/λ (eq. 3.4), :func:`covariance_kalman` P - L a P + Q, or
   P - L a P + Q_t(P_d) (Stenlund-Gustafsson); optional Joseph form in the Kalman family;
6. :func:`regularise`: P ← P (I + κP)⁻¹ (eq. 3.34) and the Levenberg-Marquardt or Tikhonov parameter update;
7. :func:`saturate`: parameter saturation X_min ≤ X̂ ≤ X_max (section 3.10.1);
8. :func:`covariance_health` — the safety net of every composition: P must stay finite, with a positive
   diagonal (every sample), positive definite (LDLᵀ pivots > 0, every ``PD_CHECK_INTERVAL`` = 16 samples; not
   for instruments, where P is not symmetric) and bounded,
   max diag P ≤ ``p_bound`` (``FP_P_BOUND`` = ``covariance_bound_ratio`` × max diag P_0). An update that
   leaves P non-finite or indefinite is rolled back (X̂ as before the sample) and P is reset to P_0; a P above
   the bound is reset to P_0 (covariance resetting, the remedy against wind-up the text lists in section
   3.8.6). Every such event is counted (``CT_P_RESETS``) and flags the blow-up;
9. :func:`scale`: robust recursive scale, recursive quantile of the a posteriori ΔB² (eq. 3.29) and σ̂²
   forgetting (Algorithm 3.3 lines 10-12).

Steps 3-7 can be iterated within a time step until X̂_t converges (the "optimal" variant of Algorithm 3.3).

:func:`run_record` processes a whole record and is what the online ``update()`` calls with a one-sample
record, so online and batch results are the same numbers by construction. ``recursive.run_many`` runs
independent records (trips) in parallel threads with the very same function (it releases the GIL).
The stages are ``inline="always"`` numba functions: after inlining, ``run_record`` is the same single loop
as one hand-written body (no array-passing calls per sample).

:func:`run_record` takes five packed records (plain tuples, in the field order named below; numba types a
plain tuple of arrays in its fast dispatch path, a named tuple costs ~13 µs more per call, which the online
``update()`` would pay on every sample):

- ``record`` (:data:`RECORD_FIELDS`): regressors A (T×n), outputs B (T,), instruments 𝔄 (T×n, or 0×n);
- ``parts`` (:data:`PARTS_FIELDS`): the composition, ``EstimatorConfig.kernel_parts``;
- ``state`` (:data:`STATE_FIELDS`): X̂, P, the scalar state, the instrument ring and the counters, updated in place;
- ``out`` (:data:`OUTPUT_FIELDS`): per-sample outputs (:func:`outputs`);
- ``work`` (:func:`scratch`): work buffers.

Inside the kernel the composition's settings travel as an :class:`Options` and the named work buffers as a
:class:`Buffers` (named tuples built in compiled code, never crossing the Python boundary).
"""

from __future__ import annotations

from collections import namedtuple

import numpy as np
from numba import njit
from roadload.jitcache import cached_njit

from .influence import PSI_L2, weight_scalar

# ---- integer settings (``codes``) ----
IP_PSI, IP_COV, IP_REG, IP_IV, IP_DELAY, IP_ROBUST_SCALE, IP_MAX_ITER, IP_JOSEPH, IP_SYMMETRIC, \
    IP_CONSTRAIN, IP_TRANSITION, IP_STORE = range(12)
N_IP = 12
# ---- float settings (``settings``) ----
FP_C1, FP_C2, FP_C3, FP_LAMBDA, FP_R, FP_KAPPA, FP_ETA, FP_P, FP_LAMBDA_SCALE, FP_SCALE_FACTOR, FP_TOL, \
    FP_MIN_SCALE, FP_BLOWUP_LEVEL, FP_P_BOUND = range(14)
N_FP = 14

COV_FORGETTING, COV_KALMAN, COV_SG = 0, 1, 2
REG_NONE, REG_LM, REG_TIKHONOV = 0, 1, 2
IV_NONE, IV_DELAY, IV_USER = 0, 1, 2
STORE_FINAL, STORE_X, STORE_FULL = 0, 1, 2

#: health of P after an update (:func:`covariance_health`)
P_HEALTHY, P_ABOVE_BOUND, P_CORRUPT = 0, 1, 2


#: the packed records of :func:`run_record`, field by field
RECORD_FIELDS = ("regressors", "outputs", "instruments")
PARTS_FIELDS = ("codes", "settings", "process_noise", "desired_cov", "transition", "xmin", "xmax", "P0")
STATE_FIELDS = ("X", "P", "scalars", "instrument_ring", "counters")
OUTPUT_FIELDS = ("X", "P_diag", "residual_prior", "residual_post", "weights", "scale")


def scratch(n: int) -> tuple[np.ndarray, np.ndarray]:
    """The ``work`` record of :func:`run_record` for n parameters: (vectors, matrices) work buffers."""
    return np.empty((N_SCRATCH_VECTORS, n)), np.empty((N_SCRATCH_MATRICES, n, n))


def outputs(T: int, n: int, store: int, trips: tuple[int, ...] = ()) -> tuple[np.ndarray, ...]:
    """The ``out`` record of :func:`run_record` (:data:`OUTPUT_FIELDS`) for T samples: X̂_t when ``store`` is
    STORE_X or STORE_FULL, the others with STORE_FULL only (arrays of length 0 where not stored). With
    ``trips`` = (K,) every array has a leading trip axis (the record of trip r is ``tuple(o[r] for o in out)``)."""
    rows = T if store == STORE_FULL else 0
    return (np.empty(trips + (T if store >= STORE_X else 0, n)), np.empty(trips + (rows, n)),
            *(np.empty(trips + (rows,)) for _ in range(4)))


def size_tag(n: int) -> tuple:
    """The ``size_tag`` argument of :func:`run_record` for n parameters."""
    return (0.0,) * int(n)


# ---- scalar state (``scalars``) and counters (``counters``) ----
SC_SIGMA2, SC_QHAT, SC_PMAX = 0, 1, 2
N_SC = 3
CT_SKIPPED, CT_ROLLED_BACK, CT_BLOWUP_AT, CT_T, CT_RING_POS, CT_RING_FILL, CT_P_RESETS = range(7)
N_CT = 7
#: samples between two positive-definiteness checks (LDLᵀ factorisation) of a symmetric P; finiteness, the
#: diagonal and the bound are checked every sample
PD_CHECK_INTERVAL = 16  # a power of two
#: scratch buffers run_record works in (allocated by the caller: the kernel runs without reference counting)
N_SCRATCH_VECTORS, N_SCRATCH_MATRICES = 11, 2

_inline = njit(inline="always")


# ============================================================================ stage 1: sample and prediction
@_inline
def read_regressors(record, t, a, n):
    """Copy a_t of ``record`` (:data:`RECORD_FIELDS`) into ``a``; returns (b_t, probe): probe is 0 when a_t and b_t
    are finite, NaN otherwise (one test for all entries: x * 0 is 0 for finite x and NaN for inf/NaN)."""
    regressors, outputs, _ = record
    b = outputs[t]
    probe = b * 0.0
    for i in range(n):
        a[i] = regressors[t, i]
        probe += a[i] * 0.0
    return b, probe


@_inline
def read_sample(record, t, a, z, instrument_ring, counters, iv, delay, n):
    """Copy a_t (and the instrument 𝔄_t) of ``record`` (:data:`RECORD_FIELDS`) into ``a`` (``z``); returns (b_t,
    all entries finite)."""
    b, probe = read_regressors(record, t, a, n)
    instruments = record[2]
    if iv == IV_USER:
        for i in range(n):
            z[i] = instruments[t, i]
            probe += z[i] * 0.0
    elif iv == IV_DELAY and counters[CT_RING_FILL] >= delay:
        pos = counters[CT_RING_POS]
        for i in range(n):
            z[i] = instrument_ring[pos, i]
    elif iv != IV_NONE:
        for i in range(n):
            z[i] = a[i]
    return b, probe == 0.0


@_inline
def symmetrise(P, n):
    """P ← (P + Pᵀ)/2 (exact symmetry where it holds in exact arithmetic)."""
    for i in range(n):
        for j in range(i + 1, n):
            m = 0.5 * (P[i, j] + P[j, i])
            P[i, j] = m
            P[j, i] = m


@_inline
def matrix_vector(M, v, out, n):
    """out = M v (n×n times n)."""
    for i in range(n):
        acc = 0.0
        for j in range(n):
            acc += M[i, j] * v[j]
        out[i] = acc


@_inline
def predict(transition, X, P, x_tmp, work, n, sym):
    """Prediction X' = F X, P' = F P Fᵀ (random-walk / PKS shift model); also for skipped samples."""
    matrix_vector(transition, X, x_tmp, n)
    for i in range(n):
        for j in range(n):
            acc = 0.0
            for k in range(n):
                acc += transition[i, k] * P[k, j]
            work[i, j] = acc
    for i in range(n):
        X[i] = x_tmp[i]
        for j in range(n):
            acc = 0.0
            for k in range(n):
                acc += work[i, k] * transition[j, k]
            P[i, j] = acc
    if sym:
        symmetrise(P, n)


# ============================================================================ stage 2: a-priori products
@_inline
def backup_state(X, P, X_prev, P_prev, n, sym, with_P):
    """X_prev ← X̂_{t-1} (roll-back, parameter update); P_prev ← P_{t-1} (upper triangle when P is symmetric) only
    ``with_P`` -- the iterated variant recomputes P from it; a single update evolves P in place."""
    for i in range(n):
        X_prev[i] = X[i]
    if with_P:
        for i in range(n):
            for j in range(i if sym else 0, n):
                P_prev[i, j] = P[i, j]


@_inline
def output_correction(a, X, b, n):
    """ΔB = b - a X̂ [unit of B] (a priori with X̂_{t-1}, a posteriori with X̂_t)."""
    r = b
    for i in range(n):
        r -= a[i] * X[i]
    return r


@_inline
def prior_products(P, X, a, z, b, P_z, a_P, n, sym, cov):
    """ΔB_t = b_t - a_t X̂_{t-1} [unit of B], P𝔄ᵀ → P_z, a P → a_P (when needed); returns (ΔB_t, s = a P 𝔄ᵀ)."""
    return output_correction(a, X, b, n), covariance_products(P, a, z, P_z, a_P, n, sym, cov != COV_FORGETTING)


@_inline
def covariance_products(P, a, z, P_z, a_P, n, sym, copy_row):
    """P𝔄ᵀ → P_z and a P → a_P; returns s = a P 𝔄ᵀ. A symmetric P (with 𝔄 = a) has a P = (P aᵀ)ᵀ: then a P is only
    copied into a_P with ``copy_row`` (the Kalman family reads it; forgetting reads P_z)."""
    s = 0.0
    for i in range(n):
        acc = 0.0
        for j in range(n):
            acc += P[i, j] * z[j]
        P_z[i] = acc
        s += a[i] * acc
    if sym:
        if copy_row:
            for j in range(n):
                a_P[j] = P_z[j]
    else:
        for j in range(n):
            acc = 0.0
            for i in range(n):
                acc += a[i] * P[i, j]
            a_P[j] = acc
    return s


@_inline
def desired_products(desired_cov, a, z, Pd_z, a_Pd, n, sym):
    """Stenlund-Gustafsson products P_d 𝔄ᵀ → Pd_z, a P_d → a_Pd; returns s_d = a P_d 𝔄ᵀ. With ``sym`` (no
    instruments: 𝔄 = a; P_d is symmetric, checked by the config) a P_d = (P_d aᵀ)ᵀ: one product, shared buffer."""
    return covariance_products(desired_cov, a, z, Pd_z, a_Pd, n, sym, False)


# ============================================================================ stages 3-4: weight and gain
@_inline
def weight(psi, residual, sigma, c1, c2, c3):
    """W = ψ(u)/u with u = ΔB/σ̂ (eq. 3.15-3.17); 1 for least squares."""
    if psi == PSI_L2:
        return 1.0
    return weight_scalar(psi, residual / sigma, c1, c2, c3)


@_inline
def gain(P_z, w, s, c_gain, L, n):
    """L = W P 𝔄ᵀ / (c + W s) (Algorithms 3.1/3.13); returns the denominator c + W s."""
    den = c_gain + w * s
    g = w / den
    for i in range(n):
        L[i] = g * P_z[i]
    return den


# ============================================================================ stage 5: covariance evolution
@_inline
def covariance_forgetting(P, P_prev, L, P_z, a_P, inv_lam, n, sym):
    """Exponential forgetting P = (P - L a P)/λ (Algorithm 3.1). ``P_prev`` may be ``P`` itself: every entry is
    read once before it is written (the lower triangle of a symmetric P is written, never read)."""
    if sym:
        for i in range(n):
            for j in range(i, n):
                val = (P_prev[i, j] - L[i] * P_z[j]) * inv_lam
                P[i, j] = val
                P[j, i] = val
    else:
        for i in range(n):
            for j in range(n):
                P[i, j] = (P_prev[i, j] - L[i] * a_P[j]) * inv_lam


@_inline
def covariance_kalman(P, P_prev, gain_terms, s, r_joseph, process_noise, desired_terms, n, sym, joseph, kalman):
    """Kalman family: P - L a P + Q (Algorithm 3.13) or + Q_t = W P_d 𝔄ᵀ a P_d / (R + W a P_d 𝔄ᵀ)
    (Stenlund-Gustafsson, Algorithm 3.16); Joseph form (I - L a) P (I - L a)ᵀ + L (R/W) Lᵀ on request.
    ``gain_terms`` = (L, P 𝔄ᵀ, a P); ``desired_terms`` = (W / (R + W a P_d 𝔄ᵀ), P_d 𝔄ᵀ, a P_d).
    ``P_prev`` may be ``P`` itself (in place, as in :func:`covariance_forgetting`)."""
    L, P_z, a_P = gain_terms
    g_sg, Pd_z, a_Pd = desired_terms
    for i in range(n):
        j0 = i if sym else 0
        for j in range(j0, n):
            if joseph:
                # (I - L a) P (I - L a)ᵀ + L (R/W) Lᵀ, written without dividing by W
                val = (P_prev[i, j] - L[i] * a_P[j] - P_z[i] * L[j] + s * L[i] * L[j]
                       + r_joseph * P_z[i] * P_z[j])
            else:
                val = P_prev[i, j] - L[i] * a_P[j]
            if kalman:
                val += process_noise[i, j]
            else:
                val += g_sg * Pd_z[i] * a_Pd[j]
            P[i, j] = val
            if sym:
                P[j, i] = val


# ============================================================================ stage 6: regularisation
@_inline
def regularise(P, kappa, col, row, n, sym):
    """P ← P (I + κP)⁻¹ = (P⁻¹ + κ I)⁻¹ (eq. 3.34), as n Sherman-Morrison updates with κ e_k e_kᵀ:
    P ← P - κ P e_k e_kᵀ P / (1 + κ P_kk); exact, no pivoting, keeps P symmetric. Returns False when a
    normaliser 1 + κ P_kk is not a finite positive number."""
    for k in range(n):
        dd = 1.0 + kappa * P[k, k]
        if not (dd > 0.0 and dd < np.inf):
            return False
        f = kappa / dd
        if sym:
            # work on the upper triangle only; mirrored once below
            for i in range(k):
                col[i] = P[i, k]
            for i in range(k, n):
                col[i] = P[k, i]
            for i in range(n):
                fi = f * col[i]
                for j in range(i, n):
                    P[i, j] -= fi * col[j]
        else:
            for i in range(n):
                col[i] = P[i, k]
                row[i] = P[k, i]
            for i in range(n):
                fi = f * col[i]
                for j in range(n):
                    P[i, j] -= fi * row[j]
    if sym:
        for i in range(n):
            for j in range(i + 1, n):
                P[j, i] = P[i, j]
    return True


@_inline
def update_parameters(X, X_prev, L, r_prior, P, kappa, tikhonov, n):
    """X̂_t = X̂_{t-1} + L ΔB_t, minus κ P X̂_{t-1} for Tikhonov regularisation (eq. 3.8, Algorithm 3.4)."""
    for i in range(n):
        X[i] = X_prev[i] + L[i] * r_prior
    if tikhonov:
        for i in range(n):
            acc = 0.0
            for j in range(n):
                acc += P[i, j] * X_prev[j]
            X[i] -= kappa * acc


# ============================================================================ stage 7: saturation
@_inline
def saturate(X, xmin, xmax, n):
    """X_min ≤ X̂ ≤ X_max element-wise (section 3.10.1)."""
    for i in range(n):
        if X[i] < xmin[i]:
            X[i] = xmin[i]
        elif X[i] > xmax[i]:
            X[i] = xmax[i]


@_inline
def converged(X, X_iter, tol, n):
    """max |X̂ - X̂_iter| ≤ tol (1 + max |X̂|) (relative convergence of the iterated time step)."""
    dmax = 0.0
    xmag = 0.0
    for i in range(n):
        d = abs(X[i] - X_iter[i])
        dmax = max(dmax, d)
        xmag = max(xmag, abs(X[i]))
    return dmax <= tol * (1.0 + xmag)


# ============================================================================ stage 8: covariance safety net
@_inline
def covariance_health(X, P, pivots, p_bound, n, sym, factorise):
    """Classify P_t (and X̂_t) after an update; returns (P_HEALTHY | P_ABOVE_BOUND | P_CORRUPT, max |diag P|).

    P_CORRUPT: any non-finite X̂_i or P_ij, a diagonal entry ≤ 0, or (P symmetric and ``factorise``) a
    non-positive pivot of P = Uᵀ D U (i.e. P not positive definite). P_ABOVE_BOUND: healthy but
    max diag P > ``p_bound``.
    For symmetric positive definite P, |P_ij| ≤ √(P_ii P_jj), so bounded diagonals bound every entry."""
    probe = 0.0
    pmax = 0.0
    dmin = np.inf
    for i in range(n):
        d = P[i, i]
        probe += X[i] * 0.0 + d * 0.0
        dmin = min(dmin, d)
        pmax = max(pmax, abs(d))
    positive = dmin > 0.0  # (a NaN diagonal entry makes probe NaN)
    if sym and factorise:
        # LDLᵀ pivots on the upper triangle (row-wise): D_j = P_jj - Σ_{k<j} U_kj² D_k, U_kj = P_kj / D_k
        for j in range(n):
            dj = P[j, j]
            for k in range(j):
                u = pivots[k, j]
                dj -= u * u * pivots[k, k]
            pivots[j, j] = dj
            if not dj > 0.0:
                positive = False
                break
            inv = 1.0 / dj
            for i in range(j + 1, n):
                acc = P[j, i]
                for k in range(j):
                    acc -= pivots[k, j] * pivots[k, i] * pivots[k, k]
                pivots[j, i] = acc * inv
    elif not sym:
        for i in range(n):
            for j in range(n):
                probe += P[i, j] * 0.0
    if not (positive and probe == 0.0):
        return P_CORRUPT, pmax
    if pmax > p_bound:
        return P_ABOVE_BOUND, pmax
    return P_HEALTHY, pmax


@_inline
def restore_state(X, X_prev, n):
    """Roll X̂ back to the backup of :func:`backup_state` (P is reset to P_0 right after, so it needs none)."""
    for i in range(n):
        X[i] = X_prev[i]


@_inline
def reset_covariance(P, P0, n):
    """P ← P_0 (covariance resetting); returns max diag P_0."""
    pmax = 0.0
    for i in range(n):
        for j in range(n):
            P[i, j] = P0[i, j]
        pmax = max(pmax, P0[i, i])
    return pmax


# ============================================================================ stage 9: robust scale
@_inline
def scale(scalars, r_post, step_up, step_down, lam_scale, scale_factor):
    """Recursive quantile Q̂ of ΔB² (eq. 3.29) and σ̂² = λ_s σ̂² + (1-λ_s) f Q̂ (Algorithm 3.3, lines 10-12)."""
    d = r_post * r_post - scalars[SC_QHAT]
    if d > 0.0:
        scalars[SC_QHAT] += step_up
    elif d < 0.0:
        scalars[SC_QHAT] += step_down
        scalars[SC_QHAT] = max(scalars[SC_QHAT], 0.0)
    scalars[SC_SIGMA2] = lam_scale * scalars[SC_SIGMA2] + (1.0 - lam_scale) * scale_factor * scalars[SC_QHAT]


@_inline
def push_instrument(a, instrument_ring, counters, delay, n):
    """Append a_t to the ring buffer of the delayed instruments 𝔄_t = a_{t-k}."""
    pos = counters[CT_RING_POS]
    for i in range(n):
        instrument_ring[pos, i] = a[i]
    counters[CT_RING_POS] = (pos + 1) % delay
    if counters[CT_RING_FILL] < delay:
        counters[CT_RING_FILL] += 1


@_inline
def store_sample(t, X, P, r_prior, r_post, w, sigma2, out, store, n):
    """Write X̂_t (STORE_X) and diag P_t, ΔB prior/post, W, σ̂ (STORE_FULL) of sample t into ``out``
    (:data:`OUTPUT_FIELDS`)."""
    out_X, out_Pdiag, out_rprior, out_rpost, out_w, out_scale = out
    if store >= STORE_X:
        for i in range(n):
            out_X[t, i] = X[i]
    if store == STORE_FULL:
        for i in range(n):
            out_Pdiag[t, i] = P[i, i]
        out_rprior[t] = r_prior
        out_rpost[t] = r_post
        out_w[t] = w
        out_scale[t] = np.sqrt(sigma2)


# ============================================================================ the record loop
#: the composition's settings inside the kernel (built by :func:`options` from ``codes`` and ``settings``)
Options = namedtuple("Options", [
    "store", "psi", "c1", "c2", "c3", "min_scale",               # weights (stage 3)
    "cov", "c_gain", "inv_lam", "R", "joseph", "sym",            # gain and covariance (stages 4-5)
    "iv", "delay", "has_transition",                            # gain direction, prediction
    "max_iter", "tol", "regularised", "tikhonov", "kappa", "constrain",  # iterations, stages 6-7
    "robust", "step_up", "step_down", "lam_scale", "scale_factor",      # robust scale (stage 9)
    "blowup_level", "p_bound"])                                  # safety net (stage 8)
#: the work buffers inside the kernel, named (built by :func:`buffers` from the ``work`` record)
Buffers = namedtuple("Buffers", ["a", "z", "X_prev", "X_iter", "P_z", "a_P", "L", "Pd_z", "a_Pd", "col", "row",
                                 "P_source", "pivots"])


@_inline
def options(codes, settings):
    """The :class:`Options` of a composition from its integer codes (IP_*) and float settings (FP_*)."""
    cov = codes[IP_COV]
    kappa = settings[FP_KAPPA]
    return Options(
        codes[IP_STORE], codes[IP_PSI], settings[FP_C1], settings[FP_C2], settings[FP_C3], settings[FP_MIN_SCALE],
        cov, settings[FP_LAMBDA] if cov == COV_FORGETTING else settings[FP_R], 1.0 / settings[FP_LAMBDA],
        settings[FP_R], codes[IP_JOSEPH] != 0, codes[IP_SYMMETRIC] != 0,
        codes[IP_IV], codes[IP_DELAY], codes[IP_TRANSITION] != 0,
        codes[IP_MAX_ITER], settings[FP_TOL], codes[IP_REG] != REG_NONE and kappa > 0.0,
        codes[IP_REG] == REG_TIKHONOV and kappa > 0.0, kappa, codes[IP_CONSTRAIN] != 0,
        codes[IP_ROBUST_SCALE] != 0, settings[FP_ETA] * 2.0 * settings[FP_P],
        -settings[FP_ETA] * 2.0 * (1.0 - settings[FP_P]), settings[FP_LAMBDA_SCALE], settings[FP_SCALE_FACTOR],
        settings[FP_BLOWUP_LEVEL], settings[FP_P_BOUND])


@_inline
def buffers(work, P, opt):
    """The named :class:`Buffers` in the ``work`` record. Without instruments the gain direction is the regressor
    itself (shared buffer, no per-sample copy); with a symmetric P_d and 𝔄 = a, a P_d equals P_d aᵀ (one buffer);
    P_{t-1} for the covariance update is a copy only when the update is iterated (each iteration restarts from
    it), else the update runs in place."""
    vectors, matrices = work
    a = vectors[0]
    return Buffers(a, a if opt.iv == IV_NONE else vectors[1], vectors[2], vectors[3], vectors[4], vectors[5],
                   vectors[6], vectors[7], vectors[7] if opt.sym else vectors[8], vectors[9], vectors[10],
                   matrices[0] if opt.max_iter > 1 else P, matrices[1])


@_inline
def a_priori(P, X, desired_cov, b, buf, opt, n):
    """Stage 2 of a finite sample: back up X̂_{t-1} (and P_{t-1} when iterated), ΔB_t, s = a P 𝔄ᵀ and s_d = a P_d 𝔄ᵀ;
    returns (ΔB_t, s, s_d, usable). A sample whose products overflow (a P aᵀ, a P 𝔄ᵀ or ΔB beyond the float
    range) is not usable: it is skipped like a non-finite one."""
    a = buf.a
    backup_state(X, P, buf.X_prev, buf.P_source, n, opt.sym, opt.max_iter > 1)
    r_prior, s = prior_products(P, X, a, buf.z, b, buf.P_z, buf.a_P, n, opt.sym, opt.cov)
    s_d = 0.0
    if opt.cov == COV_SG:
        s_d = desired_products(desired_cov, a, buf.z, buf.Pd_z, buf.a_Pd, n, opt.sym)
    probe = r_prior * 0.0 + s * 0.0 + s_d * 0.0
    if opt.iv != IV_NONE:
        # with instruments s = a P 𝔄ᵀ need not overflow for a huge a_t: test Σ a_i² P_ii ≥ a P aᵀ / n
        for i in range(n):
            probe += a[i] * a[i] * P[i, i] * 0.0
    return r_prior, s, s_d, probe == 0.0


@_inline
def covariance_update(P, process_noise, buf, w, s, s_d, den, opt, n):
    """Stage 5: P_t by forgetting (Algorithm 3.1) or in the Kalman family (Algorithms 3.13, 3.16), from
    ``buf.P_source`` (P_{t-1})."""
    if opt.cov == COV_FORGETTING:
        covariance_forgetting(P, buf.P_source, buf.L, buf.P_z, buf.a_P, opt.inv_lam, n, opt.sym)
    else:
        g_sg = w / (opt.R + w * s_d) if opt.cov == COV_SG else 0.0
        covariance_kalman(P, buf.P_source, (buf.L, buf.P_z, buf.a_P), s, opt.R * w / (den * den), process_noise,
                          (g_sg, buf.Pd_z, buf.a_Pd), n, opt.sym, opt.joseph, opt.cov == COV_KALMAN)


@_inline
def update_step(parts, X, P, sigma2, b, r_prior, s, s_d, buf, opt, n):
    """Stages 3-7 of one time step (iterated up to ``max_iter`` times until X̂_t converges, the "optimal"
    variant): weight, gain, covariance, regularisation, parameter update, saturation. Returns (W, ok); ok is
    False when the regularisation's normaliser was not a finite positive number."""
    _, _, process_noise, _, _, xmin, xmax, _ = parts
    sigma = 1.0
    if opt.psi != PSI_L2:
        sigma = np.sqrt(sigma2)
        sigma = max(sigma, opt.min_scale)
    w = weight(opt.psi, r_prior, sigma, opt.c1, opt.c2, opt.c3)
    ok = True
    for it in range(opt.max_iter):
        if it > 0:
            # iterate the weight with the current estimate until X̂_t converges
            for i in range(n):
                buf.X_iter[i] = X[i]
            w = weight(opt.psi, output_correction(buf.a, X, b, n), sigma, opt.c1, opt.c2, opt.c3)
        den = gain(buf.P_z, w, s, opt.c_gain, buf.L, n)
        covariance_update(P, process_noise, buf, w, s, s_d, den, opt, n)
        if opt.regularised:
            ok = regularise(P, opt.kappa, buf.col, buf.row, n, opt.sym)
            if not ok:
                break
        update_parameters(X, buf.X_prev, buf.L, r_prior, P, opt.kappa, opt.tikhonov, n)
        if opt.constrain:
            saturate(X, xmin, xmax, n)
        if it > 0 and converged(X, buf.X_iter, opt.tol, n):
            break
    return w, ok


@_inline
def safety_net(state, P0, sample, ok, buf, opt, n):
    """Stage 8 after an update: classify P_t (the LDLᵀ factorisation every PD_CHECK_INTERVAL samples), keep the
    largest healthy max diag P, roll back a corrupt update and reset P to P_0 when it is corrupt or above the
    bound (counted; the first such sample, or the first above the blow-up level, is the blow-up sample)."""
    X, P, scalars, _, counters = state
    health, pmax = covariance_health(X, P, buf.pivots, opt.p_bound, n, opt.sym,
                                     (sample & (PD_CHECK_INTERVAL - 1)) == 0)
    if not ok:
        health = P_CORRUPT
    if health != P_CORRUPT and pmax > scalars[SC_PMAX]:
        scalars[SC_PMAX] = pmax  # the largest diag P an update produced (before a reset)
    if health != P_HEALTHY:
        if health == P_CORRUPT:
            # a non-finite or indefinite result (overflow, singular normalisation) is undone
            counters[CT_ROLLED_BACK] += 1
            restore_state(X, buf.X_prev, n)
        counters[CT_P_RESETS] += 1
        pmax = reset_covariance(P, P0, n)
        if counters[CT_BLOWUP_AT] < 0:
            counters[CT_BLOWUP_AT] = sample
    if pmax > opt.blowup_level and counters[CT_BLOWUP_AT] < 0:
        counters[CT_BLOWUP_AT] = sample


@_inline
def finish_sample(t, b, r_prior, w, state, out, buf, opt, n):
    """Stage 9 and the outputs: a posteriori ΔB (when the scale or the outputs need it), the robust scale, the
    delayed-instrument ring, the stored sample."""
    X, P, scalars, instrument_ring, counters = state
    r_post = b
    if opt.robust or opt.store == STORE_FULL:
        r_post = output_correction(buf.a, X, b, n)
    if opt.robust:
        scale(scalars, r_post, opt.step_up, opt.step_down, opt.lam_scale, opt.scale_factor)
    if opt.iv == IV_DELAY:
        push_instrument(buf.a, instrument_ring, counters, opt.delay, n)
    store_sample(t, X, P, r_prior, r_post, w, scalars[SC_SIGMA2], out, opt.store, n)


# _nrt=False: numba's private switch for reference counting, not listed in its njit overloads
@cached_njit(nogil=True, _nrt=False)
def run_record(record, parts, state, out, work, size_tag):
    """Process one record (T samples) in place on the state.

    ``record``, ``parts``, ``state``, ``out``, ``work``: the packed records of the module docstring (``parts`` =
    the IP_*/FP_* arrays and matrices of :class:`~roadload.estimators.config.EstimatorConfig`; its P_0 is the
    target of a covariance reset). The function is compiled without numba's reference counting (``_nrt=False``:
    it allocates nothing), so the inline stages pass arrays at no cost. Outputs are written per sample when the
    store code asks for them (STORE_X: X̂_t; STORE_FULL: all). ``size_tag`` is a tuple of n zeros
    (:func:`size_tag`): its length is part of the argument type, so the function is compiled once per number of
    parameters with n a compile-time constant (small loops unrolled; about 1.5x faster than a run-time n).
    """
    codes, settings, _, desired_cov, transition, _, _, P0 = parts
    X, P, scalars, instrument_ring, counters = state
    T = record[1].shape[0]
    n = len(size_tag)
    opt = options(codes, settings)
    buf = buffers(work, P, opt)
    t0 = counters[CT_T]  # samples before this record (sample indices are global: online == batch)

    for t in range(T):
        b, valid = read_sample(record, t, buf.a, buf.z, instrument_ring, counters, opt.iv, opt.delay, n)
        if opt.has_transition:
            predict(transition, X, P, buf.X_prev, buf.pivots, n, opt.sym)
        r_prior = np.nan
        s = 0.0
        s_d = 0.0
        if valid:
            r_prior, s, s_d, valid = a_priori(P, X, desired_cov, b, buf, opt, n)
        if not valid:
            counters[CT_SKIPPED] += 1
            store_sample(t, X, P, np.nan, np.nan, np.nan, scalars[SC_SIGMA2], out, opt.store, n)
            continue
        w, ok = update_step(parts, X, P, scalars[SC_SIGMA2], b, r_prior, s, s_d, buf, opt, n)
        safety_net(state, P0, t0 + t, ok, buf, opt, n)
        finish_sample(t, b, r_prior, w, state, out, buf, opt, n)
    counters[CT_T] += T
