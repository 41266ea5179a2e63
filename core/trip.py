"""The Trip: the contract between data sources (simulator, real-log importers) and everything downstream.

A Trip holds
- ``measured``: a DataFrame of measured channels in SI units, first column ``t`` [s] (strictly increasing);
- ``units``: the SI unit of every measured column;
- ``truth``: for simulated trips only, ground-truth channels (own ``t`` column), kept in a separate frame so
  that code reading ``trip.measured`` cannot see them;
- ``meta``: JSON-serialisable metadata (source, vehicle spec, road, seed, enabled effects, repairs, notes).

The constructor checks the contract and names what is wrong (:class:`TripError`): frames or mappings of equal-length
1-D numeric channels, channel names that are strings without surrounding whitespace and not equal up to case or
whitespace, a string unit for every channel -- the catalogue's unit for a catalogued channel (roadload.channels),
an SI unit expression for any other (``km/h`` is refused with the conversion to ``m/s``).

It is saved as one open Parquet file (:mod:`roadload.trip_storage`: plain SI floats, truth columns prefixed
``truth/``, units as Arrow field metadata, the metadata as one JSON key-value entry) that pandas, polars and DuckDB
read without roadload. Writing is atomic (temporary file + rename), so a failed save never leaves a partial file.
"""

from __future__ import annotations

import copy
import json
import os
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Iterator

import numpy as np
import pandas as pd

from .channels import unit_of
from .registry import did_you_mean
from .trip_schema import TripError
from .trip_storage import (FORMAT_VERSION, PRECISIONS, RESERVED_COLUMNS, TRUTH_PREFIX, TripParts, TripWriter,
                           iter_trip_chunks, open_trip_file, read_trip_file, resolutions_from_meta,
                           storage_precision, trip_file_info)
from .units import si_unit_problem

__all__ = ["Trip", "TripError", "TripWriter", "TRUTH_PREFIX", "FORMAT_VERSION", "PRECISIONS",
           "resolutions_from_meta", "convert_trip_file"]


def _as_frame(data: Any, what: str) -> pd.DataFrame:
    """A DataFrame of the channels: a DataFrame as it is, or a mapping of channel name -> 1-D array of one length."""
    if isinstance(data, pd.DataFrame):
        return data.reset_index(drop=True)
    if isinstance(data, Mapping):
        lengths: dict[Any, int] = {}
        columns = {}
        for name, values in data.items():
            arr = np.asarray(values)
            if arr.ndim != 1:
                raise TripError(f"{what}: channel {name!r} must be a 1-D array, got shape {arr.shape}")
            lengths[name], columns[name] = arr.size, arr
        if len(set(lengths.values())) > 1:
            ref = "t" if "t" in lengths else next(iter(lengths))
            bad = {k: n for k, n in lengths.items() if n != lengths[ref]}
            raise TripError(f"{what}: channels of unequal length: {ref!r} has {lengths[ref]} samples, "
                            + ", ".join(f"{k!r} has {n}" for k, n in bad.items())
                            + " (every channel needs one value per sample of 't'; NaN marks a missing value)")
        return pd.DataFrame(columns)
    raise TripError(f"{what}: expected a pandas DataFrame or a mapping of channel name to 1-D array, got "
                    f"{type(data).__name__}")


def _check_units_type(units: Any, what: str) -> None:
    if not isinstance(units, Mapping):
        raise TripError(f"{what}: expected a dict {{channel: SI unit string}}, e.g. {{'t': 's', 'vehicle_speed': "
                        f"'m/s'}}, got {type(units).__name__}")
    for name, unit in units.items():
        if not isinstance(unit, str):
            raise TripError(f"{what}[{name!r}]: the unit must be a string such as 'm/s', got "
                            f"{type(unit).__name__} {unit!r}")


