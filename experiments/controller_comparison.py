"""The controller comparison: eco-driving MPC (oracle / abc / online force model) against cruise control, the
human-like driver and the full-route optimum, closed loop on the simulator, paired per seed and at equal trip time.

Per (vehicle case, road, condition, seed) one task (:class:`PairedTask`, :func:`run_paired_task`) drives every
force model on the same road, seed and plant at several time weights around cruise control's trip time; a joint
local fit of energy over trip time (:func:`roadload.experiments.time_matching.fit_energy_at_time`) gives each
model's energy at exactly that time; optionally the full-route optimum at the same time (:func:`optimum_at_tref`)
and FASTSim's energy of every run (:mod:`roadload.experiments.fastsim_check`). :func:`paired_summary` reports
every difference as a fleet total over seeds with its 1-sigma and 95 % CI (:func:`ratio_of_means_ci`). Both
``roadload benchmark controllers`` (roads x conditions, car) and ``roadload benchmark headline`` (car and trucks,
warm-ups, time knobs) run this one path.

Roads (:func:`paired_road`): generated hilly country roads, city routes with stops, motorway, EcoDrive-v0's route,
long grades for the trucks, windows of the real long-haul cycle, and a real grade profile from a BMW i3 log of the
shared data (``i3_munich``, :func:`road_by_name`; the log has no speed limits, so the limit is the running maximum
of the logged speed over +-500 m rounded up to 10 km/h -- the same convention as the GradeIT routes). Conditions:
``CONDITIONS`` (effects of :mod:`roadload.envs.effects`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
import pandas as pd

from roadload.road_profiles import RoadProfile

from roadload.controllers.cruise import CruiseSettings
from roadload.controllers.drive import DriveSettings, drive
from roadload.experiments.time_matching import MatchedRun, fit_energy_at_time, match_trip_time
from roadload.data import require_shared_data
from roadload.io.importer import import_log
from roadload.io.profiles import profile_from_trip
from roadload.io.derived import distance_from_speed
from roadload.controllers.mpc import MpcSettings
from roadload.controllers.dynamic_programming import cached_plant_fuel_map, dp_optimum
from roadload.controllers.optimum import OptimumSettings, OptimumTarget, route_nodes, route_preview
from roadload.controllers.sim_plant import SimulatorPlant
from roadload.controllers.vehicle_models import energy_model_from_spec, rotational_mass
from roadload.estimators import chapter5_settings
from roadload.estimators.change import GUST_ROBUST
from roadload.experiments.fastsim_check import fastsim_energy, roadload_trace_fastsim_efficiency
from roadload.presets import TRUCK_NOMINAL_MASS, truck_spec
from roadload.road_profiles import (city, cycle_to_profile, hilly, load_profile_start, long_haul_truck, long_grades,
                                    motorway)
from roadload.gym.ecodrive import cut_profile
from roadload.controllers.drive import resolve_road

KMH = 1 / 3.6

CONDITIONS: dict[str, list[str] | None] = {
    "nominal": None,
    "payload_300kg": ["payload:initial_payload=300,min_payload=300,max_payload=300,change_std=0"],
    "winter_tires": ["winter_tires"],
    "headwind_6ms": ["wind:mean_speed=6,direction=3.141592653589793,gust_std=0.5,direction_std=0.05"],
    "crosswind_6ms": ["wind:mean_speed=6,direction=1.5707963267948966,gust_std=0.5,direction_std=0.05"],
    "roof_box": ["drag_area:roof_box=0.25,windows=0,sunroof=0,toggle_rate=0"],
    "drift": ["tire_warmup:cold_factor=1.3,distance_constant=3000",
              "oil_temperature:start_temperature=278.15",
              "drag_area:roof_box=0,windows=0.08,sunroof=0.03,toggle_rate=8",
              "payload:change_std=150,max_payload=400",
              "wind:mean_speed=3,gust_std=1.5"],
}


def _i3_munich(length: float = 6000.0) -> RoadProfile:
    from scipy.ndimage import maximum_filter1d

    path = require_shared_data("bmw_i3_tum/data") / "TripB11.csv"
    trip = import_log(path, "bmw-i3")
    prof = profile_from_trip(trip, name="i3_munich", source="bmw_i3_tum TripB11 (Munich South)",
                             licence="CC BY 4.0", grade_source="elevation", curvature_source=None)
    # speed limit: running max of the logged speed over +-500 m, rounded up to 10 km/h, at least 30 km/h

    v = np.nan_to_num(trip.channel("vehicle_speed"))
    s_log = distance_from_speed(trip.t, v)
    v_s = np.interp(prof.distance, s_log, v)
    width = max(1, int(round(1000.0 / (prof.distance[1] - prof.distance[0]))))
    limit = np.maximum(np.ceil(maximum_filter1d(v_s, width) / (10 * KMH) - 1e-9) * 10 * KMH, 30 * KMH)
    keep = prof.distance <= length
    meta = {**prof.meta, "speed_limit_meaning": "running max of the logged speed over +-500 m, rounded up to "
                                                "10 km/h (the log has no posted limits)", "truncated_to_m": length}
    return RoadProfile("i3_munich", prof.distance[keep], prof.grade[keep], prof.curvature[keep], prof.bank[keep],
                       limit[keep], stops=prof.stops[prof.stops <= length], meta=meta)


def road_by_name(name: str) -> RoadProfile:
    """The comparison's roads (module docstring); other names go to ``roadload.road_profiles.load_profile``."""

    if name == "hilly":
        return hilly(seed=1, length=6000.0)
    if name == "motorway":
        return motorway(seed=1, length=10000.0)
    if name == "city":
        return city(seed=1, length=3000.0)
    if name == "i3_munich":
        return _i3_munich()

    return resolve_road(name)


ROADS = ("hilly", "motorway", "city", "i3_munich")


# ================================================================================ paired comparison
# Per (vehicle case, road, condition, seed) every force model drives the SAME road (generated from the seed, or
# the seed-th window of a real grade profile), seed and plant, at several time weights around the cruise-control
# trip time; a joint local fit of energy over trip time (time_matching.fit_energy_at_time) gives each model's
# energy at exactly the cruise time. Differences are paired per seed; mean, 1-sigma standard error and 95 % CI
# over seeds are reported, and a difference whose CI contains 0 is "not resolved".

TRUCK_MPC = MpcSettings(n_nodes=40, ds=50.0)  # 2 km horizon on a 50 m grid: long grades, < 10 ms per step
TRUCK_CRUISE = CruiseSettings(fraction=0.95, overspeed=0.8)  # 85.5 km/h set on a 90 km/h limit, +2.9 km/h band


