"""The compiled batch step: N vehicles of the simulator advanced from another numba kernel, through packed records.

A kernel outside ``roadload.envs`` (a native gym environment, a traffic model whose ego vehicles run roadload's
drive-train and road) advances vehicles with the simulator's own compiled core -- the same physics, bit for bit,
as :class:`roadload.envs.Simulator` -- without knowing how the core stores its state: it sets a command, advances,
and reads named fields of the vehicle's state record.

Python side::

    fleet = Fleet(n_vehicles)                       # empty slots; log_capacity=0: no truth log (the state only)
    fleet.load(i, Simulator(vehicle, road, effects, seed=s, initial_speed=v0))  # slot i <- that simulator
    records = fleet.records                         # FleetRecords: pass it to your compiled kernel
    fleet.state(i).speed                            # typed Python view of slot i (VehicleState)
    starts = FleetStarts(fleet); k = starts.add(simulator)   # packed episode starts (a simulator as reset)

Compiled side (from Python, or from a kernel whose numba cache follows the core's sources: ``kernel =
dependent_jit(__file__)``, then ``@kernel()`` / ``@kernel(parallel=True)`` on each kernel)::

    command_wheel_force(records, i, force, steer)   # signed wheel force [N], steer [rad] (NaN: built-in steering)
    advance_vehicle(records, i, n_substeps)         # n_substeps x SUBSTEP_SECONDS with the command held
    st = state_of(records, i)                       # the state record: st.speed [m/s], st.position [m], ...
    start_vehicle(records, i, starts.records, k, effects_random_state(seed))  # = reset(seed) + load, compiled

Every vehicle of one fleet is the same vehicle spec (the drive-train tables are shared); roads, effects, driver
settings, seeds and states differ per slot. ``load`` may grow the fleet's arrays (a longer road than any before):
read ``fleet.records`` again after it. A slot's vehicle is advanced in place; ``load`` copies the simulator's
packed vehicle and state, so the simulator itself does not move.

State record fields (read in a compiled kernel as ``state_of(records, i).<name>``; all float64, SI):

    time [s], position [m] (distance along the road), speed [m/s] (>= 0), acceleration [m/s^2] (this substep),
    gear [-] (0 neutral, 1..n), engine_speed [rad/s] (engine / motor), engine_torque [N m], clutch_torque [N m],
    lateral_acceleration [m/s^2], side_slip_angle [rad], yaw_rate [rad/s], wheel_steer_angle [rad],
    lateral_offset [m] and heading_error [rad] (to the road centre line), mass [kg] (m_V incl. payload),
    brake_pressure_front / brake_pressure_rear [Pa], state_of_charge [-] (BEV), oil_temperature [K],
    brake_disc_temperature [K], drag_area_factor [-];
    energy ledger since the start [J]: source_energy (fuel or battery), shaft_work, gearbox_loss,
    differential_loss, clutch_loss, brake_loss, rolling_loss, aero_loss, cornering_loss, climbing_work,
    payload_potential_energy.

Commands (held until the next command): ``command_wheel_force`` -- a signed wheel force, traction when >= 0,
regeneration first and friction brakes for the rest when < 0 (the default allocator of ``Simulator.step(float)``),
automatic gears; ``command_forces`` -- traction, regen and friction brake forces [N, >= 0] and a gear request
(-1: shift strategy, 0: neutral / sailing), as ``Simulator.step(Action(...))``; ``command_driver`` -- the
built-in driver. ``SUBSTEP_SECONDS`` = 0.01 s is the physics step.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from . import physics
from ._jit import dependent_jit, jit
from .numerics import asin_small, atan_small, cos_small, sin_small, tan_small  # libm-exact, for kernels outside envs
from .layout import COMMAND_DRIVER, COMMAND_FORCES, COMMAND_WHEEL_FORCE, N_LOG, N_ROAD, VEHICLE, Route, Tables
from .simulator import SimulationError, Simulator, effects_random_state
from .state import VehicleState

SUBSTEP_SECONDS = 0.01
"""Physics step [s] (100 Hz): ``advance_vehicle(records, i, n)`` moves vehicle i by n x 0.01 s."""


class FleetRecords(NamedTuple):
    """The packed records of a :class:`Fleet`, the one argument the compiled functions of this module take besides
    the vehicle index. Its arrays are the fleet's own (no copy); treat the fields as opaque and read a vehicle's
    state through :func:`state_of`."""

    vehicles: np.ndarray
    """(N,) vehicle records: state, parameters, command, road and stop counts."""
    table_values: np.ndarray
    """Drive-train tables of the fleet's vehicle spec (values)."""
    table_index: np.ndarray
    """Drive-train tables (descriptors)."""
    roads: np.ndarray
    """(N, rows, points) road attributes over distance, per vehicle."""
    stops: np.ndarray
    """(N, stops) stop-line positions [m], per vehicle."""
    cycle: np.ndarray
    """Drive cycle (unused by a road-following fleet)."""
    log: np.ndarray
    """(N, channels, capacity) truth log, per vehicle (capacity 0: none)."""



