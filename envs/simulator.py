"""The simulator: step API (``Simulator``) and whole-trip runs (``simulate``) producing a Trip.

See ``roadload.envs`` (the package docstring) for the contract other packages rely on.
"""

from __future__ import annotations

import copy
import json
import math
import os
import warnings
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, Callable, overload

import numpy as np

from roadload.channels import TRUTH
from roadload.road_profiles import DriveCycle, RoadProfile
from roadload.trip_storage import TripWriter
from roadload.road_load import RoadLoadParameters
from roadload.units import R_AIR, air_density
from roadload.vehicle import SensorSpec, VehicleSpec

from . import physics
from .driver import DriverConfig, cruise_stretches, pack_driver, speed_plan
from .drivetrain import regen_capacity as _regen_capacity
from .drivetrain import oil_loss_factor, speed_ratio
from .effects import EffectsConfig
from .layout import (
    L_A, L_ACC_X_SENS, L_ACC_Y_SENS, L_AY, L_BANK, L_BETA, L_CLUTCH, L_CSF, L_CSR, L_CURV, L_CXA, L_DELTA, L_DISC_T,
    L_DRAGF, L_ELEV, L_ESRC, L_FAERO, L_FBRAKE, L_FCLIMB, L_FCORNER, L_FR, L_FR0, L_FR1, L_FR4, L_FROLL, L_FX, L_GEAR,
    L_GRADE, L_HEAD, L_IBAT, L_LOSSF, L_MASS, L_MU, L_OIL, L_PAMB, L_PATHCURV, L_PBF, L_PBR, L_POS, L_PSRC, L_RHO,
    L_RIM, L_SOC, L_T, L_TAMB, L_TE, L_V, L_VBAT, L_WE, L_WFL, L_WFR, L_WIND_A, L_WIND_S, L_WRL, L_WRR, L_YAW,
    MODE_LOCKED, MODE_OPEN, MODE_SLIP, N_LOG, N_ROAD, R_BANK, R_CRUISE, R_CURV, R_ELEV, R_GRADE, R_HEAD, R_S, R_VLIM,
    R_VPLAN, VEHICLE, COMMAND_DRIVER, COMMAND_FORCES, COMMAND_WHEEL_FORCE, LOG, Tables, field_index,
)
from .numerics import road_value_at
from .packing import pack_vehicle
from roadload.presets import get_preset
from .schedules import pack_schedules
from .sensors import SensorModel
from .state import VehicleParameters, VehicleState
from .drivetrain import source_side_inertia, wheel_side_mass

# The truth log's column names in order (``Simulator.truth_log()``'s columns, the sensor model's input rows): the
# public read-only view of the private layout, so that code outside envs/ names a column instead of an index.
TRUTH_LOG_COLUMNS: tuple[str, ...] = tuple(LOG)

if TYPE_CHECKING:  # a streamed run writes plain column arrays: pandas (40 MB) loads only with a Trip in memory
    import pandas as pd

    from roadload.trip import Trip

DT = 0.01  # s, physics step (100 Hz)


def effects_random_state(seed: int) -> int:
    """The start of the effects' random stream (the splitmix64 state, roadload.envs.numerics) of a simulator reset
    with ``seed``: ``Simulator.reset`` and a compiled episode start (``roadload.envs.batch.start_vehicle``) use it."""
    return int(np.random.default_rng([int(seed), 100]).integers(0, 2 ** 63))

# positions of the fields the step path reads and writes in the vehicle record's float view (Python reads a word of
# a float64 view 4x faster than a structured field)
_T, _POS, _V, _A, _NLOG, _GEAR, _MODE, _OMEGA, _TE, _AY, _AY_MAX, _AY_WARN, _E_SOURCE, _MASS = (
    field_index("state", name) for name in ("time", "position", "speed", "acceleration", "log_rows", "gear",
                                            "clutch_mode", "engine_speed", "engine_torque", "lateral_acceleration",
                                            "lateral_acceleration_peak", "lateral_warning_count", "source_energy",
                                            "mass"))
_T_END, _S_END = field_index("params", "time_end"), field_index("params", "distance_end")
_C_MODE, _C_TRACTION, _C_REGEN, _C_FRICTION, _C_STEER, _C_GEAR = (
    field_index("command", name) for name in ("mode", "traction", "regen", "friction", "steer", "gear"))

# truth channels of the Trip: catalogue name -> log column
TRUTH_COLUMNS = {
    "position": L_POS, "speed": L_V, "acceleration": L_A, "tractive_force": L_FX, "rim_torque": L_RIM,
    "mass": L_MASS, "rolling_resistance_coefficient": L_FR, "rolling_resistance_f0": L_FR0,
    "rolling_resistance_f1": L_FR1, "rolling_resistance_f4": L_FR4, "drag_area": L_CXA, "drag_area_factor": L_DRAGF,
    "air_density": L_RHO, "grade": L_GRADE, "curvature": L_CURV, "path_curvature": L_PATHCURV, "bank": L_BANK,
    "wind_speed": L_WIND_S, "wind_angle": L_WIND_A, "cornering_stiffness_front": L_CSF,
    "cornering_stiffness_rear": L_CSR, "engine_torque": L_TE, "engine_speed": L_WE, "gear": L_GEAR,
    "clutch": L_CLUTCH, "brake_pressure_front": L_PBF, "brake_pressure_rear": L_PBR,
    "brake_friction_coefficient": L_MU, "brake_disc_temperature": L_DISC_T, "lateral_acceleration": L_AY,
    "specific_force_x": L_ACC_X_SENS, "specific_force_y": L_ACC_Y_SENS, "yaw_rate": L_YAW,
    "side_slip_angle": L_BETA, "wheel_steer_angle": L_DELTA, "oil_temperature": L_OIL,
    "drivetrain_loss_factor": L_LOSSF, "source_power": L_PSRC, "source_energy": L_ESRC,
    "ambient_temperature": L_TAMB, "air_pressure": L_PAMB, "elevation": L_ELEV, "heading": L_HEAD,
    "wheel_speed_fl": L_WFL, "wheel_speed_fr": L_WFR, "wheel_speed_rl": L_WRL, "wheel_speed_rr": L_WRR,
    "brake_force": L_FBRAKE, "rolling_resistance_force": L_FROLL, "aero_force": L_FAERO,
    "climbing_force": L_FCLIMB, "cornering_resistance": L_FCORNER,
}
_BEV_ONLY = ("battery_voltage", "battery_current", "state_of_charge")
_BEV_TRUTH = {"battery_voltage": L_VBAT, "battery_current": L_IBAT, "state_of_charge": L_SOC}


