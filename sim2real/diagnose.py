"""The diagnosis: where the sim departs from recorded trips, which candidate effect explains it, how far the gap
shrinks once the effect is switched on, and what stays unexplained.

:func:`diagnose` is a pipeline of named stages, each a function with a typed result (settings in
:class:`DiagnosisSettings`, the result a :class:`.results.Diagnosis`):

1. **table** (:func:`stage_table`): the recorded trips through the chapter-5 pipeline with the sim's knowledge
   (:mod:`.table`): measured force F_xV,measured and the sim's balance F_xV,sim per 10 Hz sample;
2. **split** (:func:`stage_split`): held-out test segments, training segments in CV folds (:mod:`.selection`);
3. **floor** (:func:`stage_floor`): the sim's floor from trips the sim itself drives, reduced to the recorded
   trips' channels (:mod:`.floor`), added to the sim side: r = F_xV,measured - (F_xV,sim + floor);
4. **gap** (:func:`stage_gap`): gap measures before on the held-out part (:mod:`.gap`), localisation of r over
   the regimes and the residual analysis of eq. 3.4a/3.4b (:mod:`.regimes`);
5. **base** (:func:`stage_base`): the force and energy base blocks (:mod:`.base`); with ``base_first`` the effects
   are judged over them;
6. **rank** (:func:`stage_rank`): every candidate alone by its robust out-of-fold gain with ΔAIC/ΔBIC, per side
   (force, battery power);
7. **select** (:func:`stage_select`): greedy forward selection; the accepted effects fitted on the whole training
   part (parameters with block-robust standard errors) and mapped to simulator switches;
8. **re-simulate** (:func:`stage_resimulate`): the accepted effects switched on in the simulator, the floor trips
   re-driven and the gap recomputed ("after, simulator");
9. **report** (:func:`stage_report`): gap after and per regime on the held-out part; the unexplained residual
   (regime bins still departing by at least ``min_effect`` N, the flexible reference's strongest regime variable
   when it still removes a significant part); the :class:`.results.Diagnosis`.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable, Sequence

import numpy as np
import pandas as pd

from roadload.envs.simulator import simulate
from roadload.road_profiles import load_profile
from roadload.trip import Trip

from .base import Z_SIGNIFICANT, BaseBlock, base_calibration, energy_base_calibration
from .catalog import DEFAULT_CANDIDATES, DRIVE_FORCE, get_candidate
from .energy import (ELECTRIC_POWER, POWER_RESIDUAL, SIM_ELECTRIC_POWER, SPEED_DERIVED,
                     electric_energy_per_distance, energy_columns)
from .errors import DiagnosisError
from .floor import SimFloor, reduce_channels
from .forcemodel import columns_of
from .held import separability_check
from .gap import GapMeasures, gap_measures
from .pertrip import per_trip_sizes
from .records import RobustSummary
from .reference import AdditiveRegimeModel
from .regimes import (DEFAULT_REGIMES, RegimeTable, ResidualCorrelation, get_regime, localise, residual_analysis,
                      strongest_departures)
from .results import (Diagnosis, Effect, ElectricEnergy, EnergySide, Implausible, Notes, ReferenceGain,
                      Unexplained, per_regime_gap)
from .robust import braking_rows, robust_target, weighted_fit
from .selection import CandidateResult, SelectionStep, Selector, Split, design, fitted_parameters, make_split
from .simconfig import SimConfig
from .stats import block_bootstrap_mean_difference
from .table import DiagnosisTable, build_table, finish_table

__all__ = ["Diagnosis", "DiagnosisSettings", "diagnose", "fit_floor", "plausibility_check", "sim_trips",
           "switched_on"]

FLOOR_ROADS: tuple[tuple[str, int], ...] = (("hilly", 9101), ("city", 9102), ("motorway", 9103))
RESIDUAL_SIGNALS = ("speed", "acceleration", "gradient_angle", "sim_drive_force", "sim_drive_force_rate",
                    "time_since_start", "lateral_acceleration")
#: the stages of :func:`diagnose` and the progress fraction at which each starts (monotone)
STAGES: tuple[tuple[str, float], ...] = (
    ("table", 0.0), ("split", 0.2), ("floor", 0.22), ("gap", 0.4), ("base", 0.5), ("rank", 0.55),
    ("select", 0.7), ("re-simulate", 0.85), ("report", 0.95))


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
    instead of being skipped with the reason; energy_consistency: a force-side effect must agree with the
    drive-torque signal gain the battery power shows (:func:`energy_consistency`), and a power-side signal effect
    with the drive-torque gain the force residual shows (:func:`force_consistency`; neither with base_first);
    elevation_consistency: an accelerometer bias must agree with the one the logged elevation shows
    (:func:`elevation_consistency`)."""

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
    energy_consistency: bool = True
    elevation_consistency: bool = True


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
              trips: Sequence[Trip] | None = None, extra: tuple = (), rate: float | None = None) -> SimFloor:
    """The sim's floor from its own trips reduced to ``channels`` and to the recorded trips' sample ``rate`` [Hz]
    (see :mod:`.floor`); ``extra``: (candidate, shape) pairs whose regressors join the floor basis."""
    if not settings.floor_roads and trips is None:
        return SimFloor.none()
    own = list(trips) if trips is not None else sim_trips(sim, settings.floor_roads, settings.floor_duration)
    own = [reduce_channels(t, channels, rate) for t in own]
    tab = build_table(own, sim)
    f = tab.frame
    return SimFloor.fit(f, f["sim_balance"].to_numpy(), f["residual"].to_numpy(), f["valid"].to_numpy(bool),
                        extra=extra, model=tab.model)


