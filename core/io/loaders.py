"""One loader per log format; each turns its file into source signals and hands them to the mapping layer.

=============  ==========================================================================================
format         source
=============  ==========================================================================================
dbc-mf4        ASAM MDF4 CAN bus log (a file or a folder of a session's parts) + DBC(s) from the mapping
candump        candump ``.log`` (also ``asc``, ``blf`` — python-can readers) + DBC(s)
comma2k19      comma2k19 ``processed_log/CAN/raw_can`` arrays + DBC(s)
csv            any delimited text log with a time column, through a column map (mapping ``csv`` options)
bmw-i3         TUM BMW i3 trip CSV (csv + i3 vehicle spec: rim torque, grade, payload notes)
openxc         OpenXC JSON trace, lines ``<unix time>: {"name": ..., "value": ...}``
=============  ==========================================================================================

`roadload.io.importer.import_log` is the single entry point (CLI ``roadload import``): read -> mapping -> derived
channels -> Trip with ``meta["import_report"]`` listing every repair and drop.
"""

from __future__ import annotations

import json
import re
import warnings
from pathlib import Path
from typing import Any, Callable, Sequence

import numpy as np
import pandas as pd

from ..trip import Trip
from ..units import to_si
from .dbc import DbcSource, Database, decode_frames, find_dbc, load_dbc
from .frames import CanFrames, describe_lines, read_can_log, read_comma2k19, read_mf4, read_python_can
from .mapping import Mapping, apply_mapping
from .report import ImportReport, LogImportError
from .signals import Signal, SignalSet

Progress = Callable[[str, float], None]  # (stage, fraction 0..1)

DEFAULT_MAPPINGS = {"bmw-i3": "bmw_i3", "openxc": "openxc", "dbc-mf4": "canedge_gnss_obd",
                    "comma2k19": "comma2k19_rav4", "csv": "plain_csv"}
CAN_LOG_FORMATS = ("dbc-mf4", "candump", "blf", "asc", "comma2k19")


# ------------------------------------------------------------------------------------------ CAN logs
def resolve_dbcs(mapping: Mapping, source: Path, extra: Sequence[str | Path] = ()) -> list[DbcSource]:
    """The mapping's DBC entries (searched next to the source, the mapping file and in the package) + extras."""
    roots = [source] + ([Path(mapping.path).parent] if mapping.path else [])
    out = [DbcSource(find_dbc(str(entry["file"]), roots), entry.get("bus")) for entry in mapping.dbc]
    out += [DbcSource(Path(p), None) for p in extra]
    if not out:
        raise LogImportError(f"mapping {mapping.name!r} names no DBC file and none was given (--dbc)")
    return out


def check_mapping_against_dbc(mapping: Mapping, db: Database, report: ImportReport) -> set[str]:
    """Every mapped CAN source ``message.signal`` must exist in a DBC; returns the message names needed."""
    known_msgs = db.message_names()
    known = db.signal_names()
    needed: set[str] = set()
    problems = []
    for cm in mapping.channels:
        hits = [s for s in cm.sources if s in known]
        if not hits:
            msg_names = {s.partition(".")[0] for s in cm.sources}
            absent = sorted(m for m in msg_names if m not in known_msgs)
            what = (f"message(s) {absent} not defined in any DBC" if absent
                    else f"signal(s) {cm.sources} not defined in their message")
            text = f"channel {cm.channel}: {what}"
            if cm.required:
                problems.append(text)
            else:
                report.note(f"optional {text}")
            continue
        needed |= {h.partition(".")[0] for h in hits}
    for extra in mapping.auxiliary_sources:
        if extra in known:
            needed.add(extra.partition(".")[0])
        else:
            problems.append(f"signal {extra!r} (validity flag / clock / plus) not defined in any DBC")
    if problems:
        raise LogImportError(f"mapping {mapping.name!r} does not fit the DBC files {db.files}: " + "; ".join(problems))
    return needed


def signals_from_frames(frames: CanFrames, mapping: Mapping, dbcs: list[DbcSource],
                        report: ImportReport) -> SignalSet:
    db = load_dbc(dbcs, report)
    needed = check_mapping_against_dbc(mapping, db, report)
    return decode_frames(frames, db, report, wanted_messages=needed)


