"""``roadload import`` (real logs -> Trip Parquet) and ``roadload export-can`` (Trip -> CAN log + DBC + mapping)."""

from __future__ import annotations

from pathlib import Path

import typer
from rich.console import Console
from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn

from roadload.trip import Trip, TripError
from roadload.io.importer import import_log
from roadload.io.mapping import FORMATS
from roadload.io.report import ImportReport, LogImportError
from roadload.io.export import export_trip
from roadload.presets import get_preset

from .errors import describe, fail


def _fail(exc: Exception) -> None:
    fail(describe(exc))


def register(app: typer.Typer, benchmark_app: typer.Typer) -> None:
    @app.command("import")
    def import_cmd(
        source: Path = typer.Argument(..., help="log file or folder (MF4 session folder, comma2k19 segment)"),
        fmt: str = typer.Option(..., "--format", "-f", help=f"one of {', '.join(FORMATS)}"),
        mapping: str = typer.Option(None, "--mapping", "-m",
                                    help="mapping JSON file or packaged name (default per format: "
                                         "dbc-mf4 -> canedge_gnss_obd, comma2k19 -> comma2k19_rav4, "
                                         "bmw-i3 -> bmw_i3, openxc -> openxc)"),
        out: Path = typer.Option(..., "--out", "-o", help="output trip .parquet"),
        dbc: list[Path] = typer.Option([], "--dbc", help="extra DBC file for CAN formats (repeatable)"),
        strict: bool = typer.Option(False, "--strict", help="refuse a log with malformed lines (default: leave "
                                    "them out and list their line numbers in the import report)"),
    ) -> None:
        """Import a real log into a Trip (SI channels on a uniform time base, import report in the metadata)."""
        console = Console(stderr=True, markup=False, highlight=False, soft_wrap=True)
        try:
            with Progress(TextColumn("{task.description}"), BarColumn(), TimeElapsedColumn(),
                          console=console, transient=True) as bar:
                task = bar.add_task(f"import {source.name}", total=1.0)

                def progress(stage: str, fraction: float) -> None:
                    bar.update(task, completed=fraction, description=f"import {source.name}: {stage}")

                trip = import_log(source, fmt, mapping, dbc=list(dbc), progress=progress, strict=strict)
            path = trip.save(out)
        except (LogImportError, TripError, FileNotFoundError) as exc:
            _fail(exc)
        report = ImportReport.from_dict(trip.meta["import_report"])
        console.print(f"{len(trip)} samples x {len(trip.channels)} channels, {trip.duration:.1f} s at "
                      f"{trip.meta['sample_rate']:g} Hz -> {path}")
        if trip.meta.get("clock"):
            c = trip.meta["clock"]
            console.print(f"clock aligned on {c['reference']}: offset {c['offset_s']:+.3f} s, "
                          f"drift {c['drift_ppm']:+.1f} ppm")
        console.print(report.summary())

    @app.command("export-can")
    def export_can_cmd(
        trip_path: Path = typer.Argument(..., metavar="TRIP", help="trip .parquet (e.g. a simulated trip)"),
        fmt: str = typer.Option("candump", "--format", "-f", help="candump | blf | mf4 | asc"),
        out: Path = typer.Option(None, "--out", "-o", help="output log (default: next to the trip)"),
        channels: str = typer.Option(None, help="comma-separated channels (default: all measured channels)"),
        vehicle: str = typer.Option(None, help="vehicle preset whose sensor set gives resolutions and rates "
                                               "(default: the sensor spec in the trip's metadata, if any)"),
    ) -> None:
        """Write a Trip as CAN traffic: log + project DBC (scales = sensor quantisation) + import mapping."""

        try:
            trip = Trip.load(trip_path)
            target = out or trip_path.with_suffix("")
            names = [c.strip() for c in channels.split(",")] if channels else None
            sensors = None
            if vehicle:
                sensors = get_preset(vehicle).sensors
            paths = export_trip(trip, target, fmt, channels=names, sensors=sensors)
        except (LogImportError, TripError, FileNotFoundError, ValueError) as exc:
            _fail(exc)
        for kind, p in paths.items():
            typer.echo(f"{kind}: {p}")