def _check_names(names: list[Any], what: str) -> None:
    """Channel-name hygiene: strings, no surrounding whitespace or control characters, no reserved names, no two
    names equal up to case and whitespace."""
    for c in names:
        if not isinstance(c, str):
            raise TripError(f"{what}: channel names must be strings, got {c!r} ({type(c).__name__})")
        if not c or c != c.strip() or any(ord(ch) < 32 for ch in c):
            raise TripError(f"{what}: channel name {c!r} is empty or has surrounding whitespace or control "
                            f"characters")
        if c.startswith(TRUTH_PREFIX) or c in RESERVED_COLUMNS:
            raise TripError(f"{what}: channel name {c!r} is reserved by the trip file layout (no {TRUTH_PREFIX!r} "
                            f"prefix, not {sorted(RESERVED_COLUMNS)})")
    seen: dict[str, str] = {}
    for c in names:
        key = "".join(c.split()).casefold()
        if key in seen:
            if seen[key] == c:
                raise TripError(f"{what}: duplicate channel names [{c!r}]")
            raise TripError(f"{what}: channel names {seen[key]!r} and {c!r} differ only in case or whitespace; "
                            f"rename one")
        seen[key] = c


def _check_frame(frame: pd.DataFrame, units: dict[str, str], what: str, truth: bool) -> None:
    cols = list(frame.columns)
    _check_names(cols, what)
    if "t" not in frame.columns:
        raise TripError(f"{what}: missing the time channel 't' [s]")
    for c in cols:
        if not pd.api.types.is_numeric_dtype(frame[c]):
            raise TripError(f"{what}: channel {c!r} is not numeric (dtype {frame[c].dtype})")
    t = frame["t"].to_numpy(dtype=float)
    if not np.all(np.isfinite(t)):
        raise TripError(f"{what}: time channel 't' contains NaN/inf at index {int(np.flatnonzero(~np.isfinite(t))[0])}")
    if t.size > 1 and not np.all(np.diff(t) > 0):
        bad = int(np.flatnonzero(np.diff(t) <= 0)[0])
        raise TripError(f"{what}: time channel 't' is not strictly increasing at index {bad + 1} "
                        f"(t={t[bad]:.6g} then {t[bad + 1]:.6g})")
    missing = [c for c in cols if c not in units]
    if missing:
        raise TripError(f"{what}: no unit given for channels {missing}")
    extra = [c for c in units if c not in frame.columns]
    if extra:
        raise TripError(f"{what}: units given for channels that do not exist: {extra}")
    for name, unit in units.items():
        expected = unit_of(name, truth)
        if expected is not None:
            if unit != expected:
                raise TripError(f"{what} channel {name!r} has unit {unit!r}, the catalogue says {expected!r} "
                                f"(convert to SI before building a Trip)")
            continue
        problem = si_unit_problem(unit)
        if problem is not None:
            raise TripError(f"{what} channel {name!r}: unit {problem}")


