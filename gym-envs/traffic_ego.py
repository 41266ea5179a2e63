"""The ego vehicle of ``roadload/EcoTraffic-v0``: roadload's compiled powertrain and road, batched.

Each sub-env's ego is one vehicle of a :class:`roadload.envs.batch.Fleet` (the simulator's jitted 100 Hz core:
drive-train, brakes, resistances, grade, curvature through the single-track model and cornering resistance), as
the native EcoDrive vector env holds its vehicles; :func:`ego_advance` runs n substeps of one vehicle under a
signed wheel-force command from inside the traffic kernel, the ``ego_*`` readers give the state the traffic model
and the reward need (the compiled batch-step API: command_wheel_force, advance_vehicle, state_of).

Roads: the ego's road for a road seed is EcoHighway-v0's (:func:`ego_road_profile`): the first
``road_length`` metres of the road profile with that seed, its speed limit set to the lane limit, its curvature
and bank kept (``curvature=True``) or zeroed (straight, as EcoHighway-v0). Building one takes ~5 ms (profile
generation, packing, the preview table), a hundred times a traffic reset, so each is built once per process and
kept (:func:`ego_road`, least recently used dropped beyond ROAD_CACHE_SIZE). An episode start is compiled: each
road's simulator, as reset, is packed once into the batch's bank of episode starts (roadload.envs.batch.FleetStarts)
and :func:`start_ego` copies it into the ego's fleet slot with the random state of the episode's noise seed (the
record ``Simulator.reset(seed)`` followed by ``Fleet.load`` gives, bit for bit).
"""

from __future__ import annotations

from collections import OrderedDict
from dataclasses import dataclass
from typing import Any, NamedTuple

import numpy as np

from roadload.envs import Simulator
from roadload.envs.batch import (Fleet, FleetRecords, FleetStarts, advance_vehicle, command_wheel_force,
                                 dependent_jit, effects_random_state, start_vehicle, state_of, vehicle_done)
from roadload.presets import get_preset
from roadload.road_profiles import RoadProfile, load_profile_start

from roadload.gym import ecodrive_kernel as _ecodrive_kernel
from roadload.gym.config import EcoTrafficConfig, GymConfigError
from roadload.gym.ecodrive import DriveScales, RouteTable, cut_profile
from roadload.gym.ecodrive_kernel import PREVIEW_GRID, look_ahead

kernel = dependent_jit(__file__, _ecodrive_kernel.__file__)

PREVIEW = np.array([0.0, 100.0, 200.0])
"""Distances ahead of the ego [m] at which the observation reports grade and curvature."""
ROAD_CACHE_SIZE = 512
"""Built ego roads kept per process (~0.15 MB each)."""
BANK_SIZE = 128
"""Roads an EgoBatch's bank keeps at least before it is rebuilt (~0.15 MB each; at least twice the batch size)."""



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
    """One built road of the ego: the simulator on it (reset with each episode's noise seed, then copied into the
    ego's fleet slot), and the preview table."""

    road_seed: int
    profile: RoadProfile
    simulator: Simulator
    route: RouteTable
    key: tuple
    """The road's cache key (road_key(cfg), road_seed)."""


_TEMPLATES: dict[tuple, Simulator] = {}
_ROADS: OrderedDict[tuple, EgoRoad] = OrderedDict()


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
            _TEMPLATES[tkey] = template
        sim = template.on_road(profile, 0, cfg.initial_speed)
    except GymConfigError:
        raise
    except ValueError as exc:
        raise GymConfigError(f"cannot build the ego vehicle: {exc}") from exc
    built = EgoRoad(int(road_seed), profile, sim, RouteTable(profile, PREVIEW, 1.0, 2.0), key)
    _ROADS[key] = built
    while len(_ROADS) > ROAD_CACHE_SIZE:
        _ROADS.popitem(last=False)
    return built


