"""Every controller against the full-route optimum, at its own trip time, on the same plant.

Per (vehicle case, road, condition, seed) one task drives every controller once on the same road, seed and plant
(roadload's simulator): cruise control, the truck's speed-band cruise, the human-like driver, the MPC with each
force model, and trained RL policies (PPO / SAC in EcoDrive-v0, whose plant is the same simulator, driving the
task's road: :func:`policy_episode`). For each run the full-route optimum (:mod:`roadload.controllers.optimum`:
perfect knowledge, the oracle's parameters, the MPC's comfort limits) is solved for that run's trip time and arrival
speed, from the speed the optimum's drive has at the segment start, and driven on the same plant by
:class:`~roadload.controllers.optimum.OptimumTracker`:

    excess = (E_run + dKE_start / eta_i) / E_opt(T_run, v_arr,run) - 1

E_opt is the tracked optimum's plant energy corrected to exactly the run's time and arrival speed with the optimum's
own time slope dE*/dT and the kinetic-energy difference at 1/eta_i (the tracker lands within ~0.1 % of the time);
dKE_start books the difference of the start speeds (a warm-up driven by the run itself; 0 from standstill). The
summary gives the excess as a fleet total over seeds, 100 mean(E_run - E_opt) / mean(E_opt), with its 1-sigma and
Student-t 95 % CI (:func:`roadload.experiments.controller_comparison.ratio_of_means_ci`).

The dynamic-programming cross-check (EV): the NLP (without its jerk limit) and the DP of
:mod:`roadload.controllers.dynamic_programming` on the same grid, at the cruise run's time, per seed.
"""

from __future__ import annotations

import json
import math
import time
from collections.abc import Iterable
from dataclasses import dataclass, replace
from functools import partial
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from roadload.controllers.base import ControllerError
from roadload.controllers.drive import DriveSettings, drive
from roadload.controllers.dynamic_programming import PlantFuelBound, dp_optimum
from roadload.controllers.mpc import FUEL_MODELS
from roadload.controllers.optimum import FullRouteOptimum, OptimumError, OptimumSettings, OptimumTarget
from roadload.controllers.sim_plant import SimulatorPlant
from roadload.controllers.vehicle_models import energy_model_from_spec, rotational_mass
from roadload.experiments.controller_comparison import (CONDITIONS, VEHICLE_CASES, force_model_settings,
                                                        format_difference, paired_road, ratio_of_means_ci)
from roadload.fileio import write_text
from roadload.sweep import run_sweep
from roadload.tables import markdown_table

CONTROLLERS = ("cruise", "cruise_band", "human", "mpc:oracle", "mpc:abc", "mpc:online", "mpc:online_wind",
               "mpc:oracle:transmission", *(f"mpc:oracle:{m}" for m in FUEL_MODELS), "ppo", "sac")
CAR_CONTROLLERS = ("cruise", "human", "mpc:oracle", "mpc:abc", "mpc:online", "ppo", "sac")
TRUCK_CONTROLLERS = ("cruise", "cruise_band", "human", "mpc:oracle", "mpc:abc", "mpc:online", "mpc:oracle:transmission")
TRUCK_OPTIMA = ("bound", "tracked")
# the plant-fuel bound's grid and model; stored rows of another are re-solved (run_and_store)
BOUND_KIND = ("plant-fuel bound: 40 m, 0.5 m^2/s^2, full-load and overrun actions, caps to the peak speed, "
              "a slower run against the least fuel at any time")
CSV_COLUMNS = ["vehicle", "road", "controller", "seed", "energy_J", "time_s", "optimum_energy_J", "excess_pct"]


class OptimumBenchmarkError(ValueError):
    """Bad benchmark input (unknown controller, missing policy file, ...): the message names it."""


@dataclass(frozen=True)
class OptimumTask:
    """One seed: every controller of ``controllers`` and the optimum at each run's time. warmup [m]: driven before
    the measured segment (by cruise control for the MPC runs and the optimum; the human driver drives its own);
    time_weight [J/s]: the MPC's lambda (None: the case's start value); policies: folder of ``ppo_ecodrive.zip``
    / ``sac_ecodrive.zip`` (trained by ``roadload train``); dp_step [m/s]: speed grid of the DP cross-check
    (0: none)."""

    case: str
    road: str
    seed: int
    condition: str = "nominal"
    controllers: tuple[str, ...] = CAR_CONTROLLERS
    warmup: float = 0.0
    time_weight: float | None = None
    policies: str | None = None
    dp_step: float = 0.0
    optimum_ds: float = OptimumSettings.ds
    # MPC variant (the gap breakdown): MpcSettings fields to override, the re-planning period [s] and a label
    # appended to the MPC controllers' names
    mpc: tuple[tuple[str, Any], ...] = ()
    replan_period: float | None = None
    label: str = ""
    # trucks: "bound" (the plant-fuel bound: the DP in the plant's own fuel map at the gear of least fuel, from each
    # run's own start speed) or "tracked" (the NLP optimum driven on the plant by the optimum tracker)
    truck_optimum: str = "bound"

    def __post_init__(self) -> None:
        if self.case not in VEHICLE_CASES:
            raise OptimumBenchmarkError(f"vehicle case {self.case!r}: choose one of {list(VEHICLE_CASES)}")
        bad = [c for c in self.controllers if c.partition("@")[0] not in CONTROLLERS]
        for c in self.controllers:
            if "@" in c and c not in bad:
                try:
                    force_model_settings(c.partition(":")[2])
                except ValueError as exc:
                    raise OptimumBenchmarkError(f"controller {c!r}: {exc}") from None
        if bad:
            raise OptimumBenchmarkError(f"controllers: unknown {bad}; choose from {list(CONTROLLERS)}")
        if self.condition not in CONDITIONS:
            raise OptimumBenchmarkError(f"condition {self.condition!r}: choose one of {list(CONDITIONS)}")
        if self.truck_optimum not in TRUCK_OPTIMA:
            raise OptimumBenchmarkError(f"truck_optimum {self.truck_optimum!r}: choose one of {list(TRUCK_OPTIMA)}")
        if not (math.isfinite(self.warmup) and self.warmup >= 0):
            raise OptimumBenchmarkError(f"warmup: a distance >= 0 m, got {self.warmup}")
        rl = [c for c in self.controllers if c in ("ppo", "sac")]
        if rl and (VEHICLE_CASES[self.case].truck or self.warmup > 0):
            raise OptimumBenchmarkError(f"{rl}: RL policies drive the car only (EcoDrive-v0's bmw_i3, from "
                                        f"standstill: no warm-up)")


