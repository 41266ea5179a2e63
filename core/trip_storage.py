"""Trip files: one Parquet file per trip that pandas, polars, DuckDB, Arrow and MATLAB read without roadload.

Layout (format 4)
-----------------
- ``t`` [s], float64: the time of the row.
- one column per measured channel, named as the channel (``vehicle_speed``, ``accel_x``, ...);
- one column ``truth/<name>`` per ground-truth channel (simulated trips only). :class:`roadload.Trip` keeps these
  in ``trip.truth``, apart from ``trip.measured``, so an estimator handed the measured frame cannot read them; a
  pandas user finds them by the prefix (``df.filter(like="truth/")``).
- measured and truth share one row per time instant. When their time bases differ (sensor decimation, samples
  removed by dropouts), the rows are the union of both, a measured channel is null on a truth-only row and vice
  versa, and two bool columns say which rows belong to which: ``measured_row`` and ``truth_row``. When the time
  bases are equal (the usual simulated trip) neither column exists.
- every column carries Arrow field metadata: ``unit`` (SI, from :mod:`roadload.channels`) and, where known,
  ``resolution`` (the sensor's quantisation step in that unit).
- the trip metadata is one JSON key-value entry of the file, ``roadload``: ``{"version": 4, "meta": {...},
  "precision": ..., "n_measured": ..., "n_truth": ..., "has_truth": ..., "time_base": "shared" | "union"}``.

Storage precision
-----------------
- ``compact`` (streamed simulations): plain SI floats -- float64 for ``t`` and positions (:data:`FLOAT64_CHANNELS`),
  float32 elsewhere. Measured channels are rounded to their sensor resolution (``Trip.load`` restores the exact grid
  value k x step); truth channels are rounded to :data:`TRUTH_SIGNIFICANT_BITS` significant bits (relative step
  2^-15 ~ 3e-5; float64 ones to 32 bits), which zeroes the low mantissa bits so that the file compresses. Parquet's
  own encodings do the rest: dictionary for enums and constants (gear, clutch, the mass), PLAIN for quantised
  channels (zstd finds their repeated 4-byte patterns), BYTE_STREAM_SPLIT for the rest, ZSTD on top. About 13 MB
  per simulated hour at 100 Hz (scripts/bench_trip_storage.py).
- ``exact``: every column in its own dtype, floats unrounded (bit for bit); ~5x larger.
- ``packed`` (explicit opt-in): format 3, roadload's private integer codec. Its columns are integer codes and first
  differences that only roadload decodes -- pandas, polars, DuckDB and MATLAB read meaningless integers -- for
  about 2 % less space than ``compact``. ``roadload convert`` rewrites such files (and formats 1-3) as format 4.

Writing is atomic (temporary file + rename) and streams: :class:`TripWriter` appends one row group per chunk, so a
day-long simulation holds one chunk in memory; :func:`iter_trip_chunks` reads in bounded memory.
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass
from pathlib import Path
from collections.abc import Mapping
from typing import TYPE_CHECKING, Any, Iterator, Literal, NamedTuple, TypeAlias

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from .fileio import atomic_path
from .trip_schema import TripError, TripMetadataError, parse_trip_payload

if TYPE_CHECKING:  # pandas loads where a frame is built (reading); writing a streamed trip needs none of it
    import pandas as pd

    Frame: TypeAlias = pd.DataFrame | Mapping[str, np.ndarray]  # a chunk: a frame or its columns by name

TRUTH_PREFIX = "truth/"
META_KEY = b"roadload"
FORMAT_VERSION = 4
MEASURED_ROW, TRUTH_ROW = "measured_row", "truth_row"
RESERVED_COLUMNS = frozenset({MEASURED_ROW, TRUTH_ROW})
PRECISIONS = ("compact", "exact", "packed")
#: channels kept in float64 by precision 'compact': time and positions, whose float32 step would grow with the trip
FLOAT64_CHANNELS = frozenset({"t", "position", "source_energy", "distance", "latitude", "longitude"})
#: significant bits kept of a float32 truth value by precision 'compact' (of 24); float64 truth values keep 32 (of 53)
TRUTH_SIGNIFICANT_BITS = 15
TRUTH_SIGNIFICANT_BITS_64 = 33
#: a float32 column holds grid values k x step exactly recoverable while |k| < 2^22
_F32_GRID_LIMIT = 2.0 ** 22
#: columns with at most this many distinct values in the first chunk (enums such as gear and clutch, constants) are
#: dictionary-encoded; for more, a dictionary saved no space and cost 4 MB of writer memory (1 h streamed, measured)
_DICTIONARY_MAX = 16
_ZSTD_LEVEL = 15


class TripParts(NamedTuple):
    """What a file holds, before it becomes a :class:`roadload.Trip`."""

    measured: pd.DataFrame
    units: dict[str, str]
    meta: dict[str, Any]
    truth: pd.DataFrame | None
    truth_units: dict[str, str]


# ---------------------------------------------------------------------------------------------- rounding
def round_significant(values: np.ndarray, bits: int) -> np.ndarray:
    """``values`` rounded to ``bits`` significant bits (round half to even on the mantissa; float32 or float64 kept),
    the step of a binary grid relative to each value's magnitude: 2^-(bits-1) x 2^exponent. NaN and inf pass
    unchanged. Zeroed low mantissa bits are what makes a smooth signal compress."""
    x = np.ascontiguousarray(values)
    if x.dtype not in (np.float32, np.float64):
        raise TypeError(f"round_significant: float32 or float64 expected, got {x.dtype}")
    uint = np.dtype(np.uint32 if x.dtype == np.float32 else np.uint64)
    drop = (23 if x.dtype == np.float32 else 52) - (bits - 1)
    if drop <= 0:
        return x.copy()
    b = x.view(uint)
    one, shift = np.array(1, dtype=uint), np.array(drop, dtype=uint)
    half = (one << (shift - one)) - one + ((b >> shift) & one)   # round half to even on the kept bits
    out = ((b + half) & ~((one << shift) - one)).view(x.dtype)
    finite = np.isfinite(x)
    return np.where(finite & np.isfinite(out), out, x)


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


# ---------------------------------------------------------------------------------------------- writing
@dataclass
class _Column:
    """How one column is stored (decided on the first chunk)."""

    key: str                      # column name in the file
    unit: str
    kind: Literal["time", "measured", "truth"]
    dtype: np.dtype
    step: float | None = None     # measured: round to this grid [unit]
    bits: int | None = None       # truth: round to this many significant bits
    encoding: str | None = None   # None: dictionary (or the writer's default for bool)

    def values(self, raw: np.ndarray) -> np.ndarray:
        x = np.asarray(raw)
        if self.dtype.kind != "f":
            return x.astype(self.dtype, copy=False)
        x = x.astype(np.float64, copy=False)
        if self.step is not None:
            x = np.round(x / self.step) * self.step
        x = x.astype(self.dtype, copy=False)
        if self.bits is not None:
            x = round_significant(x, self.bits)
        return x

    def field(self) -> pa.Field:
        meta = {b"unit": self.unit.encode()}
        if self.step is not None:
            meta[b"resolution"] = repr(float(self.step)).encode()
        return pa.field(self.key, pa.from_numpy_dtype(self.dtype), metadata=meta)


def _plan_integer_column(key: str, kind: Literal["time", "measured", "truth"], unit: str, sample: np.ndarray,
                         dtype: np.dtype) -> _Column:
    """An integer or bool column: dictionary for few distinct values, else delta-packed (integers) or PLAIN (bool)."""
    col = _Column(key, unit, kind, dtype)
    col.encoding = None if len(np.unique(sample)) <= _DICTIONARY_MAX else \
        ("DELTA_BINARY_PACKED" if dtype.kind in "iu" else "PLAIN")
    if dtype.kind == "b":
        col.encoding = "PLAIN"
    return col


def _plan_float_storage(key: str, name: str, kind: Literal["time", "measured", "truth"], unit: str,
                        sample: np.ndarray, precision: str, step: float | None) -> _Column:
    """A float column's stored dtype and rounding (grid ``step`` [unit] or significant bits) for ``precision``."""
    if precision == "exact":
        return _Column(key, unit, kind, np.dtype(sample.dtype))
    if kind == "time":
        return _Column(key, unit, kind, np.dtype(np.float64))
    wide = name in FLOAT64_CHANNELS
    finite = sample[np.isfinite(sample)]
    if step is not None and finite.size and float(np.abs(finite).max()) / step >= _F32_GRID_LIMIT:
        wide = True  # float32 cannot hold this grid over the channel's values
    col = _Column(key, unit, kind, np.dtype(np.float64 if wide else np.float32))
    if kind == "measured":
        col.step = step
    else:
        col.bits = TRUTH_SIGNIFICANT_BITS_64 if wide else TRUTH_SIGNIFICANT_BITS
    return col


