"""Resampling a signal of any rate onto the Trip's uniform time base. One rule per channel, named in the mapping:

- ``linear``: linear interpolation between the two neighbouring samples. For continuous physical quantities
  sampled faster or slower than the time base (speeds, altitude, torque). Slow signals (1 Hz GNSS on a 100 Hz
  base) become piecewise linear, so derivatives of them are piecewise constant — smooth before differentiating.
- ``hold``: zero-order hold, the last sample at or before the time (what a controller reading the bus sees).
  For states and slowly polled values (gear, flags, OBD-II PIDs answered every ~0.5 s) where inventing
  intermediate values would be wrong.
- ``nearest``: the sample closest in time. For values that must stay members of the source set but should not
  lag by up to a period (e.g. quantised counters compared sample by sample).

``circular=True`` (headings) unwraps the angle before interpolating and wraps the result into [0, period).
Times outside the signal's own span get NaN (no extrapolation); with ``hold`` the last sample stays valid for
one median sample interval after it (until the next periodic value would have arrived).
"""

from __future__ import annotations

import numpy as np

from .report import LogImportError

RULES = ("linear", "hold", "nearest")
# samples this close to a time-base instant count as at that instant (hold): CAN log time stamps are rounded
# to 1 us (candump) and absolute unix seconds in float64 carry ~0.2 us of rounding
TIME_TOLERANCE = 1e-6


def uniform_time_base(t_start: float, t_end: float, rate: float) -> np.ndarray:
    """Times t_start, t_start + 1/rate, ... <= t_end [s] (computed by index, no accumulated rounding)."""
    if not (rate > 0 and np.isfinite(rate)):
        raise LogImportError(f"sample rate must be positive and finite, got {rate}")
    if not t_end > t_start:
        raise LogImportError(f"empty time span: start {t_start:.6g} s, end {t_end:.6g} s")
    n = int(np.floor((t_end - t_start) * rate + 1e-9)) + 1
    return t_start + np.arange(n) / rate


def resample(t: np.ndarray, values: np.ndarray, t_new: np.ndarray, rule: str, circular: bool = False,
             period: float = 2 * np.pi) -> np.ndarray:
    """Values of the signal (t strictly increasing, finite values) at times t_new by the given rule."""
    if rule not in RULES:
        raise LogImportError(f"unknown resample rule {rule!r}; choose one of {list(RULES)}")
    t = np.asarray(t, dtype=float)
    x = np.asarray(values, dtype=float)
    t_new = np.asarray(t_new, dtype=float)
    if t.size == 0:
        return np.full(t_new.shape, np.nan)
    if circular:
        x = np.unwrap(x, period=period)
    if t.size == 1:
        out = np.where(np.isclose(t_new, t[0]), x[0], np.nan)
    elif rule == "linear":
        out = np.interp(t_new, t, x)
    elif rule == "hold":
        idx = np.searchsorted(t, t_new + TIME_TOLERANCE, side="right") - 1
        out = x[np.clip(idx, 0, t.size - 1)]
    else:  # nearest
        idx = np.clip(np.searchsorted(t, t_new), 1, t.size - 1)
        left_closer = (t_new - t[idx - 1]) <= (t[idx] - t_new)
        out = x[np.where(left_closer, idx - 1, idx)]
    out = np.asarray(out, dtype=float)
    end = t[-1]
    if rule == "hold" and t.size > 1:  # the last value of a periodic signal is valid until the next one is due
        end = t[-1] + float(np.median(np.diff(t)))
    # a time-base instant within TIME_TOLERANCE of the span is inside it: t_start + k / rate may land a rounding
    # error past the last sample it was computed to reach
    out[(t_new < t[0] - TIME_TOLERANCE) | (t_new > end + TIME_TOLERANCE)] = np.nan
    if circular:
        out = np.mod(out, period)
    return out
