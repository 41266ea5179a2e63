"""What the test worlds share: the case record, the withheld-effect table, a speed planner (the worlds' own driver
on a road profile's speed limits, curves and stops), logger helpers (noise, quantisation, latency, CSV + mapping
JSON) and the import through roadload's CSV importer.

Nothing here calls roadload's simulator (``roadload.envs``): the worlds read road profiles
(:mod:`roadload.road_profiles`) and write logs that come back through :func:`roadload.io.import_log`, exactly as a
real logger's files would.
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
from roadload.fileio import write_json, write_text
from roadload.io import import_log
from roadload.road_profiles import RoadProfile, load_profile
from roadload.trip import Trip

LOG_RATE = 100.0            # Hz of the written CSV logs
ROADS: tuple[str, ...] = ("hilly", "city", "motorway")
NONE = "none"
OUTSIDE = "torque_map_band"


class WorldError(ValueError):
    """A world cannot build the requested case (unknown world / effect, bad size); the message names what."""


@dataclass(frozen=True)
class Withheld:
    """One withheld effect of a world: ``name`` (the selftest's label), ``accepted`` (catalog candidates that count
    as the right answer), ``params`` in the world's own terms and ``description``."""

    name: str
    accepted: tuple[str, ...]
    params: dict = field(default_factory=dict)
    description: str = ""


@dataclass
class WorldCase:
    """A generated case: trip CSV paths, the mapping JSON that imports them, the roadload vehicle JSON matched to
    the world's base vehicle (the diagnosis' sim side), the truth (withheld effect and its parameters)."""

    world: str
    withheld: str
    seed: int
    trip_paths: list[Path]
    mapping_path: Path
    vehicle_path: Path
    truth: dict[str, Any]
    out_dir: Path

    @property
    def sim_path(self) -> Path:
        """The sim config ``<world>_sim.json``: the matched vehicle at the world's nominal ambient temperature."""
        return self.out_dir / f"{self.world}_sim.json"

    def import_trips(self) -> list[Trip]:
        """The trips through roadload's CSV importer and the case's mapping."""
        return [import_log(p, "csv", self.mapping_path) for p in self.trip_paths]

    def to_dict(self) -> dict[str, Any]:
        return {"world": self.world, "withheld": self.withheld, "seed": self.seed,
                "trips": [str(p) for p in self.trip_paths], "mapping": str(self.mapping_path),
                "vehicle": str(self.vehicle_path), "truth": self.truth}


# ---------------------------------------------------------------------------------------------- roads and driver
def out_and_back(profile: RoadProfile) -> RoadProfile:
    """The profile driven there and back (grade and curvature mirrored), so a trip never runs out of road."""
    s = profile.distance
    L = s[-1]
    s2 = np.concatenate([s, 2 * L - s[-2::-1]])
    def back(x, sign):
        return np.concatenate([x, sign * x[-2::-1]])
    stops = np.concatenate([profile.stops, 2 * L - profile.stops[::-1]])
    return RoadProfile(profile.name, s2, back(profile.grade, -1.0), back(profile.curvature, -1.0),
                       back(profile.bank, -1.0), back(profile.speed_limit, 1.0), np.unique(stops),
                       dict(profile.meta))


def road(name: str, seed: int, duration: float) -> RoadProfile:
    """roadload road profile ``name`` (seeded), doubled out-and-back until a trip of ``duration`` s at the speed
    limit cannot run out of road."""
    p = load_profile(name, seed=seed)
    if not isinstance(p, RoadProfile):
        raise WorldError(f"road {name!r} is a drive cycle, not a road profile")
    while p.length < duration * float(p.speed_limit.max()) * 1.05:
        p = out_and_back(p)
    return p


def _ou(rng: np.random.Generator, n: int, dt: float, tau: float, std: float) -> np.ndarray:
    """Ornstein-Uhlenbeck noise with time constant tau [s] and stationary std."""
    a = np.exp(-dt / tau)
    e = rng.normal(0.0, std * np.sqrt(1 - a * a), n)
    x = np.empty(n)
    x[0] = rng.normal(0.0, std)
    for k in range(1, n):
        x[k] = a * x[k - 1] + e[k]
    return x


def planned_speed(profile: RoadProfile, rng: np.random.Generator, *, accel: float = 1.6, power_to_mass: float = 40.0,
                  decel: float = 1.6, brake_power_to_mass: float = 45.0, lateral: float = 2.2,
                  speed_factor: float = 0.95) -> np.ndarray:
    """Target speed [m/s] over the profile's distance grid: speed limit x a driver factor (slowly varying around
    ``speed_factor``), curves at most ``lateral`` m/s² (v² κ), 0 at stops; forward pass with acceleration
    min(accel, P/m / v), backward pass with deceleration min(decel, P_brake/m / v)."""
    s = profile.distance
    ds = np.diff(s)
    factor = speed_factor + _ou(rng, s.size, 1.0, 300.0, 0.03)
    lim = profile.speed_limit * np.clip(factor, 0.8, 1.05)
    kappa = np.abs(profile.curvature)
    lim = np.minimum(lim, np.sqrt(lateral / np.maximum(kappa, 1e-6)))
    stop_idx = np.searchsorted(s, profile.stops)
    lim[np.clip(stop_idx, 0, s.size - 1)] = 0.0
    lim[0] = 0.0
    v = lim.copy()
    for k in range(s.size - 1):
        a = min(accel, power_to_mass / max(v[k], 1.0))
        v[k + 1] = min(v[k + 1], np.sqrt(v[k] ** 2 + 2 * a * ds[k]))
    for k in range(s.size - 2, -1, -1):
        b = min(decel, brake_power_to_mass / max(v[k + 1], 1.0))
        v[k] = min(v[k], np.sqrt(v[k + 1] ** 2 + 2 * b * ds[k]))
    return v


