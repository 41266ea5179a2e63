"""Running scenarios: every estimator on one scenario's A/B data, and whole sweeps on the sweep runner."""

from __future__ import annotations

import os

from typing import Any, Sequence

import numpy as np

from roadload.estimators.metrics import medse
from roadload.estimators import make_estimator
from roadload.estimators.metrics import sevn as sevn_of
from roadload.estimators import catalog_names
from roadload.sweep import run_sweep
from .faults import ABData, RobustnessError
from .metrics import prediction_recovery_time, relative_parameter_error, step_recovery_time, windup_indicators
from .scenarios import (SYNTHETIC_SWEEPS, VEHICLE_SWEEPS, Scenario, SweepSpec, build_synthetic, build_vehicle,
                        synthetic_settings)


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
                      scheduler: str | None = None, progress: bool = True, workers: int | None = None,
                      checkpoint: str | os.PathLike | None = None):
    """Run scenarios on the shared sweep runner (local processes or a Dask cluster at ``scheduler``).

    Returns (results, failed): one long DataFrame of metric rows, and [(scenario, error text)] for the
    scenarios whose construction or evaluation raised (they are reported, not dropped silently). ``checkpoint``:
    a folder where every finished scenario is stored at once; a run stopped or killed resumes from it without
    computing those again (:func:`roadload.sweep.run_sweep`)."""
    import functools

    import pandas as pd


    if estimators is not None:
        known = default_estimators()
        unknown = [e for e in estimators if e not in known]
        if unknown:
            raise RobustnessError(f"unknown estimators {unknown}; known: {known}")
    fn = functools.partial(run_scenario, estimators=list(estimators) if estimators is not None else None)
    outcomes = run_sweep(fn, list(tasks), scheduler=scheduler, progress=progress, workers=workers,
                         description="robustness", checkpoint=checkpoint,
                         name=lambda s: f"{s.backend}_{s.sweep}_{s.variant}_{s.level:g}_{s.seed}")
    rows = [row for o in outcomes if o.ok for row in o.value]
    failed = [(o.task, o.error) for o in outcomes if not o.ok]
    return pd.DataFrame(rows), failed
