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

Compiled side (from Python, or from a kernel whose numba cache follows the core's sources: ``kernel =
dependent_jit(__file__)``, then ``@kernel()`` / ``@kernel(parallel=True)`` on each kernel)::

    command_wheel_force(records, i, force, steer)   # signed wheel force [N], steer [rad] (NaN: built-in steering)
    advance_vehicle(records, i, n_substeps)         # n_substeps x SUBSTEP_SECONDS with the command held
    st = state_of(records, i)                       # the state record: st.speed [m/s], st.position [m], ...

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

from ._jit import dependent_jit

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
        raise NotImplementedError("the batch-step API is being implemented (signatures fixed)")

    @property
    def n_vehicles(self) -> int:
        """Number of slots."""
        raise NotImplementedError

    def load(self, i: int, simulator: object) -> None:
        """Slot i <- the simulator's packed vehicle, effects, driver settings, road, stops and current state (a
        copy; ``simulator`` is a :class:`roadload.envs.Simulator`, not a drive-cycle one). The first load sets the
        fleet's vehicle spec; a simulator of another spec raises ``SimulationError``. May grow the arrays: read
        :attr:`records` again afterwards."""
        raise NotImplementedError

    @property
    def records(self) -> FleetRecords:
        """The packed records to pass to a compiled kernel (the fleet's own arrays, no copy)."""
        raise NotImplementedError

    def state(self, i: int) -> object:
        """A typed Python view (:class:`roadload.envs.VehicleState`) of slot i's state: read every field, set
        ``position`` and ``speed``."""
        raise NotImplementedError


# --------------------------------------------------------------------------------------------- compiled functions
# (numba njit; callable from another compiled kernel and from Python)

def state_of(records: FleetRecords, i: int):  # -> the state record of vehicle i
    """The state record of vehicle i (a view: it changes when the vehicle is advanced); fields in the module
    docstring, e.g. ``state_of(records, i).speed`` [m/s]."""
    raise NotImplementedError


def command_wheel_force(records: FleetRecords, i: int, force: float, steer: float) -> None:
    """Hold a signed wheel force ``force`` [N] for vehicle i: >= 0 traction, < 0 braking (regeneration / engine
    drag first, friction brakes for the rest); ``steer``: front wheel angle [rad], NaN for the built-in steering
    law that follows the road; automatic gears."""
    raise NotImplementedError


def command_forces(records: FleetRecords, i: int, traction: float, regen: float, friction: float, steer: float,
                   gear: int) -> None:
    """Hold explicit wheel forces for vehicle i [N, each >= 0]: traction, regeneration (ICE: engine drag) and
    friction brakes; ``steer`` [rad] or NaN (built-in steering law); ``gear``: -1 shift strategy, 0 neutral /
    sailing, 1..n a requested gear."""
    raise NotImplementedError


def command_driver(records: FleetRecords, i: int) -> None:
    """Let the built-in driver (speed limits, curves, stops) command vehicle i."""
    raise NotImplementedError


def advance_vehicle(records: FleetRecords, i: int, n_substeps: int) -> None:
    """Advance vehicle i by ``n_substeps`` x SUBSTEP_SECONDS with its command held (the simulator core: drive-train,
    brakes, lateral model, effects, energy ledger; a truth-log row per substep while the log has room)."""
    raise NotImplementedError


def advance_vehicles(records: FleetRecords, active: np.ndarray, n_substeps: int) -> None:
    """:func:`advance_vehicle` for every vehicle i with ``active[i]`` (bool array of length N)."""
    raise NotImplementedError


def vehicle_done(records: FleetRecords, i: int) -> bool:
    """True when vehicle i has reached the end of its road."""
    raise NotImplementedError


__all__ = ["SUBSTEP_SECONDS", "Fleet", "FleetRecords", "advance_vehicle", "advance_vehicles", "command_driver",
           "command_forces", "command_wheel_force", "dependent_jit", "state_of", "vehicle_done"]