# --------------------------------------------------------------------------------------------- the batch
class EgoRecords(NamedTuple):
    """The egos' arrays as the compiled kernels take them: the fields of the fleet's records (FleetRecords, in its
    order: the batch-step functions read them by name, and a parallel numba loop cannot take a record array
    nested one tuple deeper), then the drive scales and the preview tables of the batch's roads."""

    vehicles: np.ndarray
    table_values: np.ndarray
    table_index: np.ndarray
    roads: np.ndarray
    stops: np.ndarray
    cycle: np.ndarray
    log: np.ndarray
    drive: np.ndarray
    """(peak traction force [N], peak power [W], full brake force [N]) of the vehicle (DriveScales)."""
    table: np.ndarray
    """(roads, rows, points) preview table of each road of the batch's bank (RouteTable.table), zero-padded."""
    table_n: np.ndarray
    """(roads,) points of each preview table."""
    table_slot: np.ndarray
    """(n,) the bank row of each ego's road."""


if EgoRecords._fields[:len(FleetRecords._fields)] != FleetRecords._fields:
    raise ImportError(f"EgoRecords must start with FleetRecords' fields {FleetRecords._fields}")


class EgoBatch:
    """n egos, vehicle i of a :class:`Fleet` each, on the roads of :func:`ego_road`; one vehicle preset for all.
    ``records`` are the compiled kernels' argument.

    The roads the batch has driven form its bank: row k holds a road's episode start (FleetStarts: the simulator's
    packed vehicle as reset, its road rows) and its preview table, so that an episode start is one compiled copy
    (:func:`start_ego`) instead of a Python ``Simulator.reset`` (~0.3-0.6 ms). The bank keeps at most
    ``bank_limit`` roads: beyond, it is rebuilt from the roads the egos are on."""

    def __init__(self, n: int, vehicle: str) -> None:
        self.n = n
        self.vehicle = vehicle
        drive = DriveScales.from_spec(get_preset(vehicle))
        self.drive_scales = np.array([drive.peak_traction_force, drive.peak_power, drive.full_brake_force])
        self.fleet = Fleet(n)  # no truth log: the env reads the state only
        self.starts = FleetStarts(self.fleet)
        self.bank_limit = max(BANK_SIZE, 2 * n)
        self._bank: dict[tuple, tuple[int, int]] = {}  # road key -> (bank row, start row; -1: started in Python)
        self.table = np.zeros((4, 4, 2))
        self.table_n = np.zeros(4, dtype=np.int64)
        self.table_slot = np.zeros(n, dtype=np.int64)
        self.roads: list[EgoRoad | None] = [None] * n
        self._started = False
        self._records: EgoRecords | None = None
        self._fleet_records: FleetRecords | None = None

    def prepare(self, index: list[int], roads: list[EgoRoad], noise_seeds: list[int]) -> tuple[np.ndarray, np.ndarray]:
        """Egos ``index`` onto ``roads`` with the effects' noise seeds: (start row of each, -1 where the ego was
        already started here (a road that depends on the seed: Simulator.reset and Fleet.load); the effects' random
        state of each), for :func:`start_ego`."""
        if len(self._bank) + len(index) > self.bank_limit:
            self._rebuild_bank()
        rows = np.empty(len(index), dtype=np.int64)
        states = np.zeros(len(index), dtype=np.uint64)
        for r, (i, road, seed) in enumerate(zip(index, roads, noise_seeds)):
            row, start = self._bank_row(road)
            self.table_slot[i] = row
            self.roads[i] = road
            rows[r] = start
            if start >= 0:
                states[r] = effects_random_state(seed)
                continue
            try:
                road.simulator.reset(seed=int(seed))
                self.fleet.load(i, road.simulator)
            except ValueError as exc:  # SimulationError
                raise GymConfigError(f"cannot start the ego on road {road.road_seed}: {exc}") from exc
        self._started = True
        return rows, states

    def _bank_row(self, road: EgoRoad) -> tuple[int, int]:
        """(bank row, start row) of ``road``, added to the bank on first use."""
        hit = self._bank.get(road.key)
        if hit is not None:
            return hit
        row = len(self._bank)
        nt = road.route.table.shape[1]
        if row == self.table.shape[0] or self.table.shape[2] < nt:
            grown = np.zeros((max(self.table.shape[0], 2 * row), self.table.shape[1], max(self.table.shape[2], nt)))
            grown[:self.table.shape[0], :, :self.table.shape[2]] = self.table
            self.table = grown
            self.table_n = np.concatenate([self.table_n, np.zeros(grown.shape[0] - self.table_n.size, np.int64)])
            self._records = None
        self.table[row, :, :nt] = road.route.table
        self.table_n[row] = nt
        try:
            start = -1 if road.simulator.road_depends_on_seed else self.starts.add(road.simulator)
        except ValueError as exc:  # SimulationError
            raise GymConfigError(f"cannot start the ego on road {road.road_seed}: {exc}") from exc
        self._bank[road.key] = (row, start)
        return row, start

    def _rebuild_bank(self) -> None:
        """The bank with only the roads the egos are on (rows renumbered)."""
        self._bank.clear()
        self.starts.clear()
        for i, road in enumerate(self.roads):
            if road is not None:
                self.table_slot[i] = self._bank_row(road)[0]

    def loaded(self, i: int) -> EgoRoad:
        road = self.roads[i]
        if road is None:
            raise GymConfigError(f"sub-env {i}: no episode set up (call reset first)")
        return road

    @property
    def records(self) -> EgoRecords:
        if not self._started:  # (not roads.count(None): that compares every EgoRoad with None, each step)
            raise GymConfigError("no ego loaded yet (call reset first)")
        fleet = self.fleet.records  # the same object until a load grew an array
        if self._records is None or self._fleet_records is not fleet:
            self._records = EgoRecords(*fleet, self.drive_scales, self.table, self.table_n, self.table_slot)
            self._fleet_records = fleet
        return self._records


