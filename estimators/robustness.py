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

Everything is seeded through ``numpy.random.Generator``; nothing here reads the truth of a trip except the
metrics.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Any, Sequence

import numpy as np


class RobustnessError(ValueError):
    """Bad robustness-testbed input (unknown sweep, infeasible fault spec, malformed arrays); names what."""


# ====================================================================================== synthetic A/B data
@dataclass(frozen=True)
class ABData:
    """A regression problem A X ≈ B with ground truth.

    t [s] (T,), A measured inputs (T×n), B measured output (T,), X_true true parameters X̄_t (T×n),
    A_true / B_true noise- and outlier-free signals, outlier_mask (T,) True where a sample carries an injected
    outlier (in A or B), meta: how it was generated.
    """

    t: np.ndarray
    A: np.ndarray
    B: np.ndarray
    X_true: np.ndarray
    A_true: np.ndarray
    B_true: np.ndarray
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
                         x0: Sequence[float] = (1.0, 2.0, 3.0),
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
    [-magnitude, magnitude]·s added, s the standard deviation of the clean channel (Experiment 3.3 used
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
    b_scale = float(np.std(data.B_true)) or 1.0
    B[idx[hit_output]] += u[hit_output] * b_scale
    in_rows = idx[~hit_output]
    cols = rng.integers(0, n, in_rows.size)
    a_scale = np.std(data.A_true, axis=0)
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


def breakdown_point(levels: Sequence[float], errors: Sequence[float], bound: float) -> float:
    """Empirical breakdown point: the smallest swept outlier fraction whose error exceeds ``bound``.

    levels must be increasing; errors are the parameter errors measured at those levels (NaN/inf count as
    exceeding). Returns inf when the error stays within the bound over the whole sweep (breakdown point above
    the largest level tried).
    """
    levels = np.asarray(levels, dtype=float)
    errors = np.asarray(errors, dtype=float)
    if levels.shape != errors.shape or levels.ndim != 1 or levels.size == 0:
        raise RobustnessError(f"levels {levels.shape} and errors {errors.shape} must be equal-length 1-D arrays")
    if np.any(np.diff(levels) <= 0):
        raise RobustnessError("breakdown levels must be strictly increasing")
    exceeded = ~(errors <= bound)
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
              ("column2",), tree="poor_excitation"),
    SweepSpec("drift", "relative parameter change", "1", (0.0, 0.25, 0.5, 1.0), ("step", "ramp")),
    SweepSpec("input_noise", "input noise variance", "1", (0.0, 0.005, 0.01, 0.02, 0.05), ("columns2-3",),
              tree="input_noise"),
)}
