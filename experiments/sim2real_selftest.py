"""Proof on withheld effects: for each catalog effect, "real" trips are driven with the effect switched on and the
sim runs without it; the diagnosis runs blind (all candidates) and must name the withheld effect.

Reported: the confusion matrix (withheld vs identified), top-1 accuracy, the gap shrinkage (held-out force
residual RMSE, fitted model and re-simulated sim), and the behaviour on an effect outside the catalog — a
torque-map error confined to one speed band (the drive-torque channel reads ``offset`` N m high between
``low`` and ``high`` km/h), which no candidate models: it must come out as unexplained and be localised to
that speed band. A last case withholds nothing (the "real" trips are the sim's own): nothing may be identified,
and its held-out RMSE is the noise floor for the excess shrinkage 1 - sqrt(after² - noise²)/sqrt(before² - noise²).
"""

from __future__ import annotations

import math
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Sequence

import numpy as np
import pandas as pd

from roadload.trip import Trip

from roadload.experiments.worlds import generate_case, supported_effects
from roadload.sim2real.catalog import candidate_names, get_candidate
from roadload.sim2real.diagnose import Diagnosis, DiagnosisSettings, diagnose, fit_floor, sim_trips
from roadload.sim2real.floor import SimFloor
from roadload.sim2real.simconfig import SimConfig
from roadload.sim2real.selftest import UNEXPLAINED, identified_effect, outside_localised
from roadload.sweep import run_sweep

OUTSIDE_LABEL = "torque_map_band (outside catalog)"
NONE_LABEL = "nothing withheld"


@dataclass(frozen=True)
class WithheldEffect:
    """label, simulator switch (effect name or spec:path) and its parameters."""

    label: str
    switch: str
    params: dict = field(default_factory=dict)


SELFTEST_EFFECTS: tuple[WithheldEffect, ...] = (
    WithheldEffect("wind", "wind", {"mean_speed": 6.0, "direction": math.pi, "gust_std": 0.5,
                                    "direction_std": 0.05}),
    WithheldEffect("payload", "payload", {"initial_payload": 200.0, "change_std": 0.0}),
    WithheldEffect("tire_warmup", "tire_warmup", {"cold_factor": 1.8, "distance_constant": 5000.0}),
    WithheldEffect("winter_tires", "winter_tires", {"rolling_factor": 1.3, "cornering_factor": 0.85}),
    WithheldEffect("drag_area", "drag_area", {"roof_box": 0.25, "windows": 0.0, "sunroof": 0.0,
                                              "toggle_rate": 0.0}),
    WithheldEffect("wet_road", "wet_road", {"rolling_factor": 1.1, "water_f1": 3e-4}),
    WithheldEffect("oil_temperature", "oil_temperature", {}),
    WithheldEffect("brake_pad_drift", "brake_pad_drift", {"temperature_coefficient": -2e-3,
                                                          "random_walk_std": 2e-3}),
    WithheldEffect("torque_gain", "spec:sensors.drive_torque_gain_error", {"delta": 0.05}),
    WithheldEffect("accel_bias", "spec:sensors.channels.accel_x.bias", {"delta": 0.1}),
    WithheldEffect("torque_latency", "spec:sensors.channels.drive_torque.latency", {"delta": 0.25}),
    WithheldEffect("auxiliary_load", "auxiliary_load", {"power": 1500.0}),
)
REAL_ROADS: tuple[tuple[str, int], ...] = (("hilly", 11), ("city", 12), ("motorway", 13))


def torque_map_band_error(trip: Trip, offset: float = 5.0, low: float = 50.0, high: float = 70.0) -> Trip:
    """The out-of-catalog effect: drive_torque reads ``offset`` N m high while the speed is in [low, high) km/h."""
    out = trip.copy()
    v = out.measured["vehicle_speed"].to_numpy(dtype=float) * 3.6
    band = (v >= low) & (v < high)
    out.measured.loc[band, "drive_torque"] = out.measured.loc[band, "drive_torque"] + offset
    out.meta["name"] = f"{trip.meta.get('name', 'trip')}+torque_band"
    return out


