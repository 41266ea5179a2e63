"""Estimator robustness testbed (issue 8): outliers, poor excitation and drift, swept to breakdown.

A *scenario* is (base trip configuration, fault injection spec, seed). Faults on vehicle trips are injected by
the simulator's sensor layer (``roadload.envs``), so the faults swept here are exactly the ones a user of
``simulate`` gets. For the checks of the text's decision tree (figure 3.17) a small A/B-level layer generates
synthetic regression data in the style of Experiment 3.3 (section 3.5.6) and injects outliers directly into the
measured inputs A and the measured output B.

Metrics per (scenario, estimator, model):
- parameter error SEVN_t = ||X̄_t - X̂_t||² (eq. 3.2) and a scale-free relative error (used for bounds);
- k-step-ahead prediction MEDSE (eq. 5.7) on held-out validation data;
- recovery time after a parameter step;
- wind-up indicators: trace and condition number of the covariance P;
- the empirical breakdown point: the smallest outlier fraction at which the error exceeds a stated bound.

Everything is seeded through ``numpy.random.Generator``. The truth of a trip is read only by the metrics and
the scenario bookkeeping (time of the payload step, where the driver really cruised), never by an estimator.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Any, Sequence

import numpy as np
import numpy.typing as npt

from roadload.fileio import save_figure, write_text
from roadload.tables import format_number, markdown_table
from roadload.estimators.catalog import CATALOG
from roadload.experiments.fleet import TYPICAL_SPEED
from roadload.envs import get_preset
from roadload.envs.sensors import BIAS_REFERENCE
from roadload.envs import simulate
from roadload.road_profiles import RoadProfile, load_profile
from roadload.estimators.evaluation import estimator_settings
from roadload.estimators.knowledge import knowledge_for_preset
from roadload.estimators.models import get_model
from roadload.estimators.pipeline import model_data, run_pipeline
from roadload.estimators.metrics import medse
from roadload.estimators import make_estimator
from roadload.estimators.metrics import sevn as sevn_of
from roadload.estimators import catalog_names
from roadload.sweep import run_sweep


class RobustnessError(ValueError):
    """Bad robustness-testbed input (unknown sweep, infeasible fault spec, malformed arrays); names what."""


# ====================================================================================== synthetic A/B data
@dataclass(frozen=True)
class ABData:
    """A regression problem A X ≈ B with ground truth.

    t [s] (T,), A measured inputs (T×n), B measured output (T,), X_true true parameters X̄_t (T×n),
    A_true / B_true noise- and outlier-free signals (None for vehicle trips), outlier_mask (T,) True where a
    sample carries an injected A/B-level outlier, meta: how it was generated ('event_time' [s] of a parameter
    change, 'stretches' [(t0, t1), ...] [s] of unexcited stretches, when the scenario has them).
    """

    t: np.ndarray
    A: np.ndarray
    B: np.ndarray
    X_true: np.ndarray
    A_true: np.ndarray | None
    B_true: np.ndarray | None
    outlier_mask: np.ndarray
    meta: dict[str, Any] = field(default_factory=dict)

    @property
    def n_params(self) -> int:
        return int(self.A.shape[1])

    def __len__(self) -> int:
        return int(self.t.size)


def _am_sine(t: np.ndarray, f: float) -> np.ndarray:
    """Amplitude-modulated sine sin(2π f t)·sin(2π f t/3.3) of Experiment 3.3."""
    return np.sin(2 * np.pi * t * f) * np.sin(2 * np.pi * t * f / 3.3)


def synthetic_regression(duration: float = 10_000.0, seed: int = 0, *, dt: float = 1.0,
                         x0: npt.ArrayLike = (1.0, 2.0, 3.0),
                         frequencies: Sequence[float] = (0.006, 0.012, 0.014),
                         unexcited: tuple[int, float, float] | None = None,
                         step: tuple[int, float, float] | None = None,
                         ramp: tuple[int, float, float, float] | None = None,
                         input_noise_var: Sequence[float] | float = 0.0,
                         output_noise_var: float = 0.1) -> ABData:
    """Synthetic regression data in the style of Experiment 3.3 (section 3.5.6).

    Column j of Ā is sin(2π f_j t)·sin(2π f_j t/3.3); X̄ starts at ``x0``.
    unexcited = (column, t_start [s], length [s]): the column is 0 (no excitation) in that stretch.
    step = (column, t_step [s], new value): X̄ of that column jumps at t_step.
    ramp = (column, t_start [s], t_end [s], end value): X̄ of that column changes linearly in between.
    input_noise_var: variance of white Gaussian noise on every measured input (scalar or per column);
    output_noise_var: variance of white Gaussian noise on B (0.1 in Experiment 3.3).
    The text's Experiment 3.3 is ``synthetic_regression(unexcited=(1, 1000, 5000), step=(0, 5000, 1.5))``.
    """
    if not (duration > 0 and dt > 0) or duration / dt < 2:
        raise RobustnessError(f"need duration > dt > 0 with at least 2 samples, got duration={duration}, dt={dt}")
    x0 = np.asarray(x0, dtype=float)
    freqs = np.asarray(frequencies, dtype=float)
    n = x0.size
    if freqs.size != n:
        raise RobustnessError(f"x0 has {n} parameters but {freqs.size} input frequencies were given")
    rng = np.random.default_rng(seed)
    t = np.arange(1, int(round(duration / dt)) + 1) * dt
    T = t.size
    A_true = np.column_stack([_am_sine(t, f) for f in freqs])
    if unexcited is not None:
        col, t0, length = unexcited
        _check_col(col, n, "unexcited")
        if length < 0:
            raise RobustnessError(f"unexcited stretch length must be >= 0 s, got {length}")
        A_true[(t >= t0) & (t < t0 + length), col] = 0.0
    X_true = np.tile(x0, (T, 1))
    if step is not None:
        col, ts, value = step
        _check_col(col, n, "step")
        X_true[t >= ts, col] = value
    if ramp is not None:
        col, ta, tb, value = ramp
        _check_col(col, n, "ramp")
        if not tb > ta:
            raise RobustnessError(f"ramp needs t_end > t_start, got {ta}..{tb}")
        start = X_true[:, col].copy()
        frac = np.clip((t - ta) / (tb - ta), 0.0, 1.0)
        X_true[:, col] = start + frac * (value - start)
    B_true = np.einsum("ij,ij->i", A_true, X_true)
    in_var = np.broadcast_to(np.asarray(input_noise_var, dtype=float), (n,))
    if np.any(in_var < 0) or output_noise_var < 0:
        raise RobustnessError("noise variances must be >= 0")
    A = A_true + rng.standard_normal((T, n)) * np.sqrt(in_var)
    B = B_true + rng.standard_normal(T) * np.sqrt(output_noise_var)
    meta = {"generator": "synthetic_regression", "seed": seed, "duration": duration, "dt": dt,
            "unexcited": unexcited, "step": step, "ramp": ramp,
            "input_noise_var": in_var.tolist(), "output_noise_var": output_noise_var}
    return ABData(t, A, B, X_true, A_true, B_true, np.zeros(T, dtype=bool), meta)


def _check_col(col: int, n: int, what: str) -> None:
    if not (0 <= int(col) < n):
        raise RobustnessError(f"{what}: column {col} out of range for {n} parameters")


def _outlier_rows(T: int, fraction: float, pattern: str, burst_length: int, rng: np.random.Generator) -> np.ndarray:
    """Boolean mask with round(fraction·T) corrupted samples, isolated or in bursts of ``burst_length``."""
    k = int(round(fraction * T))
    mask = np.zeros(T, dtype=bool)
    if k == 0:
        return mask
    if pattern == "isolated":
        mask[rng.choice(T, size=k, replace=False)] = True
    elif pattern == "burst":
        if burst_length < 1:
            raise RobustnessError(f"burst_length must be >= 1 sample, got {burst_length}")
        lengths = [burst_length] * (k // burst_length) + ([k % burst_length] if k % burst_length else [])
        # non-overlapping bursts: spread the T-k clean samples randomly over the len(lengths)+1 gaps
        gaps = rng.multinomial(T - k, np.full(len(lengths) + 1, 1.0 / (len(lengths) + 1)))
        pos = 0
        for gap, length in zip(gaps, lengths):
            pos += int(gap)
            mask[pos:pos + length] = True
            pos += length
    else:
        raise RobustnessError(f"unknown outlier pattern {pattern!r}; use 'isolated' or 'burst'")
    return mask


def inject_ab_outliers(data: ABData, fraction: float, *, magnitude: float = 4.0, target: str = "both",
                       pattern: str = "isolated", burst_length: int = 20, seed: int = 0) -> ABData:
    """Add outliers to measured inputs and/or output at A/B level (decision-tree checks only).

    fraction in [0, 0.5]: share of corrupted samples; a corrupted sample gets uniform noise in
    [-magnitude, magnitude]·s added, s the standard deviation of the clean channel (of the measured one when
    the clean one is unknown, as on vehicle trips) (Experiment 3.3 used
    uniform numbers in [-4, 4] on unit-amplitude signals). target: 'input' (one random column of A per
    sample), 'output' (B) or 'both' (each corrupted sample hits A or B with equal probability).
    Vehicle-trip sweeps use the simulator's sensor faults instead.
    """
    if not (0.0 <= fraction <= 0.5):
        raise RobustnessError(f"outlier fraction must be within [0, 0.5], got {fraction}")
    if magnitude < 0:
        raise RobustnessError(f"outlier magnitude must be >= 0, got {magnitude}")
    if target not in ("input", "output", "both"):
        raise RobustnessError(f"unknown outlier target {target!r}; use 'input', 'output' or 'both'")
    rng = np.random.default_rng(seed)
    T, n = data.A.shape
    rows = _outlier_rows(T, fraction, pattern, burst_length, rng)
    A = data.A.copy()
    B = data.B.copy()
    idx = np.flatnonzero(rows)
    hit_output = {"input": np.zeros(idx.size, bool), "output": np.ones(idx.size, bool),
                  "both": rng.random(idx.size) < 0.5}[target]
    u = rng.uniform(-magnitude, magnitude, idx.size)
    b_scale = float(np.std(data.B_true if data.B_true is not None else data.B)) or 1.0
    B[idx[hit_output]] += u[hit_output] * b_scale
    in_rows = idx[~hit_output]
    cols = rng.integers(0, n, in_rows.size)
    a_scale = np.std(data.A_true if data.A_true is not None else data.A, axis=0)
    a_scale[a_scale == 0] = 1.0
    A[in_rows, cols] += u[~hit_output] * a_scale[cols]
    meta = {**data.meta, "outliers": {"fraction": fraction, "magnitude": magnitude, "target": target,
                                      "pattern": pattern, "burst_length": burst_length, "seed": seed}}
    return replace(data, A=A, B=B, outlier_mask=data.outlier_mask | rows, meta=meta)


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

#: outlier targets that are measured inputs (regressor channels) of A
INPUT_TARGETS = frozenset({"input", "both", "accel_x", "vehicle_speed", "steering_wheel_angle"})
ROBUST = frozenset({"RLM", "RRLM", "MKF", "RMKF", "SGMKF", "RIVM", "RRIVM", "IVMKF", "RIVMKF", "SGIVMKF"})
WINDUP_STABLE = frozenset({"RRLM", "RMKF", "SGMKF", "RRIVM", "RIVMKF", "SGIVMKF"})
ERRORS_IN_VARIABLES = frozenset({"RIV", "RIVM", "RRIVM", "IVKF", "IVMKF", "RIVMKF", "SGIVMKF", "RGTLS"})


def recommended(aim: str, poor_excitation: bool, outliers: bool) -> tuple[str, ...]:
    """Estimators figure 3.17 recommends for an aim ('parameters' | 'prediction') and data conditions."""
    key = (aim, bool(poor_excitation), bool(outliers))
    if key not in DECISION_TREE:
        raise RobustnessError(f"unknown aim {aim!r}; use 'parameters' or 'prediction'")
    return DECISION_TREE[key]


# ====================================================================================== sweep specifications
@dataclass(frozen=True)
class SweepSpec:
    """One failure mode swept over ``levels`` for each of its ``variants``.

    parameter/unit: what a level is (e.g. outlier fraction [1], cruise length [s]); breakdown: whether a
    breakdown point over the levels is meaningful (the levels are an outlier fraction or a fault size);
    tree: the figure-3.17 question this failure mode exercises ('outliers' | 'poor_excitation' | 'input_noise')
    or None when the decision tree does not cover it (drift, bias, latency).
    """

    name: str
    parameter: str
    unit: str
    levels: tuple[float, ...]
    variants: tuple[str, ...]
    breakdown: bool = False
    tree: str | None = None

    def __post_init__(self) -> None:
        if not self.levels or np.any(np.diff(self.levels) <= 0):
            raise RobustnessError(f"sweep {self.name!r}: levels must be non-empty and strictly increasing")
        if not self.variants:
            raise RobustnessError(f"sweep {self.name!r}: needs at least one variant")


@dataclass(frozen=True)
class Scenario:
    """A scenario = (base trip config, fault injection spec, seed): backend + sweep/variant/level + seed."""

    backend: str     # 'vehicle' (simulator trip -> chapter-5 pipeline) or 'synthetic' (A/B level)
    sweep: str
    variant: str
    level: float
    seed: int
    duration: float  # [s]


OUTLIER_FRACTIONS = (0.0, 0.01, 0.02, 0.05, 0.1, 0.15, 0.2, 0.3)

# A/B-level sweeps on Experiment-3.3-style data (decision-tree checks, fast tests)
SYNTHETIC_SWEEPS: dict[str, SweepSpec] = {s.name: s for s in (
    SweepSpec("outliers", "outlier fraction", "1", OUTLIER_FRACTIONS,
              ("output/isolated", "output/burst", "input/isolated", "both/isolated"), breakdown=True,
              tree="outliers"),
    SweepSpec("excitation", "unexcited stretch length", "s", (0.0, 500.0, 1000.0, 2000.0, 4000.0),
              ("column2", "column2+step"), tree="poor_excitation"),
    SweepSpec("drift", "relative parameter change", "1", (0.0, 0.25, 0.5, 1.0), ("step", "ramp")),
    SweepSpec("input_noise", "input noise variance", "1", (0.0, 0.005, 0.01, 0.02, 0.05), ("columns2-3",),
              tree="input_noise"),
)}


# Vehicle-trip sweeps: faults injected by the simulator's sensor layer — its effects 'sensor_outliers',
# 'sensor_dropouts', 'poor_excitation', 'payload' and its per-channel SensorSpec (bias, latency, outlier scale) —
# and A/B from the chapter-5 pipeline. Outliers target one channel by zeroing the outlier scale of the others;
# variant '<channel>/x<k>': outlier size k × the channel's outlier scale of the preset (drive torque 80 N m,
# accelerometer 2 m/s², speed 3 m/s, steering 0.3 rad), rate per 100 Hz sample; '<channel>/x<k>/burst': the
# same share of samples hit in bursts of OUTLIER_BURST_LENGTH samples (simulator 'burst_length'). Variants
# 'output/ab' and 'input/ab' put isolated outliers (±10 σ, rate per 10 Hz triggered sample) into B or A after the
# pipeline (the A/B-level layer), to separate the estimators' robustness from what the preprocessing does to
# sensor outliers. Dropout variants 'outputs' | 'inputs' | 'all' are channel groups, a channel name drops that
# channel only. Excitation: 'poor_excitation' with hold_speed, so a stretch really is one constant speed for
# (level × typical motorway speed) m — at least level s, longer where the held speed is below the typical one.
# Bias and latency levels are multiples of the reference bias (0.05 m/s² accelerometer, 5 N m drive torque,
# 0.05 m/s speed) and seconds added to the channel's latency. 'wind': a headwind (against the road's initial
# heading) from calm to level m/s at mid-record, as a step or a RAMP_DURATION ramp ('wind_ramp'); the models
# have no wind term, so the recovery is judged on the prediction from the onset (prediction_recovery_time).
# 'ramps': mass (relative to the preset's), drag area or rolling resistance changed by the relative level at mid-record
# (step or ramp; simulator 'mass_ramp' | 'drag_area_ramp' | 'rolling_resistance_ramp'); recovery time as drift.
VEHICLE_SWEEPS: dict[str, SweepSpec] = {s.name: s for s in (
    SweepSpec("outliers", "outlier rate per sample", "1", OUTLIER_FRACTIONS,
              ("drive_torque/x1", "drive_torque/x10", "accel_x/x1", "vehicle_speed/x1", "steering_wheel_angle/x1",
               "drive_torque/x10/burst", "accel_x/x1/burst", "output/ab", "input/ab"),
              breakdown=True, tree="outliers"),
    SweepSpec("dropouts", "share of samples in NaN dropouts", "1", (0.0, 0.01, 0.05, 0.1, 0.2, 0.3),
              ("outputs", "inputs", "all", "drive_torque", "accel_x"), breakdown=True),
    SweepSpec("excitation", "constant-speed cruise stretch length", "s", (0.0, 60.0, 120.0, 300.0, 600.0),
              ("cruise",), tree="poor_excitation"),
    SweepSpec("drift", "payload step", "kg", (0.0, 100.0, 250.0, 500.0), ("payload/step",)),
    SweepSpec("wind", "final headwind speed", "m/s", (0.0, 3.0, 6.0, 10.0), ("step", "ramp")),
    SweepSpec("ramps", "relative parameter change", "1", (0.0, 0.1, 0.2, 0.4),
              ("mass/step", "mass/ramp", "drag_area/step", "drag_area/ramp", "rolling_resistance/step",
               "rolling_resistance/ramp")),
    SweepSpec("bias", "constant sensor bias (multiples of the reference bias)", "1", (0.0, 1.0, 2.0, 4.0, 10.0),
              ("accel_x", "drive_torque", "vehicle_speed"), breakdown=True),
    SweepSpec("latency", "extra sensor latency", "s", (0.0, 0.05, 0.1, 0.2, 0.5),
              ("drive_torque", "accel_x", "vehicle_speed"), breakdown=True),
)}

#: CLI families (``--sweep``) -> sweeps they run
SWEEP_FAMILIES: dict[str, tuple[str, ...]] = {
    "outliers": ("outliers", "dropouts"),
    "excitation": ("excitation",),
    "drift": ("drift", "ramps", "wind"),
    "bias": ("bias", "latency"),
    "input_noise": ("input_noise",),
}

# ====================================================================================== scenario construction
def _sub_seed(seed: int, *keys: str) -> int:
    """A reproducible child seed for one purpose (e.g. the outlier positions) of a scenario seed."""
    salt = [int.from_bytes(k.encode()[:8].ljust(8, b"\0"), "little") for k in keys]
    return int(np.random.SeedSequence([int(seed), *salt]).generate_state(1)[0])


SYNTHETIC_OUTLIER_MAGNITUDE = 10.0   # uniform in ±10 standard deviations of the clean channel
SYNTHETIC_OUTPUT_NOISE = 0.1         # variance of the output noise (Experiment 3.3)


def build_synthetic(scenario: Scenario) -> ABData:
    """The A/B data of a synthetic scenario; ``meta`` carries 'event_time' [s] and 'stretches' [(t0, t1)] [s].

    outliers: Experiment-3.3 inputs, outliers of magnitude ±10 σ at the level's fraction (variant
    '<target>/<pattern>', bursts of 20 samples); excitation: column 2 unexcited for ``level`` s starting
    at 1000 s (or 20 % of a shorter record) (variant 'column2+step' adds the text's +50 % step of X̄_1
    mid-stretch); drift:
    X̄_1 changes by the relative ``level`` at mid-record as a 'step' or a 'ramp' over 10 % of the record;
    input_noise: white noise of variance level and 2·level on inputs 2 and 3 (eq. 3.46 pattern), output
    noise variance 0.02.
    """
    d, s = scenario.duration, scenario.seed
    meta: dict[str, Any] = {}
    if scenario.sweep == "outliers":
        target, pattern = scenario.variant.split("/")
        base = synthetic_regression(d, s, output_noise_var=SYNTHETIC_OUTPUT_NOISE)
        data = inject_ab_outliers(base, scenario.level, magnitude=SYNTHETIC_OUTLIER_MAGNITUDE, target=target,
                                  pattern=pattern, burst_length=20, seed=_sub_seed(s, "outliers", pattern))
    elif scenario.sweep == "excitation":
        t0 = min(1000.0, 0.2 * d)
        if t0 + scenario.level > 0.8 * d:
            raise RobustnessError(f"unexcited stretch of {scenario.level} s does not fit a {d} s record "
                                  f"(starts at {t0} s; needs 10 % excited record and the 10 % validation "
                                  f"block after it)")
        step = (0, t0 + scenario.level / 2, 1.5) if scenario.variant == "column2+step" else None
        data = synthetic_regression(d, s, unexcited=(1, t0, scenario.level), step=step,
                                    output_noise_var=SYNTHETIC_OUTPUT_NOISE)
        meta = {"stretches": [(t0, t0 + scenario.level)]}
        if step is not None:
            meta["event_time"] = step[1]
    elif scenario.sweep == "drift":
        x1 = 1.0 * (1.0 + scenario.level)
        if scenario.variant == "step":
            data = synthetic_regression(d, s, step=(0, d / 2, x1), output_noise_var=SYNTHETIC_OUTPUT_NOISE)
        else:
            data = synthetic_regression(d, s, ramp=(0, d / 2, 0.6 * d, x1), output_noise_var=SYNTHETIC_OUTPUT_NOISE)
        meta = {"event_time": d / 2}
    elif scenario.sweep == "input_noise":
        data = synthetic_regression(d, s, input_noise_var=(0.0, scenario.level, 2 * scenario.level),
                                    output_noise_var=0.02)
    else:
        raise RobustnessError(f"unknown synthetic sweep {scenario.sweep!r}; known: {sorted(SYNTHETIC_SWEEPS)}")
    return replace(data, meta={**data.meta, **meta, "scenario": scenario.__dict__.copy()})


def synthetic_settings(name: str, n_params: int = 3, output_noise_var: float = SYNTHETIC_OUTPUT_NOISE) -> dict:
    """Estimator settings for the synthetic experiments (sections 3.5.6, 3.6.8, 3.8.6).

    λ = 0.995, κ = 0.1 (Levenberg-Marquardt), instruments A_{t-2}, Q = diag(1e-6, 1e-8, 1e-5) (Exp. 3.6),
    R¹ = the output noise variance, σ̂_0 = its square root, Q̂_0 = the variance. The text gives no P_d for the
    synthetic experiments: P_d = R¹ (1-λ)/E[a²] I with E[a²] = 1/4 for the amplitude-modulated unit sines,
    the steady-state parameter covariance of RLS with the same memory (a choice of this testbed, fixed
    before any sweep was run). RGTLS runs with λ = 0.995 and the online noise covariance estimator (NCE).
    """
    key = name.upper()
    if key == "RGTLS":  # with the PKS-based noise covariance estimator (the variant of [133])
        return dict(n_params=n_params, forgetting=0.995, nce=True)
    if key not in CATALOG:
        raise RobustnessError(f"unknown estimator {name!r}")
    parts = CATALOG[key].parts
    s: dict[str, Any] = dict(n_params=n_params, scale0=float(np.sqrt(output_noise_var)), quantile0=output_noise_var)
    if parts.get("covariance", "forgetting") == "forgetting":   # λ for forgetting, R¹ for the Kalman family
        s["forgetting"] = 0.995
    else:
        s["output_noise"] = output_noise_var
    if parts.get("regularisation", "none") != "none":
        s["kappa"] = 0.1
    if parts.get("instruments", "none") == "delayed":
        s["instrument_delay"] = 2
    if parts.get("covariance") == "kalman":
        s["process_noise"] = [1e-6, 1e-8, 1e-5][:n_params] + [1e-6] * max(0, n_params - 3)
    if parts.get("covariance") == "stenlund_gustafsson":
        s["desired_covariance"] = output_noise_var * (1.0 - 0.995) / 0.25
    return s


# ---------------------------------------------------------------------------------------------- vehicle trips
VEHICLE_PRESET = "gt_rwd"       # the simulator preset of the vehicle sweeps
VEHICLE_ROAD = "hilly"          # seeded road generator (the most common road kind of the fleet benchmark)
EXCITATION_ROAD = "motorway"    # the excitation sweep: long constant-speed stretches happen on the motorway
VEHICLE_MODELS = ("M3", "M4")   # gray-box models of section 5.4
OUTLIER_MAGNITUDES = {"x1": 1.0, "x10": 10.0}  # multiples of the channel's outlier scale
DROPOUT_MEAN_DURATION = 0.5     # s, mean length of one NaN dropout
CRUISE_SHARE = 0.5              # share of the road in cruise stretches in the excitation sweep
MIN_STRETCH = 30.0              # s, shortest true constant-speed run counted as an unexcited stretch
OUTLIER_BURST_LENGTH = 50       # samples (0.5 s at 100 Hz) of one outlier burst ('<channel>/<size>/burst')
EVENT_AT = 0.5                  # share of the record at which a headwind / parameter ramp starts
RAMP_DURATION = 120.0           # s, length of the '.../ramp' variants (steps: 0)


def _road_kind(scenario: Scenario) -> str:
    return EXCITATION_ROAD if scenario.sweep == "excitation" else VEHICLE_ROAD


def event_times(scenario: Scenario) -> tuple[float, float]:
    """(onset, end) [s] of the scheduled change of a 'wind' or 'ramps' scenario: onset at mid-record, end =
    onset + RAMP_DURATION for '.../ramp' variants, = onset for steps."""
    onset = EVENT_AT * scenario.duration
    return onset, onset + (RAMP_DURATION if scenario.variant.endswith("ramp") else 0.0)


def _typical_speed(road: str = VEHICLE_ROAD) -> float:
    """Typical speed [m/s] on a road kind (the fleet benchmark's sizing values)."""
    return float(TYPICAL_SPEED[road])


def _check_vehicle_scenario(scenario: Scenario) -> None:
    sw, var = scenario.sweep, scenario.variant
    if sw not in VEHICLE_SWEEPS:
        raise RobustnessError(f"unknown vehicle sweep {sw!r}; known: {sorted(VEHICLE_SWEEPS)}")
    if var not in VEHICLE_SWEEPS[sw].variants:
        raise RobustnessError(f"vehicle sweep {sw!r} has no variant {var!r}; known: {VEHICLE_SWEEPS[sw].variants}")


def vehicle_effects(scenario: Scenario) -> dict[str, dict[str, Any]]:
    """The simulator effects (sensor faults, scenario options) of a vehicle scenario; level 0 = fault off."""
    _check_vehicle_scenario(scenario)
    sw, var, lv = scenario.sweep, scenario.variant, scenario.level
    if lv == 0 or sw in ("bias", "latency"):
        return {}
    if sw == "outliers":
        if var.endswith("/ab"):
            return {}
        channel, size, *burst = var.split("/")
        if burst:  # level = share of samples hit: bursts start at rate level / burst length
            return {"sensor_outliers": {"rate": lv / OUTLIER_BURST_LENGTH, "magnitude": OUTLIER_MAGNITUDES[size],
                                        "channels": "all", "channel": channel,
                                        "burst_length": float(OUTLIER_BURST_LENGTH)}}
        return {"sensor_outliers": {"rate": lv, "magnitude": OUTLIER_MAGNITUDES[size], "channels": "all"}}
    if sw == "dropouts":   # share of samples ≈ rate [1/h] / 3600 s × mean duration
        groups = {"outputs": {"channels": "outputs"}, "inputs": {"channels": "inputs"}, "all": {"channels": "all"}}
        return {"sensor_dropouts": {"rate": lv * 3600.0 / DROPOUT_MEAN_DURATION,
                                    "mean_duration": DROPOUT_MEAN_DURATION, "mode": "nan",
                                    **groups.get(var, {"channels": "all", "channel": var})}}
    if sw == "excitation":  # hold_speed: one speed over each whole stretch, whatever the speed limits do
        return {"poor_excitation": {"fraction": CRUISE_SHARE, "stretch_length": lv * _typical_speed(EXCITATION_ROAD),
                                    "hold_speed": "yes"}}
    if sw in ("wind", "ramps"):
        onset, end = event_times(scenario)
        timing = {"onset": onset, "ramp": end - onset, "onset_unit": "s"}
        if sw == "wind":   # headwind (against the road's initial heading) rising from calm to lv m/s
            return {"wind_ramp": {**timing, "start_speed": 0.0, "final_speed": lv, "start_direction": np.pi,
                                  "final_direction": np.pi}}
        quantity = var.split("/")[0]
        if quantity == "mass":  # relative to the preset's mass
            return {"mass_ramp": {**timing, "magnitude": lv * get_preset(VEHICLE_PRESET).body.mass}}
        return {f"{quantity}_ramp": {**timing, "magnitude": lv}}
    # drift: the payload jumps to lv at the first stop (min = max clips the random change to lv)
    return {"payload": {"initial_payload": 0.0, "min_payload": lv, "max_payload": lv, "change_std": 1.0}}


def vehicle_sensors(scenario: Scenario):
    """The preset's SensorSpec with the scenario's per-channel changes: outlier scale only on the target
    channel (outliers), added constant bias (bias) or latency (latency)."""
    import copy


    _check_vehicle_scenario(scenario)
    spec = copy.deepcopy(get_preset(VEHICLE_PRESET).sensors)
    channel = scenario.variant.split("/")[0]
    if scenario.sweep == "outliers" and not scenario.variant.endswith("/ab"):
        for name, ch in spec.channels.items():
            if name != channel:
                ch.outlier_scale = 0.0
    elif scenario.sweep == "bias":
        spec.channels[channel].bias += scenario.level * BIAS_REFERENCE[channel]
    elif scenario.sweep == "latency":
        spec.channels[channel].latency += scenario.level
    return spec


def simulate_scenario(scenario: Scenario):
    """The simulated Trip of a vehicle scenario (same road and driver for every level of a seed)."""
    kind = _road_kind(scenario)
    v = _typical_speed(kind)
    length = float(np.round(scenario.duration * v * 1.6 + 2000.0, -2))
    road = load_profile(kind, seed=_sub_seed(scenario.seed, "road") % (2 ** 31), length=length)
    if not isinstance(road, RoadProfile):
        raise RobustnessError(f"road kind {kind!r} loaded a {type(road).__name__}, expected a RoadProfile")
    if scenario.sweep == "drift":  # one stop at about mid-trip: the payload step happens there
        road = replace(road, stops=np.array([0.5 * scenario.duration * v]))
    return simulate(VEHICLE_PRESET, road, vehicle_effects(scenario), vehicle_sensors(scenario), scenario.seed,
                    duration=scenario.duration)


def true_parameters(trip, model: str, t: np.ndarray) -> np.ndarray:
    """X̄_t of M3 (eq. 5.5b: m_V f_r0, m_V, ρ_a/2 A_V c_x) or M4 (eq. 5.6b: + m_V²/c_yW) from a simulated
    trip's truth, interpolated at the times t [s]. f_r1 v and f_r4 v⁴ of eq. 2.10 are not in the models:
    the estimators lump them into the other parameters, which is part of the measured error."""
    tt = trip.true("t")
    m = np.interp(t, tt, trip.true("mass"))
    cols = [m * np.interp(t, tt, trip.true("rolling_resistance_f0")), m,
            0.5 * np.interp(t, tt, trip.true("air_density")) * np.interp(t, tt, trip.true("drag_area"))]
    if model == "M4":
        cols.append(m ** 2 / np.interp(t, tt, trip.true("cornering_stiffness")))
    elif model != "M3":
        raise RobustnessError(f"true parameters are defined for M3 and M4, not {model!r}")
    return np.column_stack(cols)


def _cruise_stretches(trip, min_length: float, max_gap: float = 5.0) -> list[tuple[float, float]]:
    """(t0, t1) [s] of true constant-speed cruising (|dv/dt| < 0.02 m/s², v > 5 m/s; interruptions shorter
    than ``max_gap`` s bridged) lasting >= min_length s."""
    t = trip.true("t")
    flat = (np.abs(trip.true("acceleration")) < 0.02) & (trip.true("speed") > 5.0)
    edges = np.diff(np.r_[0, flat.astype(int), 0])
    runs = list(zip(np.flatnonzero(edges == 1).tolist(), (np.flatnonzero(edges == -1) - 1).tolist()))
    merged: list[list[int]] = []
    for a, b in runs:
        if merged and t[a] - t[merged[-1][1]] <= max_gap:
            merged[-1][1] = b
        else:
            merged.append([a, b])
    return [(float(t[a]), float(t[b])) for a, b in merged if t[b] - t[a] >= min_length]


def vehicle_settings(model: str, name: str, x0: np.ndarray) -> dict[str, Any]:
    """Section 5.5 settings for RLS, RRLM, SGMKF, RGTLS, SGIVMKF (``evaluation.estimator_settings``).

    The text gives no vehicle settings for the other catalog estimators; this testbed derives them from the
    section-5.5 ones by composition: forgetting family (RLM, RIV, RIVM, RRIVM) as RRLM (λ = 0.999, robust scale,
    κ = 1e-5 where regularised, instruments A_{t-4}); Kalman family (KF, MKF, RMKF, IVKF, IVMKF, RIVMKF) as
    SGMKF (R¹ = 0.8, robust scale) with Q = the P_d of section 5.5.3 as random-walk covariance."""

    key = name.upper()
    if key in ("RLS", "RRLM", "SGMKF", "RGTLS", "SGIVMKF"):
        return estimator_settings(model, key, x0)
    if key not in CATALOG:
        raise RobustnessError(f"unknown estimator {name!r}")
    parts = CATALOG[key].parts
    if parts.get("covariance") == "kalman":
        s = estimator_settings(model, "SGMKF", x0)
        s["process_noise"] = s.pop("desired_covariance")
    else:
        s = estimator_settings(model, "RRLM", x0)
        s.pop("regularisation", None)
    s.pop("kappa", None)
    if parts.get("regularisation", "none") != "none":
        s["kappa"] = 1e-5
    if parts.get("instruments", "none") == "delayed":
        s["instrument_delay"] = 4
    if parts.get("psi", "l2") == "l2":
        s.pop("robust_scale", None)
    return s


def build_vehicle(scenario: Scenario) -> list[tuple[str, ABData, Any]]:
    """Simulate the scenario's trip, run the chapter-5 pipeline (preprocessing + trigger) and return, per model
    (M3, M4), the triggered (t, A, B) with the true parameters and the estimator settings (X̂_0 = nominal)."""
    import functools


    trip = simulate_scenario(scenario)
    knowledge = knowledge_for_preset(VEHICLE_PRESET)
    states = run_pipeline(trip, knowledge).stages["states"]
    meta: dict[str, Any] = {"scenario": scenario.__dict__.copy(), "effects": vehicle_effects(scenario)}
    if scenario.sweep == "drift" and scenario.level > 0:
        mass = trip.true("mass")
        changed = np.flatnonzero(np.abs(mass - mass[0]) > 0.5)
        if changed.size:
            meta["event_time"] = float(trip.true("t")[changed[0]])
    if scenario.sweep in ("wind", "ramps") and scenario.level > 0:
        # parameter ramps: recovery counted from the end of the change; wind: the prediction from the onset
        meta["event_time"] = event_times(scenario)[0 if scenario.sweep == "wind" else 1]
    if scenario.sweep == "excitation":  # the same detection at every level (the driver cruises at level 0 too)
        meta["stretches"] = _cruise_stretches(trip, MIN_STRETCH)
        meta["longest_stretch"] = max([b - a for a, b in meta["stretches"]], default=0.0)
    out = []
    n_triggered = int(states["trigger"].to_numpy(dtype=bool).sum())
    for model in VEHICLE_MODELS:
        t, A, B = model_data(states, model)
        if t.size < 100:
            raise RobustnessError(f"{scenario}: only {t.size} triggered samples for {model}")
        X = true_parameters(trip, model, t)
        x0 = get_model(model).nominal_parameters(knowledge.nominal)
        # the pipeline drops triggered rows whose regressors or output are not finite: count them as reported
        data = ABData(t, A, B, X, None, None, np.zeros(t.size, dtype=bool),
                      {**meta, "n_pipeline_dropped": n_triggered - int(t.size)})
        if scenario.sweep == "outliers" and scenario.variant.endswith("/ab"):
            data = inject_ab_outliers(data, scenario.level, magnitude=SYNTHETIC_OUTLIER_MAGNITUDE,
                                      target=scenario.variant.split("/")[0], pattern="isolated",
                                      seed=_sub_seed(scenario.seed, "outliers", model))
        out.append((model, data, functools.partial(vehicle_settings, model, x0=x0)))
    return out


# ====================================================================================== evaluation
def _medse_of_estimate(B: np.ndarray, B_hat: np.ndarray) -> float:
    """Prediction MEDSE (eq. 5.7, library ``medse``); inf when the estimate predicts non-finite values
    (an estimate driven out of range must not vanish from the metric as a skipped sample would)."""

    if not np.all(np.isfinite(B_hat)):
        return float("inf")
    with np.errstate(over="ignore", invalid="ignore"):
        return medse(B, B_hat) if np.isfinite(B).any() else float("nan")


def _run_checkpointed(est, A: np.ndarray, B: np.ndarray, every: int):
    """Run ``est`` over A, B in chunks of ``every`` samples; returns (X, P_diag, full P at each chunk end,
    chunk-end indices, counters). The estimator continues from its state, so the numbers equal one run."""
    T = A.shape[0]
    Xs, Pds, Ps, ends = [], [], [], []
    for start in range(0, T, every):
        stop = min(T, start + every)
        r = est.run(A[start:stop], B[start:stop], store="full")
        Xs.append(r.X)
        Pds.append(r.P_diag)
        Ps.append(est.p[:A.shape[1], :A.shape[1]])  # RGTLS keeps the (n+1)×(n+1) block: parameter part
        ends.append(stop - 1)
    st = est.state
    counters = {"n_skipped": int(st.n_skipped), "n_rolled_back": int(st.n_rolled_back),
                "p_blowup": bool(st.blowup_at >= 0), "p_blowup_at": int(st.blowup_at)}
    return np.vstack(Xs), np.vstack(Pds), np.stack(Ps), np.asarray(ends), counters


def evaluate(data: ABData, estimators: Sequence[str], settings, *, burn_in: float = 0.2,
             validation: float = 0.1, recover_tolerance: float = 0.3, hold: float = 10.0,
             checkpoint_every: int = 50) -> list[dict[str, Any]]:
    """Run each estimator on one scenario's data and measure it against the truth.

    settings(name) -> make_estimator keyword arguments. The last ``validation`` share of the record is held
    out: the estimate at the end of training predicts it k steps ahead (prediction MEDSE, eq. 5.7, against the
    measured output as in section 5.8). Parameter errors (relative error and SEVN, eq. 3.2) are medians over the
    training record after the first ``burn_in`` share. Recovery time (scenarios with meta['event_time']): see
    :func:`step_recovery_time` (tolerance ``recover_tolerance`` of the step, held ``hold`` s). Wind-up indicators:
    trace(P) (every sample) and cond(P) (every ``checkpoint_every`` samples) over the unexcited stretches
    meta['stretches'] if given, else the post-burn-in record; trace_P_growth = the largest ratio of max trace(P)
    in a stretch to trace(P) when that stretch begins.
    """

    T = len(data)
    k = max(1, int(round(validation * T)))
    n_train = T - k
    if n_train < 10:
        raise RobustnessError(f"record of {T} samples too short for a {validation:.0%} validation split")
    t = data.t[:n_train]
    X_true = data.X_true[:n_train]
    post = t >= t[0] + burn_in * (t[-1] - t[0])
    windows = [post]
    if "stretches" in data.meta:
        windows = [(t >= t0) & (t < t1) for t0, t1 in data.meta["stretches"]]
        windows = [w for w in windows if w.any()]
    window = np.any(windows, axis=0) if windows else np.zeros(n_train, dtype=bool)
    rows = []
    for name in estimators:
        est = make_estimator(name, **settings(name))
        X, P_diag, P_ck, ends, counters = _run_checkpointed(est, data.A[:n_train], data.B[:n_train],
                                                            checkpoint_every)
        finite = bool(np.all(np.isfinite(X)))
        rel = relative_parameter_error(X, X_true)
        with np.errstate(over="ignore", invalid="ignore"):
            sevn = sevn_of(X_true, X)
            B_hat = data.A[n_train:] @ X[-1]
        row: dict[str, Any] = {
            "estimator": name,
            "rel_error": float(np.median(rel[post])),
            "rel_error_final": float(rel[-1]),
            "sevn": float(np.median(sevn[post])),
            "medse": _medse_of_estimate(data.B[n_train:], B_hat),
            "finite": finite,
            **counters,
            "n_pipeline_dropped": int(data.meta.get("n_pipeline_dropped", 0)),
        }
        if "longest_stretch" in data.meta:
            row["longest_stretch"] = float(data.meta["longest_stretch"])
        if "event_time" in data.meta:
            row["recovery_time"] = step_recovery_time(t, X, X_true, data.meta["event_time"], recover_tolerance,
                                                      hold)
            row["prediction_recovery_time"] = prediction_recovery_time(
                t, data.A[:n_train], data.B[:n_train], X, data.meta["event_time"], recover_tolerance, hold)
        if window.any():
            wu = windup_indicators(P_diag, window)
            ck = window[ends]
            row["trace_P_max"] = wu["trace_P_max"]
            row["cond_P_max"] = windup_indicators(P_ck, ck)["cond_P_max"] if ck.any() else float("nan")
            growth = []
            for w in windows:
                tr0 = float(np.sum(P_diag[np.argmax(w)]))
                tr_max = windup_indicators(P_diag, w)["trace_P_max"]
                growth.append(tr_max / tr0 if tr0 > 0 else float("inf"))
            row["trace_P_growth"] = float(max(growth))
        rows.append(row)
    return rows


# ====================================================================================== sweeps
DEFAULT_BOUND = 0.1  # breakdown: median relative parameter error 0.1 above its fault-free value
DEFAULT_SEEDS = 20
PARAMETER_ESTIMATORS_EXCLUDED = ("PKS",)  # the PKS is a signal smoother (section 3.9), not a parameter estimator


def default_estimators() -> list[str]:
    """Every catalog estimator that estimates the parameters of A X ≈ B (all but the PKS)."""
    return [n for n in catalog_names() if n not in PARAMETER_ESTIMATORS_EXCLUDED]


def sweep_specs(backend: str) -> dict[str, SweepSpec]:
    """The sweeps of a backend ('synthetic' or 'vehicle')."""
    if backend == "synthetic":
        return SYNTHETIC_SWEEPS
    if backend == "vehicle":
        return VEHICLE_SWEEPS
    raise RobustnessError(f"unknown backend {backend!r}; use 'synthetic' or 'vehicle'")


def scenarios(backend: str, sweep: str, seeds: Sequence[int] | int, duration: float, *,
              variants: Sequence[str] | None = None, levels: Sequence[float] | None = None) -> list[Scenario]:
    """All scenarios of one sweep: variants × levels × seeds (an int n means seeds 0..n-1)."""
    specs = sweep_specs(backend)
    if sweep not in specs:
        raise RobustnessError(f"unknown {backend} sweep {sweep!r}; known: {sorted(specs)}")
    spec = specs[sweep]
    variants = tuple(variants) if variants is not None else spec.variants
    unknown = [v for v in variants if v not in spec.variants]
    if unknown:
        raise RobustnessError(f"sweep {sweep!r} has no variants {unknown}; known: {list(spec.variants)}")
    levels = tuple(float(x) for x in (levels if levels is not None else spec.levels))
    if not levels or np.any(np.diff(levels) <= 0):
        raise RobustnessError("levels must be non-empty and strictly increasing")
    seeds = range(seeds) if isinstance(seeds, (int, np.integer)) else seeds
    if duration <= 0:
        raise RobustnessError(f"duration must be > 0 s, got {duration}")
    return [Scenario(backend, sweep, v, lv, int(s), float(duration)) for v in variants for lv in levels for s in seeds]


def run_scenario(scenario: Scenario, estimators: Sequence[str] | None = None) -> list[dict[str, Any]]:
    """Build one scenario's data and evaluate every estimator on it (one task of a sweep).

    Rows carry the scenario keys (backend, sweep, variant, level, seed, model) and the metrics of
    :func:`evaluate`. Vehicle scenarios give one set of rows per model structure (M3, M4)."""
    estimators = list(estimators) if estimators is not None else default_estimators()
    keys = {"backend": scenario.backend, "sweep": scenario.sweep, "variant": scenario.variant,
            "level": scenario.level, "seed": scenario.seed}
    rows = []
    if scenario.backend == "synthetic":
        data = build_synthetic(scenario)
        for r in evaluate(data, estimators, synthetic_settings):
            rows.append({**keys, "model": "synthetic", **r})
    elif scenario.backend == "vehicle":
        for model, data, settings in build_vehicle(scenario):
            for r in evaluate(data, estimators, settings):
                rows.append({**keys, "model": model, **r})
    else:
        raise RobustnessError(f"unknown backend {scenario.backend!r}")
    return rows


def run_sweep_results(tasks: Sequence[Scenario], estimators: Sequence[str] | None = None, *,
                      scheduler: str | None = None, progress: bool = True, workers: int | None = None):
    """Run scenarios on the shared sweep runner (local processes or a Dask cluster at ``scheduler``).

    Returns (results, failed): one long DataFrame of metric rows, and [(scenario, error text)] for the
    scenarios whose construction or evaluation raised (they are reported, not dropped silently)."""
    import functools

    import pandas as pd


    if estimators is not None:
        known = default_estimators()
        unknown = [e for e in estimators if e not in known]
        if unknown:
            raise RobustnessError(f"unknown estimators {unknown}; known: {known}")
    fn = functools.partial(run_scenario, estimators=list(estimators) if estimators is not None else None)
    outcomes = run_sweep(fn, list(tasks), scheduler=scheduler, progress=progress, workers=workers,
                         description="robustness")
    rows = [row for o in outcomes if o.ok for row in o.value]
    failed = [(o.task, o.error) for o in outcomes if not o.ok]
    return pd.DataFrame(rows), failed


# ====================================================================================== aggregation and report
METRICS = ("rel_error", "excess_error", "sevn", "medse", "recovery_time", "prediction_recovery_time",
           "trace_P_max", "cond_P_max", "trace_P_growth", "longest_stretch")
_KEYS = ["backend", "sweep", "variant", "model", "estimator"]


def aggregate(results):
    """Median and IQR over seeds of every metric per (backend, sweep, variant, level, model, estimator),
    plus fault counters (samples skipped, estimates rolled back, runs with P blow-up, runs with non-finite X̂)."""
    import pandas as pd

    if results.empty:
        raise RobustnessError("no results to aggregate")
    results = with_excess_error(results)
    out = []
    for key, g in results.groupby(_KEYS[:3] + ["level"] + _KEYS[3:], sort=True):
        row = dict(zip(_KEYS[:3] + ["level"] + _KEYS[3:], key))
        row["n_seeds"] = int(g["seed"].nunique())
        for m in METRICS:
            if m in g and g[m].notna().any():
                s = spread(g[m].to_numpy(dtype=float))
                row[m] = s["median"]
                row[f"{m}_q25"] = s["q25"]
                row[f"{m}_q75"] = s["q75"]
        row["n_skipped"] = int(g["n_skipped"].sum())
        row["n_pipeline_dropped"] = int(g["n_pipeline_dropped"].sum()) if "n_pipeline_dropped" in g else 0
        row["n_rolled_back"] = int(g["n_rolled_back"].sum())
        row["runs_p_blowup"] = int(g["p_blowup"].sum())
        row["runs_nonfinite"] = int((~g["finite"].astype(bool)).sum())
        out.append(row)
    return pd.DataFrame(out)


def with_excess_error(results):
    """A copy with 'excess_error': rel_error minus the fault-free rel_error of the same seed (level 0 of the
    same backend, sweep, variant, model, estimator; NaN when level 0 was not swept)."""
    out = results.copy()
    base = out[out["level"] == 0].set_index(_KEYS + ["seed"])["rel_error"]
    base = base[~base.index.duplicated()]
    idx = out.set_index(_KEYS + ["seed"]).index
    out["excess_error"] = out["rel_error"].to_numpy(dtype=float) - base.reindex(idx).to_numpy(dtype=float)
    return out


def breakdown_table(results, bound: float = DEFAULT_BOUND, metric: str = "rel_error"):
    """Per (backend, sweep, variant, model, estimator): the breakdown point of every seed and its median / IQR
    over seeds. A seed breaks down at the smallest level whose ``metric`` exceeds its own fault-free value
    (level 0 of the same seed, when swept) by more than ``bound``; inf = not up to the largest level.

    Measuring the excess over the fault-free error follows the definition (the estimate moves away from the
    solution it gives without outliers, section 3.4) and keeps the bias of the model structure on vehicle
    data (f_r1, f_r4, drive-train model, section 5.4) from counting as breakdown."""
    import pandas as pd

    out = []
    for key, g in results.groupby(_KEYS, sort=True):
        per_seed = []
        for _, gs in g.groupby("seed"):
            gs = gs.sort_values("level")
            lv, err = gs["level"].to_numpy(), gs[metric].to_numpy(dtype=float)
            base = float(err[0]) if lv[0] == 0 and np.isfinite(err[0]) else 0.0
            per_seed.append(breakdown_point(lv, err, bound, base))
        s = spread(per_seed)
        out.append({**dict(zip(_KEYS, key)), "breakdown": s["median"], "breakdown_q25": s["q25"],
                    "breakdown_q75": s["q75"], "n_seeds": s["n"], "bound": bound, "metric": metric})
    return pd.DataFrame(out)


def _score(results, spec: SweepSpec, bound: float):
    """(score table, column, ascending) used to rank estimators for one sweep."""
    top = results[results["level"] == results["level"].max()]
    med = top.groupby(_KEYS)["rel_error"].median().rename("rel_error_at_max").reset_index()
    if spec.breakdown:
        bd = breakdown_table(results, bound)
        table = bd.merge(med, on=_KEYS)
        return table, ["breakdown", "rel_error_at_max"], [False, True]
    if spec.name in ("drift", "ramps"):
        rec = top.groupby(_KEYS)["recovery_time"].median().rename("recovery_time_at_max").reset_index()
        return rec.merge(med, on=_KEYS), ["recovery_time_at_max", "rel_error_at_max"], [True, True]
    if spec.name == "wind":
        rec = (top.groupby(_KEYS)["prediction_recovery_time"].median().rename("prediction_recovery_time_at_max")
               .reset_index())
        return rec.merge(med, on=_KEYS), ["prediction_recovery_time_at_max", "rel_error_at_max"], [True, True]
    if spec.name == "excitation":
        tr = top.groupby(_KEYS)["trace_P_growth"].median().rename("trace_P_growth_at_max").reset_index()
        return med.merge(tr, on=_KEYS), ["rel_error_at_max", "trace_P_growth_at_max"], [True, True]
    return med, ["rel_error_at_max"], [True]


def rank(results, spec: SweepSpec, bound: float = DEFAULT_BOUND):
    """Estimators ranked per (model, variant) of one sweep, best first, with the scores used.

    breakdown sweeps: by breakdown point (higher is better), then error at the largest level; drift: by
    recovery time after the largest change; excitation: by parameter error after the longest unexcited stretch
    (trace(P) growth shown); other sweeps: by parameter error at the largest level."""
    table, cols, asc = _score(results, spec, bound)
    table = table.sort_values(["backend", "sweep", "model", "variant"] + cols,
                              ascending=[True, True, True, True] + asc)
    table["rank"] = table.groupby(["backend", "sweep", "model", "variant"]).cumcount() + 1
    return table


def decision_tree_checks(results, spec: SweepSpec, bound: float = DEFAULT_BOUND) -> list[dict[str, Any]]:
    """Check the measured ranking of one sweep against figure 3.17.

    outliers: the robust estimators (yes-branch) have a higher median breakdown point than the non-robust
    ones; poor_excitation: the regularised / Stenlund-Gustafsson estimators keep trace(P) bounded (median
    growth over the longest stretch) where the others wind up; input_noise: the errors-in-variables estimators
    have a lower parameter error at the largest input noise than the output-error ones. One row per model and
    variant: what the tree expects, the two group medians, and whether the measurement agrees (None: a tie, e.g.
    neither group breaks down)."""
    if spec.tree is None:
        return []
    table, _, _ = _score(results, spec, bound)
    if spec.tree == "outliers":
        group, col, better = ROBUST, "breakdown", "higher"
        expect = "robust (M-) estimators break down at a larger outlier fraction"
    elif spec.tree == "poor_excitation":
        group, col, better = WINDUP_STABLE, "trace_P_growth_at_max", "lower"
        expect = "regularised / Stenlund-Gustafsson estimators keep trace(P) bounded in unexcited stretches"
    else:
        group, col, better = ERRORS_IN_VARIABLES, "rel_error_at_max", "lower"
        expect = "errors-in-variables estimators have a smaller parameter bias under input noise"
    checks = []
    for (model, variant), g in table.groupby(["model", "variant"]):
        ins = g[g["estimator"].isin(group)][col].to_numpy(dtype=float)
        outs = g[~g["estimator"].isin(group)][col].to_numpy(dtype=float)
        if ins.size == 0 or outs.size == 0:
            continue
        a, b = spread(ins)["median"], spread(outs)["median"]
        agrees = None if a == b else (bool(a > b) if better == "higher" else bool(a < b))  # None: a tie
        note = ""
        if spec.tree == "outliers" and variant.split("/")[0] in INPUT_TARGETS:
            note = ("outliers in A are bad leverage points, against which M-estimators are not robust "
                    "(section 3.4.2): the text itself expects no advantage here")
        checks.append({"sweep": spec.name, "model": model, "variant": variant, "expected": expect,
                       "metric": col, "group_median": a, "others_median": b, "agrees": agrees, "note": note})
        checks += _pairwise_checks(spec, model, variant, g.set_index("estimator")[col], note)
    return checks


#: the text's pairwise claims: (sweep tree question, estimator that should be better, the one it beats)
PAIRWISE_CLAIMS = {
    "outliers": [("RLM", "RLS"), ("RRLM", "RLS")],                      # section 3.4 / figure 3.8
    "poor_excitation": [("RRLM", "RLM"), ("SGMKF", "RLM")],             # sections 3.3, 3.5.5, 3.7.4
    "input_noise": [("RIV", "RLS"), ("RIVM", "RLM"), ("RRIVM", "RRLM"), ("IVKF", "KF"), ("IVMKF", "MKF"),
                    ("RIVMKF", "RMKF"), ("SGIVMKF", "SGMKF")],          # section 3.6.8 / figure 3.14
}


def _pairwise_checks(spec: SweepSpec, model: str, variant: str, score, note: str) -> list[dict[str, Any]]:
    """One row per pairwise claim of the text whose two estimators were both run.

    outliers: a larger breakdown point; poor_excitation: trace(P) growth at most half of the unregularised
    estimator's growth above 1 (i.e. g - 1 < (g_RLM - 1)/2), so "bounded" means a clear difference; input
    noise: a smaller parameter error at the largest noise level. Ties (e.g. neither breaks down) give None."""
    rows = []
    for better, worse in PAIRWISE_CLAIMS.get(spec.tree or "", []):
        if better not in score.index or worse not in score.index:
            continue
        a, b = float(score[better]), float(score[worse])
        if spec.tree == "outliers":
            agrees = None if a == b else a > b
            text = f"{worse} breaks down at a lower outlier fraction than {better}"
        elif spec.tree == "poor_excitation":
            agrees = (a - 1.0) < 0.5 * (b - 1.0)
            text = f"{better} bounds the wind-up of trace(P) that {worse} shows"
        else:
            agrees = None if a == b else a < b
            text = f"{better} has a smaller parameter bias than {worse} under input noise"
        rows.append({"sweep": spec.name, "model": model, "variant": variant, "expected": text,
                     "metric": f"{better} vs {worse}", "group_median": a, "others_median": b,
                     "agrees": None if agrees is None else bool(agrees), "note": note})
    return rows


def plot_curves(agg, spec: SweepSpec, path, bound: float = DEFAULT_BOUND) -> None:
    """Breakdown curves: median excess error (relative parameter error above the fault-free one of the same
    seed; IQR band) over the swept level, one line per estimator (solid: robust, dashed: non-robust), one panel
    per (model, variant); the breakdown bound dotted. Clipped to [1e-4, 1e3] for the log axis. Atomic PNG."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    panels = sorted({(m, v) for m, v in zip(agg["model"], agg["variant"])})
    ncol = min(3, len(panels))
    nrow = int(np.ceil(len(panels) / ncol))
    fig, axes = plt.subplots(nrow, ncol, figsize=(5.2 * ncol, 3.8 * nrow), squeeze=False)
    cmap = plt.get_cmap("tab20")
    names = sorted(agg["estimator"].unique())
    for ax, (model, variant) in zip(axes.flat, panels):
        g = agg[(agg["model"] == model) & (agg["variant"] == variant)]
        for i, name in enumerate(names):
            e = g[g["estimator"] == name].sort_values("level")
            if e.empty:
                continue
            e = e[e["level"] > 0]
            if e.empty or "excess_error" not in e:
                continue
            y = np.clip(e["excess_error"].to_numpy(dtype=float), 1e-4, 1e3)
            ax.plot(e["level"], y, marker="os^vD<>ph*"[i % 10], ms=3.5, color=cmap(i % 20), label=name,
                    ls="-" if name in ROBUST else "--", lw=1.2)
            ax.fill_between(e["level"], np.clip(e["excess_error_q25"], 1e-4, 1e3),
                            np.clip(e["excess_error_q75"], 1e-4, 1e3), color=cmap(i % 20), alpha=0.12)
        ax.axhline(bound, color="k", ls=":", lw=1)
        ax.set_yscale("log")
        ax.set_title(f"{spec.name}: {variant} ({model})", fontsize=9)
        ax.set_xlabel(f"{spec.parameter} [{spec.unit}]")
        ax.set_ylabel("rel. parameter error above fault-free [1]")
        ax.grid(alpha=0.3)
    for ax in axes.flat[len(panels):]:
        ax.axis("off")
    axes.flat[0].legend(fontsize=6, ncol=2)
    fig.tight_layout()
    save_figure(fig, path, dpi=110)


def _verdict(agrees: bool | None) -> str:
    return "tie" if agrees is None else ("yes" if agrees else "NO")


def write_report(results, out_dir, bound: float = DEFAULT_BOUND,
                 failed: Sequence[tuple[Any, str]] = ()) -> dict[str, Any]:
    """Tables per sweep (CSV + Markdown), breakdown curves (PNG), rankings and the one-page summary.

    Returns {'rankings': {sweep: DataFrame}, 'checks': [decision-tree check rows], 'files': [paths]}."""
    from pathlib import Path

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    files = []
    write_text(out / "results.csv", results.to_csv(index=False))
    files.append(out / "results.csv")
    rankings, checks = {}, []
    summary = ["# Estimator robustness: summary", "",
               f"Breakdown criterion: the median relative parameter error (RMS over parameters of |X̂-X̄|/|X̄|, "
               f"after burn-in) exceeds its fault-free value (level 0, same seed) by more than {bound:g}. "
               f"Breakdown points are medians [IQR] over seeds; ∞ = no breakdown up to the largest level swept.",
               ""]
    for (backend, sweep), res in results.groupby(["backend", "sweep"], sort=True):
        spec = sweep_specs(backend)[sweep]
        agg = aggregate(res)
        stem = f"{backend}_{sweep}"
        cols = [c for c in ["variant", "model", "level", "estimator", "n_seeds", "rel_error", "rel_error_q25",
                            "rel_error_q75", "excess_error", "sevn", "medse", "recovery_time", "trace_P_max",
                            "cond_P_max",
                            "trace_P_growth", "longest_stretch", "n_skipped", "n_pipeline_dropped", "runs_p_blowup",
                            "runs_nonfinite"] if c in agg]
        write_text(out / f"table_{stem}.csv", agg[cols].to_csv(index=False))
        write_text(out / f"table_{stem}.md", f"# {backend} sweep '{sweep}' ({spec.parameter} "
                           f"[{spec.unit}])\n\n" + markdown_table(agg, cols) + "\n")
        plot_curves(agg, spec, out / f"curves_{stem}.png", bound)
        files += [out / f"table_{stem}.csv", out / f"table_{stem}.md", out / f"curves_{stem}.png"]
        ranking = rank(res, spec, bound)
        rankings[(backend, sweep)] = ranking
        write_text(out / f"ranking_{stem}.csv", ranking.to_csv(index=False))
        files.append(out / f"ranking_{stem}.csv")
        n_seeds = int(res["seed"].nunique())
        summary += [f"## {backend} / {sweep} — {spec.parameter} [{spec.unit}], {n_seeds} seeds", ""]
        score_cols = [c for c in ranking.columns if c.endswith("_at_max") or c.startswith("breakdown")]
        for (model, variant), g in ranking.groupby(["model", "variant"], sort=True):
            best = ", ".join(f"{r.estimator} ({format_number(getattr(r, score_cols[0]))})" for r in g.itertuples())
            summary.append(f"- **{variant}** ({model}), ranked by {score_cols[0]}: {best}")
        c = decision_tree_checks(res, spec, bound)
        checks += [{"backend": backend, **x} for x in c]
        faults = res[~res["finite"].astype(bool)]
        summary.append("")
        dropped = int(res["n_pipeline_dropped"].sum()) if "n_pipeline_dropped" in res else 0
        summary.append(f"Non-finite estimates: {len(faults)} of {len(res)} runs; P blow-up reported in "
                       f"{int(res['p_blowup'].sum())} runs; {int(res['n_skipped'].sum())} non-finite samples "
                       f"skipped by the estimators and {dropped} by the pipeline, all counted.")
        summary.append("")
    summary += ["## Check against the decision tree (figure 3.17)", ""]
    if checks:
        summary.append("| backend | sweep | model | variant | expected | metric | group | others | agrees | note |")
        summary.append("|---|---|---|---|---|---|---|---|---|---|")
        for x in checks:
            summary.append(f"| {x['backend']} | {x['sweep']} | {x['model']} | {x['variant']} | {x['expected']} | "
                           f"{x['metric']} | {format_number(x['group_median'])} | "
                           f"{format_number(x['others_median'])} | "
                           f"{_verdict(x['agrees'])} | {x['note']} |")
    else:
        summary.append("No sweep in this run exercises a question of the decision tree.")
    summary.append("")
    summary.append("Drift, dropouts, bias and latency are not covered by figure 3.17; they are ranked only.")
    if failed:
        summary += ["", f"## Failed scenarios ({len(failed)})", ""]
        summary += [f"- {task}: {err}" for task, err in failed]
    write_text(out / "summary.md", "\n".join(summary) + "\n")
    files.append(out / "summary.md")
    return {"rankings": rankings, "checks": checks, "files": files}