def _float_encoding(col: _Column, sample: np.ndarray) -> str | None:
    """The Parquet encoding of a float column from its stored first chunk (None: dictionary)."""
    stored = col.values(sample)
    distinct = len(np.unique(stored[np.isfinite(stored)])) if stored.size else 0
    if col.kind != "time" and distinct <= _DICTIONARY_MAX and stored.size > 4 * distinct:
        return None
    if col.step is not None and col.dtype == np.float32:
        return "PLAIN"  # zstd matches the repeated 4-byte patterns of a quantised channel
    return "BYTE_STREAM_SPLIT"


def _plan_column(key: str, name: str, kind: Literal["time", "measured", "truth"], unit: str, sample: np.ndarray,
                 precision: str, step: float | None) -> _Column:
    """How column ``key`` (channel ``name``) is stored, decided from its first chunk ``sample``."""
    dtype = np.dtype(sample.dtype)
    if dtype.kind == "b" or dtype.kind in "iu":
        return _plan_integer_column(key, kind, unit, sample, dtype)
    if dtype.kind != "f":
        raise TripError(f"channel {name!r}: cannot store dtype {dtype} (numeric channels only)")
    col = _plan_float_storage(key, name, kind, unit, sample, precision, step)
    col.encoding = _float_encoding(col, sample)
    return col