class SimulationError(ValueError):
    """Invalid simulator input (the message names the argument or field)."""


class LateralValidityWarning(UserWarning):
    """The lateral acceleration exceeded ~4 m/s^2, where the single-track model is no longer valid (sec. 2.5.1)."""


@dataclass
class Action:
    """Wheel-force command for one step [N, all >= 0, at the wheels]: traction (engine / motor torque in the
    current gear within its limits), regen (negative motor torque within the regen limit; ICE: engine drag /
    fuel cut), friction brakes (-> brake pressures). Optional: steer = front wheel steer angle [rad] (None: the
    built-in steering law follows the road), gear = requested gear (None: shift strategy; 0 = neutral / sailing)."""

    traction_force: float = 0.0
    regen_force: float = 0.0
    friction_brake_force: float = 0.0
    steer: float | None = None
    gear: int | None = None


@dataclass(slots=True)
class StepResult:
    """State after a step (SI): time, distance, speed, acceleration, gear, engine/motor speed and torque, clutch,
    source energy used in this step and in total (fuel [J] for ICE, battery [J] for BEV), tractive force, lateral
    acceleration, road attributes at s, done (end of road / cycle / duration / distance) and the vehicle mass m_V
    [kg] (with payload; ``sim.vehicle_state`` has every state field)."""

    t: float
    s: float
    v: float
    a: float
    gear: int
    engine_speed: float
    engine_torque: float
    clutch: float
    source_energy: float
    source_energy_total: float
    tractive_force: float
    lateral_acceleration: float
    grade: float
    curvature: float
    bank: float
    speed_limit: float
    done: bool
    mass: float


def _road_from_cycle(cycle: DriveCycle) -> RoadProfile:
    """A straight road along the cycle's distance (grade from the cycle if given) with generous end margin."""
    t = cycle.time
    dist = np.concatenate([[0.0], np.cumsum(0.5 * (cycle.speed[1:] + cycle.speed[:-1]) * np.diff(t))])
    length = float(dist[-1]) + 200.0
    s = np.arange(0.0, length + 5.0, 5.0)
    grade = np.zeros_like(s)
    if cycle.grade is not None:
        d_u, first = np.unique(dist, return_index=True)
        grade = np.interp(s, d_u, cycle.grade[first]) if d_u.size > 1 else np.full_like(s, cycle.grade[0])
    return RoadProfile(name=f"cycle:{cycle.name}", distance=s, grade=grade, curvature=np.zeros_like(s),
                       bank=np.zeros_like(s), speed_limit=np.full_like(s, 70.0),
                       meta={"from_cycle": cycle.name, **cycle.meta})


def _jsonable(obj: Any) -> Any:
    return json.loads(json.dumps(obj, default=lambda o: o.tolist() if hasattr(o, "tolist") else str(o)))


def _check_vehicle(vehicle: VehicleSpec | str) -> VehicleSpec:
    if isinstance(vehicle, str):
        return get_preset(vehicle)
    if not isinstance(vehicle, VehicleSpec):
        raise SimulationError(f"vehicle: expected a VehicleSpec or preset name, got {type(vehicle).__name__}")
    vehicle.validate()
    return vehicle


