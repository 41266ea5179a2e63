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
from typing import Any, Iterator, Literal

import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq

from .channels import unit_of
from .fileio import atomic_path
from .trip_schema import TripMetadataError, parse_trip_payload

TRUTH_PREFIX = "truth/"
_META_KEY = b"roadload"
FORMAT_VERSION = 3  # 3: integer-coded columns may be stored as first differences ('delta')


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
    def save(self, path: str | os.PathLike, precision: str = "exact") -> Path:
        """Write the trip as Parquet atomically; returns the path. ``precision``: 'exact' (every value bit for bit)
        or 'compact' (quantised measured channels as scaled integers -- lossless --, other measured channels and
        the truth as float32, position / source energy as fixed-step integers; see :class:`TripWriter`)."""
        with TripWriter(path, self.units, self.truth_units if self.truth is not None else None, precision,
                        resolutions_from_meta(self.meta)) as writer:
            writer.write(self.measured, self.truth)
            writer.close(self.meta)
        return Path(path)

    @staticmethod
    def read_info(path: str | os.PathLike) -> dict[str, Any]:
        """The file's bookkeeping without reading any data: meta, units, truth_units, n_measured, n_truth,
        channels, truth_channels, precision."""
        pf, payload = _open(Path(path))
        names = pf.schema_arrow.names
        return {**{k: payload[k] for k in ("meta", "units", "truth_units", "n_measured", "n_truth")},
                "channels": [c for c in names if not c.startswith(TRUTH_PREFIX) and c not in ("t", _ROWS)],
                "truth_channels": [c[len(TRUTH_PREFIX):] for c in names if c.startswith(TRUTH_PREFIX)
                                   and c != TRUTH_PREFIX + "t"],
                "precision": payload.get("precision", "exact")}

    @classmethod
    def load(cls, path: str | os.PathLike, channels: list[str] | None = None,
             truth_channels: list[str] | None = None) -> "Trip":
        """Read a trip; `channels` / `truth_channels` (optional) read only those measured / truth channels (plus
        't'; names the file lacks are ignored) — faster and smaller when a consumer needs a few of many channels.
        Values come back as float64 (or the dtype they were saved with) whatever the storage precision."""
        path = Path(path)
        pf, payload = _open(path)
        columns = _wanted_columns(pf.schema_arrow.names, channels, truth_channels)
        try:
            table = pf.read(columns=columns)
        except Exception as exc:  # pyarrow raises several types for corrupt files
            raise TripError(f"{path}: not a readable Parquet file ({exc})") from None
        return cls._from_table(table, payload, payload["n_measured"], payload["n_truth"])

    @classmethod
    def iter_chunks(cls, path: str | os.PathLike, channels: list[str] | None = None,
                    truth_channels: list[str] | None = None, rows: int = 360_000) -> Iterator["Trip"]:
        """The trip as consecutive sub-trips of about ``rows`` file rows each (1 h at 100 Hz by default), reading
        only the requested channels: memory bounded by one chunk, for consumers that do not need the whole trip
        at once. Files written before format 2 are read whole and sliced."""
        path = Path(path)
        pf, payload = _open(path)
        if payload.get("version", 1) < 2:
            trip = cls.load(path, channels, truth_channels)
            step = max(int(rows), 1)
            for a in range(0, len(trip), step):
                t = trip.measured["t"].to_numpy()
                yield trip.slice(float(t[a]), float(t[min(a + step, len(trip)) - 1]) + 1e-9)
            return
        columns = _wanted_columns(pf.schema_arrow.names, channels, truth_channels)
        carry: dict[str, Any] = {}  # 'delta' columns continue from the previous batch
        for batch in pf.iter_batches(batch_size=max(int(rows), 1), columns=columns):
            yield cls._from_table(pa.Table.from_batches([batch]), payload, None, None, carry)

    @classmethod
    def _from_table(cls, table: pa.Table, payload: dict[str, Any], n_measured: int | None,
                    n_truth: int | None, carry: dict[str, Any] | None = None) -> "Trip":
        enc = payload.get("encoding", {})
        cols: dict[str, np.ndarray] = {name: _decode(table.column(name), enc.get(name), name, carry)
                                       for name in table.column_names}
        flags = cols.pop(_ROWS, None)
        m_rows = t_rows = None
        if flags is not None:
            m_rows, t_rows = (flags.astype(np.uint8) & 1) > 0, (flags.astype(np.uint8) & 2) > 0
        truth_names = [c for c in cols if c.startswith(TRUTH_PREFIX)]
        meas = {c: v for c, v in cols.items() if not c.startswith(TRUTH_PREFIX)}
        if m_rows is not None:
            meas = {c: v[m_rows] for c, v in meas.items()}
        elif n_measured is not None:
            meas = {c: v[:n_measured] for c, v in meas.items()}
        measured = pd.DataFrame(meas, copy=False)
        truth = None
        if truth_names:
            tr = {c[len(TRUTH_PREFIX):]: cols[c] for c in truth_names}
            if t_rows is not None:
                tr = {c: v[t_rows] for c, v in tr.items()}
            elif n_truth is not None:
                tr = {c: v[:n_truth] for c, v in tr.items()}
            if "t" not in tr and payload.get("truth_time") == "measured":
                tr = {"t": measured["t"].to_numpy(), **tr}  # one time base stored once
            truth = pd.DataFrame(tr, copy=False)
        # restore dtypes that NaN padding / storage encoding changed
        measured = measured.astype({c: d for c, d in payload.get("dtypes", {}).items() if c in measured.columns
                                    and str(measured[c].dtype) != d})
        if truth is not None:
            truth = truth.astype({c: d for c, d in payload.get("truth_dtypes", {}).items() if c in truth.columns
                                  and str(truth[c].dtype) != d})
        units = {c: u for c, u in payload["units"].items() if c in measured.columns}
        truth_units = {c: u for c, u in payload["truth_units"].items() if truth is not None and c in truth.columns}
        return cls(measured.reset_index(drop=True), units, payload["meta"],
                   None if truth is None else truth.reset_index(drop=True), truth_units)


