"""``roadload drive`` (one closed-loop drive with a controller) and ``roadload benchmark controllers`` (the
comparison: table + figures), ``benchmark headline`` and ``benchmark sensitivity``.

Light at import (see the package docstring): CasADi (the MPC), the simulator, dask and matplotlib load inside the
commands, after the arguments are checked."""

from __future__ import annotations

import math
import os
import time
from pathlib import Path

import typer

from roadload.fileio import write_text

from .errors import fail


def _fail(msg: str) -> None:
    fail(msg)


def _jsonable(d):
    out = {}
    for k, v in d.items():
        if isinstance(v, dict):
            out[k] = _jsonable(v)
        elif isinstance(v, (bool, int, str)) or v is None:
            out[k] = v
        else:
            try:
                f = float(v)
                out[k] = f if math.isfinite(f) else None
            except (TypeError, ValueError):
                out[k] = str(v)
    return out


#: what ``roadload drive`` prints: metric key -> (label, unit, format)
DRIVE_METRICS = {"arrived": ("arrived", "", "{}"), "energy_kWh": ("energy", "kWh", "{:.3f}"),
                 "trip_time": ("trip time", "s", "{:.1f}"), "speed_violations": ("speed violations", "", "{:d}"),
                 "max_excess_kmh": ("max excess", "km/h", "{:.2f}"), "rms_jerk": ("RMS jerk", "m/s^3", "{:.3f}"),
                 "solve_time_median": ("solve time median", "ms", "{:.1f}"),
                 "solve_time_p99": ("solve time p99", "ms", "{:.1f}"), "fallbacks": ("fallbacks", "", "{:d}")}


def metric_lines(m: dict) -> list[str]:
    """The drive metrics rounded and with their units, e.g. ``   trip time: 362.4 [s]``; for the MPC, what its
    plans could not meet and what the fallback did (:mod:`roadload.controllers.mpc_controller`)."""
    out = []
    for key, (label, unit, fmt) in DRIVE_METRICS.items():
        if key not in m:
            continue
        value = m.get(key, 0)
        if unit == "ms":
            value = value * 1000.0
        try:
            text = fmt.format(value) if value is not None and not (isinstance(value, float) and math.isnan(value)) \
                else "-"
        except (ValueError, TypeError):
            text = str(value)
        out.append(f"{label:>20}: {text}" + (f" [{unit}]" if unit and text != "-" else ""))
    return out + feasibility_lines(m)


def feasibility_lines(m: dict) -> list[str]:
    """MPC runs: relaxed / infeasible plans out of all solves, with what they mean, the fallback brake's steps and
    the worst violation (nothing for the other controllers)."""
    if "ctl_relaxed_plans" not in m and "ctl_solves" not in m:
        return []
    solves = int(m.get("ctl_solves", 0))
    relaxed, infeasible = int(m.get("ctl_relaxed_plans", 0)), int(m.get("ctl_infeasible_plans", 0))
    lines = [f"{'relaxed plans':>20}: {relaxed} of {solves} solves "
             + ("(every plan met every stop and speed cap within the comfort limits)" if relaxed == 0 else
                "(plans that could not meet a stop, a speed cap or its margin within the comfort limits; the "
                "solver planned the hardest comfortable braking instead)"),
             f"{'infeasible plans':>20}: {infeasible} of {solves} solves"
             + ("" if infeasible == 0 else " (the solver found no plan; the named constraint could not be met)")]
    brakes = int(m.get("ctl_fallback_brake", 0))
    if brakes:
        comfort, emergency = int(m.get("ctl_comfort_brake_steps", 0)), int(m.get("ctl_emergency_brake_steps", 0))
        lines.append(f"{'fallback brake':>20}: {brakes} solves ({comfort} control steps at the maximum comfort "
                     f"deceleration, {emergency} emergency-braking)")
    worst = m.get("ctl_worst_violation") or ""
    if worst:
        lines.append(f"{'worst violation':>20}: {worst}")
    return lines


