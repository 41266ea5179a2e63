"""The typed result of a diagnosis (:class:`Diagnosis`) and its parts that no single stage module owns: the
accepted effects (one record for the force and the energy side), the energy side, the unexplained residual and
the notes. :meth:`Diagnosis.to_dict` is the documented ``diagnosis.json`` schema (:mod:`.report`)."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import pandas as pd

from .base import BaseBlock
from .floor import SimFloor
from .gap import GapMeasures
from .pertrip import PerTripSizes
from .records import Record, RobustSummary, jsonable, optional, plain
from .reference import RegimeImportance
from .regimes import RegimeBin, ResidualCorrelation
from .selection import BaselineInfo, CandidateResult, SelectionStep, SplitSummary
from .simconfig import SimConfig
from .table import DiagnosisTable, TripInfo

SCHEMA_VERSION = 1


@dataclass
class Effect(Record):
    """An accepted effect (force or energy side): the candidate, its fitted shape (e.g. τ) and parameters with
    block-robust standard errors and units, what it gained in the forward selection (share of the sim's original
    robust loss, null p, explained share), the simulator switch with the parameters it maps to, and its sizes per
    trip with the test whether they differ (:mod:`.pertrip`)."""

    name: str
    description: str
    shape: float | None
    shape_name: str
    shape_unit: str
    parameters: dict[str, float]
    std_errors: dict[str, float]
    units: dict[str, str]
    heldout_gain: float
    null_p: float
    explained_fraction: float
    sim_switch: str | None
    sim_parameters: dict[str, Any] | None
    per_trip: PerTripSizes | None = optional()


@dataclass
class ElectricEnergy(Record):
    """Battery energy per distance while moving: measured, the sim's before and after the accepted effects."""

    measured: float
    sim_before: float
    sim_after: float
    unit: str = "kWh/100 km (while moving)"


@dataclass
class EnergySide(Record):
    """The battery-power residual (battery-electric trips): its summary before and after the accepted effects
    [W], the energy base block, the battery energy, the ranking, skipped candidates, the forward selection and
    the accepted effects."""

    power_residual_before: RobustSummary
    power_residual_after: RobustSummary
    base_calibration: BaseBlock
    electric_energy_per_distance: ElectricEnergy
    ranking: list[CandidateResult]
    skipped_candidates: dict[str, str]
    forward_selection: list[SelectionStep]
    effects: list[Effect]


@dataclass
class PerRegimeGap(Record):
    """Held-out RMSE and median of the force residual [N] in one regime bin before and after the effects, and the
    share of the RMSE that remains."""

    regime: str
    bin: str
    n: int
    rmse_before: float
    rmse_after: float
    median_before: float
    median_after: float
    remaining: float


@dataclass
class ReferenceGain(Record):
    """What the flexible regime-only reference still removes of the held-out MSE: its share of the MSE before,
    the block-bootstrap interval [N²] of the loss reduction, and whether it is significant."""

    relative: float
    interval: list[float]
    significant: bool


@dataclass
class Unexplained(Record):
    """The residual no accepted effect explains: whether any is present, the held-out regime bins still departing
    from 0, the reference's gain and strongest regime variables, and the held-out RMS after the effects [N]."""

    present: bool
    departing_bins: list[RegimeBin]
    reference_gain: ReferenceGain
    reference_importance: list[RegimeImportance]
    rms_after: float


@dataclass
class Implausible(Record):
    """A fit the selection would have accepted but whose value is no plausible simulator setting, with why."""

    effect: str
    reason: str


@dataclass
class Notes(Record):
    """Pipeline notes per trip, the sim as is before any effect (baseline), what the re-simulation did, the force
    base block, implausible fits and the strongest departing regime bins before."""

    pipeline: dict[str, list[str]]
    baseline: BaselineInfo
    resimulation: str
    base_calibration: BaseBlock
    implausible: list[Implausible]
    strongest_departures_before: list[RegimeBin]


