"""The simulated test fleet of section 5.1 and the chapter-5 benchmark over it.

:func:`plan_fleet` draws a seeded campaign like the text's: ≥ 80 trips, ~20 h, a rear-drive and an all-wheel-drive
grand tourer (about 2:1), mostly hilly countryside with city and motorway trips, winter tires (and cold weather)
on about a quarter, varying passengers and luggage, air conditioning, open windows / sunroof (drag), wind, cold
drive-train oil and tires, engine-torque model errors, outliers on some trips and poor-excitation stretches on
others. :func:`generate_fleet` simulates the plan into a folder of Trip files (regenerable: same seed, same trips).

:func:`benchmark_fleet` runs the chapter-5 evaluation over stored trips (one sweep task per trip: pipeline, 10
gray-box estimator runs, M0, cross-validation for all horizons, mass NMSE) on local processes or a Dask cluster,
aggregates MEDSE and mass tables with McGill notches, checks the text's findings and writes CSV, Markdown and PNG.
"""

from __future__ import annotations

import hashlib
import json
import os
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Sequence

import numpy as np
import pandas as pd

from roadload.fileio import write_json, write_text
from roadload.tables import markdown_table, write_csv
from roadload.trip import Trip, TripError

from roadload.estimators.evaluation import (ESTIMATORS, GRAY_BOX_MODELS, HORIZONS, MIN_TRAINING, P_MAX,
                                            combination_name, common_trips, default_combinations, evaluate_trip,
                                            notch_table, significantly_different)
from roadload.estimators.knowledge import knowledge_for_preset, knowledge_for_trip, trip_vehicle
from roadload.estimators.pipeline import PIPELINE_CHANNELS, PipelineSettings
from roadload.envs import simulate
from roadload.presets import get_preset
from roadload.road_profiles import load_profile
from roadload.sweep import run_sweep
from roadload.estimators.evaluation import evaluate_states
from roadload.estimators.pipeline import run_pipeline
from roadload.estimators.figures import (plot_correction_histograms, plot_cv_single_trip, plot_notched_boxplot,
                                         plot_output_corrections, plot_parameter_traces, plot_scatter, plot_stage,
                                         save)

FLEET_VERSION = 1
ROAD_KINDS = ("city", "hilly", "motorway")
TYPICAL_SPEED = {"city": 9.0, "hilly": 17.0, "motorway": 30.0}   # m/s, to size a road for a trip duration


class FleetError(ValueError):
    """Bad fleet request (too few trips, unreadable cache, no trips found); the message names what."""


