"""``roadload simulate``, ``roadload plot``, ``roadload effects`` and ``roadload benchmark simulator``."""

from __future__ import annotations

from pathlib import Path
from typing import NoReturn

import typer
from rich.console import Console
from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn
from roadload.vehicle import load_vehicle
from roadload.presets import PRESETS, get_preset
from roadload.road_profiles import load_profile
from roadload.road_profiles import DriveCycle
from roadload.vehicle import SensorSpec, VehicleSpecError, parse_spec
from roadload.envs.effects import EffectsConfig
from roadload.envs.simulator import simulate
from roadload.trip import Trip, TripError
from roadload.envs.plotting import plot_trip
from roadload.envs.effects import describe_effects
from roadload.experiments.benchmarks.simulator import report

from .errors import fail


#: ambient temperatures the simulator's air-density and tire/oil models are meant for [degC]
AMBIENT_RANGE_C = (-60.0, 60.0)


def _fail(msg: str) -> NoReturn:
    fail(msg)


def _load_vehicle(text: str):


    if text in PRESETS:
        return get_preset(text)
    if text.endswith(".json") or Path(text).exists():
        return load_vehicle(text)
    return get_preset(text)  # raises, listing the presets


def _load_road(text: str, seed: int):

    return load_profile(text, seed=seed)


def register(app: typer.Typer, benchmark_app: typer.Typer) -> None:
    @app.command("simulate")
    def simulate_cmd(
        vehicle: str = typer.Option(..., help="vehicle preset (gt_rwd, gt_awd, bmw_i3) or vehicle JSON file"),
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
        precision: str = typer.Option("compact", help="'compact' (quantised channels as scaled integers, truth "
                                      "float32; ~4x smaller) or 'exact' (float64)"),
    ) -> None:
        """Simulate a trip (100 Hz CAN-like channels + ground truth) and write it as Parquet."""


        if out.suffix != ".parquet":
            _fail(f"--out: trip files end in .parquet, got {out.name!r}")
        if not AMBIENT_RANGE_C[0] <= ambient_temperature <= AMBIENT_RANGE_C[1]:
            _fail(f"--ambient-temperature: must lie in [{AMBIENT_RANGE_C[0]:g}, {AMBIENT_RANGE_C[1]:g}] [degC], "
                  f"got {ambient_temperature:g}")
        for opt, value, unit in (("--duration", duration, "s"), ("--distance", distance, "km")):
            if value is not None and not value > 0:
                _fail(f"{opt}: must be > 0 [{unit}], got {value:g}")
        try:
            spec = _load_vehicle(vehicle)
            profile = _load_road(road, seed if road_seed is None else road_seed)
            driver = None
            if cycle is not None:
                driver = _load_road(cycle, 0)
                if not isinstance(driver, DriveCycle):
                    _fail(f"--cycle: {cycle!r} is a road profile, not a drive cycle")
            cfg = EffectsConfig.parse(",".join(effects) or None)
            cfg = EffectsConfig.from_dict({**cfg.to_dict(), "ambient_temperature": ambient_temperature + 273.15})
            sensor_spec = None
            if sensors is not None:
                import json

                try:
                    data = json.loads(Path(sensors).read_text())
                except (OSError, json.JSONDecodeError) as exc:
                    _fail(f"--sensors {sensors}: cannot read a JSON sensor spec ({exc})")
                sensor_spec = parse_spec(SensorSpec, data, "sensors")
            with Progress(TextColumn("[bold]simulating[/bold] {task.description}"), BarColumn(),
                          TextColumn("{task.percentage:>5.1f}%"), TimeElapsedColumn(),
                          console=Console(stderr=True), transient=True) as bar:
                task = bar.add_task(f"{spec.name} on {profile.name}", total=1.0)
                # streamed: one Parquet row group per 2 min of driving, memory bounded by one chunk
                path = simulate(spec, profile, effects=cfg, sensors=sensor_spec, seed=seed,
                                duration=duration, distance=None if distance is None else distance * 1000.0,
                                driver=driver, progress=lambda f: bar.update(task, completed=f), out=out,
                                precision=precision)
            info = Trip.read_info(path)
        except typer.Exit:
            raise
        except (ValueError, VehicleSpecError, FileNotFoundError) as exc:
            _fail(str(exc))
        t_first = None
        for last in Trip.iter_chunks(path, channels=[], truth_channels=["position"]):  # bounded memory
            t_first = last.t[0] if t_first is None else t_first
        if last.truth is None:
            _fail(f"{path}: the streamed trip has no ground-truth position channel")
        km = float(last.truth["position"].iloc[-1]) / 1000.0
        duration_s = float(last.t[-1] - t_first)
        e = info["meta"]["energy"]["source"]
        use = (f"{e / 3.6e6 / km * 100:.1f} kWh/100 km" if spec.drivetrain.kind == "bev"
               else f"{e / 32.0e6 / km * 100:.1f} l/100 km (fuel at 32 MJ/l)") if km > 0 else "-"
        typer.echo(f"wrote {path}: {duration_s:.0f} s, {km:.2f} km, {info['n_measured']} samples, {use}")
        for w in info["meta"]["warnings"]:
            typer.secho(f"warning: {w}", fg=typer.colors.YELLOW, err=True)
        if plot:

            typer.echo(f"wrote {plot_trip(Trip.load(path), out.with_suffix('.png'))}")

    @app.command("plot")
    def plot_cmd(trip: Path = typer.Argument(..., help="trip file (.parquet)"),
                 out: Path = typer.Option(None, help="PNG to write (default: next to the trip)")) -> None:
        """Plot a trip over distance (speed, forces, grade/elevation, parameters) to a PNG."""


        try:
            t = Trip.load(trip)
            path = plot_trip(t, out if out is not None else trip.with_suffix(".png"))
        except (TripError, ValueError) as exc:
            _fail(str(exc))
        typer.echo(f"wrote {path}")

    @app.command("effects")
    def effects_cmd() -> None:
        """List the simulator's effects with their equations and parameters."""

        typer.echo(describe_effects())

    @benchmark_app.command("simulator")
    def bench_cmd(duration: float = typer.Option(3600.0, help="simulated seconds per run"),
                  repeats: int = typer.Option(3, help="runs (best is reported)")) -> None:
        """Simulator speed: real-time factor at 100 Hz with all sensors and effects, memory, step throughput."""

        typer.echo(report(duration, repeats))
