"""Vehicle specification: the parameters of one vehicle, shared by the simulator and the estimating side.

A :class:`VehicleSpec` nests ``body`` / ``aero`` / ``tires`` / ``drivetrain`` / ``brakes`` / ``steering`` /
``sensors`` parts. Everything is SI (kg, m, s, rad, N, N*m, W, J, K, Pa). Tables (engine full-load curve, fuel map,
motor loss map, drive-train loss maps, steering ratio) are stored as plain lists so a spec round-trips through JSON
unchanged and the estimating side can keep its own (possibly different) copy.

``VehicleSpec.from_dict`` / ``load_vehicle`` validate every field and raise :class:`VehicleSpecError` naming the
field, e.g. ``vehicle.body.mass: must be > 0``; unknown keys are errors, missing keys take the defaults.

Symbols (Rhode 2018): m_V mass, l_12 / l_34 CG-to-front / CG-to-rear axle distance, X_12 / X_34 axle cornering
stiffness (eq. 2.12), f_r0 / f_r1 / f_r4 rolling-resistance coefficients (eq. 2.10), c_x*A_V drag area (eq. 2.7),
i_G(G) gear ratios, i_D final drive, I_E / I_C / I_G / I_D / I_W inertias and loss maps f(T, omega, G) (eq. 2.17),
A_B / r_B / X_B brake area, radius and pad friction (T_B = p_B A_B r_B X_B, section 2.7).
"""

from __future__ import annotations

import dataclasses
import json
import math
import os
import types
import typing
from dataclasses import dataclass, field
from pathlib import Path
from typing import Annotated, Any

import numpy as np
from pydantic import Field, TypeAdapter
from pydantic.fields import FieldInfo

from .fileio import write_json
from .units import G, STANDARD_AIR_DENSITY
from .channels import MEASURED

__all__ = [
    "VehicleSpecError", "Curve", "Map2D", "BodySpec", "AeroSpec", "TireSpec", "EngineSpec", "MotorSpec",
    "BatterySpec", "ShiftSpec", "DrivetrainSpec", "BrakeSpec", "SteeringSpec", "ChannelSensorSpec", "SensorSpec",
    "VehicleSpec", "load_vehicle", "save_vehicle", "check_declared", "check_physics",
    "MASS_MIN", "MASS_MAX", "TOP_SPEED_MIN", "vehicle_json_schema",
]



class VehicleSpecError(ValueError):
    """A vehicle specification is invalid; the message names the field (``vehicle.body.mass: ...``)."""


# ----------------------------------------------------------------------------------------------- declared bounds
#: plausible road vehicles: a 250 kg quadricycle ... a 44 t truck (EU limit) with margin
MASS_MIN, MASS_MAX = 250.0, 60_000.0
#: gear ratios i_G of road-vehicle gearboxes (12-speed truck: ~16 ... 0.77; car overdrive ~0.6; BEV single ~10)
GEAR_RATIO_MIN, GEAR_RATIO_MAX = 0.3, 25.0
FINAL_DRIVE_MIN, FINAL_DRIVE_MAX = 0.5, 15.0
#: the top speed (kinematic and power limit, flat road) a road vehicle must reach [m/s]
TOP_SPEED_MIN = 20.0


def _q(unit: str, doc: str, *, plausible: tuple[float, float] | None = None, gt: float | None = 0.0) -> FieldInfo:
    """A declared physical quantity: > gt, inside the plausible range [lo, hi], in `unit` (pydantic Field
    metadata read by :func:`check_declared`; also shows in the JSON schema of the spec)."""
    extra: dict[str, Any] = {"unit": unit}
    if plausible is not None:
        extra["plausible"] = list(plausible)
    return Field(gt=gt, description=f"{doc} [{unit}]", json_schema_extra=extra)


_HINTS: dict[type, dict[str, Any]] = {}


def check_declared(obj: Any, path: str) -> None:
    """Check every field declared with :func:`_q` on a (nested) spec dataclass: finite, > bound, inside the
    plausible range; the error names the field, the value, the bound and the unit."""
    tp = type(obj)
    if tp not in _HINTS:
        _HINTS[tp] = typing.get_type_hints(tp, include_extras=True)
    hints = _HINTS[tp]
    for f in dataclasses.fields(obj):
        value = getattr(obj, f.name)
        hint: Any = hints.get(f.name)
        if typing.get_origin(hint) is Annotated:
            for info in hint.__metadata__:
                if isinstance(info, FieldInfo):
                    _check_quantity(f"{path}.{f.name}", value, info)
        if dataclasses.is_dataclass(value) and not isinstance(value, type):
            check_declared(value, f"{path}.{f.name}")


def _check_quantity(path: str, value: Any, info: FieldInfo) -> None:
    extra: dict[str, Any] = dict(info.json_schema_extra) if isinstance(info.json_schema_extra, dict) else {}
    unit = extra.get("unit", "")
    if not isinstance(value, (int, float)) or isinstance(value, bool) or not math.isfinite(value):
        raise VehicleSpecError(f"{path}: must be a finite number [{unit}], got {value!r}")
    for m in info.metadata:
        gt = getattr(m, "gt", None)
        if gt is not None and not value > gt:
            raise VehicleSpecError(f"{path}: must be > {gt:g} [{unit}], got {value!r}")
    if "plausible" in extra:
        lo, hi = (float(b) for b in extra["plausible"])
        if not lo <= value <= hi:
            raise VehicleSpecError(f"{path}: {value!r} {unit} is outside the plausible range [{lo:g}, {hi:g}] "
                                   f"{unit} of a road vehicle ({info.description})")