def _settings(task: OptimumTask, controller: str) -> DriveSettings:
    """DriveSettings of one controller of the task (module docstring)."""
    case = VEHICLE_CASES[task.case]
    base = replace(case.settings(), measure_from=task.warmup, warmup_driver="cruise")
    if controller == "cruise":  # plain PI cruise control (a truck's without its speed band)
        return replace(base, controller="cruise", cruise=replace(base.cruise, overspeed=0.0))
    if controller == "cruise_band":
        return replace(base, controller="cruise")
    if controller == "human":
        return replace(base, controller="human")
    _, spec, *gears = controller.split(":")
    lam = case.lam0 if task.time_weight is None else task.time_weight
    variant = dict(task.mpc)
    lam = variant.pop("time_weight", lam)  # a variant's lambda [J/s] (the DriveSettings' value reaches the MPC)
    lam *= variant.pop("time_weight_scale", 1.0)
    # ICE: the MPC requests its shift rule's gear (and a kick-down where full load needs it), as the optimum's tracker
    # does: the plant's own load-dependent strategy changes the fuel of a whole climb for a 0.1 % change of the
    # trajectory, which no plan can follow (docs/results/controllers.md); 'mpc:<model>:transmission' leaves the gear
    # to the transmission (the MPC's default elsewhere)
    if case.truck and len(gears) == 1 and gears[0] in FUEL_MODELS:  # 'mpc:<model>:<fuel model>' (MpcSettings)
        variant.setdefault("fuel_model", gears[0])
    settings = replace(base, controller="mpc", **force_model_settings(spec), time_weight=lam,
                       gear_command=case.truck and gears != ["transmission"], mpc=replace(base.mpc, **variant))
    return settings if task.replan_period is None else replace(settings, replan_period=task.replan_period)


POLICY_MIN_MEAN_SPEED = 2.0
"""[m/s] A policy's episode on a benchmark road is cut at road length / this + 60 s (EcoDrive-v0 cuts at twice its
schedule time + 30 s, where a policy that coasts through 3 km of motorway from 23 m/s is cut 10 m before the end;
the time limit is not in the observation, so it does not change how the policy drives)."""


def policy_episode(policy, env_config: dict[str, Any], road, seed: int) -> dict[str, Any]:
    """One episode of EcoDrive-v0 driven by ``policy(obs) -> action`` on the benchmark's ``road`` (any car road:
    hilly, city, motorway_short, route), not on a road of EcoDrive-v0's own generator: the road is written to a
    profile file and the env's route table (preview of grade, curvature, speed limits, stops, the schedule) is
    built from it, the rest of the env (observation, action mapping, speed shield, plant) as the policy learnt it.
    Returns the run metrics in the closed loop's names (segment = the whole road) plus the stop lines crossed
    faster than the env's stop_speed."""
    import tempfile

    from roadload.experiments.rl.rollouts import run_policy
    from roadload.road_profiles import save_profile

    with tempfile.TemporaryDirectory(prefix="roadload-policy-road-") as tmp:
        path = save_profile(road, Path(tmp) / "road.json")
        m, _ = run_policy(policy, {**env_config, "road": str(path), "route_length": road.length,
                                   "time_limit": road.length / POLICY_MIN_MEAN_SPEED + 60.0}, seed)
    return {"segment_time": m["arrival_time"], "segment_energy_J": m["arrival_energy_J"],
            "segment_start_speed": 0.0, "arrival_speed": m["arrival_speed"], "arrived": m["arrived"],
            "speed_violations": m["speed_violations"], "stop_violations": m["stop_violations"]}


def _policy_run(task: OptimumTask, algo: str, road) -> dict[str, Any]:
    """One episode of the trained policy ``algo`` of ``task.policies`` on the task's road
    (:func:`policy_episode`), in the env configuration it was trained with and the task's condition."""
    from roadload.experiments.rl.rollouts import sb3_policy
    from roadload.experiments.rl.training import load_policy

    folder = Path(task.policies or "")
    path = folder / f"{algo}_ecodrive.zip"
    if task.policies is None or not path.is_file():
        raise OptimumBenchmarkError(f"{algo}: no trained policy {path} (train one with `roadload train --algo "
                                    f"{algo} --out DIR` and pass --policies DIR)")
    meta_path = folder / f"{algo}_ecodrive.json"
    env_config = json.loads(meta_path.read_text()).get("env_config", {}) if meta_path.is_file() else {}
    if CONDITIONS[task.condition] is not None:  # nominal: the env's own default (no effects)
        env_config["effects"] = CONDITIONS[task.condition]
    return policy_episode(sb3_policy(load_policy(path)), env_config, road, task.seed)


def benchmark_road(name: str, seed: int, warmup: float = 0.0):
    """The task's road: :func:`~roadload.experiments.controller_comparison.paired_road` (``route`` = the EcoDrive-v0
    route of the seed, where the RL policies were trained)."""
    return paired_road(name, seed, warmup)


