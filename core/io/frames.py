"""Raw CAN frames as arrays, read from and written to bus-log files.

One container (`CanFrames`, column arrays, one row per frame) is what every CAN log reader returns and every
writer takes, so decoding (`roadload.io.dbc`) never cares where the frames came from:

- ASAM MDF4 bus logs (CANedge, python-can's MF4Writer): read column-wise with asammdf (fast path);
- candump ``.log``, Vector ``.asc`` and ``.blf``: read with python-can's readers (one message at a time);
- comma2k19 ``processed_log/CAN/raw_can`` numpy arrays (``t``, ``address``, ``src``, ``data``).

Time: ``t`` [s] is relative to ``start_time`` (unix seconds of the logger clock), so absolute logger time is
``start_time + t``. Bus numbers are integers (candump ``can1`` <-> 1).
"""

from __future__ import annotations

import os
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Iterable

import numpy as np

from .report import ImportReport, LogImportError
from ..fileio import atomic_path

CAN_FORMATS = ("candump", "blf", "asc", "mf4")
_SUFFIX = {"candump": ".log", "blf": ".blf", "asc": ".asc", "mf4": ".mf4"}


@dataclass
class CanFrames:
    """CAN (FD) data frames as columns: t [s] since start_time, bus, arbitration_id, is_extended, length [bytes],
    data (uint8, shape (n, width), zero-padded beyond length)."""

    t: np.ndarray
    bus: np.ndarray
    arbitration_id: np.ndarray
    is_extended: np.ndarray
    length: np.ndarray
    data: np.ndarray
    start_time: float = 0.0

    def __post_init__(self) -> None:
        self.t = np.asarray(self.t, dtype=float)
        n = self.t.size
        self.bus = np.asarray(self.bus, dtype=np.int64).reshape(-1)
        self.arbitration_id = np.asarray(self.arbitration_id, dtype=np.uint32).reshape(-1)
        self.is_extended = np.asarray(self.is_extended, dtype=bool).reshape(-1)
        self.length = np.asarray(self.length, dtype=np.int64).reshape(-1)
        self.data = np.asarray(self.data, dtype=np.uint8)
        if self.data.ndim != 2:
            raise LogImportError(f"CAN frame data must be a 2-D byte array, got shape {self.data.shape}")
        for name in ("bus", "arbitration_id", "is_extended", "length"):
            if getattr(self, name).size != n:
                raise LogImportError(f"CAN frames: column {name!r} has {getattr(self, name).size} rows, t has {n}")
        if self.data.shape[0] != n:
            raise LogImportError(f"CAN frames: data has {self.data.shape[0]} rows, t has {n}")
        if n and (self.length.max() > self.data.shape[1] or self.length.min() < 0):
            raise LogImportError("CAN frames: a frame length exceeds the data width")

    def __len__(self) -> int:
        return int(self.t.size)

    @property
    def nbytes(self) -> int:
        return int(sum(a.nbytes for a in (self.t, self.bus, self.arbitration_id, self.is_extended, self.length,
                                          self.data)))

    def select(self, mask: np.ndarray) -> "CanFrames":
        return CanFrames(self.t[mask], self.bus[mask], self.arbitration_id[mask], self.is_extended[mask],
                         self.length[mask], self.data[mask], self.start_time)

    def sorted(self) -> "CanFrames":
        """Frames in time order (stable; logs from several files or buses may interleave)."""
        order = np.argsort(self.t, kind="stable")
        return self.select(order)

    @staticmethod
    def concat(parts: list["CanFrames"]) -> "CanFrames":
        """Concatenate frame sets; times are re-referenced to the earliest start_time."""
        if not parts:
            raise LogImportError("no CAN frames to concatenate")
        start = min(p.start_time for p in parts)
        width = max(p.data.shape[1] for p in parts)
        data = [np.pad(p.data, ((0, 0), (0, width - p.data.shape[1]))) for p in parts]
        return CanFrames(np.concatenate([p.t + (p.start_time - start) for p in parts]),
                         np.concatenate([p.bus for p in parts]), np.concatenate([p.arbitration_id for p in parts]),
                         np.concatenate([p.is_extended for p in parts]), np.concatenate([p.length for p in parts]),
                         np.concatenate(data), start)