def _flat_road_speed(power: float, mass: float, tires: "TireSpec", drag_area: float, efficiency: float = 0.9) -> float:
    """Speed [m/s] where P eta = (m g f_r(v) + rho/2 c_x A v^2) v on a flat road (bisection)."""
    lo, hi = 0.0, 200.0
    for _ in range(60):
        v = 0.5 * (lo + hi)
        need = (mass * G * float(tires.rolling_resistance_coefficient(v)) + 0.5 * STANDARD_AIR_DENSITY * drag_area
                * v ** 2) * v
        lo, hi = (v, hi) if need < power * efficiency else (lo, v)
    return lo


def check_physics(spec: "VehicleSpec", path: str = "vehicle") -> None:
    """Cross-field checks of a complete spec: gear ratios in range and strictly decreasing, final drive in range,
    and a reachable top speed (min of the shaft-speed limit in the top gear and the flat-road power limit)
    above TOP_SPEED_MIN."""
    d = spec.drivetrain
    for k, r in enumerate(d.gear_ratios):
        if not GEAR_RATIO_MIN <= r <= GEAR_RATIO_MAX:
            raise VehicleSpecError(f"{path}.drivetrain.gear_ratios[{k}]: {r!r} is outside the plausible range "
                                   f"[{GEAR_RATIO_MIN:g}, {GEAR_RATIO_MAX:g}] of a gearbox ratio [1]")
    steps = np.diff(np.asarray(d.gear_ratios, dtype=float))
    if np.any(steps >= 0):
        k = int(np.flatnonzero(steps >= 0)[0])
        raise VehicleSpecError(f"{path}.drivetrain.gear_ratios: must be strictly decreasing from first gear up, "
                               f"got {d.gear_ratios[k]!r} then {d.gear_ratios[k + 1]!r} at gears {k + 1}, {k + 2}")
    if d.engine is not None and d.kind == "ice":
        shaft_max = d.engine.max_speed
        x, y = np.asarray(d.engine.full_load.x, float), np.asarray(d.engine.full_load.y, float)
        power = float(np.max(x * y))
    elif d.motor is not None:
        shaft_max = d.motor.max_speed
        power = d.motor.max_power
    else:  # validated before: an ICE has an engine, a BEV a motor
        return
    r = spec.tires.dynamic_radius
    v_shaft = shaft_max * r / (min(d.gear_ratios) * d.final_drive)
    v_power = _flat_road_speed(power, spec.body.mass, spec.tires, spec.aero.drag_area)
    v_top = min(v_shaft, v_power)
    if v_top < TOP_SPEED_MIN:
        cause = (f"shaft speed limit {shaft_max:.0f} rad/s through ratio {min(d.gear_ratios):g} x "
                 f"{d.final_drive:g} on {r:g} m wheels gives {v_shaft:.3g} m/s" if v_shaft <= v_power else
                 f"peak power {power / 1e3:.3g} kW moves {spec.body.mass:g} kg at {v_power:.3g} m/s on a flat road")
        where = "drivetrain.gear_ratios" if v_shaft <= v_power else "body.mass"
        raise VehicleSpecError(f"{path}.{where}: top speed {v_top:.3g} m/s [{v_top * 3.6:.3g} km/h] is below "
                               f"{TOP_SPEED_MIN:g} m/s [{TOP_SPEED_MIN * 3.6:g} km/h] ({cause})")


# ----------------------------------------------------------------------------------------------- check helpers
def _finite(path: str, value: float) -> None:
    if not isinstance(value, (int, float)) or isinstance(value, bool) or not math.isfinite(value):
        raise VehicleSpecError(f"{path}: must be a finite number, got {value!r}")


def _positive(path: str, value: float) -> None:
    _finite(path, value)
    if value <= 0:
        raise VehicleSpecError(f"{path}: must be > 0, got {value!r}")


def _nonneg(path: str, value: float) -> None:
    _finite(path, value)
    if value < 0:
        raise VehicleSpecError(f"{path}: must be >= 0, got {value!r}")


def _between(path: str, value: float, lo: float, hi: float) -> None:
    _finite(path, value)
    if not lo <= value <= hi:
        raise VehicleSpecError(f"{path}: must lie in [{lo}, {hi}], got {value!r}")


def _increasing(path: str, values: list[float], min_len: int = 2) -> None:
    arr = np.asarray(values, dtype=float)
    if arr.ndim != 1 or arr.size < min_len:
        raise VehicleSpecError(f"{path}: needs a list of at least {min_len} numbers")
    if not np.all(np.isfinite(arr)):
        raise VehicleSpecError(f"{path}: contains NaN/inf")
    if not np.all(np.diff(arr) > 0):
        raise VehicleSpecError(f"{path}: must be strictly increasing")