def switched_on(sim: SimConfig, effects: Sequence[Effect]) -> SimConfig | None:
    """The sim with every identified effect's simulator switch on (None when one has no switch)."""
    out = sim
    for e in effects:
        if not e.sim_switch or e.sim_parameters is None:
            return None
        out = out.with_effect(e.sim_switch, e.sim_parameters)
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


# ============================================================================================ the stages
@dataclass
class Run:
    """What every stage reads: the recorded trips, the sim, the settings, the seeded generator of the
    localisation bootstraps (the gap stage draws first, the report stage after it) and the progress callback."""

    real: Sequence[Trip]
    sim: SimConfig
    settings: DiagnosisSettings
    rng: np.random.Generator
    progress: Callable[[str, float], None]

    def stage(self, name: str) -> None:
        """Report the start of stage ``name`` (fractions of :data:`STAGES`, never backwards)."""
        self.progress(name, dict(STAGES)[name])

    @property
    def channels(self) -> set[str]:
        return set.intersection(*[set(t.channels) for t in self.real])

    @property
    def rate(self) -> float:
        """The recorded trips' sample rate [Hz] (the lowest: the sim's floor trips are taken down to it)."""
        return float(min(t.sample_rate for t in self.real))


def stage_table(run: Run) -> DiagnosisTable:
    """Stage 1: the diagnosis table of the recorded trips against the sim's balance, without the floor."""
    run.stage("table")
    return build_table(run.real, run.sim)


def stage_split(run: Run, table: DiagnosisTable) -> Split:
    """Stage 2: training / held-out segments and CV folds (:func:`.selection.make_split`)."""
    run.stage("split")
    s = run.settings
    return make_split(table.frame, segment_length=s.segment_length, test_fraction=s.test_fraction,
                      n_folds=s.n_folds, block_length=s.block_length, seed=s.seed)


@dataclass
class FloorStage:
    """The sim's floor, the table with it added to the sim side, and the residual r [N] (NaN off valid rows)."""

    floor: SimFloor
    table: DiagnosisTable
    residual: np.ndarray


