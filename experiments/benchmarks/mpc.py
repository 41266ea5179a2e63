"""Per-step solve time of the spatial MPC (100-node horizon): IPOPT warm-started and the OSQP sequential-QP path.

Drives a closed loop (the controller's own force model as plant, so only the solver is timed) over a generated
hilly road and a city route and records every solve: wall-clock time (time.perf_counter) and process CPU time
(time.process_time, robust when other jobs load the machine), iterations and failures. Prints a table and, with
--out, writes it as CSV. Targets: IPOPT warm median <= 5 ms and p99 <= 20 ms; QP median <= 2 ms. IPOPT
runs at the default warm-start tolerance (1e-4) and at 1e-6 for reference: the closed-loop energies show what the
looser tolerance costs.

The heavy truck (``--vehicle truck_40t``): its MPC (40 nodes x 50 m = 2 km horizon, the settings of the
truck comparison) on generated long grades (``--roads long_grades``), target IPOPT warm median <= 10 ms; the
car's 100-node problem on the same machine in the same run is the reference (``--vehicle bmw_i3,truck_40t``
prints both and the ratio).

The car runs the drives' grid (DriveSettings: four 5 m segments at the vehicle, then 20 m); ``--grids 4,0`` runs
each car problem also with that many near segments (0: the uniform 20 m grid), the grids interleaved per road, and
prints the CPU-time ratio of each to the first.

Usage: python scripts/bench_mpc.py [--roads hilly,city] [--length 6000] [--vehicle bmw_i3] [--out bench_mpc.csv]
       python scripts/bench_mpc.py --vehicle bmw_i3,truck_40t --roads hilly,long_grades [--quick]
       python scripts/bench_mpc.py --grids 4,0 [--quick]
"""

from __future__ import annotations

import argparse
import os
import platform
import time
from collections.abc import Callable
from typing import Any, cast

import numpy as np
import pandas as pd
from roadload.controllers.base import DriveContext
from roadload.controllers.closed_loop import Plant, run_closed_loop
from roadload.controllers.drive import DriveSettings
from roadload.controllers.force_model import FixedForceModel
from roadload.controllers.mpc import MpcSettings
from roadload.controllers.mpc_controller import MpcController, MpcControllerSettings
from roadload.controllers.plant import ModelPlant
from roadload.controllers.vehicle_models import abc_parameters, energy_model_from_spec
from roadload.experiments.controller_comparison import TRUCK_MPC
from roadload.road_profiles import RoadProfile, city, hilly, long_grades

CAR_MPC = DriveSettings().mpc  # the car's drives: 100 segments, the first 4 of 5 m, then 20 m
ROADS: dict[str, Callable[..., RoadProfile]] = {"hilly": hilly, "city": city, "long_grades": long_grades}


def _bench(vehicle, road_name, road, mpc, energy, params) -> dict:
    settings = MpcControllerSettings(mpc=mpc)
    ctl = MpcController(settings)
    plans: list[tuple[bool, Any]] = []  # (warm-started, plan) of every solve
    orig = ctl._replan

    def spy(obs, _orig=orig, _ctl=ctl, _plans=plans):
        before = _ctl.plan
        _orig(obs)
        if _ctl.plan is not None and _ctl.plan is not before:
            _plans.append((before is not None, _ctl.plan))

    ctl._replan = spy  # type: ignore[method-assign]  # the benchmark records every solve's plan
    ctx = DriveContext(road, energy, FixedForceModel(params))
    t0 = time.perf_counter()
    # the MPC commands every step, so the plant never needs a driver of its own (step(None))
    res = run_closed_loop(ctl, cast(Plant, ModelPlant(road, params, energy)), ctx)
    wall_run = time.perf_counter() - t0
    warm = [p for w, p in plans if w]
    cold = [p for w, p in plans if not w]
    wt = np.array([p.solve_time for p in warm]) * 1e3
    ct = np.array([p.cpu_time for p in warm]) * 1e3
    it = np.array([p.iterations for p in warm])
    label = mpc.solver if mpc.solver == "osqp" else f"ipopt tol={mpc.warm_tol:g}"
    return {"vehicle": vehicle, "road": road_name, "nodes": mpc.n_nodes, "ds_m": mpc.ds,
            "near_segments": mpc.near_segments, "solver": label,
            "warm_solves": len(warm), "cold_solves": len(cold),
            "median_ms": np.median(wt), "p99_ms": np.percentile(wt, 99), "max_ms": wt.max(),
            "cpu_median_ms": np.median(ct), "cpu_p99_ms": np.percentile(ct, 99),
            "iter_median": np.median(it), "iter_max": it.max(),
            "cold_median_ms": np.median([p.solve_time for p in cold]) * 1e3 if cold else np.nan,
            "failures": int(res.metrics.get("ctl_solver_failures", 0) or 0),
            "energy_kWh": res.metrics["energy_kWh"], "trip_time_s": res.metrics["trip_time"],
            "run_wall_s": wall_run}