# ----------------------------------------------------------------------------------------------- tables
@dataclass
class Curve:
    """A 1-D lookup table y(x), linear interpolation, clamped at the ends."""

    x: list[float]
    y: list[float]

    def validate(self, path: str) -> None:
        _increasing(f"{path}.x", self.x)
        y = np.asarray(self.y, dtype=float)
        if y.shape != (len(self.x),):
            raise VehicleSpecError(f"{path}.y: length {y.size} differs from x length {len(self.x)}")
        if not np.all(np.isfinite(y)):
            raise VehicleSpecError(f"{path}.y: contains NaN/inf")

    def __call__(self, x):
        return np.interp(x, self.x, self.y)


@dataclass
class Map2D:
    """A 2-D lookup table ``values[i][j] = f(x[i], y[j])``, bilinear interpolation, clamped at the edges."""

    x: list[float]
    y: list[float]
    values: list[list[float]]

    def validate(self, path: str) -> None:
        _increasing(f"{path}.x", self.x)
        _increasing(f"{path}.y", self.y)
        v = np.asarray(self.values, dtype=float)
        if v.shape != (len(self.x), len(self.y)):
            raise VehicleSpecError(f"{path}.values: shape {v.shape} differs from (len(x), len(y)) = "
                                   f"({len(self.x)}, {len(self.y)})")
        if not np.all(np.isfinite(v)):
            raise VehicleSpecError(f"{path}.values: contains NaN/inf")

    def __call__(self, x, y):
        """Bilinear interpolation (numpy, vectorised)."""
        xs, ys, v = np.asarray(self.x), np.asarray(self.y), np.asarray(self.values)
        x = np.clip(np.asarray(x, dtype=float), xs[0], xs[-1])
        y = np.clip(np.asarray(y, dtype=float), ys[0], ys[-1])
        i = np.clip(np.searchsorted(xs, x, side="right") - 1, 0, xs.size - 2)
        j = np.clip(np.searchsorted(ys, y, side="right") - 1, 0, ys.size - 2)
        u = (x - xs[i]) / (xs[i + 1] - xs[i])
        w = (y - ys[j]) / (ys[j + 1] - ys[j])
        return ((1 - u) * (1 - w) * v[i, j] + u * (1 - w) * v[i + 1, j]
                + (1 - u) * w * v[i, j + 1] + u * w * v[i + 1, j + 1])


# ----------------------------------------------------------------------------------------------- parts
@dataclass
class BodySpec:
    """Mass and geometry. mass m_V [kg] nominal incl. driver; wheelbase l = l_12 + l_34 [m];
    cg_to_front_axle l_12 [m]; yaw_inertia I_z [kg m^2]; pitch/roll gradients [rad per m/s^2] tilt the body-fixed
    accelerometers (eq. 4.4/5.2: nose up under acceleration, roll outward in corners)."""

    mass: Annotated[float, _q("kg", "nominal mass incl. driver", plausible=(MASS_MIN, MASS_MAX))]
    wheelbase: Annotated[float, _q("m", "wheelbase l = l_12 + l_34", plausible=(1.0, 10.0))]
    cg_to_front_axle: float
    cg_height: Annotated[float, _q("m", "CG height", plausible=(0.1, 3.5))] = 0.55
    track_front: Annotated[float, _q("m", "front track width", plausible=(0.5, 3.0))] = 1.6
    track_rear: Annotated[float, _q("m", "rear track width", plausible=(0.5, 3.0))] = 1.6
    yaw_inertia: Annotated[float, _q("kg m^2", "yaw inertia I_z", plausible=(10.0, 2.0e6))] = 3000.0
    pitch_gradient: float = 0.004
    roll_gradient: float = 0.006

    @property
    def cg_to_rear_axle(self) -> float:
        """l_34 [m]."""
        return self.wheelbase - self.cg_to_front_axle

    def validate(self, path: str) -> None:
        for name in ("mass", "wheelbase", "cg_to_front_axle", "cg_height", "track_front", "track_rear",
                     "yaw_inertia"):
            _positive(f"{path}.{name}", getattr(self, name))
        if self.cg_to_front_axle >= self.wheelbase:
            raise VehicleSpecError(f"{path}.cg_to_front_axle: must be < wheelbase ({self.wheelbase} m)")
        _between(f"{path}.pitch_gradient", self.pitch_gradient, 0.0, 0.05)
        _between(f"{path}.roll_gradient", self.roll_gradient, 0.0, 0.05)


@dataclass
class AeroSpec:
    """Aerodynamics (eq. 2.7): c_x(psi_a) = c_w cos(psi_a) (1 + yaw_drag_factor sin^2 psi_a), frontal area A_V."""

    drag_coefficient: Annotated[float, _q("1", "drag coefficient c_w", plausible=(1e-3, 2.0))]
    frontal_area: Annotated[float, _q("m^2", "frontal area A_V", plausible=(0.3, 15.0))]
    yaw_drag_factor: float = 0.3

    @property
    def drag_area(self) -> float:
        """c_x*A_V [m^2] at zero air approach angle."""
        return self.drag_coefficient * self.frontal_area

    def validate(self, path: str) -> None:
        _between(f"{path}.drag_coefficient", self.drag_coefficient, 1e-3, 2.0)
        _positive(f"{path}.frontal_area", self.frontal_area)
        _between(f"{path}.yaw_drag_factor", self.yaw_drag_factor, 0.0, 5.0)