def stage_floor(run: Run, table: DiagnosisTable, split: Split, floor: SimFloor | None,
                floor_trips: Sequence[Trip] | None) -> FloorStage:
    """Stage 3: the sim's floor (fitted on its own trips unless given) added to the table's sim side."""
    run.stage("floor")
    if floor is None:
        floor = fit_floor(run.sim, run.channels, run.settings, floor_trips, rate=run.rate)
    with_floor = finish_table(table.frame, table.model, table.notes, floor, table.trips)
    r = np.where(split.valid, with_floor.frame["residual"].to_numpy(dtype=float), np.nan)
    return FloorStage(floor, with_floor, r)


@dataclass
class GapStage:
    """The gap before on the held-out rows, the residual per regime bin and the residual analysis."""

    gap_before: GapMeasures
    regimes: dict[str, RegimeTable]
    residual_analysis: dict[str, ResidualCorrelation]


def stage_gap(run: Run, fl: FloorStage, split: Split) -> GapStage:
    """Stage 4: where the gap lies (held-out gap measures, regimes, eq. 3.4a/3.4b)."""
    run.stage("gap")
    s = run.settings
    table, r = fl.table.frame, fl.residual
    gap_before = gap_measures(table, np.nan_to_num(r), fl.table.model.mass, split.test,
                              replay_sim=run.sim if s.replay else None)
    regs = localise(r, table, split.blocks, s.regimes, run.rng, n_boot=s.n_boot, min_effect=s.min_effect)
    valid = split.valid
    signals = {c: table[c].to_numpy(dtype=float)[valid] for c in RESIDUAL_SIGNALS if c in table.columns}
    ra = residual_analysis(r[valid], signals, table["trip"].to_numpy()[valid], max_lag=20)
    return GapStage(gap_before, regs, ra)


@dataclass
class SideInput:
    """What one side's selection judges: its split, the residual y (N or W; with ``base_first`` net of the base
    block) and the base design refitted jointly with every candidate (None: not joint)."""

    split: Split
    residual: np.ndarray
    base_design: np.ndarray | None


@dataclass
class BaseStage:
    """The force base block and the force side's input; the energy base block and the energy side's input (None
    without battery power or energy-side candidates)."""

    force_block: BaseBlock
    force: SideInput
    energy_block: BaseBlock | None
    energy: SideInput | None
    energy_residual: np.ndarray | None


def stage_base(run: Run, fl: FloorStage, split: Split) -> BaseStage:
    """Stage 5: the base blocks (:mod:`.base`); with ``base_first`` the residual the effects are judged on is net
    of them, and with ``joint_base`` (force side) their columns are refitted with every candidate."""
    run.stage("base")
    s = run.settings
    table = fl.table.frame
    y = np.nan_to_num(fl.residual)
    target0 = robust_target(table, y, split.train, split.segments, split.fold, split.n_folds, clip=s.clip)
    block, base_A = base_calibration(table, target0, split, fl.table.model, min_size=s.min_size)
    block.used_for_effects = s.base_first
    if s.base_first and base_A.shape[1]:
        x_base = np.array([p.value for p in block.parameters if p.in_fit is not False])
        y = y - base_A @ x_base
    force = SideInput(split, y, base_A if (s.base_first and s.joint_base) else None)
    energy_block, energy, pr = _energy_base(table, split, s, run.sim)
    return BaseStage(block, force, energy_block, energy, pr)


