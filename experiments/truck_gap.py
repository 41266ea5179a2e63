"""A truck run's gap to the plant-fuel bound in two parts that add up to it (``roadload benchmark optimum
--gap-parts``).

For each truck run (energy E at the source, trip time T, start and arrival speed, on the measured segment) three
quasi-static fuels on the same road, at the same T and speeds, all booked in the plant's raw fuel map:

- B: the plant-fuel bound (:class:`~roadload.controllers.dynamic_programming.PlantFuelBound`, the dynamic programme
  in the raw map at the gear of least fuel, fuel cut in overrun);
- A: the optimum of the MPC's own fuel model over the whole route: the same programme (grid, limits, boundary
  actions) optimised in the smoothed least-over-gears table phi and its traction limit that the plant-map MPC's
  NLP uses (``PlantFuelBound(model="smooth")``), and that profile's fuel booked in the raw map (A >= B up to the
  grid's interpolation of the boundary actions: B optimises the raw map itself);
- E: the run, as driven on the plant.

    E - B = (E - A)            what the receding horizon, its terminal value, the comfort term and limits, the
                               closed loop's tracking and gear request lose against the full-route optimum of the
                               same model
          + (A - B)            what the raw map's non-convexity (the fuel-cut step, the gear steps: pulsing at full
                               load and coasting in overrun at part load) is worth, which no smooth model can use

Each part as a fleet total over seeds, 100 mean(part) / mean(B), with 1-sigma and Student-t 95 % CI
(:func:`~roadload.experiments.controller_comparison.ratio_of_means_ci`); the parts' means add up to the total's
exactly (one denominator). A_phi (the smooth model's own fuel of its optimum) is printed beside: A_phi - A is the
smooth model's error on that profile.
"""

from __future__ import annotations

import time
from typing import Any

import numpy as np
import pandas as pd

from roadload.controllers.optimum import OptimumError
from roadload.experiments.controller_comparison import VEHICLE_CASES, format_difference, ratio_of_means_ci
from roadload.experiments.optimum_benchmark import benchmark_road, stored_task, truck_bound
from roadload.tables import markdown_table

# the run's own columns carried into its gap parts: the MPC's CPU for the whole drive [s], its solves' median wall
# time [s] and failed solves
RUN_COLUMNS = ("run_cpu_s", "mpc_solves", "mpc_solve_time_median_s", "mpc_solver_failures")
PARTS = {"total": "MPC above the bound", "loop": "MPC above its model's optimum",
         "nonconvex": "its model's optimum above the bound"}


def gap_parts_of_task(stored: dict[str, Any]) -> list[dict[str, Any]]:
    """One stored truck task (``tasks/*.json`` of the benchmark): per arrived MPC run its energy, the bound B and the
    smooth model's optimum A (raw map) and A_phi [J] (module docstring), solved at the run's own time, start and
    arrival speed and peak speed."""
    task = stored_task(stored["task"])
    if not VEHICLE_CASES[task.case].truck:
        return []
    road = benchmark_road(task.road, task.seed, task.warmup)
    t0 = time.process_time()
    bound = truck_bound(task, road)
    smooth = truck_bound(task, road, model="smooth", plant_bound=bound)
    out = []
    for r in stored["rows"]:
        if not (str(r["controller"]).startswith("mpc") and r.get("arrived") and np.isfinite(r.get("energy_J", np.nan))):
            continue
        peak = max(float(r.get("peak_speed") or 0.0), float(r["start_speed"]), float(r["arrival_speed"]))
        args = (float(r["time_s"]), float(r["start_speed"]), float(r["arrival_speed"]), peak)
        row = {"vehicle": task.case, "road": task.road, "seed": task.seed, "controller": r["controller"],
               "time_s": r["time_s"], "energy_J": float(r["energy_J"]),
               **{k: r[k] for k in RUN_COLUMNS if r.get(k) is not None}}
        try:
            b, _ = bound.solve(*args)
            a, sol = smooth.solve(*args)
        except OptimumError as exc:
            out.append({**row, "status": f"not solved: {exc}"})
            continue
        snap = a - float(sol.priced_energy_J if sol.priced_energy_J is not None else sol.energy_J)
        out.append({**row, "bound_J": b, "model_optimum_J": a, "model_optimum_phi_J": sol.energy_J + snap,
                    "model_optimum_time_s": sol.model_time, "model_optimum_time_slope_J_per_s": -sol.multiplier,
                    "status": "solved"})
    for row in out:
        row["cpu_s"] = time.process_time() - t0
    return out


def gap_parts(results: list[dict[str, Any]]) -> pd.DataFrame:
    """:func:`gap_parts_of_task` of every stored truck task result, one row per run, with each part [J]:
    total = E - B, loop = E - A, nonconvex = A - B (loop + nonconvex = total)."""
    rows = pd.DataFrame([r for res in results for r in gap_parts_of_task(res)])
    if rows.empty:
        return rows
    ok = rows["status"] == "solved"
    rows.loc[ok, "total_J"] = rows["energy_J"] - rows["bound_J"]
    rows.loc[ok, "loop_J"] = rows["energy_J"] - rows["model_optimum_J"]
    rows.loc[ok, "nonconvex_J"] = rows["model_optimum_J"] - rows["bound_J"]
    return rows


def gap_parts_summary(rows: pd.DataFrame) -> pd.DataFrame:
    """Per (vehicle, road, controller): each part over the bound as a fleet total [%], 1-sigma and 95 % CI, and
    the smooth model's error on its optimum's profile, 100 mean(A_phi - A) / mean(B)."""
    if rows.empty:  # no truck MPC run among the tasks
        return pd.DataFrame()
    out = []
    ok = rows[rows["status"] == "solved"]
    for (veh, road, ctl), g in ok.groupby(["vehicle", "road", "controller"], sort=False):
        b = g["bound_J"].to_numpy(float)
        rec: dict[str, Any] = {"vehicle": veh, "road": road, "controller": ctl, "seeds": len(g),
                               "time_s_mean": float(g["time_s"].mean()),
                               "run_cpu_s_mean": float(g["run_cpu_s"].mean()) if "run_cpu_s" in g else float("nan")}
        for part in PARTS:
            mean, se, lo, hi = ratio_of_means_ci(b + g[f"{part}_J"].to_numpy(float), b)
            rec.update({f"{part}_pct": mean, f"{part}_1sigma_pct": se, f"{part}_ci95_lo": lo,
                        f"{part}_ci95_hi": hi})
        rec["model_error_pct"] = ratio_of_means_ci(
            b + (g["model_optimum_phi_J"] - g["model_optimum_J"]).to_numpy(float), b)[0]
        out.append(rec)
    return pd.DataFrame(out)


def gap_parts_markdown(summary: pd.DataFrame) -> str:
    """The summary as a markdown table: each part with its CI."""
    if summary.empty:
        return "no truck run against the plant-fuel bound\n"
    return markdown_table(pd.DataFrame([
        {"vehicle": r["vehicle"], "road": r["road"], "controller": r["controller"], "seeds": r["seeds"],
         "trip time [s]": f"{r['time_s_mean']:.1f}",
         **{name: format_difference(*(r[f"{part}_{x}"] for x in ("pct", "1sigma_pct", "ci95_lo", "ci95_hi")))
            for part, name in PARTS.items()},
         "smooth model's error on its optimum": f"{r['model_error_pct']:+.2f} %",
         "CPU per drive [s]": f"{r['run_cpu_s_mean']:.0f}" if np.isfinite(r.get("run_cpu_s_mean", np.nan)) else "-"}
        for r in summary.to_dict("records")])) + "\n"
