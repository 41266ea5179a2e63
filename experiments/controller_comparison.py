"""The headline comparison: eco-driving MPC (online / abc / oracle force model) against cruise control and the
human-like driver, closed loop on the simulator, over roads x conditions, at equal trip time.

Per (road, condition) one sweep task runs:
1. cruise control (PI at ``cruise_fraction`` of the allowed speed) -> the reference trip time T_ref;
2. the simulator's human-like driver (its own pace: reported, NOT time-matched, flagged ``matched=False``);
3. MPC with the oracle model, time-matched to T_ref within ``tol`` (search over the time weight lambda);
4. MPC with the abc and the online (M4-RRLM) model, each time-matched the same way (search started from the
   oracle's lambda).
Energies are only compared between runs whose trip times agree within ``tol`` (``matched``); a run that cannot
be matched is reported as such.

Roads: generated hilly country road, motorway and city route (seeded, see ``ROADS``) and a real grade profile
from a BMW i3 log of the shared data (``i3_munich``: grade from the logged map elevation by
:func:`roadload.io.profiles.profile_from_trip`; the log has no speed limits, so the limit is the running maximum
of the logged speed over +-500 m rounded up to 10 km/h -- the same convention as the GradeIT routes). Conditions:
``CONDITIONS`` (effects of :mod:`roadload.envs.effects`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from roadload.road_profiles import RoadProfile

from roadload.controllers.cruise import CruiseSettings
from roadload.controllers.drive import DriveSettings, drive
from roadload.experiments.time_matching import match_trip_time
from roadload.data import require_shared_data
from roadload.io.importer import import_log
from roadload.io.profiles import profile_from_trip
from roadload.io.derived import distance_from_speed
from roadload.road_profiles import city, hilly, motorway
from roadload.controllers.drive import resolve_road
from roadload.fileio import write_text
from roadload.experiments.controller_report import markdown_table, write_figures

KMH = 1 / 3.6

CONDITIONS: dict[str, list[str] | None] = {
    "nominal": None,
    "payload_300kg": ["payload:initial_payload=300,min_payload=300,max_payload=300,change_std=0"],
    "winter_tires": ["winter_tires"],
    "headwind_6ms": ["wind:mean_speed=6,direction=3.141592653589793,gust_std=0.5,direction_std=0.05"],
    "roof_box": ["drag_area:roof_box=0.25,windows=0,sunroof=0,toggle_rate=0"],
    "drift": ["tire_warmup:cold_factor=1.3,distance_constant=3000",
              "oil_temperature:start_temperature=278.15",
              "drag_area:roof_box=0,windows=0.08,sunroof=0.03,toggle_rate=8",
              "payload:change_std=150,max_payload=400",
              "wind:mean_speed=3,gust_std=1.5"],
}


def _i3_munich(length: float = 6000.0) -> RoadProfile:
    from scipy.ndimage import maximum_filter1d

    path = require_shared_data("bmw_i3_tum/data") / "TripB11.csv"
    trip = import_log(path, "bmw-i3")
    prof = profile_from_trip(trip, name="i3_munich", source="bmw_i3_tum TripB11 (Munich South)",
                             licence="CC BY 4.0", grade_source="elevation", curvature_source=None)
    # speed limit: running max of the logged speed over +-500 m, rounded up to 10 km/h, at least 30 km/h

    v = np.nan_to_num(trip.channel("vehicle_speed"))
    s_log = distance_from_speed(trip.t, v)
    v_s = np.interp(prof.distance, s_log, v)
    width = max(1, int(round(1000.0 / (prof.distance[1] - prof.distance[0]))))
    limit = np.maximum(np.ceil(maximum_filter1d(v_s, width) / (10 * KMH) - 1e-9) * 10 * KMH, 30 * KMH)
    keep = prof.distance <= length
    meta = {**prof.meta, "speed_limit_meaning": "running max of the logged speed over +-500 m, rounded up to "
                                                "10 km/h (the log has no posted limits)", "truncated_to_m": length}
    return RoadProfile("i3_munich", prof.distance[keep], prof.grade[keep], prof.curvature[keep], prof.bank[keep],
                       limit[keep], stops=prof.stops[prof.stops <= length], meta=meta)


def road_by_name(name: str) -> RoadProfile:
    """The comparison's roads (module docstring); other names go to ``roadload.road_profiles.load_profile``."""

    if name == "hilly":
        return hilly(seed=1, length=6000.0)
    if name == "motorway":
        return motorway(seed=1, length=10000.0)
    if name == "city":
        return city(seed=1, length=3000.0)
    if name == "i3_munich":
        return _i3_munich()

    return resolve_road(name)


ROADS = ("hilly", "motorway", "city", "i3_munich")


@dataclass(frozen=True)
class ComparisonTask:
    road: str
    condition: str
    vehicle: str = "bmw_i3"
    seed: int = 0
    tol: float = 0.01
    cruise_fraction: float = 0.9
    solver: str = "ipopt"
    force_models: tuple[str, ...] = ("oracle", "abc", "online")
    keep_logs: bool = True


