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
kept (:func:`ego_road`, least recently used dropped beyond ROAD_CACHE_SIZE); an episode start resets that road's
simulator with the episode's noise seed and copies it into the ego's fleet slot.
"""

from __future__ import annotations

from collections import OrderedDict
from dataclasses import dataclass
from typing import Any, NamedTuple

import numpy as np

from roadload.envs import Simulator
from roadload.envs.batch import (Fleet, FleetRecords, advance_vehicle, command_wheel_force, dependent_jit, state_of,
                                 vehicle_done)
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
    built = EgoRoad(int(road_seed), profile, sim, RouteTable(profile, PREVIEW, 1.0, 2.0))
    _ROADS[key] = built
    while len(_ROADS) > ROAD_CACHE_SIZE:
        _ROADS.popitem(last=False)
    return built


# --------------------------------------------------------------------------------------------- the batch
class EgoRecords(NamedTuple):
    """The egos' arrays as the compiled kernels take them: the fields of the fleet's records (FleetRecords, in its
    order: the batch-step functions read them by name, and a parallel numba loop cannot take a record array
    nested one tuple deeper), then the drive scales and each ego's preview table."""

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
    """(n, rows, points) preview table of each ego's road (RouteTable.table), zero-padded."""
    table_n: np.ndarray
    """(n,) points of each ego's preview table."""


if EgoRecords._fields[:len(FleetRecords._fields)] != FleetRecords._fields:
    raise ImportError(f"EgoRecords must start with FleetRecords' fields {FleetRecords._fields}")


class EgoBatch:
    """n egos, vehicle i of a :class:`Fleet` each, on the roads of :func:`ego_road`; one vehicle preset for all.
    ``records`` are the compiled kernels' argument."""

    def __init__(self, n: int, vehicle: str) -> None:
        self.n = n
        self.vehicle = vehicle
        drive = DriveScales.from_spec(get_preset(vehicle))
        self.drive_scales = np.array([drive.peak_traction_force, drive.peak_power, drive.full_brake_force])
        self.fleet = Fleet(n)  # no truth log: the env reads the state only
        self.table = np.zeros((n, 4, 2))
        self.table_n = np.zeros(n, dtype=np.int64)
        self.roads: list[EgoRoad | None] = [None] * n
        self._started = False
        self._records: EgoRecords | None = None
        self._fleet_records: FleetRecords | None = None

    def start(self, i: int, road: EgoRoad, noise_seed: int) -> None:
        """Ego i at the start of ``road`` (its simulator reset with ``noise_seed``, the effects' random stream, and
        copied into slot i), with that road's preview table."""
        sim = road.simulator
        try:
            sim.reset(seed=int(noise_seed))
            self.fleet.load(i, sim)
        except ValueError as exc:  # SimulationError
            raise GymConfigError(f"cannot start the ego on road {road.road_seed}: {exc}") from exc
        nt = road.route.table.shape[1]
        if self.table.shape[2] < nt:
            grown = np.zeros(self.table.shape[:2] + (nt,))
            grown[..., :self.table.shape[2]] = self.table
            self.table = grown
            self._records = None
        self.table[i, :, :nt] = road.route.table
        self.table_n[i] = nt
        self.roads[i] = road
        self._started = True

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
            self._records = EgoRecords(*fleet, self.drive_scales, self.table, self.table_n)
            self._fleet_records = fleet
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
    command_wheel_force(ego, i, wheel_force(u, state_of(ego, i).speed, ego.drive), np.nan)
    advance_vehicle(ego, i, n_sub)


@kernel(forceinline=True)
def ego_state(ego, i):
    """(t [s], s [m], v [m/s], a [m/s^2], source energy [J], mass [kg], climbing work m g h [J], gear,
    engine / motor speed [rad/s]) of ego i."""
    x = state_of(ego, i)
    return (x.time, x.position, x.speed, x.acceleration, x.source_energy, x.mass, x.climbing_work, x.gear,
            x.engine_speed)


@kernel(forceinline=True)
def ego_at_road_end(ego, i):
    """Whether ego i has reached the end of its road (its episode is truncated there)."""
    return vehicle_done(ego, i)


@kernel(forceinline=True)
def ego_look_ahead(ego, i, preview, s, out):
    """The preview table of ego i's road (grade, curvature, ...: RouteTable rows) at s + preview -> out."""
    look_ahead(ego.table[i, :, :ego.table_n[i]], PREVIEW_GRID, preview, s, out)


def describe(batch: EgoBatch, i: int) -> dict[str, Any]:
    """The ego's state as named SI values (for info and tests)."""
    t, s, v, a, e, m, w, gear, omega = (float(x) for x in ego_state(batch.records, i))
    return {"t": t, "s": s, "v": v, "a": a, "source_energy_total": e, "mass": m, "climbing_work": w,
            "gear": int(gear), "engine_speed": omega}