# ================================================================================ the campaign
def plan_fleet(n_trips: int = 84, seed: int = 2012, total_hours: float = 20.0) -> list[dict[str, Any]]:
    """A seeded campaign of `n_trips` trip descriptions (JSON-ready dicts) totalling about `total_hours`."""
    if n_trips < 1:
        raise FleetError(f"a fleet needs at least one trip, got {n_trips}")
    if not total_hours > 0:
        raise FleetError(f"total_hours must be > 0, got {total_hours}")
    rng = np.random.default_rng(seed)
    roads = rng.choice(ROAD_KINDS, size=n_trips, p=[0.2, 0.6, 0.2])
    raw = np.exp(rng.normal(np.log(700.0), 0.65, n_trips)) * np.where(roads == "motorway", 1.8, 1.0)
    durations = np.clip(raw * (total_hours * 3600.0 / raw.sum()), 120.0, 5400.0)
    winter = rng.random(n_trips) < 0.27
    vehicles = np.where(rng.random(n_trips) < 54 / 81, "gt_rwd", "gt_awd")
    plan = []
    for i in range(n_trips):
        r = np.random.default_rng([seed, i])
        cold = bool(winter[i])
        t_amb = float(r.uniform(268.0, 282.0) if cold else r.uniform(285.0, 305.0))
        passengers = int(r.choice([0, 1, 2, 3], p=[0.45, 0.3, 0.15, 0.1]))
        luggage = float(np.round(r.uniform(0.0, 80.0) if r.random() < 0.5 else 0.0, 1))
        payload = 75.0 * passengers + luggage
        effects: dict[str, dict[str, Any]] = {
            "payload": {"initial_payload": payload, "change_std": 0.0, "min_payload": 0.0,
                        "max_payload": max(400.0, payload)},
            "wind": {"mean_speed": float(np.round(r.uniform(0.0, 7.0), 2)),
                     "direction": float(np.round(r.uniform(-np.pi, np.pi), 3)),
                     "gust_std": float(np.round(r.uniform(0.3, 2.0), 2))},
            "drag_area": {"windows": 0.05, "sunroof": 0.02,
                          "toggle_rate": float(np.round(r.uniform(0.0, 1.0) if cold else r.uniform(0.5, 4.0), 2)),
                          "roof_box": 0.2 if r.random() < 0.05 else 0.0},
            "tire_warmup": {"cold_factor": float(np.round(r.uniform(1.1, 1.35), 3))},
            "oil_temperature": {},
            "torque_model_error": {"gain_error": float(np.round(r.normal(0.0, 0.03), 4)),
                                   "offset": float(np.round(r.normal(0.0, 6.0), 2))},
            "sensor_bias": {"scale": 1.0},
            "road_bank": {},
            "barometric": {},
        }
        if cold:
            effects["winter_tires"] = {"rolling_factor": float(np.round(r.uniform(1.1, 1.25), 3)),
                                       "cornering_factor": float(np.round(r.uniform(0.8, 0.9), 3))}
        else:
            effects["auxiliary_load"] = {"power": float(np.round(r.uniform(500.0, 2500.0), 0))}  # air conditioning
        if r.random() < (0.35 if cold else 0.15):
            effects["wet_road"] = {}
        if r.random() < 0.5:
            effects["sensor_outliers"] = {"rate": float(np.round(10 ** r.uniform(-3.5, -2.5), 6)),
                                          "magnitude": float(np.round(r.uniform(1.0, 4.0), 2)), "channels": "all"}
        if r.random() < 0.35:
            effects["poor_excitation"] = {"fraction": float(np.round(r.uniform(0.2, 0.6), 2)),
                                          "stretch_length": float(np.round(r.uniform(1000.0, 4000.0), 0))}
        if r.random() < 0.2:
            effects["sensor_dropouts"] = {"rate": float(np.round(r.uniform(5.0, 40.0), 1)), "mode": "nan"}
        road = str(roads[i])
        plan.append({
            "name": f"fleet{seed}_{i:03d}", "index": i, "seed": int(seed * 1000 + i), "vehicle": str(vehicles[i]),
            "road": road, "road_seed": int(r.integers(0, 2 ** 31 - 1)), "duration": float(np.round(durations[i], 1)),
            "road_length": float(np.round(durations[i] * TYPICAL_SPEED[road] * 1.6 + 2000.0, -2)),
            "winter": cold, "passengers": passengers, "luggage_kg": luggage, "payload_kg": payload,
            "effects": {"effects": effects, "ambient_temperature": t_amb,
                        "ambient_pressure": float(np.round(r.uniform(95000.0, 103000.0), 0))},
        })
    return plan


def plan_digest(plan: list[dict[str, Any]]) -> str:
    return hashlib.sha256(json.dumps([FLEET_VERSION, plan], sort_keys=True).encode()).hexdigest()[:16]


def simulate_planned_trip(entry: dict[str, Any]) -> Trip:
    """Simulate one planned trip (vehicle preset, seeded road profile, effects, sensors of the preset)."""

    vehicle = get_preset(entry["vehicle"])
    road = load_profile(entry["road"], seed=entry["road_seed"], length=entry["road_length"])
    trip = simulate(vehicle, road, entry["effects"], None, entry["seed"], duration=entry["duration"])
    trip.meta["name"] = entry["name"]
    trip.meta["fleet"] = {k: v for k, v in entry.items() if k != "effects"}
    return trip


def stored_trip_problem(path: Path, entry: dict[str, Any]) -> str | None:
    """Why a stored trip cannot be reused for a planned entry (unreadable, or another trip), None if it can."""
    try:
        info = Trip.read_info(path)
    except (TripError, OSError) as exc:
        return f"unreadable ({exc})"
    stored = (info["meta"] or {}).get("fleet")
    planned = json.loads(json.dumps({k: v for k, v in entry.items() if k != "effects"}))
    if stored != planned:
        return "holds another planned trip"
    return None