def _energy_base(table: pd.DataFrame, split: Split, s: DiagnosisSettings, sim: SimConfig
                 ) -> tuple[BaseBlock | None, SideInput | None, np.ndarray | None]:
    """The energy base block and the energy side's input: rows with a battery-power residual; with
    ``base_first`` the energy base (auxiliary power, motor efficiency, torque-signal gain) is fitted, subtracted
    and refitted jointly with every power-side candidate (nested comparison)."""
    pr = table[POWER_RESIDUAL].to_numpy(dtype=float)
    ok = np.isfinite(pr)
    names = [n for n in s.candidates if get_candidate(n).side == "power"]
    if not names or (ok & split.valid).sum() < 100:
        return None, None, None
    sp = Split(split.valid & ok, split.test & ok, np.where(ok, split.fold, -1), split.n_folds, split.blocks,
               split.segments)
    y = np.where(ok, pr, 0.0)
    base_A = None
    if s.base_first:
        braking = braking_rows(table)
        base_A = np.where(braking[:, None], 0.0, energy_columns(table, sim.vehicle))
        x_b = weighted_fit(base_A, y, np.ones(len(y)), sp.train)
        y = y - base_A @ x_b
    block = energy_base_calibration(table, np.where(ok, pr, np.nan), sp, sim.vehicle, s.min_power_size, s.clip)
    return block, SideInput(sp, y, base_A), pr


@dataclass
class RankStage:
    """Per side the selector (its statistics and null), the candidates ranked alone and the skipped ones."""

    force: Selector
    force_ranked: list[CandidateResult]
    force_skipped: dict[str, str]
    energy: Selector | None = None
    energy_ranked: list[CandidateResult] = field(default_factory=list)
    energy_skipped: dict[str, str] = field(default_factory=dict)


def _selector(run: Run, table: DiagnosisTable, side: SideInput, name: str, min_size: float,
              consistent: Callable | None = None) -> Selector:
    s = run.settings
    return Selector(table.frame, side.residual, side.split, table.model, robust=s.robust, n_boot=s.n_boot,
                    seed=s.seed, min_gain=s.min_gain, min_explained=s.min_explained, side=name, n_null=s.n_null,
                    alpha=s.alpha, clip=s.clip, plausible=plausibility_check(run.sim, table.model),
                    min_size=min_size, base_design=side.base_design, consistent=consistent)


def energy_consistency(block: BaseBlock | None, table: pd.DataFrame, split: Split, settings: DiagnosisSettings,
                       held: dict[str, float] | None = None) -> Callable | None:
    """The force side's check against the battery power (None without it, or with the base calibrated first):
    P_el,sim is computed from the logged torque and motor speed, so the energy base block's signed -T_E ω_E term
    measures the drive-torque signal gain ĝ (a speed-signal scale too where the motor speed comes from the
    vehicle speed). A force-side candidate is inconsistent when the gain its fit implies
    (:meth:`.catalog.CandidateEffect.torque_signal_gain`: 0 for a physical effect such as a mass or drag change)
    differs from ĝ by >= 2.58 standard errors and that difference, as a force ĝ F_drive (the force the drive
    torque delivers, :mod:`.table`), is at least the size
    gate and half the candidate's own fitted effect: a payload then cannot stand in for a torque signal reading
    high, which scales the measured force the same way. ``held``: the calibrated sim's held directions
    (:attr:`.simconfig.SimConfig.held_at_bound`); no check where the calibration kept the torque signal at the
    sim's against a gain its reference trips' battery power showed (then that term measures no signal)."""
    p = block.parameter("torque_scale") if block is not None else None
    if p is None or not np.isfinite(p.std_error) or not settings.energy_consistency or settings.base_first:
        return None
    if held and "torque_signal_gain" in held:
        # the calibration kept the torque signal at the sim's although its reference trips' battery power showed
        # a gain: calibrating it from the battery power left more of the held-out gap (:func:`.calibrate.calibrate`),
        # so on this car the battery power's -T ω term is a motor-loss shape the loss map lacks (FASTSim's
        # efficiency over the power fraction), which moves with the driving (-0.055 on FASTSim's reference trips,
        # -0.02 to -0.044 on other trips of the same car), not a measurement of the torque signal
        return None
    g_hat, se = p.value, p.std_error          # the block's coefficient of -T ω is g
    speed_derived = bool(table[SPEED_DERIVED].any()) if SPEED_DERIVED in table else False
    f = np.nan_to_num(table[DRIVE_FORCE].to_numpy(dtype=float))[split.train]
    rms_f = float(np.sqrt(np.mean(f ** 2))) if f.size else 0.0

    def check(cand, params: dict, shape, size: float) -> str | None:
        implied = cand.torque_signal_gain(params, shape, speed_derived)
        diff = g_hat - implied
        force = abs(diff) * rms_f
        if abs(diff) >= Z_SIGNIFICANT * se and force >= max(settings.min_size, 0.5 * size):
            return (f"inconsistent with the battery power: it shows a drive-torque signal gain of {g_hat:+.3f} ± "
                    f"{se:.3f} where {cand.name} implies {implied:+.3f} (a {force:.0f} N force effect unexplained)")
        return None

    return check


