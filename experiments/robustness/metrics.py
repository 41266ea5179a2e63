"""Robustness metrics: relative parameter error (from SEVN, eq. 3.2), recovery times, wind-up indicators,
excitation, the empirical breakdown point."""

from __future__ import annotations

from typing import Sequence

import numpy as np
import numpy.typing as npt

from .faults import RobustnessError


# ====================================================================================== metrics
def relative_parameter_error(X_hat: np.ndarray, X_true: np.ndarray) -> np.ndarray:
    """Scale-free parameter error e_t = sqrt(mean_i ((X̂_t,i - X̄_t,i)/|X̄_t,i|)²) [1] per time step.

    SEVN (eq. 3.2) is dominated by the largest parameter (the mass m_V in M3/M4); bounds such as the
    breakdown criterion use this relative error so that every parameter counts. Non-finite estimates give inf.
    """
    X_hat = np.atleast_2d(np.asarray(X_hat, dtype=float))
    X_true = np.atleast_2d(np.asarray(X_true, dtype=float))
    if X_hat.shape != X_true.shape:
        raise RobustnessError(f"estimate shape {X_hat.shape} differs from truth shape {X_true.shape}")
    scale = np.abs(X_true)
    if np.any(scale == 0):
        raise RobustnessError("relative error undefined: a true parameter is exactly 0")
    with np.errstate(over="ignore", invalid="ignore"):
        err = np.sqrt(np.mean(((X_hat - X_true) / scale) ** 2, axis=1))
    err[~np.isfinite(err)] = np.inf
    return err


def recovery_time(t: np.ndarray, error: np.ndarray, t_event: float, bound: float, hold: float = 0.0) -> float:
    """Time [s] after ``t_event`` until ``error`` falls below ``bound`` and stays below it for ``hold`` s
    (or until the end of the record). inf when it never recovers; 0 when it never left the bound."""
    t = np.asarray(t, dtype=float)
    error = np.asarray(error, dtype=float)
    if t.shape != error.shape:
        raise RobustnessError(f"t {t.shape} and error {error.shape} differ in shape")
    after = t >= t_event
    if not after.any():
        raise RobustnessError(f"event time {t_event} s lies after the end of the record ({t[-1]} s)")
    ta, ea = t[after], error[after]
    bad = ~(ea < bound)  # NaN counts as not recovered
    if not bad.any():
        return 0.0
    bad_idx = np.flatnonzero(bad)
    # candidate recovery instants: first good sample after each bad run
    for i in np.flatnonzero(np.diff(np.r_[bad, False].astype(int)) == -1) + 1:
        if i >= ta.size:
            break
        nxt = bad_idx[bad_idx >= i]
        good_until = ta[nxt[0]] if nxt.size else np.inf
        if good_until - ta[i] >= hold or (not nxt.size):
            return float(ta[i] - t_event)
    return float("inf")


def step_recovery_time(t: np.ndarray, X_hat: np.ndarray, X_true: np.ndarray, t_event: float,
                       tolerance: float = 0.3, hold: float = 10.0) -> float:
    """Recovery time [s] after a parameter step or ramp starting at ``t_event``.

    Only the parameters whose truth changes count. Each is judged by its step response relative to its own
    level before the event, so a constant bias of the model structure does not count as "not recovered":
    e_j(t) = |(X̂_j(t) - med X̂_j,pre) - (X̄_j(t) - X̄_j,pre)| / |ΔX̄_j|, with ΔX̄_j the total change;
    recovered when max_j e_j stays below ``tolerance`` (for ``hold`` s). pre = the 20 % of the record before the
    event (at least 1 sample). NaN when no parameter changes; inf when it never recovers."""
    t = np.asarray(t, dtype=float)
    X_hat = np.asarray(X_hat, dtype=float)
    X_true = np.asarray(X_true, dtype=float)
    pre = t < t_event
    if not pre.any():
        raise RobustnessError(f"no samples before the event at {t_event} s")
    i0 = int(np.flatnonzero(pre)[-1])
    base_true = X_true[i0]
    delta = X_true[-1] - base_true
    changed = np.abs(delta) > 1e-9 * np.maximum(np.abs(base_true), 1e-300)
    if not changed.any():
        return float("nan")
    pre_win = pre & (t >= t[i0] - 0.2 * (t[-1] - t[0]))
    with np.errstate(over="ignore", invalid="ignore"):
        base_hat = np.median(X_hat[pre_win][:, changed], axis=0)
        e = np.abs((X_hat[:, changed] - base_hat) - (X_true[:, changed] - base_true[changed])) / np.abs(delta[changed])
    e = np.where(np.isfinite(e), e, np.inf).max(axis=1)
    return recovery_time(t, e, t_event, tolerance, hold)


