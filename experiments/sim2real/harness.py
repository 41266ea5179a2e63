"""The sim-to-real selftest's harness, one rule for every world: a case diagnosed blind (:func:`diagnose_case`),
what the diagnosis named first, whether an effect outside the catalog stayed unexplained and was localised,
whether a withheld effect was found against the same seed's nothing-withheld reference
(:func:`found_against_reference`), and a world's run with its confusion table and summary (:class:`WorldRun`)."""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from roadload import tables
from roadload.fileio import save_figure
from roadload.sim2real.diagnose import Diagnosis, DiagnosisSettings, diagnose
from roadload.sim2real.floor import SimFloor
from roadload.sim2real.simconfig import SimConfig
from roadload.trip import Trip

UNEXPLAINED = "unexplained"
NONE_WORLD = "none"
OUTSIDE_WORLD = "torque_map_band"
Z_SHIFT = 2.58     # two-sided 1 %: the same level the base block calls a departure significant at


def identified_effect(diag: Diagnosis) -> str:
    """The first accepted effect (force side first, then the energy side), or 'unexplained'."""
    return diag.identified[0] if diag.identified else UNEXPLAINED


def outside_localised(diag: Diagnosis, low: float = 50.0, high: float = 70.0) -> tuple[bool, str]:
    """(nothing accepted, the residual left unexplained and localised to the speed band [low, high) km/h, where the
    diagnosis put it)."""
    un = diag.unexplained
    bins = un.departing_bins
    where = f"{bins[0].regime}: {bins[0].bin}" if bins else ""
    imp = un.reference_importance
    band = f"{low:g}-{high:g} km/h"
    ok_bin = bool(bins) and bins[0].regime == "speed" and bins[0].bin == band
    ok_ref = bool(imp) and imp[0].column == "speed"
    return (not diag.identified) and un.present and (ok_bin or ok_ref), where


@dataclass
class WorldCaseResult:
    """One diagnosed case of :func:`run_world`: the first accepted effect, all accepted ones, whether the first
    is right (for "none" and the out-of-catalog case: nothing accepted), whether the withheld effect is among the
    accepted (or a significant base departure standing for it), held-out RMSE before/after (N, or W when found on
    the energy side), the base block's significant departures, seconds; ``size_error``: the fitted size against
    the injected one (relative, the real world), ``fits``: what the scoring rule compares."""

    world: str
    seed: int
    withheld: str
    identified: str
    accepted: list[str]
    correct: bool
    among_accepted: bool
    rmse_before: float
    rmse_after: float
    shrinkage: float
    base_departures: list[str]
    unexplained_where: str
    seconds: float
    error: str = ""
    cpu_seconds: float = float("nan")
    among_with_base: bool = False
    fits: dict = field(default_factory=dict)
    stands_for: tuple[str, ...] = ()
    found: bool = False
    size_error: float = float("nan")

    def to_dict(self) -> dict:
        return dict(self.__dict__)


def _fits(diag: Diagnosis) -> dict[str, dict]:
    """What :func:`found_against_reference` compares: every accepted effect (force and energy side) by its name,
    {"source": "effect", "parameters": {name: (value, standard error)}}, and every parameter of the base blocks
    (force side; energy side with battery power) under "base:<candidate>", with "significant", "size_rms" [N or W]
    and the size gate "min_size" of its side."""
    out: dict[str, dict] = {}
    for e in diag.effects + (diag.energy.effects if diag.energy else []):
        out[e.name] = {"source": "effect", "significant": True,
                       "parameters": {k: (float(v), float(e.std_errors.get(k, float("nan"))))
                                      for k, v in e.parameters.items()}}
    for block in (b for b in (diag.base, diag.energy_base) if b is not None):
        for p in block.parameters:
            entry = out.setdefault(f"base:{p.candidate}", {
                "source": "base", "significant": bool(p.significant), "min_size": float(block.min_size or 0.0),
                "size_rms": float(p.size_rms), "parameters": {}})
            entry["parameters"][p.parameter] = (float(p.value), float(p.std_error))
    return out


def _moved(fit: dict, ref: dict) -> bool:
    """Some parameter departs from the reference fit by >= Z_SHIFT combined standard errors; for a base parameter
    the shift's contribution (size_rms |Δx| / |x|, the regressor is the same) must also reach the block's size gate
    (15 N force side, 100 W energy side), as an accepted effect must."""
    for name, (x, se) in fit["parameters"].items():
        if name not in ref["parameters"]:
            continue
        x0, se0 = ref["parameters"][name]
        s = float(np.hypot(se if np.isfinite(se) else 0.0, se0 if np.isfinite(se0) else 0.0))
        if not (np.isfinite(x) and s > 0 and abs(x - x0) >= Z_SHIFT * s):
            continue
        if fit["source"] == "base" and abs(x) > 0:
            if fit.get("size_rms", float("nan")) * abs(x - x0) / abs(x) < fit.get("min_size", 0.0):
                continue
        return True
    return False