def run_optimum_task(task: OptimumTask) -> dict[str, Any]:
    """Every controller and its optimum on one seed (module docstring): rows and the DP cross-check."""
    case = VEHICLE_CASES[task.case]
    road = benchmark_road(task.road, task.seed, task.warmup)
    effects = CONDITIONS[task.condition]
    vehicle = case.vehicle()
    energy = energy_model_from_spec(vehicle)
    eta = energy.indicated_efficiency
    opt_settings = OptimumSettings(ds=task.optimum_ds)
    rows: list[dict[str, Any]] = []
    t0 = time.process_time()

    def run(settings: DriveSettings) -> dict[str, Any]:
        cpu0 = time.process_time()
        res, plant = drive(vehicle, road, effects=effects, seed=task.seed, settings=settings)
        m = dict(res.metrics)
        m["run_cpu_s"] = time.process_time() - cpu0
        m["inertial_mass"] = plant.true_parameters().inertial_mass
        m["segment_peak_speed"] = float(res.log["v"][res.log["s"] >= task.warmup].max())
        return m

    bound = truck_bound(task, road) if case.truck and task.truck_optimum == "bound" else None
    for controller in task.controllers:
        if controller in ("ppo", "sac"):
            m = _policy_run(task, controller, road)
            m["inertial_mass"] = SimulatorPlant(vehicle, road, effects=effects, seed=task.seed).true_parameters(
                ).inertial_mass
        else:
            m = run(_settings(task, controller))
        if m.get("stop_violations"):  # EcoDrive-v0 prices a stop line crossed too fast, it has no stop and dwell
            rows.append({"vehicle": task.case, "road": task.road, "controller": controller, "seed": task.seed,
                         "condition": task.condition, "arrived": bool(m.get("arrived")), "time_s": m["segment_time"],
                         "energy_raw_J": m["segment_energy_J"], "stop_violations": m["stop_violations"],
                         "speed_violations": m.get("speed_violations"),
                         "optimum_status": f"not comparable: crossed {m['stop_violations']} stop line(s) faster "
                                           f"than EcoDrive-v0's stop_speed; the optimum stops and dwells at each"})
            continue
        if not (m.get("arrived", False) and math.isfinite(m["segment_time"])):
            rows.append({"vehicle": task.case, "road": task.road, "controller": controller + task.label,
                         "seed": task.seed,
                         "condition": task.condition, "arrived": False})
            continue
        if bound is not None:
            rows.append(_bound_row(bound, controller + task.label if controller.startswith("mpc") else controller,
                                   task, m))
            continue
        target = OptimumTarget(trip_time=float(m["segment_time"]), arrival_speed=float(m["arrival_speed"]))
        opt_drive = replace(_settings(task, "cruise_band"), controller="optimum", force_model="oracle",
                            optimum_target=target, optimum=opt_settings)
        name = controller + task.label if controller.startswith("mpc") else controller
        base_row = {"vehicle": task.case, "road": task.road, "controller": name, "seed": task.seed,
                    "condition": task.condition, "arrived": True, "time_s": m["segment_time"],
                    "energy_raw_J": m["segment_energy_J"], "arrival_speed": m["arrival_speed"],
                    "start_speed": m["segment_start_speed"], "speed_violations": m.get("speed_violations"),
                    **online_columns(m.get("online"), task.warmup),
                    **({"stop_violations": m["stop_violations"]} if "stop_violations" in m else {})}
        try:
            o = run(opt_drive)
        except (ControllerError, OptimumError) as exc:  # e.g. a driver faster than the limits and comfort allow
            rows.append({**base_row, "optimum_status": f"not solved: {exc}"})
            continue
        mass = m["inertial_mass"]
        slope = float(o.get("ctl_optimum_time_slope", float("nan")))
        e_opt = (o["segment_energy_J"] + slope * (m["segment_time"] - o["segment_time"])
                 + 0.5 * mass * (m["arrival_speed"] ** 2 - o["arrival_speed"] ** 2) / eta)
        e_run = m["segment_energy_J"] + 0.5 * mass * (m["segment_start_speed"] ** 2
                                                     - o["segment_start_speed"] ** 2) / eta
        rows.append({**base_row, "energy_J": e_run, "optimum_energy_J": e_opt,
                     "excess_pct": difference_pct(e_run, e_opt),
                     "optimum_model_energy_J": o.get("ctl_optimum_model_energy_J"),
                     "optimum_plant_energy_J": o["segment_energy_J"], "optimum_time_s": o["segment_time"],
                     "optimum_arrival_speed": o["arrival_speed"], "optimum_start_speed": o["segment_start_speed"],
                     "optimum_time_slope_J_per_s": slope, "optimum_status": o.get("ctl_optimum_status"),
                     "optimum_speed_violations": o.get("speed_violations")})
    out: dict[str, Any] = {"task": task.__dict__, "rows": rows}
    if task.dp_step > 0 and energy.kind == "ev":
        out["dp"] = dp_check(task, road, rows, opt_settings)
    out["cpu_s"] = time.process_time() - t0
    return out


def online_columns(online: dict[str, Any] | None, warmup: float) -> dict[str, Any]:
    """An online force model's diagnostics for a run's row: its change alarms, clipped parameters, the estimated
    wind (speed [m/s], direction [rad]) and its estimate (JSON, parameter name -> value) at the start of the measured
    segment (the last update before ``warmup`` [m]) and at the end; {} for other force models."""
    if not online:
        return {}
    hist = online.get("history") or {}
    names, xs, s = hist.get("parameters", []), hist.get("x", []), hist.get("s", [])
    before = [i for i, si in enumerate(s) if si <= warmup]
    start = dict(zip(names, xs[before[-1]])) if before else {}
    return {"online_alarms": online.get("change_alarms"), "online_clipped": online.get("clipped"),
            "online_wind_speed": online.get("wind_speed"), "online_wind_direction": online.get("wind_direction"),
            "online_estimate_start": json.dumps(start), "online_estimate_end": json.dumps(online.get("estimate", {}))}


def _bound_row(bound: PlantFuelBound, name: str, task: OptimumTask, m: dict[str, Any]) -> dict[str, Any]:
    """A truck run against the plant-fuel bound at its own trip time, start and arrival speed (not driven: the
    bound is quasi-static)."""
    row = {"vehicle": task.case, "road": task.road, "controller": name, "seed": task.seed,
           "condition": task.condition, "arrived": True, "time_s": m["segment_time"],
           "energy_raw_J": m["segment_energy_J"], "arrival_speed": m["arrival_speed"],
           "start_speed": m["segment_start_speed"], "speed_violations": m.get("speed_violations"),
           "peak_speed": m.get("segment_peak_speed"), "optimum_kind": BOUND_KIND,
           # the MPC's cost in CPU (the whole drive, warm-up included) and its solves (MPC runs only)
           **{k: m[src] for k, src in (("run_cpu_s", "run_cpu_s"), ("mpc_solves", "ctl_solves"),
                                       ("mpc_solve_time_median_s", "ctl_solve_time_median"),
                                       ("mpc_solver_failures", "ctl_solver_failures")) if src in m}}
    t0 = time.process_time()
    try:
        # the run's peak speed (a stored run without it: at least its start and arrival speeds)
        peak = max(float(m.get("segment_peak_speed") or 0.0), float(m["segment_start_speed"]),
                   float(m["arrival_speed"]))
        e_opt, sol = bound.solve(float(m["segment_time"]), float(m["segment_start_speed"]), float(m["arrival_speed"]),
                                 peak)
    except OptimumError as exc:
        return {**row, "optimum_status": f"not solved: {exc}"}
    return {**row, "energy_J": m["segment_energy_J"], "optimum_energy_J": e_opt,
            "excess_pct": difference_pct(m["segment_energy_J"], e_opt), "optimum_time_s": sol.model_time,
            "optimum_arrival_speed": float(sol.v[-1]), "optimum_start_speed": float(sol.v[0]),
            "optimum_time_slope_J_per_s": -sol.multiplier,
            "optimum_status": "solved" if sol.model_time >= float(m["segment_time"]) - 1e-6 else
            f"solved: the least fuel at any time ({sol.model_time:.1f} s; the run is slower)",
            "optimum_min_speed": float(sol.v.min()), "optimum_cpu_s": time.process_time() - t0}