class Fleet:
    """N vehicle slots for the compiled batch step (module docstring).

    ``n_vehicles``: number of slots (>= 1); ``log_capacity``: substeps of truth log kept per vehicle (0: none -- a
    kernel that reads the state only; with capacity > 0 rows are written until the log is full)."""

    def __init__(self, n_vehicles: int, log_capacity: int = 0) -> None:
        for name, value, low in (("n_vehicles", n_vehicles, 1), ("log_capacity", log_capacity, 0)):
            if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < low:
                raise SimulationError(f"{name}: expected an integer >= {low}, got {value!r}")
        n = int(n_vehicles)
        self._vehicles = np.zeros(n, VEHICLE)
        self._roads = np.zeros((n, N_ROAD, 2))
        self._stops = np.zeros((n, 1))
        self._log = np.zeros((n, N_LOG, int(log_capacity)))
        self._cycle = np.zeros((2, 2))
        self._cycle[0, 1] = 1.0  # a valid (unused) drive cycle: time axis 0, 1 s
        self._tables: Tables | None = None
        self._records: FleetRecords | None = None
        self._shared: Simulator | None = None
        self._shared_key: tuple[int, int, int] = (0, 0, 0)

    @classmethod
    def sharing(cls, simulator: Simulator) -> Fleet:
        """A fleet of one vehicle that *is* ``simulator``: its records are the simulator's own arrays, so a compiled
        kernel that advances vehicle 0 advances the simulator, its truth log included. Call
        ``simulator.reserve_log(n_substeps)`` before and ``simulator.refresh()`` after each advance, and read
        :attr:`records` for every call (a reset or a growing log replaces the simulator's arrays)."""
        vehicle, tables, _, _, cycle = simulator._core_records()
        if cycle is not None:
            raise SimulationError("simulator: a drive-cycle simulator cannot join a fleet (its vehicles follow roads)")
        fleet = cls(1)
        fleet._shared = simulator
        fleet._vehicles = vehicle
        fleet._tables = tables
        return fleet

    @property
    def n_vehicles(self) -> int:
        """Number of slots."""
        return int(self._vehicles.shape[0])

    def load(self, i: int, simulator: Simulator) -> None:
        """Slot i <- the simulator's packed vehicle, effects, driver settings, road, stops and current state (a
        copy; ``simulator`` is a :class:`roadload.envs.Simulator`, not a drive-cycle one). The first load sets the
        fleet's vehicle spec; a simulator of another spec raises ``SimulationError``. May grow the arrays: read
        :attr:`records` again afterwards."""
        if self._shared is not None:
            raise SimulationError("load: this fleet shares its simulator's arrays (Fleet.sharing); build a new one")
        if not isinstance(simulator, Simulator):
            raise SimulationError(f"simulator: expected a roadload.envs.Simulator, got {type(simulator).__name__}")
        if isinstance(i, bool) or not isinstance(i, (int, np.integer)) or not 0 <= i < self.n_vehicles:
            raise SimulationError(f"slot: expected an integer in 0..{self.n_vehicles - 1}, got {i!r}")
        vehicle, tables, road, stops, cycle = simulator._core_records()
        if cycle is not None:
            raise SimulationError("simulator: a drive-cycle simulator cannot join a fleet (its vehicles follow roads)")
        self._adopt_tables(tables)
        self._road_slot(road.shape[1])[i, :, :road.shape[1]] = road
        self._stop_slot(max(stops.size, 1))[i, :stops.size] = stops
        self._vehicles[i] = vehicle[0]
        self._vehicles[i]["road_points"] = road.shape[1]
        self._vehicles[i]["stop_count"] = stops.size
        self._vehicles[i]["state"]["log_rows"] = 0.0  # the fleet's own log starts empty

    def _adopt_tables(self, tables: Tables) -> None:
        if self._tables is None:
            self._tables = tables
            self._records = None
        elif tables is not self._tables and not (np.array_equal(tables.values, self._tables.values)
                                                  and np.array_equal(tables.descriptors, self._tables.descriptors)):
            raise SimulationError("simulator: its vehicle spec differs from the fleet's (one spec per fleet: the "
                                  "drive-train tables are shared)")

    def _road_slot(self, points: int) -> np.ndarray:
        if self._roads.shape[2] < points:
            self._roads = _grown(self._roads, points)
            self._records = None
        return self._roads

    def _stop_slot(self, count: int) -> np.ndarray:
        if self._stops.shape[1] < count:
            self._stops = _grown(self._stops, count)
            self._records = None
        return self._stops

    @property
    def records(self) -> FleetRecords:
        """The packed records to pass to a compiled kernel (the fleet's own arrays, no copy)."""
        if self._tables is None:
            raise SimulationError("fleet: no vehicle loaded yet (Fleet.load(i, simulator) first)")
        if self._shared is not None:
            return self._shared_records(self._shared)
        if self._records is None:
            self._records = FleetRecords(self._vehicles, self._tables.values, self._tables.descriptors, self._roads,
                                         self._stops, self._cycle, self._log)
        return self._records

    def _shared_records(self, simulator: Simulator) -> FleetRecords:
        """The records of a sharing fleet: views of the simulator's current arrays (rebuilt when a reset or a
        growing log replaced one of them)."""
        vehicle, tables, road, stops, _ = simulator._core_records()
        log = simulator._log
        key = (id(road), id(stops), id(log))
        if self._records is None or key != self._shared_key:
            vehicle[0]["road_points"] = road.shape[1]
            vehicle[0]["stop_count"] = stops.size
            self._records = FleetRecords(vehicle, tables.values, tables.descriptors, road[None], stops[None],
                                         self._cycle, log[None])
            self._shared_key = key
        return self._records

    def state(self, i: int) -> VehicleState:
        """A typed Python view (:class:`roadload.envs.VehicleState`) of slot i's state: read every field, set
        ``position`` and ``speed``."""
        if not 0 <= i < self.n_vehicles:
            raise IndexError(f"slot {i}: the fleet has {self.n_vehicles} vehicles")
        return VehicleState(self._vehicles, i)