class Simulator:
    """Vehicle simulator with a step API (see the ``roadload.envs`` docstring)."""

    def __init__(self, vehicle: VehicleSpec | str, road: RoadProfile | DriveCycle,
                 effects: EffectsConfig | list[str] | str | dict | None = None, sensors: SensorSpec | None = None,
                 seed: int = 0, driver: DriverConfig | DriveCycle | None = None, initial_speed: float = 0.0,
                 log_capacity: int = 1 << 14) -> None:
        """``log_capacity``: substeps the truth log holds before it grows (a user that only steps and reads the
        state, like the native vector env, passes a small number and saves the 7 MB allocation per reset)."""
        if isinstance(log_capacity, bool) or not isinstance(log_capacity, (int, np.integer)) or log_capacity < 1:
            raise SimulationError(f"log_capacity: expected an integer >= 1 substeps, got {log_capacity!r}")
        self._log_capacity = int(log_capacity)
        self.vehicle = _check_vehicle(vehicle)
        self.effects = EffectsConfig.parse(effects)
        if sensors is not None and not isinstance(sensors, SensorSpec):
            raise SimulationError(f"sensors: expected a SensorSpec or None, got {type(sensors).__name__}")
        self.sensors = sensors if sensors is not None else self.vehicle.sensors
        self.sensors.validate("sensors")
        self.cycle: DriveCycle | None = None
        self.driver = DriverConfig()
        if isinstance(driver, DriveCycle):
            self.cycle = driver
        elif isinstance(driver, DriverConfig):
            self.driver = driver
        elif driver is not None:
            raise SimulationError(f"driver: expected a DriverConfig, a DriveCycle or None, got {type(driver).__name__}")
        if isinstance(road, DriveCycle):
            self.cycle = road
            road = _road_from_cycle(road)
        if not isinstance(road, RoadProfile):
            raise SimulationError(f"road: expected a RoadProfile or DriveCycle, got {type(road).__name__}")
        self.road = road
        if not (isinstance(initial_speed, (int, float)) and math.isfinite(initial_speed) and initial_speed >= 0):
            raise SimulationError(f"initial_speed: must be a finite speed >= 0 m/s, got {initial_speed!r}")
        self.initial_speed = float(initial_speed)
        self._check_seed(seed)
        self.seed = int(seed)

        params, self._tables = pack_vehicle(self.vehicle, DT)
        self._pack_effects(params)
        self._params_packed = params  # vehicle + effects, the start of on_road's parameters
        self._new_records()
        self._pack_road()
        self.reset(seed)

    def _new_records(self) -> None:
        """The vehicle record of the core (state, parameters, command; module layout.py) and its views."""
        self._vehicle = np.zeros(1, VEHICLE)
        self._vehicle["params"] = self._params_packed
        self._views()

    def _views(self) -> None:
        """The views of the vehicle record: float words (the step path's fast field access, _T, _POS, ...), state
        and parameter records, and the typed public views."""
        self._words = self._vehicle.view(np.float64)
        self._x, self._p = self._vehicle[0]["state"], self._vehicle[0]["params"]
        self.vehicle_state = VehicleState(self._vehicle)
        """The live state of the vehicle (:class:`roadload.envs.VehicleState`, SI units)."""
        self.parameters = VehicleParameters(self._vehicle)
        """The packed parameters of the vehicle, effects and driver (:class:`roadload.envs.VehicleParameters`)."""

    _VIEWS = ("_words", "_x", "_p", "vehicle_state", "parameters")

    def __getstate__(self) -> dict[str, Any]:
        """Pickled / deep-copied without the views of the vehicle record (a copy would detach them from it)."""
        return {k: v for k, v in self.__dict__.items() if k not in self._VIEWS}

    def __setstate__(self, state: dict[str, Any]) -> None:
        self.__dict__.update(state)
        self._views()

    def _pack_road(self) -> None:
        """Schedules, driver and the road (or drive cycle) on top of the packed vehicle and effects; the result is the
        parameter record every reset starts from."""
        road, p = self.road, self._p
        self._scheduled = pack_schedules(self.effects, p)
        rho_nom = float(air_density(self.effects.ambient_temperature, self.effects.ambient_pressure))
        pack_driver(p, self.driver, self.vehicle.understeer_gradient(), rho_nom)
        p["road_length"] = road.length
        self._road = self._build_road()
        self._stops = np.ascontiguousarray(np.sort(np.asarray(road.stops, dtype=float)))
        if self.cycle is not None:
            p["cycle_mode"] = 1.0
            self._cycle = np.ascontiguousarray(np.vstack([self.cycle.time - self.cycle.time[0], self.cycle.speed]))
            self._stops = np.zeros(0)
        else:
            self._cycle = np.zeros((2, 2))
            self._cycle[0, 1] = 1.0
        self._log = np.zeros((N_LOG, 0))  # column-major: one contiguous array per channel (allocated by reset)
        self._params_start = p.copy()
        self._vplan_base = self._road[R_VPLAN].copy()
        self._stops_all = self._stops

    def on_road(self, road: RoadProfile, seed: int, initial_speed: float | None = None) -> "Simulator":
        """A simulator of this one's vehicle, effects, sensors, driver and log capacity on another road, reset with
        ``seed`` (and ``initial_speed``, default this one's): the state of ``Simulator(self.vehicle, road,
        self.effects, self.sensors, seed, self.driver, initial_speed, log_capacity)`` (tests/envs/test_api.py)
        without validating and packing the vehicle again (about 4x cheaper; the native vector env builds one per
        episode). The vehicle spec and its packed tables are shared with this simulator (read-only)."""
        if self.cycle is not None:
            raise SimulationError("on_road: a drive-cycle simulator has no road to swap; build a new Simulator")
        if not isinstance(road, RoadProfile):
            raise SimulationError(f"road: expected a RoadProfile, got {type(road).__name__}")
        self._check_seed(seed)
        new = copy.copy(self)
        new.road = road
        new._new_records()
        new._pack_road()
        new.reset(seed, initial_speed)
        return new

    # ------------------------------------------------------------------ setup
    @staticmethod
    def _check_seed(seed: Any) -> None:
        if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
            raise SimulationError(f"seed: expected an integer >= 0, got {seed!r}")

    def _pack_effects(self, params: np.ndarray) -> None:
        """The effects' switches and parameters into the (0-d) parameter record."""
        e = self.effects
        values: dict[str, Any] = {"ambient_temperature": e.ambient_temperature, "ambient_pressure": e.ambient_pressure}

        def on(name: str, flag: str, **fields: str) -> dict[str, Any]:
            """Switch ``flag`` of effect ``name``; its parameters (keys) into the record fields (values)."""
            values[flag] = 1.0 if e.enabled(name) else 0.0
            p = e.params(name)
            values.update({field: p[key] for key, field in fields.items()})
            return p

        on("wind", "wind_on", mean_speed="wind_mean_speed", direction="wind_direction", gust_std="wind_gust_std",
           gust_time_constant="wind_gust_time_constant", direction_std="wind_direction_std")
        p = on("payload", "payload_on", change_std="payload_change_std", min_payload="payload_min",
               max_payload="payload_max")
        if self.vehicle.body.mass + p["min_payload"] <= 0:
            raise SimulationError("effect 'payload' parameter 'min_payload': would make the mass <= 0")
        on("tire_warmup", "tire_warmup_on", cold_factor="tire_cold_factor", distance_constant="tire_warmup_distance")
        on("winter_tires", "winter_tires_on", rolling_factor="winter_rolling_factor",
           cornering_factor="winter_cornering_factor")
        on("drag_area", "drag_area_on", roof_box="drag_roof_box", windows="drag_windows", sunroof="drag_sunroof",
           toggle_rate="drag_toggle_rate")
        on("road_bank", "road_bank_on", scale="bank_scale", superelevation_gain="superelevation_gain",
           max_bank="bank_max")
        on("wet_road", "wet_road_on", rolling_factor="wet_rolling_factor", water_f1="wet_f1")
        start = on("oil_temperature", "oil_temperature_on")["start_temperature"]
        values["oil_start_temperature"] = (e.ambient_temperature if (isinstance(start, float) and math.isnan(start))
                                           else start)
        on("brake_pad_drift", "pad_drift_on", temperature_coefficient="pad_temperature_coefficient",
           reference_temperature="pad_reference_temperature", random_walk_std="pad_random_walk_std")
        on("barometric", "barometric_on", scale_height="barometric_scale_height")
        on("auxiliary_load", "auxiliary_load_on", power="auxiliary_load")
        for name, value in values.items():
            params[name] = value

    def _build_road(self) -> np.ndarray:
        rd = self.road
        road = np.zeros((N_ROAD, rd.distance.size))
        road[R_S] = rd.distance
        road[R_GRADE] = rd.grade
        road[R_CURV] = rd.curvature
        road[R_BANK] = rd.bank
        road[R_VLIM] = rd.speed_limit
        ds = np.diff(rd.distance)
        road[R_HEAD, 1:] = np.cumsum(0.5 * (rd.curvature[1:] + rd.curvature[:-1]) * ds)
        road[R_ELEV] = rd.elevation()
        road[R_VPLAN] = speed_plan(rd.distance, rd.curvature, rd.speed_limit, self.driver)
        return np.ascontiguousarray(road)

    # ------------------------------------------------------------------ reset / step
    def reset(self, seed: int | None = None, initial_speed: float | None = None) -> StepResult:
        """Back to the start of the road (optionally with a new seed / initial speed); returns the initial state."""
        if seed is not None:
            self._check_seed(seed)
            self.seed = int(seed)
        if initial_speed is not None:
            if not (math.isfinite(initial_speed) and initial_speed >= 0):
                raise SimulationError(f"initial_speed: must be a finite speed >= 0 m/s, got {initial_speed!r}")
            self.initial_speed = float(initial_speed)
        scen = np.random.default_rng([self.seed, 200])
        if self.effects.enabled("poor_excitation"):
            p = self.effects.params("poor_excitation")
            self._road[R_CRUISE] = cruise_stretches(self._road[R_S], float(p["fraction"]),
                                                    float(p["stretch_length"]), scen)
        else:
            self._road[R_CRUISE] = 0.0
        self._hold_cruise_speed()
        self.sensor_model = SensorModel(self.vehicle, self.sensors, self.effects, self.seed, DT)
        pay = self.effects.params("payload")
        payload = float(pay["initial_payload"]) if self.effects.enabled("payload") else 0.0
        if self.vehicle.body.mass + payload <= 0:
            raise SimulationError("effect 'payload' parameter 'initial_payload': makes the mass <= 0")
        self._vehicle[0]["params"] = self._params_start  # undoes the schedules and run limits of the last trip
        self._vehicle["state"] = 0
        x, p = self._x, self._p
        x["random_state"] = effects_random_state(self.seed)
        v = self.initial_speed
        x["speed"] = v
        x["last_shift_time"] = -1e9
        physics.set_initial_mass(self._vehicle, payload)
        x["drag_area_factor"] = 1.0 + (p["drag_roof_box"] if p["drag_area_on"] > 0.5 else 0.0)
        oil_on = p["oil_temperature_on"] > 0.5
        x["oil_temperature"] = p["oil_start_temperature"] if oil_on else p["oil_warm_temperature"]
        x["brake_disc_temperature"] = p["ambient_temperature"]
        d = self.vehicle.drivetrain
        x["state_of_charge"] = d.require_battery().initial_soc if d.kind == "bev" else 0.0
        x["gear"], x["clutch_mode"], x["engine_speed"] = self._initial_gear(v)
        physics.start_schedules(self._vehicle)
        self._log = np.zeros((N_LOG, self._log_capacity))
        self._log_base = 0  # absolute substep of log column 0 (> 0 once a streamed run dropped old substeps)
        self._flushed = 0  # substeps already written to a TripWriter
        self._warned = False
        self._last_energy = 0.0
        self._result = self._make_result(0.0)
        return self._result

    def _initial_gear(self, v: float) -> tuple[int, int, float]:
        """(gear, clutch mode, engine speed [rad/s]) at speed v [m/s]: BEV locked in its gear; ICE the highest gear
        whose engine speed is above 1.3 x idle and 1.2 x the low-load downshift speed, locked when above idle."""
        p = self._p
        if p["is_bev"] > 0.5:
            return 1, MODE_LOCKED, speed_ratio(p, 1) * v
        gear = 1
        for g in range(1, int(p["n_gears"]) + 1):
            if speed_ratio(p, g) * v >= max(1.3 * p["idle_speed"], 1.2 * p["downshift_speed_low"]):
                gear = g
        if speed_ratio(p, gear) * v >= p["idle_speed"]:
            return gear, MODE_LOCKED, speed_ratio(p, gear) * v
        return gear, MODE_OPEN, p["idle_speed"]

    def _hold_cruise_speed(self) -> None:
        """poor_excitation with hold_speed 'yes': one constant planned speed per cruise stretch (the lowest of the
        stretch), re-planned with the driver's deceleration into it; stops inside the stretches are skipped."""
        if not (self.effects.enabled("poor_excitation")
                and self.effects.params("poor_excitation")["hold_speed"] == "yes") or self.cycle is not None:
            return  # the plan and the stops stay as built
        rd = self._road
        rd[R_VPLAN] = self._vplan_base
        self._stops = self._stops_all
        on = rd[R_CRUISE] > 0.5
        if not on.any():
            return
        edges = np.diff(np.concatenate([[0], on.astype(int), [0]]))
        limit = self.road.speed_limit.astype(float).copy()
        keep = np.ones(self._stops.size, dtype=bool)
        for a, b in zip(np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)):
            limit[a:b] = float(self._vplan_base[a:b].min()) / self.driver.speed_limit_factor
            keep &= ~((self._stops >= rd[R_S, a]) & (self._stops <= rd[R_S, b - 1]))
        rd[R_VPLAN] = speed_plan(self.road.distance, self.road.curvature, limit, self.driver)
        self._stops = np.ascontiguousarray(self._stops[keep])

    def reserve_log(self, n_substeps: int) -> None:
        """Room in the truth log for ``n_substeps`` more substeps (it grows by doubling): for a compiled kernel that
        advances this simulator through ``roadload.envs.batch.Fleet.sharing``."""
        self._ensure_capacity(n_substeps)

    def refresh(self, warn: bool = True) -> StepResult:
        """The state after a compiled kernel advanced this simulator (``Fleet.sharing``): updates ``state`` (this
        step's source energy counted from the last step or refresh) and, with ``warn``, warns once about lateral
        accelerations beyond the single-track model's validity. A truth log that ran out of room (no
        ``reserve_log`` before the advance) is a SimulationError."""
        if int(self._words[_NLOG]) > self._log.shape[1]:
            raise SimulationError(f"refresh: the truth log holds {self._log.shape[1]} substeps but "
                                  f"{int(self._words[_NLOG])} were advanced; call reserve_log(n_substeps) before "
                                  f"each advance")
        if not warn:
            self._warned = True
        return self._after_advance()

    def _ensure_capacity(self, extra: int) -> None:
        n = int(self._words[_NLOG])
        if n + extra > self._log.shape[1]:
            new = np.zeros((N_LOG, max(2 * self._log.shape[1], n + extra)))
            new[:, :n] = self._log[:, :n]
            self._log = new

    def step(self, action: Action | float | None = None, n_substeps: int = 10) -> StepResult:
        """Advance n_substeps x 10 ms with a constant command: an Action, a signed wheel force [N] (split by the
        default allocator: regen first, then friction brakes), or None (the built-in driver)."""
        w = self._words
        if action is None:
            w[_C_MODE] = COMMAND_DRIVER
        elif isinstance(action, Action):
            tr, rg, fb = action.traction_force, action.regen_force, action.friction_brake_force
            if not (tr >= 0 and rg >= 0 and fb >= 0) or not math.isfinite(tr + rg + fb):
                raise SimulationError(f"action: forces must be finite and >= 0 N, got traction={tr!r}, "
                                      f"regen={rg!r}, friction={fb!r}")
            w[_C_MODE] = COMMAND_FORCES
            w[_C_TRACTION] = tr
            w[_C_REGEN] = rg
            w[_C_FRICTION] = fb
            w[_C_STEER] = np.nan if action.steer is None else action.steer
            w[_C_GEAR] = -1.0 if action.gear is None else action.gear
            if action.gear is not None and not 0 <= action.gear <= self.vehicle.drivetrain.n_gears:
                raise SimulationError(f"action.gear: must be in 0..{self.vehicle.drivetrain.n_gears}, got "
                                      f"{action.gear!r}")
        else:
            f = float(action)
            if not math.isfinite(f):
                raise SimulationError(f"action: wheel force must be finite, got {action!r}")
            w[_C_MODE] = COMMAND_WHEEL_FORCE
            w[_C_TRACTION] = f
            w[_C_STEER] = np.nan
            w[_C_GEAR] = -1.0
        if n_substeps < 1:
            raise SimulationError(f"n_substeps: must be >= 1, got {n_substeps!r}")
        if int(w[_NLOG]) + n_substeps > self._log.shape[1]:
            self._ensure_capacity(n_substeps)
        physics.advance_one(self._vehicle, *self._tables, self._road, self._stops, self._cycle, self._log, n_substeps)
        return self._after_advance()

    def _after_advance(self) -> StepResult:
        """The StepResult after the core advanced the vehicle (and the lateral-validity warning, once)."""
        w = self._words
        if w[_AY_WARN] > 0 and not self._warned:
            self._warn_lateral()
        e = w[_E_SOURCE]
        self._result = self._make_result(e - self._last_energy)
        self._last_energy = e
        return self._result

    def _make_result(self, d_energy: float) -> StepResult:
        w = self._words
        n = int(w[_NLOG])
        s = w[_POS]
        if n:
            row = self._log[:, n - 1]
            fx, grade, curv, bank = row[L_FX], row[L_GRADE], row[L_CURV], row[L_BANK]
        else:
            fx = 0.0
            at = self.road.at(s)
            grade, curv, bank = float(at["grade"]), float(at["curvature"]), 0.0
        mode = w[_MODE]
        return StepResult(t=w[_T], s=s, v=w[_V], a=w[_A], gear=int(w[_GEAR]), engine_speed=w[_OMEGA],
                          engine_torque=w[_TE],
                          clutch=1.0 if mode == MODE_LOCKED else (0.5 if mode == MODE_SLIP else 0.0),
                          source_energy=d_energy, source_energy_total=w[_E_SOURCE], tractive_force=fx,
                          lateral_acceleration=w[_AY], grade=grade, curvature=curv, bank=bank,
                          speed_limit=road_value_at(self._road, R_VLIM, s), done=self.done, mass=w[_MASS])

    def _warn_lateral(self) -> None:
        self._warned = True
        warnings.warn(LateralValidityWarning(
            f"lateral acceleration reached {self._words[_AY_MAX]:.2f} m/s^2 (above 4 m/s^2, where the single-track "
            f"model is no longer valid, section 2.5.1) at t={self._words[_T]:.1f} s, s={self._words[_POS]:.0f} m"),
            stacklevel=3)

    # ------------------------------------------------------------------ whole trips
    def run(self, duration: float | None = None, distance: float | None = None,
            progress: Callable[[float], None] | None = None, chunk_seconds: float = 120.0,
            writer: TripWriter | None = None) -> None:
        """Drive with the built-in driver (or the drive cycle) until the end of the road / cycle, or for the given
        duration [s] / distance [m] from now, whichever comes first. With a ``writer`` (see :meth:`trip_writer`)
        every chunk of ``chunk_seconds`` is written to it and dropped from memory."""
        w = self._words
        horizon = self._set_run_limits(duration, distance)
        t0, s0 = w[_T], w[_POS]
        max_steps = int(math.ceil(horizon / DT)) + 1
        if writer is None:  # with a writer, the log holds one chunk at a time
            self._reserve_log(max_steps, horizon)
        w[_C_MODE] = COMMAND_DRIVER
        chunk = max(1, int(chunk_seconds / DT))
        done = 0
        while done < max_steps and not self.done:
            n = min(chunk, max_steps - done)
            self._ensure_capacity(n)
            done += physics.run_one(self._vehicle, *self._tables, self._road, self._stops, self._cycle, self._log, n)
            if progress is not None:
                progress(self._run_fraction(t0, s0, horizon))
            if writer is not None:
                self._flush(writer)
        if writer is not None:
            self._flush(writer)
        if not self.done:
            warnings.warn(f"trip stopped after {w[_T] - t0:.0f} s at s={w[_POS]:.0f} m without reaching the end "
                          f"of road {self.road.name!r} (vehicle too slow or stuck)", RuntimeWarning, stacklevel=2)
        w[_T_END] = np.inf
        w[_S_END] = np.inf
        self._after_advance()

    def _set_run_limits(self, duration: float | None, distance: float | None) -> float:
        """Check duration [s] / distance [m] of a run, set the core's time / distance limits (inf: none) and return
        the horizon [s] the run is sized for (the whole cycle, the duration, or the distance at 2 m/s plus stops)."""
        w = self._words
        if duration is not None and not (math.isfinite(duration) and duration > 0):
            raise SimulationError(f"duration: must be a positive number of seconds, got {duration!r}")
        if distance is not None and not (math.isfinite(distance) and distance > 0):
            raise SimulationError(f"distance: must be a positive number of metres, got {distance!r}")
        remaining = self.road.length - w[_POS]
        if distance is not None and distance > remaining + 1e-6:
            raise SimulationError(f"distance: {distance:g} m exceeds the {remaining:.0f} m left on road "
                                  f"{self.road.name!r}")
        t0 = w[_T]
        if self.cycle is not None:
            horizon = self.cycle.duration - t0 if duration is None else min(self.cycle.duration - t0, duration)
        elif duration is not None:
            horizon = duration
        else:
            dist = remaining if distance is None else distance
            horizon = dist / 2.0 + self._stops.size * (self.driver.dwell_max + 30.0) + 600.0
        w[_T_END] = t0 + horizon if (duration is not None or self.cycle is not None) else np.inf
        w[_S_END] = w[_POS] + distance if distance is not None else np.inf
        return horizon

    def _reserve_log(self, max_steps: int, horizon: float) -> None:
        """Room in the truth log for the run: max_steps with a time limit, else the duration the speed plan
        expects (so the log rarely has to grow)."""
        if self._words[_T_END] < np.inf:
            self._ensure_capacity(max_steps)
            return
        rd = self._road
        plan = np.maximum(0.5 * (rd[R_VPLAN, 1:] + rd[R_VPLAN, :-1]), 3.0)
        expect = float(np.sum(np.diff(rd[R_S]) / plan)) + self._stops.size * (self.driver.dwell_max + 20.0)
        self._ensure_capacity(int(min(1.15 * expect, horizon) / DT))

    def _run_fraction(self, t0: float, s0: float, horizon: float) -> float:
        """Progress of a run in [0, 1]: elapsed time over the horizon with a time limit, else the distance driven
        over the distance to go (to the distance limit or the end of the road)."""
        w = self._words
        if w[_T_END] < np.inf:
            frac = (w[_T] - t0) / horizon
        else:
            goal = w[_S_END] if w[_S_END] < np.inf else self.road.length
            frac = (w[_POS] - s0) / max(goal - s0, 1e-9)
        return min(1.0, max(0.0, float(frac)))

    @property
    def done(self) -> bool:
        """End of the road (or drive cycle) reached, or the limit of the current run."""
        return bool(physics.done_one(self._vehicle))

    @property
    def road_depends_on_seed(self) -> bool:
        """Whether a reset's packed road and stop lines depend on the seed (poor_excitation draws its cruise
        stretches from it); otherwise the seed sets only the effects' random stream (effects_random_state)."""
        return self.effects.enabled("poor_excitation")

    def _core_records(self) -> tuple[np.ndarray, Tables, np.ndarray, np.ndarray, np.ndarray | None]:
        """(vehicle record array, tables, road rows, stop lines, drive cycle or None): what Fleet.load copies."""
        return self._vehicle, self._tables, self._road, self._stops, (None if self.cycle is None else self._cycle)

    # ------------------------------------------------------------------ queries
    @property
    def state(self) -> StepResult:
        return self._result

    def energy_ledger(self) -> dict[str, float]:
        """Cumulative energies [J] since reset: source (fuel/battery), shaft work T_E omega_E, dissipation by
        component, climbing work (= m g delta h for constant mass), and the kinetic energy now."""
        x = self.vehicle_state
        return {"source": x.source_energy, "shaft_work": x.shaft_work, "gearbox_loss": x.gearbox_loss,
                "differential_loss": x.differential_loss, "clutch_loss": x.clutch_loss, "brake_loss": x.brake_loss,
                "rolling_loss": x.rolling_loss, "aero_loss": x.aero_loss, "cornering_loss": x.cornering_loss,
                "climbing_work": x.climbing_work, "payload_potential": x.payload_potential_energy,
                "kinetic_energy": self.kinetic_energy()}

    def kinetic_energy(self) -> float:
        """Translational + rotational kinetic energy [J] of the longitudinal model now."""
        x = self.vehicle_state
        m_w = wheel_side_mass(self._p, x.mass)
        return 0.5 * m_w * x.speed ** 2 + 0.5 * source_side_inertia(self._p, int(x.gear)) * x.engine_speed ** 2

    def _loss_factor(self) -> float:
        """The drive-train's oil-temperature loss factor phi now (1 without the oil_temperature effect)."""
        p = self._p
        return oil_loss_factor(p, self._x["oil_temperature"]) if p["oil_temperature_on"] > 0.5 else 1.0

    def true_parameters(self) -> dict[str, float]:
        """Current true lumped parameters (for oracle controllers / evaluation), SI units."""
        x, p = self.vehicle_state, self._p
        n = int(x.log_rows)
        row = self._log[:, n - 1] if n else None
        v = x.speed
        mass = x.mass
        if row is None:  # before the first step: nominal values
            fr0, fr1, fr4 = p["rolling_f0"], p["rolling_f1"], p["rolling_f4"]
            rho = p["ambient_pressure"] / (R_AIR * p["ambient_temperature"])
            cxa = p["drag_coefficient"] * p["frontal_area"] * x.drag_area_factor
            csf, csr, mu = p["cornering_stiffness_front"], p["cornering_stiffness_rear"], p["pad_friction"]
            ws = wa = grade = curv = bank = 0.0
        else:
            fr0, fr1, fr4, rho, cxa = row[L_FR0], row[L_FR1], row[L_FR4], row[L_RHO], row[L_CXA]
            csf, csr, ws, wa, mu = row[L_CSF], row[L_CSR], row[L_WIND_S], row[L_WIND_A], row[L_MU]
            grade, curv, bank = row[L_GRADE], row[L_CURV], row[L_BANK]
        lf, lr, wb = p["cg_to_front"], p["cg_to_rear"], p["wheelbase"]
        c_eq = 1.0 / (4.0 * (lr ** 2 / csf + lf ** 2 / csr) / wb ** 2)
        a, b, c = RoadLoadParameters.from_physical(float(mass), float(fr0), float(fr1), float(fr4), float(cxa),
                                                   float(rho)).coast_down   # eq. 5.4 of the current truth
        return {
            "mass": mass, "rolling_resistance_f0": fr0, "rolling_resistance_f1": fr1, "rolling_resistance_f4": fr4,
            "rolling_resistance_coefficient": fr0 + fr1 * v + fr4 * v ** 4, "drag_area": cxa, "air_density": rho,
            "aero_coefficient": c, "wind_speed": ws, "wind_angle": wa,
            "cornering_stiffness_front": csf, "cornering_stiffness_rear": csr, "cornering_stiffness": c_eq,
            "brake_friction_coefficient": mu, "drivetrain_loss_factor": self._loss_factor(),
            "oil_temperature": x.oil_temperature, "ambient_temperature": p["ambient_temperature"],
            "ambient_pressure": p["ambient_pressure"], "grade": grade, "curvature": curv, "bank": bank,
            "wheel_radius": p["wheel_radius"], "effective_mass": self.vehicle.effective_mass(int(x.gear), mass),
            "a": a, "b": b, "c": c,
        }

    def regen_capacity(self) -> float:
        """Largest braking force [N] the engine drag / motor regen can apply now."""
        x = self.vehicle_state
        return float(_regen_capacity(self._p, self._tables, int(x.gear), int(x.clutch_mode), x.engine_speed, x.speed,
                                     self._loss_factor()))

    def observe(self) -> dict[str, float] | None:
        """The latest CAN-like sensor sample (measured channels, SI), None before the first step."""
        self._check_whole_log("observe")
        return self.sensor_model.sample(self._log, int(self._words[_NLOG]))

    def truth_log(self) -> np.ndarray:
        """The raw truth log so far (rows = 10-ms substeps, columns = ``TRUTH_LOG_COLUMNS``); a view, do not modify."""
        self._check_whole_log("truth_log")
        return self._log[:, : int(self._words[_NLOG])].T

    def _check_whole_log(self, what: str) -> None:
        if self._log_base > 0:
            raise SimulationError(f"{what}: this run was streamed to a file (run(writer=...)); the in-memory log "
                                  f"holds only its last substeps -- read the trip file instead")

    def _truth_map(self) -> dict[str, int]:
        truth_map = dict(TRUTH_COLUMNS)
        if self.vehicle.drivetrain.kind == "bev":
            truth_map.update(_BEV_TRUTH)
        return truth_map

    def truth_units(self) -> dict[str, str]:
        """SI unit of every truth channel of this simulator's trips (incl. 't')."""
        return {c: TRUTH[c].unit for c in ["t", *self._truth_map(), "cornering_stiffness"]}

    def _frames(self, start: int, stop: int) -> tuple[pd.DataFrame, pd.DataFrame]:
        """Measured and truth frames of the absolute substeps start..stop-1 (the log holds substep _log_base on)."""
        import pandas as pd  # here, not at import (see the TYPE_CHECKING import)

        t, channels, keep = self.sensor_model.measure(self._log, stop, start=start, offset=self._log_base)
        block = np.empty((len(channels) + 1, t.size))  # one 2-D block: no column-by-column consolidation
        block[0] = t
        for i, arr in enumerate(channels.values()):
            block[i + 1] = arr
        if not keep.all():
            block = block[:, keep]
        measured = pd.DataFrame(block.T, columns=["t", *channels], copy=False)
        truth_map = self._truth_map()
        rows = self._log[[L_T, *truth_map.values()], start - self._log_base:stop - self._log_base]
        truth = pd.DataFrame(rows.T, columns=["t", *truth_map], copy=False)
        truth["cornering_stiffness"] = self._cornering_stiffness(truth["cornering_stiffness_front"].to_numpy(),
                                                                 truth["cornering_stiffness_rear"].to_numpy())
        return measured, truth

    def _chunk_columns(self, start: int, stop: int) -> tuple[dict[str, np.ndarray], dict[str, np.ndarray]]:
        """The columns of :meth:`_frames` as plain arrays by name, for a streamed chunk: the truth columns are views
        of the log rows and the measured ones the sensor model's own arrays (no 2-D copies, no pandas; used before
        the log changes)."""
        log, base = self._log, self._log_base
        t, channels, keep = self.sensor_model.measure(log, stop, start=start, offset=base)
        measured = {"t": t, **{k: np.asarray(v, dtype=float) for k, v in channels.items()}}
        if not keep.all():  # samples removed by 'missing' dropouts
            measured = {k: v[keep] for k, v in measured.items()}
        truth_map = self._truth_map()
        truth = dict(zip(["t", *truth_map], (log[c, start - base:stop - base] for c in [L_T, *truth_map.values()])))
        truth["cornering_stiffness"] = self._cornering_stiffness(truth["cornering_stiffness_front"],
                                                                 truth["cornering_stiffness_rear"])
        return measured, truth

    def _cornering_stiffness(self, front: np.ndarray, rear: np.ndarray) -> np.ndarray:
        """The single-track equivalent cornering stiffness [N/rad] of one axle pair: 1 / (4 (l_r^2 / C_f +
        l_f^2 / C_r) / l^2), from the front and rear axle's C_f, C_r [N/rad] and the axle distances l_f, l_r, l [m]."""
        p = self._p
        return 1.0 / (4.0 * (p["cg_to_rear"] ** 2 / front + p["cg_to_front"] ** 2 / rear) / p["wheelbase"] ** 2)

    def _trip_meta(self, name: str | None) -> dict[str, Any]:
        warn = []
        x = self.vehicle_state
        if x.lateral_warning_count > 0:
            warn.append(f"lateral acceleration above 4 m/s^2 in {int(x.lateral_warning_count)} samples (max "
                        f"{x.lateral_acceleration_peak:.2f} m/s^2): single-track model outside its validity")
        return {
            "source": "sim",
            "name": name or f"sim-{self.vehicle.name}-{self.road.name}-{self.seed}",
            "vehicle": self.vehicle.to_dict(),
            "road": {"name": self.road.name, "length": self.road.length, "meta": _jsonable(self.road.meta)},
            "seed": self.seed,
            "effects": self.effects.to_dict(),
            "sample_rate": float(self.sensors.sample_rate),
            "driver": ({"drive_cycle": self.cycle.name} if self.cycle is not None else asdict(self.driver)),
            "sensors": asdict(self.sensors),
            "energy": {k: float(v) for k, v in self.energy_ledger().items()},
            "initial_speed": self.initial_speed,
            "warnings": warn,
        }

    def to_trip(self, name: str | None = None) -> Trip:
        """The Trip of everything stepped since reset: measured channels (sensor model) + truth + metadata."""
        n = int(self._words[_NLOG])
        if n == 0:
            raise SimulationError("to_trip: nothing simulated yet (call step() or run() first)")
        self._check_whole_log("to_trip")
        from roadload.trip import Trip  # here, not at import (see the TYPE_CHECKING import)

        measured, truth = self._frames(0, n)
        units = {"t": "s", **self.sensor_model.units}
        truth_units = {c: TRUTH[c].unit for c in truth.columns}
        return Trip(measured, units, self._trip_meta(name), truth, truth_units)

    # ------------------------------------------------------------------ streaming
    def trip_writer(self, path: str | os.PathLike, precision: str = "compact") -> TripWriter:
        """A :class:`roadload.trip.TripWriter` for this simulator's trip (channels, units, sensor resolutions);
        pass it to ``run(writer=...)`` and close it with ``writer.close(sim.trip_meta())``."""
        sm = self.sensor_model
        shared = sm.decimation == 1 and not (sm.dropouts is not None and sm.missing_mode)
        res = {n: float(c.resolution) for n, c in self.sensors.channels.items() if c.enabled and c.resolution > 0}
        return TripWriter(path, {"t": "s", **sm.units}, self.truth_units(), precision, res, shared_time=shared)

    def trip_meta(self, name: str | None = None) -> dict[str, Any]:
        """The Trip metadata of the run so far (what ``to_trip`` puts in ``meta``)."""
        return self._trip_meta(name)

    def _flush(self, writer: TripWriter) -> None:
        """Write the substeps simulated since the last flush to the writer, then drop all but the log history the
        sensor latencies reach back to."""
        n_rel = int(self._words[_NLOG])
        stop = self._log_base + n_rel
        if stop > self._flushed:
            measured, truth = self._chunk_columns(self._flushed, stop)
            writer.write(measured, truth)
            self._flushed = stop
        keep = self.sensor_model.max_delay + self.sensor_model.decimation
        if n_rel > keep:
            self._log[:, :keep] = self._log[:, n_rel - keep:n_rel]
            self._words[_NLOG] = keep
            self._log_base += n_rel - keep