def is_correct(withheld: WithheldEffect, identified: str) -> bool:
    if identified == UNEXPLAINED:
        return False
    return withheld.switch in get_candidate(identified).explains


@dataclass
class SelftestCase:
    label: str
    switch: str
    identified: str
    correct: bool
    shrinkage: float
    shrinkage_simulator: float
    rmse_before: float
    rmse_after: float
    parameters: dict
    sim_parameters: dict | None
    unexplained_where: str
    seconds: float = 0.0

    def to_dict(self) -> dict:
        return dict(self.__dict__)


@dataclass
class SelftestResult:
    cases: list[SelftestCase]
    outside: SelftestCase | None
    outside_ok: bool
    vehicle: str
    none: SelftestCase | None = None

    @property
    def noise_rmse(self) -> float:
        """Held-out force RMSE of the sim against its own trips (nothing withheld) [N]: the floor no effect
        can go below."""
        return self.none.rmse_after if self.none is not None else float("nan")

    def excess_shrinkage(self, case: SelftestCase) -> float:
        """1 - sqrt(after² - noise²) / sqrt(before² - noise²): the shrinkage of the gap above the noise floor
        (force side only)."""
        n2 = self.noise_rmse ** 2
        if not np.isfinite(n2) or case.rmse_before > 1000:    # energy-side cases are in W, not N
            return float("nan")
        b = max(case.rmse_before ** 2 - n2, 0.0)
        a = max(case.rmse_after ** 2 - n2, 0.0)
        return float(1.0 - np.sqrt(a / b)) if b > 0 else float("nan")

    @property
    def median_excess_shrinkage(self) -> float:
        x = [self.excess_shrinkage(c) for c in self.cases]
        x = [v for v in x if np.isfinite(v)]
        return float(np.median(x)) if x else float("nan")

    @property
    def catalog_cases(self) -> list[SelftestCase]:
        return self.cases

    @property
    def top1(self) -> float:
        return float(np.mean([c.correct for c in self.cases])) if self.cases else float("nan")

    @property
    def median_shrinkage(self) -> float:
        return float(np.median([c.shrinkage for c in self.cases])) if self.cases else float("nan")

    @property
    def median_shrinkage_simulator(self) -> float:
        x = [c.shrinkage_simulator for c in self.cases if np.isfinite(c.shrinkage_simulator)]
        return float(np.median(x)) if x else float("nan")

    def confusion(self) -> pd.DataFrame:
        rows = self.cases + ([self.outside] if self.outside else []) + ([self.none] if self.none else [])
        labels = [c.label for c in rows]
        cols = sorted({c.identified for c in rows})
        m = pd.DataFrame(0, index=labels, columns=cols)
        for c in rows:
            m.loc[c.label, c.identified] += 1
        return m

    def to_dict(self) -> dict:
        return {"vehicle": self.vehicle, "top1": self.top1, "median_shrinkage_rmse": self.median_shrinkage,
                "median_shrinkage_rmse_simulator": self.median_shrinkage_simulator,
                "noise_rmse": self.noise_rmse, "median_excess_shrinkage": self.median_excess_shrinkage,
                "none": self.none.to_dict() if self.none else None,
                "cases": [c.to_dict() for c in self.cases],
                "outside": self.outside.to_dict() if self.outside else None, "outside_ok": self.outside_ok,
                "confusion": self.confusion().to_dict()}