@dataclass
class Diagnosis:
    """Result of :func:`roadload.sim2real.diagnose`; :meth:`to_dict` is the documented diagnosis.json schema.
    ``table``, ``residual_after`` and ``test_rows`` are kept in memory for the figures (not in the JSON)."""

    sim: SimConfig
    trips: list[str]
    settings: Any     # DiagnosisSettings (a dataclass of :mod:`.diagnose`)
    split: SplitSummary
    floor: SimFloor
    gap_before: GapMeasures
    gap_after: GapMeasures
    gap_after_sim: GapMeasures | None
    regimes_before: dict[str, list[RegimeBin]]
    per_regime: list[PerRegimeGap]
    residual_analysis: dict[str, ResidualCorrelation]
    ranking: list[CandidateResult]
    skipped: dict[str, str]
    selection: list[SelectionStep]
    effects: list[Effect]
    unexplained: Unexplained
    energy: EnergySide | None
    notes: Notes
    trip_info: list[TripInfo] = field(default_factory=list)
    table: DiagnosisTable | None = field(default=None, repr=False)
    residual_after: np.ndarray | None = field(default=None, repr=False)
    test_rows: np.ndarray | None = field(default=None, repr=False)

    @property
    def identified(self) -> list[str]:
        """Accepted effects: force side first, then the energy side."""
        return [e.name for e in self.effects] + [e.name for e in (self.energy.effects if self.energy else [])]

    @property
    def base(self) -> BaseBlock:
        """The force-side base block."""
        return self.notes.base_calibration

    @property
    def energy_base(self) -> BaseBlock | None:
        """The energy-side base block (None without battery power)."""
        return self.energy.base_calibration if self.energy else None

    def shrinkage(self, measure: str = "rmse", simulator: bool = False) -> float:
        """1 - gap_after / gap_before of the held-out force residual's ``measure`` (rmse, medse or |median|);
        ``simulator``: the after of the re-simulated sim with the effects switched on (NaN when not run)."""
        after = self.gap_after_sim if simulator else self.gap_after
        if after is None:
            return float("nan")
        b = getattr(self.gap_before.force_residual, measure)
        a = getattr(after.force_residual, measure)
        if measure == "median":
            b, a = abs(b), abs(a)
        return float(1.0 - a / b) if b > 0 else float("nan")

    def to_dict(self) -> dict:
        measures = ("rmse", "medse", "median")
        return jsonable({
            "schema_version": SCHEMA_VERSION, "sim": self.sim.to_dict(), "trips": self.trips,
            "settings": dataclasses.asdict(self.settings), "split": plain(self.split), "floor": self.floor.to_dict(),
            "gap": {"before": plain(self.gap_before), "after": plain(self.gap_after),
                    "after_simulator": plain(self.gap_after_sim),
                    "shrinkage": {m: self.shrinkage(m) for m in measures},
                    "shrinkage_simulator": {m: self.shrinkage(m, simulator=True) for m in measures},
                    "per_regime": plain(self.per_regime)},
            "regimes": plain(self.regimes_before), "residual_analysis": plain(self.residual_analysis),
            "ranking": plain(self.ranking), "skipped_candidates": self.skipped,
            "forward_selection": plain(self.selection), "effects": plain(self.effects),
            "unexplained": plain(self.unexplained), "energy_side": plain(self.energy), "notes": plain(self.notes),
            "trip_metadata": plain(self.trip_info)})


def per_regime_gap(table: pd.DataFrame, before: np.ndarray, after: np.ndarray, rows: np.ndarray,
                   regimes: list[Any]) -> list[PerRegimeGap]:
    """Held-out RMSE and median before/after per bin of each regime (bins with >= 20 rows)."""
    out = []
    for reg in regimes:
        if reg.column not in table.columns:
            continue
        idx = reg.assign(table)
        for i, label in enumerate(reg.bin_labels()):
            sel = rows & (idx == i)
            if sel.sum() < 20:
                continue
            b = float(np.sqrt(np.mean(before[sel] ** 2)))
            a = float(np.sqrt(np.mean(after[sel] ** 2)))
            out.append(PerRegimeGap(reg.name, label, int(sel.sum()), b, a, float(np.median(before[sel])),
                                    float(np.median(after[sel])), a / b if b > 0 else float("nan")))
    return out