def found_against_reference(case: WorldCaseResult, reference: WorldCaseResult | None) -> bool:
    """The scoring rule for a withheld effect, one for every world and sim. The effect is **found** when a catalog
    candidate that stands for it

    1. is an accepted effect (force or energy side) that the reference diagnosis (same sim, same seed's drives,
       nothing withheld) does not accept, or accepts with parameters >= 2.58 combined standard errors away; or
    2. is a base-block parameter (force side: mass, drag area, rolling resistance, drive-train efficiency, brake
       gain; energy side: auxiliary power, motor efficiency) whose calibrated value moved from the reference's by
       >= 2.58 combined standard errors with a shift of at least the block's size gate (15 N / 100 W) — with an
       unmatched preset a payload *is* a mass shift and an auxiliary load an auxiliary-power shift. Without a
       reference run, a significant base departure counts."""
    if case.withheld in (NONE_WORLD, OUTSIDE_WORLD) or case.error:
        return False
    have_ref = reference is not None and not reference.error
    ref_fits = reference.fits if have_ref and reference is not None else {}
    for name in case.stands_for:
        eff, ref_eff = case.fits.get(name), ref_fits.get(name)
        if eff is not None and (ref_eff is None or _moved(eff, ref_eff)):
            return True
        base, ref_base = case.fits.get(f"base:{name}"), ref_fits.get(f"base:{name}")
        if base is None:
            continue
        if have_ref and ref_base is not None:
            if _moved(base, ref_base):
                return True
        elif base["significant"]:
            return True
    return False


def _gap_of(diag: Diagnosis) -> tuple[float, float, float]:
    """Held-out RMSE before, after and the shrinkage: force side, or the battery-power residual [W] when the
    effects are all on the energy side."""
    if diag.effects or not (diag.energy and diag.energy.effects):
        return (diag.gap_before.force_residual.rmse, diag.gap_after.force_residual.rmse, diag.shrinkage("rmse"))
    before, after = diag.energy.power_residual_before.rmse, diag.energy.power_residual_after.rmse
    return before, after, 1.0 - after / before if before > 0 else float("nan")


def case_result(world: str, seed: int, withheld: str, diag: Diagnosis, accepted_names: Sequence[str],
                seconds: float, low_high: tuple[float, float] = (50.0, 70.0)) -> WorldCaseResult:
    """Score one diagnosis of ``withheld`` (``accepted_names``: the candidates that count as naming it)."""
    first = identified_effect(diag)
    acc = list(diag.identified)
    base_dep = [p.candidate for p in diag.base.parameters if p.significant]
    bins = diag.unexplained.departing_bins
    where = f"{bins[0].regime}: {bins[0].bin}" if bins else ""
    if withheld == NONE_WORLD:
        correct = among = not acc
    elif withheld == OUTSIDE_WORLD:
        ok, where = outside_localised(diag, *low_high)
        correct = among = not acc
        where = where + ("" if ok else " (not localised to the band)")
    else:
        correct = first in accepted_names
        among = any(a in accepted_names for a in acc)
    before, after, shrink = _gap_of(diag)
    res = WorldCaseResult(world, seed, withheld, first, acc, bool(correct), bool(among), float(before),
                          float(after), float(shrink), base_dep, where, seconds)
    # a withheld effect whose signature is a base parameter (payload = mass) can only show in the base block when
    # the base is calibrated first; counted apart, as it is also what a preset's own mismatch looks like
    res.among_with_base = bool(among or (withheld not in (NONE_WORLD, OUTSIDE_WORLD)
                                         and any(b in accepted_names for b in base_dep)))
    res.fits = _fits(diag)
    res.stands_for = tuple(accepted_names)
    return res


@dataclass
class DiagnosisCase:
    """One case to diagnose: its trips, the sim they are diagnosed against, what counts as naming the withheld
    effect, the speed band of the out-of-catalog case and the injected size (real world)."""

    trips: list[Trip]
    sim: SimConfig
    accepted: tuple[str, ...]
    band: tuple[float, float] = (50.0, 70.0)
    size: Callable[[Diagnosis], float] | None = None


def diagnose_case(world: str, seed: int, name: str, case: DiagnosisCase, settings: DiagnosisSettings,
               floor: SimFloor | None, t0: float) -> WorldCaseResult:
    """Diagnose a case blind and score it (``t0``: when building the case started, for the wall seconds)."""
    c1 = time.process_time()
    diag = diagnose(case.trips, case.sim, settings, floor=floor)
    cpu = time.process_time() - c1
    res = case_result(world, seed, name, diag, case.accepted, time.perf_counter() - t0, case.band)
    res.cpu_seconds = cpu
    if case.size is not None and name not in (NONE_WORLD, OUTSIDE_WORLD):
        res.size_error = float(case.size(diag))
    return res