@dataclass
class TireSpec:
    """Tires and wheels: dynamic radius r_W [m]; f_r(v) = f_r0 + f_r1 v + f_r4 v^4 (eq. 2.10, f_r1 [s/m],
    f_r4 [s^4/m^4]); axle cornering stiffnesses X_12, X_34 [N/rad] (eq. 2.12); longitudinal slip stiffness c_xW
    per wheel [N] (eq. 2.3a); wheel inertia I_W per wheel incl. brake disc [kg m^2]; toe_in per front wheel [rad]."""

    dynamic_radius: Annotated[float, _q("m", "dynamic tyre radius r_W", plausible=(0.1, 1.5))]
    rolling_resistance_f0: float
    rolling_resistance_f1: float
    rolling_resistance_f4: float
    cornering_stiffness_front: float
    cornering_stiffness_rear: float
    longitudinal_stiffness: float = 8.0e4
    wheel_inertia: float = 1.0
    toe_in: float = 0.0015

    def rolling_resistance_coefficient(self, v):
        """f_r(v) (eq. 2.10)."""
        v = np.asarray(v, dtype=float)
        return self.rolling_resistance_f0 + self.rolling_resistance_f1 * v + self.rolling_resistance_f4 * v ** 4

    def validate(self, path: str) -> None:
        _between(f"{path}.dynamic_radius", self.dynamic_radius, 0.1, 1.5)
        _between(f"{path}.rolling_resistance_f0", self.rolling_resistance_f0, 1e-4, 0.1)
        _between(f"{path}.rolling_resistance_f1", self.rolling_resistance_f1, 0.0, 1e-2)
        _between(f"{path}.rolling_resistance_f4", self.rolling_resistance_f4, 0.0, 1e-6)
        for name in ("cornering_stiffness_front", "cornering_stiffness_rear", "longitudinal_stiffness",
                     "wheel_inertia"):
            _positive(f"{path}.{name}", getattr(self, name))
        _between(f"{path}.toe_in", self.toe_in, 0.0, 0.02)


@dataclass
class EngineSpec:
    """Combustion engine: speeds [rad/s]; full_load T_max(omega) and drag (motoring, negative) torque curves [N m];
    fuel_power map P_fuel(omega, T_E) [W] (x = speed, y = torque; zero below the drag curve = fuel cut);
    inertia I_E [kg m^2]."""

    idle_speed: Annotated[float, _q("rad/s", "idle speed", plausible=(20.0, 200.0))]
    max_speed: Annotated[float, _q("rad/s", "maximum engine speed", plausible=(100.0, 1500.0))]
    full_load: Curve
    drag: Curve
    fuel_power: Map2D
    inertia: float

    def validate(self, path: str) -> None:
        _positive(f"{path}.idle_speed", self.idle_speed)
        _positive(f"{path}.max_speed", self.max_speed)
        if self.max_speed <= self.idle_speed:
            raise VehicleSpecError(f"{path}.max_speed: must exceed idle_speed")
        self.full_load.validate(f"{path}.full_load")
        self.drag.validate(f"{path}.drag")
        if np.any(np.asarray(self.full_load.y) <= 0):
            raise VehicleSpecError(f"{path}.full_load.y: full-load torque must be > 0")
        if np.any(np.asarray(self.drag.y) > 0):
            raise VehicleSpecError(f"{path}.drag.y: drag torque must be <= 0")
        self.fuel_power.validate(f"{path}.fuel_power")
        if np.any(np.asarray(self.fuel_power.values) < 0):
            raise VehicleSpecError(f"{path}.fuel_power.values: fuel power must be >= 0")
        _positive(f"{path}.inertia", self.inertia)


@dataclass
class MotorSpec:
    """Traction motor: torque / power limits (motoring) [N m, W], regen limits (magnitudes) [N m, W], max speed
    [rad/s], rotor inertia [kg m^2], loss_map P_loss(omega, T) [W] >= 0 (x = speed, y = torque); electrical power
    P_el = T omega + P_loss (efficiency map: see ``MotorSpec.efficiency``)."""

    max_torque: Annotated[float, _q("N*m", "maximum motor torque", plausible=(5.0, 1.0e5))]
    max_power: Annotated[float, _q("W", "maximum motor power", plausible=(1.0e3, 2.0e6))]
    max_speed: Annotated[float, _q("rad/s", "maximum motor speed", plausible=(50.0, 3000.0))]
    regen_torque_limit: float
    regen_power_limit: float
    inertia: float
    loss_map: Map2D

    def efficiency(self, speed, torque):
        """Motor efficiency eta(omega, T) [-] derived from the loss map (motoring: P_m/P_el; generating: P_el/P_m)."""
        speed = np.asarray(speed, dtype=float)
        torque = np.asarray(torque, dtype=float)
        p_mech = speed * torque
        loss = self.loss_map(speed, torque)
        with np.errstate(divide="ignore", invalid="ignore"):
            eta = np.where(p_mech >= 0, p_mech / (p_mech + loss), (-p_mech - loss) / (-p_mech))
        return np.where(np.abs(p_mech) > 1e-9, eta, 0.0)

    def validate(self, path: str) -> None:
        for name in ("max_torque", "max_power", "max_speed", "regen_torque_limit", "regen_power_limit", "inertia"):
            _positive(f"{path}.{name}", getattr(self, name))
        self.loss_map.validate(f"{path}.loss_map")
        if np.any(np.asarray(self.loss_map.values) < 0):
            raise VehicleSpecError(f"{path}.loss_map.values: losses must be >= 0")