def _generate_one(task: tuple[dict[str, Any], str]) -> dict[str, str]:
    """Simulate one planned trip unless a valid file of it is stored; a corrupt or foreign file is simulated again
    (reported as rebuilt), never trusted."""
    entry, folder = task
    path = Path(folder) / f"{entry['name']}.parquet"
    problem = stored_trip_problem(path, entry) if path.exists() else "missing"
    if problem is not None:
        simulate_planned_trip(entry).save(path)
    return {"path": str(path), "status": "stored" if problem is None else "simulated" if problem == "missing"
            else f"rebuilt: the stored file was {problem}"}


def generate_fleet(folder: str | os.PathLike, n_trips: int = 84, seed: int = 2012, total_hours: float = 20.0,
                   scheduler: str | None = None, workers: int | None = None, progress: bool = True
                   ) -> dict[str, Any]:
    """Simulate the planned fleet into `folder` (trip files + plan.json); valid trips already there are kept (a run
    stopped mid-way resumes), corrupt or foreign ones are simulated again.

    Returns {"folder", "plan", "trips": [paths], "failed": [(name, error)], "rebuilt": [(name, why)]}."""

    folder = Path(folder)
    plan = plan_fleet(n_trips, seed, total_hours)
    manifest = folder / "plan.json"
    if manifest.exists():
        old = json.loads(manifest.read_text())
        if old.get("digest") != plan_digest(plan):
            raise FleetError(f"{folder} holds a different fleet (plan digest {old.get('digest')}); "
                             f"use another folder or delete it")
    write_json(manifest, {"version": FLEET_VERSION, "digest": plan_digest(plan), "seed": seed,
                           "n_trips": n_trips, "total_hours": total_hours, "plan": plan})
    outcomes = run_sweep(_generate_one, [(e, str(folder)) for e in plan], scheduler=scheduler, workers=workers,
                         progress=progress, description="simulating fleet")
    rebuilt = [(Path(o.value["path"]).stem, o.value["status"]) for o in outcomes
               if o.ok and o.value["status"].startswith("rebuilt")]
    return {"folder": str(folder), "plan": plan, "trips": [o.value["path"] for o in outcomes if o.ok],
            "failed": [(o.task[0]["name"], o.error) for o in outcomes if not o.ok], "rebuilt": rebuilt}


# ================================================================================ evaluation of stored trips
def true_mass(trip: Trip) -> float | None:
    """Mean true vehicle mass [kg] of a simulated trip (the scale reading of section 5.9), else None."""
    if trip.truth is None or "mass" not in trip.truth.columns:
        return None
    return float(np.nanmean(trip.true("mass")))


@dataclass(frozen=True)
class BenchmarkTask:
    path: str
    horizons: tuple[int, ...] = HORIZONS
    min_training: int = MIN_TRAINING
    p_max: float = P_MAX
    settings: PipelineSettings = field(default_factory=PipelineSettings)
    output_outliers: tuple[float, float] | None = None
    file_stamp: str = ""  # size and modification time of the trip file (a checkpointed result is for this file)


def inject_output_outliers(states: pd.DataFrame, rate: float, size: float, seed: int,
                           burst: int = 10) -> pd.DataFrame:
    """A sensitivity experiment, not part of the simulator: add outlier events to the measured output F_xV of the
    triggered states (after preprocessing). Each triggered sample starts an event with probability `rate`; an
    event adds ±size (1 + |N(0, 1)|) [N] to `burst` consecutive triggered samples (1 s at 10 Hz) — output
    corrections of the ~2000 N class that figures 5.5-5.7 show in the text's data."""
    rng = np.random.default_rng(seed)
    idx = np.flatnonzero(states["trigger"].to_numpy(dtype=bool))
    f = states["tractive_force"].to_numpy(dtype=float).copy()
    for start in np.flatnonzero(rng.random(idx.size) < rate):
        f[idx[start:start + burst]] += rng.choice([-1.0, 1.0]) * size * (1.0 + abs(rng.standard_normal()))
    return states.assign(tractive_force=f)


