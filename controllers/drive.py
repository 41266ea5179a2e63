"""One closed-loop drive on the simulator from names: vehicle preset, road, effects, controller, force model.

``drive(vehicle="bmw_i3", road="hilly", controller="mpc", force_model="online", effects=..., seed=0)`` builds
the plant (:class:`~.sim_plant.SimulatorPlant`), the powertrain-energy fit, the force model (abc / online /
oracle) and the controller (mpc / cruise / human), runs :func:`~.closed_loop.run_closed_loop` and returns the
:class:`~.closed_loop.RunResult` (plus the simulator, for ``to_trip()``).
"""

from __future__ import annotations

import hashlib
import json
import math
from typing import Any

import numpy as np

from dataclasses import dataclass, field, replace

from roadload.road_load import RoadLoadParameters
from roadload.road_profiles import RoadProfile
from roadload.schema import check_field_types
from roadload.vehicle import VehicleSpec

from .base import ControllerError, DriveContext
from .closed_loop import Controller, Handover, RunResult, run_closed_loop
from .cruise import CruiseController, CruiseSettings
from .dynamic_programming import cached_plant_fuel_map
from .energy import PlantFuelModel, SourceEnergyModel, with_loss_error
from .force_model import FORCE_MODEL_NAMES, ErroredForceModel, FixedForceModel, ForceModel, OracleForceModel
from .mpc import MpcSettings
from .mpc_controller import MpcController, MpcControllerSettings, TripSchedule
from .optimum import OptimumSettings, OptimumTarget, OptimumTracker
from .sim_plant import HumanDriver, SimulatorPlant
from .vehicle_models import abc_parameters, energy_model_from_spec
from roadload.estimators.knowledge import knowledge_for_preset
from roadload.estimators.models import coast_down_coefficients
from roadload.estimators.pipeline import PipelineSettings, knowledge_from_spec
from roadload.road_profiles import load_profile
from .online import OnlineForceModel
from .wind import WindAwareForceModel, wind_model_name
from roadload.envs import get_preset
from roadload.estimators.change import ChangeDetection

CONTROLLERS = ("mpc", "cruise", "human", "optimum")


