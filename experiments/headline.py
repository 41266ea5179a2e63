"""The headline comparison and the sensitivity map of the controllers: tasks, runs on the sweep runner, tables, figures.

``headline_tasks`` / ``sensitivity_tasks`` build :class:`~roadload.experiments.controller_comparison.PairedTask`
lists; :func:`run_paired` runs them through :func:`roadload.sweep.run_sweep` (local processes or Dask) and
writes ``runs.json`` (every closed-loop run), ``summary.csv`` / ``summary.md`` (paired differences with 1-sigma
resolution and 95 % CI) and PNG figures. Sensitivity: energy penalty at equal time of a force model with a
deliberate error (:class:`roadload.controllers.force_model.ErroredForceModel`) against the oracle.
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from roadload.experiments.controller_comparison import (VEHICLE_CASES, PairedTask, fastsim_per_seed,
                                                        format_difference,
                                                        other_metric_results, paired_summary, run_paired_task)
from dataclasses import replace

from roadload.controllers.drive import drive
from roadload.road_profiles import long_grades
from roadload.tables import markdown_table
from roadload.units import G
from roadload.fileio import write_text
from roadload.sweep import read_unit, run_sweep
from roadload.fileio import save_figure

SENSITIVITY_ERRORS: dict[str, tuple[float, ...]] = {
    "mass": (-0.2, 0.2), "rolling": (-0.5, 0.5), "drag_area": (-0.3, 0.3), "grade_bias": (-0.005, 0.005),
    "drivetrain_loss": (-0.3, 0.3)}
JOINT_ERROR = {"mass": 0.2, "rolling": 0.5, "drag_area": -0.3, "grade_bias": 0.005, "drivetrain_loss": 0.3}


def _spec(errors: dict[str, float]) -> str:
    return "wrong:" + ",".join(f"{k}={v:g}" for k, v in errors.items())


def sensitivity_models() -> tuple[str, ...]:
    """'wrong:<error>=<value>' force models: each error alone at both signs, and all jointly (JOINT_ERROR)."""
    one = [_spec({k: v}) for k, vals in SENSITIVITY_ERRORS.items() for v in vals]
    return ("oracle", *one, _spec(JOINT_ERROR))


QUICK = {"max_search_runs": 2, "weight_factors": ()}  # smoke runs: 2 oracle runs, 1 run per other model


def headline_tasks(cases: list[str], roads: dict[str, list[str]], seeds: int, conditions: list[str] | None = None,
                   human: bool = True, quick: bool = False, first_seed: int = 0,
                   search_runs: int | None = None, weight_factors: tuple[float, ...] | None = None,
                   truck_warmup: float = 0.0, metric: str = "net", car_warmup: float = 0.0,
                   knob: str = "lambda", time_factors: tuple[float, ...] | None = None,
                   terminal_value: str = "source", schedule_gain: float | None = None,
                   schedule_pilot: bool = False, multistart_period: float | None = None,
                   gear_command: bool = False, model_search_runs: int = 0,
                   warmup_driver: str = "mpc", force_models: tuple[str, ...] | None = None,
                   optimum: bool = False, fastsim: bool = False) -> list[PairedTask]:
    """One task per (case, road, condition, seed); roads: {case: [road, ...]}; search_runs / weight_factors
    override :class:`PairedTask`'s (fewer runs per seed on a loaded machine); truck_warmup [m]: warm-up before
    the trucks' measured segment."""
    conds = conditions or ["nominal"]
    extra: dict = dict(QUICK) if quick else {}
    extra.update(metric=metric, knob=knob, terminal_value=terminal_value, schedule_pilot=schedule_pilot,
                 multistart_period=multistart_period, gear_command=gear_command,
                 model_search_runs=model_search_runs, warmup_driver=warmup_driver, optimum=optimum)
    if force_models is not None:
        extra["force_models"] = force_models
    if schedule_gain is not None:
        extra["schedule_gain"] = schedule_gain
    if time_factors is not None:
        extra["time_factors"] = time_factors
    if search_runs is not None:
        extra["max_search_runs"] = search_runs
    if weight_factors is not None:
        extra["weight_factors"] = weight_factors
    # seed-major: a sweep that is stopped early has the same seeds for every case
    return [PairedTask(case, road, seed, condition=c, human=human,
                       warmup=truck_warmup if VEHICLE_CASES[case].truck else car_warmup,
                       fastsim=fastsim and not VEHICLE_CASES[case].truck, **extra)
            for seed in range(first_seed, first_seed + seeds)
            for case in cases for road in roads[case] for c in (conds if case == "car" else ["nominal"])]


