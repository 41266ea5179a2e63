"""Influence functions ψ, weights W = ψ(u)/u and cost functions ρ of M-estimators (eq. 3.15-3.17).

``u`` is the standardised output correction ΔB/σ̂ (dimensionless). Every kind has one scalar weight function
(:func:`weight_scalar`, numba-jitted, used by the recursive kernel and by the batch M-estimator) and the
vectorised helpers :func:`weight`, :func:`psi` and :func:`rho` built on it, so each formula exists once.

Kinds and tuning constants (``c1, c2, c3``; unused ones are ignored):

======== ====================================== ==================================== ==================
name     ψ(u)                                    W(u)                                 defaults
======== ====================================== ==================================== ==================
l2       u (3.16b)                               1                                    -
huber    u if |u|<δ else δ sgn u (3.15b)         min(1, δ/|u|)                        δ = 1.345
myriad   β²u/(β²+u²) (3.17b)                     β²/(β²+u²)                           β = 1
cauchy   u/(1+(u/c)²)                            1/(1+(u/c)²)                         c = 2.385
tukey    u(1-(u/c)²)² for |u|<c else 0           (1-(u/c)²)² for |u|<c else 0         c = 4.685
hampel   u; a sgn u; a sgn u (c-|u|)/(c-b); 0    ψ/u                                  a, b, c = 2, 4, 8
l1l2     u/√(1+u²/2)                             1/√(1+u²/2)                          -
l1       sgn u                                   1/max(|u|, 1e-6)                     -
======== ====================================== ==================================== ==================
"""

from __future__ import annotations

import numpy as np
from roadload.jitcache import cached_njit, cached_vectorize

PSI_L2, PSI_HUBER, PSI_MYRIAD, PSI_CAUCHY, PSI_TUKEY, PSI_HAMPEL, PSI_L1L2, PSI_L1 = range(8)

#: name -> (code, default tuning constants c1, c2, c3)
PSI_KINDS: dict[str, tuple[int, tuple[float, float, float]]] = {
    "l2": (PSI_L2, (0.0, 0.0, 0.0)),
    "huber": (PSI_HUBER, (1.345, 0.0, 0.0)),
    "myriad": (PSI_MYRIAD, (1.0, 0.0, 0.0)),
    "cauchy": (PSI_CAUCHY, (2.385, 0.0, 0.0)),
    "tukey": (PSI_TUKEY, (4.685, 0.0, 0.0)),
    "hampel": (PSI_HAMPEL, (2.0, 4.0, 8.0)),
    "l1l2": (PSI_L1L2, (0.0, 0.0, 0.0)),
    "l1": (PSI_L1, (0.0, 0.0, 0.0)),
}
_L1_FLOOR = 1e-6
#: consistency factor of the median absolute deviation as a scale of Gaussian residuals, 1/Φ⁻¹(3/4) (eq. 3.14)
MAD_CONSISTENCY = 1.483


class InfluenceError(ValueError):
    """Unknown influence-function name or invalid tuning constants."""


def psi_code(name: str) -> int:
    """Integer code of the influence function called ``name`` (case-insensitive; 'L1-L2' accepted)."""
    key = name.lower().replace("-", "").replace("_", "")
    if key not in PSI_KINDS:
        raise InfluenceError(f"unknown influence function {name!r}; choose one of {sorted(PSI_KINDS)}")
    return PSI_KINDS[key][0]


def psi_defaults(name: str) -> tuple[float, float, float]:
    """Default tuning constants (c1, c2, c3) of influence function ``name``."""
    psi_code(name)
    return PSI_KINDS[name.lower().replace("-", "").replace("_", "")][1]


def check_psi_params(name: str, params: tuple[float, float, float]) -> None:
    """Raise :class:`InfluenceError` when the tuning constants of ``name`` are out of range."""
    code = psi_code(name)
    c1, c2, c3 = params
    if code in (PSI_HUBER, PSI_MYRIAD, PSI_CAUCHY, PSI_TUKEY) and not (np.isfinite(c1) and c1 > 0):
        raise InfluenceError(f"{name}: tuning constant must be finite and > 0, got {c1}")
    if code == PSI_HAMPEL and not (0 < c1 < c2 < c3 and np.isfinite(c3)):
        raise InfluenceError(f"hampel: need 0 < a < b < c, got a={c1}, b={c2}, c={c3}")


