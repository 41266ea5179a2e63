"""Per-step solve time of the spatial MPC (100-node horizon): IPOPT warm-started and the OSQP sequential-QP path.

Drives a closed loop (the controller's own force model as plant, so only the solver is timed) over a generated
hilly road and a city route and records every solve: wall-clock time (time.perf_counter) and process CPU time
(time.process_time, robust when other jobs load the machine), iterations and failures. Prints a table and, with
--out, writes it as CSV. Targets (issue): IPOPT warm median <= 5 ms and p99 <= 20 ms; QP median <= 2 ms. IPOPT
runs at the default warm-start tolerance (1e-4) and at 1e-6 for reference: the closed-loop energies show what
the looser tolerance costs.

Usage: python scripts/bench_mpc.py [--roads hilly,city] [--length 6000] [--out bench_mpc.csv]
"""

from __future__ import annotations

import argparse
import os
import platform
import time

import numpy as np
import pandas as pd
from roadload.controllers.base import DriveContext
from roadload.controllers.closed_loop import run_closed_loop
from roadload.controllers.force_model import FixedForceModel
from roadload.controllers.mpc import MpcSettings
from roadload.controllers.mpc_controller import MpcController, MpcControllerSettings
from roadload.controllers.plant import ModelPlant
from roadload.controllers.vehicle_models import abc_parameters, energy_model_from_spec
from roadload.road_profiles import city, hilly


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--roads", default="hilly,city")
    ap.add_argument("--length", type=float, default=6000.0, help="road length [m]")
    ap.add_argument("--vehicle", default="bmw_i3")
    ap.add_argument("--out", default=None)
    args = ap.parse_args()


    energy = energy_model_from_spec(args.vehicle)
    params = abc_parameters(args.vehicle)
    rows = []
    for road_name in args.roads.split(","):
        road = {"hilly": hilly, "city": city}[road_name](seed=1, length=args.length)
        for solver, warm_tol in (("ipopt", 1e-4), ("ipopt", 1e-6), ("osqp", 1e-4)):
            settings = MpcControllerSettings(mpc=MpcSettings(n_nodes=100, ds=20.0, solver=solver, time_weight=9000.0,
                                                             warm_tol=warm_tol))
            ctl = MpcController(settings)
            plans = []
            orig = ctl._replan

            def spy(obs, _orig=orig, _ctl=ctl, _plans=plans):
                before = _ctl.plan
                _orig(obs)
                if _ctl.plan is not None and _ctl.plan is not before:
                    _plans.append((before is not None, _ctl.plan))

            ctl._replan = spy
            ctx = DriveContext(road, energy, FixedForceModel(params))
            t0 = time.perf_counter()
            res = run_closed_loop(ctl, ModelPlant(road, params, energy), ctx)
            wall_run = time.perf_counter() - t0
            warm = [p for w, p in plans if w]
            cold = [p for w, p in plans if not w]
            wt = np.array([p.solve_time for p in warm]) * 1e3
            ct = np.array([p.cpu_time for p in warm]) * 1e3
            it = np.array([p.iterations for p in warm])
            label = solver if solver == "osqp" else f"ipopt tol={warm_tol:g}"
            rows.append({"road": road_name, "solver": label, "warm_solves": len(warm), "cold_solves": len(cold),
                         "median_ms": np.median(wt), "p99_ms": np.percentile(wt, 99), "max_ms": wt.max(),
                         "cpu_median_ms": np.median(ct), "cpu_p99_ms": np.percentile(ct, 99),
                         "iter_median": np.median(it), "iter_max": it.max(),
                         "cold_median_ms": np.median([p.solve_time for p in cold]) * 1e3 if cold else np.nan,
                         "failures": int(res.metrics.get("ctl_solver_failures", 0) or 0),
                         "energy_kWh": res.metrics["energy_kWh"], "trip_time_s": res.metrics["trip_time"],
                         "run_wall_s": wall_run})
    table = pd.DataFrame(rows)
    load = os.getloadavg()
    cpu = platform.processor() or platform.machine()
    print(f"# MPC per-step solve time, N=100 nodes x 20 m, {args.vehicle}; {cpu}, "
          f"{os.cpu_count()} CPUs, load average {load[0]:.1f} (1 min) during the run")
    with pd.option_context("display.width", 200, "display.max_columns", 30):
        print(table.round(3).to_string(index=False))
    if args.out:
        table.to_csv(args.out, index=False)
        print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
