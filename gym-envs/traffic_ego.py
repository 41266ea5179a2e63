"""The ego vehicle of ``roadload/EcoTraffic-v0``: roadload's compiled powertrain and road, batched.

Each sub-env's ego is one roadload simulator (``roadload.envs.physics``, the jitted 100 Hz core: drive-train,
brakes, resistances, grade, curvature through the single-track model and cornering resistance) held as per-vehicle
rows of flat arrays, as the native EcoDrive vector env holds its vehicles; :func:`ego_advance` runs n substeps of
one row under a signed wheel-force command from inside the traffic kernel, the ``ego_*`` readers give the state
the traffic model and the reward need. This module is the only place the traffic env touches the simulator's
packed layout.

Roads: the ego's road for a road seed is EcoHighway-v0's (:func:`ego_road_profile`): the first
``road_length`` metres of the road profile with that seed, its speed limit set to the lane limit, its curvature
and bank kept (``curvature=True``) or zeroed (straight, as EcoHighway-v0). Building one takes ~5 ms (profile
generation, packing, the preview table), a hundred times a traffic reset, so each is built once per process and
kept (:func:`ego_road`, least recently used dropped beyond ROAD_CACHE_SIZE).
"""

from __future__ import annotations

from collections import OrderedDict
from dataclasses import dataclass
from typing import Any, NamedTuple

import numpy as np

from roadload.envs import physics
from roadload.envs._jit import dependent_jit
from roadload.envs.layout import (C_GEAR_REQ, C_STEER, C_TRACTION, C_USE_DRIVER, N_CMD, N_LOG, N_ROAD, N_STATE,
                                  S_A, S_E_SOURCE, S_GEAR, S_MASS, S_NLOG, S_OMEGA_E, S_POS, S_T, S_V, S_W_CLIMB,
                                  P_ROAD_LEN)
from roadload.envs.simulator import Simulator
from roadload.presets import get_preset
from roadload.road_profiles import RoadProfile, load_profile_start

from roadload.gym.config import EcoTrafficConfig, GymConfigError
from roadload.gym import ecodrive as _ecodrive
from roadload.gym.ecodrive import PREVIEW_GRID, DriveScales, RouteTable, cut_profile
from roadload.gym.ecodrive import _look_ahead as look_ahead

kernel = dependent_jit(__file__, _ecodrive.__file__)

PREVIEW = np.array([0.0, 100.0, 200.0])
"""Distances ahead of the ego [m] at which the observation reports grade and curvature."""
ROAD_CACHE_SIZE = 512
"""Built ego roads kept per process (~0.15 MB each)."""



# --------------------------------------------------------------------------------------------- roads
def ego_road_profile(road: str | None, length: float, seed: int, speed_limit: float,
                     curvature: bool) -> RoadProfile:
    """The ego's road (module docstring): the first ``length`` m [m] of profile ``road`` with ``seed`` (None: flat),
    extended flat to ``length``, speed limit ``speed_limit`` [m/s] throughout, curvature [1/m] and bank [rad]
    kept when ``curvature`` else zero."""
    if road is None:
        s = np.array([0.0, length])
        grade = kappa = bank = np.zeros(2)
    else:
        prof = load_profile_start(road, length, seed=seed)
        if not isinstance(prof, RoadProfile):
            raise GymConfigError(f"road: {road!r} is not a road profile")
        prof = cut_profile(prof, min(length, prof.length))
        s, grade, kappa, bank = prof.distance, prof.grade, prof.curvature, prof.bank
        if s[-1] < length:  # extend flat and straight
            s, grade = np.append(s, length), np.append(grade, 0.0)
            kappa, bank = np.append(kappa, 0.0), np.append(bank, 0.0)
    if not curvature:
        kappa = np.zeros_like(s)
        bank = np.zeros_like(s)
    kind = "traffic" if curvature else "highway"
    return RoadProfile(name=f"{kind}:{road or 'flat'}", distance=s, grade=grade, curvature=kappa, bank=bank,
                       speed_limit=np.full_like(s, speed_limit))