@dataclass(frozen=True)
class VehicleCase:
    """A vehicle for the paired comparison: the driven vehicle (preset name or truck gross mass [kg]), the
    fleet's nominal vehicle for abc / the online prior (None: the driven one), MPC and cruise settings and a
    start value of the time weight lambda [J/s] for the search."""

    name: str
    preset: str = "bmw_i3"
    gross_mass: float | None = None
    nominal_mass: float | None = None
    lam0: float = 8000.0
    truck: bool = False

    def vehicle(self):
        return truck_spec(self.gross_mass) if self.gross_mass is not None else self.preset

    def settings(self) -> DriveSettings:
        nominal = truck_spec(self.nominal_mass) if self.nominal_mass is not None else None
        if self.truck:  # a truck's slow dynamics: every controller acts every 0.2 s
            return DriveSettings(controller="cruise", force_model="abc", mpc=TRUCK_MPC, cruise=TRUCK_CRUISE,
                                 nominal_vehicle=nominal, dt=0.2)
        return DriveSettings(controller="cruise", force_model="abc", nominal_vehicle=nominal)


VEHICLE_CASES = {
    "car": VehicleCase("car", "bmw_i3", lam0=8000.0),
    **{f"truck_{m}t": VehicleCase(f"truck_{m}t", "truck_40t", gross_mass=1000.0 * m, nominal_mass=TRUCK_NOMINAL_MASS,
                                  lam0=4.0e3 * m, truck=True) for m in (15, 25, 40)},
}


LONGHAUL_MIN_GRADE_RANGE = 0.015  # [-] a window qualifies when its grades span more than 1.5 %


def longhaul_windows(length: float = 10_000.0) -> list[float]:
    """Start positions [m] of the non-overlapping windows of the real long-haul cycle whose grade range exceeds
    LONGHAUL_MIN_GRADE_RANGE (candidates every 1 km, first fit): the cycle is mostly flat, 805 km hold 7 such
    10 km windows."""
    prof = _longhaul_profile()
    s, g = prof.distance, prof.grade
    picks: list[float] = []
    for a in np.arange(0.0, s[-1] - length, 1000.0):
        if picks and a < picks[-1] + length:
            continue
        if np.ptp(np.tan(g[(s >= a) & (s <= a + length)])) > LONGHAUL_MIN_GRADE_RANGE:
            picks.append(float(a))
    return picks


def _longhaul_window(seed: int, length: float = 10_000.0) -> RoadProfile:
    """The seed-th 10 km window with real grades of the 805 km long-haul truck cycle (drive_cycles/, FASTSim;
    :func:`longhaul_windows`: non-overlapping, grade range > 1.5 %; its grades span -2.3..+2.9 %); speed limit
    90 km/h (a truck's limiter), no stops. Seeds beyond the number of windows are an error (no silent repeats)."""
    prof = _longhaul_profile()
    s, g = prof.distance, prof.grade
    starts = longhaul_windows(length)
    if not 0 <= seed < len(starts):
        raise ValueError(f"longhaul_real: seed {seed} out of range; the long-haul cycle has {len(starts)} "
                         f"non-overlapping {length / 1000:g} km windows with a grade range above "
                         f"{100 * LONGHAUL_MIN_GRADE_RANGE:g} % (seeds 0..{len(starts) - 1})")
    a = starts[seed]
    keep = (s >= a) & (s <= a + length)
    d = s[keep] - s[keep][0]
    return RoadProfile("longhaul_real", d, g[keep], np.zeros(d.size), np.zeros(d.size), np.full(d.size, 25.0),
                       stops=np.zeros(0), meta={"source": "FASTSim longHaulDriveCycle.csv (grade over distance)",
                                                "window_start_m": float(a), "seed": int(seed)})


_LONGHAUL: list[RoadProfile] = []


def _longhaul_profile() -> RoadProfile:
    if not _LONGHAUL:
        _LONGHAUL.append(cycle_to_profile(long_haul_truck(), step=10.0))
    return _LONGHAUL[0]


def paired_road(name: str, seed: int, warmup: float = 0.0) -> RoadProfile:
    """Roads of the paired comparison, one per seed: 'hilly' (2.5 km generated country road), 'long_grades'
    (4 km, 3-6 % grades of 2-4 km), 'longhaul_real' (10 km windows of the real long-haul truck cycle), 'city'
    (3 km with stops), 'motorway' (6 km; 'motorway_short': 3 km), 'route' (EcoDrive-v0's 2 km route of the
    seed, where the RL policies learnt). Short, because the shared machine gives each run a fraction of a core.
    ``warmup`` [m]: the generated road is that much longer; the measured segment is its last 2.5 / 4 km (see
    PairedTask.warmup)."""
    if name == "hilly":
        return hilly(seed=seed, length=2500.0 + warmup)
    if name == "hilly_short":  # smoke runs (--quick)
        return hilly(seed=seed, length=1200.0 + warmup)
    if name == "long_grades":
        return long_grades(seed=seed, length=4000.0 + warmup)
    if name == "longhaul_real":
        return _longhaul_window(seed)
    if name == "city":
        return city(seed=seed, length=3000.0 + warmup)
    if name == "motorway":
        return motorway(seed=seed, length=6000.0 + warmup)
    if name == "motorway_short":  # the optimum benchmark's many-seed tables (each run drives the road twice)
        return motorway(seed=seed, length=3000.0 + warmup)
    if name == "route":  # the EcoDrive-v0 route of this road seed (2 km of the generated hilly road), no warm-up
        route = load_profile_start("hilly", ROUTE_LENGTH, seed=seed)
        assert isinstance(route, RoadProfile)  # the registered 'hilly' is a generated road, never a drive cycle
        return cut_profile(route, ROUTE_LENGTH)
    raise ValueError(f"unknown paired road {name!r}; known: {', '.join(PAIRED_ROADS)}")


PAIRED_ROADS = ("hilly", "hilly_short", "long_grades", "longhaul_real", "city", "motorway", "motorway_short", "route")
ROUTE_LENGTH = 2000.0  # [m] EcoDrive-v0's default route_length


def parse_force_model(spec: str) -> tuple[str, dict[str, float] | None]:
    """'oracle' | 'abc' | 'online' | 'online_wind' | 'wrong:mass=0.2,rolling=-0.5' -> (force model, errors); an
    online model's estimator options after '@' (:func:`force_model_settings`) are not part of the name."""
    name, _, rest = spec.partition(":")
    name = name.partition("@")[0]
    if name not in ("oracle", "abc", "online", "online_wind", "wrong"):
        raise ValueError(f"force model {spec!r}: choose oracle, abc, online, online_wind or wrong:<error>=<value>,...")
    if name != "wrong":
        return name, None
    errors = {}
    for item in filter(None, rest.split(",")):
        k, _, v = item.partition("=")
        errors[k.strip()] = float(v)
    return name, errors