@dataclass(frozen=True)
class DriveSettings:
    """Controller choice and its settings for one drive."""

    controller: str = "mpc"
    force_model: str = "online"
    solver: str = "ipopt"
    time_weight: float = 8000.0  # [J/s], MPC only
    model: str = "M4"  # online force model: structure ...
    estimator: str = "RRLM"  # ... and catalog estimator
    # the MPC's grid starts with 8 segments of 5 m (MpcSettings.near_segments: launches and stop approaches at the
    # optimum's resolution, over what a car at 50 km/h drives between two re-plans plus its braking distance to a
    # stop at 2 m/s^2 less that), then 20 m
    mpc: MpcSettings = field(default_factory=lambda: MpcSettings(near_segments=8))
    cruise: CruiseSettings = field(default_factory=CruiseSettings)
    dt: float = 0.1
    # the vehicle the abc model and the online model's prior come from (a fleet operator's nominal vehicle, e.g.
    # a half-loaded truck); None: the driven vehicle itself
    nominal_vehicle: VehicleSpec | str | None = None
    pipeline: PipelineSettings | None = None  # online model: preprocessing settings (None: the defaults)
    wrong_model: dict | None = None  # sensitivity: {"mass": 0.2, ...} relative errors on the oracle (see .errors)
    measure_from: float = 0.0  # [m] start of the measured segment (warm-up before it; see run_closed_loop)
    # MPC only: target time [s] of the measured segment [measure_from, road end]; lambda follows it by feedback
    # from time_weight (mpc_controller.TripSchedule); None: the fixed time weight
    target_time: float | None = None
    multistart_period: float = 0.0  # [s] MPC only: cold multi-start solves (MpcControllerSettings); 0 = off
    gear_command: bool = False  # MPC only, ICE: request the MPC's planned gear (MpcControllerSettings.gear_command)
    # MPC only, with measure_from > 0: who drives the warm-up [0, measure_from). "mpc": the MPC itself; "cruise":
    # cruise control (``cruise`` settings) for every run, the MPC takes over at measure_from (closed_loop.Handover)
    warmup_driver: str = "mpc"
    # shape of the target schedule: (positions [m], elapsed fraction of target_time [-]); None: linear in distance
    target_shape: tuple[tuple[float, ...], tuple[float, ...]] | None = None
    schedule_gain: float = 20.0  # P gain of the target schedule's lambda feedback (TripSchedule.gain)
    # oracle force model: also the true wind vector, so the MPC plans each segment with its own headwind and
    # crosswind (the road's heading ahead); False: the current headwind component for the whole horizon
    oracle_wind: bool = True
    # controller "optimum": the trip time / arrival speed of the full-route optimum it tracks (always with the
    # oracle force model; a warm-up before measure_from is driven by cruise control) and its settings
    optimum_target: OptimumTarget | None = None
    optimum: OptimumSettings | None = None
    # online force models: the catalogue estimator's settings (None: chapter 5's for the model), a change detector
    # that resets the estimator's covariance after a change of the road load, and the wind model's heading source
    estimator_settings: dict | None = None
    change_detection: ChangeDetection | None = None
    heading_source: str = "road"
    replan_period: float = MpcControllerSettings.replan_period  # MPC only: re-planning period [s]

    def __post_init__(self) -> None:
        check_field_types(self, ControllerError)
        if self.controller not in CONTROLLERS:
            raise ControllerError(f"unknown controller {self.controller!r}; choose one of {CONTROLLERS}")
        if self.force_model not in FORCE_MODEL_NAMES:
            raise ControllerError(f"unknown force model {self.force_model!r}; choose one of {FORCE_MODEL_NAMES}")
        if not (math.isfinite(self.time_weight) and self.time_weight >= 0):
            raise ControllerError(f"time_weight: must be a finite number >= 0 [J/s], got {self.time_weight}")
        if self.target_time is not None and not (math.isfinite(self.target_time) and self.target_time > 0):
            raise ControllerError(f"target_time: must be a finite number > 0 [s] or None, got {self.target_time}")
        if self.warmup_driver not in ("mpc", "cruise"):
            raise ControllerError(f"warmup_driver: 'mpc' or 'cruise', got {self.warmup_driver!r}")
        if self.controller == "optimum" and self.optimum_target is None:
            raise ControllerError("controller 'optimum' needs optimum_target (trip time [s], arrival speed [m/s])")
        if not (math.isfinite(self.dt) and self.dt > 0):
            raise ControllerError(f"dt: must be a finite number > 0 [s], got {self.dt}")
        for name, unit in (("measure_from", "m"), ("multistart_period", "s"), ("schedule_gain", "1")):
            if getattr(self, name) < 0:
                raise ControllerError(f"DriveSettings.{name}: must be >= 0 [{unit}], got {getattr(self, name)}")


def _knowledge(vehicle):

    if isinstance(vehicle, str):
        return knowledge_for_preset(vehicle)
    return knowledge_from_spec(vehicle, coast_down=coast_down_coefficients(vehicle))


def resolve_road(road: RoadProfile | str, seed: int = 0) -> RoadProfile:
    if isinstance(road, RoadProfile):
        return road

    try:
        prof = load_profile(road, seed=seed)
    except TypeError:
        prof = load_profile(road)
    if not isinstance(prof, RoadProfile):
        raise ControllerError(f"road {road!r} is a drive cycle, not a road profile; the controllers need a road")
    return prof