@dataclass(frozen=True)
class EgoRoad:
    """One built road of the ego: the simulator on it (reset at the initial speed: its state is every episode's
    start), and the preview table."""

    road_seed: int
    profile: RoadProfile
    simulator: Simulator
    start_state: np.ndarray
    route: RouteTable


_TEMPLATES: dict[tuple, Simulator] = {}
_ROADS: OrderedDict[tuple, EgoRoad] = OrderedDict()


def _check_batchable(sim: Simulator) -> None:
    if sim._schedules.active:
        raise GymConfigError("effects: time-varying (scheduled) effects are not batched by EcoTraffic-v0's "
                             "compiled step; leave them out")
    if sim.effects.enabled("poor_excitation"):
        raise GymConfigError("effects: 'poor_excitation' re-plans the road per seed, which EcoTraffic-v0's cached "
                             "roads do not; leave it out")


def road_key(cfg: EcoTrafficConfig) -> tuple:
    """What the ego's road depends on besides the road seed (the first part of the cache key)."""
    return (cfg.vehicle, repr(cfg.effects), cfg.road, cfg.road_length, cfg.curvature, cfg.speed_limit,
            cfg.initial_speed)


def ego_road(cfg: EcoTrafficConfig, road_seed: int, base_key: tuple | None = None) -> EgoRoad:
    """The ego's road for ``road_seed`` under ``cfg`` (built on first use, then cached; module docstring);
    ``base_key`` = road_key(cfg) when the caller has it."""
    key = (base_key or road_key(cfg), road_seed)
    hit = _ROADS.get(key)
    if hit is not None:
        _ROADS.move_to_end(key)
        return hit
    try:
        profile = ego_road_profile(cfg.road, cfg.road_length, int(road_seed), cfg.speed_limit, cfg.curvature)
        tkey = (cfg.vehicle, repr(cfg.effects))
        template = _TEMPLATES.get(tkey)
        if template is None:
            template = Simulator(get_preset(cfg.vehicle), profile, cfg.effects, None, 0,
                                 initial_speed=cfg.initial_speed, log_capacity=1)
            _check_batchable(template)
            _TEMPLATES[tkey] = template
        sim = template.on_road(profile, 0, cfg.initial_speed)
    except GymConfigError:
        raise
    except ValueError as exc:
        raise GymConfigError(f"cannot build the ego vehicle: {exc}") from exc
    built = EgoRoad(int(road_seed), profile, sim, sim.X.copy(), RouteTable(profile, PREVIEW, 1.0, 2.0))
    _ROADS[key] = built
    while len(_ROADS) > ROAD_CACHE_SIZE:
        _ROADS.popitem(last=False)
    return built


