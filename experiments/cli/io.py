"""``roadload import`` (real logs -> Trip Parquet), ``roadload export`` (Trip -> MDF4 / CSV / MATLAB),
``roadload export-can`` (Trip -> CAN log + DBC + mapping) and ``roadload convert`` (older trip files -> the current
open format).

Light at import (see the package docstring): the loaders, asammdf and scipy load inside the commands, after the
arguments and input files are checked."""

from __future__ import annotations

from pathlib import Path

import typer

from .errors import CliInputError, choose, fail, require_file

#: import formats: roadload.io.mapping.FORMATS, repeated here so that the help and a refused format need not import
#: the mapping layer (tests/experiments/cli/test_startup.py checks they agree); and the default mapping per format
IMPORT_FORMATS = ("dbc-mf4", "candump", "blf", "asc", "comma2k19", "bmw-i3", "openxc", "csv", "mf4")
DEFAULT_MAPPING_HELP = ("mapping JSON file or packaged name (default per format: csv -> plain_csv, dbc-mf4 -> "
                        "canedge_gnss_obd, comma2k19 -> comma2k19_rav4, bmw-i3 -> bmw_i3, openxc -> openxc, mf4 -> "
                        "signals named like roadload channels; candump, blf, asc need one)")
EXPORT_FORMATS = ("mf4", "csv", "mat")
CAN_FORMATS = ("candump", "blf", "mf4", "asc")
PRECISIONS = ("compact", "exact", "packed")  # roadload.trip_storage.PRECISIONS (checked by the same test)


def _check_mapping(mapping: str) -> None:
    """A mapping file or packaged mapping name that exists and parses (the whole schema) -- before the log is read."""
    from roadload.io.mapping import load_mapping

    load_mapping(mapping)


def _progress():
    """A transient rich progress bar on stderr (redraw it at every reported stage: ``refresh=True``)."""
    from rich.console import Console
    from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn

    return Progress(TextColumn("{task.description}"), BarColumn(), TimeElapsedColumn(),
                    console=Console(stderr=True, markup=False, highlight=False, soft_wrap=True), transient=True)


