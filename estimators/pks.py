"""Polynomial Kalman smoother (PKS, Algorithm 3.21, section 3.9.1) and a bank of PKS for several channels.

The PKS models the last w_l + 1 + w_r samples of a signal as a polynomial p(x) = Σ_k X_k x^k of order n-1 in the
sample position x = 1 … w_l + 1 + w_r and runs RLS with exponential forgetting λ on it: each step shifts the
polynomial by one sample (X' = 𝒜 X, 𝒜_ij = binom(j-1, j-i), P' = 𝒜 P 𝒜ᵀ), then updates with the newest
sample, regressor C = [(w_l+1+w_r)^0 … (w_l+1+w_r)^(n-1)]. The smoothed value of sample t - w_r is
p(w_l + 1) (eq. after 3.52); its derivatives are p', p'', … at the same point (per sample, divided by dt^k
for physical units). The delay is exactly w_r samples for every channel and every frequency.

The update is the recursive kernel of :mod:`.kernel` (transition matrix part, L2 weights, forgetting); a bank
runs every channel through it with the same configuration.
"""

from __future__ import annotations

from dataclasses import dataclass
from math import comb, factorial
from typing import Annotated, Any

import numpy as np
from pydantic import field_validator

from .config import (Count, EstimatorConfig, EstimatorConfigError, Forgetting, Real, _setting, python_scalar,
                     settings_dataclass)
from .recursive import EstimatorInputError, RecursiveEstimator


def shift_matrix(n_params: int) -> np.ndarray:
    """𝒜 (n×n): coefficients of p(x + 1) from those of p(x); 𝒜_ij = binom(j-1, j-i) (1-based), 0 below."""
    F = np.zeros((n_params, n_params))
    for i in range(n_params):
        for j in range(i, n_params):
            F[i, j] = comb(j, j - i)
    return F


@settings_dataclass(frozen=True)
class PKSDesign:
    """Settings of a PKS: n_params = order + 1, forgetting λ, windows w_l, w_r [samples], prior P_0 = p0 I.
    The defaults are the text's experiment-3.7 setting (order 4, λ = 0.9, w_l = w_r = 20)."""

    n_params: Annotated[Count, _setting("polynomial order + 1", ge=1, le=8)] = 5
    forgetting: Forgetting = 0.9
    window_left: Annotated[Count, _setting("window w_l before the smoothed sample", "samples", ge=0)] = 20
    window_right: Annotated[Count, _setting("window w_r after the smoothed sample (the delay)", "samples",
                                            ge=0)] = 20
    p0: Annotated[Real, _setting("prior covariance P_0 = p0 I", gt=0.0)] = 1e4

    _numpy_scalars = field_validator("n_params", "window_left", "window_right", mode="before")(python_scalar)

    @classmethod
    def from_options(cls, window: int | None = None, window_left: int | None = None, window_right: int | None = None,
                     order: int | None = None, n_params: int | None = None, forgetting: float | None = None,
                     p0: float | None = None) -> "PKSDesign":
        """A design from the options of :func:`pks_bank`: ``window`` sets w_l = w_r, ``order`` = n_params - 1; an
        option left at None takes its default (windows and counts are taken as integers, λ and p0 as floats)."""
        if n_params is None and order is not None:
            n_params = int(order) + 1
        elif order is not None and int(order) + 1 != n_params:
            raise EstimatorConfigError(f"order {order} and n_params {n_params} disagree (n_params = order + 1)")
        given = dict(n_params=n_params, window_left=window if window_left is None else window_left,
                     window_right=window if window_right is None else window_right, forgetting=forgetting, p0=p0)
        kinds = dict(n_params=int, window_left=int, window_right=int, forgetting=float, p0=float)
        return cls(**{k: kinds[k](v) for k, v in given.items() if v is not None})

    @property
    def delay(self) -> int:
        """Delay of the smoothed output [samples] (= w_r)."""
        return int(self.window_right)

    @property
    def regressor(self) -> np.ndarray:
        """C = [(w_l+1+w_r)^k], k = 0 … n-1: the newest sample's position in the window."""
        return float(self.window_left + 1 + self.window_right) ** np.arange(self.n_params)

    def evaluation_rows(self, derivatives: int = 0) -> np.ndarray:
        """Rows that map X̂ to p^(j)(w_l + 1), j = 0 … derivatives (per sample^j)."""
        x = float(self.window_left + 1)
        rows = np.zeros((derivatives + 1, self.n_params))
        for j in range(derivatives + 1):
            for k in range(j, self.n_params):
                rows[j, k] = factorial(k) / factorial(k - j) * x ** (k - j)
        return rows

    def config(self) -> EstimatorConfig:
        return EstimatorConfig(n_params=int(self.n_params), name="PKS", psi="l2", covariance="forgetting",
                               forgetting=float(self.forgetting), transition=shift_matrix(int(self.n_params)),
                               p0=float(self.p0))