def stored_task(fields: dict[str, Any]) -> OptimumTask:
    """The OptimumTask of a stored result's ``task`` (JSON lists back to tuples)."""
    fields = {**fields, "controllers": tuple(fields["controllers"]),
              "mpc": tuple(tuple(x) for x in fields.get("mpc", ()))}
    return OptimumTask(**fields)


def _stale_bound(task: OptimumTask, stored: dict[str, Any]) -> bool:
    return VEHICLE_CASES[task.case].truck and task.truck_optimum == "bound" and any(
        r.get("arrived") and r.get("optimum_kind") != BOUND_KIND for r in stored["rows"])


def rebound_rows(task: OptimumTask, rows: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Stored truck rows against the current plant-fuel bound (each run's time, energy, start and arrival speed
    kept; the runs are not driven again)."""
    bound = truck_bound(task, benchmark_road(task.road, task.seed, task.warmup))
    out = []
    for r in rows:
        if not r.get("arrived"):
            out.append(r)
            continue
        m = {"segment_time": r["time_s"], "segment_energy_J": r["energy_raw_J"], "arrival_speed": r["arrival_speed"],
             "segment_start_speed": r["start_speed"], "speed_violations": r.get("speed_violations"),
             "segment_peak_speed": r.get("peak_speed")}
        out.append(_bound_row(bound, r["controller"], task, m))
    return out


# the bounds of the last segment built (a breakdown's variants, one task each, share their seed's road; building
# the programme's costs takes ~35 s of CPU on a 4 km segment at 40 t, solving it ~5 s)
_SEGMENT_BOUNDS: dict[tuple[Any, ...], PlantFuelBound] = {}


def truck_bound(task: OptimumTask, road, model: str = "plant", plant_bound: PlantFuelBound | None = None
                ) -> PlantFuelBound:
    """The plant-fuel bound of the task's measured segment (``model`` "smooth": the optimum of the plant-map MPC's
    own smoothed fuel model, booked in the plant's map, reusing ``plant_bound``'s costs, which must be the same
    segment's; :class:`PlantFuelBound`). ``road`` is the task's road (:func:`benchmark_road`); the last segment's
    bounds are kept and reused by the next task on the same segment."""
    segment = (task.case, task.road, task.seed, task.warmup, task.condition, road.length)
    if any(key[:-1] != segment for key in _SEGMENT_BOUNDS):
        _SEGMENT_BOUNDS.clear()
    key = (*segment, model)
    if key not in _SEGMENT_BOUNDS:
        vehicle = VEHICLE_CASES[task.case].vehicle()
        params = replace(SimulatorPlant(vehicle, road, effects=CONDITIONS[task.condition], seed=task.seed
                                        ).true_parameters(), rotational_mass=rotational_mass(vehicle))
        _SEGMENT_BOUNDS[key] = PlantFuelBound(road, vehicle, params, start=task.warmup, model=model,
                                              plant_bound=plant_bound)
    return _SEGMENT_BOUNDS[key]


def difference_pct(value: float, reference: float) -> float:
    """100 (value - reference) / |reference| [%]: positive when ``value`` is the larger energy, also on a route
    whose net energy is negative (downhill, more regenerated than drawn), where value / reference - 1 flips sign."""
    return 100.0 * (value - reference) / abs(reference)


def dp_table(results: list[dict[str, Any]]) -> pd.DataFrame:
    """dp_check.csv of stored task results; the differences recomputed from the two energies (results stored
    before the sign-safe difference carry value / reference - 1)."""
    dp = pd.DataFrame([res["dp"] for res in results if "dp" in res])
    if len(dp):
        dp["dp_minus_nlp_J"] = dp["dp_energy_J"] - dp["nlp_energy_J"]
        dp["dp_vs_nlp_pct"] = [difference_pct(d, n) for d, n in zip(dp["dp_energy_J"], dp["nlp_energy_J"])]
    return dp


def dp_check(task: OptimumTask, road, rows: list[dict[str, Any]], settings: OptimumSettings) -> dict[str, Any]:
    """NLP without the jerk limit and DP on the same grid at the first arrived run's time (the cruise run's)."""
    case = VEHICLE_CASES[task.case]
    ref = next(r for r in rows if r.get("arrived"))
    plant = SimulatorPlant(case.vehicle(), road, effects=CONDITIONS[task.condition], seed=task.seed)
    energy = energy_model_from_spec(case.vehicle())
    st = replace(settings, jerk=False)
    opt = FullRouteOptimum(road, energy, plant.true_parameters(), st, start=task.warmup)
    sol = opt.solve(ref["time_s"], ref["optimum_start_speed"], ref["arrival_speed"])
    t0 = time.process_time()
    dp = dp_optimum(opt.preview, energy, plant.true_parameters(), sol.model_time, ref["optimum_start_speed"],
                    ref["arrival_speed"], st, speed_step=task.dp_step)
    return {"controller": ref["controller"], "time_s": ref["time_s"], "nlp_energy_J": sol.energy_J,
            "dp_energy_J": dp.energy_J, "dp_minus_nlp_J": dp.energy_J - sol.energy_J,
            "dp_vs_nlp_pct": difference_pct(dp.energy_J, sol.energy_J),
            "nlp_time_slope": sol.time_slope, "dp_multiplier": dp.multiplier, "speed_step": task.dp_step,
            "max_speed_difference": float(np.max(np.abs(dp.v - sol.plan.v))), "dp_cpu_s": time.process_time() - t0}


# the gap breakdown: the oracle MPC with one design choice at a time set to the optimum's (or refined), and all
# together; values per vehicle kind (car: 8 x 5 m, then 20 m to 1.88 km, re-planning every 1 s; truck: 40 x 50 m =
# 2 km, re-planning every 1 s, control period 0.2 s). "time_weight" [J/s] replaces lambda, "time_weight_scale"
# multiplies the case's lambda (both handled by _settings, not MpcSettings fields)
BREAKDOWN: dict[str, dict[str, tuple[dict[str, Any], float | None]]] = {
    "car": {"": ({}, None),
            "|uniform 20 m grid": ({"near_segments": 0}, None),
            "|near grid 8 x 5 m": ({"near_segments": 8}, None),
            "|horizon 4 km": ({"n_nodes": 200}, None),
            "|grid 10 m": ({"n_nodes": 200, "ds": 10.0}, None),
            "|no comfort term": ({"accel_weight": 0.0}, None),
            "|no speed margin": ({"speed_margin": 0.0}, None),
            "|tol 1e-8": ({"warm_tol": 1e-8}, None),
            "|re-plan 0.2 s": ({}, 0.2),
            "|lambda 4000": ({"time_weight": 4000.0}, None),
            "|lambda 2000": ({"time_weight": 2000.0}, None),
            "|all": ({"n_nodes": 200, "ds": 10.0, "accel_weight": 0.0, "warm_tol": 1e-8}, 0.2)},
    "truck": {"": ({}, None),
              "|horizon 4 km": ({"n_nodes": 80}, None),
              # the long grades' measured 4 km from the hand-over: the horizon ends on the route end, where the
              # terminal value applies (the most any terminal value at a 2 km horizon end could give)
              "|route end in the horizon": ({"n_nodes": 80, "horizon_to_route_end": True}, None),
              "|grid 25 m": ({"n_nodes": 80, "ds": 25.0}, None),
              "|near grid 8 x 12.5 m": ({"n_nodes": 46, "near_segments": 8, "near_ds": 12.5}, None),  # 2 km
              "|no comfort term": ({"accel_weight": 0.0}, None),
              # the bound's caps are the speed limits (or the run's peak above them): no margin below them
              "|no speed margin": ({"speed_margin": 0.0}, None),
              "|terminal at the wheel": ({"terminal_value": "wheel"}, None),
              "|tol 1e-8": ({"warm_tol": 1e-8}, None),
              "|re-plan 0.2 s": ({}, 0.2),
              "|lambda x0.5": ({"time_weight_scale": 0.5}, None),
              "|all": ({"n_nodes": 160, "ds": 25.0, "accel_weight": 0.0, "warm_tol": 1e-8}, 0.2)},
}


def road_seeds(seeds: int | list[int], first_seed: dict[str, int], road: str) -> list[int]:
    """The seeds of ``road``: ``seeds`` themselves (a list), or a count of them from the road's first seed (0 unless
    ``first_seed`` names one, e.g. 50000 for the EcoDrive routes)."""
    return list(seeds) if isinstance(seeds, list) else [first_seed.get(road, 0) + i for i in range(seeds)]


def breakdown_tasks(cases: dict[str, list[str]], seeds: int | list[int], first_seed: dict[str, int] | None = None,
                    controller: str = "mpc:oracle", variants: list[str] | None = None,
                    **common: Any) -> list[OptimumTask]:
    """The MPC ``controller`` (an 'mpc:oracle' variant, e.g. 'mpc:oracle:plant_map') in every BREAKDOWN variant of
    its vehicle kind, or in those labelled ``variants`` ('' or 'base': the unchanged MPC; labels with or without
    the leading '|'), the labels appended to its name; per case and road seed-major; ``seeds``: a count (from
    first_seed per road) or the seeds themselves."""
    if not controller.startswith("mpc:oracle"):
        raise OptimumBenchmarkError(f"breakdown: the controller must be an oracle MPC ('mpc:oracle' or "
                                    f"'mpc:oracle:<fuel model>'), got {controller!r}")
    first = first_seed or {}
    out = []
    for case, roads in cases.items():
        kind = "truck" if VEHICLE_CASES[case].truck else "car"
        chosen = BREAKDOWN[kind]
        if variants is not None:
            wanted = ["" if v in ("", "base") else "|" + v.lstrip("|") for v in variants]
            unknown = [v for v in wanted if v not in chosen]
            if unknown:
                raise OptimumBenchmarkError(f"breakdown variants: unknown {unknown} for the {kind}; choose from "
                                            f"{['base', *(k.lstrip('|') for k in chosen if k)]}")
            chosen = {k: chosen[k] for k in wanted}
        for road in roads:
            for seed in road_seeds(seeds, first, road):
                for label, (mpc, replan) in chosen.items():
                    out.append(OptimumTask(case, road, seed, controllers=(controller,),
                                           mpc=tuple(sorted(mpc.items())), replan_period=replan, label=label,
                                           **common))
    return out


def optimum_tasks(cases: dict[str, list[str]], seeds: int | list[int], first_seed: dict[str, int] | None = None,
                  controllers: dict[str, tuple[str, ...]] | None = None, **common: Any) -> list[OptimumTask]:
    """Tasks seed-major over {case: [road, ...]}; ``seeds``: a count from first_seed per road (e.g. 50000 for the
    EcoDrive routes) or the seeds themselves."""
    first = first_seed or {}
    out = []
    for i in range(seeds if isinstance(seeds, int) else len(seeds)):
        for case, roads in cases.items():
            for road in roads:
                ctl = (controllers or {}).get(case) or (TRUCK_CONTROLLERS if VEHICLE_CASES[case].truck
                                                         else CAR_CONTROLLERS)
                out.append(OptimumTask(case, road, road_seeds(seeds, first, road)[i], controllers=ctl, **common))
    return out


def run_and_store(task: OptimumTask, folder: str) -> dict[str, Any]:
    """run_optimum_task, the result also written to ``folder`` as soon as it is done (a stopped sweep keeps it);
    a task whose result is already there (the same task) is read back, not run again."""
    path = Path(folder) / f"{task.case}_{task.road}_{task.condition}_{task.seed}{task.label}.json"
    if path.is_file():
        stored = json.loads(path.read_text())
        if stored.get("task") == json.loads(json.dumps(task.__dict__, default=float)):
            if _stale_bound(task, stored):  # the runs kept, the bound re-solved with the current grid
                stored["rows"] = rebound_rows(task, stored["rows"])
                write_text(path, json.dumps(stored, default=float))
            return stored
    result = run_optimum_task(task)
    path.parent.mkdir(parents=True, exist_ok=True)
    write_text(path, json.dumps(result, default=float))
    return result


def summarise(rows: pd.DataFrame, reference: str = "mpc:oracle") -> pd.DataFrame:
    """Per (vehicle, road, condition, controller): seeds, mean time and energy, the excess over the optimum as a
    fleet total with 1-sigma and 95 % CI, and the paired difference to ``reference`` at equal time
    (:func:`equal_time_difference`)."""
    out = []
    ok = rows[rows["arrived"].astype(bool) & np.isfinite(rows.get("optimum_energy_J", np.nan))] if len(rows) else rows
    if "condition" not in ok:
        ok = ok.assign(condition="nominal")
    for (veh, road, cond, ctl), g in ok.groupby(["vehicle", "road", "condition", "controller"], sort=False):
        mean, se, lo, hi = ratio_of_means_ci(g["energy_J"].to_numpy(float), g["optimum_energy_J"].to_numpy(float))
        ref = ok[(ok.vehicle == veh) & (ok.road == road) & (ok.condition == cond) & (ok.controller == reference)]
        d_mean, d_se, d_lo, d_hi = equal_time_difference(g, ref)
        out.append({"vehicle": veh, "road": road, "condition": cond, "controller": ctl, "seeds": len(g),
                    "time_s_mean": float(g["time_s"].mean()), "energy_kJ_mean": float(g["energy_J"].mean()) / 1e3,
                    "optimum_kJ_mean": float(g["optimum_energy_J"].mean()) / 1e3,
                    "excess_pct": mean, "excess_1sigma_pct": se, "excess_ci95_lo": lo, "excess_ci95_hi": hi,
                    "excess_per_seed_median_pct": float(g["excess_pct"].median()),
                    f"vs_{reference}_pct": d_mean, f"vs_{reference}_1sigma_pct": d_se,
                    f"vs_{reference}_ci95_lo": d_lo, f"vs_{reference}_ci95_hi": d_hi,
                    "optimum_time_error_pct_max": float(100 * np.max(np.abs(g["optimum_time_s"] / g["time_s"] - 1))),
                    "runs_left_out": int(len(rows[(rows.vehicle == veh) & (rows.road == road)
                                                  & (rows.controller == ctl)]) - len(g))})
    return pd.DataFrame(out)


def equal_time_difference(runs: pd.DataFrame, reference: pd.DataFrame) -> tuple[float, float, float, float]:
    """A controller against a reference controller at equal time, paired per seed: each run's excess over the
    optimum at its own trip time and arrival speed, E - E_opt(T, v_arr) [J], less the reference run's, as a fleet
    total over the reference's energy, 100 mean(dE - dE_ref) / mean(E_ref) [%] with 1-sigma and 95 % CI
    (:func:`~roadload.experiments.controller_comparison.ratio_of_means_ci`; the seeds both arrived on)."""
    both = runs.merge(reference, on="seed", suffixes=("", "_ref"))
    if both.empty:
        return (float("nan"),) * 4
    ref_energy = both["energy_J_ref"].to_numpy(float)
    excess = (both["energy_J"] - both["optimum_energy_J"]).to_numpy(float)
    ref_excess = (both["energy_J_ref"] - both["optimum_energy_J_ref"]).to_numpy(float)
    return ratio_of_means_ci(ref_energy + excess - ref_excess, ref_energy)


def pace_and_drive(rows: pd.DataFrame, time_weights: dict[str, float], reference: str = "mpc:oracle"
                   ) -> pd.DataFrame:
    """Each controller's cost E + lambda T [J] (lambda per vehicle case [J/s], the MPC's objective and the RL
    reward) against the reference's, paired per seed, split along the optimum's time-energy curve:
    pace = (E_opt(T) + lambda T) - (E_opt(T_ref) + lambda T_ref), what its trip time alone costs or saves when both
    drive optimally; drive = (E - E_opt(T)) - (E_ref - E_opt(T_ref)), its excess over the optimum at its own time
    less the reference's. Fleet totals over the reference's mean cost [%] with 1-sigma and 95 % CI."""
    out = []
    ok = rows[rows["arrived"].astype(bool) & np.isfinite(rows.get("optimum_energy_J", np.nan))] if len(rows) else rows
    for (veh, road, cond), g in ok.groupby(["vehicle", "road", "condition"], sort=False):
        lam = time_weights.get(veh, float("nan"))
        ref = g[g.controller == reference]
        for ctl, runs in g[g.controller != reference].groupby("controller", sort=False):
            both = runs.merge(ref, on="seed", suffixes=("", "_ref"))
            if both.empty:
                continue
            cost_ref = (both["energy_J_ref"] + lam * both["time_s_ref"]).to_numpy(float)
            pace = ((both["optimum_energy_J"] + lam * both["time_s"])
                    - (both["optimum_energy_J_ref"] + lam * both["time_s_ref"])).to_numpy(float)
            drive = ((both["energy_J"] - both["optimum_energy_J"])
                     - (both["energy_J_ref"] - both["optimum_energy_J_ref"])).to_numpy(float)
            row = {"vehicle": veh, "road": road, "condition": cond, "controller": ctl, "reference": reference,
                   "time_weight_J_per_s": lam, "seeds": len(both), "time_s": float(both["time_s"].mean()),
                   "time_s_ref": float(both["time_s_ref"].mean())}
            for name, part in (("cost", pace + drive), ("pace", pace), ("drive", drive)):
                mean, se, lo, hi = ratio_of_means_ci(cost_ref + part, cost_ref)
                row.update({f"{name}_pct": mean, f"{name}_1sigma_pct": se, f"{name}_ci95_lo": lo,
                            f"{name}_ci95_hi": hi})
            out.append(row)
    return pd.DataFrame(out)


def reference_controller(controllers: Iterable[str]) -> str:
    """The controller the others are compared with at equal time: the oracle MPC ('mpc:oracle'), else the first
    oracle MPC variant among ``controllers`` ('mpc:oracle:plant_map', ...), else 'mpc:oracle'."""
    names = list(dict.fromkeys(controllers))
    if "mpc:oracle" in names:
        return "mpc:oracle"
    return next((c for c in names if c.startswith("mpc:oracle:")), "mpc:oracle")


def reference_name(reference: str) -> str:
    """The reference as the tables name it: 'the oracle MPC' or the controller's own name."""
    return "the oracle MPC" if reference == "mpc:oracle" else reference