def speed_trace(profile: RoadProfile, v_plan: np.ndarray, duration: float, dt: float, rng: np.random.Generator,
                dwell: float = 8.0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(t, v, s): the planned speed driven in time at step dt [s] with a dwell [s] at each stop, smoothed over 1 s
    (bounded jerk); s re-integrated from v."""
    n = round(duration / dt) + 1
    v = np.zeros(n)
    s_now = 0.0
    stops = np.concatenate([profile.stops, [np.inf]])
    k_stop = 0
    still = dwell * 0.5
    L = profile.length
    for k in range(1, n):
        if still > 0:
            still -= dt
            v[k] = 0.0
            continue
        while stops[k_stop] < s_now - 1.0:
            k_stop += 1
        vp = float(np.interp(s_now, profile.distance, v_plan))
        vk = max(vp, 0.6)
        if stops[k_stop] - s_now < 1.0 and vp < 1.0:
            still = dwell * (0.5 + rng.random())
            s_now = stops[k_stop] + 1.05
            k_stop += 1
            v[k] = 0.0
            continue
        v[k] = vk
        s_now = min(s_now + vk * dt, L - 1.0)
    w = max(1, round(1.0 / dt))
    v = np.convolve(np.pad(v, (w // 2, w - 1 - w // 2), mode="edge"), np.ones(w) / w, mode="valid")
    v[0] = 0.0
    t = np.arange(n) * dt
    s = np.concatenate([[0.0], np.cumsum(0.5 * (v[1:] + v[:-1]) * dt)])
    return t, v, s


# ---------------------------------------------------------------------------------------------- logger helpers
def quantise(x: np.ndarray, step: float) -> np.ndarray:
    return np.round(np.asarray(x, dtype=float) / step) * step if step > 0 else np.asarray(x, dtype=float)


def delayed(t: np.ndarray, x: np.ndarray, latency: float) -> np.ndarray:
    """x read ``latency`` seconds late (the first value held at the start)."""
    if latency <= 0:
        return np.asarray(x, dtype=float)
    return np.interp(t - latency, t, x)


def sensor(rng: np.random.Generator, x: np.ndarray, noise: float, step: float, bias: float = 0.0) -> np.ndarray:
    return quantise(np.asarray(x, dtype=float) + bias + rng.normal(0.0, noise, np.shape(x)), step)


@dataclass(frozen=True)
class Column:
    """A logged column: header (with [unit]), Trip channel, mapping unit spelling, decimals written, resample."""

    header: str
    channel: str
    unit: str
    decimals: int
    resample: str = "linear"
    required: bool = False


def write_log(path: Path, t: np.ndarray, columns: Sequence[Column], values: dict[str, np.ndarray],
              time_header: str, sep: str = ",") -> Path:
    """The CSV a logger writes (atomically): time column + every column rounded to its decimals."""
    frame = {time_header: np.round(t, 3)}
    for c in columns:
        frame[c.header] = np.round(np.asarray(values[c.channel], dtype=float), c.decimals)
    text = pd.DataFrame(frame).to_csv(sep=sep, index=False, lineterminator="\n")
    return write_text(path, text)


def write_mapping(path: Path, name: str, columns: Sequence[Column], time_header: str, description: str,
                  sep: str = ",", extra: list[dict] | None = None) -> Path:
    """The mapping JSON (roadload.io.mapping schema) that imports :func:`write_log`'s files."""
    chans = [{"source": c.header, "channel": c.channel, "unit": c.unit, "resample": c.resample,
              **({"required": True} if c.required else {})} for c in columns] + list(extra or [])
    data = {"name": name, "format": "csv", "description": description, "licence": "generated by roadload (MIT)",
            "sample_rate": LOG_RATE, "csv": {"sep": sep, "time": time_header, "time_unit": "s"},
            "channels": chans}
    return write_json(path, data)


def resample_to_log(t_src: np.ndarray, x: np.ndarray, duration: float) -> tuple[np.ndarray, np.ndarray]:
    """(t, x) linearly interpolated onto the logger's 100 Hz clock."""
    t = np.arange(0.0, duration + 1e-9, 1.0 / LOG_RATE)
    return t, np.interp(t, t_src, x)


def truth_json(path: Path, truth: dict) -> Path:
    return write_text(path, json.dumps(truth, indent=1, default=float))