def failed_case(world: str, seed: int, withheld: str, exc: Exception, seconds: float) -> WorldCaseResult:
    """A case whose diagnosis raised: kept in the tables as a miss, never dropped."""
    msg = f"error: {type(exc).__name__}: {exc}"[:160]
    return WorldCaseResult(world, seed, withheld, msg, [], False, False, float("nan"), float("nan"), float("nan"),
                           [], "", seconds, str(exc))


# ============================================================================================ a world's run
@dataclass
class WorldRun:
    """All cases of one world (every seed) and their summary."""

    world: str
    vehicle: str
    results: list[WorldCaseResult]

    def catalog(self) -> list[WorldCaseResult]:
        return [r for r in self.results if r.withheld not in (NONE_WORLD, OUTSIDE_WORLD)]

    def confusion(self, seed: int | None = None) -> pd.DataFrame:
        """Rows: withheld effect, columns: first accepted effect ('error' for a failed case), entries: counts."""
        rows = [r for r in self.results if seed is None or r.seed == seed]
        labels = list(dict.fromkeys(r.withheld for r in rows))
        cols = sorted({_label(r.identified) for r in rows})
        m = pd.DataFrame(0, index=labels, columns=cols)
        for r in rows:
            m.loc[r.withheld, _label(r.identified)] += 1
        return m

    def score(self) -> None:
        """Set ``found`` of every case by :func:`found_against_reference` against its seed's "nothing withheld"
        case (reference None when that case was not run)."""
        refs = {r.seed: r for r in self.results if r.withheld == NONE_WORLD}
        for r in self.results:
            r.found = found_against_reference(r, refs.get(r.seed))

    def summary(self) -> dict:
        """The run's figures: cases, top-1, the scoring rule's "found", false acceptances, shrinkage, size errors
        (injected effects), timing and errors."""
        self.score()
        cat = self.catalog()
        none = [r for r in self.results if r.withheld == NONE_WORLD]
        out = [r for r in self.results if r.withheld == OUTSIDE_WORLD]
        return {"world": self.world, "vehicle": self.vehicle, "seeds": sorted({r.seed for r in self.results}),
                **_identification(cat, {x.seed for x in none}),
                "false_acceptances_none": _count(bool(r.accepted) for r in none), "none_cases": len(none),
                "false_acceptances_outside": _count(bool(r.accepted) for r in out), "outside_cases": len(out),
                **_sizes(cat), **_timing(self.results)}

    @classmethod
    def from_dicts(cls, world: str, vehicle: str, results: Sequence[dict]) -> "WorldRun":
        """A run rebuilt from :meth:`to_dict` results (possibly of several runs of the same world and sim)."""
        fields_ = set(WorldCaseResult.__dataclass_fields__)
        rows = []
        for r in results:
            kw: dict[str, Any] = {k: (tuple(v) if k == "stands_for" else v) for k, v in r.items() if k in fields_}
            rows.append(WorldCaseResult(**kw))
        for row in rows:    # results written before the energy base block keyed the force base by bare names
            row.fits = {(f"base:{k}" if f.get("source") == "base" and not k.startswith("base:") else k):
                        ({"min_size": 15.0, **f} if f.get("source") == "base" else f) for k, f in row.fits.items()}
        return cls(world, vehicle, rows)

    def markdown(self) -> str:
        """withheld x seed: ✓/✗, the accepted effects (first first; with ``found`` by the scoring rule when a
        reference ran) and the held-out RMSE before -> after."""
        self.score()
        seeds = sorted({r.seed for r in self.results})
        labels = list(dict.fromkeys(r.withheld for r in self.results))
        cell: dict[tuple[str, int], str] = {}
        refs = {r.seed for r in self.results if r.withheld == NONE_WORLD}
        for r in self.results:
            cell[(r.withheld, r.seed)] = _cell(r, r.seed in refs)
        lines = ["| withheld | " + " | ".join(f"seed {s}" for s in seeds) + " |",
                 "|---|" + "---|" * len(seeds)]
        for lab in labels:
            lines.append(f"| {lab} | " + " | ".join(cell.get((lab, s), "–") for s in seeds) + " |")
        return "\n".join(lines)

    def to_dict(self) -> dict:
        return {"summary": self.summary(), "results": [r.to_dict() for r in self.results],
                "confusion": self.confusion().to_dict()}