ACCEL_BIAS_PARAMETER = "accelerometer bias b"


def elevation_consistency(block: BaseBlock | None, sim: SimConfig, mass: float, settings: DiagnosisSettings
                          ) -> Callable | None:
    """The force side's check of ``accel_bias`` against the logged elevation (None without one, or with the base
    calibrated first): a bias b of the accelerometer turns the eq. 5.2 grade by b/g, which the climb against the
    logged elevation measures independently of the force balance (:func:`.base.accelerometer_bias_from_elevation`,
    on the same grade column); the sim's own accelerometer bias (a calibration writes the reference trips' into
    the spec) is in the sim's floor, so the bias the trips show beyond the sim is b̂ - b_sim. ``accel_bias`` is
    inconsistent when its fitted b differs from that by >= 2.58 standard errors and by at least the size gate and
    half its own fitted effect as a force m_V |Δb|: a constant force of another cause (more rolling resistance)
    then cannot pass as a bias the elevation does not show."""
    p = block.parameter("accel_bias") if block is not None else None
    if p is None or not np.isfinite(p.std_error) or not settings.elevation_consistency or settings.base_first:
        return None
    channel = sim.vehicle.sensors.channels.get("accel_x")
    b_hat, se = p.value - (channel.bias if channel is not None else 0.0), p.std_error

    def check(cand, params: dict, shape, size: float) -> str | None:
        if cand.name != "accel_bias" or ACCEL_BIAS_PARAMETER not in params:
            return None
        b = params[ACCEL_BIAS_PARAMETER]
        force = abs(b - b_hat) * mass
        if abs(b - b_hat) >= Z_SIGNIFICANT * se and force >= max(settings.min_size, 0.5 * size):
            return (f"inconsistent with the logged elevation: it shows an accelerometer bias of {b_hat:+.4f} ± "
                    f"{se:.4f} m/s^2 beyond the sim's where accel_bias fits {b:+.4f} (a {force:.0f} N force effect "
                    "unexplained)")
        return None

    return check


TORQUE_SCALE_PARAMETER = "torque scale error epsilon"


def force_consistency(ranked: Sequence[CandidateResult], table: pd.DataFrame, split: Split, model,
                      settings: DiagnosisSettings) -> Callable | None:
    """The energy side's check against the force residual (None without a force-side ``torque_scale`` fit, or with
    the base calibrated first): a power-side signal effect (``force_twin``, :mod:`.catalog`) must agree with the
    drive-torque gain ĝ_F the force residual shows (the ranked ``torque_scale`` fit alone). Its twin's force
    signature at the fitted value, projected on the drive force, is the gain it implies (a torque signal gain g:
    g; a speed-signal scale: the small part of s (m_rot v̇ + v dF_road/dv) along F_drive); it is inconsistent
    when that differs from ĝ_F by >= 2.58 standard errors and by at least the size gate and half the twin's
    own force as a force |Δg| F_drive: on the i3 (motor speed from the vehicle speed) a speed signal reading
    high and a torque signal reading high raise P_el,sim alike, and only the force side tells them apart."""
    ref = next((r for r in ranked if r.name == "torque_scale"), None)
    if ref is None or not settings.energy_consistency or settings.base_first:
        return None
    g_f, se = ref.parameters.get(TORQUE_SCALE_PARAMETER), ref.std_errors.get(TORQUE_SCALE_PARAMETER)
    if g_f is None or se is None or not np.isfinite(se):
        return None
    tr = split.train
    cols = columns_of(table)
    f = np.nan_to_num(table[DRIVE_FORCE].to_numpy(dtype=float))[tr]
    ff = float(f @ f)
    if not ff > 0:
        return None
    rms_f = float(np.sqrt(ff / f.size))

    def check(cand, params: dict, shape, size: float) -> str | None:
        if cand.force_twin is None or len(params) != 1:
            return None
        c = design([(get_candidate(cand.force_twin), None)], model, cols).A[tr, 0] * float(next(iter(params.values())))
        implied = float(c @ f) / ff
        diff = g_f - implied
        force = abs(diff) * rms_f
        if abs(diff) >= Z_SIGNIFICANT * se and force >= max(settings.min_size, 0.5 * float(np.sqrt(np.mean(c ** 2)))):
            return (f"inconsistent with the force residual: it shows a drive-torque gain of {g_f:+.3f} ± {se:.3f} "
                    f"where {cand.name} implies {implied:+.3f} (a {force:.0f} N force effect unexplained)")
        return None

    return check