def register(app: typer.Typer, benchmark_app: typer.Typer) -> None:
    register_headline(benchmark_app)
    @app.command("drive")
    def drive_cmd(
        controller: str = typer.Option("mpc", help="mpc | cruise | human"),
        force_model: str = typer.Option("online", "--force-model", help="MPC force model: abc | online | oracle"),
        road: str = typer.Option("hilly", help="road profile name (hilly, motorway, city, i3_munich, any "
                                 "roadload profile name or file)"),
        vehicle: str = typer.Option("bmw_i3", help="vehicle preset (bmw_i3, gt_rwd, gt_awd)"),
        effects: list[str] = typer.Option([], "--effects", help="simulator effects, e.g. winter_tires or "
                                          "'wind:mean_speed=6' (comma-separated and/or repeatable; see "
                                          "roadload effects)"),
        out: Path = typer.Option(None, help="write the simulated trip (.parquet) with the run's metrics in meta"),
        seed: int = typer.Option(0, help="simulation seed"),
        solver: str = typer.Option("ipopt", help="MPC solve path: ipopt | osqp"),
        time_weight: float = typer.Option(8000.0, min=0.0, help="MPC time weight lambda [J/s]"),
        model: str = typer.Option("M4", help="online model structure (M3, M4, M0)"),
        estimator: str = typer.Option("RRLM", help="online estimator (catalog name)"),
        cruise_fraction: float = typer.Option(0.9, help="cruise control set speed as a fraction of the limit"),
    ) -> None:
        """Drive a road once in closed loop on the simulator and print energy, time, violations, jerk, solver
        time and fallbacks."""
        if out is not None and out.suffix != ".parquet":
            _fail(f"--out: trip files end in .parquet, got {out.name!r}")
        from rich.console import Console
        from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn

        from roadload.controllers.cruise import CruiseSettings
        from roadload.controllers.drive import DriveSettings, drive
        from roadload.experiments.controller_comparison import road_by_name

        try:
            settings = DriveSettings(controller=controller, force_model=force_model, solver=solver,
                                     time_weight=time_weight, model=model, estimator=estimator,
                                     cruise=CruiseSettings(fraction=cruise_fraction))
            profile = road_by_name(road)
            with Progress(TextColumn("[bold]driving[/bold] {task.description}"), BarColumn(),
                          TextColumn("{task.percentage:>5.1f}%"), TimeElapsedColumn(),
                          console=Console(stderr=True), transient=True) as bar:
                task = bar.add_task(f"{controller}/{force_model} on {profile.name}", total=1.0)
                res, plant = drive(vehicle, profile, effects=",".join(effects) or None, seed=seed, settings=settings,
                                   progress=lambda f: bar.update(task, completed=f, refresh=True))
        except typer.Exit:
            raise
        except (ValueError, FileNotFoundError, KeyError) as exc:
            _fail(str(exc))
        m = res.metrics
        for line in metric_lines(m):
            typer.echo(line)
        if "online" in m:
            est = m["online"]["estimate"]
            text = (", ".join(f"{k}={v:.4g}" for k, v in est.items()) if isinstance(est, dict) else str(est))
            typer.echo(f"{'online estimate':>20}: {text}")
        if out is not None:
            trip = plant.sim.to_trip()
            trip.meta["controller"] = _jsonable({k: v for k, v in m.items()})
            typer.echo(f"wrote {trip.save(out)}")
        solves, failed = int(m.get("ctl_solves", 0)), int(m.get("ctl_solver_failures", 0))
        if controller == "mpc" and solves > 0 and failed >= solves:
            fail(f"every one of the {solves} MPC solves failed (the drive ran on the fallback controller); check "
                 f"the MPC settings (--time-weight [J/s], --solver)", code=1)

    @benchmark_app.command("controllers")
    def bench_controllers_cmd(
        out: Path = typer.Option(..., help="output folder: controllers.md, summary.csv, runs.json, headline.png"),
        roads: str = typer.Option("hilly,city,motorway", help="car roads (one per seed): hilly (2.5 km), city "
                                  "(3 km, stops), motorway (6 km), route (EcoDrive-v0's 2 km)"),
        conditions: str = typer.Option("nominal", help="comma-separated conditions or 'all' (nominal, "
                                       "payload_300kg, winter_tires, headwind_6ms, crosswind_6ms, roof_box, drift)"),
        seeds: int = typer.Option(5, help="seeds (= roads) per road and condition"),
        first_seed: int = typer.Option(0, help="first seed"),
        force_models: str = typer.Option("oracle,abc,online", help="MPC force models (oracle first): oracle, abc, "
                                         "online, online_wind"),
        optimum: bool = typer.Option(True, "--optimum/--no-optimum", help="also the full-route optimum at the "
                                     "same trip time, on the same plant"),
        fastsim: bool = typer.Option(False, "--fastsim/--no-fastsim", help="also every run's speed trace through "
                                     "FASTSim 3 (savings against cruise control from both models)"),
        quick: bool = typer.Option(False, "--quick", help="tiny run: 2 seeds of a 1.2 km hilly road, oracle and "
                                   "abc MPC"),
        scheduler: str = typer.Option(None, help="Dask scheduler address (default: local processes)"),
        workers: int = typer.Option(None, help="local worker processes (default: CPU count)"),
    ) -> None:
        """MPC (each force model) against cruise control, the human-like driver and the full-route optimum, on the
        car over roads x conditions, paired per seed at equal trip time: every difference with its 95 % CI (the
        same comparison as `benchmark headline`)."""
        from roadload.experiments.controller_comparison import CONDITIONS, PAIRED_ROADS
        from roadload.experiments.headline import headline_figure, headline_markdown, headline_tasks, run_paired

        cond_list = list(CONDITIONS) if conditions == "all" else [c.strip() for c in conditions.split(",") if c]
        bad = [c for c in cond_list if c not in CONDITIONS]
        if bad:
            _fail(f"--conditions: unknown {bad}; known: {list(CONDITIONS)}")
        fms = _force_models(force_models)
        road_list = ["hilly_short"] if quick else [r.strip() for r in roads.split(",") if r.strip()]
        bad = [r for r in road_list if r not in PAIRED_ROADS]
        if bad:
            _fail(f"--roads: unknown {bad}; known: {list(PAIRED_ROADS)}")
        seeds = 2 if quick else seeds
        if seeds < 2:
            _fail(f"--seeds: need at least 2 for a confidence interval, got {seeds}")
        wall0 = time.perf_counter()
        tasks = headline_tasks(["car"], {"car": road_list}, seeds, ["nominal"] if quick else cond_list, human=True,
                               quick=quick, first_seed=first_seed,
                               force_models=("oracle", "abc") if quick else fms, optimum=optimum, fastsim=fastsim)
        summary, failures = run_paired(tasks, out, scheduler=scheduler, workers=workers,
                                       description="controller comparison")
        if summary.empty:
            _fail("every task failed: " + "; ".join(failures[:3]))
        md = headline_markdown(summary, failures)
        write_text(out / "controllers.md", "# Controller comparison at equal trip time\n\n" + md)
        headline_figure(summary, out / "headline.png")
        typer.echo(md)
        typer.echo(f"wrote {out}/controllers.md, summary.csv, runs.json, headline.png "
                   f"({time.perf_counter() - wall0:.0f} s wall, load average {os.getloadavg()[0]:.2f})")


