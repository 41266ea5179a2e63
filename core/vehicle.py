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
import os
import typing
from dataclasses import field
from pathlib import Path
from typing import Annotated, Any, Callable, Literal, TypeVar

import numpy as np
from pydantic import ConfigDict, Field, Strict, TypeAdapter, ValidationError, field_validator, model_validator
from pydantic.fields import FieldInfo

from .fileio import write_json
from .schema import field_info_at, loc_text, spec_dataclass
from .units import G, STANDARD_AIR_DENSITY
from .channels import MEASURED

__all__ = [
    "VehicleSpecError", "Curve", "Map2D", "BodySpec", "AeroSpec", "TireSpec", "EngineSpec", "MotorSpec",
    "BatterySpec", "ShiftSpec", "DrivetrainSpec", "BrakeSpec", "SteeringSpec", "ChannelSensorSpec", "SensorSpec",
    "VehicleSpec", "load_vehicle", "save_vehicle", "parse_spec", "check_physics",
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

#: every spec part: unknown keys are errors, NaN/inf refused; numbers are JSON numbers (``Real``), not strings
_CONFIG = ConfigDict(extra="forbid", allow_inf_nan=False)
#: a finite JSON number: int or float, never a string or a bool (pydantic strict float; NaN/inf refused by _CONFIG)
Real = Annotated[float, Strict()]


def _q(unit: str, doc: str, *, plausible: tuple[float, float] | None = None, gt: float | None = 0.0,
       ge: float | None = None, le: float | None = None) -> FieldInfo:
    """A declared physical quantity (pydantic Field): > gt (or >= ge), <= le, inside the plausible range
    [lo, hi] of a road vehicle, in `unit`; bounds, unit and meaning also show in the JSON schema of the spec."""
    extra: dict[str, Any] = {"unit": unit}
    if plausible is not None:
        extra["plausible"] = list(plausible)
        ge, le = plausible
    return Field(gt=gt, ge=ge, le=le, description=f"{doc} [{unit}]", json_schema_extra=extra)


class _FieldError(ValueError):
    """Raised by a validator: `sub` is the field (relative to the validated part) the message is about."""

    def __init__(self, sub: str, message: str) -> None:
        super().__init__(message)
        self.sub = sub


T = TypeVar("T")


def _spec_error(exc: ValidationError, cls: Any) -> VehicleSpecError:
    return VehicleSpecError(spec_error_text(exc, cls, "vehicle" if cls.__name__ == "VehicleSpec" else cls.__name__))


@typing.dataclass_transform(field_specifiers=(dataclasses.field, Field))
def _spec(cls: type[T]) -> type[T]:
    """A spec part: a pydantic dataclass whose errors are one-line VehicleSpecErrors naming the field."""
    return spec_dataclass(_CONFIG, _spec_error)(cls)


def _declared_bounds(info: FieldInfo | None) -> tuple[dict[str, Any], dict[str, Any]]:
    """(json_schema_extra, {gt/ge/lt/le: bound}) of a field's declaration (empty for an undeclared field)."""
    if info is None:
        return {}, {}
    extra = dict(info.json_schema_extra) if isinstance(info.json_schema_extra, dict) else {}
    bounds = {k: getattr(m, k) for m in info.metadata for k in ("gt", "ge", "lt", "le")
              if getattr(m, k, None) is not None}
    return extra, bounds


def _interval_text(bounds: dict[str, Any]) -> str:
    """The interval of gt/ge/lt/le bounds, e.g. ``(0, 1]`` (``(-inf`` / ``inf)`` on an open side)."""
    lo = f"({bounds['gt']:g}" if "gt" in bounds else (f"[{bounds['ge']:g}" if "ge" in bounds else "(-inf")
    hi = f"{bounds['lt']:g})" if "lt" in bounds else (f"{bounds['le']:g}]" if "le" in bounds else "inf)")
    return f"{lo}, {hi}"


def _bound_text(value: Any, info: FieldInfo | None) -> str:
    """The bound a number broke, from its declaration: > gt, the plausible range, or [ge, le]; with the unit."""
    extra, bounds = _declared_bounds(info)
    unit = str(extra.get("unit", ""))
    u = f" [{unit}]" if unit else ""
    if not isinstance(value, (int, float)) or value != value or value in (float("inf"), float("-inf")):
        return f"must be a finite number{u}, got {value!r}"
    if "gt" in bounds and not value > bounds["gt"]:
        return f"must be > {bounds['gt']:g}{u}, got {value!r}"
    if "plausible" in extra:
        lo, hi = (float(b) for b in extra["plausible"])
        v_unit = "" if unit in ("", "1") else f" {unit}"
        return (f"{value!r}{v_unit} is outside the plausible range [{lo:g}, {hi:g}]{v_unit} of a road vehicle "
                f"({info.description if info is not None else ''})")
    return f"must lie in {_interval_text(bounds)}{u}, got {value!r}"


_TYPE_WORDS = {"float_type": "a number", "float_parsing": "a number", "int_type": "an integer",
               "int_from_float": "an integer", "bool_type": "true/false", "string_type": "a string",
               "list_type": "a list", "dict_type": "an object", "dataclass_type": "an object",
               "dataclass_exact_type": "an object"}


def spec_error_text(exc: ValidationError, root_type: Any, root: str = "vehicle") -> str:
    """One line for the first error of a spec's ValidationError: ``<root>.<field path>: <problem>`` naming the
    value, the bound and the unit (the style of every spec error, e.g. ``vehicle.body.mass: must be > 0 [kg]``)."""
    err = exc.errors(include_url=False)[0]
    loc, kind, value = tuple(err["loc"]), err["type"], err.get("input")
    names = list(getattr(root_type, "__pydantic_fields__", {}))
    if loc and isinstance(loc[0], int) and loc[0] < len(names):  # a positional argument: name its field
        loc = (names[loc[0]],) + loc[1:]
    ctx = err.get("ctx") or {}
    where = loc_text(loc, root)
    _, info = field_info_at(root_type, loc)
    if kind == "value_error" and isinstance(ctx.get("error"), ValueError):
        cause = ctx["error"]
        if isinstance(cause, _FieldError):
            where = f"{where}.{cause.sub}" if not cause.sub.startswith("[") else where + cause.sub
        return f"{where}: {cause}"
    if kind in ("greater_than", "greater_than_equal", "less_than", "less_than_equal", "finite_number"):
        return f"{where}: {_bound_text(value, info)}"
    if kind in _TYPE_WORDS:
        unit = _unit(info)
        got = type(value).__name__ if kind in ("list_type", "dict_type", "dataclass_type") else repr(value)
        return f"{where}: expected {_TYPE_WORDS[kind]}{unit}, got {got}"
    if kind in ("missing", "missing_argument", "missing_keyword_argument"):
        return f"{where}: missing required field"
    if kind in ("unexpected_keyword_argument", "extra_forbidden", "unexpected_positional_argument"):
        owner, _ = field_info_at(root_type, loc[:-1] + ("",)) if len(loc) > 1 else (root_type, None)
        known = sorted(getattr(owner, "__pydantic_fields__", {}))
        return f"{where}: unknown field (known: {known})"
    if kind in _CHOICE_AND_LENGTH_WORDS:
        return f"{where}: " + _CHOICE_AND_LENGTH_WORDS[kind].format(value=value, **ctx)
    return f"{where}: {err['msg']}, got {value!r}"


#: pydantic error type -> our wording (filled from the error's context: expected, min_length, actual_length, ...)
_CHOICE_AND_LENGTH_WORDS = {
    "literal_error": "must be {expected}, got {value!r}",
    "string_too_short": "must be a non-empty string, got {value!r}",
    "too_short": "needs at least {min_length} item(s), got {actual_length}",
    "too_long": "at most {max_length} items, got {actual_length}",
}


def _unit(info: FieldInfo | None) -> str:
    extra = info.json_schema_extra if info is not None else None
    return f" [{extra['unit']}]" if isinstance(extra, dict) and extra.get("unit") else ""


_ADAPTERS: dict[type, TypeAdapter] = {}


def parse_spec(tp: type[T], data: Any, path: str = "vehicle") -> T:
    """Validate JSON-like data into the spec type `tp` (a part or a whole VehicleSpec); VehicleSpecError naming
    the field under `path` on any problem."""
    if tp not in _ADAPTERS:
        _ADAPTERS[tp] = TypeAdapter(tp)
    try:
        return typing.cast(T, _ADAPTERS[tp].validate_python(data))
    except ValidationError as exc:
        raise VehicleSpecError(spec_error_text(exc, tp, path)) from None


class _Part:
    """Methods shared by every spec part."""

    @classmethod
    def from_dict(cls: type[T], data: dict[str, Any], path: str = "vehicle") -> T:
        """Build from JSON-like data; errors name the field under `path`."""
        return parse_spec(cls, data, path)

    def to_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(typing.cast(Any, self))

    def validate(self, path: str = "vehicle") -> None:
        """Re-validate after fields were changed in place (construction validates already)."""
        parse_spec(type(self), _fields_of(self), path)


def _fields_of(obj: Any) -> Any:
    """A spec as nested dicts for re-validation: parts become dicts, tables are passed as they are (not copied,
    unlike ``dataclasses.asdict``; pydantic builds new lists)."""
    if dataclasses.is_dataclass(obj) and not isinstance(obj, type):
        return {f.name: _fields_of(getattr(obj, f.name)) for f in dataclasses.fields(obj)}
    if isinstance(obj, dict):
        return {k: _fields_of(v) for k, v in obj.items()}
    if isinstance(obj, list) and obj and dataclasses.is_dataclass(obj[0]):
        return [_fields_of(v) for v in obj]
    return obj


def _flat_road_speed(power: float, mass: float, tires: "TireSpec", drag_area: float, efficiency: float = 0.9) -> float:
    """Speed [m/s] where P eta = (m g f_r(v) + rho/2 c_x A v^2) v on a flat road, to 0.01 m/s (the power need
    rises with v: the last grid speed below the available power, on a 1 m/s grid from 0 to 200 m/s, then on a
    0.01 m/s grid inside that step; two vectorised evaluations instead of a scalar bisection)."""
    lo = 0.0
    for step in (1.0, 0.01):
        v = lo + step * np.arange(0.0, 201.0 if step == 1.0 else 101.0)
        need = (mass * G * tires.rolling_resistance_coefficient(v) + 0.5 * STANDARD_AIR_DENSITY * drag_area
                * v ** 2) * v
        below = np.flatnonzero(need < power * efficiency)
        lo = float(v[below[-1]]) if below.size else lo
    return lo


def check_physics(spec: "VehicleSpec") -> None:
    """Cross-field check of a complete spec (run by VehicleSpec's model validator): a reachable top speed (min of
    the shaft-speed limit in the top gear and the flat-road power limit) above TOP_SPEED_MIN; raises a
    ValueError naming the limiting field."""
    d = spec.drivetrain
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
        raise _FieldError(where, f"top speed {v_top:.3g} m/s [{v_top * 3.6:.3g} km/h] is below "
                                 f"{TOP_SPEED_MIN:g} m/s [{TOP_SPEED_MIN * 3.6:g} km/h] ({cause})")


def _strictly_increasing(values: list[float]) -> list[float]:
    if not np.all(np.diff(np.asarray(values, dtype=float)) > 0):
        raise ValueError("must be strictly increasing")
    return values


def _nonnegative_table(what: str) -> Callable[[Any], Any]:
    """An after-validator of a table part: every entry of ``values`` >= 0."""
    def check(table: Any) -> Any:
        if np.any(np.asarray(table.values) < 0):
            raise _FieldError("values", f"{what} must be >= 0")
        return table
    return check


# ----------------------------------------------------------------------------------------------- tables
Axis = Annotated[list[Real], Field(min_length=2, description="strictly increasing breakpoints")]


@_spec
class Curve(_Part):
    """A 1-D lookup table y(x), linear interpolation, clamped at the ends."""

    x: Axis
    y: list[Real]

    _x_increasing = field_validator("x")(_strictly_increasing)

    @model_validator(mode="after")
    def _same_length(self) -> "Curve":
        if len(self.y) != len(self.x):
            raise _FieldError("y", f"length {len(self.y)} differs from x length {len(self.x)}")
        return self

    def __call__(self, x):
        return np.interp(x, self.x, self.y)


@_spec
class Map2D(_Part):
    """A 2-D lookup table ``values[i][j] = f(x[i], y[j])``, bilinear interpolation, clamped at the edges."""

    x: Axis
    y: Axis
    values: list[list[Real]]

    _axes_increasing = field_validator("x", "y")(_strictly_increasing)

    @model_validator(mode="after")
    def _shape(self) -> "Map2D":
        shape = (len(self.values), *{len(row) for row in self.values})
        if shape != (len(self.x), len(self.y)):
            raise _FieldError("values", f"shape {shape} differs from (len(x), len(y)) = "
                                        f"({len(self.x)}, {len(self.y)})")
        return self

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
@_spec
class BodySpec(_Part):
    """Mass and geometry. mass m_V [kg] nominal incl. driver; wheelbase l = l_12 + l_34 [m];
    cg_to_front_axle l_12 [m]; yaw_inertia I_z [kg m^2]; pitch/roll gradients [rad per m/s^2] tilt the body-fixed
    accelerometers (eq. 4.4/5.2: nose up under acceleration, roll outward in corners)."""

    mass: Annotated[Real, _q("kg", "nominal mass incl. driver", plausible=(MASS_MIN, MASS_MAX))]
    wheelbase: Annotated[Real, _q("m", "wheelbase l = l_12 + l_34", plausible=(1.0, 10.0))]
    cg_to_front_axle: Annotated[Real, _q("m", "CG-to-front-axle distance l_12")]
    cg_height: Annotated[Real, _q("m", "CG height", plausible=(0.1, 3.5))] = 0.55
    track_front: Annotated[Real, _q("m", "front track width", plausible=(0.5, 3.0))] = 1.6
    track_rear: Annotated[Real, _q("m", "rear track width", plausible=(0.5, 3.0))] = 1.6
    yaw_inertia: Annotated[Real, _q("kg m^2", "yaw inertia I_z", plausible=(10.0, 2.0e6))] = 3000.0
    pitch_gradient: Annotated[Real, _q("rad/(m/s^2)", "pitch gradient", gt=None, ge=0.0, le=0.05)] = 0.004
    roll_gradient: Annotated[Real, _q("rad/(m/s^2)", "roll gradient", gt=None, ge=0.0, le=0.05)] = 0.006

    @model_validator(mode="after")
    def _cg_inside_wheelbase(self) -> "BodySpec":
        if self.cg_to_front_axle >= self.wheelbase:
            raise _FieldError("cg_to_front_axle", f"must be < wheelbase ({self.wheelbase} m) [m], "
                                                  f"got {self.cg_to_front_axle!r}")
        return self

    @property
    def cg_to_rear_axle(self) -> float:
        """l_34 [m]."""
        return self.wheelbase - self.cg_to_front_axle


@_spec
class AeroSpec(_Part):
    """Aerodynamics (eq. 2.7): c_x(psi_a) = c_w cos(psi_a) (1 + yaw_drag_factor sin^2 psi_a), frontal area A_V."""

    drag_coefficient: Annotated[Real, _q("1", "drag coefficient c_w", plausible=(1e-3, 2.0))]
    frontal_area: Annotated[Real, _q("m^2", "frontal area A_V", plausible=(0.3, 15.0))]
    yaw_drag_factor: Annotated[Real, _q("1", "yaw drag factor", gt=None, ge=0.0, le=5.0)] = 0.3

    @property
    def drag_area(self) -> float:
        """c_x*A_V [m^2] at zero air approach angle."""
        return self.drag_coefficient * self.frontal_area


@_spec
class TireSpec(_Part):
    """Tires and wheels: dynamic radius r_W [m]; f_r(v) = f_r0 + f_r1 v + f_r4 v^4 (eq. 2.10, f_r1 [s/m],
    f_r4 [s^4/m^4]); axle cornering stiffnesses X_12, X_34 [N/rad] (eq. 2.12); longitudinal slip stiffness c_xW
    per wheel [N] (eq. 2.3a); wheel inertia I_W per wheel incl. brake disc [kg m^2]; toe_in per front wheel [rad]."""

    dynamic_radius: Annotated[Real, _q("m", "dynamic tyre radius r_W", plausible=(0.1, 1.5))]
    rolling_resistance_f0: Annotated[Real, _q("1", "rolling resistance f_r0 (eq. 2.10)", gt=None, ge=1e-4,
                                              le=0.1)]
    rolling_resistance_f1: Annotated[Real, _q("s/m", "rolling resistance f_r1 (eq. 2.10)", gt=None, ge=0.0,
                                              le=1e-2)]
    rolling_resistance_f4: Annotated[Real, _q("s^4/m^4", "rolling resistance f_r4 (eq. 2.10)", gt=None, ge=0.0,
                                              le=1e-6)]
    cornering_stiffness_front: Annotated[Real, _q("N/rad", "front axle cornering stiffness X_12 (eq. 2.12)")]
    cornering_stiffness_rear: Annotated[Real, _q("N/rad", "rear axle cornering stiffness X_34 (eq. 2.12)")]
    longitudinal_stiffness: Annotated[Real, _q("N", "longitudinal slip stiffness c_xW per wheel")] = 8.0e4
    wheel_inertia: Annotated[Real, _q("kg m^2", "wheel inertia I_W per wheel")] = 1.0
    toe_in: Annotated[Real, _q("rad", "toe-in per front wheel", gt=None, ge=0.0, le=0.02)] = 0.0015

    def rolling_resistance_coefficient(self, v):
        """f_r(v) (eq. 2.10)."""
        v = np.asarray(v, dtype=float)
        return self.rolling_resistance_f0 + self.rolling_resistance_f1 * v + self.rolling_resistance_f4 * v ** 4


@_spec
class EngineSpec(_Part):
    """Combustion engine: speeds [rad/s]; full_load T_max(omega) and drag (motoring, negative) torque curves [N m];
    fuel_power map P_fuel(omega, T_E) [W] (x = speed, y = torque; zero below the drag curve = fuel cut);
    inertia I_E [kg m^2]."""

    idle_speed: Annotated[Real, _q("rad/s", "idle speed", plausible=(20.0, 200.0))]
    max_speed: Annotated[Real, _q("rad/s", "maximum engine speed", plausible=(100.0, 1500.0))]
    full_load: Curve
    drag: Curve
    fuel_power: Map2D
    inertia: Annotated[Real, _q("kg m^2", "engine inertia I_E")]

    _fuel_nonnegative = field_validator("fuel_power")(_nonnegative_table("fuel power"))

    @model_validator(mode="after")
    def _curves(self) -> "EngineSpec":
        if self.max_speed <= self.idle_speed:
            raise _FieldError("max_speed", f"must exceed idle_speed ({self.idle_speed:g} rad/s) [rad/s], "
                                           f"got {self.max_speed!r}")
        if np.any(np.asarray(self.full_load.y) <= 0):
            raise _FieldError("full_load.y", "full-load torque must be > 0 [N*m]")
        if np.any(np.asarray(self.drag.y) > 0):
            raise _FieldError("drag.y", "drag torque must be <= 0 [N*m]")
        return self


@_spec
class MotorSpec(_Part):
    """Traction motor: torque / power limits (motoring) [N m, W], regen limits (magnitudes) [N m, W], max speed
    [rad/s], rotor inertia [kg m^2], loss_map P_loss(omega, T) [W] >= 0 (x = speed, y = torque); electrical power
    P_el = T omega + P_loss (efficiency map: see ``MotorSpec.efficiency``)."""

    max_torque: Annotated[Real, _q("N*m", "maximum motor torque", plausible=(5.0, 1.0e5))]
    max_power: Annotated[Real, _q("W", "maximum motor power", plausible=(1.0e3, 2.0e6))]
    max_speed: Annotated[Real, _q("rad/s", "maximum motor speed", plausible=(50.0, 3000.0))]
    regen_torque_limit: Annotated[Real, _q("N*m", "regenerative torque limit (magnitude)")]
    regen_power_limit: Annotated[Real, _q("W", "regenerative power limit (magnitude)")]
    inertia: Annotated[Real, _q("kg m^2", "rotor inertia")]
    loss_map: Map2D

    _losses_nonnegative = field_validator("loss_map")(_nonnegative_table("losses"))

    def efficiency(self, speed, torque):
        """Motor efficiency eta(omega, T) [-] derived from the loss map (motoring: P_m/P_el; generating: P_el/P_m)."""
        speed = np.asarray(speed, dtype=float)
        torque = np.asarray(torque, dtype=float)
        p_mech = speed * torque
        loss = self.loss_map(speed, torque)
        with np.errstate(divide="ignore", invalid="ignore"):
            eta = np.where(p_mech >= 0, p_mech / (p_mech + loss), (-p_mech - loss) / (-p_mech))
        return np.where(np.abs(p_mech) > 1e-9, eta, 0.0)


@_spec
class BatterySpec(_Part):
    """Traction battery: usable capacity [J], open-circuit voltage [V], internal resistance [Ohm],
    auxiliary (12 V, electronics) power [W], initial state of charge [-]."""

    capacity: Annotated[Real, _q("J", "usable battery capacity", plausible=(1.0e5, 1.0e10))]
    open_circuit_voltage: Annotated[Real, _q("V", "open-circuit voltage")]
    internal_resistance: Annotated[Real, _q("Ohm", "internal resistance", gt=None, ge=0.0)]
    auxiliary_power: Annotated[Real, _q("W", "auxiliary power", gt=None, ge=0.0)] = 300.0
    initial_soc: Annotated[Real, _q("1", "initial state of charge", gt=None, ge=0.0, le=1.0)] = 0.9


@_spec
class ShiftSpec(_Part):
    """Shift strategy and clutch: up/downshift engine speeds [rad/s] at zero and full load (linear in between),
    min time between shifts [s], engine-speed sync time constant while slipping [s], max slip time [s],
    launch engine speed [rad/s], slip speed below which the clutch locks [rad/s]."""

    upshift_speed_low: Annotated[Real, _q("rad/s", "upshift engine speed at zero load")]
    upshift_speed_high: Annotated[Real, _q("rad/s", "upshift engine speed at full load")]
    downshift_speed_low: Annotated[Real, _q("rad/s", "downshift engine speed at zero load")]
    downshift_speed_high: Annotated[Real, _q("rad/s", "downshift engine speed at full load")]
    min_interval: Annotated[Real, _q("s", "minimum time between shifts")] = 1.0
    sync_time_constant: Annotated[Real, _q("s", "engine-speed sync time constant while slipping")] = 0.08
    max_slip_time: Annotated[Real, _q("s", "maximum clutch slip time")] = 1.5
    launch_speed: Annotated[Real, _q("rad/s", "launch engine speed")] = 130.0
    lock_slip_speed: Annotated[Real, _q("rad/s", "slip speed below which the clutch locks")] = 5.0

    @model_validator(mode="after")
    def _downshift_below_upshift(self) -> "ShiftSpec":
        if self.downshift_speed_low >= self.upshift_speed_low or self.downshift_speed_high >= self.upshift_speed_high:
            raise _FieldError("downshift_speed_low", "downshift speeds must be below upshift speeds [rad/s]")
        return self


GearRatio = Annotated[Real, _q("1", "gearbox ratio i_G", plausible=(GEAR_RATIO_MIN, GEAR_RATIO_MAX))]


@_spec
class DrivetrainSpec(_Part):
    """Drive-train (eq. 2.17). kind 'ice' (engine + clutch + gearbox) or 'bev' (motor + single gear);
    driven_axle 'rear' | 'front' | 'all'; gear_ratios i_G(G) for G = 1..n; final_drive i_D;
    gearbox_inertia I_G(G) (input side), clutch_inertia I_C, differential_inertia I_D (at differential input)
    [kg m^2]; gearbox_loss[G-1]: f(T_G, omega_G, G) [N m at gearbox output] (x = input torque, y = input speed);
    differential_loss f(T_D, omega_D) [N m at differential output] (x = input torque, y = input speed).
    Losses scale with oil temperature: factor = 1 + (oil_cold_loss_factor - 1) * clip((T_warm - T_oil) /
    (T_warm - 293.15 K), 0, 1.5)."""

    kind: Literal["ice", "bev"]
    driven_axle: Literal["rear", "front", "all"]
    gear_ratios: Annotated[list[GearRatio], Field(min_length=1, max_length=12,
                                                  description="gear ratios i_G(G), strictly decreasing [1]")]
    final_drive: Annotated[Real, _q("1", "final drive ratio i_D", plausible=(FINAL_DRIVE_MIN, FINAL_DRIVE_MAX))]
    gearbox_inertia: list[Annotated[Real, _q("kg m^2", "gearbox inertia I_G(G)", gt=None, ge=0.0)]]
    clutch_inertia: Annotated[Real, _q("kg m^2", "clutch inertia I_C", gt=None, ge=0.0)]
    differential_inertia: Annotated[Real, _q("kg m^2", "differential inertia I_D", gt=None, ge=0.0)]
    gearbox_loss: list[Map2D]
    differential_loss: Map2D
    engine: EngineSpec | None = None
    motor: MotorSpec | None = None
    battery: BatterySpec | None = None
    shift: ShiftSpec | None = None
    oil_warm_temperature: Annotated[Real, _q("K", "warm oil temperature", gt=None, ge=300.0, le=450.0)] = 363.15
    oil_cold_loss_factor: Annotated[Real, _q("1", "loss factor of cold oil", gt=None, ge=1.0, le=10.0)] = 1.6
    oil_time_constant: Annotated[Real, _q("s", "oil warm-up time constant")] = 1200.0

    _differential_loss_nonnegative = field_validator("differential_loss")(_nonnegative_table("loss torques"))

    @field_validator("gear_ratios")
    @classmethod
    def _gear_ratios_decreasing(cls, ratios: list[float]) -> list[float]:
        """i_G(1) > i_G(2) > ...: a gearbox whose ratios do not fall from first gear up is a typo."""
        for k in range(len(ratios) - 1):
            if ratios[k + 1] >= ratios[k]:
                raise ValueError(f"must be strictly decreasing from first gear up, got {ratios[k]!r} then "
                                 f"{ratios[k + 1]!r} at gears {k + 1}, {k + 2} [1]")
        return ratios

    @field_validator("gearbox_loss")
    @classmethod
    def _gearbox_losses_nonnegative(cls, maps: list[Map2D]) -> list[Map2D]:
        for k, m in enumerate(maps):
            if np.any(np.asarray(m.values) < 0):
                raise _FieldError(f"[{k}].values", "loss torques must be >= 0 [N*m]")
        return maps

    @model_validator(mode="after")
    def _parts_of_the_kind(self) -> "DrivetrainSpec":
        """One gearbox inertia and loss map per gear; an ICE has an engine and a shift strategy, a BEV a motor,
        a battery and exactly one gear."""
        if len(self.gearbox_inertia) != self.n_gears:
            raise _FieldError("gearbox_inertia", f"needs one value per gear ({self.n_gears}), "
                                                 f"got {len(self.gearbox_inertia)}")
        if len(self.gearbox_loss) != self.n_gears:
            raise _FieldError("gearbox_loss", f"needs one map per gear ({self.n_gears}), got {len(self.gearbox_loss)}")
        needed = ("engine", "shift") if self.kind == "ice" else ("motor", "battery")
        for part in needed:
            if getattr(self, part) is None:
                raise _FieldError(part, f"required for kind {self.kind!r}")
        if self.kind == "bev" and self.n_gears != 1:
            raise _FieldError("gear_ratios", f"a 'bev' drive-train has exactly one gear, got {self.n_gears}")
        return self

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


@_spec
class BrakeSpec(_Part):
    """Friction brakes (T_B = p_B A_B r_B X_B, section 2.7): per-wheel effective piston area A_B [m^2], effective
    radius r_B [m] per axle, nominal pad friction X_B [-] (incl. caliper efficiency), front share of the brake
    torque [-], max pressure [Pa], lumped disc heat capacity per axle [J/K] and cooling [W/K, W/(K m/s)]."""

    front_area: Annotated[Real, _q("m^2", "front piston area A_B per wheel")]
    rear_area: Annotated[Real, _q("m^2", "rear piston area A_B per wheel")]
    front_radius: Annotated[Real, _q("m", "front effective brake radius r_B")]
    rear_radius: Annotated[Real, _q("m", "rear effective brake radius r_B")]
    pad_friction: Annotated[Real, _q("1", "pad friction X_B", gt=None, ge=0.05, le=1.5)] = 0.4
    front_share: Annotated[Real, _q("1", "front share of the brake torque", gt=None, ge=0.0, le=1.0)] = 0.65
    max_pressure: Annotated[Real, _q("Pa", "maximum brake pressure")] = 1.6e7
    disc_heat_capacity: Annotated[Real, _q("J/K", "disc heat capacity per axle")] = 8000.0
    disc_cooling: Annotated[Real, _q("W/K", "disc cooling at standstill")] = 15.0
    disc_cooling_speed: Annotated[Real, _q("W/(K m/s)", "disc cooling per speed", gt=None, ge=0.0)] = 1.5


@_spec
class SteeringSpec(_Part):
    """Steering ratio table delta_W12 = f(delta_S) (section 5.2.4): steering-wheel angle delta_S [rad] to front
    wheel steer angle delta_W [rad], strictly increasing, through (0, 0)."""

    steering_wheel_angle: Axis
    wheel_angle: Axis

    _angles_increasing = field_validator("steering_wheel_angle", "wheel_angle")(_strictly_increasing)

    @model_validator(mode="after")
    def _through_origin(self) -> "SteeringSpec":
        if len(self.wheel_angle) != len(self.steering_wheel_angle):
            raise _FieldError("wheel_angle", "length differs from steering_wheel_angle")
        if abs(float(np.interp(0.0, self.steering_wheel_angle, self.wheel_angle))) > 1e-6:
            raise _FieldError("wheel_angle", "the table must pass through (0, 0) [rad]")
        return self

    def wheel_from_steering_wheel(self, delta_s):
        return np.interp(delta_s, self.steering_wheel_angle, self.wheel_angle)

    def steering_wheel_from_wheel(self, delta_w):
        return np.interp(delta_w, self.wheel_angle, self.steering_wheel_angle)


@_spec
class ChannelSensorSpec(_Part):
    """One CAN channel: white-noise std, constant bias, resolution (quantisation step, 0 = none) in the channel's SI
    unit, latency [s], outlier scale (typical outlier size, used by the sensor_outliers effect), enabled."""

    noise_std: Annotated[Real, _q("channel unit", "white-noise standard deviation", gt=None, ge=0.0)] = 0.0
    bias: Annotated[Real, _q("channel unit", "constant bias", gt=None)] = 0.0
    resolution: Annotated[Real, _q("channel unit", "quantisation step (0 = none)", gt=None, ge=0.0)] = 0.0
    latency: Annotated[Real, _q("s", "latency", gt=None, ge=0.0, le=5.0)] = 0.0
    outlier_scale: Annotated[Real, _q("channel unit", "typical outlier size", gt=None, ge=0.0)] = 1.0
    enabled: Annotated[bool, Strict()] = True


@_spec
class SensorSpec(_Part):
    """The CAN-like sensor set: sample rate [Hz] and one ChannelSensorSpec per measured channel (names from
    roadload.channels). drive_torque_gain_error / drive_torque_offset [N m]: error of the engine / motor torque
    model (the CAN torque is a model output, section 5.2.1); speed_scale_error: ESP speed scale error [-]."""

    sample_rate: Annotated[Real, _q("Hz", "sample rate", gt=None, ge=1.0, le=1000.0)] = 100.0
    channels: dict[str, ChannelSensorSpec] = field(default_factory=dict)
    drive_torque_gain_error: Annotated[Real, _q("1", "drive-torque gain error", gt=None, ge=-0.5, le=0.5)] = 0.0
    drive_torque_offset: Annotated[Real, _q("N*m", "drive-torque offset", gt=None)] = 0.0
    speed_scale_error: Annotated[Real, _q("1", "ESP speed scale error", gt=None, ge=-0.2, le=0.2)] = 0.0

    @field_validator("channels")
    @classmethod
    def _measured_channels(cls, channels: dict[str, ChannelSensorSpec]) -> dict[str, ChannelSensorSpec]:
        for name in channels:
            if name not in MEASURED:
                raise _FieldError(name, f"not a measured channel of the catalogue (measured: {sorted(MEASURED)})")
        return channels


@_spec
class VehicleSpec(_Part):
    """A complete vehicle: body, aero, tires, drive-train, brakes, steering table and sensors."""

    name: Annotated[str, Strict(), Field(min_length=1, description="name of the vehicle")]
    body: BodySpec
    aero: AeroSpec
    tires: TireSpec
    drivetrain: DrivetrainSpec
    brakes: BrakeSpec
    steering: SteeringSpec
    sensors: SensorSpec = field(default_factory=SensorSpec)
    description: Annotated[str, Strict()] = ""

    @model_validator(mode="after")
    def _top_speed_reachable(self) -> "VehicleSpec":
        """Cross-field physics: the top speed this drive-train, mass and drag reach (see :func:`check_physics`)."""
        check_physics(self)
        return self

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

    # ------------------------------------------------------------------ I/O
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