def summary_markdown(summary: pd.DataFrame, dp: pd.DataFrame | None = None) -> str:
    """The excess table (every difference with its CI, against the reference summarise() compared with) and the
    DP cross-check."""
    refs = [c[3:-4] for c in summary.columns if c.startswith("vs_") and c.endswith("_pct") and "1sigma" not in c]
    ref = refs[0] if refs else "mpc:oracle"  # the reference summarise() compared with
    name = reference_name(ref)
    rows = [{"vehicle": r["vehicle"], "road": r["road"], "condition": r.get("condition", "nominal"),
             "controller": r["controller"], "seeds": r["seeds"],
             "trip time [s]": round(r["time_s_mean"], 1), "energy [kJ]": round(r["energy_kJ_mean"], 1),
             "optimum [kJ]": round(r["optimum_kJ_mean"], 1),
             "excess over the optimum": format_difference(r["excess_pct"], r["excess_1sigma_pct"],
                                                          r["excess_ci95_lo"], r["excess_ci95_hi"]),
             f"vs {name} at equal time": "reference" if r["controller"] == ref else format_difference(
                 *(r.get(f"vs_{ref}_{k}", float("nan")) for k in ("pct", "1sigma_pct", "ci95_lo", "ci95_hi")))}
            for r in summary.to_dict("records")]
    md = ["Energy at the source above the full-route optimum at each run's own trip time and arrival speed, on the "
          "same plant; fleet total over seeds, mean [95 % CI] (1σ); 'not resolved': the CI contains 0. Against "
          f"{name}: the two runs' excesses over their optima, paired per seed, over {name}'s energy.", "",
          markdown_table(pd.DataFrame(rows))]
    if dp is not None and len(dp):
        mean, se, lo, hi = ratio_of_means_ci(dp["dp_energy_J"].to_numpy(float), dp["nlp_energy_J"].to_numpy(float))
        md += ["", f"DP vs NLP (EV, no jerk limit, speed grid {dp['speed_step'].iloc[0]:g} m/s, {len(dp)} seeds): "
               f"{format_difference(mean, se, lo, hi)}; per seed {dp['dp_vs_nlp_pct'].min():+.3f} … "
               f"{dp['dp_vs_nlp_pct'].max():+.3f} % of |E_NLP|, {dp['dp_minus_nlp_J'].min():+.0f} … "
               f"{dp['dp_minus_nlp_J'].max():+.0f} J (DP above the NLP: > 0)"]
    return "\n".join(md) + "\n"