def evaluate_stored_trip(task: BenchmarkTask) -> dict[str, Any]:
    """Sweep task: load one stored trip and evaluate all 11 combinations at all horizons."""

    t0 = time.perf_counter()
    trip = Trip.load(task.path, channels=list(PIPELINE_CHANNELS), truth_channels=["mass"])
    knowledge = knowledge_for_preset(trip_vehicle(trip))
    t1 = time.perf_counter()
    res = run_pipeline(trip, knowledge, task.settings)
    t_pre = time.perf_counter() - t1
    states = res.states
    if task.output_outliers is not None:
        seed = int(hashlib.sha256(res.name.encode()).hexdigest()[:8], 16)
        states = inject_output_outliers(states, *task.output_outliers, seed=seed)
    ev = evaluate_states(res.name, states, knowledge, default_combinations(), task.horizons, task.min_training,
                         true_mass(trip), task.p_max)
    ev.timing["preprocessing"] = t_pre
    ev.info["notes"] = list(res.notes)
    t_load = t1 - t0
    fleet = trip.meta.get("fleet") or {}
    info = {"trip": ev.trip, "vehicle": knowledge.name, "road": fleet.get("road"), "winter": fleet.get("winter"),
            "outliers": "sensor_outliers" in json.dumps(trip.meta.get("effects", fleet)),
            "duration": trip.duration, **{k: v for k, v in ev.info.items() if k != "notes"}}
    return {"medse": ev.medse, "mass": ev.mass, "timing": {"loading": t_load, **ev.timing}, "info": info,
            "notes": ev.info.get("notes", [])}


def stored_trips(folder: str | os.PathLike, limit: int | None = None) -> list[Path]:
    folder = Path(folder)
    paths = sorted(folder.glob("*.parquet"))
    if not paths:
        raise FleetError(f"no trip files (*.parquet) in {folder}")
    return paths[:limit] if limit else paths


@dataclass
class BenchmarkResult:
    medse: pd.DataFrame
    mass: pd.DataFrame
    trips: pd.DataFrame
    failed: list[tuple[str, str]]
    timing: dict[str, float]

    def medse_table(self, horizon: int) -> pd.DataFrame:
        d = self.medse[self.medse["horizon"] == horizon]
        return notch_table(common_trips(d))

    def mass_table(self) -> pd.DataFrame:
        return notch_table(self.mass, value="nmse")


def run_benchmark(paths: Sequence[str | os.PathLike], scheduler: str | None = None, workers: int | None = None,
                  progress: bool = True, checkpoint: str | os.PathLike | None = None,
                  **task_options: Any) -> BenchmarkResult:
    """Evaluate stored trips through the sweep runner; failed trips are reported, not raised. ``checkpoint``: a
    folder where each trip's evaluation is stored as it finishes (a stopped run resumes; a trip file that changed
    since is evaluated again)."""

    def stamp(p: str | os.PathLike) -> str:
        st = os.stat(p) if checkpoint is not None and os.path.exists(p) else None
        return f"{st.st_size}-{st.st_mtime_ns}" if st is not None else ""

    tasks = [BenchmarkTask(str(p), file_stamp=stamp(p), **task_options) for p in paths]
    t0 = time.perf_counter()
    outcomes = run_sweep(evaluate_stored_trip, tasks, scheduler=scheduler, workers=workers, progress=progress,
                         description="chapter-5 benchmark", checkpoint=checkpoint,
                         name=lambda task: Path(task.path).stem)
    wall = time.perf_counter() - t0
    medse, mass, infos = [], [], []
    timing = {"loading": 0.0, "preprocessing": 0.0, "estimation": 0.0, "evaluation": 0.0}
    for o in outcomes:
        if not o.ok:
            continue
        medse += o.value["medse"]
        mass += o.value["mass"]
        infos.append(o.value["info"])
        for k in timing:
            timing[k] += o.value["timing"].get(k, 0.0)
    timing["wall"] = wall
    failed = [(Path(o.task.path).stem, o.error) for o in outcomes if o.error is not None]
    cols_m = ["trip", "model", "estimator", "combination", "horizon", "medse", "n_triggered"]
    return BenchmarkResult(pd.DataFrame(medse, columns=cols_m) if not medse else pd.DataFrame(medse),
                           pd.DataFrame(mass), pd.DataFrame(infos), failed, timing)


