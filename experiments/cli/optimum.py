"""``roadload benchmark optimum``: every controller's energy above the full-route optimum at its own trip time."""

from __future__ import annotations

import os
import time
from pathlib import Path

import typer

from .errors import fail

QUICK_CONTROLLERS = ("cruise", "mpc:oracle")


def register(app: typer.Typer, benchmark_app: typer.Typer) -> None:
    @benchmark_app.command("optimum")
    def optimum_cmd(
        out: Path = typer.Option(..., help="output folder: excess_over_optimum.csv (one row per controller run), "
                                 "summary.csv / summary.md, dp_check.csv, tasks/"),
        vehicles: str = typer.Option("car,truck_15t,truck_40t", help="vehicle cases (car = bmw_i3, truck_<m>t = "
                                     "tractor-semitrailer at m t gross)"),
        car_roads: str = typer.Option("route,city,motorway", help="car roads: route (EcoDrive-v0's 2 km hilly "
                                      "route, where the RL policies learnt; seeds from 50000), hilly (2.5 km), "
                                      "city (3 km, stops), motorway (6 km), motorway_short (3 km)"),
        truck_roads: str = typer.Option("long_grades,longhaul_real", help="truck roads: long_grades (4 km, "
                                        "3-6 %), longhaul_real (10 km windows of the real long-haul cycle)"),
        seeds: int = typer.Option(10, help="seeds (= roads) per vehicle and road"),
        first_seed: int = typer.Option(None, help="first seed (default: 50000 for 'route', 0 otherwise)"),
        seed_list: str = typer.Option("", help="comma-separated seeds to run instead of --seeds / --first-seed "
                                      "(e.g. 8,5,3)"),
        controllers: str = typer.Option("", help="comma-separated controllers for every vehicle (default: car "
                                        "cruise, human, mpc:oracle, mpc:abc, mpc:online, ppo, sac; truck cruise, "
                                        "cruise_band, human, mpc:oracle, mpc:abc, mpc:online); also mpc:online_wind; "
                                        "an online model's estimator options after '@' (mpc:online_wind@RRLM+cusum)"),
        policies: Path = typer.Option(None, help="folder with ppo_ecodrive.zip / sac_ecodrive.zip from `roadload "
                                      "train --out DIR` (without it the car runs no RL policy); the policy drives "
                                      "each car road of the benchmark in EcoDrive-v0 (a run that crosses a stop "
                                      "line faster than the env's stop_speed is left out of the excess)"),
        condition: str = typer.Option("nominal", help="car condition (see benchmark controllers)"),
        truck_warmup: float = typer.Option(2000.0, help="trucks: warm-up [m] before the measured segment, driven "
                                           "by cruise control for the MPC runs and the optimum"),
        car_warmup: float = typer.Option(0.0, help="car: warm-up [m] before the measured segment, driven by cruise "
                                         "control for every run (the online estimators converge there; not with "
                                         "RL policies)"),
        truck_optimum: str = typer.Option("bound", help="trucks' optimum: bound (the plant-fuel bound: dynamic "
                                          "programming in the plant's own fuel map at the gear of least fuel, fuel "
                                          "cut in overrun; a lower bound on the plant) or tracked (the NLP optimum "
                                          "at the shift rule's smooth ratio, driven on the plant)"),
        time_weight: float = typer.Option(-1.0, help="MPC time weight lambda [J/s] (< 0: the vehicle case's)"),
        dp_step: float = typer.Option(0.05, help="EV: speed grid [m/s] of the dynamic-programming cross-check "
                                      "(0: off)"),
        quick: bool = typer.Option(False, "--quick", help="tiny run: car, 2 seeds on a 1.2 km road, cruise "
                                   "control and the oracle MPC (and the policies of --policies)"),
        episode_cost: bool = typer.Option(False, "--episode-cost", help="the RL episode's cost E + lambda T on the "
                                          "EcoDrive-v0 routes: the policies of --policies, the MPC (default, and with "
                                          "the route end in its horizon) and the optimum of that cost"),
        breakdown: bool = typer.Option(False, "--breakdown", help="the oracle MPC's gap to the optimum, one design "
                                       "choice at a time (horizon, grid, comfort term, speed margin, terminal value, "
                                       "solver tolerance, re-planning period) and all together; the MPC is the "
                                       "one oracle MPC of --controllers (default mpc:oracle; trucks e.g. "
                                       "mpc:oracle:plant_map, with --gap-parts)"),
        variants: str = typer.Option("", help="--breakdown: comma-separated variant labels to run (default all; "
                                     "'base' = the MPC unchanged, e.g. 'base,horizon 4 km,no comfort term')"),
        gap_parts: bool = typer.Option(False, "--gap-parts", help="trucks: each run's energy above the plant-fuel "
                                       "bound in two parts that add up to it, against the full-route optimum of the "
                                       "plant-map MPC's own smoothed fuel model booked in the plant's map: above that "
                                       "optimum (horizon, terminal value, comfort, tracking) and that optimum above "
                                       "the bound (the raw map's non-convexity); gap_parts.csv, gap_parts.md"),
        merge: list[Path] = typer.Option([], "--merge", help="tasks/ folder of an earlier run to summarise with "
                                         "this one (repeatable)"),
        scheduler: str = typer.Option(None, help="Dask scheduler address (default: local processes)"),
        workers: int = typer.Option(None, help="local worker processes (default: CPU count)"),
    ) -> None:
        """Every controller (cruise control, the truck's speed-band cruise, the human-like driver, the MPC with
        each force model, PPO / SAC policies) against the full-route optimum at its own trip time and arrival
        speed, on the same plant: excess per run and per controller with 95 % CIs over seeds."""
        from roadload.experiments.controller_comparison import CONDITIONS, VEHICLE_CASES
        from roadload.experiments.optimum_benchmark import (CAR_CONTROLLERS, CONTROLLERS, TRUCK_CONTROLLERS,
                                                            EpisodeCostTask, OptimumBenchmarkError, breakdown_tasks,
                                                            optimum_tasks, run_benchmark, run_episode_cost,
                                                            summary_markdown)

        wall0, load0 = time.perf_counter(), os.getloadavg()
        cases = [v.strip() for v in vehicles.split(",") if v.strip()]
        bad = [c for c in cases if c not in VEHICLE_CASES]
        if bad:
            fail(f"--vehicles: unknown {bad}; known: {list(VEHICLE_CASES)}")
        if condition not in CONDITIONS:
            fail(f"--condition: unknown {condition!r}; known: {list(CONDITIONS)}")
        if not (truck_warmup >= 0 and car_warmup >= 0 and dp_step >= 0):
            fail(f"--truck-warmup / --car-warmup [m] and --dp-step [m/s]: numbers >= 0, got {truck_warmup}, "
                 f"{car_warmup}, {dp_step}")
        ctl = tuple(c.strip() for c in controllers.split(",") if c.strip())
        unknown = [c for c in ctl if c.partition("@")[0] not in CONTROLLERS]
        if unknown:
            fail(f"--controllers: unknown {unknown}; choose from {list(CONTROLLERS)}")
        if policies is not None and not policies.is_dir():
            fail(f"--policies: {policies} is not a folder (train with `roadload train --out DIR`)")
        if quick:
            rl = tuple(a for a in ("ppo", "sac") if policies is not None and (policies / f"{a}_ecodrive.zip").is_file())
            cases, seeds, ctl, dp_step = ["car"], 2, QUICK_CONTROLLERS + rl, 0.1 if dp_step else 0.0
            roads = {"car": ["hilly_short"]}
        else:
            roads = {c: [r.strip() for r in (truck_roads if VEHICLE_CASES[c].truck else car_roads).split(",")
                         if r.strip()] for c in cases}
        seed_values: int | list[int] = seeds
        if seed_list.strip():
            try:
                seed_values = [int(v) for v in seed_list.split(",") if v.strip()]
            except ValueError:
                fail(f"--seed-list: comma-separated integers, got {seed_list!r}")
            if not seed_values or min(seed_values) < 0 or len(set(seed_values)) < len(seed_values):
                fail(f"--seed-list: distinct seeds >= 0, got {seed_list!r}")
        elif seeds < 2 and not (seeds == 0 and merge):
            fail(f"--seeds: need at least 2 for a confidence interval (0 with --merge: summarise only), got {seeds}")
        if variants.strip() and not breakdown:
            fail("--variants: only with --breakdown")
        mpcs = [c for c in ctl if c.startswith("mpc:oracle")]
        if breakdown and (len(mpcs) > 1 or len(mpcs) < len(ctl)):
            fail(f"--breakdown: --controllers names one oracle MPC (mpc:oracle or mpc:oracle:<fuel model>), got "
                 f"{list(ctl)}")
        rl_wanted = ("ppo" in ctl or "sac" in ctl) or (not ctl and policies is not None)
        per_case = {}
        for c in cases:
            chosen = ctl
            if not chosen:
                chosen = TRUCK_CONTROLLERS if VEHICLE_CASES[c].truck else CAR_CONTROLLERS
                if policies is None:
                    chosen = tuple(x for x in chosen if x not in ("ppo", "sac"))
            if VEHICLE_CASES[c].truck:
                chosen = tuple(x for x in chosen if x not in ("ppo", "sac"))
            per_case[c] = chosen
        if rl_wanted and policies is None:
            fail("--controllers ppo/sac need --policies DIR (policies trained by `roadload train --out DIR`)")
        starts = {r: (first_seed if first_seed is not None else (50000 if r == "route" else 0))
                  for rs in roads.values() for r in rs}
        if episode_cost:
            algos = tuple(a for a in ("ppo", "sac")
                          if policies is not None and (policies / f"{a}_ecodrive.zip").is_file())
            first = first_seed if first_seed is not None else 50000
            ep_tasks = [EpisodeCostTask(first + i, time_weight=3000.0 if time_weight < 0 else time_weight,
                                        policies=None if policies is None else str(policies), algos=algos)
                        for i in range(2 if quick else seeds)]
            _, text, failures = run_episode_cost(ep_tasks, out, scheduler=scheduler, workers=workers)
            typer.echo(text)
            typer.echo(f"wrote {out}/episode_cost.csv, episode_cost.md")
            return
        try:
            tasks = []
            for case in cases:
                if breakdown:
                    tasks += breakdown_tasks({case: roads[case]}, seed_values, starts,
                                             controller=mpcs[0] if mpcs else "mpc:oracle",
                                             variants=[v.strip() for v in variants.split(",")] if variants.strip()
                                             else None,
                                             warmup=truck_warmup if VEHICLE_CASES[case].truck else car_warmup,
                                             time_weight=None if time_weight < 0 else time_weight)
                    continue
                tasks += optimum_tasks({case: roads[case]}, seed_values, starts, {case: per_case[case]},
                                       condition=condition if not VEHICLE_CASES[case].truck else "nominal",
                                       warmup=truck_warmup if VEHICLE_CASES[case].truck else car_warmup,
                                       time_weight=None if time_weight < 0 else time_weight,
                                       policies=None if policies is None else str(policies), dp_step=dp_step,
                                       truck_optimum=truck_optimum)
        except (OptimumBenchmarkError, ValueError) as exc:
            fail(str(exc))
        rows, summary, failures = run_benchmark(tasks, out, scheduler=scheduler, workers=workers, merge=list(merge))
        if summary.empty:
            fail("no controller run has an optimum: " + "; ".join(failures[:3]), code=1)
        typer.echo(summary_markdown(summary, _dp(out)))
        if gap_parts:
            _gap_parts(out, list(merge))
        for f in failures:
            typer.secho(f"failed: {f}", fg=typer.colors.YELLOW, err=True)
        typer.echo(f"wrote {out}/excess_over_optimum.csv ({len(rows)} runs), summary.csv, summary.md, dp_check.csv")
        cpu = os.times()
        load1 = os.getloadavg()
        typer.echo(f"wall time {time.perf_counter() - wall0:.0f} s, CPU time "
                   f"{cpu.user + cpu.system + cpu.children_user + cpu.children_system:.0f} s (this process and its "
                   f"finished workers) for {len(tasks)} tasks on {workers or os.cpu_count()} workers; 1-min load "
                   f"average {load0[0]:.2f} at start, {load1[0]:.2f} at end")


def _gap_parts(out: Path, merge: list[Path]) -> None:
    """--gap-parts: the parts of every stored truck run in ``out``/tasks and the merged folders."""
    import json

    from roadload.experiments.truck_gap import gap_parts, gap_parts_markdown, gap_parts_summary
    from roadload.fileio import write_text

    results = [json.loads(p.read_text()) for folder in [out / "tasks", *merge] for p in sorted(folder.glob("*.json"))]
    rows = gap_parts(results)
    summary = gap_parts_summary(rows)
    write_text(out / "gap_parts.csv", rows.to_csv(index=False))
    text = ("Energy above the plant-fuel bound in two parts that add up to it, against the optimum of the plant-map "
            "MPC's smoothed fuel model booked in the plant's map (fleet totals over the bound, 95 % CI):\n\n"
            + gap_parts_markdown(summary))
    write_text(out / "gap_parts.md", text)
    typer.echo(text)
    typer.echo(f"wrote {out}/gap_parts.csv ({len(rows)} runs), gap_parts.md")


def _dp(out: Path):
    import pandas as pd

    path = out / "dp_check.csv"
    try:
        return pd.read_csv(path)
    except (OSError, ValueError):  # an empty file: no DP check in this run
        return None
