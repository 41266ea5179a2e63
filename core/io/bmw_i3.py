"""TUM BMW i3 trips: ';'-separated latin-1 CSV at 10 Hz (three column layouts) -> Trip, plus the trip's row of
``overview.csv`` (date, route, weather, temperatures, fan, notes) in ``meta["overview"]`` and the extra payload
parsed from notes such as "+70 kg" in ``meta["extra_payload_kg"]`` (None when the note names none).

The columns go through the ``bmw_i3`` mapping like any CSV log; rim torque and grade are derived steps of that
mapping (motor torque x gear ratio x efficiency from the ``bmw_i3`` vehicle preset; elevation smoothed over
distance). Known limits of the data (README of the data set): friction braking is not logged and regenerative
torque floors near -87 N m, elevation is quantised to 1 m, TripA04 has a frozen elevation (no grade derived).
"""

from __future__ import annotations

import math
import re
from pathlib import Path
from typing import Any

import pandas as pd

from ..trip import Trip
from .loaders import Progress, load_csv_log
from .mapping import Mapping
from .report import LogImportError

_PAYLOAD = re.compile(r"\+\s*(\d+(?:\.\d+)?)\s*kg", re.IGNORECASE)


def find_overview(trip_file: Path) -> Path | None:
    for folder in (trip_file.parent, trip_file.parent.parent):
        cand = folder / "overview.csv"
        if cand.is_file():
            return cand
    return None


def extra_payload_kg(note: Any) -> float | None:
    """Extra payload [kg] named in an overview note ('+70 kg', "'+70 kg\\"", '+60 kg '), else None."""
    if not isinstance(note, str):
        return None
    m = _PAYLOAD.search(note)
    return float(m.group(1)) if m else None


def overview_row(overview: Path, trip_name: str) -> dict[str, Any] | None:
    """The overview.csv row of one trip as a JSON-safe dict (NaN -> None, unnamed columns left out)."""
    try:
        df = pd.read_csv(overview, encoding="utf-8")
    except UnicodeDecodeError:
        df = pd.read_csv(overview, encoding="latin-1")
    if "Trip" not in df.columns:
        raise LogImportError(f"{overview}: no 'Trip' column; not the BMW i3 overview sheet")
    rows = df[df["Trip"].astype(str).str.strip() == trip_name]
    if rows.empty:
        return None
    row = rows.iloc[0]
    out = {}
    for k, v in row.items():
        if str(k).startswith("Unnamed"):
            continue
        if isinstance(v, float) and math.isnan(v):
            v = None
        elif hasattr(v, "item"):
            v = v.item()
        out[str(k).strip()] = v
    return out


def load_bmw_i3(source: str | Path, mapping: Mapping, *, progress: Progress | None = None) -> Trip:
    source = Path(source)
    meta: dict[str, Any] = {"vehicle": mapping.vehicle, "trip": source.stem}
    overview = find_overview(source)
    if overview is not None:
        row = overview_row(overview, source.stem)
        meta["overview"] = row
        meta["extra_payload_kg"] = extra_payload_kg(row.get("Note")) if row else None
        if row is None:
            meta["overview_note"] = f"{source.stem} not listed in {overview.name}"
    else:
        meta["overview"] = None
        meta["extra_payload_kg"] = None
    return load_csv_log(source, mapping, progress=progress, meta=meta)
