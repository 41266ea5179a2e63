"""``roadload/EcoDrive-v0``: drive a vehicle preset along a road profile with preview, minimising source energy
and time (gymnasium env on top of :class:`roadload.envs.simulator.Simulator`).

Action: ``u`` in [-1, 1] (Box, shape (1,)), a normalised wheel-force command held for one control period
(default 0.1 s = 10 physics steps at 100 Hz). u >= 0 asks for traction u * min(F_peak, P_max / max(v, 1 m/s));
u < 0 asks for a braking force |u| * 0.5 m_V g, which the simulator splits regen first, friction brakes for the rest
(its default allocator). The drive-train clips the request to what it can deliver in the current gear.

Speed shield (``speed_shield=True``, off by default): before it is applied, the command is capped at
SHIELD_GAIN * (v_env(s) - v), where v_env is the braking envelope of the speed limits ahead lowered by
``shield_margin`` (:meth:`RouteTable.braking_envelope`). The capped command is what the vehicle gets and what
``previous_command`` reports.

Observation: see :data:`OBSERVATION_DOC` (built by :func:`observation_layout`) and the README table. Every entry is
an SI value divided by a fixed scale (``obs_scaling='normalized'``, default) or the raw SI value (``'si'``).

Reward: ``-scale * (energy + time * dt + speeding * (v - v_lim)+ dt + lateral * (|a_y| - a_y,max)+ dt
+ stop * [stop line crossed faster than stop_speed] + jerk * jerk^2 dt - progress * ds)`` with ds the metres
driven along the route in the step (potential-based shaping; see EcoDriveReward); each raw term is in
``info['terms']`` and each weighted term (J-equivalent) in ``info['costs']``, so users can re-weight.
Terminates when the route's end is reached, truncates at the time limit.
"""

from __future__ import annotations

import bisect
import math
import warnings
from dataclasses import dataclass
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces
from numba import njit

from roadload.road_profiles import RoadProfile, load_profile_start
from roadload.units import G
from roadload.vehicle import VehicleSpec

from roadload.gym.actions import validate_action
from roadload.gym.config import (SPACE_FIELDS_ECODRIVE, EcoDriveConfig, GymConfigError, make_config, updated_config)
from roadload.presets import get_preset
from roadload.envs.simulator import LateralValidityWarning, Simulator
from roadload.controllers.online import OnlineForceModel
from roadload.estimators.knowledge import knowledge_for_preset
from roadload.controllers.sim_plant import SimulatorPlant

FULL_BRAKE_DECELERATION = 0.5 * G
"""Deceleration [m/s^2] asked for by u = -1 (before resistances)."""
PREVIEW_GRID = 1.0
"""Resolution [m] of the resampled route table the preview reads."""
MIN_SCHEDULE_SPEED = 2.0
"""Lowest schedule speed [m/s] (very tight curves)."""
STOP_HORIZON = 1000.0
"""Distance to the next stop is reported up to this value [m] (= 'no stop ahead')."""

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


@njit(inline="always", cache=True)
def _grid_cell(x, n):
    """Grid position x (in grid steps) clamped to [0, n - 1.001] -> (cell index i, fraction f in [0, 1))."""
    if x < 0.0:
        x = 0.0
    elif x > n - 1.001:
        x = n - 1.001
    i = int(x)
    return i, x - i


@njit(cache=True)
def _look_ahead(table, grid, points, s, out):
    """Linear interpolation of every row of ``table`` (uniform grid step ``grid`` [m]) at s + points -> out."""
    n = table.shape[1]
    for j in range(points.size):
        i, f = _grid_cell((s + points[j]) / grid, n)
        for r in range(table.shape[0]):
            out[r, j] = table[r, i] * (1.0 - f) + table[r, i + 1] * f


SHIELD_GAIN = 2.0
"""Gain of the speed shield [1/(m/s)]: the command is capped at SHIELD_GAIN * (v_envelope - v)."""