def net_energy_metrics(metrics: dict, inertial_mass: float, energy: SourceEnergyModel) -> dict[str, float]:
    """The measured segment's source energy net of the kinetic energy it leaves behind:
    E_net = E_segment + (m_inertial/2) (v_start^2 - v_arrival^2) / eta_i  [J].

    Trips end at the road end at whatever speed the controller has, and 1 m/s more at the end of a 2.5 km car trip
    is ~4 % of its energy; E_net books that kinetic energy at its marginal source cost (the energy model's
    Willans 1/eta_i per J of wheel work; EV: 1), the value the MPC itself gives the kinetic energy at its horizon
    end. m_inertial: the plant's body plus rotating mass at arrival (engaged gear)."""
    ke = 0.5 * inertial_mass * (metrics["segment_start_speed"] ** 2 - metrics["arrival_speed"] ** 2)
    return {"kinetic_energy_change_J": -ke, "energy_net_J": metrics["segment_energy_J"]
            + ke / energy.indicated_efficiency}


def _force_model(st: DriveSettings, plant: SimulatorPlant, road: RoadProfile, nominal: VehicleSpec | str,
                 abc: RoadLoadParameters, energy: SourceEnergyModel) -> tuple[ForceModel, SourceEnergyModel]:
    """The force model the controller plans with (MPC: oracle, wrong, online, online_wind; the optimum: the oracle;
    otherwise the fixed abc model of the nominal vehicle) and the energy model (with the drive-train loss error of a
    'wrong' model)."""
    if st.controller == "optimum" or (st.controller == "mpc" and st.force_model == "oracle"):
        return OracleForceModel(plant.true_parameters, wind=plant.true_wind if st.oracle_wind else None), energy
    if st.controller == "mpc" and st.force_model == "wrong":
        errors = dict(st.wrong_model or {})
        if errors.get("drivetrain_loss"):
            energy = with_loss_error(energy, errors["drivetrain_loss"])
        return ErroredForceModel(OracleForceModel(plant.true_parameters), errors), energy
    if st.controller == "mpc" and st.force_model in ("online", "online_wind"):
        online = _online_force_model(st, road, nominal)
        online.attach(plant.can_window)
        return online, energy
    return FixedForceModel(abc), energy


def _online_force_model(st: DriveSettings, road: RoadProfile, nominal: VehicleSpec | str) -> OnlineForceModel:
    """The online force model of ``st.force_model``: the chapter-5 pipeline's model, or with the wind vector
    (online_wind: the heading from ``st.heading_source``)."""
    common: dict[str, Any] = dict(estimator=st.estimator, pipeline_settings=st.pipeline,
                                  estimator_settings=st.estimator_settings, change_detection=st.change_detection)
    if st.force_model == "online_wind":
        nominal_spec = get_preset(nominal) if isinstance(nominal, str) else nominal
        return WindAwareForceModel(_knowledge(nominal), road, model=wind_model_name(st.model),
                                   heading_source=st.heading_source,
                                   yaw_drag_factor=float(nominal_spec.aero.yaw_drag_factor), **common)
    return OnlineForceModel(_knowledge(nominal), model=st.model, **common)


def _mpc_controller(st: DriveSettings, road: RoadProfile, abc: RoadLoadParameters) -> Controller:
    """The MPC with its settings and target schedule (cruise control before ``measure_from`` with warm-up driver
    'cruise')."""
    mpc_settings = MpcSettings(**{**st.mpc.__dict__, "solver": st.solver, "time_weight": st.time_weight})
    schedule = (None if st.target_time is None
                else TripSchedule(start=st.measure_from, end=road.length, duration=st.target_time,
                                  gain=st.schedule_gain,
                                  shape_s=st.target_shape[0] if st.target_shape else (),
                                  shape_fraction=st.target_shape[1] if st.target_shape else ()))
    controller: Controller = MpcController(MpcControllerSettings(mpc=mpc_settings, schedule=schedule,
                                                                 multistart_period=st.multistart_period,
                                                                 gear_command=st.gear_command,
                                                                 replan_period=st.replan_period))
    if st.warmup_driver == "cruise" and st.measure_from > 0:
        # cruise control on the nominal abc model: the same warm-up whatever the run's force model
        controller = Handover(CruiseController(st.cruise), controller, st.measure_from, FixedForceModel(abc))
    return controller


