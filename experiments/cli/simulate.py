"""``roadload simulate``, ``roadload plot``, ``roadload effects`` and ``roadload benchmark simulator``.

Light at import (see the package docstring): the simulator, the road generators and matplotlib load inside the
commands, after the arguments and input files are checked."""

from __future__ import annotations

import json
from pathlib import Path

import typer

from roadload.presets import PRESETS

from .errors import CliInputError, choose, fail, require_file
from .io import PRECISIONS

#: ambient temperatures the simulator's air-density and tire/oil models are meant for [degC]
AMBIENT_RANGE_C = (-60.0, 60.0)
PRECISION_HELP = ("trip file storage: 'compact' (SI floats, float32 on the sensor grid, truth to 15 significant "
                  "bits; ~13 MB per simulated hour), 'exact' (every value bit for bit, ~5x larger) or 'packed' "
                  "(roadload's private integer codec: 2 % smaller, but other tools read integer codes, not SI values)")


def check_vehicle(text: str, option: str = "--vehicle") -> None:
    """A preset name (did you mean) or an existing vehicle JSON file."""
    if text in PRESETS:
        return
    if text.endswith(".json") or Path(text).exists() or "/" in text:
        require_file(Path(text), option, (".json",))
        return
    choose(text, PRESETS, option, "vehicle preset", f"presets: {', '.join(PRESETS)}, or a vehicle .json file")


def check_road(text: str, option: str = "--road") -> None:
    """A registered road profile / drive cycle name (did you mean) or an existing .json/.csv/.gpx file."""
    if Path(text).suffix.lower() in (".json", ".csv", ".gpx") or Path(text).exists():
        require_file(Path(text), option, (".json", ".csv", ".gpx"))
        return
    from roadload.road_profiles import known_profiles

    names = list(known_profiles())
    if text.lower() not in names:
        choose(text, names, option, "road", f"'roadload profiles list' shows all {len(names)} road profiles and "
                                            f"drive cycles, or give a .json/.csv/.gpx file")


def build_compiled_kernels() -> None:
    """After a run on numba's kernels that found no compiled extension: build it for the next runs (stderr says so;
    a failed build is reported once and leaves numba in charge, roadload.compiled)."""
    from roadload import compiled

    if not compiled.build_wanted:
        return
    import time

    from roadload.envs.aot import build

    t0 = time.perf_counter()
    try:
        path = build()
    except Exception as exc:  # no C compiler, a numba without pycc, ...: the JIT path stays, reported once
        compiled.record_build_failure(exc)
        typer.echo(f"note: the simulator stays on numba's JIT (the ahead-of-time build failed: {type(exc).__name__}: "
                   f"{exc})", err=True)
        return
    if path is not None:
        typer.echo(f"compiled the simulator ahead of time for the next runs ({time.perf_counter() - t0:.0f} s): "
                   f"{path.parent}", err=True)