def _case(label: str, switch: str, diag: Diagnosis, correct: bool, where: str, seconds: float) -> SelftestCase:
    effects = diag.effects + ((diag.energy or {}).get("effects") or [])
    eff = effects[0] if effects else {}
    energy = diag.energy or {}
    if diag.effects or not energy.get("effects"):
        shrink, shrink_sim = diag.shrinkage("rmse"), diag.shrinkage("rmse", simulator=True)
        before, after = diag.gap_before["force_residual"]["rmse"], diag.gap_after["force_residual"]["rmse"]
    else:   # identified on the energy side: the battery-power residual's RMSE [W]
        before = energy["power_residual_before"]["rmse"]
        after = energy["power_residual_after"]["rmse"]
        shrink, shrink_sim = 1.0 - after / before, float("nan")
    return SelftestCase(label, switch, identified_effect(diag), correct, shrink, shrink_sim, before, after,
                        eff.get("parameters", {}), eff.get("sim_parameters"), where, seconds)


def run_case(task: dict[str, Any]) -> SelftestCase:
    """One withheld effect (a picklable task for :func:`roadload.sweep.run_sweep`)."""
    t0 = time.perf_counter()
    sim: SimConfig = task["sim"]
    settings: DiagnosisSettings = task["settings"]
    roads = task["roads"]
    duration = task["duration"]
    w: WithheldEffect | None = task["effect"]
    if task.get("none"):   # nothing withheld: the 'real' trips are the sim's own; nothing may be identified
        diag = diagnose(sim_trips(sim, roads, duration), sim, settings, floor=task["floor"])
        bins = diag.unexplained.get("departing_bins") or []
        where = f"{bins[0]['regime']}: {bins[0]['bin']}" if bins else ""
        return _case(NONE_LABEL, "none", diag, not diag.identified, where, time.perf_counter() - t0)
    if w is None:   # the out-of-catalog effect
        real = [torque_map_band_error(t) for t in sim_trips(sim, roads, duration)]
    else:
        real_sim = sim.with_effect(w.switch, w.params)
        real = sim_trips(real_sim, roads, duration)
    diag = diagnose(real, sim, settings, floor=task["floor"])
    if w is None:
        ok, where = outside_localised(diag)
        return _case(OUTSIDE_LABEL, "torque_map_band", diag, ok, where, time.perf_counter() - t0)
    bins = diag.unexplained.get("departing_bins") or []
    where = f"{bins[0]['regime']}: {bins[0]['bin']}" if bins else ""
    return _case(w.label, w.switch, diag, is_correct(w, identified_effect(diag)), where, time.perf_counter() - t0)


def run_selftest(vehicle: str = "bmw_i3", effects: Sequence[WithheldEffect] = SELFTEST_EFFECTS,
                 roads: Sequence[tuple[str, int]] = REAL_ROADS, duration: float = 900.0,
                 settings: DiagnosisSettings | None = None, outside: bool = True, workers: int | None = None,
                 progress: bool = True, run: Callable | None = None) -> SelftestResult:
    """The selftest (see module doc). ``workers``: processes for :func:`roadload.sweep.run_sweep`."""

    sim = SimConfig.load(vehicle)
    if sim.vehicle.drivetrain.kind != "bev":   # the energy side (battery power) exists for electric vehicles only
        effects = [w for w in effects if w.switch != "auxiliary_load"]
    settings = settings or DiagnosisSettings()
    probe = sim_trips(sim, roads[:1], 30.0)[0]
    floor = fit_floor(sim, set(probe.channels), settings)
    tasks = [{"sim": sim, "settings": settings, "roads": tuple(roads), "duration": duration, "effect": w,
              "floor": floor} for w in effects]
    if outside:
        tasks.append({"sim": sim, "settings": settings, "roads": tuple(roads), "duration": duration,
                      "effect": None, "floor": floor})
    tasks.append({"sim": sim, "settings": settings, "roads": tuple(roads), "duration": duration,
                  "effect": None, "floor": floor, "none": True})
    outcomes = run_sweep(run or run_case, tasks, progress=progress, workers=workers,
                         description="sim2real selftest")
    cases = []
    for o in outcomes[:-1]:     # a failed case is reported as such (identified = 'error: ...'), never dropped
        if o.ok:
            cases.append(o.value)
        else:
            w = o.task["effect"]
            cases.append(SelftestCase(w.label if w else OUTSIDE_LABEL, w.switch if w else "torque_map_band",
                                      f"error: {o.error}", False, float("nan"), float("nan"), float("nan"),
                                      float("nan"), {}, None, ""))
    out_case = cases.pop() if outside else None
    last = outcomes[-1]
    nan = float("nan")
    none_case = last.value if last.ok else SelftestCase(NONE_LABEL, "none", f"error: {last.error}", False,
                                                        nan, nan, nan, nan, {}, None, "")
    return SelftestResult(cases, out_case, bool(out_case.correct) if out_case else False, vehicle, none_case)