@dataclass
class Trip:
    """Measured 100 Hz-style channels in SI units, metadata and (simulated trips only) ground truth."""

    measured: pd.DataFrame
    units: dict[str, str]
    meta: dict[str, Any] = field(default_factory=dict)
    truth: pd.DataFrame | None = None
    truth_units: dict[str, str] = field(default_factory=dict)  # None is read as {}

    def __post_init__(self) -> None:
        self.measured = _as_frame(self.measured, "measured")
        _check_units_type(self.units, "units")
        self.units = dict(self.units)
        _check_frame(self.measured, self.units, "measured", truth=False)
        if self.truth_units is None:  # "no truth units" as None, as for ``truth``
            self.truth_units = {}
        _check_units_type(self.truth_units, "truth_units")
        self.truth_units = dict(self.truth_units)
        if self.truth is not None:
            self.truth = _as_frame(self.truth, "truth")
            _check_frame(self.truth, self.truth_units, "truth", truth=True)
        elif self.truth_units:
            raise TripError("truth_units given without a truth frame")
        if not isinstance(self.meta, Mapping):
            raise TripError(f"meta: expected a dict of JSON-serialisable metadata, got {type(self.meta).__name__}")
        try:
            json.dumps(self.meta)
        except (TypeError, ValueError) as exc:
            raise TripError(f"meta must be JSON-serialisable: {exc}") from None

    # ------------------------------------------------------------------ access
    @property
    def t(self) -> np.ndarray:
        return self.measured["t"].to_numpy(dtype=float)

    @property
    def duration(self) -> float:
        t = self.t
        return float(t[-1] - t[0]) if t.size else 0.0

    @property
    def sample_rate(self) -> float:
        """Median sample rate [Hz] of the measured channels."""
        t = self.t
        return float(1.0 / np.median(np.diff(t))) if t.size > 1 else float("nan")

    @property
    def channels(self) -> list[str]:
        return [c for c in self.measured.columns if c != "t"]

    @property
    def is_simulated(self) -> bool:
        return self.truth is not None

    def __len__(self) -> int:
        return len(self.measured)

    def has(self, *names: str) -> bool:
        return all(n in self.measured.columns for n in names)

    def require(self, *names: str) -> None:
        """Raise TripError naming every required measured channel this trip lacks."""
        missing = [n for n in names if n not in self.measured.columns]
        if missing:
            hints = "".join(did_you_mean(n, self.channels) for n in missing)
            raise TripError(f"trip {self.meta.get('name', '?')!r} lacks required channels {missing}{hints}; "
                            f"it has {self.channels}")

    def channel(self, name: str) -> np.ndarray:
        """A measured channel as float array (SI)."""
        self.require(name)
        return self.measured[name].to_numpy(dtype=float)

    def true(self, name: str) -> np.ndarray:
        """A ground-truth channel (simulated trips only)."""
        if self.truth is None:
            raise TripError(f"trip {self.meta.get('name', '?')!r} has no ground truth (not simulated)")
        if name not in self.truth.columns:
            raise TripError(f"ground truth has no channel {name!r}{did_you_mean(name, self.truth.columns)}; it has "
                            f"{list(self.truth.columns)}")
        return self.truth[name].to_numpy(dtype=float)

    def to_pandas(self, include_truth: bool = False) -> pd.DataFrame:
        """Measured channels as a DataFrame (copy); truth columns appended with the 'truth/' prefix on request."""
        df = self.measured.copy()
        if include_truth and self.truth is not None:
            tr = self.truth.drop(columns="t").add_prefix(TRUTH_PREFIX)
            if len(tr) != len(df):
                raise TripError("truth and measured frames differ in length; cannot join them row by row")
            df = pd.concat([df, tr], axis=1)
        return df

    def slice(self, t_start: float, t_end: float) -> "Trip":
        """Sub-trip with t_start <= t < t_end (truth sliced on its own time base)."""
        m = self.measured[(self.measured["t"] >= t_start) & (self.measured["t"] < t_end)]
        tr = None
        if self.truth is not None:
            tr = self.truth[(self.truth["t"] >= t_start) & (self.truth["t"] < t_end)]
        return Trip(m.copy(), dict(self.units), copy.deepcopy(self.meta), tr.copy() if tr is not None else None,
                    dict(self.truth_units))

    def copy(self) -> "Trip":
        return Trip(self.measured.copy(), dict(self.units), copy.deepcopy(self.meta),
                    None if self.truth is None else self.truth.copy(), dict(self.truth_units))

    def equals(self, other: "Trip") -> bool:
        """Exact equality of channels, units, metadata and truth."""
        if not isinstance(other, Trip):
            return False
        if self.units != other.units or self.meta != other.meta or self.truth_units != other.truth_units:
            return False
        if not self.measured.equals(other.measured):
            return False
        if (self.truth is None) != (other.truth is None):
            return False
        return self.truth is None or self.truth.equals(other.truth)

    # ------------------------------------------------------------------ I/O
    def save(self, path: str | os.PathLike, precision: str = "exact") -> Path:
        """Write the trip as an open Parquet file atomically; returns the path. ``precision`` (see
        :mod:`roadload.trip_storage`): 'exact' (every value bit for bit), 'compact' (float32 SI values rounded to
        the sensor resolution, truth to 15 significant bits; ~5x smaller) or 'packed' (roadload's private integer
        codec, readable only by roadload)."""
        return _write_whole(self, path, precision, resolutions_from_meta(self.meta))

    @staticmethod
    def read_info(path: str | os.PathLike) -> dict[str, Any]:
        """The file's bookkeeping without reading any data: meta, units, truth_units, n_measured, n_truth,
        channels, truth_channels, precision, version."""
        return trip_file_info(path)

    @classmethod
    def load(cls, path: str | os.PathLike, channels: list[str] | None = None,
             truth_channels: list[str] | None = None) -> "Trip":
        """Read a trip; `channels` / `truth_channels` (optional) read only those measured / truth channels (plus
        't'; names the file lacks are ignored) -- faster and smaller when a consumer needs a few of many channels.
        Float channels come back as float64 whatever the storage precision (quantised channels on their grid)."""
        return cls._from_parts(read_trip_file(path, channels, truth_channels))

    @classmethod
    def iter_chunks(cls, path: str | os.PathLike, channels: list[str] | None = None,
                    truth_channels: list[str] | None = None, rows: int = 360_000) -> Iterator["Trip"]:
        """The trip as consecutive sub-trips of about ``rows`` file rows each (1 h at 100 Hz by default), reading
        only the requested channels: memory bounded by one chunk, for consumers that do not need the whole trip
        at once."""
        for parts in iter_trip_chunks(path, channels, truth_channels, rows):
            yield cls._from_parts(parts)

    @classmethod
    def _from_parts(cls, parts: TripParts) -> "Trip":
        return cls(parts.measured.reset_index(drop=True), parts.units, parts.meta,
                   None if parts.truth is None else parts.truth.reset_index(drop=True), parts.truth_units)


