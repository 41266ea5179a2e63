"""``roadload diagnose`` and ``roadload sim2real selftest``."""

from __future__ import annotations

from pathlib import Path
from typing import Optional

import typer
from roadload.trip import Trip
from roadload.sim2real.errors import DiagnosisError
from roadload.sim2real.catalog import DEFAULT_CANDIDATES
from roadload.sim2real.diagnose import DiagnosisSettings, diagnose
from roadload.sim2real.report import write_report
from roadload.sim2real.simconfig import SimConfig
from roadload.experiments.sim2real.selftest import WORLD_NAMES, print_run, run_world
from roadload.fileio import write_json
from roadload.io import import_log
from roadload.io.report import LogImportError

from .errors import describe, fail


# file endings of trip files per import format (a folder given to --real yields these only)
TRIP_SUFFIXES = {None: (".parquet",), "csv": (".csv",), "bmw-i3": (".csv",), "openxc": (".json", ".txt"),
                 "dbc-mf4": (".mf4",), "candump": (".log", ".txt"), "blf": (".blf",), "asc": (".asc",),
                 "comma2k19": (".log", ".bz2")}
DEFAULT_CSV_MAPPING = "plain_csv"


def _is_trip_file(path: Path, fmt: str | None) -> bool:
    suffixes = TRIP_SUFFIXES.get(fmt, (".parquet", ".csv", ".mf4", ".log", ".blf", ".asc", ".json", ".txt"))
    if path.suffix.lower() not in suffixes:
        return False
    if path.suffix.lower() == ".json":     # mapping / vehicle / truth JSON beside the logs are no trips
        head = path.read_text(encoding="utf-8", errors="replace")[:64].lstrip()
        return not head.startswith(("{", "["))
    return True


def load_trips(paths: list[Path], fmt: str | None, mapping: str | None = None) -> list:
    """Trips from Trip Parquet files, or raw logs through ``roadload.io.import_log`` when ``fmt`` is given (e.g.
    'csv' with ``mapping``, default the packaged plain_csv mapping; 'bmw-i3'). A folder yields its trip files
    only (:data:`TRIP_SUFFIXES` of the format; JSON documents such as mappings or vehicle files are skipped)."""
    if mapping is not None and not fmt:
        raise DiagnosisError("--mapping needs --format (the import format of the raw logs, e.g. csv)")
    files: list[Path] = []
    for p in paths:
        if p.is_dir():
            files += sorted(q for q in p.iterdir() if q.is_file() and _is_trip_file(q, fmt))
        elif p.exists():
            files.append(p)
        else:
            raise DiagnosisError(f"no trip file at {p}")
    if not files:
        want = ", ".join(TRIP_SUFFIXES.get(fmt, ()))
        raise DiagnosisError(f"no trip files ({want}) in {[str(p) for p in paths]}"
                             + ("" if fmt else "; raw logs need --format (and --mapping for csv)"))
    if fmt == "csv" and mapping is None:
        mapping = DEFAULT_CSV_MAPPING
    trips = []
    for f in files:
        if fmt:
            try:
                trips.append(import_log(f, fmt, mapping))
            except LogImportError as exc:
                raise DiagnosisError(f"{f}: {exc}") from None
        else:
            trips.append(Trip.load(f))
    return trips