# --------------------------------------------------------------------------------------------- compiled access
@kernel(forceinline=True, refcount=False)
def wheel_force(u, v, F):
    """The signed wheel-force request [N] of the normalised command u in [-1, 1] at speed v [m/s]
    (DriveScales.wheel_force; F = (peak traction force [N], peak power [W], full brake force [N]))."""
    return u * min(F[0], F[1] / max(v, 1.0)) if u >= 0.0 else u * F[2]


@kernel(forceinline=True, refcount=False)
def ego_advance(ego, i, u, n_sub):
    """n_sub substeps (10 ms each) of ego i under the wheel force of the normalised command u at its current
    speed (regen first, friction brakes for the rest), the built-in steering law keeping it on its road's
    curvature."""
    command_wheel_force(ego, i, wheel_force(u, state_of(ego, i).speed, ego.drive), np.nan)
    advance_vehicle(ego, i, n_sub)


@kernel(forceinline=True, refcount=False)
def ego_state(ego, i):
    """(t [s], s [m], v [m/s], a [m/s^2], source energy [J], mass [kg], climbing work m g h [J], gear,
    engine / motor speed [rad/s]) of ego i."""
    x = state_of(ego, i)
    return (x.time, x.position, x.speed, x.acceleration, x.source_energy, x.mass, x.climbing_work, x.gear,
            x.engine_speed)


@kernel(forceinline=True, refcount=False)
def ego_at_road_end(ego, i):
    """Whether ego i has reached the end of its road (its episode is truncated there)."""
    return vehicle_done(ego, i)


@kernel(forceinline=True, refcount=False)
def ego_look_ahead(ego, i, preview, s, out):
    """The preview table of ego i's road (grade, curvature, ...: RouteTable rows) at s + preview -> out."""
    k = ego.table_slot[i]
    look_ahead(ego.table[k, :, :ego.table_n[k]], PREVIEW_GRID, preview, s, out)


@kernel(forceinline=True, refcount=False)
def start_ego(ego, i, starts, row, random_state):
    """Ego i at the start of its road (start ``row`` of the bank's FleetStarts records, with the effects' random
    state; row -1: already started in Python, EgoBatch.prepare)."""
    if row >= 0:
        start_vehicle(ego, i, starts, row, random_state)


def describe(batch: EgoBatch, i: int) -> dict[str, Any]:
    """The ego's state as named SI values (for info and tests)."""
    t, s, v, a, e, m, w, gear, omega = (float(x) for x in ego_state(batch.records, i))
    return {"t": t, "s": s, "v": v, "a": a, "source_energy_total": e, "mass": m, "climbing_work": w,
            "gear": int(gear), "engine_speed": omega}
