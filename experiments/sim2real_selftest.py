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
from dataclasses import dataclass, field
from typing import Any, Callable, Sequence

import numpy as np
import pandas as pd

from roadload.trip import Trip

from roadload.sim2real.catalog import get_candidate
from roadload.sim2real.diagnose import Diagnosis, DiagnosisSettings, diagnose, fit_floor, sim_trips
from roadload.sim2real.simconfig import SimConfig
from roadload.sweep import run_sweep

UNEXPLAINED = "unexplained"
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


def identified_effect(diag: Diagnosis) -> str:
    return diag.identified[0] if diag.identified else UNEXPLAINED


def is_correct(withheld: WithheldEffect, identified: str) -> bool:
    if identified == UNEXPLAINED:
        return False
    return withheld.switch in get_candidate(identified).explains


def outside_localised(diag: Diagnosis, low: float = 50.0, high: float = 70.0) -> tuple[bool, str]:
    """(unexplained and localised to the speed band, where the diagnosis put it)."""
    un = diag.unexplained
    where = ""
    bins = un.get("departing_bins") or []
    if bins:
        where = f"{bins[0]['regime']}: {bins[0]['bin']}"
    imp = un.get("reference_importance") or []
    band = f"{low:g}-{high:g} km/h"
    ok_bin = bool(bins) and bins[0]["regime"] == "speed" and bins[0]["bin"] == band
    ok_ref = bool(imp) and imp[0]["column"] == "speed"
    return (not diag.identified) and un.get("present", False) and (ok_bin or ok_ref), where


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
    if diag.effects or not (diag.energy or {}).get("effects"):
        shrink, shrink_sim = diag.shrinkage("rmse"), diag.shrinkage("rmse", simulator=True)
        before, after = diag.gap_before["force_residual"]["rmse"], diag.gap_after["force_residual"]["rmse"]
    else:   # identified on the energy side: the battery-power residual's RMSE [W]
        before = diag.energy["power_residual_before"]["rmse"]
        after = diag.energy["power_residual_after"]["rmse"]
        shrink, shrink_sim = 1.0 - after / before, float("nan")
    return SelftestCase(label, switch, identified_effect(diag), correct, shrink, shrink_sim, before, after,
                        eff.get("parameters", {}), eff.get("sim_parameters"), where, seconds)


def run_case(task: dict[str, Any]) -> SelftestCase:
    """One withheld effect (a picklable task for :func:`roadload.sweep.run_sweep`)."""
    import time

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
    none_case = last.value if last.ok else SelftestCase(NONE_LABEL, "none", f"error: {last.error}", False,
                                                        *([float("nan")] * 4), {}, None, "")
    return SelftestResult(cases, out_case, bool(out_case.correct) if out_case else False, vehicle, none_case)
