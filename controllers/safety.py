"""Speed caps from the road and the safety envelope every controller obeys.

- :func:`speed_cap` combines the posted limit with the curve cap v <= sqrt(a_y,max / |kappa|) [m/s].
- :class:`SpeedEnvelope` is the highest speed from which the car can still meet every cap (and every stop that
  is not yet served) ahead with a given deceleration: v_env(s) = min_{s' >= s} sqrt(v_cap(s')^2 + 2 b (s' - s)).
  The closed loop clips any command that would exceed it, so neither a solver failure nor a fallback can push
  the car over the limit.
"""

from __future__ import annotations

import numpy as np

from roadload.road_profiles import RoadProfile

VIOLATION_TOLERANCE = 0.1
"""[m/s] A speed this little above a cap is numerical noise, not a violation (run metrics, MPC feasibility)."""


def speed_cap(road: RoadProfile, lateral_accel_max: float, s=None) -> np.ndarray:
    """min(speed limit, sqrt(a_y,max/|kappa|)) [m/s] on the road's grid (or at positions s [m])."""
    if s is None:
        limit, kappa = road.speed_limit, road.curvature
    else:
        at = road.at(s)
        limit, kappa = at["speed_limit"], at["curvature"]
    with np.errstate(divide="ignore"):
        curve = np.sqrt(lateral_accel_max / np.maximum(np.abs(kappa), 1e-9))
    return np.minimum(limit, curve)


def braking_envelope(s: np.ndarray, cap: np.ndarray, decel: float) -> np.ndarray:
    """Backward pass: the highest speed at each s from which cap can be met ahead braking at ``decel``."""
    v = np.array(cap, dtype=float)
    ds = np.diff(s)
    for i in range(len(v) - 2, -1, -1):
        v[i] = min(v[i], np.sqrt(v[i + 1] ** 2 + 2.0 * decel * ds[i]))
    return v


class SpeedEnvelope:
    """Speed envelope over the road with stops; ``served`` stops are dropped (after the car stopped there)."""

    def __init__(self, road: RoadProfile, lateral_accel_max: float, decel: float, step: float = 2.0,
                 cap_fraction: float = 1.0, cap_margin: float = 0.0) -> None:
        if decel <= 0:
            raise ValueError(f"envelope deceleration must be positive, got {decel}")
        if not 0 < cap_fraction <= 1:
            raise ValueError(f"cap_fraction must be in (0, 1], got {cap_fraction}")
        self.road = road
        self.decel = decel
        n = int(np.ceil(road.length / step)) + 1
        self.s = np.linspace(0.0, road.length, n)
        self.cap = np.maximum(cap_fraction * speed_cap(road, lateral_accel_max, self.s) - cap_margin, 0.5)
        self.stops = np.sort(np.asarray(road.stops, dtype=float))
        self.served = np.zeros(self.stops.size, dtype=bool)
        self._update()

    def _update(self) -> None:
        cap = self.cap.copy()
        for stop in self.stops[~self.served]:
            i = int(np.clip(np.searchsorted(self.s, stop), 0, len(cap) - 1))
            cap[i] = 0.0
        self.envelope = braking_envelope(self.s, cap, self.decel)

    def serve(self, index: int) -> None:
        self.served[index] = True
        self._update()

    def __call__(self, s) -> np.ndarray:
        return np.interp(s, self.s, self.envelope)

    def slope(self, s: float) -> float:
        """d v_env / ds [1/s] at s (forward difference over one grid step)."""
        h = self.s[1] - self.s[0]
        return float((np.interp(s + h, self.s, self.envelope) - np.interp(s, self.s, self.envelope)) / h)

    def next_stop(self, s: float) -> tuple[int, float] | None:
        """(index, position) of the next stop not yet served at or after s - 1 m, or None."""
        for i, stop in enumerate(self.stops):
            if not self.served[i] and stop >= s - 1.0:
                return i, float(stop)
        return None
