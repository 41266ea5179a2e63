"""The existing sim-to-real diagnosis (:func:`roadload.sim2real.diagnose`) run blind on the test worlds: for each
seed and withheld effect a case is generated (:func:`.cases.generate_case`), its CSV logs imported through the
case's mapping, and diagnosed against the matched vehicle with all candidates. The confusion table (withheld vs
first identified effect) is the baseline any reworked diagnosis must beat.

Scoring: a catalog effect counts as found when the first identified candidate is one of the effect's
``accepted`` candidates; the out-of-catalog torque-map band must come out unexplained and localised to its speed
band (:func:`roadload.sim2real.selftest.outside_localised`); "none" must identify nothing.
"""

from __future__ import annotations

import tempfile
import time
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd
from roadload import tables
from roadload.sim2real import DiagnosisSettings, SimConfig, diagnose
from roadload.sim2real.diagnose import Diagnosis, fit_floor
from roadload.sim2real.floor import SimFloor
from roadload.sim2real.selftest import outside_localised

from .cases import WORLDS, generate_case, supported_effects
from .common import NONE, OUTSIDE, WorldCase
from roadload.fileio import save_figure

UNEXPLAINED = "unexplained"


@dataclass
class WorldResult:
    """One diagnosed case."""

    world: str
    seed: int
    withheld: str
    identified: str
    all_identified: list[str]
    correct: bool
    rmse_before: float
    rmse_after: float
    shrinkage: float
    unexplained_where: str
    seconds: float
    error: str = ""

    def to_dict(self) -> dict:
        return asdict(self)


def _accepted(world: str, withheld: str) -> tuple[str, ...]:
    """Candidates that count as finding ``withheld`` in ``world`` (() for an unknown world or effect)."""
    effect = WORLDS[world].EFFECTS.get(withheld) if world in WORLDS else None
    return effect.accepted if effect is not None else ()


def _label(identified: str) -> str:
    """Column label of the confusion table: failed cases (full message in the results) count as 'error'."""
    return "error" if identified.startswith("error") else identified


@dataclass
class WorldSelftest:
    """All cases of a run; :meth:`confusion` per world (and per seed)."""

    results: list[WorldResult] = field(default_factory=list)

    def frame(self) -> pd.DataFrame:
        return pd.DataFrame([r.to_dict() for r in self.results])

    def confusion(self, world: str | None = None, seed: int | None = None) -> pd.DataFrame:
        """Rows: withheld effect, columns: first identified effect ('error' for a failed case), entries: counts
        over the selected cases."""
        rows = [r for r in self.results if (world is None or r.world == world) and (seed is None or r.seed == seed)]
        labels = list(dict.fromkeys(r.withheld for r in rows))
        cols = sorted({_label(r.identified) for r in rows})
        m = pd.DataFrame(0, index=labels, columns=cols)
        for r in rows:
            m.loc[r.withheld, _label(r.identified)] += 1
        return m

    def top1(self, world: str | None = None, seed: int | None = None) -> float:
        """Share of catalog effects identified first (out-of-catalog and "none" excluded)."""
        rows = [r for r in self.results if (world is None or r.world == world) and (seed is None or r.seed == seed)
                and r.withheld not in (NONE, OUTSIDE)]
        return float(np.mean([r.correct for r in rows])) if rows else float("nan")

    def summary(self, world: str | None = None) -> dict:
        rows = [r for r in self.results if world is None or r.world == world]
        out = [r for r in rows if r.withheld == OUTSIDE]
        none = [r for r in rows if r.withheld == NONE]
        cat = [r for r in rows if r.withheld not in (NONE, OUTSIDE)]
        shrink = [r.shrinkage for r in cat if np.isfinite(r.shrinkage)]
        anywhere = sum(bool(set(r.all_identified) & set(_accepted(r.world, r.withheld))) for r in cat)
        return {"cases": len(rows), "top1": self.top1(world), "found_anywhere": anywhere,
                "catalog_correct": sum(r.correct for r in rows if r.withheld not in (NONE, OUTSIDE)),
                "catalog_cases": sum(r.withheld not in (NONE, OUTSIDE) for r in rows),
                "outside_ok": f"{sum(r.correct for r in out)}/{len(out)}",
                "none_clean": f"{sum(r.correct for r in none)}/{len(none)}",
                "median_shrinkage": float(np.median(shrink)) if shrink else float("nan")}


def default_settings(quick: bool = False) -> DiagnosisSettings:
    """The diagnosis' defaults, without the re-simulation and replay (they only add the "after, simulator" gap,
    not the identification); ``quick``: 200 bootstrap draws and 300 s floor trips."""
    if quick:
        return DiagnosisSettings(resimulate=False, replay=False, n_boot=100, floor_duration=300.0)
    return DiagnosisSettings(resimulate=False, replay=False)