class StartRecords(NamedTuple):
    """The packed episode starts of a :class:`FleetStarts` (its own arrays, no copy), as :func:`start_vehicle` takes
    them; row k is start k."""

    vehicles: np.ndarray
    """(K,) vehicle records as the simulator's reset left them (road points and stop count set, no log rows)."""
    roads: np.ndarray
    """(K, rows, points) road attributes over distance."""
    stops: np.ndarray
    """(K, stops) stop-line positions [m]."""


class FleetStarts:
    """Episode starts for the vehicles of ``fleet``, packed so that a compiled kernel starts an episode without the
    Python reset: :meth:`add` stores a simulator's packed vehicle as reset, its road rows and stop lines as start k;
    ``start_vehicle(fleet.records, i, starts.records, k, effects_random_state(seed))`` then puts slot i where
    ``simulator.reset(seed)`` followed by ``fleet.load(i, simulator)`` would (the same record, bit for bit: a reset
    sets the effects' random stream from the seed and nothing else that depends on it, unless
    ``simulator.road_depends_on_seed``, which :meth:`add` refuses), without building the sensor model and step
    result the fleet never reads. May grow the fleet's arrays: read ``fleet.records`` again after :meth:`add`."""

    def __init__(self, fleet: Fleet) -> None:
        if fleet._shared is not None:
            raise SimulationError("FleetStarts: this fleet shares its simulator's arrays (Fleet.sharing)")
        self.fleet = fleet
        self.count = 0
        self._vehicles = np.zeros(4, VEHICLE)
        self._roads = np.zeros((4, N_ROAD, 2))
        self._stops = np.zeros((4, 1))
        self._records: StartRecords | None = None

    def add(self, simulator: Simulator) -> int:
        """Start k (returned) <- ``simulator`` as its last reset left it (the fleet's vehicle spec; see the class)."""
        if not isinstance(simulator, Simulator):
            raise SimulationError(f"simulator: expected a roadload.envs.Simulator, got {type(simulator).__name__}")
        if simulator.road_depends_on_seed:
            raise SimulationError("simulator: its road depends on the seed (effect 'poor_excitation'); start it with "
                                  "simulator.reset(seed) and Fleet.load")
        vehicle, tables, road, stops, cycle = simulator._core_records()
        if cycle is not None:
            raise SimulationError("simulator: a drive-cycle simulator cannot join a fleet (its vehicles follow roads)")
        fleet = self.fleet
        fleet._adopt_tables(tables)
        fleet._road_slot(road.shape[1])
        fleet._stop_slot(max(stops.size, 1))
        k = self.count
        if k == self._vehicles.shape[0]:  # doubling: amortised O(1) per start
            self._vehicles = np.concatenate([self._vehicles, np.zeros_like(self._vehicles)])
            self._roads = np.concatenate([self._roads, np.zeros_like(self._roads)])
            self._stops = np.concatenate([self._stops, np.zeros_like(self._stops)])
        if self._roads.shape[2] < road.shape[1]:
            self._roads = _grown(self._roads, road.shape[1])
        if self._stops.shape[1] < stops.size:
            self._stops = _grown(self._stops, stops.size)
        self._roads[k, :, :road.shape[1]] = road
        self._stops[k, :stops.size] = stops
        self._vehicles[k] = vehicle[0]
        self._vehicles[k]["road_points"] = road.shape[1]
        self._vehicles[k]["stop_count"] = stops.size
        self._vehicles[k]["state"]["log_rows"] = 0.0
        self.count = k + 1
        self._records = None
        return k

    def clear(self) -> None:
        """Forget every start (the arrays are kept for the next ones)."""
        self.count = 0

    @property
    def records(self) -> StartRecords:
        """The packed starts to pass to a compiled kernel (the same object until an :meth:`add` grew an array)."""
        if self._records is None or self._records.vehicles is not self._vehicles \
                or self._records.roads is not self._roads or self._records.stops is not self._stops:
            self._records = StartRecords(self._vehicles, self._roads, self._stops)
        return self._records