def chained(*checks: Callable | None) -> Callable | None:
    """The acceptance checks (candidate, parameters, shape, size) -> reason | None run in turn: the first reason
    wins (None when no check is given)."""
    live = [c for c in checks if c is not None]
    if not live:
        return None

    def check(cand, params: dict, shape, size: float) -> str | None:
        return next((r for r in (c(cand, params, shape, size) for c in live) if r is not None), None)

    return check


def _side_candidates(settings: DiagnosisSettings, side: str) -> list[str]:
    return [n for n in settings.candidates if get_candidate(n).side == side]


def stage_rank(run: Run, fl: FloorStage, base: BaseStage) -> RankStage:
    """Stage 6: every candidate alone, per side (DiagnosisError with ``strict_candidates`` when a requested one
    cannot be fitted on these trips)."""
    run.stage("rank")
    s = run.settings
    frame, model = fl.table.frame, fl.table.model
    held = run.sim.held_at_bound
    sel = _selector(run, fl.table, base.force, "force", s.min_size, chained(
        energy_consistency(base.energy_block, frame, base.force.split, s, held),
        elevation_consistency(base.force_block, run.sim, model.mass, s),
        separability_check(held, frame, base.force.split.train, model, run.sim.vehicle, "force")))
    ranked, skipped = sel.rank(_side_candidates(s, "force"))
    out = RankStage(sel, ranked, skipped)
    if s.strict_candidates:
        bad = {k: v for k, v in skipped.items() if "needs" in v}
        if bad:
            raise DiagnosisError("requested candidates cannot be fitted on these trips: "
                                 + "; ".join(f"{k} {v}" for k, v in bad.items()))
    power_asked = _side_candidates(s, "power")
    if base.energy is None:
        if s.strict_candidates and power_asked:
            raise DiagnosisError(f"requested energy-side candidates {power_asked} need battery_voltage and "
                                 f"battery_current on the trips and a battery-electric sim vehicle")
        return out
    out.energy = _selector(run, fl.table, base.energy, "power", s.min_power_size, chained(
        force_consistency(ranked, frame, base.force.split, model, s),
        separability_check(held, frame, base.energy.split.train, model, run.sim.vehicle, "power")))
    out.energy_ranked, out.energy_skipped = out.energy.rank(power_asked)
    return out