def _arrow(values: np.ndarray) -> pa.Array:
    """A numeric numpy array as an Arrow array, zero-copy, as ``pa.array`` makes it (NaN stays NaN, no nulls) but
    without ``pa.array``'s check for pandas objects, which imports pandas (40 MB of a streamed simulation)."""
    x = np.ascontiguousarray(values)
    if x.dtype.kind not in "fiu":
        return pa.array(x)
    return pa.Array.from_buffers(pa.from_numpy_dtype(x.dtype), x.size, [None, pa.py_buffer(x)])


def _column_arrays(frame: Frame, what: str) -> dict[str, np.ndarray]:
    """A chunk's columns as 1-D arrays by name, from a DataFrame or a mapping name -> array of equal lengths."""
    if not isinstance(frame, Mapping):
        return {c: frame[c].to_numpy() for c in frame.columns}
    cols = {c: np.asarray(v) for c, v in frame.items()}
    sizes = {c: v.shape for c, v in cols.items()}
    if len(set(sizes.values())) > 1 or any(len(s) != 1 for s in sizes.values()):
        raise TripError(f"{what}: every column of a chunk must be a 1-D array of one length, got shapes {sizes}")
    return cols


def _on_rows(values: np.ndarray, rows: np.ndarray | None, n: int) -> pa.Array:
    """``values`` placed on file rows ``rows`` of ``n`` (null elsewhere); ``rows=None``: one value per row."""
    if rows is None:
        return _arrow(values)
    full = np.zeros(n, dtype=values.dtype)
    full[rows] = values
    present = np.zeros(n, dtype=bool)
    present[rows] = True
    return pa.array(full, mask=~present)


