"""Profile files: save/load RoadProfile and DriveCycle as JSON or CSV (with meta), and read GPS/elevation tracks
(CSV with lat/lon or distance + elevation, GPX) into RoadProfiles via ``tracks.profile_from_track``.

JSON: ``{"format": "roadload.road_profile" | "roadload.drive_cycle", "version": 1, "name", "meta", "units",
<arrays>}``. CSV: a first line ``# roadload.road_profile {json: name, meta, units, stops}`` then the columns
``distance,grade,curvature,bank,speed_limit`` (cycles: ``time,speed[,grade]``). Values are SI
(m, rad, 1/m, m/s, s). Files are written atomically (temporary file + os.replace).
"""

from __future__ import annotations

import io
import json
import os
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from roadload.fileio import write_text

from .profile import DriveCycle, RoadProfile, RoadProfileError
from .tracks import latlon_to_xy, haversine_distance, profile_from_track

if TYPE_CHECKING:
    import pandas as pd

PROFILE_FORMAT = "roadload.road_profile"
CYCLE_FORMAT = "roadload.drive_cycle"
VERSION = 1
PROFILE_COLUMNS = ("distance", "grade", "curvature", "bank", "speed_limit")
PROFILE_UNITS = {"distance": "m", "grade": "rad", "curvature": "1/m", "bank": "rad", "speed_limit": "m/s",
                 "stops": "m"}
CYCLE_UNITS = {"time": "s", "speed": "m/s", "grade": "rad"}

_ALIASES = {
    "lat": ("lat", "latitude", "lat_deg"),
    "lon": ("lon", "lng", "long", "longitude", "lon_deg"),
    "distance": ("distance", "distance_m", "dist", "s", "s_m"),
    "elevation": ("elevation", "elevation_m", "ele", "alt", "altitude", "altitude_m", "height", "z"),
    "time": ("time", "time_s", "t", "timestamp", "datetime", "date_time"),
}
#: what each track column is, with its unit (for error messages)
_ROLES = {"lat": "latitude [deg]", "lon": "longitude [deg]", "distance": "cumulative distance [m]",
          "elevation": "elevation [m]", "heading": "heading [deg or rad, heading_unit]",
          "time": "time [s] or a date-time"}


class ProfileFileError(RoadProfileError):
    """A profile or track file is malformed; the message names the file and what is wrong."""


# --------------------------------------------------------------------------------------------- atomic write