@dataclass
class BatterySpec:
    """Traction battery: usable capacity [J], open-circuit voltage [V], internal resistance [Ohm],
    auxiliary (12 V, electronics) power [W], initial state of charge [-]."""

    capacity: Annotated[float, _q("J", "usable battery capacity", plausible=(1.0e5, 1.0e10))]
    open_circuit_voltage: float
    internal_resistance: float
    auxiliary_power: float = 300.0
    initial_soc: float = 0.9

    def validate(self, path: str) -> None:
        _positive(f"{path}.capacity", self.capacity)
        _positive(f"{path}.open_circuit_voltage", self.open_circuit_voltage)
        _nonneg(f"{path}.internal_resistance", self.internal_resistance)
        _nonneg(f"{path}.auxiliary_power", self.auxiliary_power)
        _between(f"{path}.initial_soc", self.initial_soc, 0.0, 1.0)


@dataclass
class ShiftSpec:
    """Shift strategy and clutch: up/downshift engine speeds [rad/s] at zero and full load (linear in between),
    min time between shifts [s], engine-speed sync time constant while slipping [s], max slip time [s],
    launch engine speed [rad/s], slip speed below which the clutch locks [rad/s]."""

    upshift_speed_low: float
    upshift_speed_high: float
    downshift_speed_low: float
    downshift_speed_high: float
    min_interval: float = 1.0
    sync_time_constant: float = 0.08
    max_slip_time: float = 1.5
    launch_speed: float = 130.0
    lock_slip_speed: float = 5.0

    def validate(self, path: str) -> None:
        for name in ("upshift_speed_low", "upshift_speed_high", "downshift_speed_low", "downshift_speed_high",
                     "min_interval", "sync_time_constant", "max_slip_time", "launch_speed", "lock_slip_speed"):
            _positive(f"{path}.{name}", getattr(self, name))
        if self.downshift_speed_low >= self.upshift_speed_low or self.downshift_speed_high >= self.upshift_speed_high:
            raise VehicleSpecError(f"{path}.downshift_speed_low: downshift speeds must be below upshift speeds")


