"""Road profiles (grade, curvature, bank, speed limit over distance) and drive cycles, loadable by name."""

from .profile import DriveCycle, RoadProfile, RoadProfileError

__all__ = ["DriveCycle", "RoadProfile", "RoadProfileError"]