def load_can_log(source: str | Path, mapping: Mapping, *, dbc: Sequence[str | Path] = (),
                 progress: Progress | None = None, fmt: str = "dbc-mf4") -> Trip:
    """A CAN bus log (MF4 file/folder, candump/asc/blf, comma2k19 raw_can) decoded with DBCs into a Trip."""
    source = Path(source)
    if not source.exists():
        raise LogImportError(f"no such log: {source}")
    report = ImportReport()
    dbcs = resolve_dbcs(mapping, source, list(dbc))
    mf4_progress = (lambda k, n: progress("read", 0.6 * k / n)) if progress else None
    if fmt == "comma2k19":
        frames = read_comma2k19(source)
    elif fmt == "dbc-mf4":
        frames = read_mf4(source, mf4_progress)
    elif fmt in ("candump", "blf", "asc"):
        frames = read_python_can(source, report)
    else:
        frames = read_can_log(source, mf4_progress)
    if progress:
        progress("decode", 0.6)
    signals = signals_from_frames(frames, mapping, dbcs, report)
    if progress:
        progress("map", 0.8)
    files = sorted(source.glob("*.[mM][fF]4")) if source.is_dir() and fmt == "dbc-mf4" else [source]
    meta = {"source": {"format": fmt, "path": str(source), "files": [str(f) for f in files],
                       "bytes": int(sum(f.stat().st_size for f in files if f.is_file())),
                       "n_frames": len(frames), "dbc": [str(d.path) for d in dbcs]}}
    trip = apply_mapping(signals, mapping, report, start_time=frames.start_time, meta=meta, name=source.stem)
    return trip


# ------------------------------------------------------------------------------------------ CSV
_UNIT_RE = re.compile(r"^(.*?)\s*[\[(]\s*([^\])]*)\s*[\])]\s*$")


def split_header(column: str) -> tuple[str, str | None]:
    """'Velocity [km/h]' -> ('Velocity', 'km/h'); 'max. SoC [%)' -> ('max. SoC', '%'); no bracket -> unit None."""
    m = _UNIT_RE.match(column.strip())
    if not m:
        return column.strip(), None
    return m.group(1).strip(), m.group(2).strip()


#: plausible logger sample intervals [s]: 10 kHz ... 0.2 Hz; a log longer than a day is refused
MIN_SAMPLE_INTERVAL, MAX_SAMPLE_INTERVAL, MAX_LOG_DURATION = 1e-4, 5.0, 86400.0
_TIME_UNITS = {"s": 1.0, "ms": 1e-3}  # the time units roadload.units knows


def _file_lines(positions: np.ndarray, skipped: list[int]) -> list[int]:
    """1-based file line numbers of data-frame rows (header on line 1, `skipped` malformed lines left out)."""
    out = []
    for pos in positions:
        line = int(pos) + 2
        for bad in skipped:
            if bad <= line:
                line += 1
        out.append(line)
    return out


def check_time_base(t: np.ndarray, unit: str, where: str) -> None:
    """Refuse a time column whose declared unit makes the log longer than a day or its sample interval unlike
    any logger (median step outside [1e-4, 60] s), with a hint at the unit that would fit."""
    if t.size < 2:
        return
    dt = np.diff(t)
    dt = dt[np.isfinite(dt) & (dt > 0)]
    if dt.size == 0:
        return
    step = float(np.median(dt))
    span = float(np.nanmax(t) - np.nanmin(t))
    if span <= MAX_LOG_DURATION and MIN_SAMPLE_INTERVAL <= step <= MAX_SAMPLE_INTERVAL:
        return
    factor = _TIME_UNITS.get(unit, 1.0)
    hint = ""
    for name, f in _TIME_UNITS.items():
        s_step, s_span = step / factor * f, span / factor * f
        if name != unit and MIN_SAMPLE_INTERVAL <= s_step <= MAX_SAMPLE_INTERVAL and s_span <= MAX_LOG_DURATION:
            hint = (f"; the time column looks like {name} ({_UNIT_WORDS.get(name, name)}): set the mapping's "
                    f"csv.time_unit to {name!r}")
            break
    raise LogImportError(f"{where} declared in {unit!r} gives a log of {span:.6g} s with a median sample interval "
                         f"of {step:.3g} s; expected at most {MAX_LOG_DURATION:g} s [1 day] and an interval in "
                         f"[{MIN_SAMPLE_INTERVAL:g}, {MAX_SAMPLE_INTERVAL:g}] s{hint}")


