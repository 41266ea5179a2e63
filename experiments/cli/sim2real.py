"""``roadload diagnose``, ``roadload calibrate``, ``roadload sim2real selftest`` and ``roadload sim2real inject``.

Light at import (see the package docstring): roadload.sim2real, the simulator and the test worlds load inside the
commands, after the arguments are checked."""

from __future__ import annotations

from pathlib import Path
from typing import Optional

import typer

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
    from roadload.io import import_log
    from roadload.io.report import LogImportError
    from roadload.sim2real.errors import DiagnosisError
    from roadload.trip import Trip

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
                msg = str(exc)      # the importer's message names the file already
                raise DiagnosisError(msg if (str(f) in msg or f.name in msg) else f"{f}: {msg}") from None
        else:
            trips.append(Trip.load(f))
    return trips


def withheld(trips: list, channels: str | None) -> list:
    """The trips without the comma-separated measured ``channels`` (``--drop-channels``; e.g. the logged heater and
    air-conditioning power, to see whether the diagnosis finds the load they draw)."""
    names = [c.strip() for c in (channels or "").split(",") if c.strip()]
    if not names:
        return trips
    out = []
    for t in trips:
        c = t.copy()
        drop = [n for n in names if c.has(n)]
        c.measured = c.measured.drop(columns=drop)
        for n in drop:
            c.units.pop(n, None)
        out.append(c)
    return out