# ----------------------------------------------------------------------------------------------- readers
def _mf4_files(source: str | os.PathLike | Iterable) -> list[Path]:
    if isinstance(source, (str, os.PathLike)):
        path = Path(source)
        if path.is_dir():
            files = sorted(p for p in path.iterdir() if p.suffix.lower() == ".mf4")
            if not files:
                raise LogImportError(f"{path}: folder contains no .MF4 files")
            return files
        return [path]
    return [Path(p) for p in source]


def read_mf4(source: str | os.PathLike | Iterable, progress: Callable[[int, int], None] | None = None) -> CanFrames:
    """CAN data frames of one MDF4 bus log, or of all .MF4 files of a folder (a logger session split in parts).

    Reads the ASAM bus-logging channels CAN_DataFrame.{BusChannel,ID,IDE,DataLength,DataBytes} column-wise.
    A truncated or non-MDF file raises LogImportError naming the file.
    """
    from asammdf import MDF  # heavy import, only when needed

    files = _mf4_files(source)
    parts = []
    for k, path in enumerate(files):
        if not path.is_file():
            raise LogImportError(f"{path}: no such MDF4 file")
        parts.append(_read_one_mf4(path, MDF))
        if progress is not None:
            progress(k + 1, len(files))
    return CanFrames.concat(parts).sorted()


def _block_header(fh, addr: int, size: int, what: str, path: Path) -> tuple[bytes, int, list[int]]:
    """(id, length, links) of the MDF4 block at addr; LogImportError when it lies beyond the end of the file."""
    if addr + 24 > size:
        raise LogImportError(f"{path}: MDF4 file truncated: {what} block at byte {addr} lies beyond the end "
                             f"of the file ({size} bytes)")
    fh.seek(addr)
    head = fh.read(24)
    block_id, length, n_links = head[:4], int.from_bytes(head[8:16], "little"), int.from_bytes(head[16:24], "little")
    if not block_id.startswith(b"##"):
        raise LogImportError(f"{path}: MDF4 file corrupt: no block header at byte {addr} ({what})")
    if addr + length > size:
        raise LogImportError(f"{path}: MDF4 file truncated: {what} block {block_id.decode(errors='replace')} at "
                             f"byte {addr} needs {length} bytes, the file ends {size - addr} bytes later")
    links = [int.from_bytes(fh.read(8), "little") for _ in range(min(n_links, 16))]
    return block_id, length, links


def check_mdf4_structure(path: Path) -> None:
    """Cheap structural check before asammdf parses the file: identification block, header block, and every
    data group's channel group and data block (DT/DZ/DL/HL) must lie inside the file. A file cut short by a
    failed copy or an unplugged logger fails here with a message naming the truncated block."""
    size = path.stat().st_size
    with open(path, "rb") as fh:
        ident = fh.read(64)
        if ident.startswith(b"UnFinMF "):
            return  # unfinalised logger files: leave the recovery to asammdf
        if not ident.startswith(b"MDF     "):
            raise LogImportError(f"{path}: not an MDF file (bad identification block)")
        if not ident[8:12].startswith(b"4"):
            raise LogImportError(f"{path}: MDF version {ident[8:16].decode(errors='replace').strip()} is not MDF4")
        _, _, hd_links = _block_header(fh, 64, size, "header (HD)", path)
        dg, seen = hd_links[0] if hd_links else 0, 0
        while dg and seen < 10_000:
            _, _, dg_links = _block_header(fh, dg, size, "data group (DG)", path)
            if len(dg_links) >= 3:
                if dg_links[1]:
                    _block_header(fh, dg_links[1], size, "channel group (CG)", path)
                if dg_links[2]:
                    _block_header(fh, dg_links[2], size, "data", path)
            dg = dg_links[0] if dg_links else 0
            seen += 1


