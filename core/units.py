"""Unit conversions used at the edges (CLI, importers). Inside, everything is SI."""

from __future__ import annotations

import re

import numpy as np

G = 9.80665  # m/s^2, standard gravity
R_AIR = 287.058  # J/(kg K), specific gas constant of dry air (section 2.4.3)
KELVIN = 273.15


def kmh_to_ms(v):
    return np.asarray(v, dtype=float) / 3.6


def ms_to_kmh(v):
    return np.asarray(v, dtype=float) * 3.6


def celsius_to_kelvin(temp):
    return np.asarray(temp, dtype=float) + KELVIN


def kelvin_to_celsius(temp):
    return np.asarray(temp, dtype=float) - KELVIN


def rpm_to_rad_s(n):
    return np.asarray(n, dtype=float) * (2.0 * np.pi / 60.0)


def bar_to_pa(p):
    return np.asarray(p, dtype=float) * 1e5


def percent_to_rad(grade_percent):
    """Road grade in % (rise over run) to gradient angle theta [rad]."""
    return np.arctan(np.asarray(grade_percent, dtype=float) / 100.0)


def rad_to_percent(theta):
    return np.tan(np.asarray(theta, dtype=float)) * 100.0


def air_density(temperature_k, pressure_pa):
    """Dry-air density rho_a = p_a / (R_a T_a) [kg/m^3] (section 2.4.3)."""
    return np.asarray(pressure_pa, dtype=float) / (R_AIR * np.asarray(temperature_k, dtype=float))


STANDARD_TEMPERATURE = 293.15  # K, reference air / oil temperature (20 degC)
STANDARD_PRESSURE = 101325.0  # Pa, standard atmospheric pressure (1013.25 hPa)
#: kg/m^3, dry air at 20 degC and 1013.25 hPa
STANDARD_AIR_DENSITY = float(air_density(STANDARD_TEMPERATURE, STANDARD_PRESSURE))


# Conversions from a unit string to SI: factor and offset, value_si = value * factor + offset.
_TO_SI: dict[str, tuple[str, float, float]] = {
    "m/s": ("m/s", 1.0, 0.0),
    "km/h": ("m/s", 1 / 3.6, 0.0),
    "kph": ("m/s", 1 / 3.6, 0.0),
    "mph": ("m/s", 0.44704, 0.0),
    "m/s^2": ("m/s^2", 1.0, 0.0),
    "g": ("m/s^2", G, 0.0),
    "rad": ("rad", 1.0, 0.0),
    "deg": ("rad", np.pi / 180.0, 0.0),
    "rad/s": ("rad/s", 1.0, 0.0),
    "deg/s": ("rad/s", np.pi / 180.0, 0.0),
    "rpm": ("rad/s", 2.0 * np.pi / 60.0, 0.0),
    "N*m": ("N*m", 1.0, 0.0),
    "Nm": ("N*m", 1.0, 0.0),
    "N": ("N", 1.0, 0.0),
    "Pa": ("Pa", 1.0, 0.0),
    "bar": ("Pa", 1e5, 0.0),
    "kPa": ("Pa", 1e3, 0.0),
    "K": ("K", 1.0, 0.0),
    "degC": ("K", 1.0, KELVIN),
    "°C": ("K", 1.0, KELVIN),
    "m": ("m", 1.0, 0.0),
    "km": ("m", 1000.0, 0.0),
    "s": ("s", 1.0, 0.0),
    "ms": ("s", 1e-3, 0.0),
    "1": ("1", 1.0, 0.0),
    "%": ("1", 0.01, 0.0),
    "V": ("V", 1.0, 0.0),
    "A": ("A", 1.0, 0.0),
    "W": ("W", 1.0, 0.0),
    "kW": ("W", 1e3, 0.0),
    "kg": ("kg", 1.0, 0.0),
}


def to_si(values, unit: str):
    """Convert values given in `unit` to SI; returns (values_si, si_unit). Unknown unit -> ValueError."""
    if unit not in _TO_SI:
        raise ValueError(f"unknown unit {unit!r}; known: {sorted(_TO_SI)}")
    si_unit, factor, offset = _TO_SI[unit]
    return np.asarray(values, dtype=float) * factor + offset, si_unit


def si_unit_of(unit: str) -> str:
    """The SI unit a given unit converts to (raises ValueError for unknown units)."""
    if unit not in _TO_SI:
        raise ValueError(f"unknown unit {unit!r}; known: {sorted(_TO_SI)}")
    return _TO_SI[unit][0]


# SI symbols a unit expression may combine (coherent SI base and derived units; '1' = dimensionless)
SI_SYMBOLS = frozenset({"m", "s", "kg", "K", "A", "mol", "cd", "rad", "sr", "Hz", "N", "Pa", "J", "W", "C", "V",
                        "F", "ohm", "S", "Wb", "T", "H", "lm", "lx", "1"})
_SI_FACTOR = re.compile(r"^(?P<sym>[A-Za-z]+|1)(\^-?\d+)?$")


def si_unit_problem(unit: str) -> str | None:
    """Why ``unit`` is not an SI unit expression, or None if it is one.

    An SI unit expression is ``1`` or SI symbols (:data:`SI_SYMBOLS`) joined by ``*`` and ``/`` with integer powers
    ``^n`` (``m/s^2``, ``N*m``, ``s^4/m^4``, ``kg/m^3``, ``1/m``). A known non-SI unit (``km/h``, ``bar``, ``degC``,
    ``%``, ``rpm``) is named with the SI unit it converts to and how."""
    if unit in _TO_SI and _TO_SI[unit][0] != unit:
        si_unit, factor, offset = _TO_SI[unit]
        how = f"x [{si_unit}] = x [{unit}] * {factor:.6g}" + (f" + {offset:g}" if offset else "")
        return f"{unit!r} is not SI: convert to {si_unit!r} ({how}, roadload.units.to_si)"
    if not unit or unit != unit.strip():
        return f"{unit!r} is not a unit (empty or with surrounding whitespace)"
    for part in re.split(r"[*/]", unit):
        m = _SI_FACTOR.match(part)
        if m is None or m.group("sym") not in SI_SYMBOLS:
            return (f"{unit!r} is not an SI unit expression (SI symbols {sorted(SI_SYMBOLS)} joined by '*' and '/', "
                    f"integer powers as '^n', e.g. 'm/s^2', 'N*m', '1')")
    return None


def unit_label(unit: str) -> str:
    """A unit as printed after a number: ``[m/s]``; dimensionless ``'1'`` as ``[-]`` (a bare 1 reads as a number)."""
    return "[-]" if unit in ("1", "") else f"[{unit}]"
