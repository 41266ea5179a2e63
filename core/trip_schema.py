"""Schema of the metadata a Trip Parquet file carries (the ``roadload`` key-value entry of the Parquet file), and
the error types of the Trip contract.

:func:`parse_trip_payload` checks it before ``Trip.load`` uses it: valid JSON, a known format version, units as
``{channel: unit}`` (formats 1-3; format 4 keeps each unit in its column's Arrow field metadata), row counts that
fit the file, JSON-object metadata. Errors are :class:`TripMetadataError` naming the file and the field
(``Trip.load`` re-raises them as ``TripError``), e.g. ``trip.parquet: metadata.n_measured: missing required field``.
"""

from __future__ import annotations

import json
import os
from typing import Any

from pydantic import Field, ValidationError, model_validator

from .schema import StrictModel, format_errors

__all__ = ["TripPayload", "TripError", "TripMetadataError", "parse_trip_payload", "SUPPORTED_VERSIONS"]


class TripError(ValueError):
    """A Trip (or a file claiming to be one) violates the Trip contract; the message names what."""


class TripMetadataError(ValueError):
    """The metadata of a trip file is missing, not JSON or violates the schema; the message names file and field."""

#: 2: streamed row groups, compact encodings; 3: + differenced integer columns; 4: open layout (plain SI floats,
#: Parquet's own encodings, units as Arrow field metadata)
SUPPORTED_VERSIONS = (1, 2, 3, 4)


class TripPayload(StrictModel):
    """The stored payload: format version, units, metadata and the row counts of the measured/truth frames."""

    model_config = StrictModel.model_config | {"extra": "allow"}  # newer writers may add keys

    version: int = Field(ge=1, description="Trip file format version")
    units: dict[str, str] = Field(default_factory=dict, description="unit of every measured channel (formats 1-3)")
    truth_units: dict[str, str] = Field(default_factory=dict, description="unit of every truth channel")
    meta: dict[str, Any] = Field(default_factory=dict, description="JSON metadata of the trip")
    n_measured: int = Field(ge=0, description="rows of the measured frame")
    n_truth: int = Field(0, ge=0, description="rows of the truth frame")
    dtypes: dict[str, str] = Field(default_factory=dict)
    truth_dtypes: dict[str, str] = Field(default_factory=dict)

    @model_validator(mode="after")
    def _known_version(self) -> "TripPayload":
        if self.version not in SUPPORTED_VERSIONS:
            raise ValueError(f"version {self.version} is not supported (this roadload reads {SUPPORTED_VERSIONS}); "
                             f"upgrade roadload")
        if self.version < 4 and "units" not in self.model_fields_set:
            raise ValueError(f"units: missing required field (format {self.version} keeps the units here)")
        return self


def parse_trip_payload(raw: bytes | str, path: str | os.PathLike, n_rows: int | None = None) -> dict[str, Any]:
    """The validated payload as a dict; `n_rows` (rows in the file) bounds n_measured / n_truth."""
    try:
        data = json.loads(raw)
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise TripMetadataError(f"{path}: trip metadata is not valid JSON ({exc}); the file was not written by "
                                f"roadload or is corrupt") from None
    if not isinstance(data, dict):
        raise TripMetadataError(f"{path}: trip metadata must be a JSON object, got {type(data).__name__}")
    try:
        payload = TripPayload.model_validate(data)
    except ValidationError as exc:
        raise TripMetadataError(f"{path}: {format_errors(exc, TripPayload, root='metadata')}") from None
    if n_rows is not None:
        for name in ("n_measured", "n_truth"):
            if getattr(payload, name) > n_rows:
                raise TripMetadataError(f"{path}: metadata.{name}: {getattr(payload, name)} rows declared but the file "
                                f"holds {n_rows}")
    return payload.model_dump()
