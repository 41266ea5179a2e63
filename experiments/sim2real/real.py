"""The diagnosis on the real BMW i3 trips (TUM, ``<shared data>/bmw_i3_tum``), where no truth is known but two
things are: the heater and air-conditioning power the logger recorded, and effects injected into the logs.

- :func:`hvac_experiment`: the heating and air-conditioning channels withheld; the sim calibrated on the summer
  trips whose logged HVAC power stayed low; the winter trips and the summer trips with the air conditioning on
  diagnosed against the calibration. The auxiliary load must be named first on the energy side with the
  group's logged HVAC power minus the calibration trips' as its size, and its per-trip sizes must follow the
  per-trip logged HVAC power.
- :func:`run_real_world` (``roadload sim2real selftest --world real``): the sim calibrated on trips as logged;
  copies of the same trips with an effect injected (:mod:`roadload.sim2real.inject`) diagnosed against it; the
  un-injected copies must give no acceptance.
- :func:`speed`: CPU seconds of calibrating on 10 trips and diagnosing 5;
- :func:`preset_diagnosis`: the shipped ``bmw_i3`` preset as is against all trips (where the gap lies), with an
  optional user candidate (:func:`register_cold_rolling`: rolling resistance rising in the cold).

    python scripts/sim2real_i3.py hvac | inject | speed | preset [--user-candidate] [--out DIR]
"""

from __future__ import annotations

import argparse
import os
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from roadload.data import require_shared_data
from roadload.estimators.models import Term
from roadload.io import import_log
from roadload.sim2real.calibrate import Calibration, CalibrationSettings, calibrate
from roadload.sim2real.catalog import DEFAULT_CANDIDATES, CandidateEffect, register_candidate
from roadload.sim2real.diagnose import Diagnosis, DiagnosisSettings, diagnose, fit_floor
from roadload.sim2real.report import write_report
from roadload.sim2real.inject import INJECTIONS, fitted_size, inject
from roadload.sim2real.simconfig import SimConfig
from roadload.trip import Trip
from roadload.units import STANDARD_TEMPERATURE, G

from .harness import NONE_WORLD, DiagnosisCase, WorldCaseResult, WorldRun, case_line, diagnose_case, failed_case

HVAC_CHANNELS = ("heating_power", "aircon_power")
#: summer trips whose logged heater + air conditioning stayed under ~400 W while moving: the calibration set
LOW_HVAC_SUMMER = ("TripA09", "TripA15", "TripA16", "TripA17", "TripA22", "TripA26", "TripA29", "TripA30")
#: summer trips with the air conditioning on (logged air-conditioning power >= 400 W on average)
SUMMER_AC = ("TripA01", "TripA02", "TripA06", "TripA07", "TripA08", "TripA12", "TripA21", "TripA32")
#: injected effects of the real world: two sizes each, chosen before the runs
REAL_INJECTIONS: tuple[tuple[str, float], ...] = (
    ("aux_load", 750.0), ("aux_load", 1500.0), ("torque_gain", 0.04), ("torque_gain", 0.08),
    ("accel_bias", 0.08), ("accel_bias", 0.15), ("latency", 0.15), ("latency", 0.3),
    ("speed_scale", 0.03), ("speed_scale", 0.06))


#: standstill for the HVAC-channel check: speed [m/s] and drive torque [N m] below these, at least this long [s]
STANDSTILL_SPEED, STANDSTILL_TORQUE, MIN_STANDSTILL = 0.3, 2.0, 10.0


@dataclass
class LoggedTrips:
    """Trips with the HVAC channels withheld, what the logger recorded of the HVAC power per trip (time [s],
    heater + air conditioning [W]) and, per trip whose logged HVAC power contradicts its own battery, why
    (:func:`hvac_contradiction`)."""

    trips: list[Trip]
    hvac: dict[str, tuple[np.ndarray, np.ndarray]]
    contradicts: dict[str, str] = field(default_factory=dict)