def force_model_settings(spec: str) -> dict[str, Any]:
    """DriveSettings fields of a force-model spec: 'online@SGMKF' (another catalogue estimator with chapter 5's
    settings), 'online@RRLM+forgetting=0.995' (a setting changed), 'online@RRLM+cusum' (with the CUSUM change
    detector on block means, roadload.estimators.change.GUST_ROBUST), the same after 'online_wind'; 'wrong:...' as
    parse_force_model."""
    fm, errors = parse_force_model(spec)
    out: dict[str, Any] = {"force_model": fm, "wrong_model": errors}
    head, _, options = spec.partition("@")
    if not options:
        return out
    if fm not in ("online", "online_wind"):
        raise ValueError(f"force model {spec!r}: estimator options after '@' are for online models only")
    estimator, *items = [x.strip() for x in options.split("+") if x.strip()]
    settings = dict(chapter5_settings("M4").get(estimator.upper(), {}))
    for item in items:
        if item == "cusum":
            out["change_detection"] = GUST_ROBUST
            continue
        key, _, value = item.partition("=")
        if not value:
            raise ValueError(f"force model {spec!r}: option {item!r} is not key=value or 'cusum'")
        settings[key] = float(value)
    out.update(estimator=estimator.upper(), estimator_settings=settings)
    return out


@dataclass(frozen=True)
class PairedTask:
    case: str
    road: str
    seed: int
    condition: str = "nominal"
    force_models: tuple[str, ...] = ("oracle", "abc", "online")
    weight_factors: tuple[float, ...] = (0.8, 1.25)
    tol: float = 0.002
    human: bool = False
    max_search_runs: int = 4  # oracle runs spent on the lambda search; the local fit handles the rest
    # [m] warm-up driven before the measured segment (every controller drives it; the online estimator learns
    # there, fleet practice: the estimate carries over from the trip's start); metrics cover the segment only
    warmup: float = 0.0
    # "net": segment time and source energy net of the kinetic energy left at arrival, crossings interpolated
    # (drive.net_energy_metrics); "raw": the first control step past the road end and its source energy
    metric: str = "net"
    # the time knob: "lambda" = fixed time weight per run, matched by a search over lambda (the
    # truck's trip time jumps between two gear branches); "schedule" = every model targets the segment time
    # T_cruise x (1, *time_factors) by lambda feedback with multi-start solves (DriveSettings.target_time), so
    # the segment time is continuous in the knob
    knob: str = "lambda"
    time_factors: tuple[float, ...] = (0.99, 1.01)
    terminal_value: str = "source"  # MpcSettings.terminal_value: "source" (m E_N / eta_i) or "wheel" (m E_N)
    # [s] cold multi-start solves of every MPC run (MpcControllerSettings.multistart_period); None: 5 s with the
    # schedule knob (needed to leave a gear branch), off with the lambda knob
    multistart_period: float | None = None
    # every MPC run requests the gear of its own shift rule (MpcControllerSettings.gear_command, ICE only; the
    # cruise control and human baselines keep the transmission's strategy)
    gear_command: bool = False
    # extra runs of a force model whose runs at lambda* x factors all miss T_ref by more than ``model_reach``
    # (e.g. the online MPC on the other cruise branch of a truck at every lambda): a lambda search for that model
    # alone, so its energy at T_ref comes from a local fit rather than the seed being dropped; 0 = off
    model_search_runs: int = 0
    model_reach: float = 0.01
    # who drives the warm-up of the MPC runs: "mpc" (each MPC itself) or "cruise" (cruise control for every run: the
    # measured segment then starts in the same state for every force model, and the online estimator has learnt
    # from the same samples; DriveSettings.warmup_driver)
    warmup_driver: str = "mpc"
    schedule_gain: float = 20.0  # schedule knob: P gain of the lambda feedback (TripSchedule.gain)
    schedule_pilot: bool = False  # schedule knob: lambda_0 from one oracle pilot run (see run_paired_task)
    schedule_shape: str = "linear"  # schedule knob: "linear" in distance or "cruise" (cruise control's time profile)
    # the full-route optimum at T_ref on the same plant (controllers.optimum; net metric: the kinetic energy left
    # is valued at 1/eta_i), so every model and cruise control is also compared with the best drive
    optimum: bool = False
    # every run's speed trace (with its grade) also through FASTSim 3 (experiments.fastsim_check; car only)
    fastsim: bool = False

    def __post_init__(self) -> None:
        if self.metric not in METRICS:
            raise ValueError(f"PairedTask.metric: choose one of {sorted(METRICS)}, got {self.metric!r}")
        if self.knob not in KNOBS:
            raise ValueError(f"PairedTask.knob: choose one of {KNOBS}, got {self.knob!r}")
        if self.knob == "schedule" and self.metric != "net":
            raise ValueError("PairedTask: knob 'schedule' targets the measured segment's time; use metric 'net'")
        if not all(math.isfinite(f) and 0.5 < f < 2.0 for f in self.time_factors):
            raise ValueError(f"PairedTask.time_factors: factors of the cruise time in (0.5, 2), got "
                             f"{self.time_factors}")
        if self.warmup_driver not in ("mpc", "cruise"):
            raise ValueError(f"PairedTask.warmup_driver: 'mpc' or 'cruise', got {self.warmup_driver!r}")
        if not (isinstance(self.model_search_runs, int) and self.model_search_runs >= 0):
            raise ValueError(f"PairedTask.model_search_runs: an integer >= 0, got {self.model_search_runs!r}")
        if not (math.isfinite(self.model_reach) and 0 < self.model_reach < 0.5):
            raise ValueError(f"PairedTask.model_reach: a relative time in (0, 0.5), got {self.model_reach}")
        if not (math.isfinite(self.warmup) and self.warmup >= 0):
            raise ValueError(f"PairedTask.warmup must be a finite distance >= 0 m, got {self.warmup}")


METRICS = {"net": ("segment_time", "energy_net_J"), "raw": ("trip_time", "energy_J")}
KNOBS = ("lambda", "schedule")


