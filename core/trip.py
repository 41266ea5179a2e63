"""The Trip: the contract between data sources (simulator, real-log importers) and everything downstream.

A Trip holds
- ``measured``: a DataFrame of measured channels in SI units, first column ``t`` [s] (strictly increasing);
- ``units``: the SI unit of every measured column;
- ``truth``: for simulated trips only, ground-truth channels (own ``t`` column), kept in a separate frame so
  that code reading ``trip.measured`` cannot see them;
- ``meta``: JSON-serialisable metadata (source, vehicle spec, road, seed, enabled effects, repairs, notes).

It is saved as one Parquet file (pyarrow): measured columns as they are, truth columns prefixed ``truth/``,
units and metadata as JSON in the schema metadata. Writing is atomic (temporary file + rename), so a failed
save never leaves a partial file behind.
"""

from __future__ import annotations

import copy
import json
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq

from .channels import unit_of
from .fileio import atomic_path
from .trip_schema import TripMetadataError, parse_trip_payload

TRUTH_PREFIX = "truth/"
_META_KEY = b"roadload"
FORMAT_VERSION = 1


class TripError(ValueError):
    """A Trip (or a file claiming to be one) violates the Trip contract; the message names what."""


def _check_frame(frame: pd.DataFrame, units: dict[str, str], what: str) -> None:
    if not isinstance(frame, pd.DataFrame):
        raise TripError(f"{what}: expected a pandas DataFrame, got {type(frame).__name__}")
    cols = list(frame.columns)
    dupes = sorted({c for c in cols if cols.count(c) > 1})
    if dupes:
        raise TripError(f"{what}: duplicate channel names {dupes}")
    if "t" not in frame.columns:
        raise TripError(f"{what}: missing the time channel 't' [s]")
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
    for c in cols:
        if c.startswith(TRUTH_PREFIX):
            raise TripError(f"{what}: channel name {c!r} may not start with {TRUTH_PREFIX!r}")
        if not pd.api.types.is_numeric_dtype(frame[c]):
            raise TripError(f"{what}: channel {c!r} is not numeric (dtype {frame[c].dtype})")


@dataclass
class Trip:
    """Measured 100 Hz-style channels in SI units, metadata and (simulated trips only) ground truth."""

    measured: pd.DataFrame
    units: dict[str, str]
    meta: dict[str, Any] = field(default_factory=dict)
    truth: pd.DataFrame | None = None
    truth_units: dict[str, str] = field(default_factory=dict)

    def __post_init__(self) -> None:
        self.measured = self.measured.reset_index(drop=True)
        _check_frame(self.measured, self.units, "measured")
        for name, unit in self.units.items():
            expected = unit_of(name)
            if expected is not None and unit != expected:
                raise TripError(f"measured channel {name!r} has unit {unit!r}, the catalogue says {expected!r} "
                                f"(convert to SI before building a Trip)")
        if self.truth is not None:
            self.truth = self.truth.reset_index(drop=True)
            _check_frame(self.truth, self.truth_units, "truth")
        elif self.truth_units:
            raise TripError("truth_units given without a truth frame")
        try:
            json.dumps(self.meta)
        except TypeError as exc:
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
            raise TripError(f"trip {self.meta.get('name', '?')!r} lacks required channels {missing}; "
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
            raise TripError(f"ground truth has no channel {name!r}; it has {list(self.truth.columns)}")
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
    def save(self, path: str | os.PathLike) -> Path:
        """Write the trip as Parquet atomically; returns the path."""
        path = Path(path)
        if path.suffix != ".parquet":
            raise TripError(f"trip files end in .parquet, got {path.name!r}")
        df = self.measured.copy()
        if self.truth is not None:
            tr = self.truth.add_prefix(TRUTH_PREFIX)
            if len(tr) != len(df):
                # different time bases: pad the shorter one with NaN rows; lengths are stored to undo it
                n = max(len(tr), len(df))
                df = df.reindex(range(n))
                tr = tr.reindex(range(n))
            df = pd.concat([df, tr], axis=1)
        payload = {
            "version": FORMAT_VERSION,
            "units": self.units,
            "truth_units": self.truth_units,
            "meta": self.meta,
            "n_measured": len(self.measured),
            "n_truth": 0 if self.truth is None else len(self.truth),
            "dtypes": {c: str(t) for c, t in self.measured.dtypes.items()},
            "truth_dtypes": {} if self.truth is None else {c: str(t) for c, t in self.truth.dtypes.items()},
        }
        table = pa.Table.from_pandas(df, preserve_index=False)
        table = table.replace_schema_metadata({**(table.schema.metadata or {}), _META_KEY: json.dumps(payload).encode()})
        with atomic_path(path) as tmp:
            pq.write_table(table, tmp, compression="zstd")
        return path

    @classmethod
    def load(cls, path: str | os.PathLike, channels: list[str] | None = None,
             truth_channels: list[str] | None = None) -> "Trip":
        """Read a trip; `channels` / `truth_channels` (optional) read only those measured / truth channels (plus
        't'; names the file lacks are ignored) — faster when a consumer needs a few of many channels."""
        path = Path(path)
        if not path.exists():
            raise TripError(f"no trip file at {path}")
        try:
            columns = None
            if channels is not None or truth_channels is not None:
                names = list(pq.read_schema(path).names)   # file order
                want = ["t"] + list(channels if channels is not None else
                                    [c for c in names if not c.startswith(TRUTH_PREFIX) and c != "t"])
                want += [TRUTH_PREFIX + c for c in (["t"] + list(truth_channels) if truth_channels is not None
                                                    else [c[len(TRUTH_PREFIX):] for c in names
                                                          if c.startswith(TRUTH_PREFIX)])]
                wanted = set(want)
                columns = [c for c in names if c in wanted]
            table = pq.read_table(path, columns=columns)
        except Exception as exc:  # pyarrow raises several types for corrupt files
            raise TripError(f"{path}: not a readable Parquet file ({exc})") from None
        raw = (table.schema.metadata or {}).get(_META_KEY)
        if raw is None:
            raise TripError(f"{path}: Parquet file without roadload metadata (not a Trip)")
        try:
            payload = parse_trip_payload(raw, path, table.num_rows)
        except TripMetadataError as exc:
            raise TripError(str(exc)) from None
        df = table.to_pandas()
        truth_cols = [c for c in df.columns if c.startswith(TRUTH_PREFIX)]
        measured = df.drop(columns=truth_cols).iloc[: payload["n_measured"]]
        truth = None
        if truth_cols:
            truth = df[truth_cols].iloc[: payload["n_truth"]]
            truth.columns = [c[len(TRUTH_PREFIX):] for c in truth_cols]
        # restore dtypes that NaN padding of unequal time bases may have widened
        measured = measured.astype({c: d for c, d in payload.get("dtypes", {}).items() if c in measured.columns})
        if truth is not None:
            truth = truth.astype({c: d for c, d in payload.get("truth_dtypes", {}).items() if c in truth.columns})
        units = {c: u for c, u in payload["units"].items() if c in measured.columns}
        truth_units = {c: u for c, u in payload["truth_units"].items() if truth is not None and c in truth.columns}
        return cls(measured.reset_index(drop=True), units, payload["meta"],
                   None if truth is None else truth.reset_index(drop=True), truth_units)