class TripWriter:
    """Write a Trip chunk by chunk (one Parquet row group per chunk) -- a day-long simulation never holds more than
    one chunk. Atomic: the file appears at ``path`` only on :meth:`close`; an exception inside the ``with`` block
    (or a writer never closed) leaves nothing behind.

    ``units`` / ``truth_units``: the SI unit of every measured / truth channel (``truth_units=None``: no truth);
    ``precision``: see the module docstring; ``resolutions``: quantisation step [SI] per measured channel;
    ``shared_time``: True if every chunk's truth has the measured time base, False if not, None = decide from the
    first chunk (a later mismatch raises)."""

    def __init__(self, path: str | os.PathLike, units: dict[str, str], truth_units: dict[str, str] | None,
                 precision: str = "compact", resolutions: dict[str, float] | None = None,
                 shared_time: bool | None = None) -> None:
        self.path = Path(path)
        if self.path.suffix != ".parquet":
            raise TripError(f"trip files end in .parquet, got {self.path.name!r}")
        if precision not in PRECISIONS:
            raise TripError(f"precision: expected one of {PRECISIONS}, got {precision!r}")
        self.units, self.truth_units = dict(units), dict(truth_units or {})
        self.has_truth = truth_units is not None
        self.precision = precision
        self.resolutions = dict(resolutions or {})
        self._shared_time = shared_time
        self._time_base: str | None = None
        self._columns: list[_Column] | None = None
        self._schema: pa.Schema | None = None
        self._writer: pq.ParquetWriter | None = None
        self._last_t = -np.inf
        self.n_measured = self.n_truth = 0
        self._ctx = atomic_path(self.path)
        self._tmp: Path | None = None
        self._closed = False
        self._packed = _PackedWriter(self) if precision == "packed" else None

    def __enter__(self) -> "TripWriter":
        self._tmp = self._ctx.__enter__()
        return self

    def __exit__(self, exc_type, exc, tb) -> Literal[False]:
        writer = self._packed.writer if self._packed is not None else self._writer
        if writer is not None and not self._closed:
            try:  # the file is discarded either way; closing after a failed write (a full disk) may fail as well,
                writer.close()  # and must not keep the temporary file from being removed
            except Exception:
                pass
        if exc_type is None and not self._closed:
            exc_type, exc = TripError, TripError(f"{self.path}: TripWriter left without close(meta)")
            self._ctx.__exit__(exc_type, exc, None)
            raise exc
        self._ctx.__exit__(exc_type, exc, tb)
        return False

    # -------------------------------------------------------------- layout
    def _plan(self, measured: dict[str, np.ndarray], truth: dict[str, np.ndarray] | None) -> None:
        if truth is None:
            self._time_base = "shared"
        else:
            same = np.array_equal(measured["t"], truth["t"])
            self._time_base = "shared" if (self._shared_time if self._shared_time is not None else same) else "union"
        cols = [_Column("t", self.units.get("t", "s"), "time", np.dtype(np.float64), encoding="BYTE_STREAM_SPLIT")]
        for c, values in measured.items():
            if c != "t":
                cols.append(_plan_column(c, c, "measured", self.units[c], values, self.precision,
                                         self.resolutions.get(c)))
        if truth is not None:
            for c, values in truth.items():
                if c != "t":
                    cols.append(_plan_column(TRUTH_PREFIX + c, c, "truth", self.truth_units[c], values,
                                             self.precision, None))
        fields = [col.field() for col in cols]
        if self._time_base == "union":
            fields += [pa.field(MEASURED_ROW, pa.bool_()), pa.field(TRUTH_ROW, pa.bool_())]
        self._columns, self._schema = cols, pa.schema(fields)
        encoding = {col.key: col.encoding for col in cols if col.encoding is not None}
        encoding.update({MEASURED_ROW: "PLAIN", TRUTH_ROW: "PLAIN"} if self._time_base == "union" else {})
        # no column statistics: no reader filters on them, and pyarrow's writer keeps every row group's column
        # metadata in memory until close (with statistics: +94 MB for 1440 row groups of 77 columns, measured)
        self._writer = pq.ParquetWriter(self._tmp, self._schema, compression="zstd", compression_level=_ZSTD_LEVEL,
                                        use_dictionary=[col.key for col in cols if col.encoding is None],
                                        column_encoding=encoding, write_statistics=False)

    def write(self, measured: Frame, truth: Frame | None = None) -> None:
        """Append one chunk: measured rows (first column 't') and, for simulated trips, truth rows; each a
        DataFrame or a mapping column name -> 1-D array (a streamed simulation's chunks: no pandas needed)."""
        if self._closed:
            raise TripError(f"{self.path}: write after close")
        if (truth is not None) != self.has_truth:
            raise TripError("truth: give a truth frame with every chunk iff truth_units were given")
        if self._packed is not None:
            self._packed.write(_as_dataframe(measured), None if truth is None else _as_dataframe(truth))
            return
        cols = _column_arrays(measured, "measured")
        truth_cols = None if truth is None else _column_arrays(truth, "truth")
        if "t" not in cols:
            raise TripError("measured: a chunk's first column is 't' [s]")
        if self._columns is None:
            if self._tmp is None:
                raise TripError(f"{self.path}: TripWriter has no open Parquet writer (use it as a context manager)")
            self._plan(cols, truth_cols)
        assert self._columns is not None and self._writer is not None and self._schema is not None
        self._check_columns(cols, truth_cols, self._columns)
        t, rows_m, rows_t = self._row_times(cols, truth_cols)
        table = pa.Table.from_arrays(self._chunk_arrays(cols, truth_cols, t, rows_m, rows_t), schema=self._schema)
        self._writer.write_table(table)
        del table
        pa.default_memory_pool().release_unused()  # hand the chunk's buffers back: bounded RSS over a day
        if t.size:
            self._last_t = float(t[-1])
        self.n_measured += len(cols["t"])
        self.n_truth += 0 if truth_cols is None else len(truth_cols["t"])

    def _check_columns(self, measured: dict[str, np.ndarray], truth: dict[str, np.ndarray] | None,
                       columns: list[_Column]) -> None:
        """Raise unless the chunk has the first chunk's columns, in the same order."""
        names = [c for c in measured] + ([] if truth is None else [TRUTH_PREFIX + c for c in truth if c != "t"])
        expected = [col.key for col in columns]
        if names != expected:
            raise TripError(f"{self.path}: chunk columns {names} differ from the first chunk's {expected}")

    def _row_times(self, measured: dict[str, np.ndarray], truth: dict[str, np.ndarray] | None
                   ) -> tuple[np.ndarray, np.ndarray | None, np.ndarray | None]:
        """The file rows' times t [s] and the row index of each measured / truth sample (None: every row)."""
        tm = np.asarray(measured["t"], dtype=np.float64)
        if self._time_base == "shared":
            if truth is not None and not np.array_equal(tm, np.asarray(truth["t"], dtype=np.float64)):
                raise TripError("truth: its time base differed from the measured one only after the first chunk; "
                                "give the same time base in every chunk or write one chunk")
            t, rows_m, rows_t = tm, None, None
        else:
            tt = np.asarray(truth["t"], dtype=np.float64) if truth is not None else np.empty(0)
            t = np.union1d(tm, tt)
            rows_m, rows_t = np.searchsorted(t, tm), np.searchsorted(t, tt)
        if t.size and not t[0] > self._last_t:
            raise TripError(f"{self.path}: chunk starts at t = {t[0]:.6g} s, not after the previous chunk's end "
                            f"{self._last_t:.6g} s (chunks must follow each other in time)")
        return t, rows_m, rows_t

    def _chunk_arrays(self, measured: dict[str, np.ndarray], truth: dict[str, np.ndarray] | None, t: np.ndarray,
                      rows_m: np.ndarray | None, rows_t: np.ndarray | None) -> list[pa.Array]:
        """The chunk's stored columns in schema order, plus the row flags of a union time base."""
        assert self._columns is not None
        arrays = []
        for col in self._columns:
            if col.kind == "time":
                arrays.append(_arrow(t))
                continue
            frame, rows = (measured, rows_m) if col.kind == "measured" else (truth, rows_t)
            assert frame is not None
            name = col.key[len(TRUTH_PREFIX):] if col.kind == "truth" else col.key
            arrays.append(_on_rows(col.values(frame[name]), rows, t.size))
        if self._time_base == "union":
            for rows in (rows_m, rows_t):
                flag = np.zeros(t.size, dtype=bool)
                flag[rows] = True
                arrays.append(pa.array(flag))
        return arrays

    def close(self, meta: dict[str, Any]) -> Path:
        """Finish the file with the trip's metadata (known only at the end of a streamed simulation)."""
        if self._packed is not None:
            payload, writer = self._packed.payload(meta), self._packed.writer
        else:
            payload = {"version": FORMAT_VERSION, "meta": meta, "precision": self.precision,
                       "n_measured": self.n_measured, "n_truth": self.n_truth, "has_truth": self.has_truth,
                       "time_base": self._time_base}
            writer = self._writer
        text = json.dumps(payload)  # a TypeError here leaves nothing behind
        if writer is None:
            raise TripError(f"{self.path}: nothing written (a trip needs at least one chunk)")
        writer.add_key_value_metadata({META_KEY: text.encode()})
        writer.close()
        self._closed = True
        return self.path