_UNIT_WORDS = {"s": "seconds", "ms": "milliseconds"}


def read_csv_signals(path: str | Path, mapping: Mapping, report: ImportReport) -> SignalSet:
    """Columns of a delimited log as signals on its time column. Column names are stripped; a name that occurs
    twice is kept as ``name#2`` (counted in the report); units come from ``[unit]`` in the header."""
    path = Path(path)
    if not path.is_file():
        raise LogImportError(f"no such CSV log: {path}")
    opts = mapping.csv
    time_col = opts.get("time")
    if not time_col:
        raise LogImportError(f"mapping {mapping.name!r}: csv.time (the time column) is not set")
    df, bad_lines = _read_csv_frame(path, opts, report)
    tkey = next((c for c in [time_col] + list(opts.get("time_alternatives", [])) if c in df.columns), None)
    if tkey is None:
        raise LogImportError(f"{path}: time column {time_col!r} missing; columns are {list(df.columns)[:12]}...")
    t_unit = opts.get("time_unit", "s")
    t = to_si(pd.to_numeric(df[tkey], errors="coerce").to_numpy(dtype=float), t_unit)[0]
    bad_t = ~np.isfinite(t)
    if bad_t.all():
        raise LogImportError(f"{path}: time column {tkey!r} holds no numbers")
    if bad_t.any():  # rows without a time stamp cannot be placed on the time base
        rows = _file_lines(np.flatnonzero(bad_t), bad_lines)
        report.drop(f"{path.name} lines", f"time column {tkey!r} not numeric", int(bad_t.sum()), describe_lines(rows))
        df = df.loc[~bad_t].reset_index(drop=True)
        t = t[~bad_t]
    check_time_base(t, t_unit, f"{path}: time column {tkey!r}")
    return {col: Signal(t, _numeric_column(df, col, bad_lines, report), split_header(col.split("#")[0])[1])
            for col in df.columns if col != tkey}


def _read_csv_frame(path: Path, opts: dict[str, Any], report: ImportReport) -> tuple[pd.DataFrame, list[int]]:
    """The CSV as a DataFrame with stripped, unique column names (a repeated name's later copies become name#2,
    ...; counted) and the file lines of the malformed rows pandas skipped (reported)."""
    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always", pd.errors.ParserWarning)
            df = pd.read_csv(path, sep=opts.get("sep", ","), encoding=opts.get("encoding", "utf-8"),
                             decimal=opts.get("decimal", "."), header=0, low_memory=False, on_bad_lines="warn")
    except (pd.errors.ParserError, pd.errors.EmptyDataError, UnicodeDecodeError, LookupError) as exc:
        raise LogImportError(f"{path}: unreadable CSV ({type(exc).__name__}: {exc})") from None
    bad_lines = sorted(int(n) for w in caught for n in re.findall(r"Skipping line (\d+)", str(w.message)))
    if bad_lines:
        report.drop(f"{path.name} lines", "malformed CSV line (wrong number of fields)", len(bad_lines),
                    describe_lines(bad_lines))
    # pandas renames duplicate headers 'x' -> 'x.1'; recover the raw header to name duplicates explicitly
    with open(path, encoding=opts.get("encoding", "utf-8"), newline="") as fh:
        header = fh.readline().rstrip("\r\n").split(opts.get("sep", ","))
    if len(header) != df.shape[1]:
        raise LogImportError(f"{path}: header has {len(header)} names but rows have {df.shape[1]} columns")
    names: list[str] = []
    seen: dict[str, int] = {}
    for h in header:
        h = h.strip()
        seen[h] = seen.get(h, 0) + 1
        names.append(h if seen[h] == 1 else f"{h}#{seen[h]}")
    for h, c in seen.items():
        if c > 1:
            report.repair(h, "duplicate column name; later copies renamed name#2, ...", c - 1)
    df.columns = names
    return df, bad_lines