@njit(cache=True)
def _braking_envelope(limit, grid, margin, decel, out):
    """Backward pass: out[k] = min over y >= x_k of sqrt((v_lim(y) - margin)^2 + 2 decel (y - x_k)) on the grid."""
    n = limit.size
    nxt = max(limit[n - 1] - margin, 0.0)
    out[n - 1] = nxt
    for k in range(n - 2, -1, -1):
        own = max(limit[k] - margin, 0.0)
        reach = math.sqrt(nxt * nxt + 2.0 * decel * grid)
        nxt = own if own < reach else reach
        out[k] = nxt


@njit(cache=True)
def shield_command(envelope, n, s, v, u):
    """The speed shield: the command u capped at SHIELD_GAIN * (v_env(s) - v), clipped to [-1, 1], with v_env the
    braking envelope (RouteTable.braking_envelope, first n grid points) linearly interpolated at s [m], v [m/s]."""
    i, f = _grid_cell(s / PREVIEW_GRID, n)
    cap = SHIELD_GAIN * (envelope[i] * (1.0 - f) + envelope[i + 1] * f - v)
    if cap < -1.0:
        cap = -1.0
    return u if u < cap else cap


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
        self._zero = np.zeros(1)
        self._one = np.zeros((4, 1))

    def braking_envelope(self, margin: float, deceleration: float) -> np.ndarray:
        """Highest speed [m/s] on the grid from which braking at ``deceleration`` [m/s^2] keeps the speed
        ``margin`` [m/s] under every speed limit ahead (the speed shield's envelope)."""
        out = np.empty(self.table.shape[1])
        _braking_envelope(self.table[self.SPEED_LIMIT], PREVIEW_GRID, margin, deceleration, out)
        return out

    def look_ahead(self, s: float) -> np.ndarray:
        """(4, len(preview)) grade [rad], curvature [1/m], speed limit [m/s], schedule time [s] at s + preview
        (a view, overwritten by the next call)."""
        _look_ahead(self.table, PREVIEW_GRID, self.preview, s, self._out)
        return self._out

    def at(self, s: float) -> np.ndarray:
        """(4,) grade, curvature, speed limit, schedule time at s (a view, overwritten by the next call)."""
        _look_ahead(self.table, PREVIEW_GRID, self._zero, s, self._one)
        return self._one[:, 0]

    def next_stop(self, s: float) -> float:
        """Distance [m] to the next stop line at or ahead of s (STOP_HORIZON when none within it)."""
        k = bisect.bisect_left(self.stops, s)
        if k >= len(self.stops):
            return STOP_HORIZON
        return min(self.stops[k] - s, STOP_HORIZON)

    def stops_crossed(self, s0: float, s1: float) -> list[float]:
        """Stop lines with s0 < stop <= s1."""
        return self.stops[bisect.bisect_right(self.stops, s0):bisect.bisect_right(self.stops, s1)]


# --------------------------------------------------------------------------------------------- observation layout
CAN_CHANNELS = ("vehicle_speed", "accel_x", "drive_torque", "engine_speed", "brake_pressure_front")
ESTIMATE_NAMES = ("mass", "c0", "c2")