# ---------------------------------------------------------------------------------------------- reading
def open_trip_file(path: str | os.PathLike) -> tuple[pq.ParquetFile, dict[str, Any]]:
    """The Parquet file and its validated ``roadload`` payload (TripError when it is no trip file)."""
    path = Path(path)
    if not path.exists():
        raise TripError(f"no trip file at {path}")
    try:
        pf = pq.ParquetFile(path)
    except Exception as exc:  # pyarrow raises several types for corrupt files
        raise TripError(f"{path}: not a readable Parquet file ({exc})") from None
    raw = (pf.metadata.metadata or {}).get(META_KEY)  # file key-value metadata (formats >= 2 write it last)
    if raw is None:
        raw = (pf.schema_arrow.metadata or {}).get(META_KEY)
    if raw is None:
        raise TripError(f"{path}: Parquet file without roadload metadata (not a Trip)")
    try:
        payload = parse_trip_payload(raw, path, pf.metadata.num_rows)
    except TripMetadataError as exc:
        raise TripError(str(exc)) from None
    if payload["version"] >= 4:
        payload["units"], payload["truth_units"], payload["resolutions"] = _field_units(pf.schema_arrow, path)
    return pf, payload


def _field_units(schema: pa.Schema, path: Path) -> tuple[dict[str, str], dict[str, str], dict[str, float]]:
    units, truth_units, res = {}, {}, {}
    for f in schema:
        if f.name in RESERVED_COLUMNS:
            continue
        md = f.metadata or {}
        if b"unit" not in md:
            raise TripError(f"{path}: column {f.name!r} has no 'unit' in its field metadata (not a roadload trip "
                            f"file, or a corrupt one)")
        unit = md[b"unit"].decode()
        if f.name.startswith(TRUTH_PREFIX):
            truth_units[f.name[len(TRUTH_PREFIX):]] = unit
        else:
            units[f.name] = unit
            if b"resolution" in md:
                res[f.name] = float(md[b"resolution"])
    truth_units.setdefault("t", units.get("t", "s"))
    return units, truth_units, res


def trip_file_info(path: str | os.PathLike) -> dict[str, Any]:
    """The file's bookkeeping without reading any data: meta, units, truth_units, n_measured, n_truth, channels,
    truth_channels, precision, version."""
    pf, payload = open_trip_file(path)
    names = pf.schema_arrow.names
    truth_units = payload["truth_units"] if payload.get("has_truth", payload["n_truth"] > 0 or
                                                         any(c.startswith(TRUTH_PREFIX) for c in names)) else {}
    return {"meta": payload["meta"], "units": payload["units"], "truth_units": truth_units,
            "n_measured": payload["n_measured"], "n_truth": payload["n_truth"],
            "channels": [c for c in names if not c.startswith(TRUTH_PREFIX) and c not in ("t", _ROWS)
                         and c not in RESERVED_COLUMNS],
            "truth_channels": [c[len(TRUTH_PREFIX):] for c in names if c.startswith(TRUTH_PREFIX)
                               and c != TRUTH_PREFIX + "t"],
            "precision": storage_precision(payload), "version": payload["version"]}


def trip_file_extent(path: str | os.PathLike) -> tuple[float, float, float | None]:
    """(first t [s], last t [s], last ground-truth position [m] or None) of the measured rows of a trip file.
    A format-4 file with one time base answers from two columns of its first and last row groups (no frame
    built, no pandas: the summary of a streamed day in a few kB); other files are read chunk by chunk."""
    pf, payload = open_trip_file(path)
    names = pf.schema_arrow.names
    position = TRUTH_PREFIX + "position"
    groups = pf.metadata.num_row_groups
    if payload["version"] >= 4 and payload.get("time_base") == "shared" and payload["n_measured"] > 0 and groups:
        first = pf.read_row_group(0, columns=["t"]).column("t")
        last = pf.read_row_group(groups - 1, columns=["t"] + ([position] if position in names else []))
        x_end = last.column(position)[-1].as_py() if position in names else None
        return float(first[0].as_py()), float(last.column("t")[-1].as_py()), x_end
    t_first = t_last = float("nan")
    x_last = None
    for part in iter_trip_chunks(path, channels=[], truth_channels=["position"]):
        t = part.measured["t"].to_numpy()
        if t.size:
            t_first = float(t[0]) if t_first != t_first else t_first
            t_last = float(t[-1])
        if part.truth is not None and "position" in part.truth and len(part.truth):
            x_last = float(part.truth["position"].iloc[-1])
    return t_first, t_last, x_last