class _PairedRuns:
    """The runs of one paired-comparison seed (one road, seed and plant) and their (trip time, energy) points in
    the task's metric and in the other one; net energies get cruise control's kinetic-energy change back."""

    def __init__(self, task: PairedTask) -> None:
        self.task = task
        self.case = VEHICLE_CASES[task.case]
        self.road = paired_road(task.road, task.seed, task.warmup)
        self.effects = CONDITIONS[task.condition] if not self.case.truck else None
        base = replace(self.case.settings(), measure_from=task.warmup)
        self.base = replace(base, mpc=replace(base.mpc, terminal_value=task.terminal_value))
        self.vehicle = self.case.vehicle()
        self.time_key, self.energy_key = METRICS[task.metric]
        self.other = METRICS["raw" if task.metric == "net" else "net"]
        self.offset = 0.0  # [J] cruise control's segment energy minus its net energy
        self.shape: tuple[tuple[float, ...], tuple[float, ...]] | None = None
        self.runs_out: list[dict[str, Any]] = []
        self.cruise_pts: list[tuple[float, float]] = []
        self.cruise_other: list[tuple[float, float]] = []
        self.points: dict[str, list[tuple[float, float]]] = {}
        self.points_other: dict[str, list[tuple[float, float]]] = {}
        self.fastsim_pts: dict[str, list[tuple[float, float]]] = {}
        # roadload's wheel power through FASTSim's efficiency chain: everywhere ('fastsim_efficiency'), and only
        # where the drive-train drives, roadload's own battery energy where it regenerates or coasts
        self.efficiency_pts: dict[str, dict[str, list[tuple[float, float]]]] = {
            "fastsim_efficiency": {}, "fastsim_efficiency_driving": {}}

    def run(self, settings: DriveSettings, label: str | None = None):
        """One closed-loop run; with ``task.fastsim`` its speed trace also through FASTSim 3 (labelled runs)."""
        res, plant = drive(self.vehicle, self.road, effects=self.effects, seed=self.task.seed, settings=settings)
        if self.task.fastsim and label is not None and res.metrics.get("arrived"):
            self._fastsim(res, plant, label)
        return res

    def _fastsim(self, res, plant, label: str) -> None:
        m, road = res.metrics, self.road
        fs = fastsim_energy(np.append(res.log["t"].to_numpy(float), m["arrival_time"]),
                            np.append(res.log["s"].to_numpy(float), road.length),
                            np.append(res.log["v"].to_numpy(float), m["arrival_speed"]), road, start=self.task.warmup)
        mass = plant.true_parameters().inertial_mass  # the kinetic energy left, booked as the net metric does
        ke = 0.5 * mass * (m["segment_start_speed"] ** 2 - m["arrival_speed"] ** 2)
        m["fastsim_energy_J"] = fs["energy_J"]
        m["fastsim_energy_net_J"] = fs["energy_J"] + ke
        self.fastsim_pts.setdefault(label, []).append((m["segment_time"], m["fastsim_energy_net_J"]))
        # the same trace with roadload's own wheel power through FASTSim's efficiency chain: what separates the two
        # models' savings that is efficiency alone
        eff = roadload_trace_fastsim_efficiency(plant.sim.truth_log(), self.task.warmup, road.length)
        m["fastsim_efficiency_energy_net_J"] = eff["fastsim_efficiency_J"] + ke
        m["fastsim_efficiency_driving_energy_net_J"] = (eff["fastsim_efficiency_driving_J"]
                                                        + eff["roadload_not_driving_J"] + ke)
        for prefix, points in self.efficiency_pts.items():
            points.setdefault(label, []).append((m["segment_time"], m[f"{prefix}_energy_net_J"]))

    def _point(self, m: dict[str, Any]) -> tuple[tuple[float, float], tuple[float, float]]:
        """(time [s], energy [J]) of a run in the task's metric and in the other one."""
        net = self.task.metric == "net"
        return ((m[self.time_key], m[self.energy_key] + (self.offset if net else 0.0)),
                (m[self.other[0]], m[self.other[1]] + (0.0 if net else self.offset)))

    def cruise_sweep(self) -> float:
        """Cruise control at its set-speed fraction f0 and f0 +- 0.03, +- 0.06: its trip time at f0 [s]."""
        f0 = self.base.cruise.fraction
        t_cruise = float("nan")
        for df in (0.0, -0.03, 0.03, -0.06, 0.06):
            f = f0 + df
            if not 0.5 < f <= 1.0:
                continue
            res = self.run(replace(self.base, cruise=replace(self.base.cruise, fraction=f)), "cruise")
            m = res.metrics
            if df == 0.0:  # net energies get cruise control's kinetic-energy change back (see _NET_OFFSET_DOC)
                self.shape = schedule_shape(res.log, self.task.warmup, self.road.length)
                self.offset = m["segment_energy_J"] - m["energy_net_J"]
                t_cruise = m[self.time_key]
            point, point_other = self._point(m)
            self.cruise_pts.append(point)
            self.cruise_other.append(point_other)
            self.runs_out.append({"force_model": "cruise", "cruise_fraction": f, **_run_metrics(m),
                                  "fastsim_energy_net_J": m.get("fastsim_energy_net_J")})
        if not math.isfinite(t_cruise):
            raise RuntimeError(f"cruise control did not arrive on {self.task.road} seed {self.task.seed}")
        return t_cruise

    def human(self) -> dict[str, Any]:
        """The human-like driver at its own pace, in the same metric as cruise control's."""
        if not self.task.human:
            return {}
        m = self.run(replace(self.base, controller="human"), "human").metrics
        (t, e), _ = self._point(m)
        extra = {"human_energy_J": e, "human_time": t}
        if self.task.fastsim and "fastsim_energy_net_J" in m:
            extra["human_fastsim_energy_J"] = m["fastsim_energy_net_J"] + self.offset
            extra["human_fastsim_time"] = m["segment_time"]
        return extra

    def mpc(self, spec: str, lam: float, target: float | None = None):
        """One MPC run with force model ``spec`` at time weight ``lam`` [J/s] (or the schedule knob's target)."""
        task = self.task
        multistart = task.multistart_period if task.multistart_period is not None else (
            5.0 if task.knob == "schedule" else 0.0)
        settings = replace(self.base, controller="mpc", time_weight=lam, multistart_period=multistart,
                           gear_command=task.gear_command, warmup_driver=task.warmup_driver,
                           **force_model_settings(spec))
        if target is not None:
            settings = replace(settings, target_time=target, schedule_gain=task.schedule_gain,
                               target_shape=self.shape if task.schedule_shape == "cruise" else None)
        res = self.run(settings, spec)
        m = res.metrics
        point, point_other = self._point(m)
        self.points.setdefault(spec, []).append(point)
        self.points_other.setdefault(spec, []).append(point_other)
        online = m.get("online", {})
        self.runs_out.append({"force_model": spec, "time_weight": lam, "target_time": target,
                              "time_weight_median": m.get("ctl_time_weight_median"),
                              "multistart_switches": m.get("ctl_multistart_switches", 0), **_run_metrics(m),
                              "solve_time_median": m.get("solve_time_median"), "fallbacks": m.get("fallbacks"),
                              "online_estimate": online.get("estimate"), "online_history": online.get("history"),
                              "fastsim_energy_net_J": m.get("fastsim_energy_net_J")})
        return res

    def schedule_knob(self, t_cruise: float) -> tuple[MatchedRun, float, float]:
        """Every model targets T_cruise x (1, *time_factors), no search: (the oracle's run, lambda_0, T_ref)."""
        task = self.task
        # lambda_0 of the feedback: one oracle pilot run from the case's start value, then the median lambda its
        # feedback used over the measured segment (a P law keeps a lateness proportional to the error in lambda_0)
        lam_star = self.case.lam0
        if task.schedule_pilot:
            pilot = self.mpc(task.force_models[0], self.case.lam0, t_cruise)
            lam_pilot = float(pilot.metrics.get("ctl_time_weight_median", float("nan")))
            lam_star = lam_pilot if math.isfinite(lam_pilot) and lam_pilot > 0 else self.case.lam0
        first = None
        for spec in task.force_models:
            for f in (1.0, *task.time_factors):
                res = self.mpc(spec, lam_star, t_cruise * f)
                first = res if first is None else first
        assert first is not None
        err = first.metrics[self.time_key] / t_cruise - 1.0
        return MatchedRun(first, lam_star, t_cruise, abs(err) <= task.tol, 1, [], self.time_key), lam_star, t_cruise

    def lambda_knob(self, t_cruise: float) -> tuple[MatchedRun, float, float]:
        """The oracle matched to T_cruise over lambda, every model at lambda* x factors (and a search where all
        its runs miss): (the oracle's match, lambda*, T_ref)."""
        task = self.task
        matched = match_trip_time(lambda lam: self.mpc("oracle", lam), t_cruise, tol=task.tol, lam0=self.case.lam0,
                                  max_runs=task.max_search_runs, step=2.0, time_key=self.time_key,
                                  energy_key=self.energy_key)
        lam_star = matched.time_weight
        t_ref = t_cruise if matched.matched else float(matched.result.metrics[self.time_key])
        for spec in task.force_models:
            factors = task.weight_factors if spec == "oracle" else (1.0, *task.weight_factors)
            for f in factors:
                self.mpc(spec, lam_star * f)
            if spec != "oracle" and task.model_search_runs > 0:
                tried = [(lam_star * f, t) for f, (t, _) in zip(factors, self.points[spec][-len(factors):])]
                _search_model_lambda(lambda lam, spec=spec: self.mpc(spec, lam).metrics[self.time_key], tried,
                                     t_ref, task.model_search_runs, task.model_reach, task.tol)
        return matched, lam_star, t_ref

    def fastsim_at(self, t_ref: float) -> dict[str, Any]:
        """The same joint local fit on FASTSim's energies of the same runs, and on roadload's wheel power through
        FASTSim's efficiency chain (prefix ``fastsim_efficiency_``; ``fastsim_efficiency_driving_``: only where the
        drive-train drives)."""
        out: dict[str, Any] = {}
        for prefix, points in (("fastsim", self.fastsim_pts), *self.efficiency_pts.items()):
            shifted = {k: [(t, e + self.offset) for t, e in v] for k, v in points.items()}
            fs_fit = fit_energy_at_time({k: v for k, v in shifted.items() if k not in ("cruise", "human")}, t_ref)
            fs_cruise = fit_energy_at_time({"cruise": shifted.get("cruise", [])}, t_ref, window=0.08)
            out.update({f"{prefix}_energy_at_tref_J": fs_fit.energy, f"{prefix}_cruise_energy_J":
                        fs_cruise.energy["cruise"]})
        return out


