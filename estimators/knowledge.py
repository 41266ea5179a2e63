"""Estimating-side knowledge of a vehicle: what the chapter-5 pipeline and the force models may know of it.

A simulated trip's vehicle is a preset; the estimating side knows its nominal spec and an M0 coast-down from a
simulated coast-down of the nominal vehicle (:func:`~roadload.estimators.models.coast_down_coefficients`). A real
log names a preset too, but its M0 coefficients come from the spec sheet alone
(:func:`~roadload.estimators.models.published_coast_down`), as for a car whose coast-down was never measured.
"""

from __future__ import annotations

import functools

from roadload.presets import get_preset
from roadload.trip import Trip

from .models import coast_down_coefficients, published_coast_down
from .pipeline import PipelineError, VehicleKnowledge, knowledge_from_spec

__all__ = ["knowledge_for_preset", "knowledge_for_trip", "trip_vehicle"]


@functools.lru_cache(maxsize=None)
def knowledge_for_preset(name: str) -> VehicleKnowledge:
    """Estimating-side knowledge of a simulator preset, with M0's coast-down from the nominal vehicle (cached per name:
    the simulated coast-down costs ~0.1 s)."""
    spec = get_preset(name)
    return knowledge_from_spec(spec, coast_down=coast_down_coefficients(spec))


def knowledge_for_trip(trip: Trip, preset: str | None = None) -> VehicleKnowledge:
    """Knowledge for a trip: simulated -> its preset with a simulated coast-down; real log -> the preset named by
    the log's metadata (or `preset`) with M0's coefficients from the spec sheet (:func:`published_coast_down`)."""
    name = preset or trip_vehicle(trip)
    if trip.is_simulated:
        return knowledge_for_preset(name)
    spec = get_preset(name)
    return knowledge_from_spec(spec, coast_down=published_coast_down(spec))


def trip_vehicle(trip: Trip) -> str:
    """The preset name a simulated trip was made with (from its metadata)."""
    fleet = trip.meta.get("fleet") or {}
    v = fleet.get("vehicle") or trip.meta.get("vehicle")
    if isinstance(v, dict):
        v = v.get("name")
    if not isinstance(v, str):
        raise PipelineError(f"trip {trip.meta.get('name', '?')!r}: metadata names no vehicle preset")
    return v
