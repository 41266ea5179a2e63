"""Plausibility checks on channels in SI units: absurd samples are dropped or clipped, and every change is counted.

Rules (per catalogue channel; a mapping entry's ``range`` overrides the drop range):
- speeds (``vehicle_speed``, ``gnss_speed``, wheel speeds): negative values are clipped to 0 when small
  (>= -0.5 m/s, sensor noise at standstill) and dropped when larger (a sign or decoding error);
  values above 100 m/s (360 km/h) are dropped;
- ``grade``: |grade| > 30 % (atan 0.3) is clipped to +-30 % (after smoothing, a bigger value is a spike);
- ``elevation``: outside [-500, 9000] m is dropped (e.g. CANedge's invalid GNSS altitude -5400 m at start-up);
- temperatures outside [200, 400] K and accelerations beyond +-50 m/s^2 are dropped;
- NaN/inf source samples are always dropped.
"""

from __future__ import annotations

import numpy as np

from .report import ImportReport

MAX_GRADE_RAD = float(np.arctan(0.30))
SPEED_NOISE_FLOOR = -0.5  # m/s; below this a negative speed is an error, not noise

_DROP_RANGE: dict[str, tuple[float, float]] = {
    "vehicle_speed": (SPEED_NOISE_FLOOR, 100.0),
    "gnss_speed": (SPEED_NOISE_FLOOR, 100.0),
    "wheel_speed_fl": (SPEED_NOISE_FLOOR / 0.3, 350.0),
    "wheel_speed_fr": (SPEED_NOISE_FLOOR / 0.3, 350.0),
    "wheel_speed_rl": (SPEED_NOISE_FLOOR / 0.3, 350.0),
    "wheel_speed_rr": (SPEED_NOISE_FLOOR / 0.3, 350.0),
    "elevation": (-500.0, 9000.0),
    "ambient_temperature": (200.0, 400.0),
    "battery_temperature": (200.0, 400.0),
    "accel_x": (-50.0, 50.0),
    "accel_y": (-50.0, 50.0),
    "latitude": (-90.0, 90.0),
    "longitude": (-180.0, 180.0),
}
_CLIP_BELOW_ZERO = {"vehicle_speed", "gnss_speed", "wheel_speed_fl", "wheel_speed_fr", "wheel_speed_rl",
                    "wheel_speed_rr"}


def plausible(channel: str, t: np.ndarray, values: np.ndarray, report: ImportReport,
              drop_range: tuple[float, float] | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Source samples of one channel (SI) with absurd ones dropped and small negative speeds clipped to 0."""
    t = np.asarray(t, dtype=float)
    v = np.asarray(values, dtype=float)
    bad = ~np.isfinite(v)
    report.drop(channel, "value NaN/inf", int(bad.sum()))
    t, v = t[~bad], v[~bad]
    lo, hi = drop_range if drop_range is not None else _DROP_RANGE.get(channel, (-np.inf, np.inf))
    out = (v < lo) | (v > hi)
    if out.any():
        report.drop(channel, f"outside the plausible range [{lo:g}, {hi:g}]", int(out.sum()),
                    f"min {np.min(v[out]):.6g}, max {np.max(v[out]):.6g}")
        t, v = t[~out], v[~out]
    if channel in _CLIP_BELOW_ZERO:
        neg = v < 0
        if neg.any():
            report.repair(channel, "negative speed clipped to 0", int(neg.sum()), f"min {v[neg].min():.3g} m/s")
            v = np.where(neg, 0.0, v)
    return t, v


def clip_grade(grade: np.ndarray, report: ImportReport, what: str = "grade") -> np.ndarray:
    """Grade [rad] with |grade| > 30 % clipped to +-atan(0.3), counted."""
    grade = np.asarray(grade, dtype=float)
    over = np.abs(grade) > MAX_GRADE_RAD
    if over.any():
        report.repair(what, "|grade| > 30 % clipped to 30 %", int(over.sum()),
                      f"max |grade| {np.tan(np.max(np.abs(grade[over]))) * 100:.1f} %")
    return np.clip(grade, -MAX_GRADE_RAD, MAX_GRADE_RAD)