def run_paired_task(task: PairedTask) -> dict[str, Any]:
    """One seed of the paired comparison.

    1. cruise control at its set-speed fraction f0 and at f0 +- 0.03, +- 0.06 (cheap runs) -> T_ref = the trip
       time at f0, and E_cruise(T) by a local fit;
    2. the oracle MPC matched to T_ref within ``tol`` (search over lambda). Where the closed-loop trip time
       jumps over T_ref (a truck's time saturates at its power limit and can jump between local optima), T_ref
       moves to the oracle run closest to it, and cruise control's energy comes from its local fit there;
    3. every force model at lambda* x (1, weight_factors) on the same road, seed and plant;
    4. the joint local fit of energy over trip time of the MPC runs (common slope/curvature) -> E_m(T_ref).

    Metric "net" (default): every run's segment energy is corrected to cruise control's arrival speed,
    E = E_net + (E_seg - E_net)_cruise, i.e. the kinetic energy it leaves at the road end is booked at its
    marginal source cost (drive.net_energy_metrics) relative to cruise control's. Differences between runs are
    those of E_net; percentages are relative to an energy of the size of a real trip's (a net energy alone can be
    ~0 or negative on a downhill road)."""
    runs = _PairedRuns(task)
    t_cruise = runs.cruise_sweep()
    extra = runs.human()
    knob = runs.schedule_knob if task.knob == "schedule" else runs.lambda_knob
    matched, lam_star, t_ref = knob(t_cruise)
    fit = fit_energy_at_time(runs.points, t_ref)
    cruise_fit = fit_energy_at_time({"cruise": runs.cruise_pts}, t_ref, window=0.08)
    # the other metric on the same runs (before/after comparison of the resolution): its own reference time
    t_ref_other = (float(runs.cruise_other[0][0]) if matched.matched or task.knob == "schedule"
                   else float(matched.result.metrics[runs.other[0]]))
    fit_other = fit_energy_at_time(runs.points_other, t_ref_other)
    cruise_fit_other = fit_energy_at_time({"cruise": runs.cruise_other}, t_ref_other, window=0.08)
    if task.optimum:
        extra.update(optimum_at_tref(task, runs.road, runs.effects, runs.base, t_ref, runs.offset))
    if task.fastsim:
        extra.update(runs.fastsim_at(t_ref))
    return {"task": task.__dict__, "t_ref": t_ref, "t_cruise": t_cruise, "t_ref_moved": t_ref != t_cruise,
            "kinetic_energy_offset_J": runs.offset,
            "other_metric": {"metric": "raw" if task.metric == "net" else "net", "t_ref": t_ref_other,
                             "energy_at_tref_J": fit_other.energy, "cruise_energy_J": cruise_fit_other.energy[
                                 "cruise"], "fit_residual_std": fit_other.residual_std,
                             "nearest_time_error": fit_other.nearest},
            "cruise_energy_J": cruise_fit.energy["cruise"], "cruise_nominal_energy_J": runs.cruise_pts[0][1],
            "cruise_spanned": cruise_fit.spanned["cruise"],
            "lambda_star": lam_star, "oracle_time_error": matched.time_error, "oracle_matched": matched.matched,
            "energy_at_tref_J": fit.energy, "nearest_time_error": fit.nearest, "spanned": fit.spanned,
            "fit_residual_std": fit.residual_std, "fit_slope": fit.slope, "fit_curvature": fit.curvature,
            "runs": runs.runs_out, **extra}