@cached_njit(inline="always")
def weight_scalar(kind: int, u: float, c1: float, c2: float, c3: float) -> float:
    """W = ψ(u)/u for one standardised output correction u (limit value at u = 0)."""
    if kind == PSI_L2:
        return 1.0
    au = abs(u)
    if kind == PSI_HUBER:
        if au < c1:
            return 1.0
        return c1 / au
    if kind == PSI_MYRIAD:
        return c1 * c1 / (c1 * c1 + u * u)
    if kind == PSI_CAUCHY:
        v = u / c1
        return 1.0 / (1.0 + v * v)
    if kind == PSI_TUKEY:
        if au >= c1:
            return 0.0
        v = u / c1
        v = 1.0 - v * v
        return v * v
    if kind == PSI_HAMPEL:
        if au < c1:
            return 1.0
        if au < c2:
            return c1 / au
        if au < c3:
            return c1 * (c3 - au) / ((c3 - c2) * au)
        return 0.0
    if kind == PSI_L1L2:
        return 1.0 / np.sqrt(1.0 + 0.5 * u * u)
    # PSI_L1
    if au < _L1_FLOOR:
        return 1.0 / _L1_FLOOR
    return 1.0 / au


@cached_vectorize(["float64(int64, float64, float64, float64, float64)"])
def _weight_vec(kind, u, c1, c2, c3):
    return weight_scalar(kind, u, c1, c2, c3)


def _resolve(name: str, params: tuple[float, ...] | None) -> tuple[int, float, float, float]:
    code = psi_code(name)
    p = list(psi_defaults(name))
    if params is not None:
        for i, v in enumerate(params):
            p[i] = float(v)
    check_psi_params(name, (p[0], p[1], p[2]))
    return code, p[0], p[1], p[2]


def weight(u: np.ndarray | float, name: str = "huber", params: tuple[float, ...] | None = None) -> np.ndarray:
    """Weight W = ψ(u)/u of influence function ``name`` at standardised corrections ``u`` [-]."""
    code, c1, c2, c3 = _resolve(name, params)
    return _weight_vec(code, np.asarray(u, dtype=float), c1, c2, c3)


def psi(u: np.ndarray | float, name: str = "huber", params: tuple[float, ...] | None = None) -> np.ndarray:
    """Influence function ψ(u) = W(u)·u [-]."""
    u = np.asarray(u, dtype=float)
    return weight(u, name, params) * u


def rho(u: np.ndarray | float, name: str = "huber", params: tuple[float, ...] | None = None) -> np.ndarray:
    """Cost function ρ(u) with ρ(0) = 0 and dρ/du = ψ (eq. 3.15a, 3.16a, 3.17a)."""
    code, c1, c2, c3 = _resolve(name, params)
    u = np.asarray(u, dtype=float)
    au = np.abs(u)
    if code == PSI_L2:
        return 0.5 * u * u
    if code == PSI_HUBER:
        return np.where(au < c1, 0.5 * u * u, c1 * (au - 0.5 * c1))
    if code == PSI_MYRIAD:  # (3.17a): the ln(10)/2 and log10 factors give d rho/du = psi
        return np.log(10.0) / 2.0 * c1 ** 2 * (np.log10(c1 ** 2 + u * u) - np.log10(c1 ** 2))
    if code == PSI_CAUCHY:
        return 0.5 * c1 ** 2 * np.log1p((u / c1) ** 2)
    if code == PSI_TUKEY:
        inner = c1 ** 2 / 6.0 * (1.0 - (1.0 - (u / c1) ** 2) ** 3)
        return np.where(au < c1, inner, c1 ** 2 / 6.0)
    if code == PSI_HAMPEL:
        a, b, c = c1, c2, c3
        r1 = 0.5 * u * u
        r2 = a * au - 0.5 * a * a
        r3 = a * b - 0.5 * a * a + a * (c - b) / 2.0 * (1.0 - ((c - au) / (c - b)) ** 2)
        r4 = a * b - 0.5 * a * a + a * (c - b) / 2.0
        return np.where(au < a, r1, np.where(au < b, r2, np.where(au < c, r3, r4)))
    if code == PSI_L1L2:
        return 2.0 * (np.sqrt(1.0 + 0.5 * u * u) - 1.0)
    return au