# ============================================================================================ the three worlds
WORLD_NAMES = ("roadload", "fastsim", "independent", "fastsim_conv")


@dataclass
class WorldCaseResult:
    """One diagnosed case of :func:`run_world`: the first accepted effect, all accepted ones, whether the first
    is right (for "none" and the out-of-catalog case: nothing accepted), whether the withheld effect is among the
    accepted (or, with ``base_first``, a significant base departure standing for it), held-out force RMSE
    before/after [N], the base block's significant departures, seconds."""

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

    def to_dict(self) -> dict:
        return dict(self.__dict__)


def _fits(diag: Diagnosis) -> dict[str, dict]:
    """What :func:`found_against_reference` compares: every accepted effect (force and energy side) by its name,
    {"source": "effect", "parameters": {name: (value, standard error)}}, and every parameter of the base blocks
    (force side; energy side with battery power) under "base:<candidate>", with "significant", "size_rms" [N or W]
    and the size gate "min_size" of its side."""
    out: dict[str, dict] = {}
    for e in diag.effects + list((diag.energy or {}).get("effects") or []):
        se = e.get("std_errors") or {}
        out[e["name"]] = {"source": "effect", "significant": True,
                          "parameters": {k: (float(v), float(se.get(k, float("nan"))))
                                         for k, v in (e.get("parameters") or {}).items()}}
    blocks = [diag.notes.get("base_calibration") or {}, (diag.energy or {}).get("base_calibration") or {}]
    for block in blocks:
        for p in block.get("parameters", []):
            entry = out.setdefault(f"base:{p['candidate']}", {
                "source": "base", "significant": bool(p.get("significant")), "min_size": float(block["min_size"]),
                "size_rms": float(p.get("size_rms", float("nan"))), "parameters": {}})
            entry["parameters"][p["parameter"]] = (float(p["value"]), float(p["std_error"]))
    return out


Z_SHIFT = 2.58     # two-sided 1 %: the same level the base block calls a departure significant at


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
    """The scoring rule for a withheld effect, one for every world and sim (documented in
    docs/results/sim2real.md). The effect is **found** when a catalog candidate that stands for it

    1. is an accepted effect (force or energy side) that the reference diagnosis (same sim, same seed's drives,
       nothing withheld) does not accept, or accepts with parameters >= 2.58 combined standard errors away; or
    2. is a base-block parameter (force side: mass, drag area, rolling resistance, drive-train efficiency, brake
       gain; energy side: auxiliary power, motor efficiency) whose calibrated value moved from the reference's by
       >= 2.58 combined standard errors with a shift of at least the block's size gate (15 N / 100 W) — with an
       unmatched preset a payload *is* a mass shift and an auxiliary load an auxiliary-power shift. Without a
       reference run, a significant base departure counts.

    With the matched sim the reference accepts nothing and its base block sits near zero; with a preset, rule 1's
    second half and rule 2 separate the withheld effect from the preset's own mismatch, which the base blocks and
    the effects carry on every drive."""
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