def sensitivity_tasks(cases: dict[str, str], seeds: int, quick: bool = False, first_seed: int = 0
                      ) -> list[PairedTask]:
    """cases: {vehicle case: road}; each wrong model at the oracle's matched lambda only (the joint fit takes
    slope and curvature from the oracle's search runs)."""
    models = ("oracle", "wrong:mass=0.2") if quick else sensitivity_models()
    return [PairedTask(case, road, seed, force_models=models, weight_factors=(),
                       max_search_runs=2 if quick else PairedTask.max_search_runs)
            for case, road in cases.items() for seed in range(first_seed, first_seed + seeds)]


def run_paired(tasks: list[PairedTask], out: Path, scheduler: str | None = None, workers: int | None = None,
               description: str = "paired comparison", merge: list[Path] | None = None
               ) -> tuple[pd.DataFrame, list[str]]:
    """Run the tasks on the sweep runner, write runs.json and summary.csv/.md; returns (summary, failures).

    Every finished task is stored at once in ``out/tasks/`` (a checkpointed sweep, :mod:`roadload.sweep`): a run
    that is stopped or killed keeps its finished seeds, and running the same command again computes only the
    rest (the tables equal those of an uninterrupted run). merge: runs.json files of earlier runs (other seeds),
    or their tasks/ folders, summarised together with these."""
    out.mkdir(parents=True, exist_ok=True)
    outcomes = run_sweep(run_paired_task, tasks, scheduler=scheduler, workers=workers, description=description,
                         checkpoint=out / "tasks", name=task_name)
    results = [o.value for o in outcomes if o.ok]
    for path in merge or []:
        results += load_stored(Path(path)) if Path(path).is_dir() else json.loads(Path(path).read_text())
    failures = [f"{o.task.case}/{o.task.road}/{o.task.condition}/seed {o.task.seed}: "
                f"{str(o.error).strip().splitlines()[0] if o.error else o.error}" for o in outcomes if not o.ok]
    write_text(out / "runs.json", json.dumps(results, default=_json_default, indent=1))
    summary = paired_summary(results) if results else pd.DataFrame()
    write_text(out / "summary.csv", summary.to_csv(index=False))
    other = other_metric_results(results)  # the same runs with the other metric (before/after resolution)
    write_text(out / "summary_other_metric.csv", (paired_summary(other) if other else pd.DataFrame()).to_csv(
        index=False))
    per_seed, totals = fastsim_per_seed(results)
    if len(per_seed):  # the FASTSim cross-check: the three scorings of the same runs, per seed and as gaps
        write_text(out / "fastsim_per_seed.csv", per_seed.to_csv(index=False))
        write_text(out / "fastsim_gaps.csv", totals.to_csv(index=False))
    return summary, failures


def task_name(task: PairedTask) -> str:
    """Readable prefix of a task's stored result: <case>_<road>_<condition>_<seed>."""
    return f"{task.case}_{task.road}_{task.condition}_{task.seed}"


def load_stored(folder: Path) -> list[dict[str, Any]]:
    """The per-task results stored in a run's tasks/ folder (checkpoint unit files; plain result files of older
    runs too). A file that is corrupt or not a result is refused with its name, never silently summarised."""
    out = []
    for p in sorted(Path(folder).glob("*.json")):
        value, problem = read_unit(p)
        if problem is None:
            out.append(value)
            continue
        try:
            doc = json.loads(p.read_text())
        except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
            raise ValueError(f"{p}: not a stored result ({problem}; {exc})") from None
        if not (isinstance(doc, dict) and "format" not in doc and "task" in doc):
            raise ValueError(f"{p}: not a stored result ({problem})")
        out.append(doc)
    return out


def _json_default(x: Any):
    if isinstance(x, (np.floating, np.integer)):
        return x.item()
    if isinstance(x, np.bool_):
        return bool(x)
    return str(x)