def _grown(arr: np.ndarray, width: int) -> np.ndarray:
    """``arr`` with its last axis zero-padded to ``width``."""
    new = np.zeros(arr.shape[:-1] + (width,), dtype=arr.dtype)
    new[..., :arr.shape[-1]] = arr
    return new


# --------------------------------------------------------------------------------------------- compiled functions
@jit(inline=True)
def state_of(records, i):
    """The state record of vehicle i (a view: it changes when the vehicle is advanced); fields in the module
    docstring, e.g. ``state_of(records, i).speed`` [m/s]."""
    return records.vehicles[i].state


@jit(inline=True)
def command_wheel_force(records, i, force, steer):
    """Hold a signed wheel force ``force`` [N] for vehicle i: >= 0 traction, < 0 braking (regeneration / engine
    drag first, friction brakes for the rest); ``steer``: front wheel angle [rad], NaN for the built-in steering
    law that follows the road; automatic gears."""
    c = records.vehicles[i].command
    c.mode = COMMAND_WHEEL_FORCE
    c.traction = force
    c.steer = steer
    c.gear = -1.0


@jit(inline=True)
def command_forces(records, i, traction, regen, friction, steer, gear):
    """Hold explicit wheel forces for vehicle i [N, each >= 0]: traction, regeneration (ICE: engine drag) and
    friction brakes; ``steer`` [rad] or NaN (built-in steering law); ``gear``: -1 shift strategy, 0 neutral /
    sailing, 1..n a requested gear."""
    c = records.vehicles[i].command
    c.mode = COMMAND_FORCES
    c.traction = traction
    c.regen = regen
    c.friction = friction
    c.steer = steer
    c.gear = gear