# ---------------------------------------------------------------------------------------------- storage
PRECISIONS = ("exact", "compact")
TRUTH_FIXED = {"position": 1e-4, "source_energy": 1e-3}
"""Truth channels that precision 'compact' stores as int64 multiples of a fixed step [SI] (accumulating
quantities whose float32 step would grow with the trip: position to 0.1 mm, source energy to 1 mJ at any length);
every other truth channel but 't' is float32."""
_ROWS = "_rows"  # format 2: uint8 per file row, bit 0 = a measured sample, bit 1 = a truth sample


def resolutions_from_meta(meta: dict[str, Any]) -> dict[str, float]:
    """Quantisation step [SI] of each measured channel from a simulated trip's ``meta['sensors']`` (empty when the
    trip does not declare its sensors)."""
    chans = (meta.get("sensors") or {}).get("channels") if isinstance(meta.get("sensors"), dict) else None
    if not isinstance(chans, dict):
        return {}
    out = {}
    for name, spec in chans.items():
        r = spec.get("resolution") if isinstance(spec, dict) else None
        if isinstance(r, (int, float)) and r > 0:
            out[name] = float(r)
    return out


def _undelta(col: pa.ChunkedArray, key: str, carry: dict[str, Any] | None) -> np.ndarray:
    """The integers of a 'delta' column: running sum of the stored first differences (wrapping, as they were
    formed), continued from ``carry[key]`` (the last value of the previous batch of a chunked read)."""
    d = (col.fill_null(0) if col.null_count else col).to_numpy()
    k = np.cumsum(d, dtype=d.dtype)
    if carry is not None:
        if key in carry:
            k += carry[key]
        if k.size:
            carry[key] = k[-1]
    return k