def register(app: typer.Typer, benchmark_app: typer.Typer) -> None:
    s2r = typer.Typer(help="Sim-to-real gap diagnosis.", no_args_is_help=True)
    app.add_typer(s2r, name="sim2real")

    @app.command("diagnose")
    def diagnose_cmd(
        sim: str = typer.Option(..., "--sim", help="sim config JSON (vehicle + effects) or a preset name"),
        real: list[Path] = typer.Option(..., "--real", help="recorded trips (Trip .parquet, or raw logs with "
                                                            "--format); folders expand"),
        out: Path = typer.Option(..., "--out", help="output folder: report.md, diagnosis.json, PNG figures"),
        candidates: Optional[str] = typer.Option(None, "--candidates", help="comma-separated candidate effects "
                                                                            "(default: the whole catalog)"),
        fmt: Optional[str] = typer.Option(None, "--format", "-f", help="import format of raw logs, as for "
                                                                       "'roadload import' (csv, bmw-i3, ...)"),
        mapping: Optional[str] = typer.Option(None, "--mapping", "-m",
                                              help="mapping JSON file or packaged name (csv default: plain_csv)"),
        seed: int = typer.Option(0, help="seed of the split and the bootstrap"),
        resimulate: bool = typer.Option(True, help="re-run the sim with the identified effects switched on"),
        base_first: bool = typer.Option(False, "--base-first", help="select effects over the calibrated base "
                                                                   "(mass, drag area, rolling resistance, "
                                                                   "drive-train efficiency, brake gain): for a "
                                                                   "preset that does not match the car"),
        floor_duration: float = typer.Option(900.0, help="seconds of the sim's own trips per floor road"),
        more: Optional[list[Path]] = typer.Argument(None, help="further trips (so '--real A B C' works)"),
    ) -> None:
        """Diagnose where a sim departs from recorded trips, which effect explains it, how far the gap shrinks."""
        from rich.console import Console
        from rich.progress import Progress


        console = Console()
        try:
            cfg = SimConfig.load(sim)
            trips = load_trips(list(real) + list(more or []), fmt, mapping)
            cands = tuple(c.strip() for c in candidates.split(",") if c.strip()) if candidates else DEFAULT_CANDIDATES
            if not floor_duration >= 60.0:
                raise DiagnosisError(f"--floor-duration must be at least 60 s, got {floor_duration} s")
            settings = DiagnosisSettings(candidates=cands, seed=seed, resimulate=resimulate,
                                         strict_candidates=candidates is not None, base_first=base_first,
                                         floor_duration=floor_duration)
            with Progress(console=console) as bar:
                task = bar.add_task("diagnosis", total=1.0)
                diag = diagnose(trips, cfg, settings,
                                progress=lambda what, frac: bar.update(task, completed=frac, description=what))
            paths = write_report(diag, out)
        except (DiagnosisError, ValueError) as exc:
            fail(describe(exc))
        for imp in diag.notes.implausible:
            console.print(f"[yellow]not accepted, implausible:[/yellow] {imp.effect}: {imp.reason}")
        for row in diag.base.parameters:
            console.print(f"base: {row.name} {row.value:+.4g} ± {row.std_error:.2g} {row.unit}"
                          + ("  (significant)" if row.significant else ""))
        eff = ", ".join(diag.identified) or "none"
        console.print(f"identified: {eff}; held-out force RMSE {diag.gap_before.force_residual.rmse:.1f} -> "
                      f"{diag.gap_after.force_residual.rmse:.1f} N; unexplained: {diag.unexplained.present}")
        console.print(f"wrote {paths['report']}, {paths['json']}")

    @s2r.command("selftest")
    def selftest_cmd(
        world: str = typer.Option("roadload", "--world", help="roadload | fastsim | independent"),
        seeds: str = typer.Option("0", "--seeds", help="comma-separated seeds"),
        vehicle: Optional[str] = typer.Option(None, help="a shipped preset as the sim (unmatched); default: the "
                                                         "vehicle matched to the world"),
        duration: float = typer.Option(900.0, help="seconds per trip (3 trips per case)"),
        effects: Optional[str] = typer.Option(None, help="comma-separated withheld effects (default: all)"),
        out: Optional[Path] = typer.Option(None, help="write selftest.json here"),
    ) -> None:
        """Withheld effects identified blind on a test world; nothing withheld and an effect outside the catalog
        must give no acceptance. Prints the confusion table per seed and the summary."""
        from rich.console import Console

        console = Console()
        if world not in WORLD_NAMES:
            fail(f"--world: unknown world {world!r}; choose one of {', '.join(WORLD_NAMES)}")
        try:
            seed_list = [int(x) for x in seeds.split(",") if x.strip()]
        except ValueError:
            fail(f"--seeds must be comma-separated integers, got {seeds!r}")
        names = [e.strip() for e in effects.split(",") if e.strip()] if effects else None
        run = run_world(world, seed_list, names, duration, vehicle=vehicle, say=console.print)
        print_run(run, seed_list, say=console.print)
        if out is not None:
            write_json(out / "selftest.json", run.to_dict(), default=float)
