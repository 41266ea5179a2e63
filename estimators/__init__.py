"""roadload.estimators — the recursive and batch estimators of chapter 3 (Rhode 2018), built from parts.

Recursive estimators (one numeric kernel, :mod:`.kernel`, composed by :class:`EstimatorConfig`):

- :func:`make_estimator` (name, n_params=..., **overrides) -> :class:`RecursiveEstimator` (or RGTLS/PKS);
  names in :data:`CATALOG`: RLS, RLM, RRLM, KF, MKF, RMKF, SGMKF, RIV, RIVM, RRIVM, IVKF, IVMKF, RIVMKF,
  SGIVMKF, plus 'RGTLS' and 'PKS'. :func:`make_config` gives the validated composition only.
- :meth:`RecursiveEstimator.update` (a_t, b_t[, instrument]) -> X̂_t; :meth:`RecursiveEstimator.run`
  (A, B) -> :class:`EstimationResult`; :func:`run` (name or config, A, B, **overrides) does both steps;
  :func:`run_many` runs many trips (leading axis) on all cores (worker threads, GIL-free kernel) with
  identical results.
- :func:`chapter5_settings` ('M3' | 'M4'): the section-5.5 settings by estimator name.
- influence functions: :func:`weight`, :func:`psi`, :func:`rho` (kinds in :data:`PSI_KINDS`).

Other estimators and tools:

- :class:`PolynomialKalmanSmoother` (PKS, Algorithm 3.21) and :func:`pks_bank` (several channels, one
  configuration, common delay, derivatives);
- :class:`RecursiveGTLS` (Algorithm 3.8) with the PKS-based noise covariance estimator (eq. 3.43);
- batch references: :func:`least_squares`, :func:`weighted_least_squares`, :func:`m_estimate` (IRLS with
  MAD scale), :func:`total_least_squares` (Alg. 3.5), :func:`generalized_total_least_squares` (Alg. 3.6),
  :func:`least_median_of_squares`, :func:`least_trimmed_squares`;
- metrics (eq. 3.2-3.4): :func:`sevn`, :func:`mse`, :func:`medse`, :func:`nmse`, :func:`nrmse`,
  :func:`residual_correlation`;
- :mod:`.synthetic`: data of the chapter-3 experiments.

Errors: :class:`EstimatorConfigError` (bad composition or setting), :class:`EstimatorInputError` (bad data
shapes); both are ValueError subclasses.
"""

from __future__ import annotations

from .catalog import CATALOG, CatalogEntry, catalog_names, chapter5_settings, make_config, make_estimator
from .config import EstimatorConfig, EstimatorConfigError, setting_names
from .influence import PSI_KINDS, InfluenceError, psi, rho, weight
from .recursive import (EstimationResult, EstimatorInputError, EstimatorState, RecursiveEstimator,
                        run_many)
from .pks import PKSBankResult, PKSDesign, PolynomialKalmanSmoother, pks_bank, shift_matrix
from .rgtls import RecursiveGTLS
from .batch import (BatchInputError, BatchResult, generalized_total_least_squares, least_median_of_squares,
                    least_squares, least_trimmed_squares, m_estimate, mad_scale, total_least_squares,
                    weighted_least_squares)
from .metrics import MetricError, medse, mse, nmse, nrmse, residual_correlation, sevn


def run(estimator, A, B, instruments=None, store: str = "full", **overrides) -> EstimationResult:
    """Run a recursive estimator over a whole record from its initial state.

    ``estimator``: a catalog name (then ``overrides`` are settings; n_params defaults to A's width), an
    :class:`EstimatorConfig`, or an estimator object such as :class:`RecursiveEstimator` or
    :class:`RecursiveGTLS` (continues from its current state)."""
    import numpy as np

    if isinstance(estimator, str) and estimator.upper() == "PKS":
        raise EstimatorConfigError("PKS smooths signals, it has no regressors: use pks_bank(values, ...) or "
                                   "PolynomialKalmanSmoother(...).smooth(B)")
    if isinstance(estimator, str):
        overrides.setdefault("n_params", int(np.shape(A)[1]) if np.ndim(A) == 2 else 0)
        estimator = make_estimator(estimator, **overrides)
    elif overrides:
        raise EstimatorConfigError("settings can only be overridden when the estimator is given by name")
    if isinstance(estimator, EstimatorConfig):
        estimator = RecursiveEstimator(estimator)
    return estimator.run(A, B, instruments=instruments, store=store)


__all__ = [
    "BatchInputError", "BatchResult", "MetricError", "PKSBankResult", "PKSDesign", "PolynomialKalmanSmoother",
    "RecursiveGTLS", "generalized_total_least_squares", "least_median_of_squares", "least_squares",
    "least_trimmed_squares", "m_estimate", "mad_scale", "medse", "mse", "nmse", "nrmse", "pks_bank",
    "residual_correlation", "sevn", "shift_matrix", "total_least_squares", "weighted_least_squares",
    "CATALOG", "CatalogEntry", "EstimationResult", "EstimatorConfig", "EstimatorConfigError",
    "EstimatorInputError", "EstimatorState", "InfluenceError", "PSI_KINDS", "RecursiveEstimator",
    "catalog_names", "chapter5_settings", "make_config", "make_estimator", "psi", "rho", "run", "run_many",
    "setting_names", "weight",
]

# chapter 5: tractive-force model structures, the preprocessing pipeline and its evaluation
from .models import (M0, M3, M4, ModelError, ModelStructure, NominalParameters, Term, get_model,  # noqa: E402
                     model_names, register_model)
from .pipeline import (PipelineError, PipelineResult, PipelineSettings, VehicleKnowledge,  # noqa: E402
                       knowledge_from_spec, model_data, run_pipeline)

__all__ += ["M0", "M3", "M4", "ModelError", "ModelStructure", "NominalParameters", "PipelineError",
            "PipelineResult", "PipelineSettings", "Term", "VehicleKnowledge", "get_model", "knowledge_from_spec",
            "model_data", "model_names", "register_model", "run_pipeline"]
