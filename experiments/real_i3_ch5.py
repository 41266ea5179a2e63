"""Chapter 5 on real data: the BMW i3 trips of ../shared/data/bmw_i3_tum.

Every trip runs through the chapter-5 pipeline (the log is 10 Hz already; no steering signal, so no path
curvature and no M4) with M0 (spec-sheet abc values of the i3 preset: c_w 0.29, A 2.38 m², f_r0, 1400 kg with
driver) and M3 with the five estimators of section 5.5. Prints and writes:

- the MEDSE table (medians, McGill notches) and boxplot per horizon;
- mass estimates against the payload notes of overview.csv (+60 ... +80 kg on the trips present): NMSE against
  1400 kg + payload on the noted trips, and the payload the estimators see (median estimate on noted trips minus
  median on the others) per combination;
- per trip: the accelerometer test (does ẍ_CAN contain g sin θ?), trigger share and notes.

    python scripts/real_i3_ch5.py [--out out/real_i3] [--workers 2] [--limit N]
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from typing import Any
from pathlib import Path

import numpy as np
import pandas as pd

from roadload.data import require_shared_data
from roadload.estimators.evaluation import (ESTIMATORS, HORIZONS, MIN_TRAINING, combination_name, common_trips,
                                            evaluate_trip, notch_table)
from roadload.estimators.knowledge import knowledge_for_trip
from roadload.fileio import write_text
from roadload.tables import markdown_table, write_csv
from roadload.estimators.pipeline import GradientSource, PipelineSettings, accelerometer_gravity_slope, run_pipeline
from roadload.io import import_log
from roadload.estimators.figures import plot_notched_boxplot, save
from roadload.sweep import run_sweep

GRADIENT_SOURCES: tuple[GradientSource, ...] = ("accelerometer", "grade_channel")
COMBINATIONS = [("M0", None)] + [("M3", e) for e in ESTIMATORS]
NOMINAL_MASS = 1400.0   # kg, the bmw_i3 preset: curb mass + driver


def evaluate_i3_trip(path: str) -> dict:
    """Sweep task: import one i3 CSV and evaluate M0 and M3 x 5 estimators, once with the gradient angle of
    eq. 5.2 (accelerometer) and once with the grade channel derived from elevation (the data set leaves open
    whether the accelerometer sees g sin θ; Munich is too flat for the test to decide on most trips)."""

    trip = import_log(path, "bmw-i3")
    knowledge = knowledge_for_trip(trip, "bmw_i3")
    payload = trip.meta.get("extra_payload_kg")
    true_mass = NOMINAL_MASS + payload if payload is not None else NOMINAL_MASS
    res = run_pipeline(trip, knowledge, until="decimated")
    slope = (accelerometer_gravity_slope(res.stages["decimated"]) if trip.has("grade") else float("nan"))
    medse: list[dict[str, Any]] = []
    mass: list[dict[str, Any]] = []
    masses: dict[tuple[str, str], float] = {}
    info: dict[str, Any] = {}
    for source in GRADIENT_SOURCES:
        if source == "grade_channel" and not trip.has("grade"):
            continue                                         # e.g. TripA04: frozen elevation, no grade
        ev = evaluate_trip(trip, knowledge, PipelineSettings(gradient=source), combinations=COMBINATIONS,
                           true_mass=true_mass, keep_estimates=True)
        medse += [dict(r, gradient=source) for r in ev.medse]
        mass += [dict(r, gradient=source) for r in ev.mass]
        for name, est in ev.estimates.items():
            if "m_V" in est.parameter_names and est.estimator:
                x = est.X[:, est.parameter_names.index("m_V")]
                half = x[x.size // 2:]                       # second half of the trip: past the transient
                masses[(source, name)] = float(np.median(half)) if half.size else float("nan")
        if not info:
            info = {"trip": ev.trip, "duration": trip.duration, "payload_kg": payload,
                    "accelerometer_gravity_slope": slope, **{k: v for k, v in ev.info.items() if k != "notes"},
                    "notes": "; ".join(ev.info.get("notes", []))}
    return {"medse": medse, "mass": mass, "masses": masses, "info": info}


def _arguments(argv: list[str] | None) -> argparse.Namespace:
    """The command line; --quick: 3 trips, 1 worker, a temporary output folder."""
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out", type=Path, default=Path("out/real_i3"))
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--limit", type=int, default=None)
    ap.add_argument("--quick", action="store_true", help="tiny run for CI: 3 trips, 1 worker, temporary output")
    args = ap.parse_args(argv)
    if args.quick:
        args.limit, args.workers = 3, 1
        args.out = Path(tempfile.mkdtemp(prefix="roadload-i3-"))
    return args


def _summary(info: pd.DataFrame, evaluated: int, failed: int) -> list[str]:
    """Report head: trips, hours, triggered share and the accelerometer test; its two findings are printed."""
    slopes = info["accelerometer_gravity_slope"]
    md = ["# Chapter 5 on the BMW i3 trips (real data)", "",
          f"{evaluated} trips evaluated, {failed} failed; {info['duration'].sum() / 3600:.1f} h; "
          f"triggered share of the 10 Hz samples: median {np.median(info['n_triggered'] / info['n_states']):.2f}.",
          "", f"Accelerometer test (slope of ẍ_CAN - v̇ over g sin θ from elevation, 20 s averages; 1 = sees "
          f"gravity, 0 = not): decided on {int(slopes.notna().sum())} of {len(info)} trips (the others are too "
          f"flat), median {np.nanmedian(slopes):.3f}, quartiles {np.nanpercentile(slopes, 25):.3f} / "
          f"{np.nanpercentile(slopes, 75):.3f}.", ""]
    print(md[2])
    print(md[4])
    return md


def _medse_section(medse: pd.DataFrame, source: str, order: list[str], out: Path) -> list[str]:
    """MEDSE per horizon for one gradient source: notch table (CSV + markdown) and boxplot; k = 900 printed."""
    md: list[str] = []
    ms = medse[medse["gradient"] == source].drop(columns="gradient")
    for k in HORIZONS:
        d = common_trips(ms[ms["horizon"] == k])
        if d.empty:
            continue
        tab = notch_table(d)
        tab["o"] = tab["combination"].map({c: i for i, c in enumerate(order)})
        tab = tab.sort_values("o").drop(columns="o")
        write_csv(out / f"medse_{source}_k{k}.csv", tab)
        md += [f"## MEDSE, k = {k} (m = {int(tab['m'].max())} trips with ≥ {MIN_TRAINING} training samples)",
               "", markdown_table(tab, floatfmt=".4g"), ""]
        save(plot_notched_boxplot(d, "medse", order=order, ylabel="MEDSE [N²]",
                                  title=f"BMW i3 ({source}), MEDSE, k = {k}, m = {int(tab['m'].max())}"),
             out / f"medse_boxplot_{source}_k{k}.png")
        if k == 900:
            print(f"\nMEDSE k = 900, gradient from {source} (m = {int(tab['m'].max())} trips)")
            print(tab.to_string(index=False, float_format=lambda x: f"{x:.4g}"))
    return md


def _mass_against_payload(ok: list[dict], info: pd.DataFrame, source: str, order: list[str]) -> pd.DataFrame:
    """Per combination: median mass estimate on the trips with and without a payload note, and their difference
    (the payload the estimator sees; also against the winter trips alone, as the noted trips are all winter)."""
    noted = info["payload_kg"].notna().to_numpy()
    winter = info["trip"].str.startswith("TripB").to_numpy()
    rows = []
    for c in order[1:]:
        est = np.array([v["masses"].get((source, c), np.nan) for v in ok])
        rows.append({"combination": c, "median_mass_no_note": float(np.nanmedian(est[~noted])),
                     "median_mass_noted": float(np.nanmedian(est[noted])),
                     "estimated_payload": float(np.nanmedian(est[noted]) - np.nanmedian(est[~noted])),
                     "estimated_payload_winter_only": float(np.nanmedian(est[noted])
                                                            - np.nanmedian(est[~noted & winter])),
                     "noted_payload_median": float(np.median(info.loc[noted, "payload_kg"]))})
    return pd.DataFrame(rows)


def _mass_section(ok: list[dict], info: pd.DataFrame, mass_rows: pd.DataFrame, source: str, order: list[str],
                  out: Path) -> list[str]:
    """Mass against the payload notes for one gradient source (CSV + markdown, printed) and the NMSE of the
    mass estimates on the noted trips."""
    noted = info["payload_kg"].notna().to_numpy()
    mass_tab = _mass_against_payload(ok, info, source, order)
    write_csv(out / f"mass_vs_payload_{source}.csv", mass_tab)
    noted_trips = set(info.loc[noted, "trip"])
    nm = mass_rows[(mass_rows["gradient"] == source) & mass_rows["trip"].isin(noted_trips)]
    nmse_tab = notch_table(nm, value="nmse") if not nm.empty else pd.DataFrame()
    md = ["## Mass against the payload notes", "",
          f"{int(noted.sum())} trips carry a payload note ({sorted(info.loc[noted, 'payload_kg'].tolist())} kg); "
          f"reference mass = {NOMINAL_MASS:.0f} kg (preset, with driver) + payload. Mass estimate per trip = "
          f"median over the second half of the trip.", "", markdown_table(mass_tab, floatfmt=".5g"), ""]
    print(f"\nmass vs payload notes, gradient from {source}")
    print(mass_tab.to_string(index=False, float_format=lambda x: f"{x:.1f}"))
    if not nmse_tab.empty:
        md += ["NMSE of the mass estimates (after the convergence test) on the noted trips:", "",
               markdown_table(nmse_tab, floatfmt=".5g"), ""]
        print(nmse_tab[["combination", "m", "median", "notch_low", "notch_high"]].to_string(
            index=False, float_format=lambda x: f"{x:.5f}"))
    return md


def main(argv: list[str] | None = None) -> None:
    """Evaluate the i3 trips (sweep), then write the tables, figures and report.md under --out."""
    args = _arguments(argv)
    try:
        folder = require_shared_data("bmw_i3_tum/data")
    except FileNotFoundError as exc:
        print(f"{exc}" + ("; skipped" if args.quick else ""), file=sys.stderr)
        sys.exit(0 if args.quick else 1)
    files = sorted(str(p) for p in folder.glob("Trip*.csv"))[: args.limit]
    outcomes = run_sweep(evaluate_i3_trip, files, workers=args.workers, description="BMW i3 trips")
    ok = [o.value for o in outcomes if o.ok]
    for o in outcomes:
        if not o.ok:
            print(f"failed: {Path(o.task).stem}: {o.error}")
    medse = pd.DataFrame([r for v in ok for r in v["medse"]])
    mass_rows = pd.DataFrame([r for v in ok for r in v["mass"]])
    info = pd.DataFrame([v["info"] for v in ok])
    out = args.out
    out.mkdir(parents=True, exist_ok=True)
    write_csv(out / "medse_per_trip.csv", medse)
    write_csv(out / "trips.csv", info)
    order = [combination_name(m, e) for m, e in COMBINATIONS]
    md = _summary(info, len(ok), len(outcomes) - len(ok))
    for source in GRADIENT_SOURCES:
        md += [f"# Gradient angle from: {source}", ""]
        md += _medse_section(medse, source, order, out)
        md += _mass_section(ok, info, mass_rows, source, order, out)
    md += ["# Trips", "", markdown_table(info.drop(columns=["notes"]), floatfmt=".4g"), ""]
    write_text(out / "report.md", "\n".join(md) + "\n")
    print(f"report: {out / 'report.md'}")
