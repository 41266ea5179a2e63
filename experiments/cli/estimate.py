"""CLI of the chapter-5 pipeline: ``roadload estimate TRIP`` and ``roadload benchmark fleet``.

Light at import (see the package docstring): the pipeline, the estimators, dask and matplotlib load inside the
commands, after the arguments and input files are checked."""

from __future__ import annotations

import os
import time
from pathlib import Path
from typing import Optional

import typer

from roadload.fileio import atomic_path
from roadload.units import unit_label

from .errors import fail, require_file



def _write_parquet(df, path: Path) -> None:
    with atomic_path(path) as tmp:
        df.to_parquet(tmp, index=False)


def estimate_command(
    trip: Path = typer.Argument(..., help="trip file (.parquet, a roadload Trip)"),
    model: str = typer.Option("M4", "--model", help="model structure: M0, M3, M4 or a registered one"),
    estimator: str = typer.Option("RRLM", "--estimator", help="RLS, RRLM, SGMKF, RGTLS, SGIVMKF (ignored for M0)"),
    out: Path = typer.Option(..., "--out", help="output Parquet: t, B, B̂, ΔB and the parameter traces"),
    vehicle: Optional[str] = typer.Option(None, "--vehicle", help="vehicle preset (default: from the trip)"),
    figures: Optional[Path] = typer.Option(None, "--figures", help="folder for stage/parameter figures (PNG)"),
) -> None:
    """Run the chapter-5 pipeline and one model-estimator combination over a trip."""
    if out.suffix != ".parquet":
        fail(f"--out must end in .parquet, got {out.name!r}")
    require_file(trip, "TRIP", (".parquet",))
    from roadload.estimators.evaluation import estimate
    from roadload.estimators.knowledge import knowledge_for_trip
    from roadload.estimators.models import ModelError, get_model
    from roadload.estimators.pipeline import PipelineError, model_data, run_pipeline
    from roadload.experiments.fleet import FleetError
    from roadload.trip import Trip, TripError

    try:
        t = Trip.load(trip)
        m = get_model(model)
        knowledge = knowledge_for_trip(t, vehicle)
        res = run_pipeline(t, knowledge)
        tt, A, B = model_data(res.states, m)
        if B.size == 0:
            fail(f"trip {res.name!r}: the trigger of section 5.3 is never true; nothing to estimate")
        est = estimate(tt, A, B, m, None if m.white_box else estimator, m.nominal_parameters(knowledge.nominal))
    except (TripError, ModelError, PipelineError, FleetError, ValueError) as exc:
        fail(str(exc))
        return
    frame = est.frame()
    _write_parquet(frame, out)
    last = frame.iloc[-1]
    typer.echo(f"{res.name}: {est.name}, {B.size} triggered samples of {len(res.states)} at 10 Hz")
    for p, u in zip(m.parameter_names, m.parameter_units):
        typer.echo(f"  {p:>18s} = {last[p]:.6g} {unit_label(u)}")
    for n in res.notes:
        typer.echo(f"  note: {n}")
    typer.echo(f"wrote {out}")
    if figures is not None:
        from roadload.estimators.figures import plot_output_corrections, plot_parameter_traces, plot_stage, save

        save(plot_stage(res, "states"), figures / "states.png")
        save(plot_parameter_traces({est.name: est}), figures / "parameters.png")
        if est.estimator:
            save(plot_output_corrections({est.name: est}), figures / "output_corrections.png")
        typer.echo(f"figures in {figures}")


def benchmark_fleet_command(
    out: Path = typer.Option(..., "--out", help="output folder: tables (CSV + report.md) and figures (PNG)"),
    trips: Optional[int] = typer.Option(None, "--trips", help="number of fleet trips (default 84)"),
    scheduler: Optional[str] = typer.Option(None, "--scheduler", help="Dask scheduler address (default: local)"),
    workers: Optional[int] = typer.Option(None, "--workers", help="local worker processes (default: all cores)"),
    cache: Optional[Path] = typer.Option(None, "--cache", help="folder of the stored fleet trips "
                                         "(default: $ROADLOAD_CACHE/fleet-SEED-N or ~/.cache/roadload/...)"),
    seed: int = typer.Option(2012, "--seed", help="fleet seed"),
    hours: Optional[float] = typer.Option(None, "--hours", help="total fleet duration [h] (default: 20 h for "
                                          "84 trips, proportionally less for fewer)"),
    figures: bool = typer.Option(True, "--figures/--no-figures", help="write PNG figures"),
) -> None:
    """Chapter-5 benchmark over the simulated fleet (generated into the cache when absent)."""
    n = trips or 84
    if n < 1:
        fail(f"--trips must be >= 1, got {n}")
    total = hours if hours is not None else 20.0 * n / 84
    if not total > 0:
        fail(f"--hours must be > 0, got {total}")
    from roadload.experiments.fleet import (FleetError, generate_fleet, run_benchmark, single_trip_figures,
                                            stored_trips, write_report)

    base = Path(os.environ.get("ROADLOAD_CACHE", Path.home() / ".cache" / "roadload"))
    folder = cache or base / f"fleet-{seed}-{n}"
    try:
        plan_file = folder / "plan.json"
        if not plan_file.exists() or len(list(folder.glob("*.parquet"))) < n:
            typer.echo(f"generating the fleet ({n} trips, ~{total:.1f} h) into {folder} ...")
            t0 = time.perf_counter()
            gen = generate_fleet(folder, n, seed, total, scheduler=scheduler, workers=workers)
            typer.echo(f"generated {len(gen['trips'])} trips in {time.perf_counter() - t0:.1f} s"
                       + (f", {len(gen['failed'])} failed" if gen["failed"] else ""))
            for name, err in gen["failed"]:
                typer.secho(f"  failed: {name}: {err}", fg=typer.colors.YELLOW)
        paths = stored_trips(folder, n)
        res = run_benchmark(paths, scheduler=scheduler, workers=workers)
    except (FleetError, ValueError) as exc:
        fail(str(exc))
        return
    report = write_report(res, out, figures=figures,
                          title=f"chapter-5 benchmark, fleet seed {seed}, {len(paths)} trips")
    if figures and not res.trips.empty:
        # figures 5.4-5.8 for one trip: the longest one with outliers (else the longest)
        info = res.trips.sort_values("duration", ascending=False)
        pick = info[info["outliers"].astype(bool)] if info["outliers"].astype(bool).any() else info
        name = str(pick.iloc[0]["trip"])
        single_trip_figures(next(p for p in paths if p.stem == name), out / "single_trip")
    t = res.timing
    typer.echo(f"{len(res.trips)} trips evaluated, {len(res.failed)} failed")
    for name, err in res.failed:
        typer.secho(f"  failed: {name}: {err}", fg=typer.colors.YELLOW)
    typer.echo(f"time [s]: wall {t['wall']:.1f}; summed over workers: loading {t['loading']:.1f}, preprocessing "
               f"{t['preprocessing']:.1f}, estimation {t['estimation']:.1f}, evaluation {t['evaluation']:.1f}")
    typer.echo(report.read_text().split("## Findings of the text")[-1].strip())
    typer.echo(f"report: {report}")


def register(app: typer.Typer, benchmark_app: typer.Typer) -> None:
    app.command("estimate")(estimate_command)
    benchmark_app.command("fleet")(benchmark_fleet_command)