# ================================================================================ the text's findings
def _finding_m0_worse(tab: pd.DataFrame, gray: list[str]) -> dict[str, Any]:
    """Finding 1 (fig. 5.9): M0 is significantly worse than every gray-box combination."""
    worse = [c for c in gray if tab.loc["M0", "median"] > tab.loc[c, "median"]
             and significantly_different(tab.loc["M0"], tab.loc[c])]
    return {"finding": "M0 significantly worse than every gray-box combination (fig. 5.9)",
            "reproduced": len(worse) == len(gray),
            "evidence": f"M0 median {tab.loc['M0', 'median']:.4g} N², notch "
                        f"[{tab.loc['M0', 'notch_low']:.4g}, {tab.loc['M0', 'notch_high']:.4g}]; significantly "
                        f"worse than {len(worse)}/{len(gray)} gray-box combinations"
                        + ("" if len(worse) == len(gray) else f" (not: {sorted(set(gray) - set(worse))})")}


def _finding_m4_rrlm_best(tab: pd.DataFrame, gray: list[str]) -> dict[str, Any] | None:
    """Finding 2: M4-RRLM has the lowest median MEDSE and the smallest IQR (None without M4-RRLM)."""
    key = "M4-RRLM"
    if key not in tab.index:
        return None
    best_med = tab.loc[gray, "median"].idxmin()
    best_iqr = tab.loc[gray, "iqr"].idxmin()
    sig = [c for c in gray if c != key and significantly_different(tab.loc[key], tab.loc[c])
           and tab.loc[c, "median"] > tab.loc[key, "median"]]
    return {"finding": "M4-RRLM has the lowest median MEDSE and the smallest IQR",
            "reproduced": best_med == key and best_iqr == key,
            "evidence": f"lowest median: {best_med} ({tab.loc[best_med, 'median']:.4g}); smallest IQR: "
                        f"{best_iqr} ({tab.loc[best_iqr, 'iqr']:.4g}); M4-RRLM median "
                        f"{tab.loc[key, 'median']:.4g}, IQR {tab.loc[key, 'iqr']:.4g}; significantly "
                        f"better than {len(sig)} of {len(gray) - 1} other gray-box combinations"}


def _finding_m4_beats_m3(tab: pd.DataFrame) -> dict[str, Any]:
    """Finding 3: M4 predicts better than M3, per estimator (medians)."""
    pairs = [(e, tab.loc[f"M3-{e}", "median"], tab.loc[f"M4-{e}", "median"]) for e in ESTIMATORS
             if f"M3-{e}" in tab.index and f"M4-{e}" in tab.index]
    better = [e for e, m3, m4 in pairs if m4 < m3]
    return {"finding": "M4 predicts better than M3",
            "reproduced": len(better) == len(pairs) and len(pairs) > 0,
            "evidence": "; ".join(f"{e}: M3 {m3:.4g} vs M4 {m4:.4g}" for e, m3, m4 in pairs)}


def _finding_sgivmkf_mass(result: BenchmarkResult) -> dict[str, Any] | None:
    """Finding 4 (fig. 5.10): SGIVMKF gives the best mass estimates (None without converged mass results)."""
    if result.mass.empty or not result.mass["nmse"].notna().any():
        return None
    mt = result.mass_table().set_index("combination")
    mt = mt[mt["m"] > 0]
    best = mt["median"].idxmax()
    ranked = mt["median"].sort_values(ascending=False).index
    return {"finding": "SGIVMKF gives the best mass estimates (fig. 5.10, M4-SGIVMKF best)",
            "reproduced": best.endswith("SGIVMKF"),
            "evidence": "median mass NMSE: " + ", ".join(f"{c} {mt.loc[c, 'median']:.5f}" for c in ranked)
                        + f" (m = {int(mt['m'].max())} converged trips)"}


def _prediction_failures(piv: pd.DataFrame, info: pd.DataFrame) -> list[tuple[str, str, float, float]]:
    """Per gray-box combination other than RRLM: (combination, estimator, share of trips whose MEDSE exceeds 2x
    the same model's RRLM, the same share over the trips with outliers)."""
    rows = []
    for model in GRAY_BOX_MODELS:
        ref = piv.get(f"{model}-RRLM")
        if ref is None:
            continue
        for e in ESTIMATORS:
            c = f"{model}-{e}"
            if c not in piv or e == "RRLM":
                continue
            ratio = piv[c] / ref
            ok = ratio.notna()
            fail = float((ratio[ok] > 2.0).mean()) if ok.any() else float("nan")
            fail_out = float("nan")
            if "outliers" in info:
                mask = ok & info.reindex(piv.index)["outliers"].fillna(False).astype(bool)
                fail_out = float((ratio[mask] > 2.0).mean()) if mask.any() else float("nan")
            rows.append((c, e, fail, fail_out))
    return rows