def accepted_effects(sel: Selector, steps: list[SelectionStep], alpha: float = 0.01
                     ) -> tuple[list[Effect], np.ndarray]:
    """The effects the selector accepted, fitted jointly on the training rows (with the base when it is refitted
    jointly: predicted with the design as fitted, so the base says nothing on braking rows and an effect's
    coefficients, conditional on it, are not extrapolated there), and the residual after them (one builder for
    the force and the energy side); each with its sizes per trip (:mod:`.pertrip`)."""
    y = sel.residual
    if not sel.chosen:
        return [], y.copy()
    d, fit = sel.final_fit(sel.chosen)
    after = y - (sel.fitted_columns(d) if sel.base_design is not None else d.A) @ fit.X
    effects = []
    for cand, shape in sel.chosen:
        params, errors, units = fitted_parameters(d, fit, cand.name)
        step = next(st for st in steps if st.effect == cand.name)
        effects.append(Effect(cand.name, cand.description, shape, cand.shape_name, cand.shape_unit, params, errors,
                              units, step.gain_of_original, step.null_p, step.explained_fraction, cand.sim_effect,
                              cand.sim_parameters(params, shape, sel.model),
                              per_trip_sizes(sel, sel.chosen, cand.name, alpha)))
    return effects, after


@dataclass
class SelectStage:
    """Force side: the forward-selection steps, the accepted effects and the residual after them [N]; the energy
    side as reported (None without battery power)."""

    steps: list[SelectionStep]
    effects: list[Effect]
    residual_after: np.ndarray
    energy: EnergySide | None


def stage_select(run: Run, fl: FloorStage, base: BaseStage, rank: RankStage) -> SelectStage:
    """Stage 7: greedy forward selection per side; the accepted effects with their parameters."""
    run.stage("select")
    max_effects = run.settings.max_effects
    alpha = run.settings.alpha
    steps = rank.force.forward(rank.force_ranked, max_effects=max_effects)
    effects, r_after = accepted_effects(rank.force, steps, alpha)
    energy = None
    if rank.energy is not None and base.energy is not None and base.energy_block is not None:
        e_steps = rank.energy.forward(rank.energy_ranked, max_effects=max_effects)
        e_effects, e_after = accepted_effects(rank.energy, e_steps, alpha)
        energy = _energy_report(fl.table.frame, base, e_after, rank, e_steps, e_effects)
    return SelectStage(steps, effects, r_after, energy)


def _energy_report(table: pd.DataFrame, base: BaseStage, after: np.ndarray, rank: RankStage,
                   steps: list[SelectionStep], effects: list[Effect]) -> EnergySide:
    assert base.energy is not None and base.energy_block is not None and base.energy_residual is not None
    test = base.energy.split.test
    measured = table[ELECTRIC_POWER].to_numpy(dtype=float)
    sim_p = table[SIM_ELECTRIC_POWER].to_numpy(dtype=float)
    energy = ElectricEnergy(electric_energy_per_distance(table, measured, test),
                            electric_energy_per_distance(table, sim_p, test),
                            electric_energy_per_distance(table, measured - after, test))
    return EnergySide(RobustSummary.of(base.energy_residual[test]), RobustSummary.of(after[test]),
                      base.energy_block, energy, rank.energy_ranked, rank.energy_skipped, steps, effects)


@dataclass
class Resimulation:
    """The gap with the accepted effects switched on in the simulator (None when not run) and what happened."""

    gap: GapMeasures | None
    note: str


def stage_resimulate(run: Run, fl: FloorStage, split: Split, rank: RankStage, sel: SelectStage) -> Resimulation:
    """Stage 8: the accepted effects switched on in the sim, its floor re-fitted with them and the held-out gap
    recomputed. Never aborts: the diagnosis is complete before it, a failing re-simulation is a note."""
    run.stage("re-simulate")
    s = run.settings
    if not s.resimulate:
        return Resimulation(None, "not asked (--no-resimulate)")
    if not sel.effects or fl.floor.is_none:
        return Resimulation(None, "")
    try:
        sim_after = switched_on(run.sim, sel.effects)
        if sim_after is None:
            return Resimulation(None, "an accepted effect has no simulator switch")
        extra = tuple((c.name, sh) for c, sh in rank.force.chosen)
        floor_after = fit_floor(sim_after, run.channels, s, extra=extra, rate=run.rate)
        t_after = build_table(run.real, sim_after, floor=floor_after).frame
        if len(t_after) != len(fl.table.frame):
            return Resimulation(None, "the re-simulated table differs in length; skipped")
        r_sim = np.where(split.valid, t_after["residual"].to_numpy(dtype=float), 0.0)
        gap = gap_measures(t_after, np.nan_to_num(r_sim), fl.table.model.mass, split.test,
                           replay_sim=sim_after if s.replay else None)
        gap.sim = sim_after
        return Resimulation(gap, "done")
    except (DiagnosisError, ValueError) as exc:
        return Resimulation(None, f"failed, diagnosis kept: {exc}")


