"""DBC databases (cantools) and vectorised decoding of CAN frames into signal time series.

cantools parses the DBC (signal layout, scale, offset, multiplexing); the bit extraction itself is done with
numpy on all frames of a message at once (frames up to 8 bytes), which is ~100x faster than decoding one
frame at a time. Frames longer than 8 bytes (CAN FD) and float signals fall back to cantools' own decoder.
`decode_frames` returns a `SignalSet` keyed ``"<message>.<signal>"`` with the source time of each frame.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, cast

import numpy as np

from .frames import CanFrames
from .report import ImportReport, LogImportError
from .signals import Signal, SignalSet

if TYPE_CHECKING:  # cantools is imported lazily (only when a DBC is loaded)
    from cantools.database.can import Message
    from cantools.database.can import Signal as CanSignal


@dataclass
class DbcSource:
    """One DBC file, optionally bound to one bus (frames on other buses are not decoded with it)."""

    path: Path
    bus: int | None = None


@dataclass
class Database:
    """Decoding tables: for each (bus or None, frame id, extended) the cantools message."""

    messages: dict[tuple[int | None, int, bool], Message] = field(default_factory=dict)
    files: list[str] = field(default_factory=list)

    def message_names(self) -> set[str]:
        return {m.name for m in self.messages.values()}

    def signal_names(self) -> set[str]:
        return {f"{m.name}.{s.name}" for m in self.messages.values() for s in m.signals}


def load_dbc(sources: list[DbcSource], report: ImportReport | None = None) -> Database:
    """Parse DBC files with cantools (non-strict: overlapping signals are allowed, as real DBCs have them)."""
    import cantools

    db = Database()
    for src in sources:
        path = Path(src.path)
        if not path.is_file():
            raise LogImportError(f"DBC file {path} does not exist")
        logger = logging.getLogger("cantools")
        level = logger.level
        logger.setLevel(logging.ERROR)  # duplicate message names are reported below, not printed
        try:
            parsed = cantools.database.load_file(str(path), database_format="dbc", strict=False)
        except Exception as exc:
            raise LogImportError(f"{path}: not a valid DBC file ({type(exc).__name__}: {exc})") from None
        finally:
            logger.setLevel(level)
        if not isinstance(parsed, cantools.database.can.Database):
            raise LogImportError(f"{path}: not a CAN DBC database (cantools parsed a {type(parsed).__name__})")
        names = [m.name for m in parsed.messages]
        dupes = sorted({n for n in names if names.count(n) > 1})
        if dupes and report is not None:
            report.note(f"{path.name}: message names defined under several frame ids: {dupes} "
                        f"(decoded by frame id; a log using more than one of them is an error)")
        for m in parsed.messages:
            db.messages[(src.bus, int(m.frame_id), bool(m.is_extended_frame))] = m
        db.files.append(str(path))
    return db


# ------------------------------------------------------------------------------------------ bit extraction
def _payload_words(data: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """First 8 payload bytes as little-endian and big-endian uint64 words."""
    d8 = np.zeros((data.shape[0], 8), dtype=np.uint8)
    w = min(8, data.shape[1])
    d8[:, :w] = data[:, :w]
    d8 = np.ascontiguousarray(d8)
    le = d8.view("<u8").reshape(-1)
    be = d8.view(">u8").reshape(-1).astype(np.uint64)
    return le.astype(np.uint64), be


def raw_values(signal, le: np.ndarray, be: np.ndarray) -> np.ndarray:
    """Unscaled integer values of one cantools signal from the payload words (vectorised)."""
    n = int(signal.length)
    mask = np.uint64((1 << n) - 1) if n < 64 else np.uint64(0xFFFFFFFFFFFFFFFF)
    if signal.byte_order == "little_endian":
        raw = (le >> np.uint64(signal.start)) & mask
    else:  # Motorola: DBC start bit is the MSB in sawtooth numbering
        msb = (7 - signal.start // 8) * 8 + signal.start % 8
        lsb = msb - (n - 1)
        if lsb < 0:
            raise LogImportError(f"signal {signal.name}: big-endian layout runs past the 8-byte payload")
        raw = (be >> np.uint64(lsb)) & mask
    if signal.is_signed:
        out = raw.astype(np.int64)
        if n < 64:
            out = np.where(out >= (1 << (n - 1)), out - (1 << n), out)
        return out
    return raw


def _signal_fits(signal: CanSignal, max_bytes: int) -> bool:
    if signal.byte_order == "little_endian":
        return signal.start + signal.length <= 8 * max_bytes
    msb = (7 - signal.start // 8) * 8 + signal.start % 8
    return msb - (signal.length - 1) >= 0 and signal.start // 8 < max_bytes


def _decode_message(message: Message, t: np.ndarray, data: np.ndarray, out: SignalSet, report: ImportReport) -> None:
    name = message.name
    if message.length > 8 or any(s.is_float for s in message.signals):
        _decode_message_slow(message, t, data, out, report)
        return
    le, be = _payload_words(data)
    valid: dict[str, np.ndarray] = {}  # rows where a signal is present (multiplexing)

    def rows_of(sig: CanSignal) -> np.ndarray:
        if sig.name in valid:
            return valid[sig.name]
        rows = np.ones(t.size, dtype=bool)
        if sig.multiplexer_ids is not None and sig.multiplexer_signal is not None:
            mux = message.get_signal_by_name(sig.multiplexer_signal)
            rows = rows_of(mux) & np.isin(raw_values(mux, le, be), np.asarray(sig.multiplexer_ids, dtype=np.uint64))
        valid[sig.name] = rows
        return rows

    for sig in message.signals:
        rows = rows_of(sig)
        if not rows.any():
            continue
        raw = raw_values(sig, le[rows], be[rows])
        values = raw.astype(float) * float(sig.scale) + float(sig.offset)
        key = f"{name}.{sig.name}"
        if key in out:
            raise LogImportError(f"message name {name!r} is used by several frame ids present in the log; "
                                 f"bind each DBC to its bus or remove the duplicate definitions")
        out[key] = Signal(t[rows], values, sig.unit or None)


def _decode_message_slow(message: Message, t: np.ndarray, data: np.ndarray, out: SignalSet,
                         report: ImportReport) -> None:
    cols: dict[str, tuple[list, list]] = {}
    bad = 0
    for i in range(t.size):
        try:
            # decode_containers=False and decode_choices=False: a plain dict of scaled numbers (cantools' return
            # type also covers container messages and choice names, which these flags rule out)
            decoded = cast("dict[str, float]", message.decode(bytes(data[i, : message.length]),
                                                              decode_choices=False, scaling=True))
        except Exception:
            bad += 1
            continue
        for k, v in decoded.items():
            cols.setdefault(k, ([], []))
            cols[k][0].append(t[i])
            cols[k][1].append(float(v))
    report.drop(message.name, "frame not decodable by cantools", bad)
    for k, (tt, vv) in cols.items():
        sig = message.get_signal_by_name(k)
        out[f"{message.name}.{k}"] = Signal(np.asarray(tt), np.asarray(vv), sig.unit or None)


def decode_frames(frames: CanFrames, db: Database, report: ImportReport,
                  wanted_messages: set[str] | None = None) -> SignalSet:
    """Decode all frames whose (bus, id) the database knows; undecoded ids are counted in the report.

    wanted_messages: decode only these message names (others are counted as 'not mapped'); None = all.
    """
    out: SignalSet = {}
    handled = np.zeros(len(frames), dtype=bool)
    # group frames by (bus, id, extended) once
    key = (frames.bus.astype(np.int64) << 32) | frames.arbitration_id.astype(np.int64)
    key = key * 2 + frames.is_extended.astype(np.int64)
    uniq, inverse = np.unique(key, return_inverse=True)
    for u_idx, u in enumerate(uniq):
        ext = bool(u & 1)
        fid = int((u >> 1) & 0xFFFFFFFF)
        bus = int(u >> 33)
        msg = db.messages.get((bus, fid, ext))
        if msg is None:  # DBCs bound to no bus apply to every bus
            msg = db.messages.get((None, fid, ext))
        if msg is None:
            continue
        rows = np.flatnonzero(inverse == u_idx)
        handled[rows] = True
        if wanted_messages is not None and msg.name not in wanted_messages:
            continue
        short = frames.length[rows] < msg.length
        if short.any():
            fits = [s for s in msg.signals if _signal_fits(s, int(frames.length[rows][short].min()))]
            report.drop(msg.name, f"frames shorter than the DBC length {msg.length} B", int(short.sum()),
                        f"id 0x{fid:X} bus {bus}; {len(msg.signals) - len(fits)} signals affected")
            rows = rows[~short]
        if rows.size:
            _decode_message(msg, frames.t[rows], frames.data[rows], out, report)
    if (~handled).any():
        ids, counts = np.unique(frames.arbitration_id[~handled], return_counts=True)
        detail = ", ".join(f"0x{int(i):X}: {int(c)}" for i, c in zip(ids[:12], counts[:12]))
        report.drop("CAN frames", "id not in the DBC", int((~handled).sum()), detail)
    return out


def find_dbc(name: str, roots: list[Path]) -> Path:
    """Find a DBC by file name in the given folders (each and up to two parents), then in the package."""
    p = Path(name)
    if p.is_absolute():
        if p.is_file():
            return p
        raise LogImportError(f"DBC file {p} does not exist")
    tried = []
    for root in roots:
        root = Path(root)
        if root.is_file():
            root = root.parent
        for folder in [root, *list(root.parents)[:2]]:
            cand = folder / p
            tried.append(str(cand))
            if cand.is_file():
                return cand
    cand = Path(__file__).parent / "dbc" / p
    tried.append(str(cand))
    if cand.is_file():
        return cand
    raise LogImportError(f"DBC file {name!r} not found; looked in {tried}")


__all__ = ["Database", "DbcSource", "decode_frames", "find_dbc", "load_dbc", "raw_values"]
