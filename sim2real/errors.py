"""The error type of the sim-to-real diagnosis."""

from __future__ import annotations


class DiagnosisError(ValueError):
    """Bad diagnosis input (missing channels, mismatched vehicle, unknown candidate or regime); the message
    names what is wrong or missing."""
