"""Effects of known size added to the logged channels of recorded trips: the diagnosis' proof on real logs. A copy
of each trip gets one effect; diagnosed against a calibration of the trips as logged, the effect must be named
with its size, and the un-injected copies must give no acceptance.

=================  ==============================================  ==========  ======================================
effect             what changes in the log                         size unit   the candidate that names it
=================  ==============================================  ==========  ======================================
``aux_load``       battery current + P / U (a load P drawn from    W           ``auxiliary_power`` (ΔP_aux = P)
                   the traction battery at its logged voltage U)
``torque_gain``    drive torque x (1 + g)                          1           ``torque_scale`` (ε = g),
                                                                               ``drive_efficiency`` (e_m = g) or
                                                                               ``torque_signal`` (g, battery power)
``torque_offset``  drive torque + T_off                            N*m         –
``accel_bias``     longitudinal acceleration + b                   m/s^2       ``accel_bias`` (b)
``latency``        a channel (default the drive torque) late by τ  s           ``latency`` (τ, drive torque)
``speed_scale``    vehicle speed x (1 + s)                         1           ``speed_scale`` (s) or
                                                                               ``speed_signal`` (s, battery power)
=================  ==============================================  ==========  ======================================

Sizes are checked against physical bounds (a 50 kW auxiliary load, a gain of 2 or a 10 s latency are refused with
the bound and its unit). Every injected trip keeps its name with ``+<effect>`` and records
``meta["injected"] = {"effect", "size", "unit", "channel"}``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

from roadload.trip import Trip

from .errors import DiagnosisError


@dataclass(frozen=True)
class Injection:
    """One kind of injected effect: the channel(s) it needs, the size's unit and physical bounds, the catalog
    candidates that name it with the parameter whose fitted value is its size (how it maps: size = factor x
    fitted), and what it does."""

    name: str
    needs: tuple[str, ...]
    unit: str
    low: float
    high: float
    candidates: tuple[tuple[str, str, float], ...]
    description: str
    side: str = "force"


INJECTIONS: dict[str, Injection] = {i.name: i for i in (
    Injection("aux_load", ("battery_voltage", "battery_current"), "W", 0.0, 20000.0,
              (("auxiliary_power", "delta P_aux", 1.0),), "auxiliary load drawn from the traction battery",
              side="energy"),
    Injection("torque_gain", ("drive_torque",), "1", -0.5, 0.5,
              (("torque_scale", "torque scale error epsilon", 1.0),
               ("drive_efficiency", "traction scale error e_m", 1.0),
               ("torque_signal", "drive-torque signal gain error g", 1.0)),
              "drive-torque signal gain error g: the signal reads (1 + g) T"),
    Injection("torque_offset", ("drive_torque",), "N*m", -100.0, 100.0, (),
              "drive-torque signal offset T_off: the signal reads T + T_off"),
    Injection("accel_bias", ("accel_x",), "m/s^2", -2.0, 2.0, (("accel_bias", "accelerometer bias b", 1.0),),
              "accelerometer bias b: the longitudinal acceleration reads a_x + b"),
    Injection("latency", ("drive_torque",), "s", 0.0, 5.0, (("latency", "latency tau", 1.0),),
              "a channel (default: the drive torque) logged τ late"),
    Injection("speed_scale", ("vehicle_speed",), "1", -0.2, 0.2,
              (("speed_scale", "speed scale error s", 1.0), ("speed_signal", "speed scale error s", 1.0)),
              "speed-signal scale error s: the speed reads (1 + s) v"),
)}


def _aux_load(trip: Trip, size: float, channel: str) -> None:
    u = trip.channel("battery_voltage")
    if not np.all(np.isfinite(u) & (u > 1.0)):
        raise DiagnosisError(f"trip {trip.meta.get('name', '')!r}: battery_voltage must be a positive voltage [V] "
                             "on every sample to add a load to the battery current")
    trip.measured["battery_current"] = trip.channel("battery_current") + size / u


def _scale(name: str) -> Callable[[Trip, float, str], None]:
    def apply(trip: Trip, size: float, channel: str) -> None:
        trip.measured[name] = trip.channel(name) * (1.0 + size)
    return apply


def _offset(name: str) -> Callable[[Trip, float, str], None]:
    def apply(trip: Trip, size: float, channel: str) -> None:
        trip.measured[name] = trip.channel(name) + size
    return apply


def _latency(trip: Trip, size: float, channel: str) -> None:
    """The channel's value at t is what it read at t - τ (held at its first value before the start)."""
    t = trip.t
    x = trip.channel(channel)
    ok = np.isfinite(x)
    trip.measured[channel] = np.interp(t - size, t[ok], x[ok])


_APPLY: dict[str, Callable[[Trip, float, str], None]] = {
    "aux_load": _aux_load, "torque_gain": _scale("drive_torque"), "torque_offset": _offset("drive_torque"),
    "accel_bias": _offset("accel_x"), "latency": _latency, "speed_scale": _scale("vehicle_speed")}


def get_injection(effect: str) -> Injection:
    """The injection of that name (DiagnosisError listing the known ones)."""
    if effect not in INJECTIONS:
        raise DiagnosisError(f"unknown injected effect {effect!r}; choose one of {sorted(INJECTIONS)}")
    return INJECTIONS[effect]


def inject(trip: Trip, effect: str, size: float, channel: str | None = None) -> Trip:
    """A copy of ``trip`` with ``effect`` of ``size`` (its unit: :data:`INJECTIONS`) added to the logged channels
    (module doc); ``channel``: the delayed channel of ``latency`` (default drive_torque)."""
    inj = get_injection(effect)
    if not (np.isfinite(size) and inj.low <= size <= inj.high):
        raise DiagnosisError(f"--size of {effect}: must lie in [{inj.low:g}, {inj.high:g}] [{inj.unit}], "
                             f"got {size!r}")
    if channel is not None and effect != "latency":
        raise DiagnosisError(f"--channel only goes with the latency effect, not {effect!r}")
    channel = channel or "drive_torque"
    needs = inj.needs if effect != "latency" else (channel,)
    missing = [c for c in needs if not trip.has(c)]
    name = str(trip.meta.get("name") or trip.meta.get("trip") or "trip")
    if missing:
        raise DiagnosisError(f"trip {name!r} lacks the channels {missing} that {effect} changes; it has "
                             f"{trip.channels}")
    out = trip.copy()
    _APPLY[effect](out, float(size), channel)
    out.meta["name"] = f"{name}+{effect}"
    out.meta["injected"] = {"effect": effect, "size": float(size), "unit": inj.unit,
                            "channel": channel if effect == "latency" else ",".join(inj.needs)}
    return out


def fitted_size(effect: str, name: str, parameters: dict[str, float]) -> float | None:
    """The injected size an accepted effect ``name`` with fitted ``parameters`` stands for (None when that
    candidate does not name ``effect``)."""
    for cand, param, factor in get_injection(effect).candidates:
        if cand == name and param in parameters:
            return factor * float(parameters[param])
    return None