@overload
def simulate(vehicle: VehicleSpec | str, road: RoadProfile | DriveCycle,
             effects: EffectsConfig | list[str] | str | dict | None = None, sensors: SensorSpec | None = None,
             seed: int = 0, duration: float | None = None, distance: float | None = None,
             driver: DriverConfig | DriveCycle | None = None, progress: Callable[[float], None] | None = None,
             initial_speed: float = 0.0, out: None = None, precision: str = "compact",
             chunk_seconds: float = 300.0) -> Trip: ...


@overload
def simulate(vehicle: VehicleSpec | str, road: RoadProfile | DriveCycle,
             effects: EffectsConfig | list[str] | str | dict | None = None, sensors: SensorSpec | None = None,
             seed: int = 0, duration: float | None = None, distance: float | None = None,
             driver: DriverConfig | DriveCycle | None = None, progress: Callable[[float], None] | None = None,
             initial_speed: float = 0.0, *, out: str | os.PathLike, precision: str = "compact",
             chunk_seconds: float = 300.0) -> Path: ...


def simulate(vehicle: VehicleSpec | str, road: RoadProfile | DriveCycle,
             effects: EffectsConfig | list[str] | str | dict | None = None, sensors: SensorSpec | None = None,
             seed: int = 0, duration: float | None = None, distance: float | None = None,
             driver: DriverConfig | DriveCycle | None = None, progress: Callable[[float], None] | None = None,
             initial_speed: float = 0.0, out: str | os.PathLike | None = None, precision: str = "compact",
             chunk_seconds: float = 300.0) -> Trip | Path:
    """Run the built-in driver (or a drive cycle) over a road and return the Trip (measured + truth + meta).

    With ``out`` (a .parquet path) the trip is streamed to that file instead, one Parquet row group per
    ``chunk_seconds`` of driving, holding only one chunk in memory (day-long trips in bounded memory), and the
    path is returned; ``precision`` as for :meth:`roadload.trip.Trip.save` ('compact': quantised channels as
    scaled integers, truth float32). Read it back with ``Trip.load`` / ``Trip.iter_chunks``."""
    sim = Simulator(vehicle, road, effects, sensors, seed, driver=driver, initial_speed=initial_speed)
    if out is None:
        sim.run(duration=duration, distance=distance, progress=progress, chunk_seconds=chunk_seconds)
        return sim.to_trip()
    with sim.trip_writer(out, precision) as writer:
        sim.run(duration=duration, distance=distance, progress=progress, chunk_seconds=chunk_seconds,
                writer=writer)
        writer.close(sim.trip_meta())
    return Path(out)