def hvac_contradiction(trip: Trip, hvac_power: np.ndarray) -> str | None:
    """Why the logged heater + air-conditioning power ``hvac_power`` [W] contradicts the trip's own battery (None
    when it does not, or when the trip stands still for less than 10 s). At standstill (speed < 0.3 m/s, drive
    torque < 2 N m) the traction battery supplies the HVAC and the 12 V loads and nothing else, so the battery
    power must be at least the logged HVAC power; on the i3 trips battery minus logged HVAC is +110 to +1070 W
    at standstill (the 12 V loads), and a trip where it is negative in the median logs HVAC power its battery
    does not deliver (e.g. TripA06: 6.0 kW logged, 1.1 kW drawn)."""
    v, tq = trip.channel("vehicle_speed"), trip.channel("drive_torque")
    still = (np.abs(v) < STANDSTILL_SPEED) & (np.abs(tq) < STANDSTILL_TORQUE)
    if still.sum() < MIN_STANDSTILL * trip.sample_rate:
        return None
    battery = (trip.channel("battery_voltage") * trip.channel("battery_current"))[still]
    drawn, logged = float(np.nanmedian(battery)), float(np.nanmedian(hvac_power[still]))
    if drawn - logged >= 0.0:
        return None
    return (f"logs {logged:.0f} W of HVAC power at standstill where its battery delivers {drawn:.0f} W "
            f"({still.sum() / trip.sample_rate:.0f} s standing)")


def i3_folder() -> Path:
    """The i3 trips (FileNotFoundError naming ROADLOAD_DATA when the shared data is absent)."""
    return require_shared_data("bmw_i3_tum") / "data"


def load_i3(names: Sequence[str], withhold_hvac: bool = True) -> LoggedTrips:
    """The named trips through the bmw-i3 importer, the HVAC channels withheld (kept aside as the truth)."""
    folder = i3_folder()
    trips, hvac, contradicts = [], {}, {}
    for name in names:
        trip = import_log(folder / f"{name}.csv", "bmw-i3")
        power = np.zeros(len(trip))
        for c in HVAC_CHANNELS:
            if trip.has(c):
                power = power + np.nan_to_num(trip.channel(c))
        hvac[name] = (trip.t, power)
        why = hvac_contradiction(trip, power)
        if why is not None:
            contradicts[name] = why
        if withhold_hvac:
            trip = without_channels(trip, HVAC_CHANNELS)
        trips.append(trip)
    return LoggedTrips(trips, hvac, contradicts)


def consistent_hvac(logged: LoggedTrips, say: Callable[[str], None]) -> LoggedTrips:
    """The trips whose logged HVAC power their battery confirms (:func:`hvac_contradiction`, the same rule for
    every trip); the others are named with the reason and left out of the group."""
    for name, why in logged.contradicts.items():
        say(f"{name} left out: {why}")
    keep = [t for t in logged.trips if t.meta.get("name") not in logged.contradicts]
    return LoggedTrips(keep, {k: v for k, v in logged.hvac.items() if k not in logged.contradicts})


def without_channels(trip: Trip, channels: Sequence[str]) -> Trip:
    """A copy of ``trip`` without the named measured channels."""
    out = trip.copy()
    drop = [c for c in channels if out.has(c)]
    out.measured = out.measured.drop(columns=drop)
    for c in drop:
        out.units.pop(c, None)
    return out


def logged_hvac(diag: Diagnosis, logged: LoggedTrips) -> dict[str, float]:
    """Per trip, the logged HVAC power [W] averaged over the diagnosis' valid rows (the rows its sizes are fitted
    on)."""
    assert diag.table is not None
    f = diag.table.frame
    out = {}
    for name, (t, p) in logged.hvac.items():
        sel = (f["trip"] == name).to_numpy() & f["valid"].to_numpy(bool)
        out[name] = float(np.mean(np.interp(f["t"].to_numpy(dtype=float)[sel], t, p))) if sel.any() else np.nan
    return out