@dataclass
class WorldRun:
    """All cases of one world (every seed) and their summary."""

    world: str
    vehicle: str
    results: list[WorldCaseResult]

    def catalog(self) -> list[WorldCaseResult]:
        return [r for r in self.results if r.withheld not in (NONE_WORLD, OUTSIDE_WORLD)]

    def confusion(self, seed: int | None = None) -> pd.DataFrame:
        rows = [r for r in self.results if seed is None or r.seed == seed]
        labels = list(dict.fromkeys(r.withheld for r in rows))
        cols = sorted({r.identified for r in rows})
        m = pd.DataFrame(0, index=labels, columns=cols)
        for r in rows:
            m.loc[r.withheld, r.identified] += 1
        return m

    def score(self) -> None:
        """Set ``found`` of every case by :func:`found_against_reference` against its seed's "nothing withheld"
        case (reference None when that case was not run)."""
        refs = {r.seed: r for r in self.results if r.withheld == NONE_WORLD}
        for r in self.results:
            r.found = found_against_reference(r, refs.get(r.seed))

    def summary(self) -> dict:
        self.score()
        cat = self.catalog()
        none = [r for r in self.results if r.withheld == NONE_WORLD]
        out = [r for r in self.results if r.withheld == OUTSIDE_WORLD]
        shr = [r.shrinkage for r in cat if r.correct and np.isfinite(r.shrinkage)]
        cpu = [r.cpu_seconds for r in self.results if np.isfinite(r.cpu_seconds)]
        return {"world": self.world, "vehicle": self.vehicle, "seeds": sorted({r.seed for r in self.results}),
                "catalog_cases": len(cat), "top1_correct": sum(r.correct for r in cat),
                "among_accepted": sum(r.among_accepted for r in cat),
                "among_accepted_or_base": sum(r.among_with_base for r in cat),
                "found": sum(r.found for r in cat),
                "found_cases": sum(r.seed in {x.seed for x in none} for r in cat),
                "false_acceptances_none": sum(bool(r.accepted) for r in none), "none_cases": len(none),
                "false_acceptances_outside": sum(bool(r.accepted) for r in out), "outside_cases": len(out),
                "median_shrinkage_identified": float(np.median(shr)) if shr else float("nan"),
                "median_shrinkage_all": float(np.nanmedian([r.shrinkage for r in cat])) if cat else float("nan"),
                "median_seconds": float(np.median([r.seconds for r in self.results])) if self.results else 0.0,
                "median_cpu_seconds": float(np.median(cpu)) if cpu else float("nan"),
                "max_cpu_seconds": float(np.max(cpu)) if cpu else float("nan"),
                "errors": sum(bool(r.error) for r in self.results)}

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
            mark = "✓" if r.correct else "✗"
            if r.withheld not in (NONE_WORLD, OUTSIDE_WORLD) and r.seed in refs and r.found != r.correct:
                mark += " (found)" if r.found else " (not found)"
            what = r.identified if r.error else (",".join(r.accepted) or "nothing")
            cell[(r.withheld, r.seed)] = f"{mark} {what} ({r.rmse_before:.1f}→{r.rmse_after:.1f})"
        lines = ["| withheld | " + " | ".join(f"seed {s}" for s in seeds) + " |",
                 "|---|" + "---|" * len(seeds)]
        for lab in labels:
            lines.append(f"| {lab} | " + " | ".join(cell.get((lab, s), "–") for s in seeds) + " |")
        return "\n".join(lines)

    def to_dict(self) -> dict:
        return {"summary": self.summary(), "results": [r.to_dict() for r in self.results],
                "confusion": self.confusion().to_dict()}


NONE_WORLD = "none"
OUTSIDE_WORLD = "torque_map_band"
# the roadload world's withheld effects by the names the other worlds use (winter tires stand in for cornering)
ROADLOAD_WORLD_EFFECTS: dict[str, WithheldEffect] = {
    "wind": SELFTEST_EFFECTS[0], "payload": SELFTEST_EFFECTS[1], "tire_warmup": SELFTEST_EFFECTS[2],
    "cold_drivetrain": SELFTEST_EFFECTS[6], "accel_bias": SELFTEST_EFFECTS[9], "cornering": SELFTEST_EFFECTS[3],
    "auxiliary_load": SELFTEST_EFFECTS[11], "torque_scale": SELFTEST_EFFECTS[8],
    "torque_latency": SELFTEST_EFFECTS[10], "drag_area": SELFTEST_EFFECTS[4]}


