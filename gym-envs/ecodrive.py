"""``roadload/EcoDrive-v0``: drive a vehicle preset along a road profile with preview, minimising source energy
and time (gymnasium env on top of the simulator's compiled batch step, :mod:`roadload.envs.batch`).

One step, one implementation: the single env is :class:`EcoBatch` with one sub-env, the native vector env
(:mod:`roadload.gym.vector`) the same with N; both run the compiled step of :mod:`roadload.gym.ecodrive_kernel`
(action, physics, reward, done flags, 'state' observation, info). The single env's batch shares the episode's
:class:`~roadload.envs.Simulator` (its truth log, CAN sensors, ``to_trip()``, ``true_parameters()``).

Action: ``u`` in [-1, 1] (Box, shape (1,)), a normalised wheel-force command held for one control period
(default 0.1 s = 10 physics steps at 100 Hz). u >= 0 asks for traction u * min(F_peak, P_max / max(v, 1 m/s));
u < 0 asks for a braking force |u| * 0.5 m_V g, which the simulator splits regen first, friction brakes for the rest
(its default allocator). The drive-train clips the request to what it can deliver in the current gear.

Speed shield (``speed_shield=True``, off by default): before it is applied, the command is capped at
SHIELD_GAIN * (v_env(s) - v), where v_env is the braking envelope of the speed limits ahead lowered by
``shield_margin`` (:meth:`RouteTable.braking_envelope`). The capped command is what the vehicle gets and what
``previous_command`` reports.

Observation: an observation type built by :func:`observation_factory` from ``config.observation`` ('state',
'can', 'can+estimates'; :data:`OBSERVATION_TYPES`), its entries listed by :func:`observation_layout`. Every entry is
an SI value divided by a fixed scale (``obs_scaling='normalized'``, default) or the raw SI value (``'si'``).

Reward: ``-scale * (energy + time * dt + speeding * (v - v_lim)+ dt + lateral * (|a_y| - a_y,max)+ dt
+ stop * [stop line crossed faster than stop_speed] + jerk * jerk^2 dt - progress * ds)`` with ds the metres
driven along the route in the step (potential-based shaping; see EcoDriveReward); each raw term is in
``info['terms']`` and each weighted term (J-equivalent) in ``info['costs']``, so users can re-weight.
Terminates when the route's end is reached, truncates at the time limit.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from roadload.envs import Simulator
from roadload.envs.batch import Fleet, FleetRecords
from roadload.road_profiles import RoadProfile, load_profile_start
from roadload.units import G
from roadload.vehicle import VehicleSpec

from roadload.gym.actions import validate_action
from roadload.gym.config import (SPACE_FIELDS_ECODRIVE, EcoDriveConfig, GymConfigError, make_config, updated_config)
from roadload.gym.ecodrive_kernel import (COST_NAMES, EPISODE, INFO_ROWS, I_COSTS, I_RETURN, I_TERMS, N_COSTS, N_INFO,
                                          NO_SHIELD, PREVIEW_GRID, SETTINGS, SHIELD_GAIN, SPEED_LIMIT, STOP_HORIZON,
                                          EcoOutputs, EcoRecords, braking_envelope, gather_info_all, look_ahead,
                                          route_rows, scaled_observation, start_episode, step_range)
from roadload.presets import get_preset
from roadload.controllers.online import OnlineForceModel
from roadload.estimators.knowledge import knowledge_for_preset
from roadload.controllers.sim_plant import SimulatorPlant

__all__ = ["DriveScales", "EcoBatch", "EcoDriveEnv", "OBSERVATION_TYPES", "ObservationType", "PREVIEW_GRID",
           "RouteTable", "SHIELD_GAIN", "STOP_HORIZON", "cut_profile", "observation_factory", "observation_layout"]

FULL_BRAKE_DECELERATION = 0.5 * G
"""Deceleration [m/s^2] asked for by u = -1 (before resistances)."""
MIN_SCHEDULE_SPEED = 2.0
"""Lowest schedule speed [m/s] (very tight curves)."""

# fixed scales of the normalised observation (SI value / scale)
SCALE = {"v": 30.0, "a": 3.0, "grade": 0.05, "curvature": 0.01, "speed_limit": 30.0, "time_deficit": 60.0,
         "remaining": 1000.0, "next_stop": 1000.0, "u_prev": 1.0, "drive_torque": 300.0,
         "engine_speed": 600.0, "brake_pressure": 5.0e6, "mass": 1000.0, "c0": 200.0, "c2": 0.5}


# --------------------------------------------------------------------------------------------- action mapping
@dataclass(frozen=True)
class DriveScales:
    """Scales of the normalised wheel-force command: peak traction force F_peak [N] (max shaft torque in first
    gear at the wheels), peak drive power P_max [W] and the braking force of u = -1, FULL_BRAKE_DECELERATION * m_V
    [N] (about as strong as full traction, so that a zero-mean exploring policy does not mostly brake)."""

    peak_traction_force: float
    peak_power: float
    full_brake_force: float

    @classmethod
    def from_spec(cls, spec: VehicleSpec) -> "DriveScales":
        dt = spec.drivetrain
        ratio = dt.gear_ratios[0] * dt.final_drive / spec.tires.dynamic_radius
        if dt.kind == "bev":
            motor = dt.require_motor()
            torque, power = motor.max_torque, motor.max_power
        else:
            full_load = dt.require_engine().full_load
            x, y = np.asarray(full_load.x), np.asarray(full_load.y)
            torque, power = float(y.max()), float((x * y).max())
        return cls(float(torque * ratio), float(power), float(spec.body.mass * FULL_BRAKE_DECELERATION))

    def wheel_force(self, u: float, v: float) -> float:
        """Signed wheel-force request [N] for the normalised command u in [-1, 1] at speed v [m/s]."""
        if u >= 0.0:
            return u * min(self.peak_traction_force, self.peak_power / max(v, 1.0))
        return u * self.full_brake_force


# --------------------------------------------------------------------------------------------- the route
def cut_profile(profile: RoadProfile, length: float | None) -> RoadProfile:
    """The first ``length`` metres of a road profile (the whole profile for None)."""
    if length is None or length >= profile.length:
        if length is not None and length > profile.length + 1e-6:
            raise GymConfigError(f"route_length: {length:g} m is longer than road {profile.name!r} "
                                 f"({profile.length:g} m)")
        return profile
    d = profile.distance
    keep = d < length
    at = profile.at(length)
    return RoadProfile(name=f"{profile.name}[:{length:g}m]", distance=np.append(d[keep], length),
                       grade=np.append(profile.grade[keep], at["grade"]),
                       curvature=np.append(profile.curvature[keep], at["curvature"]),
                       bank=np.append(profile.bank[keep], at["bank"]),
                       speed_limit=np.append(profile.speed_limit[keep], at["speed_limit"]),
                       stops=profile.stops[profile.stops <= length], meta=dict(profile.meta))


class RouteTable:
    """A road profile resampled on a uniform grid for fast preview look-ups, plus the schedule.

    schedule speed v_ref(s) = max(MIN_SCHEDULE_SPEED, min(fraction * v_lim(s), sqrt(a_y,max / |kappa(s)|)));
    schedule time t_ref(s) = integral of ds / v_ref (stops not included).
    """

    GRADE, CURVATURE, SPEED_LIMIT, SCHEDULE = 0, 1, 2, 3

    def __init__(self, profile: RoadProfile, preview: np.ndarray, fraction: float, lateral_limit: float) -> None:
        self.length = profile.length
        self.preview = np.ascontiguousarray(preview, dtype=float)
        n = int(math.ceil((self.length + self.preview[-1]) / PREVIEW_GRID)) + 2
        s = np.arange(n) * PREVIEW_GRID
        at = profile.at(s)  # clamped beyond the end of the road
        with np.errstate(divide="ignore"):
            curve = np.sqrt(lateral_limit / np.abs(at["curvature"]))
        v_ref = np.maximum(MIN_SCHEDULE_SPEED, np.minimum(fraction * at["speed_limit"], curve))
        schedule = np.concatenate([[0.0], np.cumsum(0.5 * (1 / v_ref[1:] + 1 / v_ref[:-1]) * PREVIEW_GRID)])
        self.table = np.ascontiguousarray(np.vstack([at["grade"], at["curvature"], at["speed_limit"], schedule]))
        self.route_time = float(np.interp(self.length, s, schedule))
        self.stops = sorted(float(x) for x in profile.stops)
        self._out = np.zeros((4, self.preview.size))

    def braking_envelope(self, margin: float, deceleration: float) -> np.ndarray:
        """Highest speed [m/s] on the grid from which braking at ``deceleration`` [m/s^2] keeps the speed
        ``margin`` [m/s] under every speed limit ahead (the speed shield's envelope)."""
        out = np.empty(self.table.shape[1])
        braking_envelope(self.table[SPEED_LIMIT], PREVIEW_GRID, margin, deceleration, out)
        return out

    def look_ahead(self, s: float) -> np.ndarray:
        """(4, len(preview)) grade [rad], curvature [1/m], speed limit [m/s], schedule time [s] at s + preview
        (a view, overwritten by the next call)."""
        look_ahead(self.table, PREVIEW_GRID, self.preview, s, self._out)
        return self._out


# --------------------------------------------------------------------------------------------- observation types
CAN_CHANNELS = ("vehicle_speed", "accel_x", "drive_torque", "engine_speed", "brake_pressure_front")
ESTIMATE_NAMES = ("mass", "c0", "c2")
ObservationRow = tuple[str, str, float, float, float]


class ObservationType:
    """One observation mode of EcoDrive-v0 (highway-env's observation types are the model): its entries
    (name, SI unit, scale, low, high; low / high are the SI bounds the observation is clipped to) and how the single
    env builds it. Every mode ends with the same route rows (ecodrive_kernel.route_rows): grade, curvature and
    speed limit at s + preview, time deficit, remaining distance, next stop, previous command."""

    name = ""
    batched = False
    """True when the compiled step builds it (the native vector env batches only such a mode)."""

    def __init__(self, config: EcoDriveConfig) -> None:
        self.config = config
        points = (0.0, *config.preview_distances)
        self.layout: list[ObservationRow] = self.vehicle_rows() + [
            *((f"grade@{d:g}m", "rad", SCALE["grade"], -0.5, 0.5) for d in points),
            *((f"curvature@{d:g}m", "1/m", SCALE["curvature"], -1.0, 1.0) for d in points),
            *((f"speed_limit@{d:g}m", "m/s", SCALE["speed_limit"], 0.0, 100.0) for d in points),
            ("time_deficit", "s", SCALE["time_deficit"], -1e5, 1e5),
            ("remaining_distance", "m", SCALE["remaining"], 0.0, 1e6),
            ("next_stop_distance", "m", SCALE["next_stop"], 0.0, STOP_HORIZON),
            ("previous_command", "1", SCALE["u_prev"], -1.0, 1.0),
        ] + self.extra_rows()

    def vehicle_rows(self) -> list[ObservationRow]:
        """The entries before the route rows."""
        raise NotImplementedError

    def extra_rows(self) -> list[ObservationRow]:
        """The entries after the route rows."""
        return []

    def bounds(self) -> np.ndarray:
        """(3, n) scale, low / scale, high / scale of the entries (scale 1 with ``obs_scaling='si'``)."""
        scale = np.array([1.0 if self.config.obs_scaling == "si" else row[2] for row in self.layout])
        return np.vstack([scale, np.array([row[3] for row in self.layout]) / scale,
                          np.array([row[4] for row in self.layout]) / scale])

    def space(self) -> spaces.Box:
        b = self.bounds()
        return spaces.Box(b[1].astype(np.float32), b[2].astype(np.float32), shape=(len(self.layout),),
                          dtype=np.float32)

    def simulator(self, spec: VehicleSpec, profile: RoadProfile, cfg: EcoDriveConfig, seed: int) -> Simulator | None:
        """The episode's simulator when the mode needs its own (None: the env builds it)."""
        return None

    def start(self, env: EcoDriveEnv) -> None:
        """After the episode setup (reset)."""

    def update(self, env: EcoDriveEnv) -> None:
        """After a step (the new substeps are in the simulator's truth log)."""

    def observe(self, env: EcoDriveEnv) -> np.ndarray:
        """The observation now (float32)."""
        raise NotImplementedError


class StateObservation(ObservationType):
    """'state': true speed v [m/s] and acceleration a [m/s^2], then the route rows at the true position; built by
    the compiled step."""

    name = "state"
    batched = True

    def vehicle_rows(self) -> list[ObservationRow]:
        return [("v", "m/s", SCALE["v"], 0.0, 100.0), ("a", "m/s^2", SCALE["a"], -50.0, 50.0)]

    def observe(self, env: EcoDriveEnv) -> np.ndarray:
        return env.batch.obs[0].copy()


class CanObservation(ObservationType):
    """'can': the noisy CAN channels vehicle_speed [m/s], accel_x [m/s^2, incl. g sin(theta)], drive_torque [N m],
    engine_speed [rad/s], brake_pressure_front [Pa] (a dropout holds the last value), then the route rows at the
    position dead-reckoned from the CAN speed (what a controller without GNSS / map matching knows)."""

    name = "can"

    def vehicle_rows(self) -> list[ObservationRow]:
        return [("can_vehicle_speed", "m/s", SCALE["v"], -5.0, 100.0),
                ("can_accel_x", "m/s^2", SCALE["a"], -50.0, 50.0),
                ("can_drive_torque", "N*m", SCALE["drive_torque"], -5000.0, 5000.0),
                ("can_engine_speed", "rad/s", SCALE["engine_speed"], -100.0, 3000.0),
                ("can_brake_pressure_front", "Pa", SCALE["brake_pressure"], -1e6, 5e7)]

    def start(self, env: EcoDriveEnv) -> None:
        self.hold = np.zeros(len(CAN_CHANNELS))
        self.hold[0] = env.config.initial_speed
        self.position = 0.0
        self.sample: dict[str, float] | None = None

    def update(self, env: EcoDriveEnv) -> None:
        sample = env.simulator.observe()
        if sample is not None:
            for j, name in enumerate(CAN_CHANNELS):
                x = sample.get(name, 0.0)
                if x == x:  # NaN (dropout): hold the last valid value
                    self.hold[j] = x
        self.position += self.hold[0] * env.config.control_period
        self.sample = sample

    def fill(self, env: EcoDriveEnv, buf: np.ndarray) -> int:
        """The CAN channels and the route rows into buf; returns the index after them."""
        b = env.batch
        k = len(CAN_CHANNELS)
        buf[:k] = self.hold
        la = b.look_ahead[0]
        look_ahead(b.tables[0, :, :b.episodes[0]["table_points"]], PREVIEW_GRID, b.preview, self.position, la)
        route_rows(buf, k, la, env.simulator.vehicle_state.time, self.position, b.episodes[0], b.stops[0])
        return k + 3 * la.shape[1] + 4

    def observe(self, env: EcoDriveEnv) -> np.ndarray:
        buf = env.batch.obs_work[0]
        self.fill(env, buf)
        out = np.empty(buf.size, dtype=np.float32)
        scaled_observation(buf, env.batch.bounds, out)
        return out


class CanEstimatesObservation(CanObservation):
    """'can+estimates': 'can' plus the running estimates of mass [kg], c0 [N] and c2 [kg/m] of roadload's online
    force model (the chapter-5 pipeline + a catalogue estimator, model M4) on the episode's CAN samples."""

    name = "can+estimates"

    def extra_rows(self) -> list[ObservationRow]:
        return [("estimated_mass", "kg", SCALE["mass"], 0.0, 1e5), ("estimated_c0", "N", SCALE["c0"], -1e5, 1e5),
                ("estimated_c2", "kg/m", SCALE["c2"], -1e3, 1e3)]

    def simulator(self, spec: VehicleSpec, profile: RoadProfile, cfg: EcoDriveConfig, seed: int) -> Simulator:
        # the controllers' plant adapter owns the simulator: its can_window() feeds the online estimator the CAN
        # samples exactly as in the MPC's closed loop
        plant = SimulatorPlant(spec, profile, effects=cfg.effects, seed=seed, dt=cfg.control_period)
        self._can_window = plant.can_window
        return plant.sim

    def start(self, env: EcoDriveEnv) -> None:
        super().start(env)
        self.estimator = _make_online_estimator(env.config, self._can_window)

    def update(self, env: EcoDriveEnv) -> None:
        super().update(env)
        if self.sample is not None:
            self.estimator.observe(self.sample)

    def observe(self, env: EcoDriveEnv) -> np.ndarray:
        buf = env.batch.obs_work[0]
        k = self.fill(env, buf)
        p = self.estimator.parameters()
        buf[k:k + 3] = (p.mass, p.c0, p.c2)
        out = np.empty(buf.size, dtype=np.float32)
        scaled_observation(buf, env.batch.bounds, out)
        return out


OBSERVATION_TYPES: dict[str, type[ObservationType]] = {
    t.name: t for t in (StateObservation, CanObservation, CanEstimatesObservation)}
"""The observation modes by ``config.observation``."""


def observation_factory(config: EcoDriveConfig) -> ObservationType:
    """The observation type of ``config.observation``."""
    try:
        return OBSERVATION_TYPES[config.observation](config)
    except KeyError:
        raise GymConfigError(f"observation: expected one of {sorted(OBSERVATION_TYPES)}, got "
                             f"{config.observation!r}") from None


def observation_layout(config: EcoDriveConfig) -> list[ObservationRow]:
    """(name, SI unit, scale, low, high) of each observation entry, in order; low/high are the SI bounds the
    observation is clipped to (generous physical ranges)."""
    return observation_factory(config).layout


# --------------------------------------------------------------------------------------------- episodes in records
class EcoBatch:
    """N EcoDrive-v0 episodes in the packed records of the compiled step (:mod:`roadload.gym.ecodrive_kernel`): the
    single env holds one, the native vector env N. ``observation``: the type whose bounds the compiled 'state'
    observation uses. ``shared`` (N = 1): the fleet is the episode's simulator itself (Fleet.sharing), so its truth
    log, CAN sensors and ``to_trip()`` follow the steps; otherwise each episode's simulator is copied into a fleet
    slot (and not advanced itself)."""

    def __init__(self, n: int, config: EcoDriveConfig, observation: ObservationType, shared: bool = False) -> None:
        if shared and n != 1:
            raise GymConfigError("EcoBatch: a batch that shares its simulator holds one episode")
        self.n = n
        self.shared = shared
        self.bounds = observation.bounds()
        self.preview = np.array((0.0, *config.preview_distances))  # column 0 = at s: the speed limit
        n_obs = self.bounds.shape[1]
        self.episodes = np.zeros(n, EPISODE)
        self.settings = np.zeros(1, SETTINGS)
        self.tables = np.zeros((n, 4, 2))
        self.envelopes = np.full((n, 2), NO_SHIELD)
        self.stops = np.zeros((n, 1))
        self.look_ahead = np.zeros((n, 4, self.preview.size))
        self.obs_work = np.zeros((n, n_obs))
        self.obs = np.zeros((n, n_obs), dtype=np.float32)
        self.reward = np.zeros(n)
        self.terminated = np.zeros(n, dtype=bool)
        self.truncated = np.zeros(n, dtype=bool)
        self.fleet = None if shared else Fleet(n)
        self.fleet_shared: Fleet | None = None
        self.simulators: list[Simulator | None] = [None] * n
        self.routes: list[RouteTable | None] = [None] * n
        self.profiles: list[RoadProfile | None] = [None] * n
        self._keys: list[tuple | None] = [None] * n
        self._templates: dict[tuple, Simulator] = {}  # per vehicle and effects: the simulator new roads start from
        self._observation = observation
        self._records: EcoRecords | None = None

    # ------------------------------------------------------------------ episode setup
    def setup(self, i: int, cfg: EcoDriveConfig, road_seed: int, sim_seed: int) -> None:
        """Sub-env i starts an episode of ``cfg`` on road seed ``road_seed`` with simulator seed ``sim_seed``:
        the road, simulator and route table are built when they changed, else the simulator is reset; then the
        records, the start look-ahead, observation and info."""
        key = (cfg.vehicle, cfg.road, road_seed, cfg.route_length, repr(cfg.effects), cfg.preview_distances,
               cfg.schedule_speed_fraction, cfg.lateral_acceleration_limit)
        if key != self._keys[i]:
            self._new_route(i, cfg, key, road_seed, sim_seed)
        else:
            self._simulator(i).reset(seed=sim_seed, initial_speed=cfg.initial_speed)
        sim, route = self._simulator(i), self.routes[i]
        if route is None:
            raise GymConfigError(f"sub-env {i}: no episode set up (its first setup failed)")
        if self.fleet is not None:
            self.fleet.load(i, sim)
        else:
            self.fleet_shared = Fleet.sharing(sim)
        self._settings(cfg, sim.vehicle)
        e = self.episodes[i]
        nt = route.table.shape[1]
        e["table_points"] = nt
        e["stop_count"] = len(route.stops)
        self._grow("envelopes", nt, NO_SHIELD)[i] = NO_SHIELD
        if cfg.speed_shield:
            self.envelopes[i, :nt] = route.braking_envelope(cfg.shield_margin, cfg.shield_deceleration)
        for name in ("speed_limit", "previous_command", "previous_acceleration", "last_source_energy"):
            e[name] = 0.0
        e["return_costs"] = 0.0
        e["time_limit"] = cfg.time_limit if cfg.time_limit is not None else 2.0 * route.route_time + 30.0
        e["route_length"] = route.length
        e["route_time"] = route.route_time
        start_episode(i, self.fleet_records(), self.records, self._outputs(np.empty((N_INFO, self.n)),
                                                                            np.empty((2, self.n), dtype=np.int64)))

    def _new_route(self, i: int, cfg: EcoDriveConfig, key: tuple, road_seed: int, sim_seed: int) -> None:
        """Road, simulator (a fresh one for the first episode of a vehicle and effects, else that one moved to the
        new road: the same state, bit for bit, without packing the vehicle again) and route table of sub-env i."""
        try:
            loaded = load_profile_start(cfg.road, cfg.route_length, seed=road_seed)
            if not isinstance(loaded, RoadProfile):
                raise GymConfigError(f"road: {cfg.road!r} is not a road profile")
            profile = cut_profile(loaded, cfg.route_length)
            spec = get_preset(cfg.vehicle)
            sim = self._observation.simulator(spec, profile, cfg, sim_seed)
            if sim is None:
                sim = self._simulator_on(spec, profile, cfg, sim_seed)
        except GymConfigError:
            raise
        except ValueError as exc:  # RoadProfileError, SimulationError, EffectsError, VehicleSpecError
            raise GymConfigError(f"cannot build the episode: {exc}") from exc
        route = RouteTable(profile, self.preview, cfg.schedule_speed_fraction, cfg.lateral_acceleration_limit)
        self.simulators[i], self.routes[i], self.profiles[i], self._keys[i] = sim, route, profile, key
        self.episodes[i]["road_seed"] = road_seed
        nt = route.table.shape[1]
        self._grow("tables", nt)[i, :, :nt] = route.table
        stops = np.asarray(route.stops, dtype=float)
        self._grow("stops", max(stops.size, 1))[i, :stops.size] = stops

    def _simulator_on(self, spec: VehicleSpec, profile: RoadProfile, cfg: EcoDriveConfig, seed: int) -> Simulator:
        template = self._templates.get((cfg.vehicle, repr(cfg.effects)))
        if template is not None:
            return template.on_road(profile, seed, cfg.initial_speed)
        sim = Simulator(spec, profile, cfg.effects, None, seed, initial_speed=cfg.initial_speed,
                        log_capacity=(1 << 14) if self.shared else cfg.n_substeps)
        self._templates[(cfg.vehicle, repr(cfg.effects))] = sim
        return sim

    def _settings(self, cfg: EcoDriveConfig, spec: VehicleSpec) -> None:
        """The shared settings: reward weights, control period, limits, substeps and the vehicle's drive scales."""
        st = self.settings[0]
        w = cfg.reward
        st["weights"] = (w.energy, w.time, w.speeding, w.lateral, w.stop, w.jerk, w.progress, w.scale)
        st["control_period"] = cfg.control_period
        st["lateral_limit"] = cfg.lateral_acceleration_limit
        st["stop_speed"] = cfg.stop_speed
        st["n_substeps"] = cfg.n_substeps
        drive = DriveScales.from_spec(spec)
        st["peak_traction_force"] = drive.peak_traction_force
        st["peak_power"] = drive.peak_power
        st["full_brake_force"] = drive.full_brake_force

    def _grow(self, name: str, width: int, fill: float = 0.0) -> np.ndarray:
        arr = getattr(self, name)
        if arr.shape[-1] < width:
            new = np.full(arr.shape[:-1] + (width,), fill, dtype=arr.dtype)
            new[..., :arr.shape[-1]] = arr
            setattr(self, name, new)
            self._records = None
            arr = new
        return arr

    def _simulator(self, i: int) -> Simulator:
        sim = self.simulators[i]
        if sim is None:
            raise GymConfigError(f"sub-env {i}: no episode set up (its first setup failed)")
        return sim

    # ------------------------------------------------------------------ records and steps
    @property
    def records(self) -> EcoRecords:
        """The episode records of the compiled step (rebuilt when an array grew)."""
        if self._records is None:
            self._records = EcoRecords(self.episodes, self.settings, self.tables, self.envelopes, self.stops,
                                       self.preview, self.bounds, self.look_ahead, self.obs_work)
        return self._records

    def fleet_records(self) -> FleetRecords:
        """The vehicles' records (the shared simulator's own arrays for a shared batch)."""
        fleet = self.fleet if self.fleet is not None else self.fleet_shared
        if fleet is None:
            raise GymConfigError("EcoDrive: no episode set up (its first setup failed)")
        return fleet.records

    def _outputs(self, info: np.ndarray, ints: np.ndarray) -> EcoOutputs:
        return EcoOutputs(self.obs, self.reward, self.terminated, self.truncated, info, ints)

    def step(self, active: np.ndarray, u: np.ndarray, stepper: Callable[..., None] | None = None
             ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """One compiled step of the active sub-envs with commands u (float64 (n,)); the others idle. Returns
        (reward, terminated, truncated, info block, integer info block), fresh arrays. ``stepper``: a kernel with
        step_range's arguments after (lo, hi) (the vector env's threaded one)."""
        n = self.n
        reward = np.empty(n)
        term = np.empty(n, dtype=bool)
        trunc = np.empty(n, dtype=bool)
        info = np.empty((N_INFO, n))
        ints = np.empty((2, n), dtype=np.int64)
        if self.shared:
            self._simulator(0).reserve_log(int(self.settings[0]["n_substeps"]))
        out = EcoOutputs(self.obs, reward, term, trunc, info, ints)
        if stepper is None:
            step_range(0, n, active, u, self.fleet_records(), self.records, out)
        else:
            stepper(active, u, self.fleet_records(), self.records, out)
        return reward, term, trunc, info, ints

    def info_blocks(self) -> tuple[np.ndarray, np.ndarray]:
        """(info block, integer info block) of every sub-env now, without terms (the info of reset())."""
        info = np.empty((N_INFO, self.n))
        ints = np.empty((2, self.n), dtype=np.int64)
        gather_info_all(self.fleet_records(), self.records, self._outputs(info, ints))
        return info, ints


def info_of(info: np.ndarray, ints: np.ndarray, i: int, with_terms: bool) -> dict[str, Any]:
    """The single env's info dict of column i of the info blocks: t, s, v, a [SI], gear, speed_limit, total source
    energy [J], road seed, route length [m], schedule time [s], return costs; terms and costs after a step."""
    col, icol = info[:, i].tolist(), ints[:, i].tolist()
    out: dict[str, Any] = {k: (col[r] if r >= 0 else icol[-1 - r]) for k, r in INFO_ROWS}
    out["return_costs"] = dict(zip(COST_NAMES, col[I_RETURN:I_RETURN + N_COSTS]))
    if with_terms:
        out["terms"] = dict(zip(COST_NAMES, col[I_TERMS:I_TERMS + N_COSTS]))
        out["costs"] = dict(zip(COST_NAMES, col[I_COSTS:I_COSTS + N_COSTS]))
    return out


# --------------------------------------------------------------------------------------------- the env
class EcoDriveEnv(gym.Env):
    """Eco-driving along a road profile (module docstring). Build with ``gymnasium.make("roadload/EcoDrive-v0",
    config={...})`` or keyword overrides (``vehicle="gt_rwd"``); ``reset(options={...})`` changes road,
    vehicle, effects, reward weights and the other fields that do not shape the spaces."""

    metadata = {"render_modes": ["rgb_array"], "render_fps": 10}

    def __init__(self, config: EcoDriveConfig | dict | None = None, render_mode: str | None = None,
                 **overrides: Any) -> None:
        super().__init__()
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise GymConfigError(f"render_mode: EcoDrive-v0 renders only 'rgb_array', got {render_mode!r}")
        self.render_mode = render_mode
        self.config: EcoDriveConfig = make_config(EcoDriveConfig, config, **overrides)
        self.observation_type = observation_factory(self.config)
        self.layout = self.observation_type.layout
        self.observation_space = self.observation_type.space()
        self.action_space = spaces.Box(-1.0, 1.0, shape=(1,), dtype=np.float32)
        self.batch = EcoBatch(1, self.config, self.observation_type, shared=True)
        self._active = np.ones(1, dtype=bool)
        # build once now so that a bad road / vehicle / effect fails at construction, not mid-episode
        self._setup(self.config, road_seed=self.config.road_seed if self.config.road_seed is not None
                    else self.config.road_seed_range[0], sim_seed=0)

    def _setup(self, cfg: EcoDriveConfig, road_seed: int, sim_seed: int) -> None:
        self.batch.setup(0, cfg, road_seed, sim_seed)
        self._state = self.simulator.state
        self.observation_type.start(self)

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        super().reset(seed=seed)
        cfg = updated_config(self.config, options, SPACE_FIELDS_ECODRIVE)
        road_seed = (cfg.road_seed if cfg.road_seed is not None
                     else int(self.np_random.integers(*cfg.road_seed_range)))
        sim_seed = int(self.np_random.integers(0, 2 ** 31 - 1))
        self.config = self.observation_type.config = cfg
        self._setup(cfg, road_seed, sim_seed)
        info, ints = self.batch.info_blocks()
        return self.observation_type.observe(self), info_of(info, ints, 0, with_terms=False)

    def step(self, action):
        u = np.array([validate_action(action, self.action_space)[0]], dtype=np.float64)
        reward, term, trunc, info, ints = self.batch.step(self._active, u)
        # no warning when |a_y| > 4 m/s^2 (the simulator's, once per episode): the env penalises lateral excess
        # above its comfort limit and reports it in info['terms'] instead
        self._state = self.simulator.refresh(warn=False)
        self.observation_type.update(self)
        return (self.observation_type.observe(self), float(reward[0]), bool(term[0]), bool(trunc[0]),
                info_of(info, ints, 0, with_terms=True))

    def render(self) -> np.ndarray | None:
        """rgb_array (H=160, W=480, uint8): the elevation of the next 500 m (grey band: this metre's speed limit
        colour-coded), the vehicle (red), a speed bar (blue) against the limit (black tick). Pure numpy, headless."""
        if self.render_mode != "rgb_array":
            return None
        h, w_px, ahead = 160, 480, 500.0
        img = np.full((h, w_px, 3), 255, dtype=np.uint8)
        st = self._state
        profile = self.route
        elevation = profile.elevation()
        xs = st.s - 50.0 + np.arange(w_px) * ((ahead + 50.0) / w_px)
        elev = np.interp(np.clip(xs, 0.0, profile.length), profile.distance, elevation)
        e0 = float(np.interp(st.s, profile.distance, elevation))
        rows = np.clip((100 - (elev - e0) * 2.0).astype(int), 20, h - 1)
        for x in range(w_px):
            img[rows[x]:, x] = (200, 200, 200)
        cx = int(50.0 / (ahead + 50.0) * w_px)
        cy = int(np.clip(100 - 0 * 2.0, 20, h - 1))
        img[max(cy - 8, 0):cy, max(cx - 6, 0):cx + 6] = (220, 30, 30)
        bar = int(min(st.v / 50.0, 1.0) * (w_px - 20))
        img[5:13, 10:10 + bar] = (40, 80, 220)
        lim = int(min(self.batch.episodes[0]["speed_limit"] / 50.0, 1.0) * (w_px - 20))
        img[2:16, 10 + lim:12 + lim] = 0
        return img

    # ------------------------------------------------------------------ access for evaluation
    @property
    def simulator(self) -> Simulator:
        """The simulator of the current episode (e.g. ``true_parameters()``, ``to_trip()``)."""
        sim = self.batch.simulators[0]
        if sim is None:
            raise GymConfigError("EcoDrive: no simulator (the episode setup failed; see the error it raised)")
        return sim

    @property
    def route(self) -> RoadProfile:
        """The road profile of the current episode (cut to route_length)."""
        profile = self.batch.profiles[0]
        if profile is None:
            raise GymConfigError("EcoDrive: no route (the episode setup failed; see the error it raised)")
        return profile


def _make_online_estimator(cfg: EcoDriveConfig, can_window: Callable[[float], Any]) -> OnlineForceModel:
    """The running estimator of observation mode 'can+estimates': roadload.controllers' online force model (the
    chapter-5 pipeline + a catalog estimator, model M4) on the episode's CAN samples, updated every 10 s."""
    try:
        model = OnlineForceModel(knowledge_for_preset(cfg.vehicle), model="M4", estimator=cfg.estimator)
    except ValueError as exc:
        raise GymConfigError(f"estimator: {exc}") from exc
    model.attach(can_window)
    return model