def _jsonable(value: Any) -> Any:
    if isinstance(value, dict):
        return {str(k): _jsonable(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_jsonable(v) for v in value]
    if isinstance(value, np.ndarray):
        return [_jsonable(v) for v in value.tolist()]
    if isinstance(value, np.generic):
        return value.item()
    return value


# --------------------------------------------------------------------------------------------- save

def save_profile(profile: RoadProfile | DriveCycle, path: str | os.PathLike) -> Path:
    """Write a RoadProfile or DriveCycle to ``path`` (.json or .csv) atomically; returns the path."""
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix not in (".json", ".csv"):
        raise ProfileFileError(f"{path}: unsupported extension {suffix!r}; use .json or .csv")
    stops: list[float] | None = None  # only road profiles carry stop positions [m]
    if isinstance(profile, DriveCycle):
        kind, units = CYCLE_FORMAT, CYCLE_UNITS
        arrays = {"time": profile.time, "speed": profile.speed}
        if profile.grade is not None:
            arrays["grade"] = profile.grade
    elif isinstance(profile, RoadProfile):
        kind, units = PROFILE_FORMAT, PROFILE_UNITS
        arrays = {c: getattr(profile, c) for c in PROFILE_COLUMNS}
        stops = profile.stops.tolist()
    else:
        raise TypeError(f"save_profile: expected RoadProfile or DriveCycle, got {type(profile).__name__}")
    if suffix == ".json":
        doc = {"format": kind, "version": VERSION, "name": profile.name, "meta": _jsonable(profile.meta),
               "units": units, **{k: v.tolist() for k, v in arrays.items()}}
        if stops is not None:
            doc["stops"] = stops
        text = json.dumps(doc, allow_nan=False)
    else:
        header = {"version": VERSION, "name": profile.name, "meta": _jsonable(profile.meta), "units": units}
        if stops is not None:
            header["stops"] = stops
        import pandas as pd  # here, not at import (see _read_frame)

        buffer = io.StringIO()
        buffer.write(f"# {kind} {json.dumps(header, allow_nan=False)}\n")
        pd.DataFrame(arrays).to_csv(buffer, index=False, float_format="%.17g", lineterminator="\n")
        text = buffer.getvalue()
    write_text(path, text, newline="")
    return path


# --------------------------------------------------------------------------------------------- input checks

def _check_name(path: Path, name: Any) -> str:
    """A profile name from a file: a non-empty string without surrounding white space."""
    if not isinstance(name, str) or not name.strip() or name != name.strip():
        raise ProfileFileError(f"{path}: name must be a non-empty string without leading or trailing spaces, got "
                               f"{name!r}")
    return name


def _check_units(path: Path, units: Any, expected: dict[str, str], where: str) -> None:
    """The ``units`` a file declares must be the SI units roadload stores (the values are read as such)."""
    if units is None:
        return
    if not isinstance(units, dict):
        raise ProfileFileError(f"{path}: 'units' ({where}) must map field names to unit strings, got {units!r}; "
                               f"expected {expected}")
    for field_name, unit in units.items():
        if field_name not in expected:
            raise ProfileFileError(f"{path}: units.{field_name} ({where}): unknown field; the fields are "
                                   f"{sorted(expected)}")
        if unit != expected[field_name]:
            raise ProfileFileError(f"{path}: units.{field_name} ({where}) is {unit!r}; expected "
                                   f"{expected[field_name]!r} (profile files store SI values)")


def _check_time_order(path: Path, seconds: np.ndarray, label: str, where: str = "row") -> None:
    """Refuse a time base that runs backwards (samples out of driving order); missing times are skipped."""
    known = np.flatnonzero(np.isfinite(seconds))
    back = np.flatnonzero(np.diff(seconds[known]) < 0)
    if back.size:
        i, j = int(known[back[0]]), int(known[back[0] + 1])
        raise ProfileFileError(f"{path}: {label} runs backwards at {where} {j}: {seconds[j]:g} s after "
                               f"{seconds[i]:g} s (at {where} {i}); expected time in driving order [s]")


# --------------------------------------------------------------------------------------------- load

def _build(kind: str, name: str, meta: dict, arrays: dict[str, Any], stops, path: Path) -> RoadProfile | DriveCycle:
    _check_name(path, name)
    try:
        if kind == CYCLE_FORMAT:
            for column in ("time", "speed"):
                if column not in arrays:
                    raise ProfileFileError(f"{path}: drive cycle without the {column!r} field")
            _check_time_order(path, np.asarray(arrays["time"], float), "time", "sample")
            return DriveCycle(name=name, time=arrays["time"], speed=arrays["speed"], grade=arrays.get("grade"),
                              meta=meta)
        missing = [c for c in PROFILE_COLUMNS if c not in arrays]
        if missing:
            raise ProfileFileError(f"{path}: road profile without the fields {missing}")
        return RoadProfile(name=name, meta=meta, stops=np.asarray(stops if stops is not None else [], dtype=float),
                           **{c: arrays[c] for c in PROFILE_COLUMNS})
    except ProfileFileError:
        raise
    except (RoadProfileError, ValueError, TypeError) as exc:
        raise ProfileFileError(f"{path}: {exc}") from exc


def _load_json(path: Path) -> RoadProfile | DriveCycle:
    try:
        doc = json.loads(path.read_text(encoding="utf-8"))
    except json.JSONDecodeError as exc:
        raise ProfileFileError(f"{path}: not valid JSON ({exc})") from exc
    if not isinstance(doc, dict) or doc.get("format") not in (PROFILE_FORMAT, CYCLE_FORMAT):
        raise ProfileFileError(f"{path}: not a roadload profile (expected \"format\": {PROFILE_FORMAT!r} or "
                               f"{CYCLE_FORMAT!r})")
    if doc.get("version") != VERSION:
        raise ProfileFileError(f"{path}: unsupported version {doc.get('version')!r} (expected {VERSION})")
    keys = PROFILE_COLUMNS if doc["format"] == PROFILE_FORMAT else ("time", "speed", "grade")
    _check_units(path, doc.get("units"), PROFILE_UNITS if doc["format"] == PROFILE_FORMAT else CYCLE_UNITS, "JSON")
    arrays = {k: _numeric(path, k, doc[k]) for k in keys if doc.get(k) is not None}
    return _build(doc["format"], doc.get("name", path.stem), _meta(path, doc.get("meta")), arrays,
                  doc.get("stops"), path)


def _meta(path: Path, meta: Any) -> dict:
    if meta is None:
        return {}
    if not isinstance(meta, dict):
        raise ProfileFileError(f"{path}: 'meta' must be a JSON object, got {meta!r}")
    return dict(meta)


def _numeric(path: Path, field: str, values) -> np.ndarray:
    try:
        return np.asarray(values, dtype=float)
    except (TypeError, ValueError) as exc:
        raise ProfileFileError(f"{path}: field {field!r} is not numeric ({exc})") from exc


def _load_roadload_csv(path: Path, first_line: str) -> RoadProfile | DriveCycle:
    kind, _, header_text = first_line[1:].strip().partition(" ")
    try:
        header = json.loads(header_text) if header_text else {}
    except json.JSONDecodeError as exc:
        raise ProfileFileError(f"{path}: the header line is not valid JSON ({exc})") from exc
    if not isinstance(header, dict):
        raise ProfileFileError(f"{path}: the header line must hold a JSON object, got {header!r}")
    if kind not in (PROFILE_FORMAT, CYCLE_FORMAT):
        raise ProfileFileError(f"{path}: unknown header {kind!r}; expected {PROFILE_FORMAT!r} or {CYCLE_FORMAT!r}")
    if header.get("version", VERSION) != VERSION:
        raise ProfileFileError(f"{path}: unsupported version {header.get('version')!r} (expected {VERSION})")
    _check_units(path, header.get("units"), PROFILE_UNITS if kind == PROFILE_FORMAT else CYCLE_UNITS,
                 "header line")
    import pandas as pd  # here, not at import (see _read_frame)

    frame = _read_frame(path, skiprows=1)
    arrays = {}
    for column in frame.columns:
        values = pd.to_numeric(frame[column], errors="coerce").to_numpy(float)
        text_bad = np.flatnonzero(np.isnan(values) & frame[column].notna().to_numpy())
        if text_bad.size:
            raise ProfileFileError(f"{path}: column {column!r} has a non-numeric value at row {int(text_bad[0])}")
        arrays[column] = values
    return _build(kind, header.get("name", path.stem), _meta(path, header.get("meta")), arrays,
                  header.get("stops"), path)


def _read_frame(path: Path, skiprows: int = 0) -> pd.DataFrame:
    import pandas as pd  # here, not at import: a road from a JSON file needs no pandas (45 MB of a simulate)

    try:
        frame = pd.read_csv(path, skiprows=skiprows, encoding="utf-8-sig")
    except (pd.errors.ParserError, pd.errors.EmptyDataError, UnicodeDecodeError) as exc:
        raise ProfileFileError(f"{path}: cannot parse CSV ({exc})") from exc
    if frame.empty:
        raise ProfileFileError(f"{path}: no data rows")
    frame.columns = [str(c).strip() for c in frame.columns]
    return frame


def load_profile_file(path: str | os.PathLike, **kw) -> RoadProfile | DriveCycle:
    """Load a .json / .csv / .gpx file. A CSV without the ``# roadload.`` header line is read as a GPS/elevation
    track (``load_track_csv``, keyword arguments passed on); a GPX file via ``load_gpx``."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"profile file {path} does not exist")
    suffix = path.suffix.lower()
    if suffix == ".json":
        if kw:
            raise TypeError(f"unexpected keyword arguments for a JSON profile: {sorted(kw)}")
        return _load_json(path)
    if suffix == ".gpx":
        return load_gpx(path, **kw)
    if suffix == ".csv":
        with path.open(encoding="utf-8-sig") as handle:
            first = handle.readline()
        if first.startswith("# roadload."):
            if kw:
                raise TypeError(f"unexpected keyword arguments for a roadload CSV profile: {sorted(kw)}")
            return _load_roadload_csv(path, first)
        return load_track_csv(path, **kw)
    raise ProfileFileError(f"{path}: unsupported extension {suffix!r}; use .json, .csv or .gpx")


# --------------------------------------------------------------------------------------------- tracks

def _column(frame: pd.DataFrame, path: Path, role: str, given: str | None, required: bool = False) -> np.ndarray | None:
    name = _column_name(frame, path, role, given, required)
    return None if name is None else _numeric_column(frame, path, name, role)


def _column_name(frame: pd.DataFrame, path: Path, role: str, given: str | None, required: bool = False) -> str | None:
    """The column holding ``role``: ``given``, else the one column whose name is an alias of the role (two such
    columns are ambiguous and refused)."""
    if given is not None:
        if given not in frame.columns:
            raise ProfileFileError(f"{path}: no column {given!r} for {role}; columns are {list(frame.columns)}")
        return given
    found = [c for c in frame.columns if c.lower() in _ALIASES[role]]
    if len(found) > 1:
        raise ProfileFileError(f"{path}: columns {found} all look like the {_ROLES[role]}; pass {role}=<column "
                               f"name> to choose one")
    if not found:
        if required:
            raise ProfileFileError(f"{path}: no {role} column (looked for {list(_ALIASES[role])}); "
                                   f"columns are {list(frame.columns)} - pass {role}=<column name>")
        return None
    return found[0]


def _numeric_column(frame: pd.DataFrame, path: Path, name: str, role: str) -> np.ndarray:
    """A numeric column: an empty cell is a missing value (NaN); text or +-inf is refused with its row."""
    import pandas as pd  # here, not at import (see _read_frame)

    values = pd.to_numeric(frame[name], errors="coerce").to_numpy(float)
    text_bad = np.flatnonzero(np.isnan(values) & frame[name].notna().to_numpy())
    if text_bad.size:
        i = int(text_bad[0])
        raise ProfileFileError(f"{path}: column {name!r} has a non-numeric value {frame[name].iloc[i]!r} at row "
                               f"{i}; expected the {_ROLES[role]}")
    inf = np.flatnonzero(np.isinf(values))
    if inf.size:
        i = int(inf[0])
        raise ProfileFileError(f"{path}: column {name!r} has a non-finite value {values[i]:g} at row {i}; expected "
                               f"a finite {_ROLES[role]} (an empty cell marks a missing one)")
    return values


def _time_column(frame: pd.DataFrame, path: Path, given: str | None) -> np.ndarray | None:
    """Seconds from the track's time column (numbers [s] or date-times), None without one."""
    import pandas as pd  # here, not at import (see _read_frame)

    name = _column_name(frame, path, "time", given)
    if name is None:
        return None
    if pd.api.types.is_numeric_dtype(frame[name]):
        return _numeric_column(frame, path, name, "time")
    stamps = pd.to_datetime(frame[name], errors="coerce", utc=True, format="mixed")
    bad = np.flatnonzero(stamps.isna().to_numpy() & frame[name].notna().to_numpy())
    if bad.size:
        i = int(bad[0])
        raise ProfileFileError(f"{path}: column {name!r} has a value {frame[name].iloc[i]!r} at row {i} that is "
                               f"neither seconds nor a date-time; expected the {_ROLES['time']}")
    first = stamps.dropna()
    if first.empty:
        return None
    return ((stamps - first.iloc[0]).dt.total_seconds()).to_numpy(float)


def load_track_csv(path: str | os.PathLike, *, lat: str | None = None, lon: str | None = None,
                   distance: str | None = None, elevation: str | None = None, heading: str | None = None,
                   heading_unit: str = "deg", heading_reference: str = "course", time: str | None = None,
                   name: str | None = None, licence: str = "unknown (user file)", **profile_kw) -> RoadProfile:
    """A RoadProfile from a CSV track: lat/lon [deg] or distance [m], plus optional elevation [m] and heading.

    Column names are found case-insensitively among common aliases (lat/latitude, lon/lng/longitude,
    distance/s, elevation/ele/alt/altitude, time/t/timestamp) or given explicitly; two columns that both match a
    role are refused as ambiguous. With lat/lon the curvature comes from the positions (distance by haversine
    unless a distance column is given); with distance only, from ``heading`` (``heading_reference`` "course" =
    clockwise from north, "math" = counter-clockwise from east; unit "deg" or "rad") or 0. A time column (seconds
    or date-times) must not run backwards: rows out of driving order would be driven in the wrong order. Rows with
    missing lat/lon are dropped (counted in meta repairs); text or +-inf in a numeric column is refused with its
    row. Other keyword arguments go to ``profile_from_track`` (step, elevation_window, heading_window,
    default_speed_limit, ...).
    """
    path = Path(path)
    frame = _read_frame(path)
    lat_v = _column(frame, path, "lat", lat)
    lon_v = _column(frame, path, "lon", lon)
    dist_v = _column(frame, path, "distance", distance)
    ele_v = _column(frame, path, "elevation", elevation)
    time_v = _time_column(frame, path, time)
    if time_v is not None:
        _check_time_order(path, time_v, f"column {_column_name(frame, path, 'time', time)!r}")
    head_v = None
    if heading is not None:
        if heading not in frame.columns:
            raise ProfileFileError(f"{path}: no column {heading!r} for heading; columns are {list(frame.columns)}")
        head_v = _numeric_column(frame, path, heading, "heading")
        if heading_unit not in ("deg", "rad"):
            raise ValueError(f"heading_unit must be 'deg' or 'rad', got {heading_unit!r}")
        if heading_reference not in ("course", "math"):
            raise ValueError(f"heading_reference must be 'course' or 'math', got {heading_reference!r}")
        head_v = np.radians(head_v) if heading_unit == "deg" else head_v
        head_v = np.pi / 2 - head_v if heading_reference == "course" else head_v
    if (lat_v is None) != (lon_v is None):
        raise ProfileFileError(f"{path}: found only one of latitude/longitude; columns are {list(frame.columns)}")
    if lat_v is None and dist_v is None:
        raise ProfileFileError(f"{path}: needs lat/lon or a distance column; columns are {list(frame.columns)} "
                               "(pass lat=, lon= or distance=)")
    meta = {"source": str(path.name), "licence": licence}
    try:
        return _track_from_columns(path, lat_v, lon_v, dist_v, ele_v, head_v, name or path.stem, meta, profile_kw)
    except ProfileFileError:
        raise
    except RoadProfileError as exc:
        raise ProfileFileError(f"{path}: {exc}") from exc


def _track_from_columns(path: Path, lat_v, lon_v, dist_v, ele_v, head_v, name: str, meta: dict,
                        profile_kw: dict) -> RoadProfile:
    dropped = 0
    xy = None
    if lat_v is not None:
        ok = np.isfinite(lat_v) & np.isfinite(lon_v)
        dropped = int((~ok).sum())
        if ok.sum() < 2:
            raise ProfileFileError(f"{path}: fewer than 2 rows with valid latitude/longitude")
        lat_v, lon_v = lat_v[ok], lon_v[ok]
        ele_v = ele_v[ok] if ele_v is not None else None
        head_v = head_v[ok] if head_v is not None else None
        dist_v = dist_v[ok] if dist_v is not None else haversine_distance(lat_v, lon_v)
        if head_v is None:
            xy = latlon_to_xy(lat_v, lon_v)
    if dist_v is not None and np.any(~np.isfinite(dist_v)):
        i = int(np.flatnonzero(~np.isfinite(dist_v))[0])
        raise ProfileFileError(f"{path}: distance has a missing value at row {i}")
    if dropped:
        meta["repairs"] = {"rows_without_position_dropped": dropped}
    return profile_from_track(dist_v, elevation=ele_v, heading=head_v, xy=xy, name=name, meta=meta, **profile_kw)


def _gpx_points(path: Path, gpx) -> list:
    """All track segments' points in order, else the routes', else the waypoints (at least 2)."""
    points = [p for t in gpx.tracks for seg in t.segments for p in seg.points]
    if not points:
        points = [p for r in gpx.routes for p in r.points] or list(gpx.waypoints)
    if len(points) < 2:
        raise ProfileFileError(f"{path}: fewer than 2 track/route points")
    return points


def _gpx_coordinates(path: Path, points: list) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Latitude, longitude [deg] and elevation [m] (NaN where a point has none); ±inf refused naming the point."""
    lat = np.array([p.latitude for p in points], dtype=float)
    lon = np.array([p.longitude for p in points], dtype=float)
    ele = np.array([np.nan if p.elevation is None else p.elevation for p in points], dtype=float)
    for label, values in (("latitude [deg]", lat), ("longitude [deg]", lon), ("elevation [m]", ele)):
        inf = np.flatnonzero(np.isinf(values))
        if inf.size:
            raise ProfileFileError(f"{path}: point {int(inf[0])} has a non-finite {label} {values[inf[0]]:g}")
    return lat, lon, ele


def _check_gpx_times(path: Path, points: list) -> None:
    """Point times, where the file has any, must not run backwards (one time base)."""
    stamps = [getattr(p, "time", None) for p in points]  # track, route and way points all carry one in GPX
    if any(s is not None for s in stamps):
        known = [s for s in stamps if s is not None]
        first = known[0]
        seconds = np.array([np.nan if s is None else _seconds_between(path, first, s) for s in stamps])
        _check_time_order(path, seconds, "the point time", "point")


def load_gpx(path: str | os.PathLike, *, name: str | None = None, licence: str = "unknown (user file)",
             **profile_kw) -> RoadProfile:
    """A RoadProfile from a GPX file: all track segments in order (else the routes, else the waypoints).

    Distance by haversine, curvature from the positions, grade from the elevations (missing elevations are
    interpolated and counted; none at all -> grade 0). Keyword arguments go to ``profile_from_track``.
    """
    import gpxpy
    import gpxpy.gpx

    path = Path(path)
    try:
        gpx = gpxpy.parse(path.read_text(encoding="utf-8"))
    except (gpxpy.gpx.GPXException, ValueError) as exc:
        raise ProfileFileError(f"{path}: not a valid GPX file ({exc})") from exc
    points = _gpx_points(path, gpx)
    lat, lon, ele = _gpx_coordinates(path, points)
    _check_gpx_times(path, points)
    track_name = name or next((t.name for t in gpx.tracks if t.name), None) or path.stem
    meta = {"source": str(path.name), "licence": licence, "gpx_points": len(points)}
    try:
        xy = latlon_to_xy(lat, lon)
        return profile_from_track(haversine_distance(lat, lon), elevation=None if np.isnan(ele).all() else ele,
                                  xy=xy, name=track_name, meta=meta, **profile_kw)
    except RoadProfileError as exc:
        raise ProfileFileError(f"{path}: {exc}") from exc


def _seconds_between(path: Path, first, stamp) -> float:
    try:
        return float((stamp - first).total_seconds())
    except TypeError as exc:  # a time zone on some points only
        raise ProfileFileError(f"{path}: point times mix time zones ({first.isoformat()} and "
                               f"{stamp.isoformat()}); expected one time base") from exc
