"""The diagnosis: where the sim departs from recorded trips, which candidate effect explains it, how far the gap
shrinks once the effect is switched on, and what stays unexplained.

Steps of :func:`diagnose` (settings in :class:`DiagnosisSettings`):

1. the sim's floor (:mod:`.floor`) from trips the sim itself drives, reduced to the recorded trips' channels;
2. the diagnosis table of the recorded trips (:mod:`.table`): residual r = F_xV,measured - (F_xV,sim + floor);
3. the split (:func:`.selection.make_split`): held-out test segments, training segments in CV folds;
4. gap measures before (:mod:`.gap`) on the held-out part; localisation of r over the regimes
   (:mod:`.regimes`) and the residual analysis of eq. 3.4a/3.4b;
5. candidates ranked alone by out-of-fold MSE with ΔAIC/ΔBIC; greedy forward selection (:mod:`.selection`);
6. the accepted effects fitted on the whole training part (parameters with block-robust standard errors),
   mapped to simulator switches; gap measures after / remaining per regime on the held-out part;
7. the unexplained residual: regime bins of the held-out residual after the accepted effects that still depart
   from 0 by at least ``min_effect`` N, and the flexible reference's strongest regime variable when the
   reference still removes a significant part of it.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field
from typing import Callable, Sequence

import numpy as np
import pandas as pd

from roadload.trip import Trip

from .catalog import DEFAULT_CANDIDATES, get_candidate
from .errors import DiagnosisError
from .floor import SimFloor, reduce_channels
from .gap import gap_measures
from .reference import AdditiveRegimeModel
from .regimes import DEFAULT_REGIMES, get_regime, localise, residual_analysis, strongest_departures
from .selection import Selector, make_split
from .base import base_calibration, energy_base_calibration, energy_base_columns
from .robust import braking_rows, robust_target, weighted_fit
from .simconfig import SimConfig
from .stats import block_bootstrap_mean_difference
from .table import DiagnosisTable, build_table
from roadload.envs.simulator import simulate
from roadload.road_profiles import load_profile
from .energy import POWER_RESIDUAL, SIM_ELECTRIC_POWER, ELECTRIC_POWER, electric_energy_per_distance
from .selection import Split
from .stats import robust_summary

SCHEMA_VERSION = 1
FLOOR_ROADS: tuple[tuple[str, int], ...] = (("hilly", 9101), ("city", 9102), ("motorway", 9103))
RESIDUAL_SIGNALS = ("speed", "acceleration", "gradient_angle", "sim_drive_force", "sim_drive_force_rate",
                    "time_since_start", "lateral_acceleration")


@dataclass
class DiagnosisSettings:
    """Settings of :func:`diagnose`: candidate and regime names; split (segment_length [s], test_fraction,
    n_folds, block_length [s] of the bootstrap, seed); fitting (robust Huber fit, n_boot bootstrap draws);
    acceptance (min_gain: robust out-of-fold gain as a share of the sim's original robust loss, :mod:`.robust`;
    min_explained: share of the reference-removable part; n_null wild-bootstrap draws over segments and the
    family-wise level alpha the gain must beat; clip: winsorising at clip MAD scales per regime cell;
    min_size [N] / min_power_size [W]: smallest RMS of an accepted effect's fitted contribution — the robust
    loss sees offsets of a few N where cruising scatters by a few N, which is no sim-to-real gap worth a switch;
    max_effects); base_first: rank and select the effects over the calibrated base (mass, drag area, rolling
    resistance, drive-train efficiency, brake gain; :mod:`.base`) — for a preset that does not match the car;
    the base block is reported either way; joint_base (with base_first): the base is refitted jointly with every
    candidate (nested comparison base vs base + candidate, :class:`.selection.Selector`) instead of only
    subtracted before the effects are judged; min_effect [N]: smallest bin median reported as a departure /
    unexplained residual;
    floor roads (profile name, seed) and floor_duration [s] per road for the sim's own trips (none: no floor);
    resimulate: switch the identified effects on in the simulator with their fitted parameters, re-drive the
    floor trips and recompute the gap ("after, simulator"); replay: feed the recorded forces and road into the
    simulator (before, and after with the effects on) and compare the speed traces (:mod:`.replay`);
    strict_candidates: a candidate the trips lack channels for is an error (the user asked for it by name)
    instead of being skipped with the reason."""

    candidates: tuple[str, ...] = DEFAULT_CANDIDATES
    regimes: tuple[str, ...] = DEFAULT_REGIMES
    segment_length: float = 60.0
    test_fraction: float = 1 / 3
    n_folds: int = 5
    block_length: float = 10.0
    seed: int = 0
    robust: bool = True
    n_boot: int = 200
    min_gain: float = 0.02
    min_explained: float = 0.5
    max_effects: int = 3
    min_effect: float = 20.0
    n_null: int = 199
    alpha: float = 0.01
    clip: float = 5.0
    min_size: float = 15.0
    min_power_size: float = 100.0
    base_first: bool = False
    joint_base: bool = True
    floor_roads: tuple[tuple[str, int], ...] = FLOOR_ROADS
    floor_duration: float = 900.0
    resimulate: bool = True
    replay: bool = True
    strict_candidates: bool = False


@dataclass
class Diagnosis:
    """Result of :func:`diagnose`; :meth:`to_dict` is the documented diagnosis.json schema."""

    sim: dict
    trips: list[str]
    settings: dict
    split: dict
    floor: dict
    gap_before: dict
    gap_after: dict
    gap_after_sim: dict | None
    regimes_before: dict
    per_regime: list[dict]
    residual_analysis: dict
    ranking: list[dict]
    skipped: dict
    selection: list[dict]
    effects: list[dict]
    unexplained: dict
    energy: dict | None
    notes: dict
    table: DiagnosisTable | None = field(default=None, repr=False)
    residual_after: np.ndarray | None = field(default=None, repr=False)
    test_rows: np.ndarray | None = field(default=None, repr=False)

    @property
    def identified(self) -> list[str]:
        """Accepted effects: force side first, then the energy side."""
        return [e["name"] for e in self.effects] + [e["name"] for e in (self.energy or {}).get("effects", [])]

    def shrinkage(self, measure: str = "rmse", simulator: bool = False) -> float:
        """1 - gap_after / gap_before of the held-out force residual's ``measure`` (rmse, medse or |median|);
        ``simulator``: the after of the re-simulated sim with the effects switched on (NaN when not run)."""
        after = self.gap_after_sim if simulator else self.gap_after
        if after is None:
            return float("nan")
        b = self.gap_before["force_residual"][measure]
        a = after["force_residual"][measure]
        if measure == "median":
            b, a = abs(b), abs(a)
        return float(1.0 - a / b) if b > 0 else float("nan")

    def to_dict(self) -> dict:
        return _jsonable({
            "schema_version": SCHEMA_VERSION, "sim": self.sim, "trips": self.trips, "settings": self.settings,
            "split": self.split, "floor": self.floor,
            "gap": {"before": self.gap_before, "after": self.gap_after, "after_simulator": self.gap_after_sim,
                    "shrinkage": {m: self.shrinkage(m) for m in ("rmse", "medse", "median")},
                    "shrinkage_simulator": {m: self.shrinkage(m, simulator=True) for m in ("rmse", "medse", "median")},
                    "per_regime": self.per_regime},
            "regimes": self.regimes_before, "residual_analysis": self.residual_analysis,
            "ranking": self.ranking, "skipped_candidates": self.skipped, "forward_selection": self.selection,
            "effects": self.effects, "unexplained": self.unexplained, "energy_side": self.energy,
            "notes": self.notes})


def _jsonable(x):
    if isinstance(x, dict):
        return {str(k): _jsonable(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_jsonable(v) for v in x]
    if isinstance(x, (np.floating, float)):
        return None if not np.isfinite(x) else float(x)
    if isinstance(x, (np.integer,)):
        return int(x)
    if isinstance(x, np.bool_):
        return bool(x)
    if isinstance(x, np.ndarray):
        return _jsonable(x.tolist())
    return x


def sim_trips(sim: SimConfig, roads: Sequence[tuple[str, int]], duration: float,
              effects=None) -> list[Trip]:
    """Trips the sim itself drives on the given (profile, seed) roads (``effects`` overrides the sim's)."""

    out = []
    for name, seed in roads:
        trip = simulate(sim.vehicle, load_profile(name, seed=seed), sim.effects if effects is None else effects,
                        seed=seed, duration=duration)
        trip.meta["name"] = f"sim-{name}-{seed}"
        out.append(trip)
    return out


def fit_floor(sim: SimConfig, channels: set[str], settings: DiagnosisSettings,
              trips: Sequence[Trip] | None = None, extra: tuple = ()) -> SimFloor:
    """The sim's floor from its own trips reduced to ``channels`` (see :mod:`.floor`); ``extra``: (candidate,
    shape) pairs whose regressors join the floor basis."""
    if not settings.floor_roads and trips is None:
        return SimFloor.none()
    own = list(trips) if trips is not None else sim_trips(sim, settings.floor_roads, settings.floor_duration)
    own = [reduce_channels(t, channels) for t in own]
    tab = build_table(own, sim)
    f = tab.frame
    return SimFloor.fit(f, f["sim_balance"].to_numpy(), f["residual"].to_numpy(), f["valid"].to_numpy(bool),
                        extra=extra, model=tab.model)


def switched_on(sim: SimConfig, effects: Sequence[dict]) -> SimConfig | None:
    """The sim with every identified effect's simulator switch on (None when one has no switch)."""
    out = sim
    for e in effects:
        if not e.get("sim_switch") or e.get("sim_parameters") is None:
            return None
        out = out.with_effect(e["sim_switch"], e["sim_parameters"])
    return out


def plausibility_check(sim: SimConfig, model) -> Callable:
    """(candidate, fitted parameters, shape) -> None when the simulator switch takes the fitted value, else the
    reason (e.g. the spec field's physical range it leaves): such a fit is reported, never accepted, never an
    abort."""

    def check(cand, params: dict, shape) -> str | None:
        if cand.sim_effect is None:
            return None
        try:
            sp = cand.sim_parameters(params, shape, model)
        except (KeyError, ValueError, ZeroDivisionError) as exc:
            return f"no simulator setting for the fitted values ({exc})"
        if sp is None:
            return None
        bad = {k: v for k, v in sp.items() if isinstance(v, float) and not np.isfinite(v)}
        if bad:
            return f"non-finite simulator parameters {bad}"
        try:
            sim.with_effect(cand.sim_effect, sp)
        except (DiagnosisError, ValueError, TypeError) as exc:
            return f"fitted {params} switch {cand.sim_effect} by {sp}: {exc}"
        return None

    return check


def _per_regime(table: pd.DataFrame, before: np.ndarray, after: np.ndarray, rows: np.ndarray,
                regimes: Sequence[str]) -> list[dict]:
    out = []
    for name in regimes:
        reg = get_regime(name)
        if reg.column not in table.columns:
            continue
        idx = reg.assign(table)
        for i, label in enumerate(reg.bin_labels()):
            sel = rows & (idx == i)
            if sel.sum() < 20:
                continue
            b = float(np.sqrt(np.mean(before[sel] ** 2)))
            a = float(np.sqrt(np.mean(after[sel] ** 2)))
            out.append({"regime": reg.name, "bin": label, "n": int(sel.sum()), "rmse_before": b, "rmse_after": a,
                        "median_before": float(np.median(before[sel])), "median_after": float(np.median(after[sel])),
                        "remaining": a / b if b > 0 else float("nan")})
    return out


def _unexplained(table: pd.DataFrame, residual_after: np.ndarray, split, settings: DiagnosisSettings,
                 rng: np.random.Generator, mse_before: float) -> dict:
    """Held-out bins still departing after the accepted effects, and whether the flexible reference still
    removes a significant part (at least min_gain of the held-out MSE before) — with its strongest regimes."""
    test = split.test
    tabs = localise(np.where(test, residual_after, np.nan), table, split.blocks, settings.regimes, rng,
                    n_boot=settings.n_boot, min_effect=settings.min_effect)
    departures = strongest_departures(tabs, top=8)
    # does a flexible reference still find structure? fitted on training, judged on the held-out rows
    train = split.train
    ref = AdditiveRegimeModel().fit(table[train], residual_after[train])
    pred = ref.predict(table)
    loss0 = np.where(test, residual_after ** 2, np.nan)
    loss1 = np.where(test, (residual_after - pred) ** 2, np.nan)
    gain = block_bootstrap_mean_difference(loss0, loss1, split.blocks, rng, settings.n_boot)
    rel = gain[0] / mse_before if mse_before > 0 else 0.0
    structured = bool(gain[1] > 0 and rel >= settings.min_gain)
    importance = ref.importance(table[test]) if structured else []
    return {"present": bool(departures) or structured, "departing_bins": departures,
            "reference_gain": {"relative": rel, "interval": list(gain), "significant": structured},
            "reference_importance": importance[:5],
            "rms_after": float(np.sqrt(np.nanmean(loss0)))}


def _energy_side(table: pd.DataFrame, split, settings: DiagnosisSettings, model, plausible=None) -> dict | None:
    """The battery-power residual (:mod:`.energy`): gap before/after, ranking and forward selection of the
    power-side candidates on the same split; None without battery power."""

    pr = table[POWER_RESIDUAL].to_numpy(dtype=float)
    ok = np.isfinite(pr)
    names = [n for n in settings.candidates if get_candidate(n).side == "power"]
    if not names or (ok & split.valid).sum() < 100:
        return None
    sp = Split(split.valid & ok, split.test & ok, np.where(ok, split.fold, -1), split.n_folds, split.blocks,
               split.segments)
    y = np.where(ok, pr, 0.0)
    base_A = None
    if settings.base_first:
        # base mismatch first: the energy base block (auxiliary power, motor efficiency, torque-signal gain) is
        # fitted and subtracted, and refitted jointly with every power-side candidate (nested comparison)
        braking = braking_rows(table)
        base_A = np.where(braking[:, None], 0.0, np.nan_to_num(energy_base_columns(table)))
        x_b = weighted_fit(base_A, y, np.ones(len(y)), sp.train)
        y = y - base_A @ x_b
    sel = Selector(table, y, sp, model, robust=settings.robust, n_boot=settings.n_boot,
                   seed=settings.seed, min_gain=settings.min_gain, min_explained=settings.min_explained, side="power",
                   n_null=settings.n_null, alpha=settings.alpha, clip=settings.clip, plausible=plausible,
                   min_size=settings.min_power_size, base_design=base_A)
    ranked, skipped = sel.rank(names)
    steps = sel.forward(ranked, max_effects=settings.max_effects)
    after = y.copy()
    effects = []
    if sel.chosen:
        d, fit = sel.final_fit(sel.chosen)
        after = after - (sel.fitted_columns(d) if sel.base_design is not None else d.A) @ fit.X
        se = np.sqrt(np.clip(np.diag(fit.cov), 0, None)) if fit.cov is not None else np.full(fit.X.size, np.nan)
        for cand, shape in sel.chosen:
            own = [i for i, o in enumerate(d.owner) if o == cand.name]
            params = {d.names[i]: float(fit.X[i]) for i in own}
            effects.append({"name": cand.name, "parameters": params,
                            "std_errors": {d.names[i]: float(se[i]) for i in own},
                            "units": {d.names[i]: d.units[i] for i in own}, "sim_switch": cand.sim_effect,
                            "sim_parameters": cand.sim_parameters(params, shape, model)})
    test = sp.test
    measured = table[ELECTRIC_POWER].to_numpy(dtype=float)
    sim_p = table[SIM_ELECTRIC_POWER].to_numpy(dtype=float)
    e_meas = electric_energy_per_distance(table, measured, test)
    e_before = electric_energy_per_distance(table, sim_p, test)
    e_after = electric_energy_per_distance(table, measured - after, test)
    return {"power_residual_before": robust_summary(pr[test]), "power_residual_after": robust_summary(after[test]),
            "base_calibration": energy_base_calibration(table, np.where(ok, pr, np.nan), sp,
                                                        settings.min_power_size),
            "electric_energy_per_distance": {"measured": e_meas, "sim_before": e_before, "sim_after": e_after,
                                             "unit": "kWh/100 km (while moving)"},
            "ranking": [r.to_dict() for r in ranked], "skipped_candidates": skipped, "forward_selection": steps,
            "effects": effects}


def diagnose(real: Sequence[Trip], sim: SimConfig, settings: DiagnosisSettings | None = None,
             floor_trips: Sequence[Trip] | None = None, floor: SimFloor | None = None,
             progress: Callable[[str, float], None] | None = None) -> Diagnosis:
    """Diagnose ``sim`` against the recorded trips ``real`` (see module doc)."""
    settings = settings or DiagnosisSettings()
    step = progress or (lambda what, frac: None)
    for name in settings.candidates:
        get_candidate(name)
    for name in settings.regimes:
        get_regime(name)
    if not real:
        raise DiagnosisError("no recorded trips given")
    channels = set.intersection(*[set(t.channels) for t in real])
    step("sim floor", 0.05)
    if floor is None:
        floor = fit_floor(sim, channels, settings, floor_trips)
    step("diagnosis table", 0.25)
    dt = build_table(real, sim, floor=floor)
    table = dt.frame
    model = dt.model
    split = make_split(table, segment_length=settings.segment_length, test_fraction=settings.test_fraction,
                       n_folds=settings.n_folds, block_length=settings.block_length, seed=settings.seed)
    rng = np.random.default_rng(settings.seed)
    r = np.where(split.valid, table["residual"].to_numpy(dtype=float), np.nan)
    test = split.test
    step("gap and regimes", 0.35)
    gap_before = gap_measures(table, np.nan_to_num(r), model.mass, test, replay_sim=sim if settings.replay else None)
    regs = localise(r, table, split.blocks, settings.regimes, rng, n_boot=settings.n_boot,
                    min_effect=settings.min_effect)
    valid = split.valid
    signals = {c: table[c].to_numpy(dtype=float)[valid] for c in RESIDUAL_SIGNALS if c in table.columns}
    ra = residual_analysis(r[valid], signals, table["trip"].to_numpy()[valid], max_lag=20)
    step("ranking candidates", 0.45)
    plausible = plausibility_check(sim, model)
    step("base calibration", 0.42)
    y_sel = np.nan_to_num(r)
    target0 = robust_target(table, y_sel, split.train, split.segments, split.fold, split.n_folds,
                            clip=settings.clip)
    base, base_A = base_calibration(table, target0, split, model, min_size=settings.min_size)
    base["used_for_effects"] = settings.base_first
    if settings.base_first and base_A.shape[1]:
        x_base = np.array([p_["value"] for p_ in base["parameters"] if p_.get("in_fit", True)])
        y_sel = y_sel - base_A @ x_base
    sel = Selector(table, y_sel, split, model, robust=settings.robust, n_boot=settings.n_boot,
                   seed=settings.seed, min_gain=settings.min_gain, min_explained=settings.min_explained,
                   n_null=settings.n_null, alpha=settings.alpha, clip=settings.clip, plausible=plausible,
                   min_size=settings.min_size,
                   base_design=base_A if (settings.base_first and settings.joint_base) else None)
    explicit = settings.strict_candidates
    ranked, skipped = sel.rank([n for n in settings.candidates if get_candidate(n).side == "force"])
    if explicit:
        bad = {k: v for k, v in skipped.items() if "needs" in v}
        if bad:
            raise DiagnosisError("requested candidates cannot be fitted on these trips: "
                                 + "; ".join(f"{k} {v}" for k, v in bad.items()))
    step("forward selection", 0.7)
    steps = sel.forward(ranked, max_effects=settings.max_effects)
    chosen = sel.chosen
    effects: list[dict] = []
    r_after = y_sel.copy()
    if chosen:
        d, fit = sel.final_fit(chosen)
        # jointly with the base: predict with the design as fitted (the base says nothing on braking rows, so an
        # effect's coefficients, conditional on it, are not extrapolated there)
        r_after = y_sel - (sel.fitted_columns(d) if sel.base_design is not None else d.A) @ fit.X
        se = np.sqrt(np.clip(np.diag(fit.cov), 0, None)) if fit.cov is not None else np.full(fit.X.size, np.nan)
        for cand, shape in chosen:
            own = [i for i, o in enumerate(d.owner) if o == cand.name]
            params = {d.names[i]: float(fit.X[i]) for i in own}
            step_info = next(s for s in steps if s["effect"] == cand.name)
            effects.append({"name": cand.name, "description": cand.description, "shape": shape,
                            "shape_name": cand.shape_name, "shape_unit": cand.shape_unit, "parameters": params,
                            "std_errors": {d.names[i]: float(se[i]) for i in own},
                            "units": {d.names[i]: d.units[i] for i in own},
                            "heldout_gain": step_info["gain_of_original"], "null_p": step_info["null_p"],
                            "explained_fraction": step_info["explained_fraction"],
                            "sim_switch": cand.sim_effect,
                            "sim_parameters": cand.sim_parameters(params, shape, model)})
    energy = _energy_side(table, split, settings, model, plausible)
    power_asked = [n for n in settings.candidates if get_candidate(n).side == "power"]
    if explicit and power_asked and energy is None:
        raise DiagnosisError(f"requested energy-side candidates {power_asked} need battery_voltage and "
                             f"battery_current on the trips and a battery-electric sim vehicle")
    step("gap after", 0.85)
    gap_after = gap_measures(table, r_after, model.mass, test)
    gap_after_sim = None
    resim_note = "not asked (--no-resimulate)" if not settings.resimulate else ""
    if settings.resimulate and effects and not floor.is_none:
        # never abort here: the diagnosis above is complete; a failing re-simulation is a note in the report
        try:
            sim_after = switched_on(sim, effects)
            if sim_after is None:
                resim_note = "an accepted effect has no simulator switch"
            else:
                step("re-simulating with the effects on", 0.88)
                extra = tuple((c.name, sh) for c, sh in chosen)
                floor_after = fit_floor(sim_after, channels, settings, extra=extra)
                t_after = build_table(real, sim_after, floor=floor_after).frame
                if len(t_after) == len(table):
                    r_sim = np.where(split.valid, t_after["residual"].to_numpy(dtype=float), 0.0)
                    gap_after_sim = gap_measures(t_after, np.nan_to_num(r_sim), model.mass, test,
                                                 replay_sim=sim_after if settings.replay else None)
                    gap_after_sim["sim"] = sim_after.to_dict()
                    resim_note = "done"
                else:
                    resim_note = "the re-simulated table differs in length; skipped"
        except (DiagnosisError, ValueError) as exc:
            resim_note = f"failed, diagnosis kept: {exc}"
    per_regime = _per_regime(table, np.nan_to_num(r), r_after, test, settings.regimes)
    unexplained = _unexplained(table, np.where(valid, r_after, np.nan), split, settings, rng,
                               float(gap_before["force_residual"]["rmse"]) ** 2)
    regimes_before = {k: v.rows for k, v in regs.items()}
    diag = Diagnosis(
        sim=sim.to_dict(), trips=list(pd.unique(table["trip"])), settings=asdict(settings), split=split.describe(),
        floor=floor.to_dict(), gap_before=gap_before, gap_after=gap_after, gap_after_sim=gap_after_sim,
        regimes_before=regimes_before,
        per_regime=per_regime, residual_analysis=ra, ranking=[c.to_dict() for c in ranked], skipped=skipped,
        selection=steps, effects=effects, unexplained=unexplained, energy=energy,
        notes={"pipeline": dt.notes, "baseline": sel.baseline_info, "resimulation": resim_note,
               "base_calibration": base,
               "implausible": [{"effect": s_["effect"], "reason": s_["implausible"]} for s_ in steps
                               if s_.get("implausible")],
               "strongest_departures_before": strongest_departures(regs, top=8)},
        table=dt, residual_after=r_after, test_rows=test)
    step("done", 1.0)
    return diag