def storage_precision(payload: dict[str, Any]) -> str:
    """The precision a file was written with ('compact' files of formats 2-3 are the private codec, 'packed')."""
    precision = str(payload.get("precision", "exact"))
    return "packed" if payload["version"] < 4 and precision == "compact" else precision


def _wanted_columns(names: list[str], channels: list[str] | None, truth_channels: list[str] | None
                    ) -> list[str] | None:
    if channels is None and truth_channels is None:
        return None
    want = ["t", _ROWS, MEASURED_ROW, TRUTH_ROW] + list(
        channels if channels is not None else
        [c for c in names if not c.startswith(TRUTH_PREFIX) and c != "t"])
    if truth_channels is None or len(truth_channels) > 0:  # [] = no truth at all
        want += [TRUTH_PREFIX + c for c in (["t"] + list(truth_channels) if truth_channels is not None
                                            else [c[len(TRUTH_PREFIX):] for c in names
                                                  if c.startswith(TRUTH_PREFIX)])]
    wanted = set(want)
    return [c for c in names if c in wanted]


def read_trip_file(path: str | os.PathLike, channels: list[str] | None = None,
                   truth_channels: list[str] | None = None) -> TripParts:
    """The whole file (or only the named channels, plus 't'; names the file lacks are ignored)."""
    path = Path(path)
    pf, payload = open_trip_file(path)
    columns = _wanted_columns(pf.schema_arrow.names, channels, truth_channels)
    try:
        table = pf.read(columns=columns)
    except Exception as exc:  # pyarrow raises several types for corrupt files
        raise TripError(f"{path}: not a readable Parquet file ({exc})") from None
    if payload["version"] >= 4:
        return _parts_v4(table, payload, truth_channels)
    return _parts_legacy(table, payload, payload["n_measured"], payload["n_truth"])


def iter_trip_chunks(path: str | os.PathLike, channels: list[str] | None = None,
                     truth_channels: list[str] | None = None, rows: int = 360_000) -> Iterator[TripParts]:
    """The file as consecutive parts of about ``rows`` file rows each, reading only the requested channels: memory
    bounded by one part. Files written before format 2 are read whole and sliced."""
    path = Path(path)
    pf, payload = open_trip_file(path)
    step = max(int(rows), 1)
    if payload["version"] < 2:
        whole = read_trip_file(path, channels, truth_channels)
        t = whole.measured["t"].to_numpy()
        for a in range(0, len(t), step):
            lo, hi = t[a], t[min(a + step, len(t)) - 1]
            m = whole.measured[(whole.measured["t"] >= lo) & (whole.measured["t"] <= hi)].reset_index(drop=True)
            tr = None if whole.truth is None else \
                whole.truth[(whole.truth["t"] >= lo) & (whole.truth["t"] <= hi)].reset_index(drop=True)
            yield TripParts(m, whole.units, whole.meta, tr, whole.truth_units)
        return
    columns = _wanted_columns(pf.schema_arrow.names, channels, truth_channels)
    carry: dict[str, Any] = {}  # format 3 'delta' columns continue from the previous batch
    for batch in pf.iter_batches(batch_size=step, columns=columns):
        table = pa.Table.from_batches([batch])
        if payload["version"] >= 4:
            yield _parts_v4(table, payload, truth_channels)
        else:
            yield _parts_legacy(table, payload, None, None, carry)


def _as_float64(col: pa.ChunkedArray, step: float | None) -> np.ndarray:
    """A stored float column as float64; values of a quantised channel back on the grid k x step (the very product
    the sensor's quantiser formed) where float32 held k exactly."""
    x = col.to_numpy(zero_copy_only=False).astype(np.float64, copy=False)
    if step is not None and col.type == pa.float32():
        k = np.round(x / step)
        on_grid = np.abs(k) < _F32_GRID_LIMIT
        x = np.where(on_grid, k * step, x)
    return x


def _parts_v4(table: pa.Table, payload: dict[str, Any], truth_channels: list[str] | None) -> TripParts:
    import pandas as pd  # here, not at import (see the TYPE_CHECKING import)

    res = payload.get("resolutions", {})
    measured_table = truth_table = table
    if payload.get("time_base") == "union":
        measured_table = table.filter(table.column(MEASURED_ROW))
        truth_table = table.filter(table.column(TRUTH_ROW))

    def values(tab: pa.Table, name: str, step: float | None) -> np.ndarray:
        col = tab.column(name)
        return _as_float64(col, step) if pa.types.is_floating(col.type) else col.to_numpy(zero_copy_only=False)

    measured = pd.DataFrame({c: values(measured_table, c, res.get(c)) for c in measured_table.column_names
                             if c not in RESERVED_COLUMNS and not c.startswith(TRUTH_PREFIX)}, copy=False)
    truth = None
    if payload.get("has_truth", False) and (truth_channels is None or len(truth_channels) > 0):
        truth = pd.DataFrame({"t": values(truth_table, "t", None),
                              **{c[len(TRUTH_PREFIX):]: values(truth_table, c, None)
                                 for c in truth_table.column_names if c.startswith(TRUTH_PREFIX)}}, copy=False)
    units = {c: u for c, u in payload["units"].items() if c in measured.columns}
    truth_units = {} if truth is None else {c: u for c, u in payload["truth_units"].items() if c in truth.columns}
    return TripParts(measured, units, payload["meta"], truth, truth_units)