def _read_one_mf4(path: Path, MDF) -> CanFrames:
    size = path.stat().st_size
    check_mdf4_structure(path)
    try:
        mdf = MDF(path)
    except Exception as exc:  # asammdf raises many types for corrupt files
        raise LogImportError(f"{path}: unreadable MDF4 file, truncated or corrupt ({size} bytes; "
                             f"{type(exc).__name__}: {exc})") from None
    try:
        group = None
        for i, g in enumerate(mdf.groups):
            names = {c.name for c in g.channels}
            if "CAN_DataFrame.ID" in names and "CAN_DataFrame.DataBytes" in names:
                group = i
                break
        if group is None:
            raise LogImportError(f"{path}: MDF4 file has no CAN_DataFrame channel group (not a CAN bus log)")
        columns = ["CAN_DataFrame.BusChannel", "CAN_DataFrame.ID", "CAN_DataFrame.IDE", "CAN_DataFrame.DataLength",
                   "CAN_DataFrame.DataBytes"]
        try:
            sigs = mdf.select([(n, group, None) for n in columns])
        except Exception as exc:
            raise LogImportError(f"{path}: MDF4 CAN channels unreadable, file truncated or corrupt "
                                 f"({type(exc).__name__}: {exc})") from None
        expected = mdf.groups[group].channel_group.cycles_nr
        n = len(sigs[1].samples)
        if n != expected:
            raise LogImportError(f"{path}: MDF4 data truncated: channel group declares {expected} frames, "
                                 f"{n} readable (file size {size} bytes)")
        start = mdf.start_time.timestamp()
        raw = sigs[4].samples
        if raw.dtype == object:  # variable-length (CAN FD) payloads
            width = max((len(b) for b in raw), default=8)
            data = np.zeros((len(raw), max(width, 8)), dtype=np.uint8)
            for i, b in enumerate(raw):
                data[i, : len(b)] = np.frombuffer(bytes(b), dtype=np.uint8)
        else:
            data = np.asarray(raw, dtype=np.uint8).reshape(n, -1)
        ident = np.asarray(sigs[1].samples, dtype=np.uint32)
        return CanFrames(sigs[1].timestamps, sigs[0].samples, ident & 0x1FFFFFFF, sigs[2].samples,
                         np.minimum(sigs[3].samples, data.shape[1]), data, start)
    finally:
        mdf.close()


def _bus_number(channel) -> int:
    if channel is None:
        return 0
    if isinstance(channel, (int, np.integer)):
        return int(channel)
    m = re.search(r"(\d+)$", str(channel))
    return int(m.group(1)) if m else 0


# a candump line: (time) interface id#data | id#R | id##<flags><data> (CAN FD)
_CANDUMP_LINE = re.compile(r"^\(\s*\d+(?:\.\d+)?\s*\)\s+\S+\s+[0-9A-Fa-f]{1,8}"
                           r"(?:#(?:R\d?|(?:[0-9A-Fa-f]{2})*)|##[0-9A-Fa-f](?:[0-9A-Fa-f]{2})*)(?:\s+[RT])?\s*$")
# an ASC line that starts like a classic CAN frame: time channel id Rx|Tx d|r ...
_ASC_FRAME = re.compile(r"^\s*\d+\.\d+\s+\d+\s+\S+\s+(?:Rx|Tx)\s+[dDrR]\b")
_ASC_DATA = re.compile(r"^\s*\d+\.\d+\s+\d+\s+[0-9A-Fa-f]{1,8}x?\s+(?:Rx|Tx)\s+"
                       r"(?:[rR]\b.*|[dD]\s+([0-9A-Fa-f])((?:\s+[0-9A-Fa-f]{2})*)(?:\s+[A-Za-z].*)?)\s*$")
_ASC_TIMED = re.compile(r"^\s*\d+\.\d+\s")
_ASC_TIMESTAMP_LIKE = re.compile(r"^\s*[0-9.]+[^0-9.\s]")


#: ASC lines without a time stamp that belong to the format (header, trigger blocks, comments)
_ASC_HEADER_PREFIXES = ("date", "base", "internal events", "no internal events", "begin triggerblock",
                        "end triggerblock", "//", "version", "start of measurement")


