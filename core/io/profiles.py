"""Road profiles (grade and curvature over distance) extracted from imported real logs.

A Trip's time series become distance-based tracks and go through ``roadload.road_profiles.tracks.
profile_from_track`` (the project's one implementation of spike removal, smoothing over distance,
differentiation and clipping):

- distance s: integrated speed (GNSS speed when present: OBD-II speed is whole km/h and lags);
- grade from elevation (GNSS altitude, BMW i3 map elevation) smoothed over ``elevation_window`` metres,
  or from GNSS pitch: an elevation track z(s) = integral sin(pitch) ds whose constant mounting offset is
  removed so that z(end) - z(start) matches the altitude difference (section 'grade_source' in meta);
- curvature from the yaw rate (heading psi = integral r dt, gyro bias at standstill removed) or from the GNSS
  course (psi = pi/2 - course), differentiated over distance after smoothing over ``heading_window`` metres
  — i.e. r / v without dividing by speeds near zero.

Profiles carry source, licence, trip name, the choices above and the repair counts in ``meta``.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from ..trip import Trip
from .derived import distance_from_speed, freeze_elevation_at_standstill
from .report import ImportReport, LogImportError
from roadload.road_profiles.tracks import profile_from_track
from roadload.road_profiles.files import save_profile

MAX_PROFILE_GRADE = 0.30  # |tan theta| above 30 % is clipped (and counted) like every import


def _speed(trip: Trip) -> tuple[str, np.ndarray]:
    for name in ("gnss_speed", "vehicle_speed"):
        if trip.has(name):
            v = trip.channel(name)
            return name, np.where(np.isfinite(v), v, 0.0)
    raise LogImportError(f"trip {trip.meta.get('name')!r} has no speed channel (gnss_speed / vehicle_speed)")


def _yaw_heading(t: np.ndarray, speed: np.ndarray, yaw_rate: np.ndarray) -> tuple[np.ndarray, float, int]:
    """Heading psi [rad] integrated from the yaw rate after removing the gyro bias (median at standstill)."""
    r = np.where(np.isfinite(yaw_rate), yaw_rate, 0.0)
    still = speed < 0.05
    bias = float(np.median(r[still])) if still.sum() >= 100 else 0.0
    r = r - bias
    psi = np.concatenate([[0.0], np.cumsum(0.5 * (r[1:] + r[:-1]) * np.diff(t))])
    return psi, bias, int(still.sum())


def profile_from_trip(trip: Trip, *, name: str, source: str, licence: str, grade_source: str = "elevation",
                      curvature_source: str | None = "yaw_rate", elevation_window: float = 150.0,
                      heading_window: float = 40.0, step: float = 5.0, default_speed_limit: float = 100 / 3.6):
    """A RoadProfile (roadload.road_profiles) of the road a real trip drove.

    grade_source: 'elevation' | 'pitch' | None (grade 0). curvature_source: 'yaw_rate' | 'heading' | None.
    The speed limit is not in the logs: ``default_speed_limit`` everywhere (marked in meta).
    """

    t = trip.t
    speed_name, v = _speed(trip)
    s = distance_from_speed(t, v)
    if s[-1] < 2 * max(elevation_window, heading_window):
        raise LogImportError(f"trip {trip.meta.get('name')!r}: only {s[-1]:.0f} m driven, too short for a profile")
    info: dict[str, Any] = {"source": source, "licence": licence, "trip": trip.meta.get("name"),
                            "distance_from": f"integrated {speed_name}",
                            "speed_limit_meaning": f"not in the log: default {default_speed_limit * 3.6:.0f} km/h",
                            "grade_source": grade_source, "curvature_source": curvature_source,
                            "import_report": {"n_repaired": trip.meta.get("import_report", {}).get("n_repaired"),
                                              "n_dropped": trip.meta.get("import_report", {}).get("n_dropped")}}
    if trip.meta.get("t0_unix") is not None:
        info["t0_unix"] = trip.meta["t0_unix"]
    elevation = None
    report = ImportReport()
    if grade_source == "elevation":
        trip.require("elevation")
        elevation = freeze_elevation_at_standstill(v, trip.channel("elevation"), report)
    elif grade_source == "pitch":
        trip.require("pitch", "elevation")
        pitch = np.where(np.isfinite(trip.channel("pitch")), trip.channel("pitch"), 0.0)
        z_rel = np.concatenate([[0.0], np.cumsum(0.5 * (np.sin(pitch[1:]) + np.sin(pitch[:-1])) * np.diff(s))])
        alt = trip.channel("elevation")
        ok = np.flatnonzero(np.isfinite(alt))
        rise = float(alt[ok[-1]] - alt[ok[0]]) if ok.size > 1 else 0.0
        offset = (z_rel[-1] - rise) / s[-1]  # mean sin(pitch) that is mounting, not road
        elevation = z_rel - offset * s
        info["pitch_mounting_offset_rad"] = float(np.arcsin(np.clip(offset, -1, 1)))
    elif grade_source is not None:
        raise LogImportError(f"grade_source must be 'elevation', 'pitch' or None, got {grade_source!r}")
    heading = None
    if curvature_source == "yaw_rate":
        trip.require("yaw_rate")
        heading, bias, n_still = _yaw_heading(t, v, trip.channel("yaw_rate"))
        info["yaw_rate_bias_rad_s"] = bias
        info["yaw_rate_bias_from_standstill_samples"] = n_still
    elif curvature_source == "heading":
        trip.require("heading")
        course = trip.channel("heading")
        ok = np.isfinite(course)
        course = np.interp(t, t[ok], np.unwrap(course[ok]))
        heading = np.pi / 2 - course  # compass course (clockwise from north) -> counter-clockwise from east
    elif curvature_source is not None:
        raise LogImportError(f"curvature_source must be 'yaw_rate', 'heading' or None, got {curvature_source!r}")
    info["repairs_before_smoothing"] = report.to_dict()["repairs"]
    return profile_from_track(s, elevation=elevation, heading=heading, name=name, step=step,
                              elevation_window=elevation_window, heading_window=heading_window,
                              max_grade=MAX_PROFILE_GRADE, default_speed_limit=default_speed_limit, meta=info)


def save_trip_profile(profile, folder: str | Path) -> Path:
    """Write the profile as ``<folder>/<name>.json`` in the road-profiles file format (atomic)."""

    return save_profile(profile, Path(folder) / f"{profile.name}.json")