def run_benchmark(tasks: list[OptimumTask], out: Path, scheduler: str | None = None, workers: int | None = None,
                  merge: list[Path] | None = None) -> tuple[pd.DataFrame, pd.DataFrame, list[str]]:
    """Run the tasks on the sweep runner; write excess_over_optimum.csv (one row per controller run),
    summary.csv / summary.md and dp_check.csv into ``out``. Returns (rows, summary, failures)."""
    out.mkdir(parents=True, exist_ok=True)
    outcomes = run_sweep(partial(run_and_store, folder=str(out / "tasks")), tasks, scheduler=scheduler,
                         workers=workers, description="optimum benchmark")
    results = [o.value for o in outcomes if o.ok]
    for path in merge or []:
        for p in sorted(Path(path).glob("*.json")):
            stored = json.loads(p.read_text())
            task = stored_task(stored["task"])
            if _stale_bound(task, stored):  # re-solved once, written back as run_and_store does
                stored["rows"] = rebound_rows(task, stored["rows"])
                write_text(p, json.dumps(stored, default=float))
            results.append(stored)
    failures = [f"{o.task.case}/{o.task.road}/seed {o.task.seed}: {o.error}" for o in outcomes if not o.ok]
    rows, summary = write_tables(results, failures, out)
    return rows, summary, failures