@jit(inline=True)
def command_driver(records, i):
    """Let the built-in driver (speed limits, curves, stops) command vehicle i."""
    records.vehicles[i].command.mode = COMMAND_DRIVER


@jit(inline=True)
def advance_vehicle(records, i, n_substeps):
    """Advance vehicle i by ``n_substeps`` x SUBSTEP_SECONDS with its command held (the simulator core: drive-train,
    brakes, lateral model, effects, energy ledger; a truth-log row per substep while the log has room)."""
    v = records.vehicles[i]
    route = Route(records.roads[i, :, :v.road_points], records.stops[i, :v.stop_count], records.cycle)
    physics.advance(v.state, v.params, v.command, Tables(records.table_values, records.table_index), route,
                    records.log[i], n_substeps)


@jit
def advance_vehicles(records, active, n_substeps):
    """:func:`advance_vehicle` for every vehicle i with ``active[i]`` (bool array of length N)."""
    for i in range(records.vehicles.shape[0]):
        if active[i]:
            advance_vehicle(records, i, n_substeps)


@jit(inline=True)
def start_vehicle(records, i, starts, k, random_state):
    """Vehicle i at start k of ``starts`` (a FleetStarts' records) with the effects' random stream
    ``random_state`` (``roadload.envs.simulator.effects_random_state(seed)``): its packed record, road rows and stop
    lines copied into slot i (the fleet's arrays are wide enough: FleetStarts.add grew them)."""
    v = starts.vehicles[k]
    records.vehicles[i] = v
    records.vehicles[i].state.random_state = random_state
    for row in range(records.roads.shape[1]):  # loops, not slices: a slice copy allocates (no kernel without NRT)
        for p in range(v.road_points):
            records.roads[i, row, p] = starts.roads[k, row, p]
    for p in range(v.stop_count):
        records.stops[i, p] = starts.stops[k, p]


@jit(inline=True)
def vehicle_done(records, i):
    """True when vehicle i has reached the end of its road."""
    v = records.vehicles[i]
    return physics.is_done(v.state, v.params)


__all__ = ["SUBSTEP_SECONDS", "Fleet", "FleetRecords", "FleetStarts", "StartRecords", "advance_vehicle",
           "advance_vehicles", "asin_small", "atan_small", "command_driver", "command_forces", "command_wheel_force",
           "cos_small", "dependent_jit", "effects_random_state", "sin_small", "start_vehicle", "state_of", "tan_small",
           "vehicle_done"]
