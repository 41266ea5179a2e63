"""Road profiles over distance and speed-vs-time drive cycles: the road the simulator drives and the MPC previews."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np


class RoadProfileError(ValueError):
    """A road profile or drive cycle is malformed; the message names the field."""


def _as_1d(name: str, values, n: int | None = None) -> np.ndarray:
    arr = np.asarray(values, dtype=float)
    if arr.ndim != 1:
        raise RoadProfileError(f"{name}: expected a 1-D array, got shape {arr.shape}")
    if n is not None and arr.size != n:
        raise RoadProfileError(f"{name}: length {arr.size} differs from distance length {n}")
    bad = np.flatnonzero(~np.isfinite(arr))
    if bad.size:
        raise RoadProfileError(f"{name}: {bad.size} NaN/inf values, first at index {int(bad[0])}")
    return arr


@dataclass
class RoadProfile:
    """Road attributes sampled over distance s [m] (strictly increasing, starting at 0).

    grade: gradient angle theta [rad] (positive uphill); curvature: 1/r [1/m] (positive = left turn);
    bank: road bank angle phi_r [rad], right-handed about the direction of travel (x forward, y left, z up):
    positive = left edge higher, so gravity pulls to the right with g*sin(phi_r); a left curve (curvature > 0)
    superelevated for the curve has bank < 0; speed_limit: [m/s]; stops: distances [m] where the vehicle must stop;
    meta: source, licence, generator seed, ...
    """

    name: str
    distance: np.ndarray
    grade: np.ndarray
    curvature: np.ndarray
    bank: np.ndarray
    speed_limit: np.ndarray
    stops: np.ndarray = field(default_factory=lambda: np.zeros(0))
    meta: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        self.distance = _as_1d("distance", self.distance)
        n = self.distance.size
        if n < 2:
            raise RoadProfileError("distance: a profile needs at least 2 samples")
        if not np.all(np.diff(self.distance) > 0):
            i = int(np.flatnonzero(np.diff(self.distance) <= 0)[0])
            raise RoadProfileError(f"distance: not strictly increasing at index {i + 1}")
        if abs(self.distance[0]) > 1e-9:
            raise RoadProfileError(f"distance: must start at 0 m, starts at {self.distance[0]}")
        self.grade = _as_1d("grade", self.grade, n)
        self.curvature = _as_1d("curvature", self.curvature, n)
        self.bank = _as_1d("bank", self.bank, n)
        self.speed_limit = _as_1d("speed_limit", self.speed_limit, n)
        self.stops = _as_1d("stops", self.stops)
        if np.any(np.abs(self.grade) > np.arctan(0.3)):
            raise RoadProfileError("grade: |grade| above 30 % is not a road")
        if np.any(self.speed_limit <= 0):
            raise RoadProfileError("speed_limit: must be positive everywhere [m/s]")
        if np.any((self.stops < 0) | (self.stops > self.length)):
            raise RoadProfileError("stops: outside the profile's distance range")

    @property
    def length(self) -> float:
        return float(self.distance[-1])

    def at(self, s) -> dict[str, np.ndarray]:
        """Linearly interpolated attributes at distance(s) s [m] (clamped to the profile ends)."""
        s = np.asarray(s, dtype=float)
        return {k: np.interp(s, self.distance, getattr(self, k))
                for k in ("grade", "curvature", "bank", "speed_limit")}

    def elevation(self) -> np.ndarray:
        """Elevation [m] over distance, integrated from the grade (starts at 0)."""
        ds = np.diff(self.distance)
        mid = 0.5 * (np.sin(self.grade[1:]) + np.sin(self.grade[:-1]))
        return np.concatenate([[0.0], np.cumsum(mid * ds)])


@dataclass
class DriveCycle:
    """A speed-vs-time cycle (e.g. WLTC class 3): time [s], speed [m/s], optional grade [rad] over time."""

    name: str
    time: np.ndarray
    speed: np.ndarray
    grade: np.ndarray | None = None
    meta: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        self.time = _as_1d("time", self.time)
        self.speed = _as_1d("speed", self.speed, self.time.size)
        if self.grade is not None:
            self.grade = _as_1d("grade", self.grade, self.time.size)
        if self.time.size < 2 or not np.all(np.diff(self.time) > 0):
            raise RoadProfileError("time: needs >= 2 strictly increasing samples")
        if np.any(self.speed < 0):
            raise RoadProfileError("speed: negative values in a drive cycle")

    @property
    def duration(self) -> float:
        return float(self.time[-1] - self.time[0])

    @property
    def distance(self) -> float:
        return float(np.trapezoid(self.speed, self.time))
