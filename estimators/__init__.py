"""roadload.estimators — the recursive and batch estimators of chapter 3 (Rhode 2018), built from parts.

Recursive estimators (one numeric kernel, :mod:`.kernel`, composed by :class:`EstimatorConfig`):

- :func:`make_estimator` (name, n_params=..., **overrides) -> :class:`RecursiveEstimator` (or RGTLS/PKS);
  names in :data:`CATALOG`: RLS, RLM, RRLM, KF, MKF, RMKF, SGMKF, RIV, RIVM, RRIVM, IVKF, IVMKF, RIVMKF,
  SGIVMKF, plus 'RGTLS' and 'PKS'. :func:`make_config` gives the validated composition only.
- :meth:`RecursiveEstimator.update` (a_t, b_t[, instrument]) -> X̂_t; :meth:`RecursiveEstimator.run`
  (A, B) -> :class:`EstimationResult`; :func:`run` (name or config, A, B, **overrides) does both steps;
  :func:`run_many` runs many trips (leading axis) in parallel with identical results.
- :func:`chapter5_settings` ('M3' | 'M4'): the section-5.5 settings by estimator name.
- influence functions: :func:`weight`, :func:`psi`, :func:`rho` (kinds in :data:`PSI_KINDS`).

Errors: :class:`EstimatorConfigError` (bad composition or setting), :class:`EstimatorInputError` (bad data
shapes); both are ValueError subclasses.
"""

from __future__ import annotations

from .catalog import CATALOG, CatalogEntry, catalog_names, chapter5_settings, make_config, make_estimator
from .config import EstimatorConfig, EstimatorConfigError, setting_names
from .influence import PSI_KINDS, InfluenceError, psi, rho, weight
from .recursive import (EstimationResult, EstimatorInputError, EstimatorState, RecursiveEstimator,
                        run_many)


def run(estimator, A, B, instruments=None, store: str = "full", **overrides) -> EstimationResult:
    """Run a recursive estimator over a whole record from its initial state.

    ``estimator``: a catalog name (then ``overrides`` are settings; n_params defaults to A's width), an
    :class:`EstimatorConfig`, or a :class:`RecursiveEstimator` (continues from its current state)."""
    import numpy as np

    if isinstance(estimator, str):
        overrides.setdefault("n_params", int(np.shape(A)[1]) if np.ndim(A) == 2 else 0)
        estimator = make_estimator(estimator, **overrides)
    elif overrides:
        raise EstimatorConfigError("settings can only be overridden when the estimator is given by name")
    if isinstance(estimator, EstimatorConfig):
        estimator = RecursiveEstimator(estimator)
    return estimator.run(A, B, instruments=instruments, store=store)


__all__ = [
    "CATALOG", "CatalogEntry", "EstimationResult", "EstimatorConfig", "EstimatorConfigError",
    "EstimatorInputError", "EstimatorState", "InfluenceError", "PSI_KINDS", "RecursiveEstimator",
    "catalog_names", "chapter5_settings", "make_config", "make_estimator", "psi", "rho", "run", "run_many",
    "setting_names", "weight",
]