def stage_report(run: Run, fl: FloorStage, split: Split, gap: GapStage, base: BaseStage, rank: RankStage,
                 sel: SelectStage, resim: Resimulation) -> Diagnosis:
    """Stage 9: the gap after and per regime, the unexplained residual, the :class:`.results.Diagnosis`."""
    run.stage("report")
    s = run.settings
    table = fl.table.frame
    test = split.test
    r_after = sel.residual_after
    gap_after = gap_measures(table, r_after, fl.table.model.mass, test)
    per_regime = per_regime_gap(table, np.nan_to_num(fl.residual), r_after, test,
                                [get_regime(n) for n in s.regimes])
    unexplained = _unexplained(table, np.where(split.valid, r_after, np.nan), split, s, run.rng,
                               float(gap.gap_before.force_residual.rmse) ** 2)
    notes = Notes(fl.table.notes, rank.force.baseline_info, resim.note, base.force_block,
                  [Implausible(st.effect, st.implausible) for st in sel.steps if st.implausible],
                  strongest_departures(gap.regimes, top=8))
    diag = Diagnosis(run.sim, list(pd.unique(table["trip"])), s, split.describe(), fl.floor, gap.gap_before,
                     gap_after, resim.gap, {k: v.rows for k, v in gap.regimes.items()}, per_regime,
                     gap.residual_analysis, rank.force_ranked, rank.force_skipped, sel.steps, sel.effects,
                     unexplained, sel.energy, notes, fl.table.trips, table=fl.table, residual_after=r_after,
                     test_rows=test)
    run.progress("done", 1.0)
    return diag


def diagnose(real: Sequence[Trip], sim: SimConfig, settings: DiagnosisSettings | None = None,
             floor_trips: Sequence[Trip] | None = None, floor: SimFloor | None = None,
             progress: Callable[[str, float], None] | None = None) -> Diagnosis:
    """Diagnose ``sim`` against the recorded trips ``real``: the stages of the module doc in order.
    ``floor``: a floor fitted before (else fitted on ``floor_trips`` or on the sim's own trips);
    ``progress(stage, fraction)``: called at the start of every stage, fractions never decrease."""
    settings = settings or DiagnosisSettings()
    for name in settings.candidates:
        get_candidate(name)
    for name in settings.regimes:
        get_regime(name)
    if not real:
        raise DiagnosisError("no recorded trips given")
    run = Run(real, sim, settings, np.random.default_rng(settings.seed), progress or (lambda what, frac: None))
    table = stage_table(run)
    split = stage_split(run, table)
    fl = stage_floor(run, table, split, floor, floor_trips)
    gap = stage_gap(run, fl, split)
    base = stage_base(run, fl, split)
    rank = stage_rank(run, fl, base)
    sel = stage_select(run, fl, base, rank)
    resim = stage_resimulate(run, fl, split, rank, sel)
    return stage_report(run, fl, split, gap, base, rank, sel, resim)


def _unexplained(table: pd.DataFrame, residual_after: np.ndarray, split: Split, settings: DiagnosisSettings,
                 rng: np.random.Generator, mse_before: float) -> Unexplained:
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
    return Unexplained(bool(departures) or structured, departures, ReferenceGain(rel, list(gain), structured),
                       importance[:5], float(np.sqrt(np.nanmean(loss0))))
