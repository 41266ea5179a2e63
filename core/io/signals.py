"""Source signals before mapping: each one a time series on its own clock, in the unit its source declares.

Every loader turns its file into a `SignalSet` (``{source name: Signal}``); the mapping layer
(`roadload.io.mapping`) turns that into a Trip. Nothing here converts units or renames anything.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .report import ImportReport, LogImportError

# Time may go backwards at most this often (fraction of samples) before the log is rejected instead of sorted.
MAX_BACKWARD_FRACTION = 0.01


@dataclass
class Signal:
    """One source signal: sample times t [s] (source clock), values, declared unit (None when undeclared)."""

    t: np.ndarray
    values: np.ndarray
    unit: str | None = None

    def __post_init__(self) -> None:
        self.t = np.asarray(self.t, dtype=float).reshape(-1)
        self.values = np.asarray(self.values).reshape(-1)
        if self.t.size != self.values.size:
            raise LogImportError(f"signal has {self.t.size} time stamps but {self.values.size} values")

    def __len__(self) -> int:
        return int(self.t.size)


SignalSet = dict[str, Signal]


def monotonic(name: str, sig: Signal, report: ImportReport) -> Signal:
    """The signal with strictly increasing time: NaN times dropped, rare backward steps sorted, repeated
    time stamps reduced to their last sample; each repair counted. Many backward steps -> LogImportError."""
    t, v = sig.t, sig.values
    bad_t = ~np.isfinite(t)
    if bad_t.any():
        report.drop(name, "time stamp NaN/inf", int(bad_t.sum()))
        t, v = t[~bad_t], v[~bad_t]
    if t.size < 2:
        return Signal(t, v, sig.unit)
    back = int(np.count_nonzero(np.diff(t) < 0))
    if back:
        if back > MAX_BACKWARD_FRACTION * t.size:
            i = int(np.flatnonzero(np.diff(t) < 0)[0])
            raise LogImportError(f"{name}: time is not monotonic: it goes backwards {back} times "
                                 f"(first at sample {i + 1}: {t[i]:.6g} s -> {t[i + 1]:.6g} s); "
                                 f"more than {MAX_BACKWARD_FRACTION:.0%} of samples, refusing to sort")
        order = np.argsort(t, kind="stable")
        t, v = t[order], v[order]
        report.repair(name, "out-of-order samples sorted by time", back)
    dup = np.diff(t) == 0
    if dup.any():
        keep = np.concatenate([~dup, [True]])  # keep the last sample of each repeated time stamp
        report.drop(name, "repeated time stamp (kept the last sample)", int(dup.sum()))
        t, v = t[keep], v[keep]
    return Signal(t, v, sig.unit)