def register(app: typer.Typer, benchmark_app: typer.Typer) -> None:
    @app.command("import")
    def import_cmd(
        source: Path = typer.Argument(..., help="log file or folder (MF4 session folder, comma2k19 segment)"),
        fmt: str = typer.Option(..., "--format", "-f", help=f"one of {', '.join(IMPORT_FORMATS)}"),
        mapping: str = typer.Option(None, "--mapping", "-m", help=DEFAULT_MAPPING_HELP),
        out: Path = typer.Option(..., "--out", "-o", help="output trip .parquet"),
        dbc: list[Path] = typer.Option([], "--dbc", help="extra DBC file for CAN formats (repeatable)"),
        strict: bool = typer.Option(False, "--strict", help="refuse a log with malformed lines (default: leave "
                                    "them out and list their line numbers in the import report)"),
    ) -> None:
        """Import a real log into a Trip (SI channels on a uniform time base, import report in the metadata)."""
        choose(fmt, IMPORT_FORMATS, "--format", "import format")
        if not source.exists():
            require_file(source, "SOURCE")
        if out.suffix != ".parquet":
            fail(f"--out: trip files end in .parquet, got {out.name!r}")
        for extra in dbc:
            require_file(extra, "--dbc", (".dbc",))
        if mapping is not None:
            _check_mapping(mapping)

        from rich.console import Console

        from roadload.io.importer import import_log
        from roadload.io.report import ImportReport

        console = Console(stderr=True, markup=False, highlight=False, soft_wrap=True)
        with _progress() as bar:
            task = bar.add_task(f"import {source.name}", total=1.0)

            def progress(stage: str, fraction: float) -> None:
                bar.update(task, completed=fraction, description=f"import {source.name}: {stage}", refresh=True)

            trip = import_log(source, fmt, mapping, dbc=list(dbc), progress=progress, strict=strict)
        path = trip.save(out)
        report = ImportReport.from_dict(trip.meta["import_report"])
        console.print(f"{len(trip)} samples x {len(trip.channels)} channels, {trip.duration:.1f} s at "
                      f"{trip.meta['sample_rate']:g} Hz -> {path}")
        if trip.meta.get("clock"):
            c = trip.meta["clock"]
            console.print(f"clock aligned on {c['reference']}: offset {c['offset_s']:+.3f} s, "
                          f"drift {c['drift_ppm']:+.1f} ppm")
        console.print(report.summary())

    @app.command("export")
    def export_cmd(
        trip_path: Path = typer.Argument(..., metavar="TRIP", help="trip .parquet"),
        fmt: str = typer.Option(..., "--format", "-f", help="mf4 (ASAM MDF4, asammdf), csv (units row) or mat "
                                                            "(MATLAB)"),
        out: Path = typer.Option(None, "--out", "-o", help="output file (default: the trip's name with the "
                                                           "format's suffix, next to it)"),
        truth: bool = typer.Option(False, "--truth", help="also the ground truth of a simulated trip (columns "
                                                          "truth/<name>)"),
    ) -> None:
        """Export a Trip for other tools: ASAM MDF4 (asammdf, units per channel), CSV with a units row, or MATLAB
        .mat."""
        choose(fmt, EXPORT_FORMATS, "--format", "export format")
        require_file(trip_path, "TRIP", (".parquet",))
        target = out if out is not None else trip_path.with_suffix("." + fmt)
        if target.suffix.lower() != "." + fmt:
            fail(f"--out: a {fmt} export ends in .{fmt}, got {target.name!r}")

        from roadload.io.export import export_file
        from roadload.trip import Trip

        trip = Trip.load(trip_path, truth_channels=None if truth else [])
        path = export_file(trip, target, fmt, truth=truth)
        typer.echo(f"wrote {path}: {len(trip.channels)} channels" + (f" + {len(trip.truth.columns) - 1} truth "
                                                                      f"channels" if truth and trip.truth is not None
                                                                      else "") + f", {len(trip)} samples")

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
        choose(fmt, CAN_FORMATS, "--format", "CAN log format")
        require_file(trip_path, "TRIP", (".parquet",))
        names = None
        if channels is not None:
            names = [c.strip() for c in channels.split(",") if c.strip()]
            if not names:
                raise CliInputError(f"--channels: no channel named in {channels!r} (leave the option out for all)")
        sensors = None
        if vehicle is not None:
            from roadload.presets import PRESETS, get_preset

            sensors = get_preset(choose(vehicle, PRESETS, "--vehicle", "vehicle preset")).sensors

        from roadload.io.export import export_trip
        from roadload.trip import Trip

        trip = Trip.load(trip_path, truth_channels=[])
        if names is not None:
            for name in names:
                choose(name, trip.channels, "--channels", "channel of the trip")
        paths = export_trip(trip, out or trip_path.with_suffix(""), fmt, channels=names, sensors=sensors)
        for kind, p in paths.items():
            typer.echo(f"{kind}: {p}")

    @app.command("convert")
    def convert_cmd(
        source: Path = typer.Argument(..., help="trip .parquet of any format roadload reads"),
        out: Path = typer.Option(..., "--out", "-o", help="output trip .parquet (a new file)"),
        precision: str = typer.Option(None, help="compact | exact | packed (default: compact for files written "
                                                 "compact or packed, else exact)"),
    ) -> None:
        """Rewrite a trip file of an older format (or another precision) as the current open Parquet format."""
        require_file(source, "SOURCE", (".parquet",))
        if out.suffix != ".parquet":
            fail(f"--out: trip files end in .parquet, got {out.name!r}")
        if precision is not None:
            choose(precision, PRECISIONS, "--precision", "storage precision")

        from roadload.trip import Trip, convert_trip_file

        before = Trip.read_info(source)
        path = convert_trip_file(source, out, precision)
        after = Trip.read_info(path)
        typer.echo(f"wrote {path}: format {before['version']} ({before['precision']}, "
                   f"{source.stat().st_size / 1e6:.1f} MB) -> format {after['version']} ({after['precision']}, "
                   f"{path.stat().st_size / 1e6:.1f} MB), {after['n_measured']} samples")