# ============================================================================================ HVAC withheld
@dataclass
class GroupResult:
    """A group diagnosed against the calibration: what the energy side named first, the fitted auxiliary load
    (pooled and the mean of the per-trip sizes) [W], the group's logged HVAC minus the calibration trips' [W],
    the relative error of each, per-trip sizes and logged HVAC [W] and their Pearson r."""

    group: str
    first_energy: str
    first_force: str
    pooled: float
    per_trip_mean: float
    logged_difference: float
    error_pooled: float
    error_per_trip_mean: float
    sizes: dict[str, float]
    logged: dict[str, float]
    pearson_r: float
    cpu_seconds: float


def _valid_weighted_mean(diag: Diagnosis, per_trip: dict[str, float]) -> float:
    """The mean of per-trip values weighted by each trip's valid rows in the diagnosis table."""
    f = diag.table.frame if diag.table is not None else pd.DataFrame()
    w = {k: float(np.sum((f["trip"] == k).to_numpy() & f["valid"].to_numpy(bool))) for k in per_trip}
    return sum(per_trip[k] * w[k] for k in per_trip) / max(sum(w.values()), 1.0)


def _pearson(sizes: dict[str, float], logged: dict[str, float]) -> float:
    """Pearson r of the per-trip sizes against the logged values over the trips both hold (nan under 3)."""
    common = [k for k in sizes if k in logged]
    if len(common) < 3:
        return float("nan")
    return float(np.corrcoef([sizes[k] for k in common], [logged[k] for k in common])[0, 1])


def _group(name: str, diag: Diagnosis, logged: dict[str, float], reference: float, cpu: float) -> GroupResult:
    en = diag.energy
    energy_effects = en.effects if en else []
    aux = next((e for e in energy_effects if e.name == "auxiliary_power"), None)
    pooled = aux.parameters["delta P_aux"] if aux else float("nan")
    per_trip = aux.per_trip if aux else None
    sizes = {s.trip: s.values["delta P_aux"] for s in per_trip.sizes} if per_trip else {}
    mean = per_trip.mean["delta P_aux"] if per_trip else pooled
    diff = _valid_weighted_mean(diag, logged) - reference
    first_energy = energy_effects[0].name if energy_effects else "none"
    return GroupResult(name, first_energy, diag.effects[0].name if diag.effects else "none", pooled, mean, diff,
                       pooled / diff - 1.0, mean / diff - 1.0, sizes, logged, _pearson(sizes, logged), cpu)


def hvac_experiment(settings: DiagnosisSettings | None = None, say: Callable[[str], None] = print
                    ) -> tuple[Calibration, list[GroupResult]]:
    """Calibrate on the low-HVAC summer trips, diagnose the winter and the summer air-conditioning trips (module
    doc); HVAC channels withheld everywhere."""
    settings = settings or DiagnosisSettings(resimulate=False, replay=False)
    ref = consistent_hvac(load_i3(LOW_HVAC_SUMMER), say)
    c0 = time.process_time()
    cal = calibrate(ref.trips, SimConfig.load("bmw_i3"))
    say(f"calibrated on {len(ref.trips)} low-HVAC summer trips ({time.process_time() - c0:.1f} s cpu): "
        + "; ".join(cal.notes))
    probe = diagnose(ref.trips, cal.sim_config, settings)
    reference = _valid_weighted_mean(probe, logged_hvac(probe, ref))
    say(f"calibration trips' logged HVAC: {reference:.0f} W; identified against their own calibration: "
        f"{probe.identified or 'nothing'}")
    winter = sorted(p.stem for p in i3_folder().glob("TripB*.csv"))
    out = []
    for name, names in (("winter", winter), ("summer, air conditioning on", SUMMER_AC)):
        group = consistent_hvac(load_i3(names), say)
        c0 = time.process_time()
        diag = diagnose(group.trips, cal.sim_config, settings)
        out.append(_group(name, diag, logged_hvac(diag, group), reference, time.process_time() - c0))
        say(hvac_line(out[-1]))
    return cal, out


def hvac_line(g: GroupResult) -> str:
    return (f"{g.group}: energy side names {g.first_energy} first (force side {g.first_force}); auxiliary load "
            f"{g.pooled:.0f} W pooled, {g.per_trip_mean:.0f} W mean of the per-trip sizes, against "
            f"{g.logged_difference:.0f} W logged ({100 * g.error_pooled:+.0f} % / "
            f"{100 * g.error_per_trip_mean:+.0f} %); per-trip Pearson r {g.pearson_r:.2f} over {len(g.sizes)} "
            f"trips ({g.cpu_seconds:.0f} s cpu)")