@dataclass
class DrivetrainSpec:
    """Drive-train (eq. 2.17). kind 'ice' (engine + clutch + gearbox) or 'bev' (motor + single gear);
    driven_axle 'rear' | 'front' | 'all'; gear_ratios i_G(G) for G = 1..n; final_drive i_D;
    gearbox_inertia I_G(G) (input side), clutch_inertia I_C, differential_inertia I_D (at differential input)
    [kg m^2]; gearbox_loss[G-1]: f(T_G, omega_G, G) [N m at gearbox output] (x = input torque, y = input speed);
    differential_loss f(T_D, omega_D) [N m at differential output] (x = input torque, y = input speed).
    Losses scale with oil temperature: factor = 1 + (oil_cold_loss_factor - 1) * clip((T_warm - T_oil) /
    (T_warm - 293.15 K), 0, 1.5)."""

    kind: str
    driven_axle: str
    gear_ratios: list[float]
    final_drive: Annotated[float, _q("1", "final drive ratio i_D", plausible=(FINAL_DRIVE_MIN, FINAL_DRIVE_MAX))]
    gearbox_inertia: list[float]
    clutch_inertia: float
    differential_inertia: float
    gearbox_loss: list[Map2D]
    differential_loss: Map2D
    engine: EngineSpec | None = None
    motor: MotorSpec | None = None
    battery: BatterySpec | None = None
    shift: ShiftSpec | None = None
    oil_warm_temperature: float = 363.15
    oil_cold_loss_factor: float = 1.6
    oil_time_constant: float = 1200.0

    @property
    def n_gears(self) -> int:
        return len(self.gear_ratios)

    @property
    def source_inertia(self) -> float:
        """I_E (engine) or motor rotor inertia [kg m^2]."""
        return self.require_engine().inertia if self.kind == "ice" else self.require_motor().inertia

    def require_engine(self) -> EngineSpec:
        """The engine of an 'ice' drive-train; VehicleSpecError when it is missing."""
        if self.engine is None:
            raise VehicleSpecError(f"drivetrain.engine: required for kind {self.kind!r}, got None")
        return self.engine

    def require_shift(self) -> ShiftSpec:
        """The shift strategy of an 'ice' drive-train; VehicleSpecError when it is missing."""
        if self.shift is None:
            raise VehicleSpecError(f"drivetrain.shift: required for kind {self.kind!r}, got None")
        return self.shift

    def require_motor(self) -> MotorSpec:
        """The traction motor of a 'bev' drive-train; VehicleSpecError when it is missing."""
        if self.motor is None:
            raise VehicleSpecError(f"drivetrain.motor: required for kind {self.kind!r}, got None")
        return self.motor

    def require_battery(self) -> BatterySpec:
        """The traction battery of a 'bev' drive-train; VehicleSpecError when it is missing."""
        if self.battery is None:
            raise VehicleSpecError(f"drivetrain.battery: required for kind {self.kind!r}, got None")
        return self.battery

    def reduced_inertia(self, gear: int) -> float:
        """I_red(G) [kg m^2] at the wheels, without the wheels themselves (eq. 2.17); gear 0 = neutral (ICE)."""
        i_d = self.final_drive
        if self.kind == "bev":
            gear = 1  # the motor cannot be disconnected
        if gear == 0:
            return i_d ** 2 * self.differential_inertia
        i_g = self.gear_ratios[gear - 1]
        return i_d ** 2 * self.differential_inertia + (i_d * i_g) ** 2 * (
            self.gearbox_inertia[gear - 1] + self.clutch_inertia + self.source_inertia)

    def validate(self, path: str) -> None:
        if self.kind not in ("ice", "bev"):
            raise VehicleSpecError(f"{path}.kind: must be 'ice' or 'bev', got {self.kind!r}")
        if self.driven_axle not in ("rear", "front", "all"):
            raise VehicleSpecError(f"{path}.driven_axle: must be 'rear', 'front' or 'all', got {self.driven_axle!r}")
        if not self.gear_ratios:
            raise VehicleSpecError(f"{path}.gear_ratios: needs at least one gear")
        if len(self.gear_ratios) > 12:
            raise VehicleSpecError(f"{path}.gear_ratios: at most 12 gears")
        for k, r in enumerate(self.gear_ratios):
            _positive(f"{path}.gear_ratios[{k}]", r)
        _positive(f"{path}.final_drive", self.final_drive)
        if len(self.gearbox_inertia) != self.n_gears:
            raise VehicleSpecError(f"{path}.gearbox_inertia: needs one value per gear ({self.n_gears})")
        for k, r in enumerate(self.gearbox_inertia):
            _nonneg(f"{path}.gearbox_inertia[{k}]", r)
        _nonneg(f"{path}.clutch_inertia", self.clutch_inertia)
        _nonneg(f"{path}.differential_inertia", self.differential_inertia)
        if len(self.gearbox_loss) != self.n_gears:
            raise VehicleSpecError(f"{path}.gearbox_loss: needs one map per gear ({self.n_gears})")
        for k, m in enumerate(self.gearbox_loss):
            m.validate(f"{path}.gearbox_loss[{k}]")
            if np.any(np.asarray(m.values) < 0):
                raise VehicleSpecError(f"{path}.gearbox_loss[{k}].values: loss torques must be >= 0")
        self.differential_loss.validate(f"{path}.differential_loss")
        if np.any(np.asarray(self.differential_loss.values) < 0):
            raise VehicleSpecError(f"{path}.differential_loss.values: loss torques must be >= 0")
        if self.kind == "ice":
            if self.engine is None:
                raise VehicleSpecError(f"{path}.engine: required for kind 'ice'")
            if self.shift is None:
                raise VehicleSpecError(f"{path}.shift: required for kind 'ice'")
            self.engine.validate(f"{path}.engine")
            self.shift.validate(f"{path}.shift")
        else:
            if self.motor is None:
                raise VehicleSpecError(f"{path}.motor: required for kind 'bev'")
            if self.battery is None:
                raise VehicleSpecError(f"{path}.battery: required for kind 'bev'")
            if self.n_gears != 1:
                raise VehicleSpecError(f"{path}.gear_ratios: a 'bev' drive-train has exactly one gear")
            self.motor.validate(f"{path}.motor")
            self.battery.validate(f"{path}.battery")
        _between(f"{path}.oil_warm_temperature", self.oil_warm_temperature, 300.0, 450.0)
        _between(f"{path}.oil_cold_loss_factor", self.oil_cold_loss_factor, 1.0, 10.0)
        _positive(f"{path}.oil_time_constant", self.oil_time_constant)


@dataclass
class BrakeSpec:
    """Friction brakes (T_B = p_B A_B r_B X_B, section 2.7): per-wheel effective piston area A_B [m^2], effective
    radius r_B [m] per axle, nominal pad friction X_B [-] (incl. caliper efficiency), front share of the brake
    torque [-], max pressure [Pa], lumped disc heat capacity per axle [J/K] and cooling [W/K, W/(K m/s)]."""

    front_area: float
    rear_area: float
    front_radius: float
    rear_radius: float
    pad_friction: float = 0.4
    front_share: float = 0.65
    max_pressure: float = 1.6e7
    disc_heat_capacity: float = 8000.0
    disc_cooling: float = 15.0
    disc_cooling_speed: float = 1.5

    def validate(self, path: str) -> None:
        for name in ("front_area", "rear_area", "front_radius", "rear_radius", "max_pressure",
                     "disc_heat_capacity", "disc_cooling"):
            _positive(f"{path}.{name}", getattr(self, name))
        _between(f"{path}.pad_friction", self.pad_friction, 0.05, 1.5)
        _between(f"{path}.front_share", self.front_share, 0.0, 1.0)
        _nonneg(f"{path}.disc_cooling_speed", self.disc_cooling_speed)


