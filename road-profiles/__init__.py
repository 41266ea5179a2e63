"""Road profiles (grade, curvature, bank, speed limit over distance) and drive cycles, loadable by name.

``load_profile("hilly", seed=1)`` / ``"motorway"`` / ``"city"`` (seeded generators), ``load_profile("wltc3")``
(drive cycles -> DriveCycle), ``load_profile("route.gpx")`` (files), ``register_profile`` for more names.
"""

from .cycles import (cycle_position, cycle_stops, cycle_to_profile, ftp75, load_cycle, long_haul_truck,
                     speed_at_position, tsdc_trip)
from .files import ProfileFileError, load_gpx, load_profile_file, load_track_csv, save_profile
from .generate import city, hilly, long_grades, motorway
from .profile import DriveCycle, RoadProfile, RoadProfileError
from .real_routes import bus_route, bus_route_measured, gradeit_route, racetrack
from .registry import (UnknownProfileError, known_profiles, load_profile, load_profile_start, register_profile,
                       register_profile_file, register_profile_folder)
from .tracks import (curvature_from_heading, curvature_from_xy, curve_speed_limit, grade_from_elevation,
                     haversine_distance, heading_from_xy, latlon_to_xy, path_length, profile_from_track,
                     remove_spikes, smooth_over_distance)

__all__ = [
    "DriveCycle", "RoadProfile", "RoadProfileError", "ProfileFileError", "UnknownProfileError",
    "load_profile", "load_profile_start", "save_profile", "load_profile_file", "register_profile",
    "register_profile_file",
    "register_profile_folder", "known_profiles",
    "hilly", "motorway", "city", "long_grades",
    "load_cycle", "ftp75", "tsdc_trip", "long_haul_truck", "cycle_position", "speed_at_position", "cycle_stops",
    "cycle_to_profile",
    "load_gpx", "load_track_csv", "gradeit_route", "racetrack", "bus_route", "bus_route_measured",
    "profile_from_track", "smooth_over_distance", "remove_spikes", "grade_from_elevation",
    "curvature_from_heading", "curvature_from_xy", "heading_from_xy", "curve_speed_limit", "haversine_distance",
    "latlon_to_xy", "path_length",
]