def optimum_at_tref(task: PairedTask, road: RoadProfile, effects, base: DriveSettings, t_ref: float,
                    offset: float) -> dict[str, Any]:
    """The full-route optimum of the measured segment at T_ref, driven on the same plant (cruise control drives a
    warm-up): its net energy (the kinetic energy left at 1/eta_i, the paired comparison's metric; the MPC's
    terminal value 'source'), corrected to exactly T_ref with the optimum's own slope dE*/dT."""
    target = OptimumTarget(trip_time=t_ref, arrival_speed=None, terminal="source")
    settings = replace(base, controller="optimum", force_model="oracle", optimum_target=target)
    res, _ = drive(VEHICLE_CASES[task.case].vehicle(), road, effects=effects, seed=task.seed, settings=settings)
    m = res.metrics
    slope = float(m.get("ctl_optimum_time_slope", float("nan")))
    energy = m["energy_net_J"] + offset + slope * (t_ref - m["segment_time"])
    return {"optimum_energy_J": energy, "optimum_time": m["segment_time"], "optimum_time_slope": slope,
            "optimum_model_energy_J": m.get("ctl_optimum_model_energy_J"), "optimum_arrival_speed": m["arrival_speed"]}


# the gear-aware bound of a truck segment (gear_choice_bound): 20 m nodes, a grid uniform in v^2/2 with 0.5 m^2/s^2
# steps (0.25 m^2/s^2 on 10 m nodes gives the same energy within 0.02 % on 40 t seed 0), accelerations within
# +-1 m/s^2 and speeds >= 10 m/s (the controllers' range on the long grades: -0.36 ... +0.24 m/s^2, >= 19 m/s at 40 t)
TRUCK_BOUND = OptimumSettings(ds=20.0, accel_max=1.0, decel_max=1.0, speed_floor=10.0, jerk=False)
TRUCK_BOUND_ENERGY_STEP = 0.5  # [m^2/s^2]


def gear_choice_bound(task: PairedTask, road: RoadProfile, t_ref: float, start_speed: float,
                      offset: float) -> dict[str, Any]:
    """A truck's segment at T_ref by dynamic programming with the gear of least fuel for every segment, priced by
    the plant's own fuel map (fuel cut while braking; :func:`~roadload.controllers.dynamic_programming.dp_optimum`
    with ``fuel_table``, :func:`~roadload.controllers.dynamic_programming.cached_plant_fuel_map`), from the
    segment start speed [m/s], the kinetic energy left valued at 1/eta_i; the true parameters with the top gear's
    rotating mass. Its net energy [J] in the paired comparison's metric (+ ``offset``), not driven on the plant."""
    spec = VEHICLE_CASES[task.case].vehicle()
    energy = energy_model_from_spec(spec)
    params = replace(SimulatorPlant(spec, road, seed=task.seed).true_parameters(),
                     rotational_mass=rotational_mass(spec))
    preview = route_preview(road, route_nodes(task.warmup, road.length, [], TRUCK_BOUND.ds), energy, TRUCK_BOUND)
    sol = dp_optimum(preview, energy, params, t_ref, start_speed, None, TRUCK_BOUND,
                     terminal_value=1.0 / energy.indicated_efficiency, gear_choice=True,
                     energy_step=TRUCK_BOUND_ENERGY_STEP, fuel_table=cached_plant_fuel_map(spec))
    ke = 0.5 * params.inertial_mass * (start_speed ** 2 - float(sol.v[-1]) ** 2) / energy.indicated_efficiency
    return {"bound_energy_J": sol.energy_J + ke + offset, "bound_arrival_speed": float(sol.v[-1])}


def _search_model_lambda(run, tried: list[tuple[float, float]], t_ref: float, max_runs: int, reach: float,
                         tol: float) -> None:
    """Extra runs ``run(lambda) -> T`` of one force model when every run in ``tried`` [(lambda [J/s], T [s])] missed
    T_ref by more than ``reach`` and all lie on one side of it: lambda x 2 (all slower) or / 2 (all faster) until
    a run lands on the other side, then log-lambda interpolation inside the bracket (kept 10 % from its ends;
    a gear branch makes T jump, so it may end in the gap), at most ``max_runs`` runs or until within ``tol``."""
    hist = [(lam, t) for lam, t in tried if math.isfinite(t)]
    if not hist or min(abs(t / t_ref - 1.0) for _, t in hist) <= reach:
        return
    if min(t for _, t in hist) <= t_ref <= max(t for _, t in hist):
        return  # the runs span T_ref: the local fit interpolates
    for _ in range(max_runs):
        slow = [h for h in hist if h[1] > t_ref]  # lambda too small
        fast = [h for h in hist if h[1] <= t_ref]
        if slow and fast:
            (l1, t1), (l2, t2) = max(slow), min(fast)
            x1, x2 = math.log(l1), math.log(l2)
            x = x1 + (t_ref - t1) * (x2 - x1) / (t2 - t1)
            lam = math.exp(min(max(x, x1 + 0.1 * (x2 - x1)), x2 - 0.1 * (x2 - x1)))
        else:
            lam = 2.0 * max(hist)[0] if slow else 0.5 * min(hist)[0]
        t = run(lam)
        hist.append((lam, t if math.isfinite(t) else float("inf")))
        if abs(t / t_ref - 1.0) <= tol:
            return


def schedule_shape(log: pd.DataFrame, start: float, end: float, step: float = 100.0
                   ) -> tuple[tuple[float, ...], tuple[float, ...]]:
    """The time profile of a run over the segment [start, end] [m] as (positions [m], elapsed fraction of its
    segment time [-]) on a ``step`` grid: the shape of the schedule knob's target (cruise control's pace, slow on
    the power-limited climbs)."""
    s, t = log["s"].to_numpy(float), log["t"].to_numpy(float)
    grid = np.append(np.arange(start, end, step), end)
    tg = np.interp(grid, s, t)
    frac = (tg - tg[0]) / max(tg[-1] - tg[0], 1e-9)
    return tuple(float(x) for x in grid), tuple(float(x) for x in np.maximum.accumulate(frac))


def _run_metrics(m: dict[str, Any]) -> dict[str, Any]:
    keys = ("trip_time", "energy_J", "segment_time", "energy_net_J", "arrival_speed", "segment_start_speed",
            "kinetic_energy_change_J", "speed_violations")
    return {k: m.get(k) for k in keys}


