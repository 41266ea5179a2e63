"""Typed results of the diagnosis: every stage returns dataclasses, and :meth:`Record.to_dict` turns them into the
documented ``diagnosis.json`` schema (:mod:`.report`): field names are the JSON keys, a field marked
:func:`optional` is left out of the JSON while it is None (a key the schema only has in some cases)."""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np

from roadload.estimators.batch import mad_scale

_OMIT_NONE = "omit_when_none"


def optional(default: Any = None) -> Any:
    """A dataclass field that the JSON leaves out while it is None."""
    return dataclasses.field(default=default, metadata={_OMIT_NONE: True})


def plain(value: Any) -> Any:
    """Records, lists, dicts and objects with ``to_dict`` as plain JSON-ready values (numpy scalars stay; see
    :func:`jsonable`)."""
    if isinstance(value, Record):
        return value.to_dict()
    if hasattr(value, "to_dict") and not isinstance(value, type):
        return value.to_dict()
    if isinstance(value, dict):
        return {k: plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [plain(v) for v in value]
    return value


def jsonable(x: Any) -> Any:
    """A plain value with numpy scalars and arrays as Python numbers and lists, NaN/inf as None."""
    if isinstance(x, dict):
        return {str(k): jsonable(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [jsonable(v) for v in x]
    if isinstance(x, (np.floating, float)):
        return None if not np.isfinite(x) else float(x)
    if isinstance(x, (np.integer,)):
        return int(x)
    if isinstance(x, np.bool_):
        return bool(x)
    if isinstance(x, np.ndarray):
        return jsonable(x.tolist())
    return x


class Record:
    """Base of the typed results: :meth:`to_dict` gives the JSON object (see module doc)."""

    def to_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = {}
        for f in dataclasses.fields(self):  # type: ignore[arg-type]
            value = getattr(self, f.name)
            if value is None and f.metadata.get(_OMIT_NONE):
                continue
            out[f.name] = plain(value)
        return out


@dataclasses.dataclass
class RobustSummary(Record):
    """n, mean, median, MAD scale (1.483 med|r - med r|, eq. 3.14), MEDSE (med r²) and RMSE of a residual (N, or W
    on the energy side)."""

    n: int
    mean: float
    median: float
    mad: float
    medse: float
    rmse: float

    @classmethod
    def of(cls, residual: np.ndarray) -> "RobustSummary":
        r = np.asarray(residual, dtype=float)
        r = r[np.isfinite(r)]
        if r.size == 0:
            nan = float("nan")
            return cls(0, nan, nan, nan, nan, nan)
        return cls(int(r.size), float(np.mean(r)), float(np.median(r)), float(mad_scale(r)),
                   float(np.median(r ** 2)), float(np.sqrt(np.mean(r ** 2))))