def _grid_ratios(table: pd.DataFrame, grids: list[int]) -> None:
    """Per car road and solver: each grid's warm CPU median and p99 against the first grid's, same run."""
    car = table[~table.vehicle.str.startswith("truck")]
    for (road, solver), g in car.groupby(["road", "solver"], sort=False):
        ref = g[g.near_segments == grids[0]].iloc[0]
        for _, r in g[g.near_segments != grids[0]].iterrows():
            print(f"# {road}, {solver}: {r.near_segments} near segments against {grids[0]}: warm CPU median "
                  f"{r.cpu_median_ms:.2f} / {ref.cpu_median_ms:.2f} ms = {r.cpu_median_ms / ref.cpu_median_ms:.2f} x, "
                  f"p99 {r.cpu_p99_ms / ref.cpu_p99_ms:.2f} x; energy {r.energy_kWh:.4f} / {ref.energy_kWh:.4f} kWh")


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--roads", default="hilly,city")
    ap.add_argument("--length", type=float, default=6000.0, help="road length [m]")
    ap.add_argument("--vehicle", default="bmw_i3", help="comma-separated presets (bmw_i3, truck_40t, ...)")
    ap.add_argument("--out", default=None)
    ap.add_argument("--quick", action="store_true", help="tiny run (1.5 km, IPOPT tol 1e-4 only)")
    ap.add_argument("--grids", default=str(CAR_MPC.near_segments),
                    help="car: near segments of 5 m per grid, comma-separated (0: uniform 20 m)")
    args = ap.parse_args(argv)
    grids = [int(g) for g in args.grids.split(",")]
    length = 1500.0 if args.quick else args.length
    solvers = (("ipopt", 1e-4),) if args.quick else (("ipopt", 1e-4), ("ipopt", 1e-6), ("osqp", 1e-4))
    rows = []
    for vehicle in args.vehicle.split(","):
        truck = vehicle.startswith("truck")
        energy = energy_model_from_spec(vehicle)
        params = abc_parameters(vehicle)
        for road_name in args.roads.split(","):
            if truck != (road_name == "long_grades"):
                continue  # trucks on long grades, cars on the car roads
            road = ROADS[road_name](seed=1, length=length)
            for solver, warm_tol in solvers:
                for near in [0] if truck else grids:
                    base = TRUCK_MPC if truck else MpcSettings(**{**CAR_MPC.__dict__, "near_segments": near})
                    mpc = MpcSettings(**{**base.__dict__, "solver": solver, "warm_tol": warm_tol,
                                         "time_weight": 1.6e5 if truck else 9000.0})
                    rows.append(_bench(vehicle, road_name, road, mpc, energy, params))
    table = pd.DataFrame(rows)
    load = os.getloadavg()
    print(f"# MPC per-step solve time, {args.vehicle}; {platform.processor() or platform.machine()}, "
          f"{os.cpu_count()} CPUs, load average {load[0]:.1f} (1 min) during the run")
    ipopt = table[table.solver == "ipopt tol=0.0001"]
    if ipopt.vehicle.nunique() > 1:
        ref = float(ipopt[~ipopt.vehicle.str.startswith("truck")].cpu_median_ms.median())
        for _, r in ipopt[ipopt.vehicle.str.startswith("truck")].iterrows():
            print(f"# {r.vehicle} on {r.road}: IPOPT warm median CPU time {r.cpu_median_ms:.2f} ms = "
                  f"{r.cpu_median_ms / ref:.2f} x the car's 100-node median ({ref:.2f} ms) in this run (wall "
                  f"{r.median_ms:.2f} ms at this load); target <= 10 ms")
    _grid_ratios(table, grids)
    with pd.option_context("display.width", 200, "display.max_columns", 30):
        print(table.round(3).to_string(index=False))
    if args.out:
        table.to_csv(args.out, index=False)
        print(f"wrote {args.out}")