def prediction_recovery_time(t: np.ndarray, A: np.ndarray, B: np.ndarray, X_hat: np.ndarray, t_event: float,
                             tolerance: float = 0.3, hold: float = 10.0, window: float = 30.0) -> float:
    """Recovery time [s] of the one-step-ahead prediction after an event the model has no parameter for (e.g. a
    headwind onset: M3/M4 have no wind term, so the true X̄ does not change and :func:`step_recovery_time` is
    undefined). r_t = |B_t - A_t X̂_{t-1}|, m(t) its running median over the last ``window`` s; recovered when
    m(t) <= (1 + tolerance) x the median of r over the 20 % of the record before the event, held ``hold`` s.
    0 when the prediction never degraded; inf when it never recovers."""
    import pandas as pd

    t = np.asarray(t, dtype=float)
    if not (t.size == len(A) == len(B) == len(X_hat)) or t.size < 2:
        raise RobustnessError(f"t, A, B, X_hat must have the same length >= 2, got {t.size}, {len(A)}, {len(B)}, "
                              f"{len(X_hat)}")
    pre = t < t_event
    if not pre.any():
        raise RobustnessError(f"no samples before the event at {t_event} s")
    with np.errstate(over="ignore", invalid="ignore"):
        r = np.abs(np.asarray(B, float)[1:] - np.einsum("ij,ij->i", np.asarray(A, float)[1:],
                                                        np.asarray(X_hat, float)[:-1]))
    r = np.where(np.isfinite(r), r, np.inf)
    tt = t[1:]
    m = pd.Series(r, index=pd.to_timedelta(tt, unit="s")).rolling(f"{window}s").median().to_numpy()
    pre_win = (tt < t_event) & (tt >= t_event - 0.2 * (t[-1] - t[0]))
    if not pre_win.any():
        raise RobustnessError(f"no samples before the event at {t_event} s")
    base = float(np.median(r[pre_win]))
    if not (np.isfinite(base) and base > 0):
        return float("nan")
    return recovery_time(tt, m / base - 1.0, t_event, tolerance, hold)


def windup_indicators(P: np.ndarray, window: np.ndarray | None = None) -> dict[str, float]:
    """Wind-up indicators of a covariance history P (T×n×n full matrices, or T×n diagonals).

    Returns max trace(P) and max condition number over the window (boolean mask over T; all samples if None).
    With diagonals only, the condition number is the lower bound max(diag)/min(diag) ≤ cond(P) (P is SPD),
    reported as 'cond_P_lower_bound'. Non-finite or non-positive P counts as inf (blown up).
    """
    P = np.asarray(P, dtype=float)
    if P.ndim not in (2, 3):
        raise RobustnessError(f"P must be T×n (diagonals) or T×n×n, got shape {P.shape}")
    if window is not None:
        window = np.asarray(window, dtype=bool)
        if window.shape != (P.shape[0],):
            raise RobustnessError(f"window mask shape {window.shape} does not match {P.shape[0]} samples")
        P = P[window]
    if P.shape[0] == 0:
        return {"trace_P_max": float("nan"), "cond_P_max": float("nan")}
    if P.ndim == 3:
        tr = np.trace(P, axis1=1, axis2=2)
        finite = np.all(np.isfinite(P), axis=(1, 2))
        cond = np.full(P.shape[0], np.inf)
        if finite.any():
            ev = np.linalg.eigvalsh(0.5 * (P[finite] + np.swapaxes(P[finite], 1, 2)))
            with np.errstate(divide="ignore", invalid="ignore"):
                c = np.where(ev[:, 0] > 0, ev[:, -1] / ev[:, 0], np.inf)
            cond[finite] = c
        key = "cond_P_max"
    else:
        tr = P.sum(axis=1)
        with np.errstate(divide="ignore", invalid="ignore"):
            cond = np.where(P.min(axis=1) > 0, P.max(axis=1) / P.min(axis=1), np.inf)
        key = "cond_P_lower_bound_max"
    tr = np.where(np.isfinite(tr), tr, np.inf)
    cond = np.where(np.isfinite(cond), cond, np.inf)
    return {"trace_P_max": float(np.max(tr)), key: float(np.max(cond))}


