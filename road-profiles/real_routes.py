"""Real routes from the shared data folder as named profiles (read in place, never copied; licence kept in meta).

* NREL GradeIT GPS traces (BSD-3-Clause): curvature from lat/lon, no elevation (grade 0), speed limit
  estimated from the measured GPS speed (see ``gradeit_route``).
* TUMFTM race-track centre lines (LGPL-3.0): closed-loop curvature profiles, curve speed from lateral acceleration.
* TUM FTM Eco-Driving Singapore bus routes (LGPL-3.0): posted speed limits, corner speeds, bus stops with dwell
  times and traffic lights with their signal timing (in meta) -- a city route with real stops for the MPC.
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from roadload.data import shared_data_dir

from .profile import DriveCycle, RoadProfile, RoadProfileError
from .tracks import DEFAULT_HEADING_WINDOW, haversine_distance, latlon_to_xy, path_length, profile_from_track

if TYPE_CHECKING:
    import pandas as pd

GRADEIT_TRIPS = {"gradeit_trip1": "sample_trip_1.csv", "gradeit_trip2": "sample_trip_2.csv",
                 "gradeit_trip3": "sample_trip_3.csv", "gradeit_sf_bridge": "SF_bridge_trip_segment.csv"}
RACETRACKS = ("Austin", "BrandsHatch", "Budapest", "Catalunya", "Hockenheim", "IMS", "Melbourne", "MexicoCity",
              "Montreal", "Monza", "MoscowRaceway", "Norisring", "Nuerburgring", "Oschersleben", "Sakhir",
              "SaoPaulo", "Sepang", "Shanghai", "Silverstone", "Sochi", "Spa", "Spielberg", "Suzuka", "YasMarina",
              "Zandvoort")
BUS_ROUTES = {"bus_route91": "Route91", "bus_route185": "Route185", "bus_route91_3stops": "Route91_first3stops"}

_GRADEIT = ("NREL/gradeit examples/data (snapshot b2fefa03)", "BSD-3-Clause (Alliance for Sustainable Energy)")
_RACETRACK = ("TUMFTM/racetrack-database tracks/ (snapshot e59595d1)", "LGPL-3.0")
_BUS = ("TUMFTM/Eco-Driving Input/*.mat (snapshot 0f02a915), Teichert, doi 10.1109/ITSC45102.2020.9294517",
        "LGPL-3.0")


def _folder(name: str) -> Path:
    base = shared_data_dir()
    if base is None or not (base / name).is_dir():
        raise FileNotFoundError(f"this profile needs the shared data folder {name}/: set ROADLOAD_DATA to the shared "
                                "data folder (or place it at ../shared/data next to the project)")
    return base / name


def _read(path: Path, columns: tuple[str, ...], **kw) -> pd.DataFrame:
    import pandas as pd  # here, not at import: a simulate on another road needs no pandas (45 MB)

    if not path.is_file():
        raise FileNotFoundError(f"{path} is missing from the shared data folder")
    frame = pd.read_csv(path, **kw)
    missing = [c for c in columns if c not in frame.columns]
    if missing:
        raise RoadProfileError(f"{path.name}: missing columns {missing}; found {list(frame.columns)}")
    return frame


# --------------------------------------------------------------------------------------------- GradeIT GPS

def gradeit_route(name: str, step: float = 5.0, limit_window: float = 1000.0) -> RoadProfile:
    """GradeIT GPS trace ``name`` (a key of GRADEIT_TRIPS) as a RoadProfile over distance.

    Curvature from the positions, heading window max(40 m, 2x median sample spacing) because samples are
    1-2 s (25-40 m) apart. No elevation in the data: grade 0. No posted limits in the data: speed_limit is the
    running maximum of the measured GPS speed over ``limit_window`` [m], rounded up to 10 km/h (>= 30 km/h),
    marked as estimated in meta. The largest gap between samples is reported in meta (trip 3 has a 2.7 km
    GPS dropout bridged by a straight line).
    """
    if name not in GRADEIT_TRIPS:
        raise RoadProfileError(f"unknown GradeIT trip {name!r}; known: {sorted(GRADEIT_TRIPS)}")
    path = _folder("gps_routes_gradeit") / GRADEIT_TRIPS[name]
    sf = name == "gradeit_sf_bridge"
    frame = _read(path, ("latitude", "longitude", "gpsspeed" if sf else "speed_kph"))
    lat, lon = frame["latitude"].to_numpy(float), frame["longitude"].to_numpy(float)
    speed = frame["gpsspeed"].to_numpy(float) * 0.44704 if sf else frame["speed_kph"].to_numpy(float) / 3.6
    distance = haversine_distance(lat, lon)
    spacing = np.diff(distance)
    window = max(DEFAULT_HEADING_WINDOW, 2.0 * float(np.median(spacing[spacing > 0.5])))
    profile = profile_from_track(distance, xy=latlon_to_xy(lat, lon), step=step, heading_window=window, name=name,
                                 meta={"source": f"{_GRADEIT[0]}/{path.name}", "licence": _GRADEIT[1],
                                       "speed_limit_meaning": f"estimated: running max of GPS speed over "
                                                              f"{limit_window:.0f} m, rounded up to 10 km/h",
                                       "grade_meaning": "no elevation in the data: grade set to 0",
                                       "largest_sample_gap_m": float(spacing.max())})
    # running max of the measured speed over limit_window on the profile grid, rounded up to 10 km/h
    grid = profile.distance
    size = int(round(limit_window / (grid[1] - grid[0]))) | 1
    from scipy.ndimage import maximum_filter1d  # here, not at import: 16 MB a trip simulated from a file never needs

    running_max = maximum_filter1d(np.interp(grid, distance, speed), size=size, mode="nearest")
    limit = np.maximum(np.ceil(running_max * 3.6 / 10.0 - 1e-9) * 10.0, 30.0) / 3.6
    return replace(profile, speed_limit=limit)


# --------------------------------------------------------------------------------------------- race tracks

def racetrack(track: str, laps: int = 1, step: float = 5.0, lateral_acceleration: float = 6.0,
              max_speed: float = 200 / 3.6) -> RoadProfile:
    """Race-circuit centre line ``track`` (one of RACETRACKS) as a closed-loop curvature profile of ``laps`` laps.

    The loop is tiled before smoothing so the curvature is periodic (no end effects at the start/finish line).
    speed_limit = min(max_speed, sqrt(lateral_acceleration / |kappa|)) -- a curve speed, not a posted limit
    (defaults: 6 m/s^2, 200 km/h). Grade and bank 0 (planar data).
    """
    key = {t.lower(): t for t in RACETRACKS}.get(track.lower())
    if key is None:
        raise RoadProfileError(f"unknown race track {track!r}; known: {list(RACETRACKS)}")
    if laps < 1:
        raise RoadProfileError(f"laps must be >= 1, got {laps}")
    path = _folder("racetrack_geometry") / "tracks" / f"{key}.csv"
    if not path.is_file():
        raise FileNotFoundError(f"{path} is missing from the shared data folder")
    import pandas as pd  # here, not at import (see _read)

    xy = pd.read_csv(path, comment="#", header=None).to_numpy(float)[:, :2]
    if not np.isfinite(xy).all():
        raise RoadProfileError(f"{path.name}: NaN in the centre line")
    closed = np.vstack([xy, xy[:1]])  # close the loop
    lap_length = float(path_length(closed[:, 0], closed[:, 1])[-1])
    tiled = np.vstack([closed[:-1]] * (laps + 2) + [closed[:1]])
    full = profile_from_track(xy=(tiled[:, 0], tiled[:, 1]), step=step, name=key, default_speed_limit=max_speed,
                              curve_lateral_acceleration=lateral_acceleration)
    keep = (full.distance >= lap_length - 1e-6) & (full.distance <= (laps + 1) * lap_length + 1e-6)
    distance = full.distance[keep] - full.distance[keep][0]
    return RoadProfile(name=f"racetrack_{key.lower()}", distance=distance, grade=full.grade[keep],
                       curvature=full.curvature[keep], bank=full.bank[keep], speed_limit=full.speed_limit[keep],
                       meta={**full.meta, "source": f"{_RACETRACK[0]}/{path.name}", "licence": _RACETRACK[1],
                             "lap_length_m": lap_length, "laps": laps, "closed_loop": True,
                             "speed_limit_meaning": f"curve speed sqrt({lateral_acceleration} m/s^2 / |kappa|), "
                                                    f"capped at {max_speed * 3.6:.0f} km/h"})


# --------------------------------------------------------------------------------------------- bus routes

def _bus_csv(route: str, part: str, columns: tuple[str, ...]) -> pd.DataFrame:
    return _read(_folder("tum_ecodriving_bus_routes") / "csv" / f"{route}_{part}.csv", columns)


def bus_route(name: str, step: float = 5.0, corner_half_length: float = 10.0) -> RoadProfile:
    """Singapore bus route ``name`` (a key of BUS_ROUTES) with its real constraints as a RoadProfile.

    speed_limit: the posted piecewise-constant limits, reduced to the measured maximum cornering speed over
    +-``corner_half_length`` [m] around each corner; stops: the bus stops after the start (dwell times [s] in
    meta["stop_dwell_s"]); traffic lights (position, first green, green and red durations [s]) in
    meta["traffic_lights"]. Length: the end of the route (last stop / limit breakpoint / measured trip). No
    elevation and no geometry in the data: grade, curvature and bank are 0.
    """
    if name not in BUS_ROUTES:
        raise RoadProfileError(f"unknown bus route {name!r}; known: {sorted(BUS_ROUTES)}")
    route = BUS_ROUTES[name]
    limits = _bus_csv(route, "speed_limits", ("s_vlim_m", "v_vlim_mps"))
    stops = _bus_csv(route, "stops", ("s_stop_m", "t_stop_s"))
    corners = _bus_csv(route, "corners", ("s_corner_m", "v_corner_mps"))
    lights = _bus_csv(route, "traffic_lights", ("s_tl_m", "t_firstgreen_s", "t_green_s", "t_red_s"))
    measured = _bus_csv(route, "measured_profile", ("t_measured_s", "s_measured_m", "v_measured_mps"))
    length = float(max(limits["s_vlim_m"].max(), stops["s_stop_m"].max(), measured["s_measured_m"].max()))
    n = max(int(round(length / step)) + 1, 2)
    s = np.linspace(0.0, length, n)
    s_lim, v_lim = limits["s_vlim_m"].to_numpy(float), limits["v_vlim_mps"].to_numpy(float)
    limit = v_lim[np.clip(np.searchsorted(s_lim, s, side="right") - 1, 0, v_lim.size - 1)]
    for s_c, v_c in corners[["s_corner_m", "v_corner_mps"]].to_numpy(float):
        mask = np.abs(s - s_c) <= corner_half_length
        limit[mask] = np.minimum(limit[mask], v_c)
    stop_s = stops["s_stop_m"].to_numpy(float)
    moving = stop_s > 0
    meta = {"source": f"{_BUS[0]} {route}", "licence": _BUS[1],
            "stop_dwell_s": stops["t_stop_s"].to_numpy(float)[moving].tolist(),
            "traffic_lights": [{"position_m": float(r.s_tl_m), "first_green_s": float(r.t_firstgreen_s),
                                "green_s": float(r.t_green_s), "red_s": float(r.t_red_s)}
                               for r in lights.itertuples()],
            "corners": [{"position_m": float(a), "max_speed_mps": float(b)}
                        for a, b in corners[["s_corner_m", "v_corner_mps"]].to_numpy(float)],
            "measured_trip_duration_s": float(measured["t_measured_s"].max()),
            "grade_meaning": "no elevation or geometry in the data: grade, curvature, bank set to 0"}
    zeros = np.zeros(n)
    return RoadProfile(name=name, distance=s, grade=zeros, curvature=zeros.copy(), bank=zeros.copy(),
                       speed_limit=limit, stops=stop_s[moving], meta=meta)


def bus_route_measured(name: str) -> DriveCycle:
    """The measured bus trip on route ``name`` (a key of BUS_ROUTES) as a speed-vs-time DriveCycle."""
    if name not in BUS_ROUTES:
        raise RoadProfileError(f"unknown bus route {name!r}; known: {sorted(BUS_ROUTES)}")
    route = BUS_ROUTES[name]
    frame = _bus_csv(route, "measured_profile", ("t_measured_s", "s_measured_m", "v_measured_mps"))
    t = frame["t_measured_s"].to_numpy(float)
    return DriveCycle(name=f"{name}_measured", time=t - t[0], speed=frame["v_measured_mps"].to_numpy(float),
                      meta={"source": f"{_BUS[0]} {route}", "licence": _BUS[1],
                            "description": "measured bus trip (1 Hz speed) on the route",
                            "measured_distance_m": float(frame["s_measured_m"].max())})
