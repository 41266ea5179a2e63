"""ASAM MDF4 files of decoded signals -- what asammdf, INCA, CANape and ``roadload export --format mf4`` write: each
channel a named signal with its unit on its channel group's time base (``--format dbc-mf4`` is the other kind: raw
CAN frames decoded through a DBC).

``import_log(path, "mf4")`` reads such a file through a mapping (``"format": "mf4"``, sources = MDF channel names).
Without a mapping file, every signal named like a measured channel of the catalogue (roadload.channels) maps to it,
its unit converted to SI (signals named ``truth/...`` -- ground truth a roadload export may carry -- and names the
catalogue does not know are listed in ``meta["unmapped_signals"]``, not imported). A roadload export therefore
re-imports as the same measured channels, equal within their resolution (but for the importer's counted repairs, such
as small negative speeds clipped to 0).
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np

from ..channels import MEASURED
from ..trip import Trip
from .mapping import Mapping, apply_mapping, normalise_unit
from .report import ImportReport, LogImportError
from .signals import Signal, SignalSet

#: catalogue channels held between samples when resampled (discrete states), the others are interpolated
HOLD_CHANNELS = frozenset({"gear", "clutch", "regen_braking", "brake_pedal"})
#: the embedded attachment that carries a roadload trip's metadata through an MDF4 export
META_ATTACHMENT = "roadload_meta.json"


def read_mdf_signals(path: str | Path, report: ImportReport) -> tuple[SignalSet, dict[str, Any]]:
    """Every non-master channel of an MDF file as a Signal (name, time stamps [s], values, unit), and the file's
    start time (``t0_unix`` [s]) plus the roadload metadata attachment, if any."""
    from asammdf import MDF

    path = Path(path)
    if not path.is_file():
        raise LogImportError(f"no MDF file at {path}")
    try:
        mdf = MDF(path)
    except Exception as exc:  # asammdf raises several types for files it cannot parse
        raise LogImportError(f"{path}: not a readable MDF file ({type(exc).__name__}: {exc})") from None
    signals: SignalSet = {}
    try:
        for sig in mdf.iter_channels(skip_master=True):
            if sig.samples.dtype.kind not in "biuf" or sig.samples.ndim != 1:
                report.note(f"MDF channel {sig.name!r} skipped: not a 1-D numeric signal ({sig.samples.dtype})")
                continue
            if sig.name in signals:
                report.note(f"MDF channel {sig.name!r} appears in more than one channel group; the first is used")
                continue
            signals[sig.name] = Signal(np.asarray(sig.timestamps, dtype=float), np.asarray(sig.samples),
                                       sig.unit or None)
        info: dict[str, Any] = {"t0_unix": float(mdf.header.start_time.timestamp())}
        for index, attachment in enumerate(getattr(mdf, "attachments", [])):
            if Path(str(getattr(attachment, "file_name", ""))).name == META_ATTACHMENT:
                try:
                    data = mdf.extract_attachment(index)[0]
                    info["origin"] = json.loads(data if isinstance(data, str) else bytes(data).decode("utf-8"))
                except (ValueError, TypeError, IndexError):
                    report.note(f"MDF attachment {META_ATTACHMENT} is not readable JSON; ignored")
    finally:
        mdf.close()
    if not signals:
        raise LogImportError(f"{path}: no numeric signals in the MDF file")
    return signals, info


def catalogue_mapping(signals: SignalSet, report: ImportReport, sample_rate: float | None = None) -> Mapping:
    """The mapping an MDF4 file without a mapping file gets: each signal named like a measured catalogue channel
    maps to it with its declared unit, converted to SI (undeclared: the catalogue unit; a unit roadload does not
    know: the signal is left out, with a note)."""
    channels = []
    for name, sig in signals.items():
        if name not in MEASURED or name == "t":
            continue
        catalogue = MEASURED[name].unit
        unit = catalogue if sig.unit in (None, catalogue) else normalise_unit(sig.unit)
        if unit is None:
            report.note(f"MDF signal {name!r}: unit {sig.unit!r} is not one roadload converts; not imported")
            continue
        channels.append({"source": name, "channel": name, "unit": unit,
                         "resample": "hold" if name in HOLD_CHANNELS else "linear"})
    if not channels:
        raise LogImportError(f"no signal is named like a measured channel of roadload.channels (signals: "
                             f"{sorted(signals)[:20]}); give a mapping file with 'format': 'mf4'")
    return Mapping.from_dict({"name": "mf4_catalogue_names", "format": "mf4", "sample_rate": sample_rate,
                              "description": "MDF4 signals named like roadload channels", "channels": channels},
                             "mf4 catalogue mapping")


def load_mdf_log(source: str | Path, mapping: Mapping | None = None, *, progress=None) -> Trip:
    """An MDF4 file of decoded signals -> Trip (see the module docstring)."""
    report = ImportReport()
    if progress:
        progress("read", 0.0)
    signals, info = read_mdf_signals(source, report)
    if mapping is None:  # the signals it leaves out are listed in meta["unmapped_signals"]
        mapping = catalogue_mapping(signals, report)
    if progress:
        progress("map", 0.7)
    meta: dict[str, Any] = {"source": {"format": "mf4", "path": str(source), "bytes": Path(source).stat().st_size}}
    if "origin" in info:
        meta["origin"] = {k: info["origin"].get(k) for k in ("name", "source", "seed", "sample_rate")
                          if isinstance(info["origin"], dict) and k in info["origin"]}
    return apply_mapping(signals, mapping, report, start_time=info["t0_unix"], meta=meta, name=Path(source).stem)