def _decode(col: pa.ChunkedArray, enc: dict[str, Any] | None, key: str = "",
            carry: dict[str, Any] | None = None) -> np.ndarray:
    if enc is not None and enc.get("delta"):
        k = _undelta(col, key, carry)
        if "float32" in enc:
            return k.view(np.float32).astype(np.float64)
        out = k.astype(np.float64) * enc["scale"]  # the very product the sensor's quantiser formed
        if col.null_count:
            out[col.is_null().to_numpy(zero_copy_only=False)] = np.nan
        return out
    if enc is not None and ("float32" in enc or "float64bits" in enc):
        bits = (col.fill_null(0) if col.null_count else col).to_numpy()  # padding rows: dropped by _rows
        return bits.view(np.float32).astype(np.float64) if "float32" in enc else bits.view(np.float64)
    if enc is not None and "scale" in enc:
        k = col.to_numpy().astype(np.float64) if col.null_count == 0 else \
            col.cast(pa.float64()).to_numpy(zero_copy_only=False)
        return k * enc["scale"]  # the very product the sensor's quantiser formed: bit-identical
    if pa.types.is_floating(col.type):
        return col.to_numpy(zero_copy_only=False).astype(np.float64, copy=False)
    return col.to_numpy(zero_copy_only=False)


def _wanted_columns(names: list[str], channels: list[str] | None, truth_channels: list[str] | None
                    ) -> list[str] | None:
    if channels is None and truth_channels is None:
        return None
    want = ["t", _ROWS] + list(channels if channels is not None else
                               [c for c in names if not c.startswith(TRUTH_PREFIX) and c != "t"])
    if truth_channels is None or len(truth_channels) > 0:  # [] = no truth at all
        want += [TRUTH_PREFIX + c for c in (["t"] + list(truth_channels) if truth_channels is not None
                                            else [c[len(TRUTH_PREFIX):] for c in names
                                                  if c.startswith(TRUTH_PREFIX)])]
    wanted = set(want)
    return [c for c in names if c in wanted]


def _open(path: Path) -> tuple[pq.ParquetFile, dict[str, Any]]:
    if not path.exists():
        raise TripError(f"no trip file at {path}")
    try:
        pf = pq.ParquetFile(path)
    except Exception as exc:  # pyarrow raises several types for corrupt files
        raise TripError(f"{path}: not a readable Parquet file ({exc})") from None
    raw = (pf.metadata.metadata or {}).get(_META_KEY)  # file key-value metadata (format 2 writes it last)
    if raw is None:
        raw = (pf.schema_arrow.metadata or {}).get(_META_KEY)
    if raw is None:
        raise TripError(f"{path}: Parquet file without roadload metadata (not a Trip)")
    try:
        return pf, parse_trip_payload(raw, path, pf.metadata.num_rows)
    except TripMetadataError as exc:
        raise TripError(str(exc)) from None