def _asc_line_ok(line: str) -> bool:
    if _ASC_TIMESTAMP_LIKE.match(line):
        return False  # a mangled time stamp, e.g. '0.0x5 1 123 ...'
    if not _ASC_TIMED.match(line):
        return line.strip().lower().startswith(_ASC_HEADER_PREFIXES)  # free text is no ASC line
    if not _ASC_FRAME.match(line):
        return True  # events, error frames, CAN FD lines: left to python-can
    m = _ASC_DATA.match(line)
    if m is None:
        return False
    if m.group(1) is None:  # remote frame
        return True
    dlc = int(m.group(1), 16)
    return len(m.group(2).split()) == min(dlc, 8)


def screen_log_lines(path: Path, fmt: str) -> tuple[str, list[int]]:
    """Text of a candump/ASC log without its malformed lines, and the 1-based numbers of the lines left out.
    A candump line must read ``(time) iface id#hexdata``; an ASC frame line needs as many data bytes as its DLC."""
    try:
        text = path.read_text(encoding="utf-8", errors="replace")
    except OSError as exc:
        raise LogImportError(f"{path}: unreadable CAN log ({exc.strerror})") from None
    keep, bad = [], []
    for lineno, line in enumerate(text.splitlines(), 1):
        if not line.strip():
            continue
        ok = _CANDUMP_LINE.match(line) is not None if fmt == "candump" else _asc_line_ok(line)
        if ok:
            keep.append(line)
        else:
            bad.append(lineno)
    return "\n".join(keep) + "\n", bad


def describe_lines(numbers: list[int], limit: int = 10) -> str:
    """'lines 3, 7, 12' (the first `limit`, then '... (n more)')."""
    head = ", ".join(str(n) for n in numbers[:limit])
    more = f" ... ({len(numbers) - limit} more)" if len(numbers) > limit else ""
    return f"line{'s' if len(numbers) > 1 else ''} {head}{more}"


def read_python_can(path: str | os.PathLike, report: ImportReport | None = None) -> CanFrames:
    """Frames of a candump .log, .asc, .blf (or any python-can readable) log. Remote/error frames are skipped.

    Text logs (candump, ASC) are screened line by line first: malformed lines are left out and counted in
    ``report`` with their line numbers (without a report, any malformed line is an error)."""
    import io

    import can

    path = Path(path)
    if not path.is_file():
        raise LogImportError(f"{path}: no such CAN log file")
    suffix = path.suffix.lower()
    text_fmt = "candump" if suffix == ".log" else "asc" if suffix == ".asc" else None
    source: Any = str(path)
    if text_fmt is not None:
        text, bad = screen_log_lines(path, text_fmt)
        if bad:
            if report is None:
                raise LogImportError(f"{path}: {len(bad)} malformed {text_fmt} {describe_lines(bad)}")
            report.drop(f"{path.name} lines", f"malformed {text_fmt} line", len(bad), describe_lines(bad))
        source = io.StringIO(text)
    t, bus, ident, ext, length, rows = [], [], [], [], [], []
    try:
        reader = (can.CanutilsLogReader(source) if text_fmt == "candump" else can.ASCReader(source)
                  if text_fmt == "asc" else can.LogReader(source))
        for msg in reader:
            if msg.is_error_frame or msg.is_remote_frame:
                continue
            t.append(msg.timestamp)
            bus.append(_bus_number(msg.channel))
            ident.append(msg.arbitration_id)
            ext.append(msg.is_extended_id)
            length.append(len(msg.data))
            rows.append(bytes(msg.data))
    except (ValueError, KeyError, IndexError, OSError, EOFError) as exc:
        raise LogImportError(f"{path}: unreadable CAN log ({type(exc).__name__}: {exc})") from None
    except Exception as exc:  # python-can readers raise their own parse errors
        raise LogImportError(f"{path}: unreadable CAN log ({type(exc).__name__}: {exc})") from None
    if not t:
        raise LogImportError(f"{path}: CAN log contains no data frames")
    width = max(8, max(length))
    data = np.zeros((len(rows), width), dtype=np.uint8)
    for i, b in enumerate(rows):
        data[i, : len(b)] = np.frombuffer(b, dtype=np.uint8)
    times = np.asarray(t, dtype=float)
    start = float(times[0])
    return CanFrames(times - start, np.asarray(bus), np.asarray(ident), np.asarray(ext), np.asarray(length), data,
                     start)