# ============================================================================================ injection world
def _size_of(effect: str, size: float) -> Callable[[Diagnosis], float]:
    def relative_error(diag: Diagnosis) -> float:
        for e in diag.effects + (diag.energy.effects if diag.energy else []):
            fitted = fitted_size(effect, e.name, e.parameters)
            if fitted is not None:
                return fitted / size - 1.0
        return float("nan")
    return relative_error


def run_real_world(seeds: Sequence[int] = (0,), effects: Sequence[str] | None = None,
                   settings: DiagnosisSettings | None = None, say: Callable[[str], None] | None = None,
                   trips: Sequence[str] = LOW_HVAC_SUMMER) -> WorldRun:
    """The real world (module doc): ``effects`` by "name:size" (default :data:`REAL_INJECTIONS`, plus "none"),
    ``seeds``: the split seed of calibration and diagnosis."""
    say = say or (lambda msg: None)
    settings = settings or DiagnosisSettings(resimulate=False, replay=False)
    cases = _real_cases(effects)
    logged = load_i3(trips).trips
    results: list[WorldCaseResult] = []
    for seed in seeds:
        cal = calibrate(logged, SimConfig.load("bmw_i3"), CalibrationSettings(seed=seed))
        sim = cal.sim_config
        st = DiagnosisSettings(**{**settings.__dict__, "seed": seed})
        floor = fit_floor(sim, set.intersection(*[set(t.channels) for t in logged]), st,
                          rate=min(t.sample_rate for t in logged))
        for label, effect, size in cases:
            t0 = time.perf_counter()
            try:
                real = logged if effect is None else [inject(t, effect, size) for t in logged]
                accepted = () if effect is None else tuple(c for c, _, _ in INJECTIONS[effect].candidates)
                case = DiagnosisCase(real, sim, accepted, size=None if effect is None else _size_of(effect, size))
                res = diagnose_case("real", seed, label, case, st, floor, t0)
            except Exception as exc:      # reported in the table, never dropped
                res = failed_case("real", seed, label, exc, time.perf_counter() - t0)
            results.append(res)
            say(case_line(res))
    return WorldRun("real", f"bmw_i3 calibrated on {len(logged)} real trips as logged", results)


def _real_cases(effects: Sequence[str] | None) -> list[tuple[str, str | None, float]]:
    """(label, effect, size) of each case: "aux_load:1500" style names, "none" for the un-injected copies."""
    names = list(effects) if effects is not None else [f"{e}:{s:g}" for e, s in REAL_INJECTIONS] + [NONE_WORLD]
    out: list[tuple[str, str | None, float]] = []
    for n in names:
        if n == NONE_WORLD:
            out.append((NONE_WORLD, None, 0.0))
            continue
        effect, _, size = n.partition(":")
        if effect not in INJECTIONS or not size:
            raise ValueError(f"real-world case {n!r}: give EFFECT:SIZE with EFFECT one of {sorted(INJECTIONS)}")
        out.append((n, effect, float(size)))
    return out


# ============================================================================================ speed
def speed(say: Callable[[str], None] = print) -> tuple[float, float]:
    """CPU seconds of calibrating on 10 real trips and of diagnosing 5 (re-simulation and replay off, defaults
    otherwise), with the load average."""
    names = sorted(p.stem for p in i3_folder().glob("TripA*.csv"))
    cal_trips, diag_trips = load_i3(names[:10]).trips, load_i3(names[10:15]).trips
    c0 = time.process_time()
    cal = calibrate(cal_trips, SimConfig.load("bmw_i3"))
    c1 = time.process_time()
    diagnose(diag_trips, cal.sim_config, DiagnosisSettings(resimulate=False, replay=False))
    c2 = time.process_time()
    say(f"calibrate on 10 trips {c1 - c0:.1f} s cpu, diagnose 5 trips {c2 - c1:.1f} s cpu, together "
        f"{c2 - c0:.1f} s (target <= 60 s); load average {os.getloadavg()[0]:.1f}")
    return c1 - c0, c2 - c1