# --------------------------------------------------------------------------------------------- the batch
class RoadPool:
    """The built roads one batch uses, packed side by side (a slot each) so that a reset points a sub-env at a
    slot instead of copying ~150 kB: the simulator parameters P, the road and stop arrays and the preview table of
    each road (the core only reads them). Slots nobody uses are reused, least recently released
    first, once ``max_slots`` are filled."""

    def __init__(self, max_slots: int) -> None:
        self.max_slots = max_slots
        self.P = np.zeros((0, 1))
        self.road = np.zeros((0, N_ROAD, 2))
        self.road_n = np.zeros(0, dtype=np.int64)
        self.stops = np.zeros((0, 1))
        self.stops_n = np.zeros(0, dtype=np.int64)
        self.table = np.zeros((0, 4, 2))
        self.table_n = np.zeros(0, dtype=np.int64)
        self.tabs: np.ndarray | None = None
        self.ti: np.ndarray | None = None
        self.roads: list[EgoRoad] = []
        self._slot: dict[int, int] = {}  # id(EgoRoad) -> slot
        self._users: list[int] = []
        self._free: OrderedDict[int, None] = OrderedDict()  # unused slots, least recently released first
        self.version = 0  # bumped whenever an array is reallocated (the kernels' argument tuples are rebuilt)

    def _grow(self, name: str, rows: int, width: int | None) -> None:
        arr = getattr(self, name)
        shape = list(arr.shape)
        need_rows = rows > shape[0]
        need_width = width is not None and width > shape[-1]
        if not (need_rows or need_width):
            return
        if need_rows:  # room for twice as many roads: packing n roads copies O(n) rows, not O(n^2)
            shape[0] = min(max(rows, 2 * shape[0], 8), self.max_slots)
        if width is not None:
            shape[-1] = max(shape[-1], width)
        new = np.zeros(tuple(shape), dtype=arr.dtype)
        new[tuple(slice(0, k) for k in arr.shape)] = arr
        setattr(self, name, new)
        self.version += 1

    def acquire(self, road: EgoRoad) -> int:
        """The slot holding ``road`` (packed on first use), counted as used once more."""
        slot = self._slot.get(id(road))
        if slot is None or self.roads[slot] is not road:
            slot = self._place(road)
        if self._users[slot] == 0:
            self._free.pop(slot, None)
        self._users[slot] += 1
        return slot

    def release(self, slot: int) -> None:
        self._users[slot] -= 1
        if self._users[slot] == 0:
            self._free[slot] = None

    def _place(self, road: EgoRoad) -> int:
        if len(self.roads) < self.max_slots:
            slot = len(self.roads)
            self.roads.append(road)
            self._users.append(0)
        elif self._free:
            slot, _ = self._free.popitem(last=False)
            self._slot.pop(id(self.roads[slot]), None)
            self.roads[slot] = road
        else:
            raise GymConfigError(f"the batch's road pool is full ({self.max_slots} roads in use)")
        sim = road.simulator
        if self.tabs is None:
            self.tabs, self.ti = sim.tabs, sim.ti
        rows = slot + 1
        nr, ns, nt = sim._road.shape[1], sim._stops.size, road.route.table.shape[1]
        for name, width in (("P", sim.P.size), ("road", nr), ("road_n", None),
                            ("stops", max(ns, 1)), ("stops_n", None), ("table", nt), ("table_n", None)):
            self._grow(name, rows, width)
        self.P[slot] = 0.0
        self.P[slot, :sim.P.size] = sim.P
        self.road[slot, :, :nr] = sim._road
        self.road_n[slot] = nr
        self.stops[slot, :ns] = sim._stops
        self.stops_n[slot] = ns
        self.table[slot, :, :nt] = road.route.table
        self.table_n[slot] = nt
        self._slot[id(road)] = slot
        return slot


class EgoRecords(NamedTuple):
    """The egos' arrays as the compiled kernels take them: per-ego state, pool slot, effect-noise stream, command
    and (empty) truth log; the drive scales; the road pool (simulator parameters, drive-train tables,
    roads, stops, preview tables)."""

    X: np.ndarray
    slot: np.ndarray
    rng: np.ndarray
    cmd: np.ndarray
    log: np.ndarray
    cycle: np.ndarray
    drive: np.ndarray
    """(peak traction force [N], peak power [W], full brake force [N]) of the vehicle (DriveScales)."""
    P: np.ndarray
    tabs: np.ndarray
    ti: np.ndarray
    road: np.ndarray
    road_n: np.ndarray
    stops: np.ndarray
    stops_n: np.ndarray
    table: np.ndarray
    table_n: np.ndarray


