"""Channels derived from imported ones: rim torque from motor torque, distance, grade from elevation, curvature.

The road-geometry algorithms (smoothing over distance, grade from elevation, curvature from heading) live in
``roadload.road_profiles.tracks``; this module only turns a Trip's time series into the distance-based tracks
those functions take and interpolates their result back onto the Trip's time base.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from roadload.presets import get_preset
from roadload.road_profiles.tracks import profile_from_track

from ..trip import Trip
from .report import ImportReport, LogImportError
from .validate import MAX_GRADE_RAD

STANDSTILL_SPEED = 0.5  # m/s; below this the heading of a GNSS receiver is noise


def rim_torque_from_motor(motor_torque, ratio: float, efficiency: float) -> np.ndarray:
    """Sum of rim torques T_R [N m] from motor torque T_M [N m] through a fixed ratio i and efficiency eta:
    T_R = i eta T_M when driving (T_M >= 0), T_R = i T_M / eta when recuperating (power flows wheel -> motor)."""
    if not (ratio > 0 and 0 < efficiency <= 1):
        raise LogImportError(f"rim torque: ratio must be > 0 and efficiency in (0, 1], got {ratio}, {efficiency}")
    tm = np.asarray(motor_torque, dtype=float)
    return np.where(tm >= 0, ratio * efficiency * tm, ratio * tm / efficiency)


def distance_from_speed(t, speed) -> np.ndarray:
    """Travelled distance s [m] by trapezoidal integration of speed v [m/s] over t [s] (NaN speed counts 0)."""
    t = np.asarray(t, dtype=float)
    v = np.nan_to_num(np.asarray(speed, dtype=float), nan=0.0)
    return np.concatenate([[0.0], np.cumsum(0.5 * (v[1:] + v[:-1]) * np.diff(t))])


def _profile(distance, *, name: str, report: ImportReport, what: str, **kwargs):
    kwargs.setdefault("max_grade", float(np.tan(MAX_GRADE_RAD)))
    prof = profile_from_track(distance, name=name, **kwargs)
    for key, count in prof.meta.get("repairs", {}).items():
        if key == "samples_dropped_too_close":
            continue  # standstill samples thinned before smoothing: not a data repair
        report.repair(what, key.replace("_", " "), int(count))
    return prof


def freeze_elevation_at_standstill(speed, elevation, report: ImportReport, what: str = "elevation",
                                   threshold: float = STANDSTILL_SPEED) -> np.ndarray:
    """Elevation [m] with every change that happens while the vehicle stands (speed < threshold) removed.

    A standing vehicle cannot climb: such changes are sensor artefacts (a GNSS altitude wandering at a traffic
    light, the i3 log ramping its elevation over the first minute at standstill), and over almost no distance
    they become absurd grades. The changes are subtracted cumulatively (the profile after the stop continues
    from the elevation before it); the number of samples and the metres removed are reported.
    """
    v = np.nan_to_num(np.asarray(speed, dtype=float), nan=0.0)
    z = np.asarray(elevation, dtype=float)
    dz = np.diff(z, prepend=z[:1])
    dz = np.where(np.isfinite(dz), dz, 0.0)
    still = (v < threshold) & (dz != 0)
    if not still.any():
        return z
    removed = np.cumsum(np.where(still, dz, 0.0))
    report.repair(what, "elevation change at standstill removed", int(still.sum()),
                  f"{np.abs(dz[still]).sum():.1f} m in total, net {removed[-1]:+.1f} m")
    return z - removed


def grade_from_elevation_track(t, speed, elevation, report: ImportReport, *, window: float = 150.0,
                               name: str = "trip") -> np.ndarray | None:
    """Grade theta [rad] at each time sample: elevation z over distance (integrated speed), smoothed over
    `window` metres and differentiated (roadload.road_profiles.tracks). Returns None (and notes why) when the
    elevation never changes over more than 1 km (a frozen sensor, not a flat road)."""
    s = distance_from_speed(t, speed)
    z = np.asarray(elevation, dtype=float)
    if s[-1] < 2 * window:
        report.note(f"grade not derived: only {s[-1]:.0f} m driven (< 2 x {window:g} m smoothing window)")
        return None
    finite = z[np.isfinite(z)]
    if finite.size and np.ptp(finite) == 0 and s[-1] > 1000:
        report.note(f"grade not derived: elevation frozen at {finite[0]:g} m over {s[-1] / 1000:.1f} km")
        return None
    z = freeze_elevation_at_standstill(speed, z, report)
    prof = _profile(s, elevation=z, name=name, report=report, what="grade", elevation_window=window)
    return prof.at(s - s[0])["grade"]


def curvature_from_yaw_rate_track(t, speed, yaw_rate, report: ImportReport, *, window: float = 40.0,
                                  name: str = "trip") -> np.ndarray:
    """Curvature kappa [1/m] at each time sample from the yaw rate r [rad/s]: heading psi = integral r dt, then
    dpsi/ds smoothed over `window` metres (equivalent to r/v without dividing by a speed near 0)."""
    t = np.asarray(t, dtype=float)
    r = np.nan_to_num(np.asarray(yaw_rate, dtype=float), nan=0.0)
    psi = np.concatenate([[0.0], np.cumsum(0.5 * (r[1:] + r[:-1]) * np.diff(t))])
    s = distance_from_speed(t, speed)
    prof = _profile(s, heading=psi, name=name, report=report, what="curvature", heading_window=window)
    return prof.at(s - s[0])["curvature"]


def vehicle_spec(preset: str):
    """A roadload.envs vehicle preset (VehicleSpec) by name; LogImportError when it does not exist."""
    try:
        return get_preset(preset)
    except (KeyError, ValueError) as exc:
        raise LogImportError(f"unknown vehicle preset {preset!r}: {exc}") from None


def add_derived(trip: Trip, steps: list[dict[str, Any]], report: ImportReport, vehicle: str | None) -> Trip:
    """Apply the mapping's ``derived`` steps in order; returns a new Trip (meta records the parameters used)."""
    df = trip.measured.copy()
    units = dict(trip.units)
    meta = dict(trip.meta)
    done = []
    t = df["t"].to_numpy(dtype=float)
    for step in steps:
        kind = step.get("kind")
        if kind == "rim_torque":
            if vehicle is None:
                raise LogImportError("derived rim_torque needs the mapping's 'vehicle' preset")
            spec = vehicle_spec(vehicle)
            ratio = float(spec.drivetrain.gear_ratios[0] * spec.drivetrain.final_drive)
            eff = float(step.get("efficiency", 0.97))
            trip.require("drive_torque")
            df["rim_torque"] = rim_torque_from_motor(df["drive_torque"].to_numpy(), ratio, eff)
            units["rim_torque"] = "N*m"
            done.append({"kind": kind, "ratio": ratio, "efficiency": eff, "vehicle": vehicle,
                         "rule": "T_R = i*eta*T_M (T_M >= 0), i*T_M/eta (T_M < 0)"})
        elif kind == "distance":
            speed = step.get("speed", "vehicle_speed")
            trip.require(speed)
            df["distance"] = distance_from_speed(t, df[speed].to_numpy())
            units["distance"] = "m"
            done.append({"kind": kind, "speed": speed})
        elif kind == "grade":
            window = float(step.get("window", 150.0))
            speed = step.get("speed", "vehicle_speed")
            trip.require(speed, "elevation")
            g = grade_from_elevation_track(t, df[speed].to_numpy(), df["elevation"].to_numpy(), report,
                                           window=window, name=str(meta.get("name", "trip")))
            if g is not None:
                df["grade"] = g
                units["grade"] = "rad"
            done.append({"kind": kind, "window_m": window, "speed": speed, "derived": g is not None})
        elif kind == "curvature":
            window = float(step.get("window", 40.0))
            speed = step.get("speed", "vehicle_speed")
            trip.require(speed, "yaw_rate")
            df["curvature"] = curvature_from_yaw_rate_track(t, df[speed].to_numpy(), df["yaw_rate"].to_numpy(),
                                                            report, window=window, name=str(meta.get("name")))
            units["curvature"] = "1/m"
            done.append({"kind": kind, "window_m": window, "speed": speed})
        else:
            raise LogImportError(f"unknown derived step {kind!r}; known: rim_torque, distance, grade, curvature")
    meta["derived"] = done
    meta["import_report"] = report.to_dict()
    return Trip(df, units, meta, trip.truth, dict(trip.truth_units))
