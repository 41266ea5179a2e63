"""Tables out: one Markdown writer and one CSV writer for every report roadload prints or writes."""

from __future__ import annotations

from pathlib import Path
from typing import Any, Sequence

import numpy as np
import pandas as pd

from .fileio import write_text

__all__ = ["format_number", "markdown_table", "write_csv"]


def format_number(value: Any, floatfmt: str | None = None, digits: int = 3) -> str:
    """One table cell: floats with ``floatfmt`` (e.g. ".4g") or ``digits`` significant decimals, ∞ and – for
    infinities and NaN; everything else as ``str``."""
    if isinstance(value, (float, np.floating)):
        x = float(value)
        if np.isnan(x):
            return "–"
        if np.isinf(x):
            return "∞" if x > 0 else "-∞"
        if floatfmt is not None:
            return format(x, floatfmt)
        if abs(x) >= 1e4 or (abs(x) < 1e-2 and x != 0):
            return f"{x:.{digits}g}"
        return f"{x:.{digits}f}".rstrip("0").rstrip(".")
    return str(value)


def markdown_table(frame: pd.DataFrame | None, columns: Sequence[str] | None = None, *, floatfmt: str | None = None,
                   digits: int = 3) -> str:
    """A GitHub-flavoured Markdown table of ``frame`` (all columns, or ``columns`` in that order)."""
    if frame is None or not len(frame):
        return "(no rows)"
    cols = list(frame.columns) if columns is None else list(columns)
    lines = ["| " + " | ".join(map(str, cols)) + " |", "|" + "|".join("---" for _ in cols) + "|"]
    for _, row in frame.iterrows():
        lines.append("| " + " | ".join(format_number(row[c], floatfmt, digits) for c in cols) + " |")
    return "\n".join(lines)


def write_csv(path: str | Path, frame: pd.DataFrame) -> Path:
    """Write ``frame`` as CSV (no index) atomically; returns the path."""
    path = Path(path)
    write_text(path, frame.to_csv(index=False))
    return path