# ---------------------------------------------------------------------------------------------- formats 1-3
# Format 3 ('packed', roadload's private codec) and earlier: measured channels with a quantisation step stored as
# int32 multiples of it, other floats as float32 / float64 bit patterns, integer codes optionally as first
# differences continued across row groups ('delta'); truth 'position' / 'source_energy' as int64 multiples of a
# fixed step; '_rows' flags which rows of the file belong to which frame (rows padded with nulls).
_ROWS = "_rows"
PACKED_VERSION = 3
TRUTH_FIXED = {"position": 1e-4, "source_energy": 1e-3}


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


def _row_flags(cols: dict[str, np.ndarray]) -> tuple[np.ndarray | None, np.ndarray | None]:
    """Which file rows are measured / truth rows, from the '_rows' flags (popped from ``cols``; None: no flags)."""
    flags = cols.pop(_ROWS, None)
    if flags is None:
        return None, None
    return (flags.astype(np.uint8) & 1) > 0, (flags.astype(np.uint8) & 2) > 0


def _take_rows(frame: dict[str, np.ndarray], rows: np.ndarray | None, n: int | None) -> dict[str, np.ndarray]:
    """The columns of ``frame`` on the flagged ``rows``, else on the first ``n`` rows, else whole."""
    if rows is not None:
        return {c: v[rows] for c, v in frame.items()}
    if n is not None:
        return {c: v[:n] for c, v in frame.items()}
    return frame


def _legacy_truth(cols: dict[str, np.ndarray], payload: dict[str, Any], rows: np.ndarray | None, n: int | None,
                  measured: pd.DataFrame) -> pd.DataFrame | None:
    """The truth frame of a format 1-3 table (its 't' from the measured frame when stored once)."""
    import pandas as pd  # here, not at import (see the TYPE_CHECKING import)

    truth_names = [c for c in cols if c.startswith(TRUTH_PREFIX)]
    if not truth_names:
        return None
    tr = _take_rows({c[len(TRUTH_PREFIX):]: cols[c] for c in truth_names}, rows, n)
    if "t" not in tr and payload.get("truth_time") == "measured":
        tr = {"t": measured["t"].to_numpy(), **tr}  # one time base stored once
    return pd.DataFrame(tr, copy=False)


def _restore_dtypes(frame: pd.DataFrame, dtypes: dict[str, str]) -> pd.DataFrame:
    """``frame`` with the dtypes it was written with (NaN padding and the storage encoding changed them)."""
    return frame.astype({c: d for c, d in dtypes.items() if c in frame.columns and str(frame[c].dtype) != d})


def _parts_legacy(table: pa.Table, payload: dict[str, Any], n_measured: int | None, n_truth: int | None,
                  carry: dict[str, Any] | None = None) -> TripParts:
    """A format 1-3 table decoded (``n_measured`` / ``n_truth``: rows of each frame when the file has no flags)."""
    import pandas as pd  # here, not at import (see the TYPE_CHECKING import)

    enc = payload.get("encoding", {})
    cols: dict[str, np.ndarray] = {name: _decode(table.column(name), enc.get(name), name, carry)
                                   for name in table.column_names}
    m_rows, t_rows = _row_flags(cols)
    meas = _take_rows({c: v for c, v in cols.items() if not c.startswith(TRUTH_PREFIX)}, m_rows, n_measured)
    measured = pd.DataFrame(meas, copy=False)
    truth = _legacy_truth(cols, payload, t_rows, n_truth, measured)
    measured = _restore_dtypes(measured, payload.get("dtypes", {}))
    if truth is not None:
        truth = _restore_dtypes(truth, payload.get("truth_dtypes", {}))
    units = {c: u for c, u in payload["units"].items() if c in measured.columns}
    truth_units = {c: u for c, u in payload["truth_units"].items() if truth is not None and c in truth.columns}
    return TripParts(measured.reset_index(drop=True), units, payload["meta"],
                     None if truth is None else truth.reset_index(drop=True), truth_units)


def _as_dataframe(frame: Frame) -> pd.DataFrame:
    """A chunk as a DataFrame (the packed writer records and restores the frames' dtypes)."""
    import pandas as pd  # here, not at import (see the TYPE_CHECKING import)

    return frame if isinstance(frame, pd.DataFrame) else pd.DataFrame(_column_arrays(frame, "chunk"), copy=False)