def _cell(r: WorldCaseResult, have_reference: bool) -> str:
    """✓/✗ (with the scoring rule's verdict where it differs), the accepted effects, RMSE before → after."""
    mark = "✓" if r.correct else "✗"
    if r.withheld not in (NONE_WORLD, OUTSIDE_WORLD) and have_reference and r.found != r.correct:
        mark += " (found)" if r.found else " (not found)"
    what = r.identified if r.error else (",".join(r.accepted) or "nothing")
    size = f", size {100 * r.size_error:+.0f} %" if np.isfinite(r.size_error) else ""
    return f"{mark} {what} ({r.rmse_before:.1f}→{r.rmse_after:.1f}{size})"


def _count(flags) -> int:
    return int(sum(bool(f) for f in flags))


def _identification(cat: list[WorldCaseResult], reference_seeds: set[int]) -> dict:
    """Top-1, among the accepted (or a base departure standing for it), found by the scoring rule, shrinkage."""
    shr = [r.shrinkage for r in cat if r.correct and np.isfinite(r.shrinkage)]
    return {"catalog_cases": len(cat), "top1_correct": _count(r.correct for r in cat),
            "among_accepted": _count(r.among_accepted for r in cat),
            "among_accepted_or_base": _count(r.among_with_base for r in cat),
            "found": _count(r.found for r in cat), "found_cases": _count(r.seed in reference_seeds for r in cat),
            "median_shrinkage_identified": _median(shr),
            "median_shrinkage_all": _median([r.shrinkage for r in cat if np.isfinite(r.shrinkage)])}


def _sizes(cat: list[WorldCaseResult]) -> dict:
    """Injected effects: top-1 with the fitted size within 25 % of the injected one, median |size error|."""
    sized = [r for r in cat if np.isfinite(r.size_error)]
    return {"top1_within_size": _count(r.correct and abs(r.size_error) <= 0.25 for r in sized),
            "size_cases": len(sized), "median_abs_size_error": _median([abs(r.size_error) for r in sized])}


def _timing(results: list[WorldCaseResult]) -> dict:
    cpu = [r.cpu_seconds for r in results if np.isfinite(r.cpu_seconds)]
    return {"median_seconds": _median([r.seconds for r in results]) if results else 0.0,
            "median_cpu_seconds": _median(cpu), "max_cpu_seconds": float(np.max(cpu)) if cpu else float("nan"),
            "errors": _count(r.error for r in results)}


def _median(x: Sequence[float]) -> float:
    return float(np.median(x)) if len(x) else float("nan")


def _label(identified: str) -> str:
    """Column label of the confusion table: failed cases (full message in the results) count as 'error'."""
    return "error" if identified.startswith("error") else identified


def summary_line(s: dict) -> str:
    """One line with the figures of :meth:`WorldRun.summary`."""
    size = (f"; top-1 with the size within 25 % {s['top1_within_size']}/{s['catalog_cases']} (median |size "
            f"error| {100 * s['median_abs_size_error']:.0f} %)" if s.get("size_cases") else "")
    return (f"found (scoring rule) {s['found']}/{s['catalog_cases']} ({s['found_cases']} with a reference run); "
            f"top-1 {s['top1_correct']}/{s['catalog_cases']}{size}; withheld among the accepted "
            f"{s['among_accepted']}/{s['catalog_cases']}; false acceptances: nothing withheld "
            f"{s['false_acceptances_none']}/{s['none_cases']}, out-of-catalog {s['false_acceptances_outside']}/"
            f"{s['outside_cases']}; median held-out shrinkage (identified cases) "
            f"{100 * s['median_shrinkage_identified']:.1f} %; cpu per diagnosis median {s['median_cpu_seconds']:.1f} s,"
            f" max {s['max_cpu_seconds']:.1f} s; errors {s['errors']}")


def case_line(r: WorldCaseResult) -> str:
    """The progress line of one case."""
    size = f" size {100 * r.size_error:+.0f} %" if np.isfinite(r.size_error) else ""
    return (f"{r.world:11s} seed {r.seed} {r.withheld:16s} -> {r.identified:18s} {'ok  ' if r.correct else 'MISS'} "
            f"accepted {','.join(r.accepted) or '-':30s} base {','.join(r.base_departures) or '-':24s} "
            f"RMSE {r.rmse_before:7.1f} -> {r.rmse_after:7.1f} ({100 * r.shrinkage:5.1f} %){size} "
            f"{r.seconds:5.1f} s (cpu {r.cpu_seconds:5.1f} s) {r.unexplained_where}")


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
    ax.set_xlabel("first accepted effect")
    ax.set_ylabel("withheld effect")
    ax.set_title(title, fontsize=10)
    fig.tight_layout()
    return save_figure(fig, path)


def confusion_markdown(table: pd.DataFrame, index_name: str = "withheld \\ identified") -> str:
    """A confusion table as Markdown through the one table writer (index as the first column, zeros blank)."""
    counts = table.astype(object).where(table != 0, "")
    frame = counts.reset_index()
    frame.columns = [index_name] + [str(c) for c in table.columns]
    return tables.markdown_table(frame)