def headline_markdown(summary: pd.DataFrame, failures: list[str]) -> str:
    """The headline table: each MPC force model against the oracle and against cruise control at equal time."""
    rows = []
    for _, r in summary.iterrows():
        reference = r.force_model in ("oracle", "cruise control")
        rows.append({"vehicle": r.vehicle, "road": r.road, "condition": r.condition, "MPC force model": r.force_model,
                     "seeds": r.seeds,
                     "vs oracle MPC": "-" if reference else format_difference(
                         r.vs_oracle_pct, r.resolution_1sigma_pct, r.ci95_lo_pct, r.ci95_hi_pct),
                     "vs cruise control": "-" if r.force_model == "cruise control" else format_difference(
                         r.vs_cruise_pct, r.vs_cruise_1sigma_pct, r.vs_cruise_ci95_lo, r.vs_cruise_ci95_hi),
                     "nearest run |dT| [%]": round(float(r.nearest_run_time_error_pct_median), 3),
                     "fit residual [%]": round(float(r.fit_residual_std_pct), 3)})
        if "vs_optimum_pct" in summary:
            rows[-1]["vs the optimum"] = format_difference(r.vs_optimum_pct, r.vs_optimum_1sigma_pct,
                                                           r.vs_optimum_ci95_lo, r.vs_optimum_ci95_hi)
        for prefix, column in (("fastsim_efficiency_driving", "FASTSim's efficiency while driving: vs cruise control"),
                               ("fastsim_efficiency", "roadload's wheel power, FASTSim's efficiency: vs cruise "
                                                      "control"), ("fastsim", "FASTSim: vs cruise control")):
            if f"{prefix}_vs_cruise_pct" in summary:
                rows[-1][column] = format_difference(*(r[f"{prefix}_vs_cruise_{k}"] for k in (
                    "pct", "1sigma_pct", "ci95_lo", "ci95_hi")))
    md = ["Energy at the source at exactly the cruise-control trip time (joint local fit over >= 3 time weights "
          "per model), paired per seed (same road, seed and plant for every force model); mean [95 % CI] "
          "(1σ = standard error of the paired mean = the resolution). 'not resolved': the CI contains 0.", "",
          markdown_table(pd.DataFrame(rows))]
    if failures:
        md += ["", "Failed tasks:", ""] + [f"- {f}" for f in failures]
    return "\n".join(md) + "\n"


def sensitivity_table(summary: pd.DataFrame) -> pd.DataFrame:
    """Sensitivity rows: vehicle, parameter, error, penalty vs oracle [%] with 1-sigma and CI."""
    rows = []
    for _, r in summary.iterrows():
        if not str(r.force_model).startswith("wrong:"):
            continue
        errs = dict(kv.split("=") for kv in str(r.force_model)[6:].split(","))
        param = "joint" if len(errs) > 1 else next(iter(errs))
        value = float("nan") if len(errs) > 1 else float(next(iter(errs.values())))
        rows.append({"vehicle": r.vehicle, "road": r.road, "parameter": param, "error": value,
                     "model": r.force_model, "seeds": r.seeds, "penalty_pct": r.vs_oracle_pct,
                     "resolution_1sigma_pct": r.resolution_1sigma_pct, "ci95_lo_pct": r.ci95_lo_pct,
                     "ci95_hi_pct": r.ci95_hi_pct,
                     "result": format_difference(r.vs_oracle_pct, r.resolution_1sigma_pct, r.ci95_lo_pct,
                                                 r.ci95_hi_pct)})
    return pd.DataFrame(rows)


def sensitivity_figure(table: pd.DataFrame, path: Path) -> Path:
    """Bar chart per vehicle: penalty vs oracle [%] with 95 % CI per (parameter, error sign)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    vehicles = list(dict.fromkeys(table.vehicle))
    fig, axes = plt.subplots(1, len(vehicles), figsize=(6.5 * len(vehicles), 4.2), squeeze=False)
    for ax, veh in zip(axes[0], vehicles):
        t = table[table.vehicle == veh].reset_index(drop=True)
        labels = [("joint" if p == "joint" else f"{p} {e:+g}") + f" (n={n})"
                  for p, e, n in zip(t.parameter, t.error, t.seeds)]
        y = t.penalty_pct.to_numpy(float)
        err = np.vstack([y - t.ci95_lo_pct.to_numpy(float), t.ci95_hi_pct.to_numpy(float) - y])
        colors = ["tab:red" if (lo > 0 or hi < 0) else "tab:gray" for lo, hi in zip(t.ci95_lo_pct, t.ci95_hi_pct)]
        ax.barh(range(len(t)), y, xerr=np.nan_to_num(err), color=colors, capsize=3)
        ax.set_yticks(range(len(t)), labels)
        ax.axvline(0.0, color="k", lw=0.8)
        ax.set_xlabel("energy penalty vs oracle MPC at equal time [%] (95 % CI)")
        ax.set_title(f"{veh} ({t.road.iloc[0] if len(t) else ''}; red: CI excludes 0; n=1: no CI)")
        ax.invert_yaxis()
    fig.tight_layout()
    return save_figure(fig, path, dpi=120)


def headline_figure(summary: pd.DataFrame, path: Path) -> Path:
    """Per (vehicle, road): abc / online MPC vs the oracle [%] with 95 % CI."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    s = summary[summary.force_model.isin(["abc", "online"])].reset_index(drop=True)
    labels = [f"{v} {r} {c} {m}" for v, r, c, m in zip(s.vehicle, s.road, s.condition, s.force_model)]
    y = s.vs_oracle_pct.to_numpy(float)
    err = np.vstack([y - s.ci95_lo_pct.to_numpy(float), s.ci95_hi_pct.to_numpy(float) - y])
    fig, ax = plt.subplots(figsize=(8, 0.45 * len(s) + 1.5))
    ax.barh(range(len(s)), y, xerr=np.nan_to_num(err), capsize=3,
            color=["tab:blue" if m == "online" else "tab:orange" for m in s.force_model])
    ax.set_yticks(range(len(s)), labels)
    ax.axvline(0, color="k", lw=0.8)
    ax.set_xlabel("MPC energy vs oracle MPC at equal trip time [%] (95 % CI over seeds)")
    ax.invert_yaxis()
    fig.tight_layout()
    return save_figure(fig, path, dpi=120)


