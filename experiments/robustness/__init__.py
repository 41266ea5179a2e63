"""Estimator robustness testbed: outliers, poor excitation and drift, swept to breakdown.

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

Modules: ``faults`` (synthetic A/B data, outlier injection), ``metrics``, ``scenarios`` (decision tree, sweep
definitions, scenario construction), ``sweeps`` (running), ``report`` (aggregation, rankings, figures, Markdown).
"""

from .faults import (  # noqa: F401
    ABData,
    RobustnessError,
    inject_ab_outliers,
    synthetic_regression,
)
from .metrics import (  # noqa: F401
    DECISION_TREE,
    breakdown_point,
    excitation_condition,
    prediction_recovery_time,
    recovery_time,
    relative_parameter_error,
    spread,
    step_recovery_time,
    windup_indicators,
)
from .scenarios import (  # noqa: F401
    CRUISE_SHARE,
    DROPOUT_MEAN_DURATION,
    ERRORS_IN_VARIABLES,
    EVENT_AT,
    EXCITATION_ROAD,
    INPUT_TARGETS,
    MIN_STRETCH,
    OUTLIER_BURST_LENGTH,
    OUTLIER_FRACTIONS,
    OUTLIER_MAGNITUDES,
    RAMP_DURATION,
    ROBUST,
    SWEEP_FAMILIES,
    SYNTHETIC_OUTLIER_MAGNITUDE,
    SYNTHETIC_OUTPUT_NOISE,
    SYNTHETIC_SWEEPS,
    Scenario,
    SweepSpec,
    VEHICLE_MODELS,
    VEHICLE_PRESET,
    VEHICLE_ROAD,
    VEHICLE_SWEEPS,
    WINDUP_STABLE,
    build_synthetic,
    build_vehicle,
    event_times,
    recommended,
    simulate_scenario,
    synthetic_settings,
    true_parameters,
    vehicle_effects,
    vehicle_sensors,
    vehicle_settings,
)
from .sweeps import (  # noqa: F401
    DEFAULT_BOUND,
    DEFAULT_SEEDS,
    PARAMETER_ESTIMATORS_EXCLUDED,
    default_estimators,
    evaluate,
    run_scenario,
    run_sweep_results,
    scenarios,
    sweep_specs,
)
from .report import (  # noqa: F401
    METRICS,
    PAIRWISE_CLAIMS,
    aggregate,
    breakdown_table,
    decision_tree_checks,
    plot_curves,
    rank,
    with_excess_error,
    write_report,
)