def score(case: WorldCase, diag: Diagnosis) -> tuple[str, bool, str]:
    """(first identified or 'unexplained', correct, where the unexplained residual departs most)."""
    first = diag.identified[0] if diag.identified else UNEXPLAINED
    bins = diag.unexplained.get("departing_bins") or []
    where = f"{bins[0]['regime']}: {bins[0]['bin']}" if bins else ""
    if case.withheld == NONE:
        return first, not diag.identified, where
    if case.withheld == OUTSIDE:
        band = case.truth["parameters"]
        ok, where = outside_localised(diag, band["low_kmh"], band["high_kmh"])
        return first, ok, where
    return first, first in case.truth["accepted"], where


def diagnose_case(case: WorldCase, settings: DiagnosisSettings, floor: SimFloor | None = None
                  ) -> tuple[Diagnosis, WorldResult]:
    """Import the case's logs, diagnose them against the matched vehicle, score."""
    t0 = time.perf_counter()
    trips = case.import_trips()
    sim = SimConfig.load(case.sim_path)
    diag = diagnose(trips, sim, settings, floor=floor)
    first, ok, where = score(case, diag)
    gb = diag.gap_before["force_residual"]["rmse"]
    ga = diag.gap_after["force_residual"]["rmse"]
    return diag, WorldResult(case.world, case.seed, case.withheld, first, diag.identified, bool(ok), float(gb),
                             float(ga), float(diag.shrinkage("rmse")), where, time.perf_counter() - t0)


def world_floor(world: str, settings: DiagnosisSettings, work: Path) -> SimFloor:
    """The sim's floor for the world's matched vehicle, reduced to the channels the world logs (fitted once)."""
    probe = generate_case(world, NONE, 0, n_trips=1, duration_s=120.0, out_dir=work / "probe")
    trips = probe.import_trips()
    sim = SimConfig.load(probe.sim_path)
    return fit_floor(sim, set(trips[0].channels), settings)


def run_world_selftest(world: str, seeds: Sequence[int] = (0,), effects: Sequence[str] | None = None,
                       n_trips: int = 3, duration_s: float = 900.0, settings: DiagnosisSettings | None = None,
                       out_dir: Path | str | None = None,
                       progress: Callable[[str], None] | None = None) -> WorldSelftest:
    """The diagnosis on ``world`` for every seed x withheld effect (default: all the world supports); a case
    that fails is kept with identified = 'error: ...'."""
    settings = settings or default_settings()
    names = list(effects) if effects is not None else list(supported_effects(world))
    say = progress or (lambda msg: None)
    tmp = None
    if out_dir is None:
        tmp = tempfile.TemporaryDirectory(prefix=f"worlds-{world}-")
        out_dir = tmp.name
    work = Path(out_dir)
    result = WorldSelftest()
    try:
        floor = world_floor(world, settings, work)
        for seed in seeds:
            for name in names:
                t0 = time.perf_counter()
                try:
                    case = generate_case(world, name, seed, n_trips=n_trips, duration_s=duration_s,
                                         out_dir=work / f"seed{seed}")
                    _, res = diagnose_case(case, settings, floor)
                except Exception as exc:  # noqa: BLE001 - a failed case is reported in the table, never dropped
                    res = WorldResult(world, seed, name, f"error: {type(exc).__name__}: {exc}"[:120], [], False,
                                      float("nan"), float("nan"), float("nan"), "", time.perf_counter() - t0,
                                      str(exc))
                result.results.append(res)
                say(f"{world} seed {seed} {name:18s} -> {res.identified:20s} {'ok' if res.correct else 'MISS'} "
                    f"({res.seconds:.0f} s) {res.unexplained_where}")
    finally:
        if tmp is not None:
            tmp.cleanup()
    return result


def plot_confusion(table: pd.DataFrame, path: Path | str, title: str) -> Path:
    """The confusion table as a PNG heat map (counts written in the cells)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(max(6.0, 2.5 + 0.75 * table.shape[1]), max(3.5, 1.8 + 0.45 * table.shape[0])))
    ax.imshow(table.to_numpy(dtype=float), cmap="Blues", aspect="auto")
    ax.set_xticks(range(table.shape[1]), table.columns, rotation=40, ha="right")
    ax.set_yticks(range(table.shape[0]), table.index)
    for i in range(table.shape[0]):
        for j in range(table.shape[1]):
            if table.iat[i, j]:
                ax.text(j, i, str(table.iat[i, j]), ha="center", va="center")
    ax.set_xlabel("first identified effect")
    ax.set_ylabel("withheld effect")
    ax.set_title(title, fontsize=10)
    fig.tight_layout()
    return save_figure(fig, path)


def markdown_table(table: pd.DataFrame, index_name: str = "withheld \\ identified") -> str:
    """A confusion table as Markdown through the one table writer (index as the first column, zeros blank)."""
    counts = table.astype(object).where(table != 0, "")
    frame = counts.reset_index()
    frame.columns = [index_name] + [str(c) for c in table.columns]
    return tables.markdown_table(frame)