@dataclass
class SteeringSpec:
    """Steering ratio table delta_W12 = f(delta_S) (section 5.2.4): steering-wheel angle delta_S [rad] to front
    wheel steer angle delta_W [rad], strictly increasing, through (0, 0)."""

    steering_wheel_angle: list[float]
    wheel_angle: list[float]

    def wheel_from_steering_wheel(self, delta_s):
        return np.interp(delta_s, self.steering_wheel_angle, self.wheel_angle)

    def steering_wheel_from_wheel(self, delta_w):
        return np.interp(delta_w, self.wheel_angle, self.steering_wheel_angle)

    def validate(self, path: str) -> None:
        _increasing(f"{path}.steering_wheel_angle", self.steering_wheel_angle)
        _increasing(f"{path}.wheel_angle", self.wheel_angle)
        if len(self.wheel_angle) != len(self.steering_wheel_angle):
            raise VehicleSpecError(f"{path}.wheel_angle: length differs from steering_wheel_angle")
        if abs(float(np.interp(0.0, self.steering_wheel_angle, self.wheel_angle))) > 1e-6:
            raise VehicleSpecError(f"{path}.wheel_angle: the table must pass through (0, 0)")


@dataclass
class ChannelSensorSpec:
    """One CAN channel: white-noise std, constant bias, resolution (quantisation step, 0 = none) in the channel's SI
    unit, latency [s], outlier scale (typical outlier size, used by the sensor_outliers effect), enabled."""

    noise_std: float = 0.0
    bias: float = 0.0
    resolution: float = 0.0
    latency: float = 0.0
    outlier_scale: float = 1.0
    enabled: bool = True

    def validate(self, path: str) -> None:
        _nonneg(f"{path}.noise_std", self.noise_std)
        _finite(f"{path}.bias", self.bias)
        _nonneg(f"{path}.resolution", self.resolution)
        _between(f"{path}.latency", self.latency, 0.0, 5.0)
        _nonneg(f"{path}.outlier_scale", self.outlier_scale)


@dataclass
class SensorSpec:
    """The CAN-like sensor set: sample rate [Hz] and one ChannelSensorSpec per measured channel (names from
    roadload.channels). drive_torque_gain_error / drive_torque_offset [N m]: error of the engine / motor torque
    model (the CAN torque is a model output, section 5.2.1); speed_scale_error: ESP speed scale error [-]."""

    sample_rate: float = 100.0
    channels: dict[str, ChannelSensorSpec] = field(default_factory=dict)
    drive_torque_gain_error: float = 0.0
    drive_torque_offset: float = 0.0
    speed_scale_error: float = 0.0

    def validate(self, path: str) -> None:

        _between(f"{path}.sample_rate", self.sample_rate, 1.0, 1000.0)
        for name, ch in self.channels.items():
            if name not in MEASURED:
                raise VehicleSpecError(f"{path}.channels.{name}: not a measured channel of the catalogue")
            ch.validate(f"{path}.channels.{name}")
        _between(f"{path}.drive_torque_gain_error", self.drive_torque_gain_error, -0.5, 0.5)
        _finite(f"{path}.drive_torque_offset", self.drive_torque_offset)
        _between(f"{path}.speed_scale_error", self.speed_scale_error, -0.2, 0.2)


@dataclass
class VehicleSpec:
    """A complete vehicle: body, aero, tires, drive-train, brakes, steering table and sensors."""

    name: str
    body: BodySpec
    aero: AeroSpec
    tires: TireSpec
    drivetrain: DrivetrainSpec
    brakes: BrakeSpec
    steering: SteeringSpec
    sensors: SensorSpec = field(default_factory=SensorSpec)
    description: str = ""

    def __post_init__(self) -> None:
        self.validate()

    # ------------------------------------------------------------------ derived quantities
    @property
    def mass(self) -> float:
        """Nominal mass m_V [kg]."""
        return self.body.mass

    @property
    def wheel_radius(self) -> float:
        return self.tires.dynamic_radius

    @property
    def drag_area(self) -> float:
        return self.aero.drag_area

    def effective_mass(self, gear: int, mass: float | None = None) -> float:
        """m_V + (I_red(G) + 4 I_W) / r_W^2 [kg] with the clutch engaged (gear 0 = neutral / clutch open)."""
        m = self.body.mass if mass is None else mass
        r = self.tires.dynamic_radius
        return m + (self.drivetrain.reduced_inertia(gear) + 4.0 * self.tires.wheel_inertia) / r ** 2

    def understeer_gradient(self, mass: float | None = None) -> float:
        """EG = m/l (l_34/X_12 - l_12/X_34) [rad s^2/m] of the linear single-track model."""
        m = self.body.mass if mass is None else mass
        b, t = self.body, self.tires
        return m / b.wheelbase * (b.cg_to_rear_axle / t.cornering_stiffness_front
                                  - b.cg_to_front_axle / t.cornering_stiffness_rear)

    def yaw_rate_gain(self, speed: float, mass: float | None = None) -> float:
        """Steady-state yaw-rate gain psi_dot/delta_W = v / (l + EG v^2) [1/s]."""
        return speed / (self.body.wheelbase + self.understeer_gradient(mass) * speed ** 2)

    def equivalent_cornering_stiffness(self) -> float:
        """c_yW of eq. 2.15 equivalent to eq. 2.14: 1/(4 c_y) = (l_34^2/X_12 + l_12^2/X_34)/l^2 [N/rad]."""
        b, t = self.body, self.tires
        inv = (b.cg_to_rear_axle ** 2 / t.cornering_stiffness_front
               + b.cg_to_front_axle ** 2 / t.cornering_stiffness_rear) / b.wheelbase ** 2
        return 1.0 / (4.0 * inv)

    # ------------------------------------------------------------------ validation and I/O
    def validate(self, path: str = "vehicle") -> None:
        if not isinstance(self.name, str) or not self.name:
            raise VehicleSpecError(f"{path}.name: must be a non-empty string")
        check_declared(self, path)
        for part in ("body", "aero", "tires", "drivetrain", "brakes", "steering", "sensors"):
            getattr(self, part).validate(f"{path}.{part}")
        check_physics(self, path)

    def to_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)

    @classmethod
    def from_dict(cls, data: dict[str, Any], path: str = "vehicle") -> "VehicleSpec":
        return _build(cls, data, path)

    def replace(self, **changes: Any) -> "VehicleSpec":
        """A validated copy with dotted-path changes, e.g. ``spec.replace(**{"body.mass": 2100.0})``."""
        d = self.to_dict()
        for key, value in changes.items():
            node = d
            parts = key.split(".")
            for p in parts[:-1]:
                if not isinstance(node, dict) or p not in node:
                    raise VehicleSpecError(f"vehicle.{key}: no such field")
                node = node[p]
            if not isinstance(node, dict) or parts[-1] not in node:
                raise VehicleSpecError(f"vehicle.{key}: no such field")
            node[parts[-1]] = value
        return VehicleSpec.from_dict(d)

    def save(self, path: str | os.PathLike) -> Path:
        return save_vehicle(self, path)


