"""Synthetic A/B data in the style of Experiment 3.3 and outliers injected into A and B."""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Any, Sequence

import numpy as np
import numpy.typing as npt




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
