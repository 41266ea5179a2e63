"""The one numeric kernel of the recursive linear estimators of chapter 3 (Algorithms 3.1-3.4, 3.9-3.21).

A time step is the composition of interchangeable parts, selected by small integer codes (``ip``) and float
settings (``fp``); see :mod:`roadload.estimators.config` for the mapping from names to codes:

1. skip a non-finite sample (a_t, b_t or the instrument), count it, leave the state as it was (apart from the
   prediction step X' = F X, P' = F P Fᵀ when a transition matrix is set, e.g. in the PKS);
2. a priori output correction ΔB_t = b_t - a_t X̂_{t-1};
3. weight W = ψ(ΔB/σ̂_{t-1})/(ΔB/σ̂_{t-1}) (``influence.weight_scalar``);
4. gain L = W P 𝔄ᵀ / (c + W a P 𝔄ᵀ) with c = λ (forgetting family) or R (Kalman family), 𝔄 = a_t, a delayed
   regressor or a user instrument;
5. covariance P = (P - L a P)/λ, or P - L a P + Q, or P - L a P + Q_t(P_d) (Stenlund-Gustafsson); optional
   Joseph form in the Kalman family;
6. regularisation P ← P (I + κP)⁻¹ (eq. 3.34) and the Levenberg-Marquardt or Tikhonov parameter update;
7. parameter saturation X_min ≤ X̂ ≤ X_max (section 3.10.1);
8. robust recursive scale: recursive quantile of the a posteriori ΔB² (eq. 3.29) and σ̂² forgetting
   (Algorithm 3.3 lines 10-12).

Steps 3-6 can be iterated within a time step until X̂_t converges (the "optimal" variant of Algorithm 3.3).

:func:`run_record` processes a whole record and is what the online ``update()`` calls with a one-sample
record, so online and batch results are the same numbers by construction. ``recursive.run_many`` runs
independent records (trips) in parallel threads with the very same function (it releases the GIL).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from .influence import PSI_L2, weight_scalar

# ---- integer settings (ip) ----
IP_PSI, IP_COV, IP_REG, IP_IV, IP_DELAY, IP_ROBUST_SCALE, IP_MAX_ITER, IP_JOSEPH, IP_SYMMETRIC, \
    IP_CONSTRAIN, IP_TRANSITION, IP_STORE = range(12)
N_IP = 12
# ---- float settings (fp) ----
FP_C1, FP_C2, FP_C3, FP_LAMBDA, FP_R, FP_KAPPA, FP_ETA, FP_P, FP_LAMBDA_SCALE, FP_SCALE_FACTOR, FP_TOL, \
    FP_MIN_SCALE, FP_BLOWUP_LEVEL = range(13)
N_FP = 13

COV_FORGETTING, COV_KALMAN, COV_SG = 0, 1, 2
REG_NONE, REG_LM, REG_TIKHONOV = 0, 1, 2
IV_NONE, IV_DELAY, IV_USER = 0, 1, 2
STORE_FINAL, STORE_X, STORE_FULL = 0, 1, 2

def size_tag(n: int) -> tuple:
    """The ``size_tag`` argument of :func:`run_record` for n parameters."""
    return (0.0,) * int(n)


# ---- scalar state (sc) and counters ----
SC_SIGMA2, SC_QHAT, SC_PMAX = 0, 1, 2
N_SC = 3
CT_SKIPPED, CT_ROLLED_BACK, CT_BLOWUP_AT, CT_T, CT_RING_POS, CT_RING_FILL = range(6)
N_CT = 6


@njit(cache=True, nogil=True)
def run_record(A, B, Z, ip, fp, Qm, Pd, F, xmin, xmax, X, P, sc, ring, ct,
               out_X, out_Pdiag, out_rprior, out_rpost, out_w, out_scale, size_tag):
    """Process one record (T samples) in place on the state (X, P, sc, ring, ct).

    A (T×n) regressors, B (T,) outputs, Z (T×n) user instruments (only read when ip[IP_IV] == IV_USER).
    Outputs are written per sample when ip[IP_STORE] asks for them (STORE_X: out_X; STORE_FULL: all).
    ``size_tag`` is a tuple of n zeros (:func:`size_tag`): its length is part of the argument type, so the
    function is compiled once per number of parameters with n a compile-time constant (small loops unrolled;
    about 1.5x faster than a run-time n). The body is one function without array-passing calls per sample.
    """
    T = B.shape[0]
    n = len(size_tag)
    store = ip[IP_STORE]
    psi = ip[IP_PSI]
    cov = ip[IP_COV]
    reg = ip[IP_REG]
    iv = ip[IP_IV]
    k = ip[IP_DELAY]
    max_iter = ip[IP_MAX_ITER]
    robust = ip[IP_ROBUST_SCALE] != 0
    joseph = ip[IP_JOSEPH] != 0
    sym = ip[IP_SYMMETRIC] != 0
    constrain = ip[IP_CONSTRAIN] != 0
    transition = ip[IP_TRANSITION] != 0
    c1 = fp[FP_C1]
    c2 = fp[FP_C2]
    c3 = fp[FP_C3]
    lam = fp[FP_LAMBDA]
    inv_lam = 1.0 / lam
    R = fp[FP_R]
    kappa = fp[FP_KAPPA]
    regularise = reg != REG_NONE and kappa > 0.0
    tikhonov = reg == REG_TIKHONOV and kappa > 0.0
    c_gain = lam if cov == COV_FORGETTING else R
    tol = fp[FP_TOL]
    min_scale = fp[FP_MIN_SCALE]
    blowup = fp[FP_BLOWUP_LEVEL]
    eta = fp[FP_ETA]
    step_up = eta * 2.0 * fp[FP_P]
    step_down = -eta * 2.0 * (1.0 - fp[FP_P])
    lam_s = fp[FP_LAMBDA_SCALE]
    sfac = fp[FP_SCALE_FACTOR]

    a = np.empty(n)
    # without instruments the gain direction is the regressor itself: share the buffer (no per-sample copy)
    z = a if iv == IV_NONE else np.empty(n)
    Xp = np.empty(n)
    Pp = np.empty((n, n))
    Xit = np.empty(n)
    Pz = np.empty(n)
    aP = np.empty(n)
    L = np.empty(n)
    u = np.empty(n)
    v = np.empty(n)
    work = np.empty((n, n))
    pc = np.empty(n)
    pr = np.empty(n)

    for t in range(T):
        b = B[t]
        # one test for all entries: x * 0 is 0 for finite x and NaN for inf/NaN
        probe = b * 0.0
        for i in range(n):
            a[i] = A[t, i]
            probe += a[i] * 0.0
        if iv == IV_USER:
            for i in range(n):
                z[i] = Z[t, i]
                probe += z[i] * 0.0
        elif iv == IV_DELAY and ct[CT_RING_FILL] >= k:
            pos = ct[CT_RING_POS]
            for i in range(n):
                z[i] = ring[pos, i]
        elif iv != IV_NONE:
            for i in range(n):
                z[i] = a[i]
        valid = probe == 0.0
        if transition:
            # prediction X' = F X, P' = F P Fᵀ (also for skipped samples: time advances)
            for i in range(n):
                acc = 0.0
                for j in range(n):
                    acc += F[i, j] * X[j]
                Xp[i] = acc
            for i in range(n):
                for j in range(n):
                    acc = 0.0
                    for kk in range(n):
                        acc += F[i, kk] * P[kk, j]
                    work[i, j] = acc
            for i in range(n):
                X[i] = Xp[i]
                for j in range(n):
                    acc = 0.0
                    for kk in range(n):
                        acc += work[i, kk] * F[j, kk]
                    P[i, j] = acc
            if sym:
                for i in range(n):
                    for j in range(i + 1, n):
                        m = 0.5 * (P[i, j] + P[j, i])
                        P[i, j] = m
                        P[j, i] = m
        if not valid:
            ct[CT_SKIPPED] += 1
            if store >= STORE_X:
                for i in range(n):
                    out_X[t, i] = X[i]
            if store == STORE_FULL:
                for i in range(n):
                    out_Pdiag[t, i] = P[i, i]
                out_rprior[t] = np.nan
                out_rpost[t] = np.nan
                out_w[t] = np.nan
                out_scale[t] = np.sqrt(sc[SC_SIGMA2])
            continue
        # ---- quantities that do not depend on the weight
        # backup of the state for iterations and roll-back (upper triangle suffices when P is symmetric)
        r0 = b
        for i in range(n):
            Xp[i] = X[i]
            r0 -= a[i] * X[i]
            for j in range(i if sym else 0, n):
                Pp[i, j] = P[i, j]
        s = 0.0
        for i in range(n):
            acc = 0.0
            for j in range(n):
                acc += P[i, j] * z[j]
            Pz[i] = acc
            s += a[i] * acc
        if sym:
            if cov != COV_FORGETTING:
                for j in range(n):
                    aP[j] = Pz[j]
        else:
            for j in range(n):
                acc = 0.0
                for i in range(n):
                    acc += a[i] * P[i, j]
                aP[j] = acc
        sd = 0.0
        if cov == COV_SG:
            for i in range(n):
                acc = 0.0
                acc2 = 0.0
                for j in range(n):
                    acc += Pd[i, j] * z[j]
                    acc2 += a[j] * Pd[j, i]
                u[i] = acc
                v[i] = acc2
            for i in range(n):
                sd += a[i] * u[i]
        sigma = 1.0
        w = 1.0
        if psi != PSI_L2:
            sigma = np.sqrt(sc[SC_SIGMA2])
            if sigma < min_scale:
                sigma = min_scale
            w = weight_scalar(psi, r0 / sigma, c1, c2, c3)
        ok = True
        for it in range(max_iter):
            if it > 0:
                # iterate the weight with the current estimate until X̂_t converges ("optimal" variant)
                r = b
                for i in range(n):
                    Xit[i] = X[i]
                    r -= a[i] * X[i]
                w = weight_scalar(psi, r / sigma, c1, c2, c3)
            den = c_gain + w * s
            g = w / den
            for i in range(n):
                L[i] = g * Pz[i]
            rr = R * w / (den * den)
            gq = 0.0
            if cov == COV_SG:
                gq = w / (R + w * sd)
            if cov == COV_FORGETTING:
                if sym:
                    for i in range(n):
                        for j in range(i, n):
                            val = (Pp[i, j] - L[i] * Pz[j]) * inv_lam
                            P[i, j] = val
                            P[j, i] = val
                else:
                    for i in range(n):
                        for j in range(n):
                            P[i, j] = (Pp[i, j] - L[i] * aP[j]) * inv_lam
            else:
                for i in range(n):
                    j0 = i if sym else 0
                    for j in range(j0, n):
                        if joseph:
                            # (I - L a) P (I - L a)ᵀ + L (R/W) Lᵀ, written without dividing by W
                            val = (Pp[i, j] - L[i] * aP[j] - Pz[i] * L[j] + s * L[i] * L[j]
                                   + rr * Pz[i] * Pz[j])
                        else:
                            val = Pp[i, j] - L[i] * aP[j]
                        if cov == COV_KALMAN:
                            val += Qm[i, j]
                        else:
                            # Stenlund-Gustafsson: Q_t = W P_d 𝔄ᵀ a P_d / (R + W a P_d 𝔄ᵀ)
                            val += gq * u[i] * v[j]
                        P[i, j] = val
                        if sym:
                            P[j, i] = val
            if regularise:
                # P <- P (I + κP)⁻¹ = (P⁻¹ + κ I)⁻¹ (eq. 3.34), as n Sherman-Morrison updates with κ e_i e_iᵀ:
                # P <- P - κ P e_i e_iᵀ P / (1 + κ P_ii); exact, no pivoting, keeps P symmetric.
                for kk in range(n):
                    dd = 1.0 + kappa * P[kk, kk]
                    if not (dd > 0.0 and dd < np.inf):
                        ok = False
                        break
                    f = kappa / dd
                    if sym:
                        # work on the upper triangle only; mirrored once below
                        for i in range(kk):
                            pc[i] = P[i, kk]
                        for i in range(kk, n):
                            pc[i] = P[kk, i]
                        for i in range(n):
                            fi = f * pc[i]
                            for j in range(i, n):
                                P[i, j] -= fi * pc[j]
                    else:
                        for i in range(n):
                            pc[i] = P[i, kk]
                            pr[i] = P[kk, i]
                        for i in range(n):
                            fi = f * pc[i]
                            for j in range(n):
                                P[i, j] -= fi * pr[j]
                if not ok:
                    break
                if sym:
                    for i in range(n):
                        for j in range(i + 1, n):
                            P[j, i] = P[i, j]
            for i in range(n):
                X[i] = Xp[i] + L[i] * r0
            if tikhonov:
                for i in range(n):
                    acc = 0.0
                    for j in range(n):
                        acc += P[i, j] * Xp[j]
                    X[i] -= kappa * acc
            if constrain:
                for i in range(n):
                    if X[i] < xmin[i]:
                        X[i] = xmin[i]
                    elif X[i] > xmax[i]:
                        X[i] = xmax[i]
            if it > 0:
                dmax = 0.0
                xmag = 0.0
                for i in range(n):
                    d = abs(X[i] - Xit[i])
                    if d > dmax:
                        dmax = d
                    if abs(X[i]) > xmag:
                        xmag = abs(X[i])
                if dmax <= tol * (1.0 + xmag):
                    break
        # a non-finite result (overflowing P, singular normalisation) is rolled back and counted
        # with P symmetric positive semi-definite, |P_ij| <= sqrt(P_ii P_jj): X and diag P suffice
        probe = 0.0
        pmax = P[0, 0]
        for i in range(n):
            probe += X[i] * 0.0 + P[i, i] * 0.0
            if P[i, i] > pmax:
                pmax = P[i, i]
        if not sym:
            for i in range(n):
                for j in range(n):
                    probe += P[i, j] * 0.0
        finite = ok and probe == 0.0
        if not finite:
            ct[CT_ROLLED_BACK] += 1
            for i in range(n):
                X[i] = Xp[i]
                for j in range(i if sym else 0, n):
                    P[i, j] = Pp[i, j]
                    if sym:
                        P[j, i] = Pp[i, j]
            pmax = P[0, 0]
            for i in range(1, n):
                if P[i, i] > pmax:
                    pmax = P[i, i]
        if pmax > sc[SC_PMAX]:
            sc[SC_PMAX] = pmax
        if pmax > blowup and ct[CT_BLOWUP_AT] < 0:
            ct[CT_BLOWUP_AT] = ct[CT_T] + t
        rpost = b
        if robust or store == STORE_FULL:
            for i in range(n):
                rpost -= a[i] * X[i]
        if robust:
            # recursive quantile of ΔB² (eq. 3.29) and σ̂² forgetting (Algorithm 3.3, lines 10-12)
            d = rpost * rpost - sc[SC_QHAT]
            if d > 0.0:
                sc[SC_QHAT] += step_up
            elif d < 0.0:
                sc[SC_QHAT] += step_down
                if sc[SC_QHAT] < 0.0:
                    sc[SC_QHAT] = 0.0
            sc[SC_SIGMA2] = lam_s * sc[SC_SIGMA2] + (1.0 - lam_s) * sfac * sc[SC_QHAT]
        if iv == IV_DELAY:
            pos = ct[CT_RING_POS]
            for i in range(n):
                ring[pos, i] = a[i]
            ct[CT_RING_POS] = (pos + 1) % k
            if ct[CT_RING_FILL] < k:
                ct[CT_RING_FILL] += 1
        if store >= STORE_X:
            for i in range(n):
                out_X[t, i] = X[i]
        if store == STORE_FULL:
            for i in range(n):
                out_Pdiag[t, i] = P[i, i]
            out_rprior[t] = r0
            out_rpost[t] = rpost
            out_w[t] = w
            out_scale[t] = np.sqrt(sc[SC_SIGMA2])
    ct[CT_T] += T
