"""Synthetic data of the chapter-3 experiments (reproductions and tests share these generators).

- :func:`straight_line` — experiments 3.1/3.2: seven points on B = 3 A with Gaussian output noise, optionally an
  output outlier in B_2, a bad leverage point A_4 or a good leverage point A_7 (figures 3.4, 3.6);
- :func:`linear_miso` — section 3.5.6 and its variants (experiments 3.3, 3.4, 3.6, 3.7): three sine-product
  inputs, A_2 unexcited 1000-6000 s, a step of X̄_1 at 5000 s, input/output noise, 5 % outliers uniform in
  [-4, 4] replacing entries of A and B, optionally X̄_3 a random walk.

All randomness comes from the ``seed`` (an int or a numpy Generator).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

STRAIGHT_LINE_CASES = ("clean", "outlier", "bad_leverage", "good_leverage")


def straight_line(case: str = "clean", seed: int | np.random.Generator = 0, noise_std: float = 1.0,
                  outlier_shift: float = 25.0, bad_leverage_at: float = 15.0,
                  good_leverage_at: float = 20.0) -> tuple[np.ndarray, np.ndarray, float]:
    """A (7×1), B (7,), X̄ = 3. 'outlier': B_2 += outlier_shift; 'bad_leverage': A_4 moved to
    ``bad_leverage_at`` (B_4 kept); 'good_leverage': A_7 moved to ``good_leverage_at`` on the line."""
    if case not in STRAIGHT_LINE_CASES:
        raise ValueError(f"unknown case {case!r}; choose one of {STRAIGHT_LINE_CASES}")
    rng = np.random.default_rng(seed)
    x_true = 3.0
    A = np.arange(1.0, 8.0)
    noise = rng.normal(0.0, noise_std, 7)
    B = x_true * A + noise
    if case == "outlier":
        B[1] += outlier_shift
    elif case == "bad_leverage":
        A[3] = bad_leverage_at
    elif case == "good_leverage":
        A[6] = good_leverage_at
        B[6] = x_true * A[6] + noise[6]
    return A[:, None], B, x_true


@dataclass
class MisoData:
    """t [s] (1 … m), measured A (m×3) and B (m,), noise-free Ā, B̄, true X̄_t (m×3), outlier masks."""

    t: np.ndarray
    A: np.ndarray
    B: np.ndarray
    A_true: np.ndarray
    B_true: np.ndarray
    X_true: np.ndarray
    outlier_A: np.ndarray
    outlier_B: np.ndarray

    @property
    def any_outlier(self) -> np.ndarray:
        """Rows with an outlier in A or B."""
        return self.outlier_B | np.any(self.outlier_A, axis=1)


def _prod_sine(t: np.ndarray, f: float) -> np.ndarray:
    return np.sin(2 * np.pi * t * f) * np.sin(2 * np.pi * t * f / 3.3)


def linear_miso(seed: int | np.random.Generator = 0, m: int = 10_000, input_noise_var=(0.0, 0.0, 0.0),
                output_noise_var: float = 0.1, outlier_fraction: float = 0.05, outlier_range: float = 4.0,
                random_walk_std: float | None = None, step_at: float = 5000.0,
                outliers_in_unexcited: bool = True) -> MisoData:
    """Section 3.5.6: Ā_1 = s(0.006), Ā_2 = s(0.012) for t < 1000, 0 for 1000 ≤ t < 6000, s(0.012) of
    t - 5000 after, Ā_3 = s(0.014), with s(f) = sin(2π t f) sin(2π t f / 3.3); X̄ = [1 2 3], X̄_1 = 1.5 from
    ``step_at``; B̄ = Σ Ā_j X̄_j. Noise variances: ``input_noise_var`` (A columns), ``output_noise_var`` (B)
    (experiment 3.4: [0 0.005 0.01] and 0.02). Each column of A and B independently gets
    ``outlier_fraction`` of its entries replaced by U(-outlier_range, outlier_range). With
    ``random_walk_std`` X̄_3 = 3 + cumulative N(0, std²) (experiment 3.6). The text says both that A_2
    "remains constant" from 1000 s to 6000 s and that all signals contain outliers; with
    ``outliers_in_unexcited=False`` A_2 gets no outliers in that interval (its noise, if any, stays)."""
    rng = np.random.default_rng(seed)
    t = np.arange(1, m + 1, dtype=float)
    a2 = np.where(t < 1000, _prod_sine(t, 0.012), 0.0)
    a2 = np.where(t >= 6000, _prod_sine(t - 5000, 0.012), a2)
    A_true = np.column_stack([_prod_sine(t, 0.006), a2, _prod_sine(t, 0.014)])
    X_true = np.tile([1.0, 2.0, 3.0], (m, 1))
    X_true[t >= step_at, 0] = 1.5
    if random_walk_std is not None:
        steps = rng.normal(0.0, random_walk_std, m)
        steps[0] = 0.0
        X_true[:, 2] = 3.0 + np.cumsum(steps)
    B_true = np.sum(A_true * X_true, axis=1)
    in_var = np.broadcast_to(np.asarray(input_noise_var, dtype=float), (3,))
    A = A_true + rng.normal(size=(m, 3)) * np.sqrt(in_var)
    B = B_true + rng.normal(0.0, np.sqrt(output_noise_var), m)
    out_A = rng.random((m, 3)) < outlier_fraction
    if not outliers_in_unexcited:
        out_A[(t >= 1000) & (t < 6000), 1] = False
    out_B = rng.random(m) < outlier_fraction
    A[out_A] = rng.uniform(-outlier_range, outlier_range, out_A.sum())
    B[out_B] = rng.uniform(-outlier_range, outlier_range, out_B.sum())
    return MisoData(t, A, B, A_true, B_true, X_true, out_A, out_B)