def register(app: typer.Typer, benchmark_app: typer.Typer) -> None:
    @app.command("simulate")
    def simulate_cmd(
        vehicle: str = typer.Option(..., help=f"vehicle preset ({', '.join(PRESETS)}) or vehicle JSON file"),
        road: str = typer.Option(..., help="road profile / drive cycle name (roadload profiles list) or a "
                                 ".json/.csv/.gpx file"),
        out: Path = typer.Option(..., help="output trip file (.parquet)"),
        seed: int = typer.Option(0, help="seed of the simulation (noise, disturbances, driver)"),
        effects: list[str] = typer.Option([], help="effects, e.g. 'wind:mean_speed=5,payload,tire_warmup' or 'all' "
                                          "(comma-separated and/or repeatable; roadload effects lists them)"),
        distance: float = typer.Option(None, help="stop after this distance [km]"),
        duration: float = typer.Option(None, help="stop after this duration [s]"),
        road_seed: int = typer.Option(None, help="seed of generated roads (default: --seed)"),
        cycle: str = typer.Option(None, help="follow this drive cycle on the road instead of the built-in driver"),
        ambient_temperature: float = typer.Option(20.0, help="ambient temperature [degC]"),
        sensors: Path = typer.Option(None, help="sensor spec JSON (default: the vehicle's sensors)"),
        plot: bool = typer.Option(False, help="also write a PNG next to the trip"),
        precision: str = typer.Option("compact", help=PRECISION_HELP),
    ) -> None:
        """Simulate a trip (100 Hz CAN-like channels + ground truth) and write it as Parquet."""
        if out.suffix != ".parquet":
            fail(f"--out: trip files end in .parquet, got {out.name!r}")
        if not AMBIENT_RANGE_C[0] <= ambient_temperature <= AMBIENT_RANGE_C[1]:
            fail(f"--ambient-temperature: must lie in [{AMBIENT_RANGE_C[0]:g}, {AMBIENT_RANGE_C[1]:g}] [degC], "
                 f"got {ambient_temperature:g}")
        for opt, value, unit in (("--duration", duration, "s"), ("--distance", distance, "km")):
            if value is not None and not value > 0:
                fail(f"{opt}: must be > 0 [{unit}], got {value:g}")
        choose(precision, PRECISIONS, "--precision", "storage precision")
        check_vehicle(vehicle)
        sensor_data = None
        if sensors is not None:
            require_file(sensors, "--sensors", (".json",))
            try:
                sensor_data = json.loads(sensors.read_text())
            except (OSError, json.JSONDecodeError) as exc:
                raise CliInputError(f"--sensors {sensors}: cannot read a JSON sensor spec ({exc})") from None
        from roadload.experiments import cli

        if cli.runs_as_command:  # before the road generator and the simulator are imported: no numba, no LLVM
            from roadload.compiled import use_compiled_kernels

            use_compiled_kernels()
        check_road(road)
        if cycle is not None:
            check_road(cycle, "--cycle")

        from rich.console import Console
        from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn

        from roadload.envs.effects import EffectsConfig
        from roadload.envs.simulator import simulate
        from roadload.presets import get_preset
        from roadload.road_profiles import DriveCycle, load_profile
        from roadload.trip_storage import trip_file_extent, trip_file_info
        from roadload.vehicle import SensorSpec, load_vehicle, parse_spec

        spec = get_preset(vehicle) if vehicle in PRESETS else load_vehicle(vehicle)
        profile = load_profile(road, seed=seed if road_seed is None else road_seed)
        driver = None
        if cycle is not None:
            driver = load_profile(cycle, seed=0)
            if not isinstance(driver, DriveCycle):
                fail(f"--cycle: {cycle!r} is a road profile, not a drive cycle")
        cfg = EffectsConfig.parse(",".join(effects) or None)
        cfg = EffectsConfig.from_dict({**cfg.to_dict(), "ambient_temperature": ambient_temperature + 273.15})
        sensor_spec = None if sensor_data is None else parse_spec(SensorSpec, sensor_data, "sensors")
        with Progress(TextColumn("[bold]simulating[/bold] {task.description}"), BarColumn(),
                      TextColumn("{task.percentage:>5.1f}%"), TimeElapsedColumn(), console=Console(stderr=True),
                      transient=True) as bar:
            # until the first chunk is done the bar cannot move (a first run compiles the simulator, holding the GIL
            # that rich's refresh thread needs): say so, then show the vehicle and road
            task = bar.add_task(f"{spec.name} on {profile.name} (starting; a first run compiles the simulator: "
                                f"20-60 s)", total=1.0)
            # streamed: one Parquet row group per 5 min of driving, memory bounded by one chunk; each chunk
            # redraws the bar (the compiled simulator holds the GIL, so rich's refresh thread cannot run meanwhile)
            path = simulate(spec, profile, effects=cfg, sensors=sensor_spec, seed=seed,
                            duration=duration, distance=None if distance is None else distance * 1000.0,
                            driver=driver, out=out, progress=lambda f: bar.update(
                                task, completed=f, description=f"{spec.name} on {profile.name}", refresh=True),
                            precision=precision)
        info = trip_file_info(path)
        t_first, t_last, x_end = trip_file_extent(path)  # bounded memory, no frames
        if x_end is None:
            fail(f"{path}: the streamed trip has no ground-truth position channel")
        km = float(x_end) / 1000.0
        duration_s = t_last - t_first
        e = info["meta"]["energy"]["source"]
        use = (f"{e / 3.6e6 / km * 100:.1f} kWh/100 km" if spec.drivetrain.kind == "bev"
               else f"{e / 32.0e6 / km * 100:.1f} l/100 km (fuel at 32 MJ/l)") if km > 0 else "-"
        typer.echo(f"wrote {path}: {duration_s:.0f} s, {km:.2f} km, {info['n_measured']} samples, {use}")
        for w in info["meta"]["warnings"]:
            typer.secho(f"warning: {w}", fg=typer.colors.YELLOW, err=True)
        if plot:
            from roadload.envs.plotting import plot_trip
            from roadload.trip import Trip

            typer.echo(f"wrote {plot_trip(Trip.load(path), out.with_suffix('.png'))}")
        build_compiled_kernels()

    @app.command("plot")
    def plot_cmd(trip: Path = typer.Argument(..., help="trip file (.parquet)"),
                 out: Path = typer.Option(None, help="PNG to write (default: next to the trip)")) -> None:
        """Plot a trip over distance (speed, forces, grade and elevation, energy) to a PNG."""
        require_file(trip, "TRIP", (".parquet",))
        if out is not None and out.suffix.lower() != ".png":
            fail(f"--out: the plot is a .png file, got {out.name!r}")
        from roadload.envs.plotting import plot_trip
        from roadload.trip import Trip

        typer.echo(f"wrote {plot_trip(Trip.load(trip), out if out is not None else trip.with_suffix('.png'))}")

    @app.command("effects")
    def effects_cmd() -> None:
        """List the simulator's effects with their equations and parameters."""
        from roadload.envs.effects import describe_effects

        typer.echo(describe_effects())

    @benchmark_app.command("simulator")
    def bench_cmd(duration: float = typer.Option(3600.0, help="simulated seconds per run"),
                  repeats: int = typer.Option(3, help="runs (best is reported)")) -> None:
        """Simulator speed: real-time factor at 100 Hz with all sensors and effects, memory, step throughput."""
        from roadload.experiments.benchmarks.simulator import report

        typer.echo(report(duration, repeats))
