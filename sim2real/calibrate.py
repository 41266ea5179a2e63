"""Calibrate the sim's base vehicle to reference trips: a preset never matches the car, so before trips are
diagnosed the base road load, drive-train, motor and sensors are fitted to trips taken under known conditions
and written as a vehicle spec every tool reads (``roadload diagnose --sim``, ``roadload simulate --vehicle``,
the MPC's force models). Diagnosing new trips against it names what differs from the reference.

The reference trips go through the diagnosis' first stages (:mod:`.diagnose`: table, split, floor), so the
residuals are the diagnosis' own: force r_F = F_xV,measured - (F_xV,sim + floor) [N] and battery power
r_P = P_el,measured - (P_el,sim + floor) [W]. Both are fitted on the training segments, energy side first:

energy side (battery-electric trips), r_P ≈ ΔP_aux + (s - 1) P_loss(ω_E, T_E) - Δg T_E ω_E - ΔT_off ω_E:
    auxiliary power ΔP_aux [W]; motor / inverter loss scale s [1] of the sim's loss map P_loss; drive-torque
    signal gain error Δg [1] and offset ΔT_off [N m] (P_el,sim is computed from the *logged* torque, so a signal
    reading (1 + Δg) T + ΔT_off over-predicts the power by Δg T ω + ΔT_off ω);
force side, r_F - Δg F_drive - ΔT_off i η / r_W + m_V b ≈ Δm_V (g sin θ + v̇ + g cos θ f_r(v)) + Δf_r0 m_V g cos θ
    + Δf_r1 m_V g cos θ v + Δf_r4 m_V g cos θ v⁴ + Δ(c_x A_V) ρ_a/2 v² + ε |F_drive| + Δm_rot v̇
    (+ k F_B with brake pressure, + Δ(m_V²/c_yW) v⁴ κ²/4 with a path curvature; eq. 2.5-2.10, 2.15, 2.17):
    mass, rolling resistance f_r0, f_r1 and f_r4, drag area, the drive-train's mesh-loss error ε — reported as the
    efficiency in traction η_t = η_sim / (1 + ε) and in regeneration η_r = η_sim (1 - ε) (the pipeline turns the
    logged torque into force with η_sim: T i η / r_W in traction, T i / (η r_W) in regeneration, so a loss
    proportional to the transmitted torque, section 2.6, moves the two oppositely) —, rotating inertia
    Δm_rot = ΔI_red / r_W², brake gain k; the torque-signal terms are those of the energy side and b is the
    accelerometer bias from the logged elevation (:func:`.base.accelerometer_bias_from_elevation`).

Why one loss error and not an efficiency per direction: the sim's drive force F_drive = m_V (v̇ + g sin θ + g cos θ
f_r) + ρ/2 c_x A v² + ... is, term by term, in the span of the mass, rolling-resistance, drag-area and inertia
regressors, so a *symmetric* part ε_s F_drive is collinear with scaling all of them (the residual cannot tell a
drive force read 5 % high from a car 5 % heavier with 5 % more road load). With η_t and η_r fitted apart, that
direction is set by the priors and by noise: on FASTSim's Zoe against the bmw_i3 preset the fit slid along it to
mass +557 kg with η_t and η_r at their physical bounds (1.0 and 0.7), and with 100x wider priors to mass +1782 kg
and ε_t = -1.07. Only the antisymmetric part, ε |F_drive|, is identified: fitted alone it reads η = 0.914 / 0.911
(FASTSim's transmission: 0.92) and mass 1573 kg (1600), the same with 100x wider priors.

Each side is a Gaussian posterior around the sim's values: the data's information is the inverse of the
cluster-robust (10 s block) covariance of the fit, H M⁻¹ H with H = Aᵀ W A and M the blocks' score outer
products (autocorrelated 10 Hz samples are not counted as independent), plus a prior of physical width per
parameter (:data:`PARAMETERS`, e.g. the mass ± 10 %): x = (H M⁻¹ H + Λ)⁻¹ H M⁻¹ Aᵀ W y, covariance
(H M⁻¹ H + Λ)⁻¹. Directions the trips do not determine (a drive-train efficiency against a mass that scales every
force alike) stay at the sim's value with the prior's uncertainty instead of drifting to any value. The force
side is fitted on the diagnosis' robust, regime-normalised target (:mod:`.robust`), the energy side on the power
residual winsorised at 5 MAD scales. Calibrated values outside a parameter's physical range are clipped to it and
flagged, efficiencies outside [0.7, 1] flagged as implausible.

Where the trips log the motor speed, the overall drive ratio i_G i_D / r_W is measured first from ω_E / v
(:func:`drive_ratio`): every force the pipeline derives from the logged torque scales with it, and no road-load
parameter can stand in for it (a ratio error looks like an efficiency above 1 in regeneration).

Whether the battery power's signed T ω term is a torque-signal error is decided on the reference trips: the
calibration runs with the torque-signal gain and offset fitted on the energy side and carried over to the force
side, and with them kept at the sim's (a motor whose losses the sim's loss map does not shape, as in FASTSim,
leaves a signed T ω term that is no signal error); the one that leaves less of the held-out gap on both sides
(force RMSE after / before plus battery-power RMSE after / before) is kept, and the notes say which.

The check: the reference trips are re-run against the written spec (its own floor, the same split) and the
held-out gap (force and battery-power RMSE on the held-out segments) is compared with the sim's before.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable, Sequence

import numpy as np
import pandas as pd

from roadload.envs.effects import EffectsConfig
from roadload.trip import Trip
from roadload.vehicle import VehicleSpec, VehicleSpecError

from .base import accelerometer_bias_from_elevation
from .catalog import DRIVE_FORCE
from .diagnose import FLOOR_ROADS, DiagnosisSettings, Run, stage_floor, stage_split, stage_table
from .energy import MOTOR_SPEED, POWER_RESIDUAL, SPEED_DERIVED, energy_columns
from .errors import DiagnosisError
from .forcemodel import SimForceModel
from .held import DRIVETRAIN_LOSS, force_columns
from .records import Record, RobustSummary
from .robust import robust_target, winsorised
from .selection import Split
from .simconfig import SimConfig

ETA_PLAUSIBLE = (0.7, 1.0)
CLIP_SCALES = 5.0


@dataclass(frozen=True)
class Parameter:
    """One calibrated parameter: ``name``, the fitted change's ``symbol`` and ``unit``, the side (force / energy),
    the prior's width as a function of the sim (same unit), the physical range of the calibrated value and its
    unit, and what it is."""

    name: str
    symbol: str
    unit: str
    side: str
    prior: Callable[[VehicleSpec, SimForceModel], float]
    low: float
    high: float
    value_unit: str
    description: str


def _bev(spec: VehicleSpec) -> bool:
    return spec.drivetrain.kind == "bev"


PARAMETERS: tuple[Parameter, ...] = (
    Parameter("mass", "Δm_V", "kg", "force", lambda s, m: 0.1 * m.mass, 250.0, 60000.0, "kg",
              "vehicle mass m_V incl. driver and load"),
    Parameter("rolling_resistance_f0", "Δf_r0", "1", "force", lambda s, m: 0.3 * m.rolling_resistance_f0,
              1e-4, 0.1, "1", "rolling resistance f_r0 (eq. 2.10)"),
    Parameter("rolling_resistance_f1", "Δf_r1", "s/m", "force", lambda s, m: 1e-4, 0.0, 1e-2, "s/m",
              "rolling resistance speed term f_r1 (eq. 2.10)"),
    Parameter("rolling_resistance_f4", "Δf_r4", "s^4/m^4", "force", lambda s, m: 1e-9, 0.0, 1e-6, "s^4/m^4",
              "rolling resistance speed term f_r4 (eq. 2.10)"),
    Parameter("drag_area", "Δc_x A_V", "m^2", "force", lambda s, m: 0.15 * m.drag_area, 0.1, 15.0, "m^2",
              "drag area c_x A_V (eq. 2.7)"),
    Parameter("drivetrain_efficiency_traction", "ε_t", "1", "force", lambda s, m: 0.05, *ETA_PLAUSIBLE, "1",
              "drive-train efficiency in traction η_t = η_sim / (1 + ε_t)"),
    Parameter("drivetrain_efficiency_regen", "ε_r", "1", "force", lambda s, m: 0.05, *ETA_PLAUSIBLE, "1",
              "drive-train efficiency in regeneration η_r = η_sim (1 + ε_r)"),
    Parameter("rotating_inertia", "Δm_rot", "kg", "force", lambda s, m: 0.05 * m.mass, 0.0, 2000.0, "kg",
              "rotating inertia at the wheels (I_red + 4 I_W) / r_W² (eq. 2.17)"),
    Parameter("brake_gain", "k", "1", "force", lambda s, m: 0.2, 0.05, 1.5, "1",
              "brake pad friction X_B (the wheels brake with (1 + k) F_B)"),
    Parameter("cornering", "Δ(m_V²/c_yW)", "kg^2 rad/N", "force",
              lambda s, m: m.mass ** 2 / m.cornering_stiffness, 0.2, 5.0, "x c_yW",
              "cornering stiffness factor (eq. 2.15)"),
    Parameter("auxiliary_power", "ΔP_aux", "W", "energy", lambda s, m: 1000.0, 0.0, 20000.0, "W",
              "auxiliary power P_aux drawn from the traction battery"),
    Parameter("motor_loss_scale", "s - 1", "1", "energy", lambda s, m: 0.5, 0.2, 5.0, "x P_loss",
              "motor / inverter loss scale of the loss map"),
    Parameter("torque_signal_gain", "Δg", "1", "energy", lambda s, m: 0.1, -0.5, 0.5, "1",
              "drive-torque signal gain error g (signal = (1 + g) T + T_off)"),
    Parameter("torque_signal_offset", "ΔT_off", "N*m", "energy", lambda s, m: 10.0, -100.0, 100.0, "N*m",
              "drive-torque signal offset T_off"),
)
#: the force side's fitted drive-train parameter: the loss error ε of the column |F_drive| (module doc), reported
#: as the two efficiencies above; its prior and range are theirs (:func:`_bounds`)
DRIVETRAIN_LOSS_PARAMETER = Parameter(DRIVETRAIN_LOSS, "ε", "1", "force", lambda s, m: 0.05, *ETA_PLAUSIBLE, "1",
                                      "drive-train mesh-loss error ε: η_t = η_sim / (1 + ε), η_r = η_sim (1 - ε)")
DRIVE_RATIO = Parameter("drive_ratio", "i_G i_D / r_W", "1/m", "force", lambda s, m: 0.0, 5.0, 200.0, "1/m",
                        "overall drive ratio per wheel radius (first gear), from the logged motor speed")
ACCEL_BIAS = Parameter("accelerometer_bias", "b", "m/s^2", "force", lambda s, m: 0.0, -1.0, 1.0, "m/s^2",
                       "accelerometer bias b (eq. 5.2 grade offset b/g), from the logged elevation")


@dataclass
class CalibratedParameter(Record):
    """A calibrated parameter: the fitted change ``delta`` ± ``std_error`` (``unit``), the sim's value and the
    calibrated one in ``value_unit`` with its uncertainty, the prior's width, the physical range, whether the data
    determined it (posterior SD below half the prior's), flags (clipped to the range, implausible) and ``held``:
    the change the fit wanted beyond the end of its range and the range held back (``unit``; 0: none)."""

    name: str
    symbol: str
    side: str
    delta: float
    std_error: float
    unit: str
    sim: float
    calibrated: float
    calibrated_std: float
    value_unit: str
    prior_std: float
    low: float
    high: float
    determined: bool
    flag: str
    description: str
    held: float = 0.0


@dataclass
class HeldOutGap(Record):
    """Held-out RMSE of the force residual [N] and the battery-power residual [W] against the sim before and the
    calibrated sim after, the shrinkage 1 - after / before, and the battery-power residual's median [W]."""

    force_before: float
    force_after: float
    force_shrinkage: float
    power_before: float
    power_after: float
    power_shrinkage: float
    power_median_before: float
    power_median_after: float


@dataclass
class BinGap(Record):
    """Median force residual [N] per speed x acceleration bin on the held-out rows, before and after."""

    speed: str
    acceleration: str
    n: int
    median_before: float
    median_after: float


@dataclass
class CalibrationSettings:
    """Split (segment_length [s], test_fraction, n_folds, block_length [s], seed), the sims' floors (roads and
    floor_duration [s]), winsorising (clip, MAD scales), ``prior_scale`` multiplying every prior width, the
    number of fitting ``passes`` (:func:`calibrate`)."""

    segment_length: float = 60.0
    test_fraction: float = 1 / 3
    n_folds: int = 5
    block_length: float = 10.0
    seed: int = 0
    floor_roads: tuple[tuple[str, int], ...] = FLOOR_ROADS
    floor_duration: float = 900.0
    clip: float = 5.0
    prior_scale: float = 1.0
    passes: int = 2

    def diagnosis(self) -> DiagnosisSettings:
        return DiagnosisSettings(segment_length=self.segment_length, test_fraction=self.test_fraction,
                                 n_folds=self.n_folds, block_length=self.block_length, seed=self.seed,
                                 floor_roads=self.floor_roads, floor_duration=self.floor_duration, clip=self.clip,
                                 resimulate=False, replay=False)


@dataclass
class Calibration(Record):
    """The result of :func:`calibrate`: the sim it started from, the reference trips, the calibrated parameters,
    the held-out gap before/after, the per-bin residual and the calibrated vehicle spec (written by
    :func:`write_calibration`)."""

    sim: str
    trips: list[str]
    parameters: list[CalibratedParameter]
    heldout: HeldOutGap
    bins: list[BinGap]
    notes: list[str]
    spec: VehicleSpec = field(repr=False)
    reference_ambient: float = float("nan")

    def parameter(self, name: str) -> CalibratedParameter:
        for p in self.parameters:
            if p.name == name:
                return p
        raise DiagnosisError(f"no calibrated parameter {name!r}; have {[p.name for p in self.parameters]}")

    def to_dict(self) -> dict:
        out = super().to_dict()
        out.pop("spec")
        return out

    @property
    def held_at_bound(self) -> dict[str, float]:
        """The fitted changes held at a bound of their range, by the name the fit gives them (the two drive-train
        efficiencies are one loss error ε, :data:`.held.DRIVETRAIN_LOSS`) -> what the bound held back (signed, in
        the change's unit): what every trip diagnosed against this calibration still carries (:mod:`.held`)."""
        out = {}
        for p in self.parameters:
            if p.held:
                traction = p.name == "drivetrain_efficiency_traction"
                regen = p.name == "drivetrain_efficiency_regen"
                out[DRIVETRAIN_LOSS if traction or regen else p.name] = -p.held if regen else p.held
        return out

    @property
    def sim_config(self) -> SimConfig:
        """The calibrated vehicle at the reference trips' median ambient temperature (the sim's own floor trips then
        see the reference's air density; the sim's default where the trips log none)."""
        effects = EffectsConfig()
        if np.isfinite(self.reference_ambient):
            effects = EffectsConfig.from_dict({**effects.to_dict(), "ambient_temperature": self.reference_ambient})
        return SimConfig(self.spec, effects, f"{self.sim} calibrated", self.held_at_bound)


# ============================================================================================ the fit
def posterior(A: np.ndarray, y: np.ndarray, w: np.ndarray, rows: np.ndarray, blocks: np.ndarray,
              prior_std: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """x and covariance of y ≈ A x on ``rows`` with weights w and a zero-mean Gaussian prior of ``prior_std`` per
    column (module doc): information H M⁻¹ H of the cluster-robust fit over ``blocks`` plus diag(1/prior²)."""
    a, yy, ww = A[rows], y[rows], w[rows]
    scale = np.sqrt(np.mean(a ** 2 * ww[:, None], axis=0))
    scale[~(scale > 0)] = 1.0
    a = a / scale
    tau = np.asarray(prior_std, dtype=float) * scale
    H = a.T @ (a * ww[:, None])
    # the meat of the sandwich at the residual of the prior-free fit's best direction: the data's own noise
    x0, *_ = np.linalg.lstsq(a * np.sqrt(ww)[:, None], yy * np.sqrt(ww), rcond=1e-10)
    M = cluster_meat(a, yy - a @ x0, blocks[rows], ww)
    M += 1e-9 * max(float(np.trace(M)), 1e-300) / len(M) * np.eye(len(M))
    info = H @ np.linalg.solve(M, H)
    lam = np.diag(1.0 / tau ** 2)
    cov_s = np.linalg.inv(info + lam)
    x_s = cov_s @ (H @ np.linalg.solve(M, a.T @ (ww * yy)))
    return x_s / scale, cov_s / np.outer(scale, scale)


def cluster_meat(A: np.ndarray, r: np.ndarray, blocks: np.ndarray, w: np.ndarray) -> np.ndarray:
    """Σ_blocks g_b g_bᵀ with g_b = Σ_{i in b} w_i a_i r_i (the meat of :func:`.stats.cluster_covariance`)."""
    _, inv = np.unique(blocks, return_inverse=True)
    g = np.zeros((inv.max() + 1, A.shape[1]))
    np.add.at(g, inv, A * (w * r)[:, None])
    return g.T @ g


@dataclass
class SideFit:
    """The fitted changes of one side with their covariance, and the prediction on every row."""

    names: list[str]
    x: np.ndarray
    cov: np.ndarray
    predicted: np.ndarray
    held: dict[str, float] = field(default_factory=dict)

    def get(self, name: str, default: float = 0.0) -> float:
        return float(self.x[self.names.index(name)]) if name in self.names else default


def fit_energy(table: pd.DataFrame, split: Split, spec: VehicleSpec, model: SimForceModel,
               settings: CalibrationSettings, signal: bool = True) -> SideFit | None:
    """The energy side (module doc); None without battery power or a traction motor. ``signal`` False: without
    the torque-signal gain and offset (they stay the sim's, reported with a change of 0 and, as held back, what
    the fit with them wanted where that is >= 2.58 standard errors: the battery power's signed T ω term the
    calibration left to every trip, which the diagnosis' energy-consistency check then reads relative to)."""
    if not _bev(spec) or POWER_RESIDUAL not in table.columns:
        return None
    y = table[POWER_RESIDUAL].to_numpy(dtype=float)
    ok = np.isfinite(y)
    rows = split.train & ok
    if rows.sum() < 100:
        return None
    names = [p.name for p in PARAMETERS if p.side == "energy"]
    A = energy_columns(table, spec)
    yw, w = winsorised(np.where(ok, y, 0.0), rows, settings.clip)
    prior = np.array([_param(n).prior(spec, model) for n in names]) * settings.prior_scale
    x, cov, back = bounded_posterior(A, yw, w, rows, split.blocks, prior, _bounds(names, spec, model))
    held = {n: float(b) for n, b in zip(names, back) if b}
    if signal:
        return SideFit(names, x, cov, A @ x, held)
    keep = np.array([not n.startswith("torque_signal") for n in names])
    x_kept, cov_kept, back_kept = bounded_posterior(A[:, keep], yw, w, rows, split.blocks, prior[keep],
                                                    _bounds([n for n, k in zip(names, keep) if k], spec, model))
    se = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    held = {n: float(b) for n, b in zip([n for n, k in zip(names, keep) if k], back_kept) if b}
    held.update({n: float(v) for n, v, s_, k in zip(names, x, se, keep) if not k and abs(v) >= Z_HELD * s_})
    x_out = np.zeros(len(names))
    x_out[keep] = x_kept
    cov[np.ix_(keep, keep)] = cov_kept
    cov[np.ix_(keep, ~keep)] = 0.0
    cov[np.ix_(~keep, keep)] = 0.0
    return SideFit(names, x_out, cov, A[:, keep] @ x_kept, held)


def _torque_terms(table: pd.DataFrame, spec: VehicleSpec, model: SimForceModel, energy: SideFit | None
                  ) -> np.ndarray:
    """What the energy side's torque-signal gain and offset do to the measured force [N]: Δg F_drive +
    ΔT_off i_G i_D η_sim / r_W."""
    if energy is None:
        return np.zeros(len(table))
    d = spec.drivetrain
    gear = np.clip(np.rint(np.nan_to_num(table["gear"].to_numpy(dtype=float), nan=1.0)), 1, d.n_gears).astype(int)
    ratio = np.asarray(d.gear_ratios, dtype=float)[gear - 1] * d.final_drive
    f = np.nan_to_num(table[DRIVE_FORCE].to_numpy(dtype=float))
    return (energy.get("torque_signal_gain") * f
            + energy.get("torque_signal_offset") * ratio * model.drivetrain_efficiency / model.wheel_radius)


def fit_force(table: pd.DataFrame, split: Split, residual: np.ndarray, spec: VehicleSpec, model: SimForceModel,
              settings: CalibrationSettings, known: np.ndarray) -> SideFit:
    """The force side (module doc) on the robust target of ``residual - known`` [N]. Mass, road load, inertia and
    brake gain are fitted on the braking rows too (they hold there as well; the target's per-regime scale weighs
    the braking transients down); the drive-train efficiencies are not (in friction braking the measured force
    mixes the regenerative torque with the brake-pressure force and its transients)."""
    y = np.nan_to_num(residual) - known
    target = robust_target(table, y, split.train, split.segments, split.fold, split.n_folds, clip=settings.clip)
    A, names = force_columns(table, model)
    drive = np.array([n == DRIVETRAIN_LOSS for n in names])
    A[np.ix_(target.braking, drive)] = 0.0
    prior = np.array([_param(n).prior(spec, model) for n in names]) * settings.prior_scale
    x, cov, back = bounded_posterior(A, target.r_w, target.weight, split.train, split.blocks, prior,
                                     _bounds(names, spec, model))
    return SideFit(names, x, cov, A @ x, {n: float(b) for n, b in zip(names, back) if b})


def _bounds(names: list[str], spec: VehicleSpec, model: SimForceModel) -> np.ndarray:
    """(k x 2) bounds of the fitted changes that keep each calibrated value in its physical range."""
    out = []
    for n in names:
        if n == DRIVETRAIN_LOSS:     # ε = ε_t = -ε_r: both efficiencies within their range
            t, r = (_bounds([f"drivetrain_efficiency_{d}"], spec, model)[0] for d in ("traction", "regen"))
            out.append((max(t[0], -r[1]), min(t[1], -r[0])))
            continue
        p = _param(n)
        lo, hi = (_delta_for(n, v, spec, model) for v in (p.low, p.high))
        out.append((min(lo, hi), max(lo, hi)))
    return np.asarray(out, dtype=float)


def _delta_for(name: str, value: float, spec: VehicleSpec, model: SimForceModel) -> float:
    """The fitted change that gives the calibrated ``value`` (the inverse of :func:`_physical`)."""
    sim = _physical(name, 0.0, 0.0, spec, model)[0]
    if name == "drivetrain_efficiency_traction":
        return sim / value - 1.0
    if name == "drivetrain_efficiency_regen":
        return value / sim - 1.0
    if name == "brake_gain":
        return value / sim - 1.0
    if name == "cornering":
        k = model.mass ** 2 / model.cornering_stiffness
        return k / value - k
    return value - sim


def bounded_posterior(A: np.ndarray, y: np.ndarray, w: np.ndarray, rows: np.ndarray, blocks: np.ndarray,
                      prior_std: np.ndarray, bounds: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`posterior` with every change kept within ``bounds``: a change that leaves them is held at its
    bound and the others refitted given it (so the rest of the calibration takes up what the bound holds back,
    instead of a clipped value leaving it unexplained); a held change keeps its unconstrained uncertainty.
    Returns x, its covariance and per change what its bound held back: the fitted value beyond the bound minus
    the bound where that is at least :data:`Z_HELD` standard errors (0 elsewhere; the data want beyond the range,
    not just a noisy value at its edge)."""
    x, cov = posterior(A, y, w, rows, blocks, prior_std)
    held = np.zeros(x.size, dtype=bool)
    held_back = np.zeros(x.size)
    for _ in range(x.size):
        out = (~held) & ((x < bounds[:, 0]) | (x > bounds[:, 1]))
        if not out.any():
            break
        held |= out
        x_held = np.clip(x, bounds[:, 0], bounds[:, 1])
        beyond = np.where(out, x - x_held, 0.0)
        se = np.sqrt(np.clip(np.diag(cov), 0.0, None))
        held_back = np.where(np.abs(beyond) >= Z_HELD * se, beyond, held_back)
        free = ~held
        x = x_held.copy()
        if free.any():
            x_free, cov_free = posterior(A[:, free], y - A[:, held] @ x_held[held], w, rows, blocks,
                                         prior_std[free])
            x[free] = x_free
            cov = cov.copy()
            cov[np.ix_(free, free)] = cov_free
    return x, cov, held_back


Z_HELD = 2.58      # a bound holds back a change when the fit wants beyond it by this many standard errors


def _param(name: str) -> Parameter:
    for p in PARAMETERS + (ACCEL_BIAS, DRIVE_RATIO, DRIVETRAIN_LOSS_PARAMETER):
        if p.name == name:
            return p
    raise DiagnosisError(f"unknown calibration parameter {name!r}")


# ============================================================================================ the calibrated spec
def drivetrain_efficiencies(spec: VehicleSpec) -> tuple[float, float]:
    """(η in traction, η in regeneration) of the spec's drive-train: its loss maps fitted as (1 - η) |T| i + drag i
    over the rows of positive and of negative input torque (first gear, median speed) times the differential's."""
    d = spec.drivetrain
    out = []
    for sign in (1.0, -1.0):
        eta = 1.0 - _slope(d.gearbox_loss[0], d.gear_ratios[0], sign)
        out.append(float(np.clip(eta, 0.5, 1.0) * np.clip(1.0 - _slope(d.differential_loss, d.final_drive), 0.5, 1.0)))
    return out[0], out[1]


def _physical(name: str, delta: float, se: float, spec: VehicleSpec, model: SimForceModel
              ) -> tuple[float, float, float]:
    """(current value, calibrated value, its standard error) of a parameter in its ``value_unit``. A drive-train
    efficiency change ε is relative to the spec's own efficiency of that direction: the sim's floor, fitted on the
    spec's own trips, makes the sim side follow the spec's loss maps rather than the pipeline's symmetric η."""
    if name == "drivetrain_efficiency_traction":
        eta = drivetrain_efficiencies(spec)[0]
        return eta, eta / (1.0 + delta), eta * se / (1.0 + delta) ** 2
    if name == "drivetrain_efficiency_regen":
        eta = drivetrain_efficiencies(spec)[1]
        return eta, eta * (1.0 + delta), eta * se
    if name == "motor_loss_scale":
        return 1.0, 1.0 + delta, se
    if name == "brake_gain":
        pad = spec.brakes.pad_friction
        return pad, pad * (1.0 + delta), pad * se
    if name == "cornering":
        k = model.mass ** 2 / model.cornering_stiffness
        return 1.0, k / (k + delta), k * se / (k + delta) ** 2
    sim = {"mass": model.mass, "rolling_resistance_f0": model.rolling_resistance_f0,
           "rolling_resistance_f1": model.rolling_resistance_f1,
           "rolling_resistance_f4": model.rolling_resistance_f4, "drag_area": model.drag_area,
           "rotating_inertia": spec.effective_mass(1) - spec.body.mass,
           "auxiliary_power": spec.drivetrain.battery.auxiliary_power if spec.drivetrain.battery else 0.0,
           "torque_signal_gain": spec.sensors.drive_torque_gain_error,
           "torque_signal_offset": spec.sensors.drive_torque_offset,
           "accelerometer_bias": spec.sensors.channels["accel_x"].bias if "accel_x" in spec.sensors.channels
           else 0.0}[name]
    return float(sim), float(sim + delta), float(se)


def _calibrated(p: Parameter, delta: float, se: float, spec: VehicleSpec, model: SimForceModel,
                prior: float) -> CalibratedParameter:
    sim, value, value_se = _physical(p.name, delta, se, spec, model)
    flag = ""
    if not p.low <= value <= p.high:
        if p.name.startswith("drivetrain_efficiency"):
            flag = f"implausible: an efficiency of {value:.3f} lies outside [{p.low:g}, {p.high:g}]"
        else:
            flag = f"clipped to the physical range [{p.low:g}, {p.high:g}] {p.value_unit} (fitted {value:.4g})"
        value = float(np.clip(value, p.low, p.high))
    determined = bool(np.isfinite(se) and (prior <= 0 or se < 0.5 * prior))
    return CalibratedParameter(p.name, p.symbol, p.side, float(delta), float(se), p.unit, sim, value,
                               float(value_se), p.value_unit, float(prior), p.low, p.high, determined, flag,
                               p.description)


def _scaled_rows(values: list[list[float]], axis: list[float], add: Callable[[float], float]) -> list[list[float]]:
    """A loss table with ``add(x)`` added to every entry of row x (clipped at 0: losses are never negative)."""
    return [[max(float(v) + add(float(x)), 0.0) for v in row] for x, row in zip(axis, values)]


def calibrated_spec(spec: VehicleSpec, params: Sequence[CalibratedParameter]) -> VehicleSpec:
    """A copy of ``spec`` with the calibrated values (clipped to their ranges) written into its fields: body mass,
    tires' f_r0 / f_r1, the drag coefficient, the gearbox loss maps (traction and regeneration rows apart, so the
    drive-train efficiency becomes η_t / η_r), the wheel inertia (rotating inertia), pad friction, axle cornering
    stiffnesses, the motor loss map (scaled), the battery's auxiliary power and the sensor model (drive-torque
    gain and offset, accelerometer bias)."""
    by = {p.name: p for p in params}
    d = spec.to_dict()
    val = {k: p.calibrated for k, p in by.items()}
    if "mass" in val:      # the sim's mass may carry a payload effect: the change goes onto the body
        d["body"]["mass"] = spec.body.mass + val["mass"] - by["mass"].sim
    for k in ("rolling_resistance_f0", "rolling_resistance_f1", "rolling_resistance_f4"):
        if k in val:
            d["tires"][k] = float(np.clip(d["tires"][k] + val[k] - by[k].sim, by[k].low, by[k].high))
    if "drag_area" in val:
        d["aero"]["drag_coefficient"] = val["drag_area"] / spec.aero.frontal_area
    if "rotating_inertia" in val:
        d_rot = val["rotating_inertia"] - by["rotating_inertia"].sim
        d["tires"]["wheel_inertia"] = max(spec.tires.wheel_inertia + d_rot * spec.tires.dynamic_radius ** 2 / 4.0,
                                          1e-3)
    _efficiency(d, spec, by)
    if "brake_gain" in val:
        d["brakes"]["pad_friction"] = val["brake_gain"]
    if "cornering" in val:
        d["tires"]["cornering_stiffness_front"] *= val["cornering"]
        d["tires"]["cornering_stiffness_rear"] *= val["cornering"]
    _energy_fields(d, spec, val)
    d["description"] = (spec.description + " " if spec.description else "") + \
        f"Calibrated with roadload calibrate from {spec.name}."
    try:
        return VehicleSpec.from_dict(d)
    except VehicleSpecError as exc:
        raise DiagnosisError(f"the calibrated spec is not valid: {exc}") from None


def _efficiency(d: dict, spec: VehicleSpec, by: dict[str, CalibratedParameter]) -> None:
    """Gearbox loss rows of positive input torque raised or lowered so that the drive-train efficiency in
    traction becomes η_t, rows of negative torque so that it becomes η_r (loss ≈ (1 - η) |T| i + drag i)."""
    t, r = by.get("drivetrain_efficiency_traction"), by.get("drivetrain_efficiency_regen")
    if t is None or r is None:
        return
    # η_sim = η_G η_D: the change goes into the gearbox, η_G' = η / η_D, its loss slope (1 - η_G') |T| i
    eta_d = float(np.clip(1.0 - _slope(spec.drivetrain.differential_loss, spec.drivetrain.final_drive), 0.5, 1.0))
    d_t, d_r = (t.sim - t.calibrated) / eta_d, (r.sim - r.calibrated) / eta_d
    for g, (m, ratio) in enumerate(zip(spec.drivetrain.gearbox_loss, spec.drivetrain.gear_ratios)):
        def add(x: float, ratio: float = ratio) -> float:
            return (d_t if x > 0 else d_r if x < 0 else 0.0) * abs(x) * ratio
        d["drivetrain"]["gearbox_loss"][g]["values"] = _scaled_rows(m.values, list(m.x), add)


def _slope(loss_map, ratio: float, sign: float = 0.0) -> float:
    """1 - η of a loss table, fitted as (1 - η) |T| i + drag i over its torque axis at its median speed (``sign``
    +1 / -1: over the rows of positive / negative torque and zero only)."""
    torque = np.asarray(loss_map.x, dtype=float)
    if sign:
        torque = torque[sign * torque >= 0]
    speed = float(np.median(np.asarray(loss_map.y, dtype=float)))
    loss = np.asarray(loss_map(torque, np.full_like(torque, speed)), dtype=float)
    A = np.column_stack([np.abs(torque) * ratio, np.full_like(torque, ratio)])
    return float(np.linalg.lstsq(A, loss, rcond=None)[0][0])


def _energy_fields(d: dict, spec: VehicleSpec, val: dict[str, float]) -> None:
    if "motor_loss_scale" in val and d["drivetrain"].get("motor"):
        s = val["motor_loss_scale"]
        lm = d["drivetrain"]["motor"]["loss_map"]
        lm["values"] = [[float(v) * s for v in row] for row in lm["values"]]
    if "auxiliary_power" in val and d["drivetrain"].get("battery"):
        d["drivetrain"]["battery"]["auxiliary_power"] = val["auxiliary_power"]
    if "torque_signal_gain" in val:
        d["sensors"]["drive_torque_gain_error"] = val["torque_signal_gain"]
    if "torque_signal_offset" in val:
        d["sensors"]["drive_torque_offset"] = val["torque_signal_offset"]
    if "accelerometer_bias" in val and "accel_x" in d["sensors"].get("channels", {}):
        d["sensors"]["channels"]["accel_x"]["bias"] = val["accelerometer_bias"]


# ============================================================================================ calibrate
def calibrate(trips: Sequence[Trip], sim: SimConfig, settings: CalibrationSettings | None = None,
              progress: Callable[[str, float], None] | None = None) -> Calibration:
    """Calibrate ``sim``'s vehicle to the reference ``trips`` (module doc). The fit runs ``settings.passes`` times,
    each against the previous pass's spec and its own floor (the floor is fitted on the spec's own trips, so a
    spec's floor shifts a little with the spec; the second pass takes up what the first left), then the
    reference trips are re-run against the written spec for the held-out check."""
    settings = settings or CalibrationSettings()
    say = progress or (lambda what, frac: None)
    if not trips:
        raise DiagnosisError("no reference trips given")
    ds = settings.diagnosis()
    n = settings.passes + 1

    def run_of(spec: VehicleSpec, k: int) -> Run:
        return Run(trips, SimConfig(spec, sim.effects, sim.name if k == 0 else f"{sim.name} calibrated"), ds,
                   np.random.default_rng(settings.seed), lambda what, frac: say(what, (k + frac) / n))

    run = run_of(sim.vehicle, 0)
    table = stage_table(run)
    split = stage_split(run, table)
    fl = first = stage_floor(run, table, split, None, None)
    spec = sim.vehicle
    ratio = drive_ratio(table.frame, split, spec)
    if ratio is not None and abs(ratio.calibrated / ratio.sim - 1.0) > RATIO_TOLERANCE:
        # the logged motor speed says the drive ratio is not the sim's: every force the pipeline derives from the
        # logged torque scales with it, so the fit starts from the spec with the measured ratio
        spec = with_drive_ratio(spec, ratio.calibrated / ratio.sim)
        run = run_of(spec, 0)
        fl = stage_floor(run, stage_table(run), split, None, None)
    signals = (True, False) if _bev(spec) and POWER_RESIDUAL in table.frame else (True,)
    variants = [_variant(fl, spec, signal, split, first, run_of, settings, say) for signal in signals]
    _, signal, spec, passes, heldout, bins = min(variants, key=lambda v: v[0])
    params = _combined(passes) + ([ratio] if ratio is not None else [])
    notes = [f"{p.name}: {p.flag}" for p in params if p.flag]
    if len(variants) > 1:
        other = next(v for v in variants if v[1] != signal)
        kept = "calibrated from the battery power" if signal else "kept at the sim's"
        alternative = "keeping them" if signal else "calibrating them from the battery power"
        h = other[4]
        notes.append(f"torque-signal gain and offset {kept}: held-out force / battery-power RMSE "
                     f"{heldout.force_after:.1f} N / {heldout.power_after:.0f} W, against {h.force_after:.1f} N / "
                     f"{h.power_after:.0f} W {alternative}")
    say("done", 1.0)
    amb = table.frame["ambient_temperature"].to_numpy(dtype=float)
    amb = amb[np.isfinite(amb)]
    return Calibration(sim.name, list(pd.unique(table.frame["trip"])), params, heldout, bins, notes, spec,
                       float(np.median(amb)) if amb.size else float("nan"))


def _variant(fl, spec: VehicleSpec, signal: bool, split: Split, first, run_of: Callable[[VehicleSpec, int], Run],
             settings: CalibrationSettings, say: Callable[[str, float], None]) -> tuple:
    """The passes of one variant (``signal``: the torque signal calibrated from the battery power or kept) from
    the floor stage ``fl`` of ``spec``, and the held-out check of its spec: (held-out force RMSE [N], signal, spec,
    passes, held-out gap, bins)."""
    n = settings.passes + 1
    passes: list[list[CalibratedParameter]] = []
    for k in range(settings.passes):
        if k:
            run = run_of(spec, k)
            fl = stage_floor(run, stage_table(run), split, None, None)
        say(f"fitting pass {k + 1}" + ("" if signal else " (torque signal as the sim's)"), (k + 0.9) / n)
        passes.append(_fit_pass(fl, split, spec, settings, signal))
        spec = calibrated_spec(spec, passes[-1])
    after = run_of(spec, settings.passes)
    heldout, bins = _heldout(first, stage_floor(after, stage_table(after), split, None, None), split)
    return (_score(heldout), signal, spec, passes, heldout, bins)


def _score(h: HeldOutGap) -> float:
    """What a variant leaves of the held-out gap on both sides it changes: force RMSE after / before plus battery
    power RMSE after / before (the force side alone where there is no battery power)."""
    terms = [h.force_after / h.force_before, h.power_after / h.power_before]
    finite = [t for t in terms if np.isfinite(t)]
    return float(sum(finite)) if finite else np.inf


def _fit_pass(fl, split: Split, spec: VehicleSpec, settings: CalibrationSettings, signal: bool = True
              ) -> list[CalibratedParameter]:
    """One pass: the energy side, the accelerometer bias from the elevation, the force side given both
    (``signal`` False: the torque-signal gain and offset stay the sim's)."""
    frame, model = fl.table.frame, fl.table.model
    energy = fit_energy(frame, split, spec, model, settings, signal)
    bias = accelerometer_bias_from_elevation(frame, split, model.mass)
    known = _torque_terms(frame, spec, model, energy) - model.mass * (bias.value if bias is not None else 0.0)
    force = fit_force(frame, split, fl.residual, spec, model, settings, known)
    return _parameters(force, energy, bias, spec, model, settings)


RATIO_TOLERANCE = 0.003    # a measured drive ratio within 0.3 % of the sim's is the sim's


def drive_ratio(frame: pd.DataFrame, split: Split, spec: VehicleSpec) -> CalibratedParameter | None:
    """The overall drive ratio per wheel radius i_G(1) i_D / r_W [1/m] measured from the logged motor speed:
    the median of ω_E / (v i_G(G) / i_G(1)) over the training rows above 5 m/s (where a wheel barely slips), with
    the standard error of the median over 10 s blocks; None without a logged motor speed."""
    if SPEED_DERIVED not in frame or frame[SPEED_DERIVED].all():
        return None
    d = spec.drivetrain
    gear = np.clip(np.rint(np.nan_to_num(frame["gear"].to_numpy(dtype=float), nan=1.0)), 1, d.n_gears).astype(int)
    rel = np.asarray(d.gear_ratios, dtype=float)[gear - 1] / d.gear_ratios[0]
    v = frame["speed"].to_numpy(dtype=float)
    r = frame[MOTOR_SPEED].to_numpy(dtype=float) / (v * rel)
    rows = split.train & (v > 5.0) & np.isfinite(r) & ~frame[SPEED_DERIVED].to_numpy(bool)
    if rows.sum() < 100:
        return None
    per_block = pd.Series(r[rows]).groupby(split.blocks[rows]).median().to_numpy()
    value = float(np.median(per_block))
    se = float(1.2533 * 1.4826 * np.median(np.abs(per_block - value)) / np.sqrt(per_block.size))
    sim = d.gear_ratios[0] * d.final_drive / spec.tires.dynamic_radius
    flag = "" if DRIVE_RATIO.low <= value <= DRIVE_RATIO.high else "outside the physical range"
    return CalibratedParameter(DRIVE_RATIO.name, DRIVE_RATIO.symbol, "force", value - sim, se, "1/m", float(sim),
                               value, se, "1/m", 0.0, DRIVE_RATIO.low, DRIVE_RATIO.high, True, flag,
                               DRIVE_RATIO.description)


def with_drive_ratio(spec: VehicleSpec, factor: float) -> VehicleSpec:
    """The spec with its final drive times ``factor`` (the wheel radius, which the rolling and inertia terms
    also use, stays)."""
    try:
        return spec.replace(**{"drivetrain.final_drive": spec.drivetrain.final_drive * factor})
    except VehicleSpecError as exc:
        raise DiagnosisError(f"the measured drive ratio gives no valid spec: {exc}") from None


#: parameters whose calibrated value is a factor on the sim's (passes multiply, the sim's value is 1)
RELATIVE = ("motor_loss_scale", "cornering")


def _combined(passes: list[list[CalibratedParameter]]) -> list[CalibratedParameter]:
    """The passes as one calibration against the first pass's sim: its sim value, the last pass's value (factors
    multiplied), uncertainty, prior, determination and flag; ``delta`` = calibrated - sim."""
    out = []
    for first in passes[0]:
        chain = [next(p for p in ps if p.name == first.name) for ps in passes]
        last = chain[-1]
        value = float(np.prod([p.calibrated for p in chain])) if first.name in RELATIVE else last.calibrated
        se = last.calibrated_std * (value / last.calibrated if first.name in RELATIVE and last.calibrated else 1.0)
        out.append(CalibratedParameter(first.name, first.symbol, first.side, value - first.sim, se,
                                       first.value_unit, first.sim, value, se, first.value_unit, first.prior_std,
                                       first.low, first.high, last.determined, last.flag, first.description,
                                       last.held))
    return out


def _held_flag(p: Parameter, c: CalibratedParameter) -> str:
    v = c.calibrated
    if p.low < v < p.high:          # not fitted (the torque signal kept at the sim's, :func:`fit_energy`)
        return f"kept at the sim's value; the reference trips wanted a change of {c.held:+.4g} {p.unit}"
    end = "upper" if abs(v - p.high) <= abs(v - p.low) else "lower"
    return (f"held at the {end} end of its physical range [{p.low:g}, {p.high:g}] {p.value_unit}: the reference "
            "trips wanted beyond it")


def _parameters(force: SideFit, energy: SideFit | None, bias, spec: VehicleSpec, model: SimForceModel,
                settings: CalibrationSettings) -> list[CalibratedParameter]:
    out = []
    for fit in (force, energy):
        if fit is None:
            continue
        se = np.sqrt(np.clip(np.diag(fit.cov), 0, None))
        for j, name in enumerate(fit.names):
            # the loss error ε is reported as the two efficiencies it sets: ε_t = ε, ε_r = -ε
            for reported, sign in (((name, 1.0),) if name != DRIVETRAIN_LOSS else
                                   (("drivetrain_efficiency_traction", 1.0), ("drivetrain_efficiency_regen", -1.0))):
                p = _param(reported)
                out.append(_calibrated(p, sign * float(fit.x[j]), float(se[j]), spec, model,
                                       p.prior(spec, model) * settings.prior_scale))
                out[-1].held = sign * fit.held.get(name, 0.0)
                if out[-1].held and not out[-1].flag:
                    out[-1].flag = _held_flag(p, out[-1])
    if bias is not None:
        out.append(_calibrated(ACCEL_BIAS, bias.value, bias.std_error, spec, model, 0.0))
    return out


def _heldout(before, after, split: Split) -> tuple[HeldOutGap, list[BinGap]]:
    test = split.test
    fb = before.table.frame
    fa = after.table.frame
    rb = np.nan_to_num(before.residual)
    ra = np.where(split.valid, np.nan_to_num(fa["residual"].to_numpy(dtype=float)), 0.0)
    pb = fb[POWER_RESIDUAL].to_numpy(dtype=float) if POWER_RESIDUAL in fb else np.full(len(fb), np.nan)
    pa = fa[POWER_RESIDUAL].to_numpy(dtype=float) if POWER_RESIDUAL in fa else np.full(len(fa), np.nan)
    f0, f1 = RobustSummary.of(rb[test]).rmse, RobustSummary.of(ra[test]).rmse
    s0, s1 = RobustSummary.of(pb[test]), RobustSummary.of(pa[test])
    gap = HeldOutGap(f0, f1, _shrink(f0, f1), s0.rmse, s1.rmse, _shrink(s0.rmse, s1.rmse), s0.median, s1.median)
    return gap, residual_bins(fb, test, rb, ra)


def _shrink(before: float, after: float) -> float:
    return float(1.0 - after / before) if np.isfinite(before) and before > 0 else float("nan")


SPEED_EDGES_KMH = (0.0, 30.0, 50.0, 70.0, 90.0, 110.0, 250.0)
ACCEL_EDGES = (-np.inf, -1.5, -0.5, -0.1, 0.1, 0.5, 1.5, np.inf)


def residual_bins(frame: pd.DataFrame, rows: np.ndarray, before: np.ndarray, after: np.ndarray,
                  min_n: int = 20) -> list[BinGap]:
    """Median residual before / after per speed [km/h] x acceleration [m/s²] bin on ``rows`` (bins with at least
    ``min_n`` rows)."""
    v = frame["speed"].to_numpy(dtype=float) * 3.6
    a = frame["acceleration"].to_numpy(dtype=float)
    iv = np.searchsorted(SPEED_EDGES_KMH, v, side="right") - 1
    ia = np.searchsorted(ACCEL_EDGES, a, side="right") - 1
    out = []
    for i in range(len(SPEED_EDGES_KMH) - 1):
        for j in range(len(ACCEL_EDGES) - 1):
            sel = rows & (iv == i) & (ia == j)
            if sel.sum() < min_n:
                continue
            out.append(BinGap(f"{SPEED_EDGES_KMH[i]:g}-{SPEED_EDGES_KMH[i + 1]:g} km/h",
                              f"{ACCEL_EDGES[j]:g}..{ACCEL_EDGES[j + 1]:g} m/s^2", int(sel.sum()),
                              float(np.median(before[sel])), float(np.median(after[sel]))))
    return out


