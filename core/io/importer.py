"""``import_log``: the single entry point of the importers (CLI ``roadload import``): read -> mapping -> derived
channels -> Trip with ``meta["import_report"]`` listing every repair and drop."""

from __future__ import annotations

from pathlib import Path
from typing import Sequence

from ..registry import did_you_mean
from ..trip import Trip
from .bmw_i3 import load_bmw_i3
from .derived import add_derived
from .loaders import CAN_LOG_FORMATS, DEFAULT_MAPPINGS, Progress, load_can_log, load_csv_log, load_openxc
from .mapping import FORMATS, Mapping, load_mapping
from .report import ImportReport, LogImportError

__all__ = ["import_log"]


def import_log(source: str | Path, fmt: str, mapping: str | Path | Mapping | None = None, *,
               dbc: Sequence[str | Path] = (), progress: Progress | None = None, strict: bool = False) -> Trip:
    """Import a log of the given format through a mapping (file, packaged name, or default for the format).

    Malformed lines of text logs (candump, ASC, CSV) are left out and reported with their line numbers in
    ``meta["import_report"]``; ``strict=True`` makes any malformed line an error instead. Format 'mf4' (decoded
    MDF4 signals, :mod:`roadload.io.mdf`) needs no mapping when its signals carry the catalogue's names."""
    if fmt not in FORMATS:
        raise LogImportError(f"unknown import format {fmt!r}{did_you_mean(fmt, FORMATS)}; choose one of "
                             f"{list(FORMATS)}")
    if fmt == "mf4":
        trip = _import_mf4(source, mapping, progress)
    else:
        m = _mapping_for(fmt, mapping)
        trip = _load(source, fmt, m, dbc, progress)
        if strict:
            _refuse_malformed_lines(source, trip)
        if m.derived:
            if progress:
                progress("derive", 0.9)
            trip = add_derived(trip, m.derived, ImportReport.from_dict(trip.meta["import_report"]), m.vehicle)
    if progress:
        progress("done", 1.0)
    return trip


def _import_mf4(source: str | Path, mapping: str | Path | Mapping | None, progress: Progress | None) -> Trip:
    """Decoded MDF4 signals (a mapping only where the signals lack the catalogue's names)."""
    from .mdf import load_mdf_log  # asammdf loads only for MDF4 files

    return load_mdf_log(source, None if mapping is None else
                        mapping if isinstance(mapping, Mapping) else load_mapping(mapping), progress=progress)


def _mapping_for(fmt: str, mapping: str | Path | Mapping | None) -> Mapping:
    """The given mapping (object, file or packaged name), else the format's default one."""
    if mapping is None:
        if fmt not in DEFAULT_MAPPINGS:
            raise LogImportError(f"format {fmt!r} needs a mapping file (--mapping)")
        mapping = DEFAULT_MAPPINGS[fmt]
    return mapping if isinstance(mapping, Mapping) else load_mapping(mapping)


def _load(source: str | Path, fmt: str, m: Mapping, dbc: Sequence[str | Path], progress: Progress | None) -> Trip:
    """The format's loader."""
    if fmt in CAN_LOG_FORMATS:
        return load_can_log(source, m, dbc=dbc, progress=progress, fmt=fmt)
    if fmt == "csv":
        return load_csv_log(source, m, progress=progress)
    if fmt == "bmw-i3":
        return load_bmw_i3(source, m, progress=progress)
    if fmt == "openxc":
        return load_openxc(source, m, progress=progress)
    raise LogImportError(f"import format {fmt!r} has no loader")


def _refuse_malformed_lines(source: str | Path, trip: Trip) -> None:
    """Strict import: any malformed line the loader left out is an error."""
    bad = [d for d in trip.meta["import_report"].get("dropped", []) if str(d["what"]).endswith(" lines")]
    if bad:
        raise LogImportError(f"{source}: strict import refused: " + "; ".join(
            f"{d['count']} x {d['reason']} ({d['detail']})" for d in bad))