def _finding_outlier_instability(result: BenchmarkResult, horizon: int) -> dict[str, Any] | None:
    """Finding 5 (fig. 5.4/5.8): RLS and RGTLS are unstable under outliers, measured as the share of trips where
    the prediction fails (MEDSE > 2x the same model's RRLM); None without RRLM references."""
    d = result.medse[result.medse["horizon"] == horizon]
    piv = d.pivot_table(index="trip", columns="combination", values="medse")
    info = result.trips.set_index("trip") if not result.trips.empty else pd.DataFrame()
    rows = _prediction_failures(piv, info)
    if not rows:
        return None
    share = {e: float(np.nanmean([r[2] for r in rows if r[1] == e])) for e in ESTIMATORS if e != "RRLM"}
    nonrobust = [share.get("RLS", np.nan), share.get("RGTLS", np.nan)]
    robust = [share.get("SGMKF", np.nan), share.get("SGIVMKF", np.nan)]
    tails = ""
    if "outlier_share" in info and "max_output_correction" in info:
        tails = (f"; outliers as the estimators see them (M3-RRLM ΔB): median share beyond 5 robust σ "
                 f"{np.nanmedian(info['outlier_share']):.4f}, median of the per-trip largest |ΔB| "
                 f"{np.nanmedian(info['max_output_correction']):.0f} N")
    return {"finding": "RLS and RGTLS are unstable under outliers (fig. 5.4/5.8)",
            "reproduced": bool(np.nanmin(nonrobust) > np.nanmax(robust)),
            "evidence": "share of trips with MEDSE > 2x the same model's RRLM (all trips / trips with "
                        "outliers): " + ", ".join(f"{c} {f:.2f}/{fo:.2f}" for c, _, f, fo in rows) + tails}


def check_findings(result: BenchmarkResult, horizon: int = 900) -> list[dict[str, Any]]:
    """Which findings of sections 5.8/5.9 the results reproduce, with the evidence (numbers) for each."""
    tab = result.medse_table(horizon).set_index("combination")
    gray = [c for c in tab.index if c != "M0"]
    if "M0" not in tab.index or not gray or tab["m"].min() == 0:
        return [{"finding": "all", "reproduced": None, "evidence": f"no complete results at k = {horizon}"}]
    findings = [_finding_m0_worse(tab, gray), _finding_m4_rrlm_best(tab, gray), _finding_m4_beats_m3(tab),
                _finding_sgivmkf_mass(result), _finding_outlier_instability(result, horizon)]
    return [f for f in findings if f is not None]


def single_trip_figures(path: str | os.PathLike, out_dir: str | os.PathLike, model: str = "M3") -> list[Path]:
    """Figures 5.4-5.8 for one stored trip: parameter traces, output corrections, histograms, scatter (model
    `model` with the four estimators of section 5.6) and the cross-validation bars of all combinations."""

    trip = Trip.load(path)
    knowledge = knowledge_for_trip(trip)
    res = run_pipeline(trip, knowledge)
    mass_true = true_mass(trip)
    ev = evaluate_trip(trip, knowledge, keep_estimates=True, true_mass=mass_true)
    ests = {k: v for k, v in ev.estimates.items() if k.startswith(model + "-") and not k.endswith("SGIVMKF")}
    out = Path(out_dir)
    truth = {"m_V": mass_true} if mass_true else None
    files = [save(plot_stage(res, "states"), out / f"{res.name}_states.png"),
             save(plot_parameter_traces(ests, truth), out / f"{res.name}_fig5_4_parameters.png"),
             save(plot_output_corrections(ests), out / f"{res.name}_fig5_5_output_corrections.png"),
             save(plot_correction_histograms(ests), out / f"{res.name}_fig5_6_histograms.png"),
             save(plot_scatter(ests), out / f"{res.name}_fig5_7_scatter.png"),
             save(plot_cv_single_trip(pd.DataFrame(ev.medse), res.name), out / f"{res.name}_fig5_8_cv.png")]
    return files