# ----------------------------------------------------------------------------------------------- dict -> dataclass
def _build(tp: Any, data: Any, path: str) -> Any:
    """Convert JSON-like data into the annotated type, naming the field on any error (no validation of values)."""
    origin = typing.get_origin(tp)
    args = typing.get_args(tp)
    if origin in (typing.Union, types.UnionType):
        if data is None and type(None) in args:
            return None
        inner = [a for a in args if a is not type(None)]
        return _build(inner[0], data, path)
    if isinstance(tp, type) and dataclasses.is_dataclass(tp):
        if isinstance(data, tp):
            return data
        if not isinstance(data, dict):
            raise VehicleSpecError(f"{path}: expected an object, got {type(data).__name__}")
        hints = typing.get_type_hints(tp)
        names = {f.name for f in dataclasses.fields(tp)}
        unknown = sorted(set(data) - names)
        if unknown:
            raise VehicleSpecError(f"{path}.{unknown[0]}: unknown field (known: {sorted(names)})")
        kwargs = {}
        for f in dataclasses.fields(tp):
            if f.name in data:
                kwargs[f.name] = _build(hints[f.name], data[f.name], f"{path}.{f.name}")
            elif f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING:
                raise VehicleSpecError(f"{path}.{f.name}: missing required field")
        return tp(**kwargs)
    if origin is list:
        if not isinstance(data, (list, tuple)):
            raise VehicleSpecError(f"{path}: expected a list, got {type(data).__name__}")
        return [_build(args[0], x, f"{path}[{i}]") for i, x in enumerate(data)]
    if origin is dict:
        if not isinstance(data, dict):
            raise VehicleSpecError(f"{path}: expected an object, got {type(data).__name__}")
        return {str(k): _build(args[1], v, f"{path}.{k}") for k, v in data.items()}
    if tp is float:
        if isinstance(data, bool) or not isinstance(data, (int, float)):
            raise VehicleSpecError(f"{path}: expected a number, got {data!r}")
        return float(data)
    if tp is int:
        if isinstance(data, bool) or not isinstance(data, int):
            raise VehicleSpecError(f"{path}: expected an integer, got {data!r}")
        return data
    if tp is bool:
        if not isinstance(data, bool):
            raise VehicleSpecError(f"{path}: expected true/false, got {data!r}")
        return data
    if tp is str:
        if not isinstance(data, str):
            raise VehicleSpecError(f"{path}: expected a string, got {data!r}")
        return data
    raise VehicleSpecError(f"{path}: unsupported type {tp!r}")  # pragma: no cover - programming error


def vehicle_json_schema() -> dict[str, Any]:
    """The JSON schema of a vehicle spec file (pydantic): fields with units, lower bounds and plausible ranges."""
    return TypeAdapter(VehicleSpec).json_schema()


def load_vehicle(path: str | os.PathLike) -> VehicleSpec:
    """Read a vehicle JSON file; errors name the file and the field."""
    path = Path(path)
    try:
        text = path.read_text()
    except OSError as exc:
        raise VehicleSpecError(f"{path}: cannot read vehicle file ({exc.strerror})") from None
    try:
        data = json.loads(text)
    except json.JSONDecodeError as exc:
        raise VehicleSpecError(f"{path}: not valid JSON ({exc.msg} at line {exc.lineno})") from None
    try:
        return VehicleSpec.from_dict(data)
    except VehicleSpecError as exc:
        raise VehicleSpecError(f"{path}: {exc}") from None


def save_vehicle(spec: VehicleSpec, path: str | os.PathLike) -> Path:
    """Write a vehicle spec as JSON atomically."""
    return write_json(path, spec.to_dict())