def excitation_condition(A: np.ndarray, window: int) -> np.ndarray:
    """Condition number of the windowed information matrix Σ_{i=t-window+1}^{t} A_iᵀA_i (section 3.3).

    A large value flags poor excitation (the persistent-excitation condition fails). NaN rows are ignored;
    a singular window gives inf. Returns (T,), NaN for the first window-1 samples.
    """
    A = np.asarray(A, dtype=float)
    if A.ndim != 2 or window < 1:
        raise RobustnessError(f"need A as T×n and window >= 1, got shape {A.shape}, window {window}")
    A = np.where(np.isfinite(A), A, 0.0)
    outer = np.einsum("ti,tj->tij", A, A)
    cs = np.cumsum(outer, axis=0)
    R = cs[window - 1:] - np.concatenate([np.zeros((1,) + outer.shape[1:]), cs[:-window]], axis=0)
    ev = np.linalg.eigvalsh(R)
    with np.errstate(divide="ignore", invalid="ignore"):
        cond = np.where(ev[:, 0] > 1e-12 * max(ev[:, -1].max(), 1e-300), ev[:, -1] / ev[:, 0], np.inf)
    return np.r_[np.full(window - 1, np.nan), cond]


def breakdown_point(levels: npt.ArrayLike, errors: npt.ArrayLike, bound: float, baseline: float = 0.0) -> float:
    """Empirical breakdown point: the smallest swept outlier fraction whose error exceeds ``baseline + bound``.

    levels must be increasing; errors are the parameter errors measured at those levels (NaN/inf count as
    exceeding); baseline: the error without the fault (the model-structure bias on vehicle data). Returns inf
    when the error stays within the bound over the whole sweep (breakdown point above the largest level tried).
    """
    levels = np.asarray(levels, dtype=float)
    errors = np.asarray(errors, dtype=float)
    if levels.shape != errors.shape or levels.ndim != 1 or levels.size == 0:
        raise RobustnessError(f"levels {levels.shape} and errors {errors.shape} must be equal-length 1-D arrays")
    if np.any(np.diff(levels) <= 0):
        raise RobustnessError("breakdown levels must be strictly increasing")
    exceeded = ~(errors <= baseline + bound)
    return float(levels[np.argmax(exceeded)]) if exceeded.any() else float("inf")


def spread(values: Sequence[float]) -> dict[str, float]:
    """Median and inter-quartile range over seeds; NaN dropped, inf counts (e.g. "no breakdown")."""
    v = np.asarray(values, dtype=float)
    v = v[~np.isnan(v)]
    if v.size == 0:
        return {"median": float("nan"), "q25": float("nan"), "q75": float("nan"), "n": 0}
    if np.isinf(v).any():  # interpolation towards inf is undefined: use order statistics (lower, lower, higher)
        q25, med = np.quantile(v, [0.25, 0.5], method="lower")
        q75 = np.quantile(v, 0.75, method="higher")
    else:
        q25, med, q75 = np.quantile(v, [0.25, 0.5, 0.75])
    return {"median": float(med), "q25": float(q25), "q75": float(q75), "n": int(v.size)}


# ====================================================================================== decision tree (fig. 3.17)
# Figure 3.17 as described in section 3.11: aim (accurate parameters -> errors-in-variables estimators,
# fig. 3.17a; prediction -> output-error estimators, fig. 3.17b), then poor excitation yes/no, then outliers
# yes/no. The figure itself is not reproduced in the text we have; the grouping below follows the section
# titles of chapter 3 (regularized = RR*/R*MKF, wind-up stable = SG*, robust = *M*). "Regularized non-robust
# estimators are not explicitly presented herein" -> that leaf is empty.
DECISION_TREE: dict[tuple[str, bool, bool], tuple[str, ...]] = {
    # (aim, poor_excitation, outliers): recommended estimators
    ("parameters", False, False): ("RIV", "IVKF", "RGTLS"),
    ("parameters", False, True): ("RIVM", "IVMKF"),
    ("parameters", True, False): (),
    ("parameters", True, True): ("RRIVM", "RIVMKF", "SGIVMKF"),
    ("prediction", False, False): ("RLS", "KF"),
    ("prediction", False, True): ("RLM", "MKF"),
    ("prediction", True, False): (),
    ("prediction", True, True): ("RRLM", "RMKF", "SGMKF"),
}
