"""Where the gap lies: a residual binned by driving regime, with robust statistics and a significance test per
bin, and the residual analysis of eq. 3.4a/3.4b.

A :class:`Regime` names one column of the diagnosis table (see :mod:`roadload.sim2real.table`) and its bins
(edges in SI, labels for people in km/h, %, °C, min). Per bin :func:`bin_statistics` gives n, the number of
independent blocks, median / MAD / MEDSE, a block-bootstrap 95 % interval of the median with its p-value and
McGill's notch (counted over blocks); a bin *departs* when the bootstrap interval excludes 0 and the notch does
too. Users add regimes with :func:`register_regime`.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Sequence

import numpy as np
import pandas as pd

from roadload.estimators.metrics import residual_correlation as _residual_correlation
from roadload.registry import Registry
from roadload.units import KELVIN

from .errors import DiagnosisError
from .records import Record, RobustSummary
from .stats import block_bootstrap_median, notch_interval


@dataclass(frozen=True)
class Regime:
    """One regime variable: ``column`` of the diagnosis table, numeric ``edges`` (SI, len = bins + 1, ±inf
    allowed) or ``categories`` (values of a categorical column), and ``labels`` for reports."""

    name: str
    column: str
    edges: tuple[float, ...] = ()
    categories: tuple = ()
    labels: tuple[str, ...] = ()
    absolute: bool = False
    description: str = ""

    def __post_init__(self) -> None:
        if bool(self.edges) == bool(self.categories):
            raise DiagnosisError(f"regime {self.name!r}: give either numeric edges or categories")
        n = len(self.edges) - 1 if self.edges else len(self.categories)
        if self.edges and (n < 1 or np.any(np.diff(self.edges) <= 0)):
            raise DiagnosisError(f"regime {self.name!r}: edges must be increasing with at least two entries")
        if self.labels and len(self.labels) != n:
            raise DiagnosisError(f"regime {self.name!r}: {len(self.labels)} labels for {n} bins")

    @property
    def n_bins(self) -> int:
        return len(self.edges) - 1 if self.edges else len(self.categories)

    def bin_labels(self) -> list[str]:
        if self.labels:
            return list(self.labels)
        if self.categories:
            return [str(c) for c in self.categories]
        return [f"[{a:g}, {b:g})" for a, b in zip(self.edges[:-1], self.edges[1:])]

    def assign(self, table: pd.DataFrame) -> np.ndarray:
        """Bin index of every row (-1: outside all bins or value missing)."""
        if self.column not in table.columns:
            raise DiagnosisError(f"regime {self.name!r} needs the column {self.column!r}, which the diagnosis "
                                 f"table lacks (it has {sorted(table.columns)})")
        col = table[self.column]
        if self.categories:
            out = np.full(len(table), -1, dtype=int)
            for i, c in enumerate(self.categories):
                out[(col == c).to_numpy()] = i
            return out
        x = col.to_numpy(dtype=float)
        if self.absolute:
            x = np.abs(x)
        idx = np.searchsorted(np.asarray(self.edges), x, side="right") - 1
        idx[~np.isfinite(x) | (idx < 0) | (idx >= self.n_bins)] = -1
        return idx


_KMH = 1 / 3.6
_REGIMES: Registry[Regime] = Registry("regime", Regime, DiagnosisError)


def register_regime(regime: Regime, replace_existing: bool = False) -> Regime:
    return _REGIMES.register(regime.name, regime, replace_existing)


def get_regime(name: str | Regime) -> Regime:
    return _REGIMES.get(name)


def regime_names() -> list[str]:
    return _REGIMES.names()


for _r in (
    Regime("speed", "speed", tuple(np.array([0, 30, 50, 70, 90, 110, 250]) * _KMH),
           labels=("<30 km/h", "30-50 km/h", "50-70 km/h", "70-90 km/h", "90-110 km/h", ">110 km/h"),
           description="vehicle speed v_V"),
    Regime("acceleration", "acceleration", (-np.inf, -1.5, -0.5, -0.1, 0.1, 0.5, 1.5, np.inf),
           labels=("< -1.5", "-1.5..-0.5", "-0.5..-0.1", "cruise ±0.1", "0.1..0.5", "0.5..1.5", "> 1.5"),
           description="dv_V/dt [m/s^2]"),
    Regime("grade", "gradient_angle", tuple(np.arctan(np.array([-100, -4, -2, -0.5, 0.5, 2, 4, 100]) / 100)),
           labels=("< -4 %", "-4..-2 %", "-2..-0.5 %", "flat", "0.5..2 %", "2..4 %", "> 4 %"),
           description="gradient angle θ"),
    Regime("lateral_acceleration", "lateral_acceleration", (0.0, 0.5, 1.5, 3.0, np.inf), absolute=True,
           labels=("straight <0.5", "0.5..1.5", "1.5..3", "> 3 m/s^2"),
           description="|v_V² / r| [m/s^2] (cornering)"),
    Regime("mode", "mode", categories=("traction", "coast", "regen", "braking"),
           description="traction vs coasting vs regenerative vs friction braking"),
    Regime("gear", "gear", categories=tuple(float(g) for g in range(1, 9)),
           labels=tuple(f"gear {g}" for g in range(1, 9)), description="engaged gear"),
    Regime("ambient_temperature", "ambient_temperature",
           tuple(np.array([-40, 0, 10, 20, 30, 60]) + KELVIN),
           labels=("< 0 °C", "0-10 °C", "10-20 °C", "20-30 °C", "> 30 °C"), description="ambient temperature T_a"),
    Regime("time_since_start", "time_since_start", (0, 300, 600, 1200, 2400, np.inf),
           labels=("0-5 min", "5-10 min", "10-20 min", "20-40 min", "> 40 min"),
           description="time since trip start (warm-up)"),
    Regime("payload", "payload", (-np.inf, 1.0, 80.0, 130.0, np.inf),
           labels=("none", "< 80 kg", "80-130 kg", "> 130 kg"), description="extra payload from trip metadata"),
    Regime("season", "season", categories=("winter", "spring", "summer", "autumn"),
           description="season from the trip date (or ambient temperature)"),
):
    register_regime(_r)

DEFAULT_REGIMES: tuple[str, ...] = tuple(_REGIMES)


@dataclass
class RegimeBin(Record):
    """One bin of a regime: n samples in n_blocks blocks, their share of all, median / MAD / mean / MEDSE of the
    residual [N], the block-bootstrap 95 % interval of the median (ci_low, ci_high) with its p-value, McGill's
    notch (notch_low, notch_high) and whether the bin departs from 0."""

    regime: str
    bin: str
    bin_index: int
    n: int
    n_blocks: int
    share: float
    median: float
    mad: float
    mean: float
    medse: float
    ci_low: float
    ci_high: float
    p_value: float
    notch_low: float
    notch_high: float
    departs: bool


@dataclass
class RegimeTable:
    """Statistics of a residual per bin of one regime (rows: bins with samples)."""

    regime: str
    description: str
    rows: list[RegimeBin] = field(default_factory=list)

    def frame(self) -> pd.DataFrame:
        return pd.DataFrame([r.to_dict() for r in self.rows])

    def departing(self) -> list[RegimeBin]:
        return [r for r in self.rows if r.departs]


def bin_statistics(residual: np.ndarray, table: pd.DataFrame, regime: str | Regime, blocks: np.ndarray,
                   rng: np.random.Generator, n_boot: int = 200, min_blocks: int = 3,
                   min_effect: float = 0.0) -> RegimeTable:
    """Robust statistics of ``residual`` [N] per bin of ``regime`` (see module doc).

    A bin departs when it has >= ``min_blocks`` blocks, its bootstrap interval and notch both exclude 0 and
    |median| >= ``min_effect`` [N]. Bins without samples are left out."""
    reg = get_regime(regime)
    r = np.asarray(residual, dtype=float)
    if r.shape[0] != len(table):
        raise DiagnosisError(f"residual has {r.shape[0]} samples, the table {len(table)} rows")
    idx = reg.assign(table)
    labels = reg.bin_labels()
    out = RegimeTable(reg.name, reg.description)
    total = int(np.sum(np.isfinite(r)))
    for i, label in enumerate(labels):
        sel = (idx == i) & np.isfinite(r)
        if not sel.any():
            continue
        x, b = r[sel], blocks[sel]
        nb = int(np.unique(b).size)
        summ = RobustSummary.of(x)
        med, lo, hi, p = block_bootstrap_median(x, b, rng, n_boot=n_boot)
        _, n_lo, n_hi = notch_interval(x, n_effective=nb)
        departs = bool(nb >= min_blocks and (lo > 0 or hi < 0) and (n_lo > 0 or n_hi < 0)
                       and abs(med) >= min_effect)
        out.rows.append(RegimeBin(reg.name, label, i, summ.n, nb, summ.n / max(total, 1), med, summ.mad, summ.mean,
                                  summ.medse, lo, hi, p, n_lo, n_hi, departs))
    return out


def localise(residual: np.ndarray, table: pd.DataFrame, blocks: np.ndarray, regimes: Sequence[str | Regime],
             rng: np.random.Generator, n_boot: int = 200, min_effect: float = 0.0) -> dict[str, RegimeTable]:
    """:func:`bin_statistics` for every regime whose column the table has with at least one valid value."""
    out: dict[str, RegimeTable] = {}
    for name in regimes:
        reg = get_regime(name)
        if reg.column not in table.columns:
            continue
        if reg.n_bins and np.all(reg.assign(table) < 0):
            continue
        out[reg.name] = bin_statistics(residual, table, reg, blocks, rng, n_boot=n_boot, min_effect=min_effect)
    return out


def strongest_departures(tables: dict[str, RegimeTable], top: int = 5) -> list[RegimeBin]:
    """Departing bins of all regimes, largest |median| × √share first (effect size weighted by coverage).
    Regimes with one populated bin are left out: they only repeat the overall median."""
    rows = [r for tab in tables.values() if len(tab.rows) > 1 for r in tab.departing()]
    rows.sort(key=lambda r: -abs(r.median) * np.sqrt(r.share))
    return rows[:top]


@dataclass
class ResidualCorrelation(Record):
    """Correlation coefficients of the residual with one signal (eq. 3.4a; with itself: eq. 3.4b) at each lag
    0..max_lag [samples], the largest |correlation| with its lag, and the ±2/√m white-noise bound."""

    correlation: list[float]
    max_abs: float
    lag: int
    bound: float


def residual_analysis(residual: np.ndarray, signals: dict[str, np.ndarray], trip_index: np.ndarray,
                      max_lag: int = 20) -> dict[str, ResidualCorrelation]:
    """Residual analysis of eq. 3.4a/3.4b, normalised to correlation coefficients and pooled over trips.

    Returns per signal (and 'residual' for the auto-correlation 3.4b): the correlation at each lag τ = 0..max_lag
    samples, the largest |correlation| with its lag, and the ±2/√m white-noise bound."""
    r = np.asarray(residual, dtype=float)
    trip_index = np.asarray(trip_index)
    signals = {k: v for k, v in signals.items() if np.isfinite(np.asarray(v, dtype=float)).sum() > max_lag + 1}
    names = ["residual"] + list(signals)
    acc = {n: np.zeros(max_lag + 1) for n in names}
    m_total = 0
    for k in np.unique(trip_index):
        sel = trip_index == k
        rk = r[sel]
        if rk.size <= max_lag + 1:
            continue
        rk = rk - np.nanmean(rk)
        m_total += rk.size
        acc["residual"] += _residual_correlation(np.nan_to_num(rk), None, max_lag) * rk.size
        for n in signals:
            y = np.asarray(signals[n], dtype=float)[sel]
            y = np.nan_to_num(y - np.nanmean(y))
            acc[n] += _residual_correlation(np.nan_to_num(rk), y, max_lag) * rk.size
    if m_total == 0:
        raise DiagnosisError(f"residual analysis needs trips longer than max_lag + 1 = {max_lag + 1} samples")
    out = {}
    sr = np.sqrt(np.nansum(np.where(np.isfinite(r), (r - np.nanmean(r)) ** 2, 0.0)) / m_total)
    for n in names:
        y = r if n == "residual" else np.asarray(signals[n], dtype=float)
        sy = np.sqrt(np.nanmean((y - np.nanmean(y)) ** 2))
        denom = sr * sy if sr > 0 and sy > 0 else np.inf
        corr = acc[n] / m_total / denom
        j = int(np.argmax(np.abs(corr[1:]) if n == "residual" else np.abs(corr))) + (1 if n == "residual" else 0)
        out[n] = ResidualCorrelation(corr.tolist(), float(abs(corr[j])), j, float(2.0 / np.sqrt(m_total)))
    return out
