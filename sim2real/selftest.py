"""Scoring helpers of the sim-to-real selftests (the harnesses live in :mod:`roadload.experiments`): what a
diagnosis named first, and whether an effect outside the catalog stayed unexplained and was localised."""

from __future__ import annotations

from .diagnose import Diagnosis

UNEXPLAINED = "unexplained"


def identified_effect(diag: Diagnosis) -> str:
    """The first accepted effect, or 'unexplained'."""
    return diag.identified[0] if diag.identified else UNEXPLAINED


def outside_localised(diag: Diagnosis, low: float = 50.0, high: float = 70.0) -> tuple[bool, str]:
    """(nothing accepted, the residual left unexplained and localised to the speed band [low, high) km/h, where the
    diagnosis put it)."""
    un = diag.unexplained
    where = ""
    bins = un.get("departing_bins") or []
    if bins:
        where = f"{bins[0]['regime']}: {bins[0]['bin']}"
    imp = un.get("reference_importance") or []
    band = f"{low:g}-{high:g} km/h"
    ok_bin = bool(bins) and bins[0]["regime"] == "speed" and bins[0]["bin"] == band
    ok_ref = bool(imp) and imp[0]["column"] == "speed"
    return (not diag.identified) and un.get("present", False) and (ok_bin or ok_ref), where