def _report_head(result: BenchmarkResult, title: str) -> list[str]:
    """The report's title, counts, failed trips and time split (Markdown lines)."""
    md = [f"# {title}", "", f"{len(result.trips)} trips evaluated, {len(result.failed)} failed.", ""]
    if result.failed:
        md += ["## Failed trips", ""] + [f"- {n}: {e}" for n, e in result.failed] + [""]
    t = result.timing
    md += ["## Time", "", "| stage | seconds (summed over workers) |", "|---|---|"]
    md += [f"| {k} | {t[k]:.2f} |" for k in ("loading", "preprocessing", "estimation", "evaluation") if k in t]
    md += [f"| wall clock | {t.get('wall', float('nan')):.2f} |", ""]
    return md


def _medse_section(result: BenchmarkResult, out: Path, horizon: int, order: list[str], figures: bool) -> list[str]:
    """The MEDSE table (CSV + Markdown) and notched box plot of one horizon; no lines without results."""
    d = result.medse[result.medse["horizon"] == horizon]
    if d.empty:
        return []
    tab = notch_table(common_trips(d))
    tab["order"] = tab["combination"].map({c: i for i, c in enumerate(order)})
    tab = tab.sort_values("order").drop(columns="order")
    write_csv(out / f"medse_k{horizon}.csv", tab)
    m = int(tab["m"].max()) if len(tab) else 0
    if figures and len(tab) and m > 0:
        save(plot_notched_boxplot(common_trips(d), "medse", order=[c for c in order if c in set(d["combination"])],
                                  ylabel="MEDSE [N²]", title=f"prediction MEDSE, k = {horizon}, m = {m} trips"),
             out / f"medse_boxplot_k{horizon}.png")
    return [f"## MEDSE of the tractive-force prediction, k = {horizon} (trips with every combination: m = {m})", "",
            markdown_table(tab, floatfmt=".4g"), ""]


def _mass_section(result: BenchmarkResult, out: Path, order: list[str], figures: bool) -> list[str]:
    """The mass NMSE table (CSV + Markdown) and its box plot; no lines without mass results."""
    if result.mass.empty:
        return []
    mt = result.mass_table()
    write_csv(out / "mass_nmse.csv", mt)
    if figures and mt["m"].max() > 0:
        mass_order = [c for c in order if c in set(result.mass["combination"])]
        save(plot_notched_boxplot(result.mass, "nmse", order=mass_order, log=False, ylabel="mass NMSE [-]",
                                  title="mass NMSE (best = 1)"),
             out / "mass_nmse_boxplot.png")
    return [f"## Mass NMSE after the convergence test (P_t < P_max = {P_MAX} on SGMKF)", "",
            markdown_table(mt, floatfmt=".5g"), ""]


def _findings_section(result: BenchmarkResult, out: Path) -> list[str]:
    """The text's findings (CSV + Markdown list) at the default horizon."""
    findings = check_findings(result)
    write_csv(out / "findings.csv", pd.DataFrame(findings))
    verdicts = {True: "reproduced", False: "NOT reproduced", None: "undecided"}
    return ["## Findings of the text", ""] + [f"- **{f['finding']}**: {verdicts[f['reproduced']]}. {f['evidence']}"
                                              for f in findings]


def write_report(result: BenchmarkResult, out_dir: str | os.PathLike, horizons: Sequence[int] = HORIZONS,
                 figures: bool = True, title: str = "chapter-5 benchmark") -> Path:
    """Tables (CSV + one Markdown report) and figures (PNG) of a benchmark into out_dir; returns the report."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    write_csv(out / "medse_per_trip.csv", result.medse)
    write_csv(out / "mass_per_trip.csv", result.mass)
    write_csv(out / "trips.csv", result.trips)
    order = [combination_name(m, e) for m, e in default_combinations()]
    md = _report_head(result, title)
    for k in horizons:
        md += _medse_section(result, out, k, order, figures)
    md += _mass_section(result, out, order, figures)
    md += _findings_section(result, out)
    report = out / "report.md"
    write_text(report, "\n".join(md) + "\n")
    return report
