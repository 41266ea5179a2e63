"""Road profiles from measured tracks: distance, elevation, heading or planar positions -> RoadProfile.

GNSS and map data are noisy and quantised (e.g. the BMW i3 elevation is quantised to 1 m), so every derivative is
taken only after smoothing over *distance* (never over time: a vehicle standing still must not smear the road):

* elevation z(s) -> smoothed over ~150 m -> grade theta = arctan(dz/ds)          (grade_from_elevation)
* heading psi(s) -> unwrapped, smoothed over ~40 m -> curvature kappa = dpsi/ds   (curvature_from_heading)
* positions x(s), y(s) -> smoothed -> heading -> curvature                       (curvature_from_xy)

Smoothing is a Gaussian kernel over distance whose +-2 sigma span equals ``window`` [m] (sigma = window/4), applied
on a uniform grid with point-symmetric padding at the ends, so a straight ramp or a circular arc is reproduced
exactly (no end effects on linear trends). Absurd values after differentiation are clipped and the number of
clipped samples is recorded in ``meta["repairs"]`` of the resulting profile.
"""

from __future__ import annotations

import logging
from typing import Any

import numpy as np

from .profile import RoadProfile, RoadProfileError

log = logging.getLogger(__name__)

EARTH_RADIUS = 6_371_008.8  # m, mean Earth radius (IUGG)
DEFAULT_STEP = 5.0  # m, distance grid of resampled profiles
DEFAULT_ELEVATION_WINDOW = 150.0  # m
DEFAULT_HEADING_WINDOW = 40.0  # m
DEFAULT_MAX_GRADE = 0.25  # rise/run; steeper after smoothing is a data error, not a road
DEFAULT_MAX_CURVATURE = 0.2  # 1/m, i.e. a 5 m turning radius
DEFAULT_MIN_SPACING = 0.5  # m, samples closer than this to the previous kept one are dropped


# --------------------------------------------------------------------------------------------- geometry

def haversine_distance(lat, lon) -> np.ndarray:
    """Cumulative great-circle distance [m] along lat/lon [deg] samples (starts at 0)."""
    lat = np.radians(np.asarray(lat, dtype=float))
    lon = np.radians(np.asarray(lon, dtype=float))
    dlat, dlon = np.diff(lat), np.diff(lon)
    a = np.sin(dlat / 2) ** 2 + np.cos(lat[:-1]) * np.cos(lat[1:]) * np.sin(dlon / 2) ** 2
    step = 2 * EARTH_RADIUS * np.arcsin(np.sqrt(np.clip(a, 0.0, 1.0)))
    return np.concatenate([[0.0], np.cumsum(step)])


def latlon_to_xy(lat, lon) -> tuple[np.ndarray, np.ndarray]:
    """Planar east/north positions x, y [m] from lat/lon [deg], starting at (0, 0).

    Each step is projected in the local east-north-up frame at its own mid latitude and the steps are summed, so
    local geometry (heading, curvature) stays exact over routes of hundreds of km where a single tangent plane
    would distort; absolute positions of far-apart points are only approximate, which no derivative here needs.
    """
    lat = np.asarray(lat, dtype=float)
    lon = np.asarray(lon, dtype=float)
    if lat.shape != lon.shape or lat.ndim != 1:
        raise RoadProfileError(f"lat/lon: expected two 1-D arrays of equal length, got {lat.shape} and {lon.shape}")
    for name, arr in (("latitude", lat), ("longitude", lon)):
        bad = np.flatnonzero(~np.isfinite(arr))
        if bad.size:
            raise RoadProfileError(f"{name}: {bad.size} NaN/inf values, first at index {int(bad[0])}")
    if np.any(np.abs(lat) > 90) or np.any(np.abs(lon) > 360):
        raise RoadProfileError("latitude/longitude: values out of range (are the columns swapped or not degrees?)")
    lat_r, lon_r = np.radians(lat), np.radians(lon)
    dlon = (np.diff(lon_r) + np.pi) % (2 * np.pi) - np.pi  # across the antimeridian
    lat_mid = 0.5 * (lat_r[1:] + lat_r[:-1])
    dx = EARTH_RADIUS * np.cos(lat_mid) * dlon
    dy = EARTH_RADIUS * np.diff(lat_r)
    return np.concatenate([[0.0], np.cumsum(dx)]), np.concatenate([[0.0], np.cumsum(dy)])