def finite(x: float) -> bool:
    return isinstance(x, float) and math.isfinite(x)


# -------------------------------------------------------------------------- online estimate vs distance (trucks)
def convergence_run(case: str, seed: int, length: float) -> dict[str, Any]:
    """One online-MPC drive of a truck case on a ``length`` [m] long-grades road (time weight: the case's start
    value): the M4-RRLM estimate after every update against the truth, by position. Truth: the plant's mass and
    drag coefficient rho/2 c_x A, and m g f_r0 of the tyres (M4's m_V f_r0 also absorbs f_r1 v, so its
    reference is rough)."""
    vc = VEHICLE_CASES[case]
    road = long_grades(seed=seed, length=length)
    res, plant = drive(vc.vehicle(), road, seed=seed,
                       settings=replace(vc.settings(), controller="mpc", force_model="online", time_weight=vc.lam0))
    p = plant.true_parameters()
    truth = {"m_V": p.mass, "rho_a/2 A_V c_x": p.c2, "m_V f_r0": p.c0 / G}
    hist = res.metrics["online"]["history"]
    names = hist["parameters"]
    x = np.asarray(hist["x"], float)
    return {"case": case, "seed": seed, "length_m": length, "s": hist.get("s", []), "t": hist["t"],
            "truth": truth, "estimate": {n: x[:, i].tolist() for i, n in enumerate(names) if n in truth},
            "trip_time": res.metrics["trip_time"]}


def convergence_table(runs: list[dict[str, Any]], at: tuple[float, ...] = (2000.0, 4000.0, 8000.0, 12000.0,
                                                                            16000.0)) -> pd.DataFrame:
    """Median over seeds of the relative estimate error [%] per case, parameter and distance [m] (the last
    update at or before that distance)."""
    rows = []
    for case in dict.fromkeys(r["case"] for r in runs):
        rs = [r for r in runs if r["case"] == case]
        for name in ("m_V", "rho_a/2 A_V c_x", "m_V f_r0"):
            for d in at:
                errs = []
                for r in rs:
                    s = np.asarray(r["s"], float)
                    k = np.flatnonzero(s <= d)
                    if k.size and d <= r["length_m"]:
                        errs.append(100.0 * (r["estimate"][name][k[-1]] / r["truth"][name] - 1.0))
                if errs:
                    rows.append({"vehicle": case, "parameter": name, "distance_km": d / 1000.0,
                                 "error_median_pct": float(np.median(errs)),
                                 "error_abs_max_pct": float(np.max(np.abs(errs))), "seeds": len(errs)})
    return pd.DataFrame(rows)


def convergence_figure(runs: list[dict[str, Any]], path: Path) -> Path:
    """Relative error of m_V, rho/2 c_x A and m_V f_r0 [%] over distance [km], one line per run."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    names = ("m_V", "rho_a/2 A_V c_x", "m_V f_r0")
    fig, axes = plt.subplots(1, 3, figsize=(15, 4.0))
    colors = {c: f"C{i}" for i, c in enumerate(dict.fromkeys(r["case"] for r in runs))}
    for ax, name in zip(axes, names):
        for r in runs:
            s = np.asarray(r["s"], float) / 1000.0
            e = 100.0 * (np.asarray(r["estimate"][name]) / r["truth"][name] - 1.0)
            ax.plot(s, e, color=colors[r["case"]], lw=1.0, alpha=0.8,
                    label=r["case"] if r["seed"] == min(q["seed"] for q in runs if q["case"] == r["case"]) else None)
        ax.axhline(0.0, color="k", lw=0.8)
        ax.set_ylim(-60, 60) if name != "m_V" else ax.set_ylim(-20, 20)
        ax.set_xlabel("distance driven [km]")
        ax.set_ylabel(f"{name}: estimate vs truth [%]")
        ax.grid(alpha=0.3)
    axes[0].legend()
    fig.suptitle("Online M4-RRLM estimate on the truck's CAN stream (online MPC, long grades)")
    fig.tight_layout()
    return save_figure(fig, path, dpi=120)