def _world_result(world: str, seed: int, withheld: str, diag: Diagnosis, accepted_names: Sequence[str],
                  seconds: float, low_high: tuple[float, float] = (50.0, 70.0)) -> WorldCaseResult:
    first = identified_effect(diag)
    acc = list(diag.identified)
    base = diag.notes.get("base_calibration") or {}
    base_dep = [p["candidate"] for p in base.get("parameters", []) if p.get("significant")]
    bins = diag.unexplained.get("departing_bins") or []
    where = f"{bins[0]['regime']}: {bins[0]['bin']}" if bins else ""
    if withheld == NONE_WORLD:
        correct = among = not acc
    elif withheld == OUTSIDE_WORLD:
        ok, where = outside_localised(diag, *low_high)
        correct = among = not acc
        where = where + ("" if ok else " (not localised to the band)")
    else:
        correct = first in accepted_names
        among = any(a in accepted_names for a in acc)
    if diag.effects or not (diag.energy or {}).get("effects"):
        before, after = diag.gap_before["force_residual"]["rmse"], diag.gap_after["force_residual"]["rmse"]
        shrink = diag.shrinkage("rmse")
    else:       # identified on the energy side: battery-power residual [W]
        en = diag.energy or {}
        before = en["power_residual_before"]["rmse"]
        after = en["power_residual_after"]["rmse"]
        shrink = 1.0 - after / before if before > 0 else float("nan")
    res = WorldCaseResult(world, seed, withheld, first, acc, bool(correct), bool(among), float(before),
                          float(after), float(shrink), base_dep, where, seconds)
    # a withheld effect whose signature is a base parameter (payload = mass) can only show in the base block when
    # the base is calibrated first; counted apart, as it is also what a preset's own mismatch looks like
    res.among_with_base = bool(among or (withheld not in (NONE_WORLD, OUTSIDE_WORLD)
                                         and any(b in accepted_names for b in base_dep)))
    res.fits = _fits(diag)
    res.stands_for = tuple(accepted_names)
    return res


def _failed(world: str, seed: int, withheld: str, exc: Exception, seconds: float) -> WorldCaseResult:
    msg = f"error: {type(exc).__name__}: {exc}"[:160]
    return WorldCaseResult(world, seed, withheld, msg, [], False, False, float("nan"), float("nan"), float("nan"),
                           [], "", seconds, str(exc))