def path_length(x, y) -> np.ndarray:
    """Cumulative planar distance [m] along positions x, y [m] (starts at 0)."""
    return np.concatenate([[0.0], np.cumsum(np.hypot(np.diff(x), np.diff(y)))])


# --------------------------------------------------------------------------------------------- smoothing

def _uniform_grid(distance: np.ndarray, step: float) -> np.ndarray:
    length = float(distance[-1] - distance[0])
    n = max(int(round(length / step)) + 1, 2)
    return np.linspace(distance[0], distance[-1], n)


def _gaussian_point_symmetric(values: np.ndarray, sigma_samples: float) -> np.ndarray:
    """Gaussian filter with point-symmetric (odd) padding: linear trends pass unchanged, also at the ends."""
    if sigma_samples <= 0.0 or values.size < 3:
        return values.copy()
    pad = min(int(np.ceil(4 * sigma_samples)), values.size - 1)
    left = 2 * values[0] - values[1:pad + 1][::-1]
    right = 2 * values[-1] - values[-pad - 1:-1][::-1]
    padded = np.concatenate([left, values, right])
    from scipy.ndimage import gaussian_filter1d  # here, not at import: 16 MB a trip simulated from a file never needs

    out = gaussian_filter1d(padded, sigma_samples, mode="nearest", truncate=4.0)
    return out[pad:pad + values.size]


def smooth_over_distance(distance, values, window: float, *, step: float | None = None) -> np.ndarray:
    """Values smoothed over distance with a Gaussian kernel, sigma = window/4 [m]; returned at the input samples.

    distance [m] must be strictly increasing (may be non-uniform). The signal is interpolated onto a uniform grid
    of ``step`` (default: the finer of window/20 and the median sample spacing, at least 0.25 m), filtered with
    point-symmetric end padding (straight lines stay straight) and interpolated back. window <= 0 returns the
    values unchanged.
    """
    distance = np.asarray(distance, dtype=float)
    values = np.asarray(values, dtype=float)
    _check_track("distance", distance)
    if values.shape != distance.shape:
        raise RoadProfileError(f"values: length {values.size} differs from distance length {distance.size}")
    if window <= 0 or distance.size < 3:
        return values.copy()
    h = step if step is not None else max(min(window / 20.0, float(np.median(np.diff(distance)))), 0.25)
    h = max(h, float(distance[-1] - distance[0]) / 2_000_000)  # bound the grid size on very long routes
    grid = _uniform_grid(distance, h)
    h = float(grid[1] - grid[0])
    smooth = _gaussian_point_symmetric(np.interp(grid, distance, values), (window / 4.0) / h)
    return np.interp(distance, grid, smooth)


