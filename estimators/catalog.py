"""The named estimators of chapter 3 as compositions of parts, and the chapter-5 settings (section 5.5).

``make_estimator(name, n_params=..., **overrides)`` returns a ready estimator; any part can be overridden,
so variants the catalog lacks (e.g. ``make_estimator('SGIVMKF', n_params=4, regularisation='tikhonov',
kappa=1e-3, psi='myriad', desired_covariance=...)``) need no update code.

Defaults common to all compositions come from section 5.5 where the text gives them: P_0 = 100 I,
λ = 0.999, σ̂_0 = 25, Q̂_0 = 350, σ̂² forgetting 0.995, η = 0.01, κ = 1e-5 (RRLM), R¹ = 0.8 (Kalman family),
instruments A_{t-4}. Q (Kalman) and P_d (Stenlund-Gustafsson) depend on the model and must be given.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from .config import (INSTRUMENT_DELAY, EstimatorConfig, EstimatorConfigError, check_setting_names,
                     estimator_defaults)
from .recursive import RecursiveEstimator
from .rgtls import RecursiveGTLS
from .pks import PolynomialKalmanSmoother


@dataclass(frozen=True)
class CatalogEntry:
    """A thesis name, its algorithm number(s) and the parts it is composed of."""

    name: str
    algorithm: str
    description: str
    parts: dict


_M = dict(psi="huber", robust_scale=True)          # M-estimator weights with the robust scale (Alg. 3.3/3.11)
_LM = dict(regularisation="levenberg_marquardt", kappa=1e-5)
_IV = dict(instruments="delayed", instrument_delay=INSTRUMENT_DELAY)
_KF = dict(covariance="kalman")
_SG = dict(covariance="stenlund_gustafsson")

CATALOG: dict[str, CatalogEntry] = {e.name: e for e in [
    CatalogEntry("RLS", "3.1", "recursive least squares", dict(psi="l2")),
    CatalogEntry("RLM", "3.2/3.3", "recursive M-estimator with robust scale", dict(_M)),
    CatalogEntry("RRLM", "3.4 in 3.3", "recursive regularised M-estimator with robust scale", dict(_M, **_LM)),
    CatalogEntry("KF", "3.13", "Kalman filter (random-walk parameters)", dict(psi="l2", **_KF)),
    CatalogEntry("MKF", "3.14", "M-Kalman filter with robust scale", dict(_M, **_KF)),
    CatalogEntry("RMKF", "3.15", "regularised M-Kalman filter with robust scale", dict(_M, **_KF, **_LM)),
    CatalogEntry("SGMKF", "3.16", "Stenlund-Gustafsson M-Kalman filter with robust scale", dict(_M, **_SG)),
    CatalogEntry("RIV", "3.9", "recursive instrumental variables", dict(psi="l2", **_IV)),
    CatalogEntry("RIVM", "3.10/3.11", "recursive IV M-estimator with robust scale", dict(_M, **_IV)),
    CatalogEntry("RRIVM", "3.12 in 3.11", "recursive regularised IV M-estimator with robust scale",
                 dict(_M, **_IV, **_LM)),
    CatalogEntry("IVKF", "3.17", "IV Kalman filter", dict(psi="l2", **_IV, **_KF)),
    CatalogEntry("IVMKF", "3.18", "IV M-Kalman filter with robust scale", dict(_M, **_IV, **_KF)),
    CatalogEntry("RIVMKF", "3.19", "regularised IV M-Kalman filter with robust scale",
                 dict(_M, **_IV, **_KF, **_LM)),
    CatalogEntry("SGIVMKF", "3.20", "Stenlund-Gustafsson IV M-Kalman filter with robust scale",
                 dict(_M, **_IV, **_SG)),
]}

#: estimators that are their own classes (not compositions of the kernel parts)
SPECIAL = ("RGTLS", "PKS")


def catalog_names() -> list[str]:
    """All names :func:`make_estimator` accepts."""
    return list(CATALOG) + list(SPECIAL)


def make_config(name: str, **overrides: Any) -> EstimatorConfig:
    """The validated :class:`EstimatorConfig` of catalog entry ``name`` with ``overrides`` applied."""
    key = name.upper()
    if key not in CATALOG:
        raise EstimatorConfigError(f"unknown estimator {name!r}; the catalog has {catalog_names()}")
    check_setting_names(overrides)
    if "n_params" not in overrides:
        raise EstimatorConfigError(f"{key}: n_params (number of parameters) is required")
    settings = dict(CATALOG[key].parts)
    settings.update(overrides)
    settings.setdefault("name", key)
    return EstimatorConfig(**settings)


def make_estimator(name: str, **overrides: Any):
    """A recursive estimator by its thesis name (see :data:`CATALOG`, plus 'RGTLS' and 'PKS').

    Example: ``make_estimator("RRLM", n_params=4, forgetting=0.999, kappa=1e-5, psi="huber",
    robust_scale=True)``. Unknown settings or out-of-range values raise EstimatorConfigError."""
    key = name.upper()
    if key == "RGTLS":
        return RecursiveGTLS(**overrides)
    if key == "PKS":
        return PolynomialKalmanSmoother(**overrides)
    return RecursiveEstimator(make_config(name, **overrides))


def chapter5_settings(model: str = "M3") -> dict[str, dict[str, Any]]:
    """Section 5.5 settings of RLS, RRLM, SGMKF, RGTLS and SGIVMKF for model M3 (3 parameters) or M4 (4).

    Returns name -> keyword arguments for :func:`make_estimator` (X̂_0 is vehicle specific: pass ``x0``).
    Units are those of the tractive-force models (B in N)."""
    model = model.upper()
    if model not in ("M3", "M4"):
        raise EstimatorConfigError(f"chapter 5 defines settings for models 'M3' and 'M4', not {model!r}")
    n = 3 if model == "M3" else 4
    pd = [5e-5, 1e-6, 1e-8] + ([1e-6] if n == 4 else [])
    d = estimator_defaults()   # section 5.5's values are the library's defaults; listed here to be seen
    p0 = dict(p0=d["p0"])
    robust = dict(psi="huber", robust_scale=True, **{k: d[k] for k in ("scale0", "quantile0", "scale_forgetting",
                                                                       "learn_rate")})
    return {
        "RLS": dict(n_params=n, forgetting=d["forgetting"], **p0),
        "RRLM": dict(n_params=n, forgetting=d["forgetting"], **_LM, **p0, **robust),
        "SGMKF": dict(n_params=n, output_noise=d["output_noise"], desired_covariance=pd, **p0, **robust),
        "RGTLS": dict(n_params=n, forgetting=d["forgetting"], noise_covariance=1.0, **p0),
        "SGIVMKF": dict(n_params=n, output_noise=d["output_noise"], desired_covariance=pd,
                        instrument_delay=d["instrument_delay"], **p0, **robust),
    }