class _PackedWriter:
    """The writer of format 3 ('packed'): see the section comment above. Kept as an explicit opt-in only."""

    def __init__(self, owner: TripWriter) -> None:
        self.owner = owner
        self.writer: pq.ParquetWriter | None = None
        self._schema: pa.Schema | None = None
        self._encoding: dict[str, dict[str, Any]] = {}
        self._carry: dict[str, Any] = {}  # last integer of every 'delta' column (its differences continue)
        self._dtypes: dict[str, str] = {}
        self._truth_dtypes: dict[str, str] = {}
        self._truth_time = "own" if owner._shared_time is False else "measured"

    def _column(self, name: str, values: np.ndarray, truth: bool) -> pa.Array:
        key = (TRUTH_PREFIX + name) if truth else name
        if self._schema is None:  # first chunk: decide the column's storage
            enc = None
            if values.dtype.kind == "f":
                step = TRUTH_FIXED.get(name) if truth else self.owner.resolutions.get(name)
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
                            f"its resolution {step!r} (write it with precision='compact' or 'exact')")
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

    def write(self, measured: pd.DataFrame, truth: pd.DataFrame | None) -> None:
        """Append one chunk as format 3 (integer codes, rows padded with nulls to the longer frame)."""
        owner = self.owner
        nm, nt = len(measured), 0 if truth is None else len(truth)
        first = self._schema is None
        if first:
            self._record_dtypes(measured, truth)
        self._check_truth_time(measured, truth, first)
        table = self._chunk_table(measured, truth, nm, nt)
        if first:
            self._open(table.schema)
        elif table.schema != self._schema:
            raise TripError(f"{owner.path}: chunk columns {table.schema.names} differ from the first chunk's "
                            f"{self._schema.names if self._schema is not None else []}")
        assert self.writer is not None
        self.writer.write_table(table)
        del table
        pa.default_memory_pool().release_unused()
        owner.n_measured += nm
        owner.n_truth += nt

    def _record_dtypes(self, measured: pd.DataFrame, truth: pd.DataFrame | None) -> None:
        """Remember the first chunk's dtypes, restored on reading."""
        self._dtypes = {c: str(t) for c, t in measured.dtypes.items()}
        if truth is not None:
            self._truth_dtypes = {c: str(t) for c, t in truth.dtypes.items()}

    def _check_truth_time(self, measured: pd.DataFrame, truth: pd.DataFrame | None, first: bool) -> None:
        """Store truth's 't' apart ('own') when its time base differs from the measured one on the first chunk."""
        if truth is None or self._truth_time != "measured":
            return
        same = len(measured) == len(truth) and np.array_equal(measured["t"].to_numpy(), truth["t"].to_numpy())
        if not same:
            if not first or self.owner._shared_time:
                raise TripError("truth: its time base differed from the measured one only after the first "
                                "chunk; give the same time base in every chunk or write one chunk")
            self._truth_time = "own"

    def _chunk_table(self, measured: pd.DataFrame, truth: pd.DataFrame | None, nm: int, nt: int) -> pa.Table:
        """The chunk's coded columns, each padded with nulls to the longer frame, and the '_rows' flags."""
        n = max(nm, nt)

        def pad(arr: pa.Array, k: int) -> pa.Array:
            return arr if k == n else pa.concat_arrays([arr, pa.nulls(n - k, arr.type)])

        arrays, names = [], []
        for c in measured.columns:
            arrays.append(pad(self._column(c, measured[c].to_numpy(), False), nm))
            names.append(c)
        for c in ([] if truth is None else truth.columns):
            if c == "t" and self._truth_time == "measured":
                continue
            assert truth is not None
            arrays.append(pad(self._column(c, truth[c].to_numpy(), True), nt))
            names.append(TRUTH_PREFIX + c)
        flags = np.zeros(n, dtype=np.uint8)
        flags[:nm] |= 1
        flags[:nt] |= 2
        arrays.append(pa.array(flags))
        names.append(_ROWS)
        return pa.Table.from_arrays(arrays, names=names)

    def _open(self, schema: pa.Schema) -> None:
        """Open the Parquet writer on the first chunk's schema: floats byte-stream-split, integers delta-packed."""
        owner = self.owner
        self._schema = schema
        encoding = {f.name: "BYTE_STREAM_SPLIT" for f in schema if pa.types.is_floating(f.type)}
        encoding.update({f.name: "DELTA_BINARY_PACKED" for f in schema if pa.types.is_integer(f.type)})
        if owner._tmp is None:
            raise TripError(f"{owner.path}: TripWriter has no open Parquet writer (use it as a context manager)")
        self.writer = pq.ParquetWriter(owner._tmp, schema, compression="zstd", compression_level=15,
                                       use_dictionary=False, column_encoding=encoding, write_statistics=False)

    def payload(self, meta: dict[str, Any]) -> dict[str, Any]:
        owner = self.owner
        return {
            "version": PACKED_VERSION, "units": owner.units, "truth_units": owner.truth_units, "meta": meta,
            "n_measured": owner.n_measured, "n_truth": owner.n_truth, "dtypes": self._dtypes,
            "truth_dtypes": self._truth_dtypes, "precision": "packed", "encoding": self._encoding,
            "truth_time": self._truth_time if owner.has_truth else None,
        }