class EgoBatch:
    """n egos (rows of the state, command and random-stream arrays), each on a road of the batch's
    :class:`RoadPool` (``slot``); one vehicle preset for all. ``records`` are the compiled kernels' argument."""

    def __init__(self, n: int, vehicle: str) -> None:
        self.n = n
        self.vehicle = vehicle
        drive = DriveScales.from_spec(get_preset(vehicle))
        self.drive_scales = np.array([drive.peak_traction_force, drive.peak_power, drive.full_brake_force])
        self.pool = RoadPool(max(512, 2 * n))
        self.X = np.zeros((n, N_STATE))
        self.slot = np.full(n, -1, dtype=np.int64)
        self.rng = np.zeros((n, 1), dtype=np.uint64)
        self.cmd = np.zeros((n, N_CMD))
        # a truth log of no rows: the env reads the state, never the log (the core skips the row when it is full)
        self.log = np.zeros((n, N_LOG, 0))
        self.cycle = np.zeros((2, 2))
        self.cycle[0, 1] = 1.0
        self._records: EgoRecords | None = None
        self._version = -1

    def start(self, i: int, road: EgoRoad, noise_seed: int) -> None:
        """Row i at the start of ``road`` (its pool slot and the start state), the effects' random stream seeded
        with ``noise_seed``."""
        old = int(self.slot[i])
        new = self.pool.acquire(road)
        if old >= 0:
            self.pool.release(old)
        self.slot[i] = new
        self.X[i] = road.start_state
        self.rng[i, 0] = np.uint64(noise_seed)
        self.cmd[i] = 0.0

    def loaded(self, i: int) -> EgoRoad:
        slot = int(self.slot[i])
        if slot < 0:
            raise GymConfigError(f"sub-env {i}: no episode set up (call reset first)")
        return self.pool.roads[slot]

    @property
    def records(self) -> EgoRecords:
        pool = self.pool
        if self._records is None or self._version != pool.version:
            if pool.tabs is None or pool.ti is None:
                raise GymConfigError("no ego loaded yet (call reset first)")
            self._records = EgoRecords(self.X, self.slot, self.rng, self.cmd, self.log, self.cycle, self.drive_scales,
                                       pool.P, pool.tabs, pool.ti, pool.road, pool.road_n, pool.stops, pool.stops_n,
                                       pool.table, pool.table_n)
            self._version = pool.version
        return self._records


# --------------------------------------------------------------------------------------------- compiled access
@kernel(forceinline=True)
def wheel_force(u, v, F):
    """The signed wheel-force request [N] of the normalised command u in [-1, 1] at speed v [m/s]
    (DriveScales.wheel_force; F = (peak traction force [N], peak power [W], full brake force [N]))."""
    return u * min(F[0], F[1] / max(v, 1.0)) if u >= 0.0 else u * F[2]


@kernel()
def ego_advance(ego, i, u, n_sub):
    """n_sub substeps (10 ms each) of ego i under the wheel force of the normalised command u at its current
    speed (regen first, friction brakes for the rest), the built-in steering law keeping it on its road's
    curvature."""
    x = ego.X[i]
    c = ego.cmd[i]
    c[C_USE_DRIVER] = 2.0
    c[C_TRACTION] = wheel_force(u, x[S_V], ego.drive)
    c[C_STEER] = np.nan
    c[C_GEAR_REQ] = -1.0
    x[S_NLOG] = 0.0
    k = ego.slot[i]
    physics.advance(x, ego.P[k], ego.tabs, ego.ti, ego.road[k, :, :ego.road_n[k]], ego.stops[k, :ego.stops_n[k]],
                    ego.cycle, ego.rng[i], c, ego.log[i], n_sub)


@kernel(forceinline=True)
def ego_state(ego, i):
    """(t [s], s [m], v [m/s], a [m/s^2], source energy [J], mass [kg], climbing work m g h [J], gear,
    engine / motor speed [rad/s]) of ego i."""
    x = ego.X[i]
    return x[S_T], x[S_POS], x[S_V], x[S_A], x[S_E_SOURCE], x[S_MASS], x[S_W_CLIMB], x[S_GEAR], x[S_OMEGA_E]


@kernel(forceinline=True)
def ego_at_road_end(ego, i):
    """Whether ego i has reached the end of its road (its episode is truncated there)."""
    return ego.X[i, S_POS] >= ego.P[ego.slot[i], P_ROAD_LEN] - 1e-6


@kernel(forceinline=True)
def ego_look_ahead(ego, i, preview, s, out):
    """The preview table of ego i's road (grade, curvature, ...: RouteTable rows) at s + preview -> out."""
    k = ego.slot[i]
    look_ahead(ego.table[k, :, :ego.table_n[k]], PREVIEW_GRID, preview, s, out)


def describe(batch: EgoBatch, i: int) -> dict[str, Any]:
    """The ego's state as named SI values (for info and tests)."""
    t, s, v, a, e, m, w, gear, omega = (float(x) for x in ego_state(batch.records, i))
    return {"t": t, "s": s, "v": v, "a": a, "source_energy_total": e, "mass": m, "climbing_work": w,
            "gear": int(gear), "engine_speed": omega}