def observation_layout(config: EcoDriveConfig) -> list[tuple[str, str, float, float, float]]:
    """(name, SI unit, scale, low, high) of each observation entry, in order; low/high are the SI bounds the
    observation is clipped to (generous physical ranges)."""
    points = (0.0, *config.preview_distances)
    if config.observation == "state":
        rows = [("v", "m/s", SCALE["v"], 0.0, 100.0), ("a", "m/s^2", SCALE["a"], -50.0, 50.0)]
    else:
        rows = [("can_vehicle_speed", "m/s", SCALE["v"], -5.0, 100.0),
                ("can_accel_x", "m/s^2", SCALE["a"], -50.0, 50.0),
                ("can_drive_torque", "N*m", SCALE["drive_torque"], -5000.0, 5000.0),
                ("can_engine_speed", "rad/s", SCALE["engine_speed"], -100.0, 3000.0),
                ("can_brake_pressure_front", "Pa", SCALE["brake_pressure"], -1e6, 5e7)]
    rows += [(f"grade@{d:g}m", "rad", SCALE["grade"], -0.5, 0.5) for d in points]
    rows += [(f"curvature@{d:g}m", "1/m", SCALE["curvature"], -1.0, 1.0) for d in points]
    rows += [(f"speed_limit@{d:g}m", "m/s", SCALE["speed_limit"], 0.0, 100.0) for d in points]
    rows += [("time_deficit", "s", SCALE["time_deficit"], -1e5, 1e5),
             ("remaining_distance", "m", SCALE["remaining"], 0.0, 1e6),
             ("next_stop_distance", "m", SCALE["next_stop"], 0.0, STOP_HORIZON),
             ("previous_command", "1", SCALE["u_prev"], -1.0, 1.0)]
    if config.observation == "can+estimates":
        rows += [("estimated_mass", "kg", SCALE["mass"], 0.0, 1e5), ("estimated_c0", "N", SCALE["c0"], -1e5, 1e5),
                 ("estimated_c2", "kg/m", SCALE["c2"], -1e3, 1e3)]
    return rows


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
        self.layout = observation_layout(self.config)
        n_obs = len(self.layout)
        self._scale = np.array([1.0 if self.config.obs_scaling == "si" else row[2] for row in self.layout])
        self._low = np.array([row[3] for row in self.layout]) / self._scale
        self._high = np.array([row[4] for row in self.layout]) / self._scale
        self.observation_space = spaces.Box(self._low.astype(np.float32), self._high.astype(np.float32),
                                            shape=(n_obs,), dtype=np.float32)
        self.action_space = spaces.Box(-1.0, 1.0, shape=(1,), dtype=np.float32)
        self._sim: Simulator | None = None
        self._sim_key: tuple | None = None
        self._estimator: OnlineForceModel | None = None  # observation mode 'can+estimates' only
        # build once now so that a bad road / vehicle / effect fails at construction, not mid-episode
        self._setup(self.config, road_seed=self.config.road_seed if self.config.road_seed is not None
                    else self.config.road_seed_range[0], sim_seed=0)

    # ------------------------------------------------------------------ episode setup
    def _setup(self, cfg: EcoDriveConfig, road_seed: int, sim_seed: int) -> None:
        key = (cfg.vehicle, cfg.road, road_seed, cfg.route_length, repr(cfg.effects), cfg.preview_distances,
               cfg.schedule_speed_fraction, cfg.lateral_acceleration_limit)
        if key != self._sim_key:
            try:
                loaded = load_profile_start(cfg.road, cfg.route_length, seed=road_seed)
                if not isinstance(loaded, RoadProfile):
                    raise GymConfigError(f"road: {cfg.road!r} is not a road profile")
                profile = cut_profile(loaded, cfg.route_length)
                spec = get_preset(cfg.vehicle)
                self._can_window = None
                if cfg.observation == "can+estimates":
                    # the controllers' plant adapter owns the simulator here: its can_window() feeds the online
                    # estimator the CAN samples exactly as in the MPC's closed loop
                    plant = SimulatorPlant(spec, profile, effects=cfg.effects, seed=sim_seed, dt=cfg.control_period)
                    self._sim, self._can_window = plant.sim, plant.can_window
                else:
                    self._sim = Simulator(spec, profile, cfg.effects, None, sim_seed,
                                          initial_speed=cfg.initial_speed)
            except GymConfigError:
                raise
            except ValueError as exc:  # RoadProfileError, SimulationError, EffectsError, VehicleSpecError
                raise GymConfigError(f"cannot build the episode: {exc}") from exc
            self._spec = spec
            self._profile = profile
            self._route = RouteTable(profile, np.array((0.0, *cfg.preview_distances)), cfg.schedule_speed_fraction,
                                     cfg.lateral_acceleration_limit)
            self._drive = DriveScales.from_spec(spec)
            self._elevation = profile.elevation()
            self._sim_key = key
            self._road_seed = road_seed
        self._time_limit = (cfg.time_limit if cfg.time_limit is not None
                            else 2.0 * self._route.route_time + 30.0)
        self._state = self.simulator.reset(seed=sim_seed, initial_speed=cfg.initial_speed)
        if cfg.observation == "can+estimates":
            self._estimator = _make_online_estimator(cfg, self._can_window)
        self._dt = cfg.control_period
        self._n_sub = cfg.n_substeps
        self._u_prev = 0.0
        self._a_prev = 0.0
        self._s_hat = 0.0
        self._can = None
        self._can_hold = np.zeros(len(CAN_CHANNELS))
        self._can_hold[0] = cfg.initial_speed
        self._return_costs = dict.fromkeys(("energy", "time", "speeding", "lateral", "stop", "jerk", "progress"),
                                           0.0)
        self._limit = float(self._route.at(self._state.s)[RouteTable.SPEED_LIMIT])
        self._obs_buf = np.zeros(len(self.layout))
        self._envelope = (self._route.braking_envelope(cfg.shield_margin, cfg.shield_deceleration)
                          if cfg.speed_shield else None)

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        super().reset(seed=seed)
        cfg = updated_config(self.config, options, SPACE_FIELDS_ECODRIVE)
        road_seed = (cfg.road_seed if cfg.road_seed is not None
                     else int(self.np_random.integers(*cfg.road_seed_range)))
        sim_seed = int(self.np_random.integers(0, 2 ** 31 - 1))
        self.config = cfg
        self._setup(cfg, road_seed, sim_seed)
        return self._observe(), self._info()

    # ------------------------------------------------------------------ step
    def step(self, action):
        u = float(validate_action(action, self.action_space)[0])
        u = -1.0 if u < -1.0 else (1.0 if u > 1.0 else u)
        cfg = self.config
        w = cfg.reward
        st0 = self._state
        if self._envelope is not None:
            u = float(shield_command(self._envelope, self._envelope.size, st0.s, st0.v, u))
        limit0 = self._limit
        force = self._drive.wheel_force(u, st0.v)
        with warnings.catch_warnings():
            # the simulator warns (once per episode) when |a_y| > 4 m/s^2; the env penalises lateral excess
            # above its comfort limit and reports it in info['terms'] instead
            warnings.simplefilter("ignore", LateralValidityWarning)
            st = self._sim.step(force, self._n_sub)
        self._state = st
        self._limit = float(self._route.at(st.s)[RouteTable.SPEED_LIMIT])
        dt = self._dt
        if cfg.observation != "state":
            self._update_can()
        # raw terms
        speeding = max(0.0, 0.5 * (st0.v + st.v - limit0 - self._limit)) * dt
        lateral = max(0.0, abs(st.lateral_acceleration) - cfg.lateral_acceleration_limit) * dt
        stop = 0.0
        for s_stop in self._route.stops_crossed(st0.s, st.s):
            frac = (s_stop - st0.s) / max(st.s - st0.s, 1e-9)
            if st0.v + frac * (st.v - st0.v) > cfg.stop_speed:
                stop += 1.0
        jerk = (st.a - self._a_prev) / dt
        terminated = bool(st.s >= self._route.length - 1e-6)
        truncated = bool(not terminated and st.t >= self._time_limit - 1e-9)
        progress = min(st.s, self._route.length) - min(st0.s, self._route.length)
        energy = float(st.source_energy)
        terms = {"energy": energy, "time": dt, "speeding": speeding, "lateral": lateral, "stop": stop,
                 "jerk": jerk * jerk * dt, "progress": progress}
        costs = {"energy": w.energy * energy, "time": w.time * dt, "speeding": w.speeding * speeding,
                 "lateral": w.lateral * lateral, "stop": w.stop * stop, "jerk": w.jerk * terms["jerk"],
                 "progress": -w.progress * progress}
        total = 0.0
        acc = self._return_costs
        for k, c in costs.items():
            total += c
            acc[k] += c
        self._u_prev = u
        self._a_prev = float(st.a)
        info = self._info()
        info["terms"] = terms
        info["costs"] = costs
        return self._observe(), -w.scale * total, terminated, truncated, info

    def _update_can(self) -> None:
        sample = self.simulator.observe()
        hold = self._can_hold
        if sample is not None:
            for j, name in enumerate(CAN_CHANNELS):
                x = sample.get(name, 0.0)
                if x == x:  # NaN (dropout): hold the last valid value
                    hold[j] = x
        # dead-reckoned position from the CAN speed: what a controller without GNSS/map matching knows
        self._s_hat += hold[0] * self._dt
        if self._estimator is not None and sample is not None:
            self._estimator.observe(sample)

    # ------------------------------------------------------------------ observation / info
    def _observe(self) -> np.ndarray:
        cfg = self.config
        st = self._state
        buf = self._obs_buf
        if cfg.observation == "state":
            s = st.s
            buf[0] = st.v
            buf[1] = st.a
            k = 2
        else:
            s = self._s_hat
            k = len(CAN_CHANNELS)
            buf[:k] = self._can_hold
        la = self._route.look_ahead(s)
        m = la.shape[1]
        buf[k:k + 3 * m] = la[:3].ravel()
        k += 3 * m
        buf[k] = st.t - la[RouteTable.SCHEDULE, 0]
        buf[k + 1] = max(self._route.length - s, 0.0)
        buf[k + 2] = self._route.next_stop(s)
        buf[k + 3] = self._u_prev
        if cfg.observation == "can+estimates":
            if self._estimator is None:
                raise GymConfigError("observation 'can+estimates': no online estimator yet (call reset() first)")
            p = self._estimator.parameters()
            buf[k + 4:k + 7] = (p.mass, p.c0, p.c2)
        obs = buf / self._scale
        np.clip(obs, self._low, self._high, out=obs)
        return obs.astype(np.float32)

    def _info(self) -> dict[str, Any]:
        st = self._state
        return {"t": float(st.t), "s": float(st.s), "v": float(st.v), "a": float(st.a), "gear": st.gear,
                "speed_limit": self._limit, "source_energy_total": float(st.source_energy_total),
                "road_seed": self._road_seed, "route_length": self._route.length,
                "schedule_time": self._route.route_time, "return_costs": dict(self._return_costs)}

    def render(self) -> np.ndarray | None:
        """rgb_array (H=160, W=480, uint8): the elevation of the next 500 m (grey band: this metre's speed limit
        colour-coded), the vehicle (red), a speed bar (blue) against the limit (black tick). Pure numpy, headless."""
        if self.render_mode != "rgb_array":
            return None
        h, w_px, ahead = 160, 480, 500.0
        img = np.full((h, w_px, 3), 255, dtype=np.uint8)
        st = self._state
        xs = st.s - 50.0 + np.arange(w_px) * ((ahead + 50.0) / w_px)
        elev = np.interp(np.clip(xs, 0.0, self._route.length), self._profile.distance, self._elevation)
        e0 = float(np.interp(st.s, self._profile.distance, self._elevation))
        rows = np.clip((100 - (elev - e0) * 2.0).astype(int), 20, h - 1)
        for x in range(w_px):
            img[rows[x]:, x] = (200, 200, 200)
        cx = int(50.0 / (ahead + 50.0) * w_px)
        cy = int(np.clip(100 - 0 * 2.0, 20, h - 1))
        img[max(cy - 8, 0):cy, max(cx - 6, 0):cx + 6] = (220, 30, 30)
        bar = int(min(st.v / 50.0, 1.0) * (w_px - 20))
        img[5:13, 10:10 + bar] = (40, 80, 220)
        lim = int(min(self._limit / 50.0, 1.0) * (w_px - 20))
        img[2:16, 10 + lim:12 + lim] = 0
        return img

    # ------------------------------------------------------------------ access for evaluation
    @property
    def simulator(self) -> Simulator:
        """The simulator of the current episode (e.g. ``true_parameters()``, ``to_trip()``)."""
        if self._sim is None:
            raise GymConfigError("EcoDrive: no simulator (the episode setup failed; see the error it raised)")
        return self._sim

    @property
    def route(self) -> RoadProfile:
        """The road profile of the current episode (cut to route_length)."""
        return self._profile


def _make_online_estimator(cfg: EcoDriveConfig, can_window) -> OnlineForceModel:
    """The running estimator of observation mode 'can+estimates': roadload.controllers' online force model (the
    chapter-5 pipeline + a catalog estimator, model M4) on the episode's CAN samples, updated every 10 s."""

    try:
        model = OnlineForceModel(knowledge_for_preset(cfg.vehicle), model="M4", estimator=cfg.estimator)
    except ValueError as exc:
        raise GymConfigError(f"estimator: {exc}") from exc
    model.attach(can_window)
    return model