def _numeric_column(df: pd.DataFrame, col: str, bad_lines: list[int], report: ImportReport) -> np.ndarray:
    """A column's values: numbers where the column is numeric; a text column with some numbers becomes numeric with
    the non-numeric cells NaN (counted with their file lines); an all-text column stays as it is."""
    values = df[col].to_numpy()
    if values.dtype != object:
        return values
    numeric = pd.to_numeric(df[col], errors="coerce").to_numpy(dtype=float)
    bad = np.isnan(numeric) & df[col].notna().to_numpy()
    if bad.all():
        return values
    if bad.any():
        report.drop(col, "non-numeric cell", int(bad.sum()),
                    describe_lines(_file_lines(np.flatnonzero(bad), bad_lines)))
    return numeric


def load_csv_log(source: str | Path, mapping: Mapping, *, progress: Progress | None = None,
                 meta: dict[str, Any] | None = None) -> Trip:
    source = Path(source)
    report = ImportReport()
    if progress:
        progress("read", 0.0)
    signals = read_csv_signals(source, mapping, report)
    if progress:
        progress("map", 0.7)
    meta = {"source": {"format": mapping.format, "path": str(source), "bytes": source.stat().st_size},
            **(meta or {})}
    return apply_mapping(signals, mapping, report, meta=meta, name=source.stem)


# ------------------------------------------------------------------------------------------ OpenXC
def read_openxc_signals(path: str | Path, report: ImportReport) -> tuple[SignalSet, float]:
    """OpenXC trace lines ``<unix time>: {"name": n, "value": v}`` -> signals (t relative to the first line)."""
    path = Path(path)
    if not path.is_file():
        raise LogImportError(f"no such OpenXC trace: {path}")
    cols: dict[str, tuple[list[float], list[Any]]] = {}
    bad = events = 0
    with open(path, encoding="utf-8") as fh:
        for lineno, line in enumerate(fh, 1):
            line = line.strip()
            if not line:
                continue
            head, sep, body = line.partition(": ")
            if not sep or head.startswith("{"):
                raise LogImportError(f"{path}:{lineno}: OpenXC line without a time stamp "
                                     f"(expected '<unix time>: {{json}}'); untimed traces cannot be imported")
            try:
                ts = float(head)
                rec = json.loads(body)
                name, value = rec["name"], rec["value"]
            except (ValueError, KeyError, TypeError):
                bad += 1
                continue
            if "event" in rec:
                events += 1
            cols.setdefault(str(name), ([], []))
            cols[str(name)][0].append(ts)
            cols[str(name)][1].append(value)
    report.drop("OpenXC lines", "malformed JSON record", bad)
    if events:
        report.note(f"{events} OpenXC records carry an 'event' field (ignored)")
    if not cols:
        raise LogImportError(f"{path}: no OpenXC records")
    start = min(min(v[0]) for v in cols.values())
    out = {k: Signal(np.asarray(tt) - start, np.asarray(vv, dtype=object if any(isinstance(x, str) for x in vv)
                                                          else float), None)
           for k, (tt, vv) in cols.items()}
    return out, start


def load_openxc(source: str | Path, mapping: Mapping, *, progress: Progress | None = None) -> Trip:
    source = Path(source)
    report = ImportReport()
    signals, start = read_openxc_signals(source, report)
    meta = {"source": {"format": "openxc", "path": str(source), "bytes": source.stat().st_size}}
    return apply_mapping(signals, mapping, report, start_time=start, meta=meta, name=source.name.split(".")[0])


# ------------------------------------------------------------------------------------------ entry point
__all__ = ["load_can_log", "load_csv_log", "load_openxc", "read_csv_signals", "read_openxc_signals",
           "split_header", "CAN_LOG_FORMATS"]
