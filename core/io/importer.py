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
        from .mdf import load_mdf_log  # asammdf loads only for MDF4 files

        trip = load_mdf_log(source, None if mapping is None else
                            mapping if isinstance(mapping, Mapping) else load_mapping(mapping), progress=progress)
        if progress:
            progress("done", 1.0)
        return trip
    if mapping is None:
        if fmt not in DEFAULT_MAPPINGS:
            raise LogImportError(f"format {fmt!r} needs a mapping file (--mapping)")
        mapping = DEFAULT_MAPPINGS[fmt]
    m = mapping if isinstance(mapping, Mapping) else load_mapping(mapping)
    if fmt in CAN_LOG_FORMATS:
        trip = load_can_log(source, m, dbc=dbc, progress=progress, fmt=fmt)
    elif fmt == "csv":
        trip = load_csv_log(source, m, progress=progress)
    elif fmt == "bmw-i3":
        trip = load_bmw_i3(source, m, progress=progress)
    elif fmt == "openxc":
        trip = load_openxc(source, m, progress=progress)
    else:
        raise LogImportError(f"import format {fmt!r} has no loader")
    if strict:
        bad = [d for d in trip.meta["import_report"].get("dropped", []) if str(d["what"]).endswith(" lines")]
        if bad:
            raise LogImportError(f"{source}: strict import refused: " + "; ".join(
                f"{d['count']} x {d['reason']} ({d['detail']})" for d in bad))
    if m.derived:
        if progress:
            progress("derive", 0.9)
        trip = add_derived(trip, m.derived, ImportReport.from_dict(trip.meta["import_report"]), m.vehicle)
    if progress:
        progress("done", 1.0)
    return trip
