"""Typed Python views of a simulated vehicle's state and parameters (the public face of the core's records).

``sim.vehicle_state`` (and ``Fleet.state(i)``) is a :class:`VehicleState`: every field of the state record as a
named attribute in SI units, read live (it follows the simulator as it steps); ``position`` and ``speed`` may be set
between steps (e.g. to start a replay window at a measured position). ``sim.parameters`` is a
:class:`VehicleParameters`: the packed vehicle / effect / driver parameters by name (read-only).
"""

from __future__ import annotations

from typing import Any, overload

import numpy as np

from .layout import PARAM_FIELDS, STATE_FIELDS, field_index

STATE_UNITS: dict[str, str] = {name: unit for name, unit, _ in STATE_FIELDS}
"""SI unit of every state field."""
PARAMETER_UNITS: dict[str, str] = {name: unit for name, unit, _ in PARAM_FIELDS}
"""SI unit of every scalar parameter."""


class _Field:
    """One float64 field of a vehicle record, read (and, when settable, written) through the record's float view."""

    def __init__(self, record: str, name: str, settable: bool = False) -> None:
        self.index = field_index(record, name)
        self.name = name
        self.settable = settable

    @overload
    def __get__(self, obj: None, owner: type) -> "_Field": ...

    @overload
    def __get__(self, obj: "_RecordView", owner: type) -> float: ...

    def __get__(self, obj: "_RecordView | None", owner: type) -> "float | _Field":
        if obj is None:
            return self
        return obj._words[obj._base + self.index]

    def __set__(self, obj: "_RecordView", value: float) -> None:
        if not self.settable:
            raise AttributeError(f"{self.name}: read-only (set position or speed)")
        value = float(value)
        if not np.isfinite(value) or (self.name == "speed" and value < 0.0):
            raise ValueError(f"{self.name}: expected a finite value{' >= 0 m/s' if self.name == 'speed' else ''}, "
                             f"got {value!r}")
        obj._words[obj._base + self.index] = value


class _RecordView:
    """Slot ``i`` of a VEHICLE array, read through its float64 words."""

    _record = ""
    _fields: tuple[tuple[str, str, str], ...] = ()

    def __init__(self, vehicles: np.ndarray, i: int = 0) -> None:
        words = vehicles.view(np.float64)
        self._words = words
        self._base = i * (vehicles.dtype.itemsize // 8)

    def to_dict(self) -> dict[str, float]:
        """Every field by name (SI)."""
        return {name: float(self._words[self._base + field_index(self._record, name)]) for name, _, _ in
                self._fields}

    def __repr__(self) -> str:
        return f"{type(self).__name__}({', '.join(f'{k}={v:.6g}' for k, v in self.to_dict().items())})"

    def __eq__(self, other: Any) -> bool:
        return type(other) is type(self) and self.to_dict() == other.to_dict()

    __hash__ = None  # type: ignore[assignment]


def _state(name: str, settable: bool = False) -> Any:
    return _Field("state", name, settable)


def _param(name: str) -> Any:
    return _Field("params", name)


class VehicleState(_RecordView):
    """The state of one simulated vehicle, live, SI units (units in ``STATE_UNITS``). Settable: ``position`` [m],
    ``speed`` [m/s]."""

    _record = "state"
    _fields = STATE_FIELDS

    time: float = _state("time")
    position: float = _state("position", settable=True)
    speed: float = _state("speed", settable=True)
    acceleration: float = _state("acceleration")
    gear: float = _state("gear")
    clutch_mode: float = _state("clutch_mode")
    engine_speed: float = _state("engine_speed")
    engine_torque: float = _state("engine_torque")
    clutch_torque: float = _state("clutch_torque")
    brake_pressure_front: float = _state("brake_pressure_front")
    brake_pressure_rear: float = _state("brake_pressure_rear")
    state_of_charge: float = _state("state_of_charge")
    side_slip_angle: float = _state("side_slip_angle")
    yaw_rate: float = _state("yaw_rate")
    wheel_steer_angle: float = _state("wheel_steer_angle")
    lateral_offset: float = _state("lateral_offset")
    heading_error: float = _state("heading_error")
    lateral_acceleration: float = _state("lateral_acceleration")
    lateral_acceleration_peak: float = _state("lateral_acceleration_peak")
    lateral_warning_count: float = _state("lateral_warning_count")
    mass: float = _state("mass")
    drag_area_factor: float = _state("drag_area_factor")
    oil_temperature: float = _state("oil_temperature")
    brake_disc_temperature: float = _state("brake_disc_temperature")
    pad_friction_walk: float = _state("pad_friction_walk")
    log_rows: float = _state("log_rows")
    source_energy: float = _state("source_energy")
    shaft_work: float = _state("shaft_work")
    gearbox_loss: float = _state("gearbox_loss")
    differential_loss: float = _state("differential_loss")
    clutch_loss: float = _state("clutch_loss")
    brake_loss: float = _state("brake_loss")
    rolling_loss: float = _state("rolling_loss")
    aero_loss: float = _state("aero_loss")
    cornering_loss: float = _state("cornering_loss")
    climbing_work: float = _state("climbing_work")
    payload_potential_energy: float = _state("payload_potential_energy")


class VehicleParameters(_RecordView):
    """The packed parameters of one simulated vehicle (vehicle spec, effects, driver, run limits), read-only, SI
    units (``PARAMETER_UNITS``); the scheduled effects change mass_nominal, drag_coefficient, rolling_f0/f1/f4 and
    the wind while a trip runs."""

    _record = "params"
    _fields = PARAM_FIELDS

    dt: float = _param("dt")
    mass_nominal: float = _param("mass_nominal")
    wheel_radius: float = _param("wheel_radius")
    wheelbase: float = _param("wheelbase")
    cg_to_front: float = _param("cg_to_front")
    cg_to_rear: float = _param("cg_to_rear")
    rolling_f0: float = _param("rolling_f0")
    rolling_f1: float = _param("rolling_f1")
    rolling_f4: float = _param("rolling_f4")
    cornering_stiffness_front: float = _param("cornering_stiffness_front")
    cornering_stiffness_rear: float = _param("cornering_stiffness_rear")
    drag_coefficient: float = _param("drag_coefficient")
    frontal_area: float = _param("frontal_area")
    pad_friction: float = _param("pad_friction")
    ambient_temperature: float = _param("ambient_temperature")
    ambient_pressure: float = _param("ambient_pressure")
    road_length: float = _param("road_length")


__all__ = ["PARAMETER_UNITS", "STATE_UNITS", "VehicleParameters", "VehicleState"]