def write_tables(results: list[dict[str, Any]], failures: list[str], out: Path) -> tuple[pd.DataFrame, pd.DataFrame]:
    """excess_over_optimum.csv, summary.csv / summary.md and dp_check.csv of stored task results into ``out``."""
    rows = pd.DataFrame([r for res in results for r in res["rows"]])
    extra = [c for c in rows.columns if c not in CSV_COLUMNS]
    rows = rows[[c for c in CSV_COLUMNS if c in rows.columns] + extra] if len(rows) else rows
    write_text(out / "excess_over_optimum.csv", rows.to_csv(index=False))
    ref = reference_controller(rows["controller"]) if len(rows) else "mpc:oracle"
    summary = summarise(rows, ref) if len(rows) else pd.DataFrame()
    write_text(out / "summary.csv", summary.to_csv(index=False))
    dp = dp_table(results)
    write_text(out / "dp_check.csv", dp.to_csv(index=False))
    md = summary_markdown(summary, dp) if len(summary) else "no run arrived\n"
    lams = {res["task"]["case"]: res["task"].get("time_weight") or VEHICLE_CASES[res["task"]["case"]].lam0
            for res in results}
    split = pace_and_drive(rows, lams, ref) if len(rows) else pd.DataFrame()
    write_text(out / "pace_drive.csv", split.to_csv(index=False))
    if len(split):
        md += (f"\nCost E + lambda T against {reference_name(ref)}, paired per seed, split into pace (the optimum "
               "at each trip time) and drive (each run's excess over its optimum):\n\n" + markdown_table(pd.DataFrame(
                   [{"vehicle": r["vehicle"], "road": r["road"], "controller": r["controller"],
                     "lambda [J/s]": r["time_weight_J_per_s"], "seeds": r["seeds"],
                     "trip time [s] (reference)": f"{r['time_s']:.1f} ({r['time_s_ref']:.1f})",
                     **{f"{k} vs {reference_name(ref)}": format_difference(*(r[f"{k}_{x}"] for x in (
                         "pct", "1sigma_pct", "ci95_lo", "ci95_hi"))) for k in ("cost", "pace", "drive")}}
                    for r in split.to_dict("records")])) + "\n")
    if failures:
        md += "\nFailed tasks:\n\n" + "\n".join(f"- {f}" for f in failures) + "\n"
    write_text(out / "summary.md", "# Excess over the full-route optimum\n\n" + md)
    return rows, summary