def remove_spikes(distance, values, *, threshold: float, window: float = 200.0) -> tuple[np.ndarray, int]:
    """Replace samples deviating more than ``threshold`` from the running median over ``window`` [m].

    Returns (cleaned values, number replaced). Replaced samples are linearly interpolated over distance from the
    kept neighbours. Use for GNSS altitude glitches (e.g. -5400 m at start-up) before smoothing.
    """
    distance = np.asarray(distance, dtype=float)
    values = np.asarray(values, dtype=float)
    if values.size < 3:
        return values.copy(), 0
    spacing = max(float(np.median(np.diff(distance))), 1e-3)
    size = int(np.clip(window / spacing, 3, max(values.size // 2 * 2 - 1, 3))) | 1
    from scipy.ndimage import median_filter  # here, not at import (as gaussian_filter1d above)

    median = median_filter(values, size=size, mode="nearest")
    bad = np.abs(values - median) > threshold
    if not bad.any():
        return values.copy(), 0
    if bad.all():
        raise RoadProfileError("values: every sample is an outlier against its running median")
    out = values.copy()
    out[bad] = np.interp(distance[bad], distance[~bad], values[~bad])
    return out, int(bad.sum())


# --------------------------------------------------------------------------------------------- derivatives

def grade_from_elevation(distance, elevation, *, window: float = DEFAULT_ELEVATION_WINDOW) -> np.ndarray:
    """Gradient angle theta = arctan(dz/ds) [rad] from elevation z [m] over distance s [m], smoothed over window."""
    distance = np.asarray(distance, dtype=float)
    z = smooth_over_distance(distance, elevation, window)
    return np.arctan(np.gradient(z, distance))


def curvature_from_heading(distance, heading, *, window: float = DEFAULT_HEADING_WINDOW) -> np.ndarray:
    """Curvature kappa = dpsi/ds [1/m] (positive = left turn) from heading psi [rad] over distance s [m].

    psi is counter-clockwise from east (math convention); a compass course (clockwise from north) must be
    converted first: psi = pi/2 - course. The heading is unwrapped, then smoothed over ``window`` before
    differentiation.
    """
    distance = np.asarray(distance, dtype=float)
    psi = np.unwrap(np.asarray(heading, dtype=float))
    return np.gradient(smooth_over_distance(distance, psi, window), distance)


def heading_from_xy(distance, x, y, *, window: float = DEFAULT_HEADING_WINDOW) -> np.ndarray:
    """Unwrapped heading psi [rad] (counter-clockwise from +x / east) of positions x, y [m] smoothed over window.

    x and y are smoothed over the given distance before the direction is taken, so GNSS jitter between close
    samples cannot produce heading reversals.
    """
    distance = np.asarray(distance, dtype=float)
    xs = smooth_over_distance(distance, x, window / 2)
    ys = smooth_over_distance(distance, y, window / 2)
    return np.unwrap(np.arctan2(np.gradient(ys, distance), np.gradient(xs, distance)))


def curvature_from_xy(distance, x, y, *, window: float = DEFAULT_HEADING_WINDOW) -> np.ndarray:
    """Curvature kappa [1/m] (positive = left) of a planar path x, y [m] over its distance s [m].

    Positions are smoothed (window/2), the heading is taken and differentiated by ``curvature_from_heading``
    (window/2 again), so the total smoothing is comparable to ``curvature_from_heading(window)``.
    Gaussian smoothing of a circle shrinks it but keeps its heading rate over the original arc length, so a
    circle of radius R gives 1/R.
    """
    psi = heading_from_xy(distance, x, y, window=window)
    return curvature_from_heading(distance, psi, window=window / 2)


def curve_speed_limit(curvature, *, base_limit, lateral_acceleration: float) -> np.ndarray:
    """Speed limit [m/s] reduced in curves to sqrt(a_y / |kappa|): min(base_limit, sqrt(a_y/|kappa|)).

    ``lateral_acceleration`` a_y [m/s^2] is the comfortable lateral acceleration (e.g. 2 m/s^2 on public roads).
    """
    kappa = np.abs(np.asarray(curvature, dtype=float))
    with np.errstate(divide="ignore"):
        v_curve = np.where(kappa > 0, np.sqrt(lateral_acceleration / np.maximum(kappa, 1e-300)), np.inf)
    return np.minimum(np.broadcast_to(np.asarray(base_limit, dtype=float), kappa.shape), v_curve)


# --------------------------------------------------------------------------------------------- track -> profile

def _check_track(name: str, distance: np.ndarray) -> None:
    if distance.ndim != 1 or distance.size < 2:
        raise RoadProfileError(f"{name}: expected a 1-D array of >= 2 samples, got shape {distance.shape}")
    bad = np.flatnonzero(~np.isfinite(distance))
    if bad.size:
        raise RoadProfileError(f"{name}: {bad.size} NaN/inf values, first at index {int(bad[0])}")
    if not np.all(np.diff(distance) > 0):
        first = int(np.flatnonzero(np.diff(distance) <= 0)[0]) + 1
        raise RoadProfileError(f"{name}: not strictly increasing at index {first}")


def _thin(distance: np.ndarray, min_spacing: float) -> np.ndarray:
    """Indices of samples kept so that each is at least min_spacing [m] beyond the previous kept one."""
    keep = [0]
    last = distance[0]
    for i in range(1, distance.size):
        if distance[i] - last >= min_spacing:
            keep.append(i)
            last = distance[i]
    if keep[-1] != distance.size - 1 and distance[-1] - distance[keep[-1]] > 1e-9:
        keep[-1] = distance.size - 1  # keep the end point so the profile has the full length
    return np.asarray(keep)


def _optional(name: str, values, n: int) -> np.ndarray | None:
    if values is None:
        return None
    arr = np.asarray(values, dtype=float)
    if arr.ndim != 1 or arr.size != n:
        raise RoadProfileError(f"{name}: expected {n} samples like distance, got shape {arr.shape}")
    return arr


def _fill_missing(name: str, distance: np.ndarray, values: np.ndarray, repairs: dict[str, int]) -> np.ndarray:
    bad = ~np.isfinite(values)
    if not bad.any():
        return values
    if bad.all():
        raise RoadProfileError(f"{name}: no valid samples")
    out = values.copy()
    out[bad] = np.interp(distance[bad], distance[~bad], values[~bad])
    repairs[f"{name}_missing_interpolated"] = int(bad.sum())
    return out


def _track_distance(distance, heading, xy) -> tuple[np.ndarray, np.ndarray | None, np.ndarray | None]:
    """(s [m], x, y) of a track: the given cumulative distance, or the path length of the planar positions xy."""
    x = y = None
    if xy is not None:
        x, y = (np.asarray(a, dtype=float) for a in xy)
        if x.shape != y.shape or x.ndim != 1:
            raise RoadProfileError(f"xy: expected two 1-D arrays of equal length, got {x.shape} and {y.shape}")
        for nm, arr in (("x", x), ("y", y)):
            bad = np.flatnonzero(~np.isfinite(arr))
            if bad.size:
                raise RoadProfileError(f"{nm}: {bad.size} NaN/inf values, first at index {int(bad[0])}")
        if heading is not None:
            raise RoadProfileError("give either heading or xy, not both")
    if distance is None:
        if x is None or y is None:
            raise RoadProfileError("distance: required when no xy positions are given")
        distance = path_length(x, y)
    distance = np.asarray(distance, dtype=float)
    if distance.ndim != 1 or distance.size < 2:
        raise RoadProfileError(f"distance: expected a 1-D array of >= 2 samples, got shape {distance.shape}")
    bad = np.flatnonzero(~np.isfinite(distance))
    if bad.size:
        raise RoadProfileError(f"distance: {bad.size} NaN/inf values, first at index {int(bad[0])}")
    back = np.flatnonzero(np.diff(distance) < -1e-6)
    if back.size:
        raise RoadProfileError(f"distance: decreases at index {int(back[0]) + 1} (distance must be cumulative)")
    return distance, x, y


def _grade_on_grid(s: np.ndarray, grid: np.ndarray, z: np.ndarray | None, spike_threshold: float | None,
                   window: float, repairs: dict[str, int]) -> np.ndarray:
    """θ [rad] on the grid from the elevation z [m] at s (missing samples interpolated, spikes replaced; 0 without
    elevation)."""
    if z is None:
        return np.zeros_like(grid)
    z = _fill_missing("elevation", s, z, repairs)
    if spike_threshold is not None:
        z, n_spikes = remove_spikes(s, z, threshold=spike_threshold)
        if n_spikes:
            repairs["elevation_spikes_replaced"] = n_spikes
    return grade_from_elevation(grid, np.interp(grid, s, z), window=window)


def _curvature_from_track_heading(s: np.ndarray, grid: np.ndarray, psi: np.ndarray, window: float,
                                  repairs: dict[str, int]) -> np.ndarray:
    """κ [1/m] on the grid from the heading ψ [rad] at s (unwrapped before gaps are bridged, so that a gap across
    ±π is not a turn)."""
    psi = psi.copy()
    finite = np.isfinite(psi)
    psi[finite] = np.unwrap(psi[finite])
    psi = _fill_missing("heading", s, psi, repairs)
    return curvature_from_heading(grid, np.interp(grid, s, psi), window=window)


def _clip_grade_and_curvature(grade: np.ndarray, curvature: np.ndarray, max_grade: float, max_curvature: float,
                              repairs: dict[str, int]) -> tuple[np.ndarray, np.ndarray]:
    """|tan θ| ≤ max_grade and |κ| ≤ max_curvature (each clipped sample counted)."""
    limit_tan = np.tan(grade)
    too_steep = np.abs(limit_tan) > max_grade
    if too_steep.any():
        repairs["grade_clipped"] = int(too_steep.sum())
        grade = np.arctan(np.clip(limit_tan, -max_grade, max_grade))
    too_tight = np.abs(curvature) > max_curvature
    if too_tight.any():
        repairs["curvature_clipped"] = int(too_tight.sum())
        curvature = np.clip(curvature, -max_curvature, max_curvature)
    return grade, curvature


def profile_from_track(distance=None, elevation=None, heading=None, xy=None, *,
                       name: str = "track",
                       speed_limit=None,
                       default_speed_limit: float = 100 / 3.6,
                       curve_lateral_acceleration: float | None = None,
                       bank=None,
                       stops=(),
                       step: float = DEFAULT_STEP,
                       elevation_window: float = DEFAULT_ELEVATION_WINDOW,
                       heading_window: float = DEFAULT_HEADING_WINDOW,
                       elevation_spike_threshold: float | None = 50.0,
                       max_grade: float = DEFAULT_MAX_GRADE,
                       max_curvature: float = DEFAULT_MAX_CURVATURE,
                       min_spacing: float = DEFAULT_MIN_SPACING,
                       meta: dict[str, Any] | None = None) -> RoadProfile:
    """A RoadProfile on a uniform distance grid from a measured track.

    distance: cumulative distance s [m] per sample (non-decreasing, e.g. integrated wheel speed or haversine);
      computed from ``xy`` when omitted. elevation z [m] (NaN = missing, interpolated and counted) -> grade.
      heading psi [rad] (counter-clockwise from east) or xy = (x, y) [m] planar positions -> curvature; with
      neither the curvature is 0. speed_limit [m/s] per sample (else ``default_speed_limit``), optionally reduced
      in curves to sqrt(a_y/|kappa|) when ``curve_lateral_acceleration`` a_y [m/s^2] is given. bank [rad] per
      sample (else 0). stops: distances [m] where the vehicle must stop.

    Steps: drop samples closer than ``min_spacing`` to the previous kept one (standstill, GNSS jitter); replace
    elevation spikes (> ``elevation_spike_threshold`` m from the running median over 200 m); resample onto a
    uniform ``step`` grid; smooth elevation over ``elevation_window`` and heading over ``heading_window`` before
    differentiating; clip |tan theta| > ``max_grade`` and |kappa| > ``max_curvature``. Every repair is counted in
    ``meta["repairs"]`` and logged as a warning (dropped close samples are ordinary thinning: counted only).
    """
    repairs: dict[str, int] = {}
    distance, x, y = _track_distance(distance, heading, xy)
    n = distance.size
    z = _optional("elevation", elevation, n)
    psi = _optional("heading", heading, n)
    v_lim = _optional("speed_limit", speed_limit, n)
    phi = _optional("bank", bank, n)
    if x is not None and x.size != n:
        raise RoadProfileError(f"xy: {x.size} samples, distance has {n}")

    keep = _thin(distance, min_spacing)
    if keep.size < 2:
        raise RoadProfileError(f"distance: the track is shorter than {min_spacing} m")
    if keep.size < n:
        repairs["samples_dropped_too_close"] = int(n - keep.size)
    s = distance[keep] - distance[keep[0]]

    grid = _uniform_grid(s, step)
    grade = _grade_on_grid(s, grid, None if z is None else z[keep], elevation_spike_threshold, elevation_window,
                           repairs)
    if psi is not None:
        curvature = _curvature_from_track_heading(s, grid, psi[keep], heading_window, repairs)
    elif x is not None and y is not None:
        curvature = curvature_from_xy(grid, np.interp(grid, s, x[keep]), np.interp(grid, s, y[keep]),
                                      window=heading_window)
    else:
        curvature = np.zeros_like(grid)
    grade, curvature = _clip_grade_and_curvature(grade, curvature, max_grade, max_curvature, repairs)

    if v_lim is not None:
        limit = np.interp(grid, s, _fill_missing("speed_limit", s, v_lim[keep], repairs))
    else:
        limit = np.full_like(grid, float(default_speed_limit))
    if curve_lateral_acceleration is not None:
        limit = curve_speed_limit(curvature, base_limit=limit, lateral_acceleration=curve_lateral_acceleration)
    if phi is not None:
        bank_grid = np.interp(grid, s, _fill_missing("bank", s, phi[keep], repairs))
    else:
        bank_grid = np.zeros_like(grid)

    grid = grid - grid[0]
    stops_arr = np.asarray(stops, dtype=float)
    stops_arr = stops_arr[(stops_arr >= 0) & (stops_arr <= grid[-1])]
    info = dict(meta or {})
    info.setdefault("source", "track")
    info["repairs"] = {**info.get("repairs", {}), **repairs}
    info["processing"] = {"step_m": float(grid[1] - grid[0]), "elevation_window_m": elevation_window,
                          "heading_window_m": heading_window, "smoothing": "gaussian, sigma = window/4",
                          "max_grade": max_grade, "max_curvature_1_per_m": max_curvature,
                          "has_elevation": z is not None, "has_heading": psi is not None or x is not None}
    serious = {k: v for k, v in repairs.items() if k != "samples_dropped_too_close"}
    if serious:
        log.warning("profile %s: repaired %s", name, serious)
    return RoadProfile(name=name, distance=grid, grade=grade, curvature=curvature, bank=bank_grid,
                       speed_limit=limit, stops=np.sort(stops_arr), meta=info)