def read_comma2k19(folder: str | os.PathLike) -> CanFrames:
    """Frames of comma2k19's ``processed_log/CAN/raw_can`` arrays (t [s boot time], address, src bus, data)."""
    folder = Path(folder)
    if (folder / "processed_log").is_dir():
        folder = folder / "processed_log" / "CAN" / "raw_can"
    arrays = {}
    for name in ("t", "address", "src", "data"):
        p = folder / name
        if not p.is_file():
            raise LogImportError(f"{folder}: comma2k19 raw_can array {name!r} missing")
        try:
            arrays[name] = np.load(p, allow_pickle=False)
        except Exception as exc:
            raise LogImportError(f"{p}: unreadable numpy array ({type(exc).__name__}: {exc})") from None
    raw = arrays["data"]
    if raw.dtype.kind != "S":
        raise LogImportError(f"{folder}/data: expected fixed-width bytes, got dtype {raw.dtype}")
    width = max(8, raw.dtype.itemsize)
    buf = np.frombuffer(raw.astype(f"S{width}").tobytes(), dtype=np.uint8).reshape(-1, width)
    # numpy 'S' strips trailing NUL bytes: the true length is unknown, take the DBC length when decoding
    length = np.full(raw.size, width, dtype=np.int64)
    t = np.asarray(arrays["t"], dtype=float)
    ident = np.asarray(arrays["address"], dtype=np.int64)
    return CanFrames(t - t[0], arrays["src"], ident & 0x1FFFFFFF, ident > 0x7FF, length, buf, float(t[0])).sorted()


def read_can_log(path: str | os.PathLike, progress: Callable[[int, int], None] | None = None) -> CanFrames:
    """Dispatch on the file type: MF4 (file or folder of parts), comma2k19 raw_can folder, or python-can logs."""
    path = Path(path)
    if path.is_dir():
        if (path / "address").is_file() or (path / "processed_log").is_dir():
            return read_comma2k19(path)
        return read_mf4(path, progress)
    if path.suffix.lower() == ".mf4":
        return read_mf4(path, progress)
    return read_python_can(path)


# ----------------------------------------------------------------------------------------------- writers
def write_can_log(frames: CanFrames, path: str | os.PathLike, fmt: str | None = None) -> Path:
    """Write frames as candump .log, .blf, .asc or .mf4 (python-can writers), atomically (temp file + rename)."""
    import can

    path = Path(path)
    fmt = fmt or {v: k for k, v in _SUFFIX.items()}.get(path.suffix.lower())
    if fmt not in _SUFFIX:
        raise LogImportError(f"unknown CAN log format {fmt!r} for {path.name}; choose one of {list(CAN_FORMATS)}")
    if path.suffix.lower() != _SUFFIX[fmt]:
        raise LogImportError(f"{path.name}: a {fmt} log must end in {_SUFFIX[fmt]}")
    writer_cls = {"candump": can.CanutilsLogWriter, "blf": can.BLFWriter, "asc": can.ASCWriter,
                  "mf4": can.MF4Writer}[fmt]
    with atomic_path(path) as tmp:
        writer = writer_cls(str(tmp))
        t_abs = frames.start_time + frames.t
        fd_frames = frames.length > 8
        for i in range(len(frames)):
            n = int(frames.length[i])
            channel = f"can{int(frames.bus[i])}" if fmt == "candump" else int(frames.bus[i])
            writer.on_message_received(can.Message(
                timestamp=float(t_abs[i]), arbitration_id=int(frames.arbitration_id[i]),
                is_extended_id=bool(frames.is_extended[i]), data=frames.data[i, :n].tobytes(), channel=channel,
                is_fd=bool(fd_frames[i]), is_rx=True))
        writer.stop()
    return path