def _row(task: ComparisonTask, controller: str, force_model: str, metrics: dict[str, Any], t_ref: float,
         matched: bool, runs: int, lam: float, energy_at_ref: float = float("nan")) -> dict[str, Any]:
    keys = ("energy_kWh", "trip_time", "speed_violations", "violation_time", "max_excess_kmh", "rms_jerk",
            "max_abs_accel", "solve_time_median", "solve_time_p99", "fallbacks", "arrived")
    row = {"road": task.road, "condition": task.condition, "vehicle": task.vehicle, "controller": controller,
           "force_model": force_model, **{k: metrics.get(k) for k in keys}}
    row["time_error_pct"] = 100.0 * (metrics["trip_time"] / t_ref - 1.0) if t_ref > 0 else float("nan")
    if controller == "cruise":
        energy_at_ref = metrics["energy_J"]
    row["energy_at_Tref_kWh"] = energy_at_ref / 3.6e6
    row.update(matched=bool(matched), runs=int(runs), time_weight=float(lam),
               solves=int(metrics.get("ctl_solves", 0) or 0))
    if "online" in metrics:
        est = metrics["online"]["estimate"]
        row["online_estimate"] = "; ".join(f"{k}={v:.4g}" for k, v in est.items())
    return row


def run_comparison_task(task: ComparisonTask) -> dict[str, Any]:
    """All runs of one (road, condition): rows for the table and the logs of the final runs."""
    road = road_by_name(task.road)
    effects = CONDITIONS[task.condition]
    cruise_settings = CruiseSettings(fraction=task.cruise_fraction)
    base = DriveSettings(controller="cruise", force_model="abc", solver=task.solver, cruise=cruise_settings)
    rows, logs = [], {}

    def run(settings: DriveSettings):
        res, _ = drive(task.vehicle, road, effects=effects, seed=task.seed, settings=settings)
        return res

    cruise = run(base)
    t_ref = cruise.metrics["trip_time"]
    if not math.isfinite(t_ref):
        raise RuntimeError(f"cruise control did not arrive on {task.road}/{task.condition}")
    rows.append(_row(task, "cruise", "-", cruise.metrics, t_ref, True, 1, float("nan")))
    logs["cruise"] = cruise.log
    human = run(replace(base, controller="human"))
    rows.append(_row(task, "human", "-", human.metrics, t_ref,
                     abs(human.metrics["trip_time"] / t_ref - 1) <= task.tol, 1, float("nan")))
    logs["human"] = human.log
    lam0 = 8000.0
    for fm in task.force_models:
        matched = match_trip_time(lambda lam: run(replace(base, controller="mpc", force_model=fm, time_weight=lam)),
                                  t_ref, tol=task.tol, lam0=lam0)
        if fm == "oracle" and matched.matched:
            lam0 = matched.time_weight
        rows.append(_row(task, "mpc", fm, matched.result.metrics, t_ref, matched.matched, matched.runs,
                         matched.time_weight, matched.energy_at_target()))
        logs[f"mpc_{fm}"] = matched.result.log
    out: dict[str, Any] = {"rows": rows}
    if task.keep_logs:
        out["logs"] = {k: v[["t", "s", "v", "a", "traction", "regen", "brake", "energy", "speed_limit", "grade"]]
                       for k, v in logs.items()}
        out["road"] = {"s": road.distance, "elevation": road.elevation(), "speed_limit": road.speed_limit,
                       "grade": road.grade}
    return out


def summarise(table: pd.DataFrame) -> pd.DataFrame:
    """Per (road, condition): MPC energy relative to cruise and to the oracle MPC [%]: the energy interpolated to
    exactly the cruise trip time where bracketing runs exist, else the matched run's energy (|dT| <= tol);
    NaN where the run could not be matched."""
    out = []
    for (road, cond), g in table.groupby(["road", "condition"], sort=False):
        def energy(ctl, fm="-"):
            r = g[(g.controller == ctl) & (g.force_model == fm)]
            if not len(r) or not bool(r.matched.iloc[0]):
                return float("nan")
            e = float(r.energy_at_Tref_kWh.iloc[0])
            return e if math.isfinite(e) else float(r.energy_kWh.iloc[0])

        cruise, oracle = energy("cruise"), energy("mpc", "oracle")
        row = {"road": road, "condition": cond}
        for fm in ("oracle", "abc", "online"):
            e = energy("mpc", fm)
            row[f"{fm}_vs_cruise_pct"] = 100 * (e / cruise - 1)
            if fm != "oracle":
                row[f"{fm}_vs_oracle_pct"] = 100 * (e / oracle - 1)
        out.append(row)
    return pd.DataFrame(out)


def write_outputs(results: list[dict[str, Any]], failures: list[str], out: Path) -> tuple[pd.DataFrame, pd.DataFrame]:
    """comparison.csv / comparison.md / summary.csv and the figures into ``out`` (atomic file writes)."""

    out.mkdir(parents=True, exist_ok=True)
    table = pd.DataFrame([r for res in results for r in res["rows"]])
    summary = summarise(table) if len(table) else pd.DataFrame()
    write_text(out / "comparison.csv", table.to_csv(index=False))
    write_text(out / "summary.csv", summary.to_csv(index=False))
    md = ["# Controller comparison (closed loop, simulator)", "",
          "Energy at the source (battery) per run; MPC runs time-matched to cruise control (|time error| <= "
          "tolerance, column `matched`); the human driver keeps its own pace (not time-matched).", "",
          markdown_table(table), "", "## MPC energy relative to cruise control and to the oracle MPC [%]", "",
          markdown_table(summary)]
    if failures:
        md += ["", "## Failed tasks", ""] + [f"- {f}" for f in failures]
    write_text(out / "comparison.md", "\n".join(md) + "\n")
    write_figures(results, table, out)
    return table, summary