def _controller(st: DriveSettings, road: RoadProfile, abc: RoadLoadParameters) -> Controller:
    """The controller of ``st.controller``: mpc, optimum (the full-route optimum's tracker), cruise or human."""
    if st.controller == "mpc":
        return _mpc_controller(st, road, abc)
    if st.controller == "optimum" and st.optimum_target is not None:
        tracker: Controller = OptimumTracker(replace(st.optimum_target, measure_from=st.measure_from), st.optimum)
        if st.measure_from > 0:  # the same warm-up as the MPC runs with warmup_driver 'cruise'
            tracker = Handover(CruiseController(st.cruise), tracker, st.measure_from, FixedForceModel(abc))
        return tracker
    if st.controller == "cruise":
        return CruiseController(st.cruise)
    return HumanDriver()


def _online_history(force_model: OnlineForceModel, result: RunResult) -> dict:
    """The online force model's description, with the position [m] of each estimate update."""
    desc = force_model.describe()
    hist = desc.get("history")
    if hist and hist["t"]:  # where the estimate stood: position [m] of each update
        desc["history"]["s"] = [float(x) for x in np.interp(hist["t"], result.log["t"], result.log["s"])]
    return desc


def plant_fuel_model(spec: VehicleSpec) -> PlantFuelModel:
    """The plant's own fuel map per gear of an ICE spec as the MPC's fuel model (MpcSettings.fuel_model
    'plant_map'): :func:`~.dynamic_programming.cached_plant_fuel_map`, the map the plant-fuel bound uses."""
    key = json.dumps(spec.to_dict(), sort_keys=True)
    return PlantFuelModel(cached_plant_fuel_map(spec), f"{spec.name}:{hashlib.sha1(key.encode()).hexdigest()}")


def drive(vehicle="bmw_i3", road: RoadProfile | str = "hilly", effects=None, seed: int = 0,
          settings: DriveSettings | None = None, progress=None, road_seed: int | None = None
          ) -> tuple[RunResult, SimulatorPlant]:
    """Run one closed-loop drive (module docstring): plant, energy model, force model, controller, closed loop,
    metrics."""
    st = settings or DriveSettings()
    road = resolve_road(road, seed if road_seed is None else road_seed)
    plant = SimulatorPlant(vehicle, road, effects=effects, seed=seed, dt=st.dt)
    spec = plant.spec
    energy = energy_model_from_spec(vehicle if isinstance(vehicle, str) else spec)
    nominal = st.nominal_vehicle if st.nominal_vehicle is not None else (vehicle if isinstance(vehicle, str)
                                                                         else spec)
    abc = abc_parameters(nominal)
    force_model, energy = _force_model(st, plant, road, nominal, abc, energy)
    if st.controller == "mpc" and st.mpc.fuel_model.startswith("plant_map") and energy.kind == "ice":
        energy = replace(energy, plant_fuel=plant_fuel_model(spec))
    ctx = DriveContext(road=road, energy=energy, force_model=force_model, dt=st.dt,
                       lateral_accel_max=st.mpc.lateral_accel_max)
    controller = _controller(st, road, abc)
    result = run_closed_loop(controller, plant, ctx, progress=progress, measure_from=st.measure_from)
    result.metrics.update(net_energy_metrics(result.metrics, plant.true_parameters().inertial_mass, energy))
    mpc = st.controller == "mpc"
    result.metrics.update(controller=st.controller, force_model=st.force_model if mpc else "-",
                          solver=st.solver if mpc else "-", time_weight=st.time_weight if mpc else float("nan"))
    if isinstance(force_model, OnlineForceModel) and mpc:
        result.metrics["online"] = _online_history(force_model, result)
    return result, plant