class PolynomialKalmanSmoother:
    """One PKS (Algorithm 3.21). ``update(b_t)`` returns the smoothed value of sample t - w_r;
    ``smooth(B, dt, derivatives)`` processes a record and returns aligned values and derivatives."""

    def __init__(self, design: PKSDesign | None = None, **settings: Any):
        """``design``, or the settings of a :class:`PKSDesign` (n_params, forgetting, window_left, window_right,
        p0) by name."""
        if design is not None and settings:
            raise EstimatorConfigError("give a PKS design or its settings, not both")
        self.design = design if design is not None else PKSDesign(**settings)
        self._est = RecursiveEstimator(self.design.config())
        self._c = self.design.regressor
        self._rows = self.design.evaluation_rows(0)

    @property
    def delay(self) -> int:
        return self.design.delay

    @property
    def x(self) -> np.ndarray:
        """Polynomial coefficients X̂_t."""
        return self._est.x

    def reset(self) -> None:
        self._est.reset()

    def update(self, b_t: float) -> float:
        """Process one sample; returns B̂_{t - w_r} (a NaN sample is skipped, the polynomial still shifts)."""
        x = self._est.update(self._c, b_t)
        return float(self._rows[0] @ x)

    def run(self, B, instruments=None, store: str = "x"):
        """Run over a record; returns the kernel's EstimationResult (X̂_t are polynomial coefficients)."""
        B = np.asarray(B, dtype=float)
        if B.ndim != 1:
            raise EstimatorInputError(f"PKS input must be one signal (T,), got shape {B.shape}")
        A = np.tile(self._c, (B.shape[0], 1))
        return self._est.run(A, B, store=store)

    def smooth(self, B, dt: float = 1.0, derivatives: int = 0) -> "PKSBankResult":
        """Smoothed B and its derivatives [unit/s^j]; ``value[t]`` estimates sample t - delay."""
        return pks_bank({"signal": B}, dt=dt, derivatives=derivatives, design=self.design)


@dataclass
class PKSBankResult:
    """Output of a PKS bank. ``value[name][t]`` is the smoothed sample t - delay (produced at t); derivative[name]
    its first derivative [unit/s] (None if not requested); derivatives[name] is (T × k) with the 1st … k-th
    derivatives [unit/s^j]; delay [samples] and delay_s [s] are the same for every channel."""

    value: dict[str, np.ndarray]
    derivative: dict[str, np.ndarray] | None
    derivatives: dict[str, np.ndarray]
    delay: int
    delay_s: float
    design: PKSDesign

    def aligned(self, name: str) -> np.ndarray:
        """Smoothed channel shifted back by the delay: element t estimates sample t (last `delay` are NaN)."""
        v = self.value[name]
        out = np.full_like(v, np.nan)
        out[:v.size - self.delay] = v[self.delay:]
        return out


def pks_bank(values, dt: float = 1.0, derivatives: int = 1, *, window: int | None = None,
             window_left: int | None = None, window_right: int | None = None, order: int | None = None,
             n_params: int | None = None, forgetting: float | None = None, p0: float | None = None,
             design: PKSDesign | None = None) -> PKSBankResult:
    """Smooth several channels with one PKS configuration (section 5.3), in parallel.

    values: dict name -> (T,) array (all the same length) or a (T × channels) array (names '0', '1', …).
    dt [s]: sample period (derivatives are divided by dt^j). ``design``, or the options of
    :meth:`PKSDesign.from_options` (window sets w_l = w_r; order = n_params - 1; the rest :class:`PKSDesign`'s
    defaults). NaN samples are skipped (the polynomial shifts on).
    """
    if design is None:
        design = PKSDesign.from_options(window, window_left, window_right, order, n_params, forgetting, p0)
    names, arrays = _channels(values)
    if not (np.isfinite(dt) and dt > 0):
        raise EstimatorInputError(f"dt must be a positive sample period [s], got {dt}")
    if not (isinstance(derivatives, (int, np.integer)) and 0 <= derivatives < design.n_params):
        raise EstimatorInputError(f"derivatives must be an integer in 0..{design.n_params - 1}, got {derivatives!r}")
    T = arrays[0].shape[0]
    A = np.tile(design.regressor, (T, 1))
    rows = design.evaluation_rows(derivatives)
    cfg = design.config()
    # channels one after the other through the kernel (cheap; the parallel path is for long estimator runs)
    est = np.stack([RecursiveEstimator(cfg).run(A, a, store="x").X @ rows.T for a in arrays])
    value = {k: est[i, :, 0].copy() for i, k in enumerate(names)}
    ders = {k: est[i, :, 1:] / dt ** np.arange(1, derivatives + 1) for i, k in enumerate(names)}
    first = {k: ders[k][:, 0].copy() for k in names} if derivatives >= 1 else None
    return PKSBankResult(value, first, ders, design.delay, design.delay * dt, design)


def _channels(values) -> tuple[list[str], list[np.ndarray]]:
    """(names, 1-D float arrays of one length) of a dict of channels or a (T × channels) array."""
    if isinstance(values, dict):
        names = list(values)
        arrays = [np.asarray(values[k], dtype=float) for k in names]
    else:
        arr = np.asarray(values, dtype=float)
        if arr.ndim == 1:
            arr = arr[:, None]
        if arr.ndim != 2:
            raise EstimatorInputError(f"values must be a dict of 1-D arrays or a (T x channels) array, "
                                      f"got shape {arr.shape}")
        names = [str(i) for i in range(arr.shape[1])]
        arrays = [arr[:, i] for i in range(arr.shape[1])]
    if not arrays:
        raise EstimatorInputError("pks_bank needs at least one channel")
    T = arrays[0].shape[0]
    for name, a in zip(names, arrays):
        if a.ndim != 1 or a.shape[0] != T:
            raise EstimatorInputError(f"channel {name!r}: expected shape ({T},), got {a.shape}")
    return names, arrays