def _mean_ci(values: np.ndarray) -> tuple[float, float, float, float]:
    """(mean, 1-sigma standard error, 95 % CI low, high) of per-seed values (Student t)."""
    from scipy.stats import t as student_t

    v = np.asarray(values, float)
    v = v[np.isfinite(v)]
    if v.size == 0:
        return (float("nan"),) * 4
    mean = float(v.mean())
    if v.size < 2:
        return mean, float("nan"), float("nan"), float("nan")
    se = float(v.std(ddof=1) / np.sqrt(v.size))
    h = float(student_t.ppf(0.975, v.size - 1)) * se
    return mean, se, mean - h, mean + h


def other_metric_results(results: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """The same seeds evaluated with the task's other metric (``other_metric`` of run_paired_task: raw vs net),
    for a before/after comparison of the resolution on identical runs."""
    out = []
    for r in results:
        o = r.get("other_metric")
        if o is None:
            continue
        out.append({**r, "t_ref": o["t_ref"], "energy_at_tref_J": o["energy_at_tref_J"],
                    "cruise_energy_J": o["cruise_energy_J"], "fit_residual_std": o["fit_residual_std"],
                    "nearest_time_error": o["nearest_time_error"],
                    "task": {**r["task"], "metric": o["metric"]}})
    return out


def ratio_of_means_ci(energy: np.ndarray, reference: np.ndarray) -> tuple[float, float, float, float]:
    """Paired difference as a fleet total [%]: 100 mean(E - E_ref) / mean(E_ref) over the seeds where both are
    finite, its 1-sigma standard error and Student-t 95 % CI (the spread of the per-seed differences E - E_ref
    over the same mean reference). Unlike the mean of per-seed percentages it stays meaningful when one road is
    net downhill and its energy ~0. Over |mean(E_ref)|: positive when E is the larger energy, also where the
    reference's mean is negative (short downhill roads driven slowly regenerate more than they draw)."""
    ok = np.isfinite(energy) & np.isfinite(reference)
    if not ok.any():
        return (float("nan"),) * 4
    scale = 100.0 / abs(float(np.mean(reference[ok])))
    mean, se, lo, hi = _mean_ci((energy[ok] - reference[ok]) * scale)
    return mean, se, lo, hi


def paired_summary(results: list[dict[str, Any]]) -> pd.DataFrame:
    """Per (case, road, condition, force model): paired energy difference at equal time vs the oracle MPC and vs
    cruise control [%] over seeds (fleet totals, :func:`ratio_of_means_ci`): mean, 1-sigma resolution (standard
    error), 95 % CI, and 'resolved' (CI excludes 0); the median of the per-seed percentages alongside."""
    rows = []
    groups: dict[tuple, list[dict[str, Any]]] = {}
    for r in results:
        t = r["task"]
        groups.setdefault((t["case"], t["road"], t["condition"]), []).append(r)
    for (case, road, cond), rs in groups.items():
        models = list(dict.fromkeys(m for r in rs for m in r["energy_at_tref_J"]))
        for m in models:
            e_m = np.array([r["energy_at_tref_J"].get(m, np.nan) for r in rs], float)
            e_o = np.array([r["energy_at_tref_J"]["oracle"] for r in rs], float)
            e_c = np.array([r["cruise_energy_J"] for r in rs], float)
            vs_oracle = 100 * (e_m / e_o - 1)
            mo, so, lo, hi = ratio_of_means_ci(e_m, e_o)
            mc, sc, lc, hc = ratio_of_means_ci(e_m, e_c)
            near = np.array([r["nearest_time_error"][m] for r in rs], float)
            extra = _optimum_fastsim_columns(rs, e_m, m)
            rows.append({"vehicle": case, "road": road, "condition": cond, "force_model": m,
                         "metric": rs[0]["task"].get("metric", "raw"), "warmup_m": rs[0]["task"].get("warmup", 0.0),
                         "seeds": int(np.isfinite(vs_oracle).sum()),
                         "vs_oracle_pct": mo, "resolution_1sigma_pct": so, "ci95_lo_pct": lo, "ci95_hi_pct": hi,
                         "vs_oracle_per_seed_median_pct": float(np.nanmedian(vs_oracle))
                         if np.isfinite(vs_oracle).any() else float("nan"),
                         "resolved": bool(np.isfinite(lo) and (lo > 0 or hi < 0)) if m != "oracle" else False,
                         "vs_cruise_pct": mc, "vs_cruise_1sigma_pct": sc, "vs_cruise_ci95_lo": lc,
                         "vs_cruise_ci95_hi": hc,
                         "nearest_run_time_error_pct_median": float(100 * np.nanmedian(near)),
                         "fit_residual_std_pct": float(100 * np.nanmedian([r["fit_residual_std"] for r in rs])),
                         **extra})
        if any("optimum_energy_J" in r for r in rs):  # cruise control against the optimum too
            e_c = np.array([r["cruise_energy_J"] for r in rs], float)
            rows.append({"vehicle": case, "road": road, "condition": cond, "force_model": "cruise control",
                         "metric": rs[0]["task"].get("metric", "raw"), "warmup_m": rs[0]["task"].get("warmup", 0.0),
                         "seeds": int(np.isfinite(e_c).sum()), **_optimum_fastsim_columns(rs, e_c, None)})
    return pd.DataFrame(rows)


def _optimum_fastsim_columns(results: list[dict[str, Any]], energy: np.ndarray, model: str | None
                             ) -> dict[str, Any]:
    """vs the optimum at T_ref [%] (fleet total, 1-sigma, CI) where the results have it; FASTSim's energy of the
    same runs vs FASTSim's cruise control [%] where they have it (model None: cruise control itself)."""
    out: dict[str, Any] = {}
    if any("optimum_energy_J" in r for r in results):
        e_opt = np.array([r.get("optimum_energy_J", np.nan) for r in results], float)
        mo, so, lo, hi = ratio_of_means_ci(energy, e_opt)
        out.update(vs_optimum_pct=mo, vs_optimum_1sigma_pct=so, vs_optimum_ci95_lo=lo, vs_optimum_ci95_hi=hi)
    for prefix in ("fastsim", "fastsim_efficiency", "fastsim_efficiency_driving"):
        if model is not None and any(f"{prefix}_energy_at_tref_J" in r for r in results):
            fs_m = np.array([r.get(f"{prefix}_energy_at_tref_J", {}).get(model, np.nan) for r in results], float)
            fs_c = np.array([r.get(f"{prefix}_cruise_energy_J", np.nan) for r in results], float)
            mf, sf, lf, hf = ratio_of_means_ci(fs_m, fs_c)
            out.update({f"{prefix}_vs_cruise_pct": mf, f"{prefix}_vs_cruise_1sigma_pct": sf,
                        f"{prefix}_vs_cruise_ci95_lo": lf, f"{prefix}_vs_cruise_ci95_hi": hf})
    return out


FASTSIM_SCORINGS = {"roadload": ("energy_at_tref_J", "cruise_energy_J"),
                    "fastsim_efficiency_driving": ("fastsim_efficiency_driving_energy_at_tref_J",
                                                   "fastsim_efficiency_driving_cruise_energy_J"),
                    "fastsim_efficiency": ("fastsim_efficiency_energy_at_tref_J", "fastsim_efficiency_cruise_energy_J"),
                    "fastsim": ("fastsim_energy_at_tref_J", "fastsim_cruise_energy_J")}
"""The scorings of the same runs in the FASTSim cross-check: roadload; roadload's wheel power through FASTSim's
efficiency chain (experiments.fastsim_check.fastsim_efficiency_power) only where the drive-train drives (roadload's
own battery energy where it regenerates or coasts), and everywhere; FASTSim: (MPC energy, cruise energy) keys."""


def fastsim_per_seed(results: list[dict[str, Any]], model: str = "oracle") -> tuple[pd.DataFrame, pd.DataFrame]:
    """The MPC's (``model``) saving against cruise control at the cruise time per seed in each scoring of
    FASTSIM_SCORINGS the results carry (runs stored before a scoring existed lack it) [%], and the fleet totals with
    the gaps between them: each saving 100 sum(E_m - E_c) / |sum E_c|, each gap (a - b) the mean of the per-seed
    d_i = 100 (dE_a,i / |mean E_c,a| - dE_b,i / |mean E_c,b|) with its 1-sigma and Student-t 95 % CI (so the gap's
    mean is exactly the difference of the two savings)."""
    rs = [r for r in results if "fastsim_energy_at_tref_J" in r and model in r["energy_at_tref_J"]]
    if not rs:
        return pd.DataFrame(), pd.DataFrame()
    seeds = [r["task"]["seed"] for r in rs]
    diff: dict[str, np.ndarray] = {}
    scale: dict[str, float] = {}
    table: dict[str, Any] = {"seed": seeds}
    for name, (mpc_key, cruise_key) in FASTSIM_SCORINGS.items():
        if not all(mpc_key in r and cruise_key in r for r in rs):
            continue
        e_m = np.array([r[mpc_key].get(model, np.nan) for r in rs], float)
        e_c = np.array([r[cruise_key] for r in rs], float)
        diff[name], scale[name] = e_m - e_c, 100.0 / abs(float(np.mean(e_c)))
        table[f"{name}_saving_pct"] = 100.0 * (e_m / e_c - 1.0)
        table[f"{name}_cruise_kJ"], table[f"{name}_mpc_kJ"] = e_c / 1e3, e_m / 1e3
    totals = [{"what": f"{name} saving", **dict(zip(("pct", "1sigma", "ci95_lo", "ci95_hi"),
                                                       _mean_ci(diff[name] * scale[name])))} for name in diff]
    for a, b in (("fastsim", "roadload"), ("fastsim_efficiency", "roadload"),
                 ("fastsim_efficiency_driving", "roadload"), ("fastsim_efficiency", "fastsim_efficiency_driving"),
                 ("fastsim", "fastsim_efficiency")):
        if a not in diff or b not in diff:
            continue
        totals.append({"what": f"{a} - {b} [pp]", **dict(zip(("pct", "1sigma", "ci95_lo", "ci95_hi"), _mean_ci(
            diff[a] * scale[a] - diff[b] * scale[b])))})
    return pd.DataFrame(table), pd.DataFrame(totals)


def format_difference(mean: float, se: float, lo: float, hi: float) -> str:
    """'+0.42 % [+0.10, +0.74] (1σ 0.15)' or 'not resolved (-0.05 % [-0.30, +0.20], 1σ 0.12)'."""
    if not np.isfinite(mean):
        return "n/a"
    if not np.isfinite(lo):
        return f"{mean:+.2f} % (1 seed, no CI)"
    text = f"{mean:+.2f} % [{lo:+.2f}, {hi:+.2f}] (1σ {se:.2f})"
    return text if (lo > 0 or hi < 0) else f"not resolved ({text})"


def refit_results(results: list[dict[str, Any]], metric: str = "net", window: float = 0.06,
                  quadratic: bool = True) -> list[dict[str, Any]]:
    """The stored runs of run_paired_task refitted with another metric / time window / fit order (the
    resolution study of experiments/headline_resolution.py: same closed-loop runs, different matching). The
    reference time is the cruise-control time of the nominal set speed when the oracle matched it, else the
    oracle's closest run."""
    if metric not in METRICS:
        raise ValueError(f"metric: choose one of {sorted(METRICS)}, got {metric!r}")
    time_key, energy_key = METRICS[metric]
    out = []
    for r in results:
        off = r.get("kinetic_energy_offset_J", 0.0) if metric == "net" else 0.0
        cruise = [x for x in r["runs"] if x["force_model"] == "cruise"]
        mpc_runs = [x for x in r["runs"] if x["force_model"] != "cruise"]
        if not cruise or not mpc_runs or cruise[0].get(time_key) is None:
            continue
        t_cruise = float(cruise[0][time_key])
        oracle = [x for x in mpc_runs if x["force_model"] == "oracle"]
        closest = min(oracle, key=lambda x: abs(x[time_key] / t_cruise - 1.0))
        t_ref = t_cruise if abs(closest[time_key] / t_cruise - 1.0) <= r["task"].get("tol", 0.002) else float(
            closest[time_key])
        if r["task"].get("knob") == "schedule":  # the schedule knob always compares at the cruise time
            t_ref = t_cruise
        points: dict[str, list[tuple[float, float]]] = {}
        for x in mpc_runs:
            points.setdefault(x["force_model"], []).append((x[time_key], x[energy_key] + off))
        fit = fit_energy_at_time(points, t_ref, window=window, quadratic=quadratic)
        cfit = fit_energy_at_time({"cruise": [(x[time_key], x[energy_key] + off) for x in cruise]}, t_ref,
                                  window=max(window, 0.08))
        out.append({**r, "t_ref": t_ref, "energy_at_tref_J": fit.energy, "cruise_energy_J": cfit.energy["cruise"],
                    "nearest_time_error": fit.nearest, "fit_residual_std": fit.residual_std,
                    "task": {**r["task"], "metric": f"{metric} (window {100 * window:g} %)"}})
    return out