# ----------------------------------------------------------------------------------- the RL episode's cost
EPISODE_MPC_VARIANTS: dict[str, dict[str, Any]] = {
    "mpc:oracle": {},
    "mpc:oracle|route end, KE worth nothing": {"horizon_to_route_end": True, "terminal_value": "none"},
    "mpc:oracle|route end, KE at source value": {"horizon_to_route_end": True},
}


@dataclass(frozen=True)
class EpisodeCostTask:
    """One EcoDrive-v0 route (road seed): the episode's cost E + lambda T (lambda = the reward's time weight, the
    MPC's time weight) of the RL policies, of the MPC (its default and with the route end in its horizon) and of
    the full-route optimum of that cost (kinetic energy at the end worth nothing, as in the episode), all on the
    same plant."""

    seed: int
    time_weight: float = 3000.0
    policies: str | None = None
    algos: tuple[str, ...] = ("ppo",)


def run_episode_cost_task(task: EpisodeCostTask) -> dict[str, Any]:
    road = paired_road("route", task.seed)
    lam = task.time_weight
    energy = energy_model_from_spec("bmw_i3")
    rows: list[dict[str, Any]] = []

    def add(name: str, m: dict[str, Any]) -> None:
        rows.append({"controller": name, "seed": task.seed, "energy_J": m["arrival_energy_J"],
                     "time_s": m["arrival_time"], "arrival_speed": m["arrival_speed"],
                     "cost_J": m["arrival_energy_J"] + lam * m["arrival_time"],
                     "speed_violations": m.get("speed_violations")})

    base = DriveSettings(controller="mpc", force_model="oracle", time_weight=lam, dt=0.1)
    ot = OptimumTask("car", "route", task.seed, controllers=tuple(task.algos), policies=task.policies)
    for algo in task.algos:
        m = _policy_run(ot, algo, road)
        add(algo, {"arrival_energy_J": m["segment_energy_J"], "arrival_time": m["segment_time"],
                   "arrival_speed": m["arrival_speed"], "speed_violations": m["speed_violations"]})
    for name, changes in EPISODE_MPC_VARIANTS.items():
        res, _ = drive("bmw_i3", road, seed=task.seed, settings=replace(base, mpc=replace(base.mpc, **changes)))
        add(name, res.metrics)
    plant = SimulatorPlant("bmw_i3", road, seed=task.seed)
    opt = FullRouteOptimum(road, energy, plant.true_parameters())
    for terminal in ("none", "source"):
        sol = opt.solve_weighted(lam, 0.0, terminal)
        target = OptimumTarget(trip_time=sol.trip_time, arrival_speed=None, terminal=terminal)
        res, _ = drive("bmw_i3", road, seed=task.seed, settings=replace(base, controller="optimum",
                                                                         optimum_target=target))
        add(f"optimum (KE at the end {'worth nothing' if terminal == 'none' else 'at source value'})",
            res.metrics)
        rows[-1].update(model_cost_J=sol.energy_J + lam * sol.trip_time, model_time_s=sol.trip_time)
    return {"task": task.__dict__, "rows": rows}


def episode_cost_summary(rows: pd.DataFrame, reference: str) -> pd.DataFrame:
    """Per controller: mean cost [kJ], energy, time, arrival speed, and its cost against ``reference``'s as a fleet
    total with 1-sigma and 95 % CI (paired per seed)."""
    out = []
    ref = rows[rows.controller == reference].set_index("seed")["cost_J"]
    for name, g in rows.groupby("controller", sort=False):
        g = g.set_index("seed")
        common = g.index.intersection(ref.index)
        mean, se, lo, hi = ratio_of_means_ci(g.loc[common, "cost_J"].to_numpy(float),
                                             ref.loc[common].to_numpy(float))
        out.append({"controller": name, "seeds": len(g), "cost_kJ": g["cost_J"].mean() / 1e3,
                    "energy_kWh": g["energy_J"].mean() / 3.6e6, "time_s": g["time_s"].mean(),
                    "arrival_speed": g["arrival_speed"].mean(), f"vs {reference}": format_difference(mean, se, lo, hi),
                    "vs_pct": mean, "vs_1sigma": se, "vs_ci95_lo": lo, "vs_ci95_hi": hi})
    return pd.DataFrame(out)


def run_episode_cost(tasks: list[EpisodeCostTask], out: Path, scheduler: str | None = None,
                     workers: int | None = None) -> tuple[pd.DataFrame, str, list[str]]:
    """The episode-cost study on the sweep runner: episode_cost.csv (one row per run) and episode_cost.md."""
    out.mkdir(parents=True, exist_ok=True)
    outcomes = run_sweep(run_episode_cost_task, tasks, scheduler=scheduler, workers=workers,
                         description="episode cost")
    rows = pd.DataFrame([r for o in outcomes if o.ok for r in o.value["rows"]])
    failures = [f"seed {o.task.seed}: {o.error}" for o in outcomes if not o.ok]
    write_text(out / "episode_cost.csv", rows.to_csv(index=False))
    md = ["# The RL episode's cost E + lambda T on EcoDrive-v0 routes", ""]
    if len(rows):
        optimum = next(c for c in rows.controller.unique() if c.startswith("optimum (KE at the end worth nothing"))
        cols = ["controller", "seeds", "cost_kJ", "energy_kWh", "time_s", "arrival_speed"]
        for ref in [optimum] + [a for a in ("ppo", "sac") if a in set(rows.controller)]:
            table = episode_cost_summary(rows, ref)
            md += [f"Cost against `{ref}` (fleet total over seeds, 95 % CI):", "",
                   markdown_table(table[cols + [f"vs {ref}"]].round(3)), ""]
    md += [f"- failed: {f}" for f in failures]
    text = "\n".join(md) + "\n"
    write_text(out / "episode_cost.md", text)
    return rows, text, failures