def _progress(console, label: str):
    """A Rich progress bar and the (stage, fraction) callback that moves it."""
    from rich.progress import Progress

    bar = Progress(console=console)
    task = bar.add_task(label, total=1.0)
    return bar, (lambda what, frac: bar.update(task, completed=frac, description=what))


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
        drop_channels: Optional[str] = typer.Option(None, "--drop-channels",
                                                    help="comma-separated channels withheld from the trips, e.g. "
                                                         "heating_power,aircon_power"),
        more: Optional[list[Path]] = typer.Argument(None, help="further trips (so '--real A B C' works)"),
    ) -> None:
        """Diagnose where a sim departs from recorded trips, which effect explains it, how far the gap shrinks.

        Against a calibrated sim (roadload calibrate), the effects are what differs from the reference trips."""
        from rich.console import Console

        from roadload.sim2real.catalog import DEFAULT_CANDIDATES
        from roadload.sim2real.diagnose import DiagnosisSettings, diagnose
        from roadload.sim2real.errors import DiagnosisError
        from roadload.sim2real.report import write_report
        from roadload.sim2real.simconfig import SimConfig
        from roadload.sim2real.report import why_none

        console = Console(soft_wrap=True)
        try:
            cfg = SimConfig.load(sim)
            trips = withheld(load_trips(list(real) + list(more or []), fmt, mapping), drop_channels)
            cands = tuple(c.strip() for c in candidates.split(",") if c.strip()) if candidates else DEFAULT_CANDIDATES
            if not floor_duration >= 60.0:
                raise DiagnosisError(f"--floor-duration must be at least 60 s, got {floor_duration} s")
            settings = DiagnosisSettings(candidates=cands, seed=seed, resimulate=resimulate,
                                         strict_candidates=candidates is not None, base_first=base_first,
                                         floor_duration=floor_duration)
            bar, step = _progress(console, "diagnosis")
            with bar:
                diag = diagnose(trips, cfg, settings, progress=step)
            paths = write_report(diag, out)
        except (DiagnosisError, ValueError) as exc:
            fail(describe(exc))
        for imp in diag.notes.implausible:
            console.print(f"[yellow]not accepted, implausible:[/yellow] {imp.effect}: {imp.reason}")
        for row in diag.base.parameters:
            console.print(f"base: {row.name} {row.value:+.4g} ± {row.std_error:.2g} {row.unit}"
                          + ("  (significant)" if row.significant else ""), markup=False)
        eff = ", ".join(diag.identified) or "none"
        console.print(f"identified: {eff}; held-out force RMSE {diag.gap_before.force_residual.rmse:.1f} -> "
                      f"{diag.gap_after.force_residual.rmse:.1f} N; unexplained: {diag.unexplained.present}")
        if not diag.effects:
            console.print(f"force side: {why_none(diag, 'force')}", markup=False)
        if diag.energy is not None and not diag.energy.effects:
            console.print(f"energy side: {why_none(diag, 'energy')}", markup=False)
        console.print(f"wrote {paths['report']}, {paths['json']}", markup=False)

    @app.command("calibrate")
    def calibrate_cmd(
        sim: str = typer.Option(..., "--sim", help="the sim to start from: a preset name, a sim config JSON or a "
                                                   "vehicle spec JSON"),
        real: list[Path] = typer.Option(..., "--real", help="reference trips taken under known conditions (Trip "
                                                            ".parquet, or raw logs with --format); folders expand"),
        out: Path = typer.Option(..., "--out", help="the calibrated vehicle spec (.json); its report, record and "
                                                    "figure are written beside it"),
        fmt: Optional[str] = typer.Option(None, "--format", "-f", help="import format of raw logs, as for "
                                                                       "'roadload import' (csv, bmw-i3, ...)"),
        mapping: Optional[str] = typer.Option(None, "--mapping", "-m",
                                              help="mapping JSON file or packaged name (csv default: plain_csv)"),
        seed: int = typer.Option(0, help="seed of the training / held-out split"),
        floor_duration: float = typer.Option(900.0, help="seconds of the sim's own trips per floor road"),
        drop_channels: Optional[str] = typer.Option(None, "--drop-channels",
                                                    help="comma-separated channels withheld from the trips"),
        more: Optional[list[Path]] = typer.Argument(None, help="further trips (so '--real A B C' works)"),
    ) -> None:
        """Calibrate the sim's base vehicle to reference trips and write it as a vehicle spec.

        Fits mass, road load, drive-train efficiency, inertia, brakes, motor losses, torque signal and auxiliary
        power; diagnose --sim, simulate --vehicle and the MPC's force models read the spec; reports how far the
        held-out gap shrinks."""
        from rich.console import Console

        from roadload.sim2real.calibrate import CalibrationSettings, calibrate
        from roadload.sim2real.errors import DiagnosisError
        from roadload.sim2real.report import calibration_paths, write_calibration
        from roadload.sim2real.simconfig import SimConfig

        console = Console(soft_wrap=True)
        try:
            paths = calibration_paths(out)
            if not floor_duration >= 60.0:
                raise DiagnosisError(f"--floor-duration must be at least 60 s, got {floor_duration} s")
            cfg = SimConfig.load(sim)
            trips = withheld(load_trips(list(real) + list(more or []), fmt, mapping), drop_channels)
            bar, step = _progress(console, "calibration")
            with bar:
                cal = calibrate(trips, cfg, CalibrationSettings(seed=seed, floor_duration=floor_duration),
                                progress=step)
            paths = write_calibration(cal, out)
        except (DiagnosisError, ValueError) as exc:
            fail(describe(exc))
        for p in cal.parameters:
            console.print(f"{p.name:32s} {p.sim:10.4g} -> {p.calibrated:10.4g} ± {p.calibrated_std:.2g} "
                          f"{p.value_unit}" + (f"  ({p.flag})" if p.flag else ""), markup=False)
        h = cal.heldout
        console.print(f"held-out force RMSE {h.force_before:.1f} -> {h.force_after:.1f} N "
                      f"({100 * h.force_shrinkage:.0f} % shrinkage); battery power RMSE {h.power_before:.0f} -> "
                      f"{h.power_after:.0f} W", markup=False)
        console.print(f"wrote {paths['spec']} (diagnose --sim / simulate --vehicle), {paths['report']}, "
                      f"{paths['figure']}", markup=False)

    @s2r.command("selftest")
    def selftest_cmd(
        world: str = typer.Option("roadload", "--world", help="roadload | fastsim | independent | fastsim_conv | real "
                                                              "(effects injected into the real i3 trips)"),
        seeds: str = typer.Option("0", "--seeds", help="comma-separated seeds"),
        vehicle: Optional[str] = typer.Option(None, help="a shipped preset as the sim (unmatched); default: the "
                                                         "vehicle matched to the world"),
        duration: float = typer.Option(900.0, help="seconds per trip (3 trips per case)"),
        effects: Optional[str] = typer.Option(None, help="comma-separated withheld effects (default: all; the "
                                                         "real world: EFFECT:SIZE, e.g. aux_load:1500)"),
        out: Optional[Path] = typer.Option(None, help="write selftest.json here"),
    ) -> None:
        """Withheld effects identified blind on a test world; nothing withheld and an effect outside the catalog
        must give no acceptance. Prints the confusion table per seed and the summary."""
        from rich.console import Console

        from roadload.experiments.sim2real.selftest import WORLD_NAMES, print_run, run_world
        from roadload.fileio import write_json

        console = Console(soft_wrap=True)
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

    @s2r.command("inject")
    def inject_cmd(
        real: list[Path] = typer.Option(..., "--real", help="recorded trips (Trip .parquet, or raw logs with "
                                                            "--format); folders expand"),
        effect: str = typer.Option(..., "--effect", help="one of accel_bias, aux_load, latency, "
                                                         "speed_scale, torque_gain, torque_offset"),
        size: float = typer.Option(..., "--size", help="the effect's size in its unit: aux_load W, torque_gain 1, "
                                                       "torque_offset N*m, accel_bias m/s^2, latency s, "
                                                       "speed_scale 1"),
        out: Path = typer.Option(..., "--out", help="folder for the injected copies (Trip .parquet)"),
        channel: Optional[str] = typer.Option(None, help="the delayed channel of latency (default drive_torque)"),
        fmt: Optional[str] = typer.Option(None, "--format", "-f", help="import format of raw logs"),
        mapping: Optional[str] = typer.Option(None, "--mapping", "-m", help="mapping JSON file or packaged name"),
        more: Optional[list[Path]] = typer.Argument(None, help="further trips"),
    ) -> None:
        """Write copies of recorded trips with an effect of known size added to the logged channels (auxiliary
        load into the battery current, drive-torque gain or offset, accelerometer bias, a channel latency,
        speed-signal scale): diagnosed against a calibration of the trips as logged, it must be named."""
        from rich.console import Console

        from roadload.sim2real.errors import DiagnosisError
        from roadload.sim2real.inject import INJECTIONS, inject

        console = Console(soft_wrap=True)
        try:
            trips = load_trips(list(real) + list(more or []), fmt, mapping)
            copies = [inject(t, effect, size, channel) for t in trips]    # all checked before anything is written
            out.mkdir(parents=True, exist_ok=True)
            written = [c.save(out / f"{c.meta['name']}.parquet") for c in copies]
        except (DiagnosisError, ValueError) as exc:
            fail(describe(exc))
        console.print(f"wrote {len(written)} trips with {effect} = {size:g} {INJECTIONS[effect].unit} into {out}",
                      markup=False)