def _write_whole(trip: Trip, path: str | os.PathLike, precision: str, resolutions: dict[str, float]) -> Path:
    """Write a whole trip in one chunk with the given quantisation steps [SI] of its measured channels."""
    with TripWriter(path, trip.units, trip.truth_units if trip.truth is not None else None, precision,
                    resolutions) as writer:
        writer.write(trip.measured, trip.truth)
        writer.close(trip.meta)
    return Path(path)


def convert_trip_file(source: str | os.PathLike, out: str | os.PathLike, precision: str | None = None) -> Path:
    """Rewrite a trip file of any readable format as the current open format (``precision`` default: 'compact'
    for files written 'compact' or 'packed', else 'exact'). Streams chunk by chunk when measured and truth share
    a time base (bounded memory for day-long trips); otherwise reads the trip whole."""
    source, out = Path(source), Path(out)
    _, payload = open_trip_file(source)
    old = storage_precision(payload)
    precision = precision or ("exact" if old == "exact" else "compact")
    if precision not in PRECISIONS:
        raise TripError(f"precision: expected one of {PRECISIONS}, got {precision!r}")
    if source.resolve() == out.resolve():
        raise TripError(f"{out}: convert writes a new file; give an output path other than the source")
    res = resolutions_from_meta(payload["meta"])
    res.update({c: float(e["scale"]) for c, e in payload.get("encoding", {}).items()
                if "scale" in e and not c.startswith(TRUTH_PREFIX)})
    res.update(payload.get("resolutions", {}))
    truth_units = payload["truth_units"] if (payload.get("has_truth") or payload["n_truth"] > 0) else None
    shared = payload["version"] >= 2 and (payload["version"] >= 4 and payload.get("time_base") == "shared"
                                          or payload.get("truth_time") == "measured" or truth_units is None)
    if not shared:  # read whole, written with the file's resolutions (its metadata may not declare them)
        return _write_whole(Trip.load(source), out, precision, res)
    with TripWriter(out, payload["units"], truth_units, precision, res, shared_time=True) as writer:
        for parts in iter_trip_chunks(source, rows=360_000):
            writer.write(parts.measured, parts.truth)
        writer.close(payload["meta"])
    return out