class TripWriter:
    """Write a Trip chunk by chunk (Parquet row groups as they come) -- a day-long simulation never holds more
    than one chunk. Atomic: the file appears at ``path`` only on :meth:`close`; an exception inside the ``with``
    block (or a writer never closed) leaves nothing behind.

    ``precision='compact'``: measured channels with a quantisation step (``resolutions``) as int32 multiples of it
    (lossless: decoded as k * step, the product the quantiser formed), other measured channels and truth channels
    as float32 except ``TRUTH_FIXED`` (int64 multiples of a fixed step) and 't' (float64); 'exact': float64.
    Compact floats are stored as their bit patterns (int32 / int64) with Parquet's delta encoding + zstd level 15:
    consecutive samples of a smooth 100 Hz signal differ in few low bits (15.7 vs 23.7 MB per simulated hour
    with byte-stream-split floats); 'exact' keeps float64 with byte-stream-split. Dictionaries did not pay."""

    def __init__(self, path: str | os.PathLike, units: dict[str, str], truth_units: dict[str, str] | None,
                 precision: str = "compact", resolutions: dict[str, float] | None = None,
                 shared_time: bool | None = None) -> None:
        """``shared_time``: True if every chunk's truth has the measured time base (then 't' is stored once),
        False if not, None = decide from the first chunk (a later mismatch raises)."""
        self.path = Path(path)
        if self.path.suffix != ".parquet":
            raise TripError(f"trip files end in .parquet, got {self.path.name!r}")
        if precision not in PRECISIONS:
            raise TripError(f"precision: expected one of {PRECISIONS}, got {precision!r}")
        self.units, self.truth_units = dict(units), dict(truth_units or {})
        self.has_truth = truth_units is not None
        self.precision = precision
        self.resolutions = dict(resolutions or {})
        self._writer: pq.ParquetWriter | None = None
        self._schema: pa.Schema | None = None
        self._encoding: dict[str, dict[str, Any]] = {}
        self._carry: dict[str, Any] = {}  # last integer of every 'delta' column (its differences continue)
        self._dtypes: dict[str, str] = {}
        self._truth_dtypes: dict[str, str] = {}
        self._truth_time = "own" if shared_time is False else "measured"
        self._shared_time = shared_time
        self.n_measured = self.n_truth = 0
        self._ctx = atomic_path(self.path)
        self._tmp: Path | None = None
        self._closed = False

    def __enter__(self) -> "TripWriter":
        self._tmp = self._ctx.__enter__()
        return self

    def __exit__(self, exc_type, exc, tb) -> Literal[False]:
        if self._writer is not None and not self._closed:
            try:  # the file is discarded either way; closing after a failed write (a full disk) may fail as well,
                self._writer.close()  # and must not keep the temporary file from being removed
            except Exception:
                pass
        if exc_type is None and not self._closed:
            exc_type, exc = TripError, TripError(f"{self.path}: TripWriter left without close(meta)")
            self._ctx.__exit__(exc_type, exc, None)
            raise exc
        self._ctx.__exit__(exc_type, exc, tb)
        return False

    # -------------------------------------------------------------- encoding
    def _column(self, name: str, values: np.ndarray, truth: bool) -> pa.Array:
        key = (TRUTH_PREFIX + name) if truth else name
        if self._schema is None:  # first chunk: decide the column's storage
            enc = None
            if values.dtype.kind == "f" and self.precision == "compact":
                step = TRUTH_FIXED.get(name) if truth else self.resolutions.get(name)
                if step is not None:
                    enc = {"scale": step, **({"fixed": True} if truth else {})}
                elif name != "t":
                    enc = {"float32": True}
                else:  # lossless: increments of a clock are small in the bit pattern too
                    enc = {"float64bits": True}
            if enc is not None:
                self._encoding[key] = enc
        enc = self._encoding.get(key)
        if enc is None:
            return pa.array(values)
        if "float32" in enc:  # the float32 bit pattern as int32: delta encoding of smooth signals packs it
            return self._integers(key, np.ascontiguousarray(values, dtype=np.float32).view(np.int32), None)
        if "float64bits" in enc:
            return pa.array(np.ascontiguousarray(values, dtype=np.float64).view(np.int64))
        step = enc["scale"]
        k = np.round(values / step)
        nan = np.isnan(values)
        if enc.get("fixed"):  # lossy by design (half a step)
            k[nan] = 0.0
            return self._integers(key, k.astype(np.int64), nan if nan.any() else None)
        ok = ~nan
        if not (np.array_equal(k[ok] * step, values[ok]) and np.all(np.abs(k[ok]) < 2 ** 31)):
            bad = int(np.flatnonzero(ok & ((k * step != values) | (np.abs(k) >= 2 ** 31)))[0])
            raise TripError(f"measured channel {name!r}: value {values[bad]!r} at row {bad} is not a multiple of "
                            f"its resolution {step!r} (write it with precision='exact')")
        k[nan] = 0.0
        return self._integers(key, k.astype(np.int32), nan if nan.any() else None)

    def _integers(self, key: str, k: np.ndarray, mask: np.ndarray | None) -> pa.Array:
        """An integer-coded column as stored: k itself, or (encoding 'delta', chosen on the first chunk where the
        second differences of k take fewer bits than the first) its first differences, continued across chunks
        (wrapping integer arithmetic, undone exactly by :func:`_undelta`); masked rows (NaN) hold the last value."""
        enc = self._encoding[key]
        carry = self._carry.get(key, k.dtype.type(0))
        if mask is not None:  # hold the last valid value under the mask, so the differences skip the gaps
            idx = np.where(mask, -1, np.arange(k.size))
            np.maximum.accumulate(idx, out=idx)
            k = np.where(idx >= 0, k[np.maximum(idx, 0)], carry).astype(k.dtype)
        if self._schema is None and k.size > 2:
            k64 = k.astype(np.int64)
            bits = [np.log2(1.0 + np.abs(np.diff(k64, n))).mean() for n in (1, 2)]  # ~ packed bit widths
            enc["delta"] = bool(bits[1] < bits[0])
        if not enc.get("delta"):
            return pa.array(k, mask=mask)
        d = np.diff(k, prepend=carry)  # wraps in k's dtype, as the decoder's running sum does
        if k.size:
            self._carry[key] = k[-1]
        return pa.array(d, mask=mask)

    def write(self, measured: pd.DataFrame, truth: pd.DataFrame | None = None) -> None:
        """Append one chunk: measured rows (first column 't') and, for simulated trips, truth rows."""
        if self._closed:
            raise TripError(f"{self.path}: write after close")
        if (truth is not None) != self.has_truth:
            raise TripError("truth: give a truth frame with every chunk iff truth_units were given")
        nm, nt = len(measured), 0 if truth is None else len(truth)
        n = max(nm, nt)
        first = self._schema is None
        if first:
            self._dtypes = {c: str(t) for c, t in measured.dtypes.items()}
            if truth is not None:
                self._truth_dtypes = {c: str(t) for c, t in truth.dtypes.items()}
        if truth is not None and self._truth_time == "measured":
            same = nm == nt and np.array_equal(measured["t"].to_numpy(), truth["t"].to_numpy())
            if not same:
                if not first or self._shared_time:
                    raise TripError("truth: its time base differed from the measured one only after the first "
                                    "chunk; give the same time base in every chunk or write one chunk")
                self._truth_time = "own"
        arrays, names = [], []

        def pad(arr: pa.Array, k: int) -> pa.Array:
            return arr if k == n else pa.concat_arrays([arr, pa.nulls(n - k, arr.type)])

        for c in measured.columns:
            arrays.append(pad(self._column(c, measured[c].to_numpy(), False), nm))
            names.append(c)
        if truth is not None:
            for c in truth.columns:
                if c == "t" and self._truth_time == "measured":
                    continue
                arrays.append(pad(self._column(c, truth[c].to_numpy(), True), nt))
                names.append(TRUTH_PREFIX + c)
        flags = np.zeros(n, dtype=np.uint8)
        flags[:nm] |= 1
        flags[:nt] |= 2
        arrays.append(pa.array(flags))
        names.append(_ROWS)
        table = pa.Table.from_arrays(arrays, names=names)
        if first:
            self._schema = table.schema
            encoding = {f.name: "BYTE_STREAM_SPLIT" for f in table.schema if pa.types.is_floating(f.type)}
            encoding.update({f.name: "DELTA_BINARY_PACKED" for f in table.schema if pa.types.is_integer(f.type)})
            # no column statistics: no reader filters on them, and pyarrow's writer keeps every row group's column
            # metadata in memory until close (with statistics: +94 MB for 1440 row groups of 77 columns, measured)
            self._writer = pq.ParquetWriter(self._tmp, table.schema, compression="zstd", compression_level=15,
                                            use_dictionary=False, column_encoding=encoding, write_statistics=False)
        elif table.schema != self._schema:
            expected = [] if self._schema is None else self._schema.names
            raise TripError(f"{self.path}: chunk columns {names} differ from the first chunk's {expected}")
        if self._writer is None:
            raise TripError(f"{self.path}: TripWriter has no open Parquet writer (use it as a context manager)")
        self._writer.write_table(table)
        del table, arrays
        pa.default_memory_pool().release_unused()  # hand the chunk's buffers back: bounded RSS over a day
        self.n_measured += nm
        self.n_truth += nt

    def close(self, meta: dict[str, Any]) -> Path:
        """Finish the file with the trip's metadata (known only at the end of a streamed simulation)."""
        payload = {
            "version": FORMAT_VERSION, "units": self.units, "truth_units": self.truth_units, "meta": meta,
            "n_measured": self.n_measured, "n_truth": self.n_truth, "dtypes": self._dtypes,
            "truth_dtypes": self._truth_dtypes, "precision": self.precision, "encoding": self._encoding,
            "truth_time": self._truth_time if self.has_truth else None,
        }
        text = json.dumps(payload)  # a TypeError here leaves nothing behind
        if self._writer is None:
            raise TripError(f"{self.path}: nothing written (a trip needs at least one chunk)")
        self._writer.add_key_value_metadata({_META_KEY: text.encode()})
        self._writer.close()
        self._closed = True
        return self.path