def _force_models(text: str) -> tuple[str, ...]:
    """The --force-models list: oracle first, then abc, online, online_wind (estimator options after '@')."""
    from roadload.experiments.controller_comparison import force_model_settings

    fms = tuple(f.strip() for f in text.split(",") if f.strip())
    try:
        for f in fms:
            force_model_settings(f)
    except ValueError as exc:
        _fail(f"--force-models: {exc}")
    if not fms or fms[0] != "oracle":
        _fail(f"--force-models: oracle first, then any of abc, online, online_wind (options after '@'); got {fms}")
    return fms


def _car_truck_cases(vehicles: str) -> list[str]:
    from roadload.experiments.controller_comparison import VEHICLE_CASES

    cases = [v.strip() for v in vehicles.split(",") if v.strip()]
    bad = [c for c in cases if c not in VEHICLE_CASES]
    if bad:
        _fail(f"--vehicles: unknown {bad}; known: {list(VEHICLE_CASES)}")
    return cases


def register_headline(benchmark_app: typer.Typer) -> None:
    """``roadload benchmark headline`` and ``roadload benchmark sensitivity``."""
    @benchmark_app.command("headline")
    def headline_cmd(
        out: Path = typer.Option(..., help="output folder: runs.json, summary.csv, headline.md, headline.png"),
        vehicles: str = typer.Option("car,truck_15t,truck_25t,truck_40t", help="vehicle cases (car = bmw_i3, "
                                     "truck_<m>t = tractor-semitrailer at m t gross, abc at 27.5 t)"),
        car_roads: str = typer.Option("hilly", help="car roads (hilly = 2.5 km generated, one per seed)"),
        truck_roads: str = typer.Option("long_grades", help="truck roads: long_grades (4 km, 3-6 %), "
                                        "longhaul_real (10 km windows of the real long-haul cycle)"),
        conditions: str = typer.Option("nominal", help="car conditions (see benchmark controllers)"),
        seeds: int = typer.Option(10, help="seeds (= roads) per vehicle, road and condition"),
        quick: bool = typer.Option(False, "--quick", help="tiny run: car only, 2 seeds on a 1.2 km road"),
        search_runs: int = typer.Option(4, help="oracle runs spent on the time-weight search per seed"),
        weight_factors: str = typer.Option("0.8,1.25", help="extra time weights (x the matched one) per model; "
                                           "'none': one run per model at the matched weight"),
        first_seed: int = typer.Option(0, help="first seed (seeds first_seed .. first_seed + seeds - 1)"),
        merge: list[Path] = typer.Option([], "--merge", help="runs.json of an earlier run (other seeds), or its "
                                         "tasks/ folder of finished seeds, to summarise together with this one "
                                         "(repeatable)"),
        scheduler: str = typer.Option(None, help="Dask scheduler address (default: local processes)"),
        workers: int = typer.Option(None, help="local worker processes (default: CPU count)"),
        truck_warmup: float = typer.Option(0.0, help="trucks: warm-up distance [m] driven before the measured "
                                           "4 km (the online estimator converges there; every controller drives it)"),
        car_warmup: float = typer.Option(0.0, help="car: warm-up distance [m] driven before the measured 2.5 km"),
        metric: str = typer.Option("net", help="net: segment energy net of the kinetic energy left at arrival, "
                                   "crossings interpolated; raw: first step past the road end"),
        knob: str = typer.Option("lambda", help="time knob: lambda (fixed time weight per run, searched) or "
                                 "schedule (every model targets the cruise time x (1, time factors) by lambda "
                                 "feedback and multi-start solves; continuous in the target)"),
        time_factors: str = typer.Option("0.99,1.01", help="schedule knob: extra target times (x the cruise time)"),
        schedule_gain: float = typer.Option(20.0, help="schedule knob: P gain of the lambda feedback on the "
                                            "lateness (ln lambda change per lateness / scheduled time left)"),
        schedule_pilot: bool = typer.Option(False, "--schedule-pilot", help="schedule knob: lambda_0 from one "
                                            "oracle pilot run (its median lambda over the segment)"),
        multistart_period: float = typer.Option(-1.0, help="[s] cold multi-start MPC solves this often (leave a "
                                                "gear branch); < 0: 5 s with the schedule knob, off with lambda"),
        model_search_runs: int = typer.Option(0, help="extra lambda-search runs of a force model whose runs all "
                                              "miss the reference time by > 1 % (e.g. on the other cruise branch)"),
        warmup_driver: str = typer.Option("mpc", help="who drives the warm-up of the MPC runs: mpc (each MPC) or "
                                          "cruise (cruise control for every run: same state at the segment start)"),
        gear_command: bool = typer.Option(False, "--mpc-gear", help="ICE: every MPC run requests the gear of its own "
                                          "shift rule (predictive powertrain control); the baselines keep the "
                                          "transmission's load-dependent strategy"),
        terminal_value: str = typer.Option("source", help="MPC value of the kinetic energy at the horizon end: "
                                           "source (m E_N / eta_i) or wheel (m E_N, the earlier value)"),
        optimum: bool = typer.Option(False, "--optimum/--no-optimum", help="also the full-route optimum at the "
                                     "reference trip time, on the same plant"),
        fastsim: bool = typer.Option(False, "--fastsim/--no-fastsim", help="car: also every run's speed trace "
                                     "through FASTSim 3"),
        force_models: str = typer.Option("oracle,abc,online", help="MPC force models (oracle first)"),
    ) -> None:
        """MPC with the oracle / abc / online force model against cruise control at equal trip time, paired over
        seeds, with the 1-sigma resolution and 95 % CIs of every difference."""
        from roadload.experiments.controller_comparison import CONDITIONS
        from roadload.experiments.headline import headline_figure, headline_markdown, headline_tasks, run_paired

        if metric not in ("net", "raw"):
            _fail(f"--metric: net or raw, got {metric!r}")
        if not (schedule_gain >= 0):
            _fail(f"--schedule-gain: a number >= 0, got {schedule_gain}")
        if knob not in ("lambda", "schedule"):
            _fail(f"--knob: lambda or schedule, got {knob!r}")
        if terminal_value not in ("source", "wheel"):
            _fail(f"--terminal-value: source or wheel, got {terminal_value!r}")
        fms = _force_models(force_models)
        try:
            t_factors = tuple(float(f) for f in time_factors.split(",") if f.strip())
        except ValueError:
            _fail(f"--time-factors: comma-separated numbers (x the cruise time), got {time_factors!r}")
        if not (truck_warmup >= 0 and car_warmup >= 0):
            _fail(f"--truck-warmup / --car-warmup: distances >= 0 m, got {truck_warmup} / {car_warmup}")
        wall0, load0 = time.perf_counter(), os.getloadavg()
        cases = ["car"] if quick else _car_truck_cases(vehicles)
        seeds = 2 if quick else seeds
        if seeds < 2 and not (seeds == 0 and merge):
            _fail(f"--seeds: need at least 2 for a confidence interval (0 with --merge: summarise only), got "
                  f"{seeds}")
        roads = {c: [r.strip() for r in (car_roads if c == "car" else truck_roads).split(",") if r.strip()]
                 for c in cases}
        if quick:
            roads = {"car": ["hilly_short"]}
        conds = [c.strip() for c in conditions.split(",") if c.strip()]
        bad = [c for c in conds if c not in CONDITIONS]
        if bad:
            _fail(f"--conditions: unknown {bad}; known: {list(CONDITIONS)}")
        try:
            factors = () if weight_factors.strip().lower() == "none" else tuple(
                float(f) for f in weight_factors.split(",") if f.strip())
        except ValueError:
            _fail(f"--weight-factors: comma-separated numbers or 'none', got {weight_factors!r}")
        if search_runs < 1:
            _fail(f"--search-runs: at least 1, got {search_runs}")
        if warmup_driver not in ("mpc", "cruise"):
            _fail(f"--warmup-driver: mpc or cruise, got {warmup_driver!r}")
        if model_search_runs < 0:
            _fail(f"--model-search-runs: 0 or more, got {model_search_runs}")
        tasks = headline_tasks(cases, roads, seeds, conds, human=True, quick=quick, first_seed=first_seed,
                               search_runs=None if quick else search_runs, weight_factors=None if quick else factors,
                               truck_warmup=truck_warmup, metric=metric, car_warmup=car_warmup, knob=knob,
                               time_factors=t_factors, terminal_value=terminal_value,
                               schedule_gain=schedule_gain, schedule_pilot=schedule_pilot,
                               multistart_period=None if multistart_period < 0 else multistart_period,
                               gear_command=gear_command, model_search_runs=model_search_runs,
                               warmup_driver=warmup_driver, optimum=optimum, fastsim=fastsim,
                               force_models=None if quick else fms)
        summary, failures = run_paired(tasks, out, scheduler=scheduler, workers=workers, description="headline",
                                       merge=list(merge))
        if summary.empty:
            _fail("every task failed: " + "; ".join(failures[:3]))
        md = headline_markdown(summary, failures)
        write_text(out / "headline.md", "# Headline: eco-driving MPC force models at equal trip time\n\n" + md)
        headline_figure(summary, out / "headline.png")
        typer.echo(md)
        typer.echo(f"wrote {out}/headline.md, summary.csv, summary_other_metric.csv, runs.json, headline.png")
        load1 = os.getloadavg()
        cpu = os.times()
        typer.echo(f"CPU time {cpu.user + cpu.system + cpu.children_user + cpu.children_system:.0f} s (this "
                   f"process and its finished workers)")
        typer.echo(f"wall time {time.perf_counter() - wall0:.0f} s for {len(tasks)} tasks on "
                   f"{workers or os.cpu_count()} workers; 1-min load average {load0[0]:.2f} at start, "
                   f"{load1[0]:.2f} at end (5-min {load1[1]:.2f})")

    @benchmark_app.command("sensitivity")
    def sensitivity_cmd(
        out: Path = typer.Option(..., help="output folder: sensitivity.md/.csv, sensitivity.png, runs.json"),
        vehicles: str = typer.Option("car,truck_40t", help="vehicle cases"),
        seeds: int = typer.Option(4, help="seeds (= roads) per vehicle"),
        quick: bool = typer.Option(False, "--quick", help="tiny run: car only, 2 seeds, mass +20 % only"),
        first_seed: int = typer.Option(0, help="first seed (seeds first_seed .. first_seed + seeds - 1)"),
        merge: list[Path] = typer.Option([], "--merge", help="runs.json of an earlier run (other seeds) to "
                                         "summarise together with this one (repeatable)"),
        scheduler: str = typer.Option(None, help="Dask scheduler address (default: local processes)"),
        workers: int = typer.Option(None, help="local worker processes (default: CPU count)"),
    ) -> None:
        """Energy penalty at equal time vs force-model error (mass, rolling resistance, drag area, grade bias,
        drive-train losses; one at a time and jointly) against the oracle MPC: table and figure per vehicle."""
        from roadload.experiments.headline import run_paired, sensitivity_figure, sensitivity_table, sensitivity_tasks
        from roadload.tables import markdown_table

        cases = ["car"] if quick else _car_truck_cases(vehicles)
        seeds = 2 if quick else seeds
        if seeds < 2:
            _fail(f"--seeds: need at least 2 for a confidence interval, got {seeds}")
        road = {c: ("hilly_short" if quick else "hilly" if c == "car" else "long_grades") for c in cases}
        summary, failures = run_paired(sensitivity_tasks(road, seeds, quick=quick, first_seed=first_seed), out,
                                       scheduler=scheduler, workers=workers, description="sensitivity",
                                       merge=list(merge))
        if summary.empty:
            _fail("every task failed: " + "; ".join(failures[:3]))
        table = sensitivity_table(summary)
        write_text(out / "sensitivity.csv", table.to_csv(index=False))
        md = ("Energy penalty of the MPC with a wrong force model vs the oracle MPC at equal trip time, paired per "
              "seed; mean [95 % CI] (1σ resolution); 'not resolved': CI contains 0.\n\n"
              + markdown_table(table[["vehicle", "road", "parameter", "error", "seeds", "result"]]) + "\n")
        if failures:
            md += "\nFailed tasks:\n\n" + "\n".join(f"- {f}" for f in failures) + "\n"
        write_text(out / "sensitivity.md", "# Sensitivity map\n\n" + md)
        sensitivity_figure(table, out / "sensitivity.png")
        typer.echo(md)
        typer.echo(f"wrote {out}/sensitivity.md, sensitivity.csv, sensitivity.png, runs.json")