def run_world(world: str, seeds: Sequence[int] = (0, 1, 2), effects: Sequence[str] | None = None,
              duration: float = 900.0, vehicle: str | None = None, settings: DiagnosisSettings | None = None,
              work: str | None = None, say: Callable[[str], None] | None = None) -> WorldRun:
    """The selftest on one world: for every seed and withheld effect (default: the user's ten, the out-of-catalog
    torque-map band and nothing withheld), 3 trips of ``duration`` s, diagnosed blind. ``vehicle``: a preset for
    the sim instead of the vehicle matched to the world (then the base is calibrated first). Worlds 'fastsim' and
    'independent' come from :mod:`roadload.experiments.worlds` (their logs go through the CSV importer); 'roadload'
    drives roadload's own simulator (a failing case is kept with identified = 'error: ...')."""
    say = say or (lambda msg: None)
    if world not in WORLD_NAMES:
        raise ValueError(f"unknown world {world!r}; choose one of {WORLD_NAMES}")
    settings = settings or DiagnosisSettings(resimulate=False, replay=False)
    if vehicle is not None:
        settings = DiagnosisSettings(**{**settings.__dict__, "base_first": True})
    results: list[WorldCaseResult] = []
    if world == "roadload":
        names = list(effects) if effects is not None else list(ROADLOAD_WORLD_EFFECTS) + [OUTSIDE_WORLD, NONE_WORLD]
        sim = SimConfig.load(vehicle or "bmw_i3")
        probe = sim_trips(sim, REAL_ROADS[:1], 30.0)[0]
        floor = fit_floor(sim, set(probe.channels), settings)
        for seed in seeds:
            roads = tuple((name, s + 1000 * seed) for name, s in REAL_ROADS)
            for name in names:
                t0 = time.perf_counter()
                try:
                    if name == NONE_WORLD:
                        real = sim_trips(sim, roads, duration)
                        accepted: tuple[str, ...] = ()
                    elif name == OUTSIDE_WORLD:
                        real = [torque_map_band_error(t) for t in sim_trips(sim, roads, duration)]
                        accepted = ()
                    else:
                        w = ROADLOAD_WORLD_EFFECTS[name]
                        real = sim_trips(sim.with_effect(w.switch, w.params), roads, duration)
                        accepted = tuple(c for c in candidate_names() if w.switch in get_candidate(c).explains)
                    t1, c1 = time.perf_counter(), time.process_time()
                    diag = diagnose(real, sim, settings, floor=floor)
                    res = _world_result(world, seed, name, diag, accepted, time.perf_counter() - t1)
                    res.cpu_seconds = time.process_time() - c1
                except Exception as exc:      # reported in the table, never dropped
                    res = _failed(world, seed, name, exc, time.perf_counter() - t0)
                results.append(res)
                say(_line(res))
        return WorldRun(world, vehicle or "bmw_i3 (matched: the world is roadload's own)", results)
    names = list(effects) if effects is not None else [n for n in supported_effects(world)]
    tmp: tempfile.TemporaryDirectory[str] | None = None
    if work is None:
        tmp = tempfile.TemporaryDirectory(prefix=f"s2r-{world}-")
        root = Path(tmp.name)
    else:
        root = Path(work)
    world_floor: SimFloor | None = None  # fitted on the first case's trips, shared by all cases
    try:
        for seed in seeds:
            for name in names:
                t0 = time.perf_counter()
                try:
                    case = generate_case(world, name, seed, n_trips=3, duration_s=duration, out_dir=root / f"s{seed}")
                    trips = case.import_trips()
                    sim = SimConfig.load(vehicle if vehicle else case.sim_path)
                    if world_floor is None:
                        world_floor = fit_floor(sim, set(trips[0].channels), settings)
                    t1, c1 = time.perf_counter(), time.process_time()
                    diag = diagnose(trips, sim, settings, floor=world_floor)
                    cpu = time.process_time() - c1
                    band = case.truth["parameters"] if name == OUTSIDE_WORLD else {}
                    res = _world_result(world, seed, name, diag, tuple(case.truth.get("accepted", ())),
                                        time.perf_counter() - t1,
                                        (band.get("low_kmh", 50.0), band.get("high_kmh", 70.0)))
                    res.cpu_seconds = cpu
                except Exception as exc:      # reported in the table, never dropped
                    res = _failed(world, seed, name, exc, time.perf_counter() - t0)
                results.append(res)
                say(_line(res))
    finally:
        if tmp is not None:
            tmp.cleanup()
    return WorldRun(world, vehicle or f"{world} matched vehicle", results)


def _line(r: WorldCaseResult) -> str:
    return (f"{r.world:11s} seed {r.seed} {r.withheld:16s} -> {r.identified:18s} {'ok  ' if r.correct else 'MISS'} "
            f"accepted {','.join(r.accepted) or '-':30s} base {','.join(r.base_departures) or '-':24s} "
            f"RMSE {r.rmse_before:7.1f} -> {r.rmse_after:7.1f} ({100 * r.shrinkage:5.1f} %) {r.seconds:5.1f} s "
            f"(cpu {r.cpu_seconds:5.1f} s) "
            f"{r.unexplained_where}")
