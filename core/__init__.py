"""roadload: an open testbed for vehicle tractive-force estimation and eco-driving control."""

from .trip import Trip, TripError

__version__ = "0.1.0"
__all__ = ["Trip", "TripError", "__version__"]