# ============================================================================================ the preset as is
def register_cold_rolling() -> str:
    """A user-added candidate (not in the catalog): rolling resistance rising in the cold,
    f_r(v, T_a) = f_r(v) (1 + k max(293.15 K - T_a, 0) / 10 K); regressor m_V g cos(theta) f_r(v) max(...)/10 K,
    parameter k (relative rise per 10 K below 20 degC). The simulator has no such switch (sim_effect None)."""

    def terms(model, shape):
        def build(s):
            th = np.asarray(s["gradient_angle"], dtype=float)
            cold = np.clip(STANDARD_TEMPERATURE - np.asarray(s["ambient_temperature"], dtype=float), 0.0, None) / 10.0
            return model.mass * G * np.cos(th) * model.rolling_resistance_coefficient(
                np.asarray(s["speed"], dtype=float)) * np.nan_to_num(cold)
        return (Term("m_V g cos(theta) f_r(v) max(20 degC - T_a, 0)/10 K", "cold rolling rise k", "1/(10 K)",
                     build, ("gradient_angle", "speed", "ambient_temperature"), lambda n: 0.0),)

    register_candidate(CandidateEffect("cold_rolling", "rolling resistance rising in the cold (user candidate)",
                                       terms, ("gradient_angle", "speed", "ambient_temperature"),
                                       regime_hint="ambient_temperature"), replace_existing=True)
    return "cold_rolling"


def preset_diagnosis(out: Path, user_candidate: bool = False, base_first: bool = False,
                     say: Callable[[str], None] = print) -> Diagnosis:
    """The ``bmw_i3`` preset as shipped against all i3 trips (heating channels kept); report into ``out``."""
    names = sorted(p.stem for p in i3_folder().glob("Trip*.csv"))
    trips = load_i3(names, withhold_hvac=False).trips
    cands = DEFAULT_CANDIDATES + ((register_cold_rolling(),) if user_candidate else ())
    diag = diagnose(trips, SimConfig.load("bmw_i3"), DiagnosisSettings(candidates=cands, base_first=base_first),
                    progress=lambda what, frac: say(f"  {what}"))
    write_report(diag, out)
    fb, fa = diag.gap_before.force_residual, diag.gap_after.force_residual
    say(f"{len(trips)} trips; held-out force residual median {fb.median:.0f} -> {fa.median:.0f} N, RMSE "
        f"{fb.rmse:.0f} -> {fa.rmse:.0f} N; identified {diag.identified or 'nothing'}; wrote {out / 'report.md'}")
    return diag


def main(argv: list[str] | None = None) -> int:
    """``scripts/sim2real_i3.py`` (see the module doc)."""
    os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("what", nargs="?", default="all", choices=("hvac", "inject", "speed", "preset", "all"))
    ap.add_argument("--quick", action="store_true", help="CI smoke run: two trips, one injected case")
    ap.add_argument("--user-candidate", action="store_true", help="preset: add the user candidate cold_rolling")
    ap.add_argument("--base-first", action="store_true", help="preset: select effects over the calibrated base")
    ap.add_argument("--out", type=Path, default=Path("out/sim2real_i3"), help="preset: report folder")
    args = ap.parse_args(argv)
    try:
        i3_folder()
    except FileNotFoundError as exc:
        print(f"{exc}; skipped" if args.quick else str(exc))
        return 0 if args.quick else 1
    if args.quick:
        run = run_real_world(effects=["aux_load:1500"], trips=LOW_HVAC_SUMMER[:2], say=print)
        print(run.markdown())
        return 0
    if args.what in ("hvac", "all"):
        hvac_experiment()
    if args.what in ("inject", "all"):
        run = run_real_world(say=print)
        print(run.markdown())
    if args.what in ("speed", "all"):
        speed()
    if args.what == "preset":
        preset_diagnosis(args.out, args.user_candidate, args.base_first)
    return 0
