"""Base mismatch first, effects second: a vehicle preset never matches the car, so before any effect is named the
diagnosis calibrates the sim's base road load against the trips and reports it as its own block.

Base parameters (the catalog term of that name, :mod:`.catalog`): mass Δm_V [kg] (``mass_offset``), drag area
Δc_x A_V [m²] (``drag_area``), rolling resistance factor - 1 (``rolling_scale``), drive-train efficiency ε
(reported as ``drive_efficiency``: F_xV,measured = F_xV,sim-side + ε |F_xV,sim-side|, i.e. the tractive force
per drive force is (1 + ε) in traction and (1 - ε) in regeneration: a mesh loss proportional to the transmitted
torque, section 2.6), rotating inertia ΔI_red/r_W² [kg] (``rotational_inertia``: dv/dt alone, eq. 2.6/2.17),
cornering resistance Δm_V²/c_yW (``cornering``, eq. 2.15; only with a path curvature), brake gain k
(``friction_brake``: the wheels brake with (1 + k) F_B; only where the trips log brake pressure); reported with
them but not in their force fit: the accelerometer bias b [m/s²] from the logged elevation (``accel_bias``,
:func:`accelerometer_bias_from_elevation`). With inertia and cornering the sim's drive force lies in the
block's span, so no drive-force direction is left over for a candidate to pick up a preset's mismatch.

Why the efficiency and not a symmetric torque scale: F_xV,sim-side = m_V (v̇ + g sin θ + g cos θ f_r) + ρ/2 c_x A
v² + cornering is, term by term, the span of the mass, rolling and drag-area regressors, so a symmetric scale
(1 + ε) F_xV,sim-side is collinear with them and the joint fit splits a payload arbitrarily between mass and
scale (seen: +200 kg withheld -> mass unchanged, scale -0.13 -> -0.28). A symmetric drive-torque gain is therefore
not a base parameter: with an unmatched preset it is indistinguishable from a larger mass and road load.

The parameters are fitted jointly by weighted least squares on the robust, regime-normalised residual of
:mod:`.robust` (training rows; braking rows fit the brake gain only), with cluster-robust standard errors over
10 s blocks (:func:`.stats.cluster_covariance`). A parameter is *significant* when |value| >= z SE (z = 2.58,
two-sided 1 %) and its contribution's RMS is at least ``min_size`` N.

With ``DiagnosisSettings.base_first`` the candidate effects are then ranked and selected over the calibrated base
(with ``joint_base`` the base columns join every design and are refitted with each candidate: a nested comparison
base vs base + candidate, :class:`.selection.Selector`): an effect is named only for what it adds beyond the base.
A withheld effect whose signature *is* a base parameter (a payload is a mass offset) then shows up in the base
block, not as an effect — the base block says which catalog effect each significant base departure stands for.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from roadload.estimators.batch import BatchInputError, m_estimate
from roadload.estimators.models import ACCELERATION
from roadload.units import G

from .catalog import DRIVE_FORCE, get_candidate
from .energy import MOTOR_SPEED, energy_columns
from .forcemodel import SimForceModel, columns_of
from .records import Record, optional
from .robust import RobustTarget, weighted_fit, winsorised
from .selection import Split, design
from .stats import cluster_covariance

BASE_PARAMETERS: tuple[tuple[str, str], ...] = (
    ("mass_offset", "mass m_V"), ("drag_area", "drag area c_x A_V"), ("rolling_scale", "rolling resistance f_r"),
    ("drive_efficiency", "drive-train efficiency"), ("rotational_inertia", "rotating inertia I_red/r_W^2"),
    ("cornering", "cornering resistance m_V^2/c_yW"), ("friction_brake", "brake gain X_B"))
EFFICIENCY_PARAMETER = "drive-train loss error epsilon (|F_drive|)"
INERTIA_PARAMETER = "delta I_red/r_W^2 (all gears)"


@dataclass
class PhysicalValue(Record):
    """A base parameter in the sim's own terms: the sim's value, the calibrated one and their unit; for the
    drive-train efficiency the calibrated value is the efficiency in traction and ``calibrated_regen`` the one in
    regeneration; ``flag`` says why a value is not physically plausible (an efficiency above 1 or below 0.7)."""

    sim: float
    calibrated: float
    unit: str
    calibrated_regen: float | None = optional()
    flag: str | None = optional()


@dataclass
class BaseParameter(Record):
    """One fitted base parameter: ``name`` (what it is), the catalog ``candidate`` it stands for, the fitted
    ``parameter`` with its ``unit``, value and standard error, the RMS of its contribution (N, or W on the energy
    side) and whether it is significant; ``physical``: the value in the sim's terms (force side); ``in_fit``
    False and ``method`` for a parameter reported with the block but fitted apart (accelerometer bias)."""

    name: str
    candidate: str
    parameter: str
    unit: str
    value: float
    std_error: float
    size_rms: float
    significant: bool
    in_fit: bool | None = optional()
    physical: PhysicalValue | None = optional()
    method: str | None = optional()


@dataclass
class BaseBlock(Record):
    """A base block (force or energy side): its parameters, how they were fitted, the significance level z and
    size gate (N or W), whether the effects were selected over it; ``note`` when nothing could be fitted."""

    parameters: list[BaseParameter] = field(default_factory=list)
    note: str | None = optional()
    method: str | None = optional()
    z: float | None = optional()
    min_size: float | None = optional()
    unit_of_size: str | None = optional()
    used_for_effects: bool | None = optional()

    def parameter(self, candidate: str) -> BaseParameter | None:
        """The parameter standing for ``candidate`` (None when the block has none)."""
        return next((p for p in self.parameters if p.candidate == candidate), None)


def _efficiency_column(cols: dict) -> np.ndarray:
    """|F_xV,sim-side| [N]: the base drive-train efficiency's regressor (module doc)."""
    return np.abs(np.nan_to_num(np.asarray(cols[DRIVE_FORCE], dtype=float)))[:, None]
Z_SIGNIFICANT = 2.58


def base_columns(table: pd.DataFrame, model: SimForceModel, braking: np.ndarray,
                 valid: np.ndarray) -> tuple[np.ndarray, list[dict]]:
    """Regressors of the base calibration with one description per column; a parameter whose channels the trips
    lack (no brake pressure: no brake gain) is left out; non-brake columns are zero on ``braking`` rows."""
    cols = columns_of(table)
    sub = {k: np.asarray(v)[valid] for k, v in cols.items()}
    blocks, info = [], []
    for name, label in BASE_PARAMETERS:
        cand = get_candidate(name)
        if name == "rotational_inertia":
            # the rotating masses' share of the inertial mass (eq. 2.6/2.17: wheels, rotor, gears): dv/dt alone;
            # a preset's wheels and rotor never match the car either, and without it the sim's drive force (whose
            # inertial term is m_red dv/dt, not m dv/dt) is not in the block's span
            if ACCELERATION not in sub or not np.isfinite(sub[ACCELERATION]).any():
                continue
            A = np.nan_to_num(np.asarray(cols[ACCELERATION], dtype=float))[:, None]
            names, units = [INERTIA_PARAMETER], ["kg"]
            A = np.where(np.asarray(braking)[:, None], 0.0, A)
            blocks.append(A)
            info += [{"name": label, "candidate": name, "parameter": n, "unit": u} for n, u in zip(names, units)]
            continue
        if cand.missing(sub):
            continue
        if name == "drive_efficiency":
            A, names, units = _efficiency_column(cols), [EFFICIENCY_PARAMETER], ["1"]
        else:
            d = design([(cand, None)], model, cols)
            A, names, units = d.A, d.names, d.units
        A = A if cand.is_brake else np.where(np.asarray(braking)[:, None], 0.0, A)
        blocks.append(A)
        info += [{"name": label, "candidate": name, "parameter": n, "unit": u} for n, u in zip(names, units)]
    return (np.hstack(blocks) if blocks else np.zeros((len(table), 0))), info


EFFICIENCY_PLAUSIBLE = (0.7, 1.0)


def efficiency_value(eta_sim: float, epsilon: float) -> PhysicalValue:
    """The drive-train efficiency the base block's loss error ε stands for. The pipeline turns the logged torque
    into force with the sim's η (T i η / r_W in traction, T i / (η r_W) in regeneration), so a measured force
    (1 + ε) times the true one in traction means η_t = η_sim / (1 + ε), and (1 - ε) times in regeneration
    η_r = η_sim (1 - ε). Flagged when either leaves [0.7, 1]."""
    eta_t, eta_r = eta_sim / (1.0 + epsilon), eta_sim * (1.0 - epsilon)
    lo, hi = EFFICIENCY_PLAUSIBLE
    bad = [f"{what} {eta:.3f}" for what, eta in (("traction", eta_t), ("regeneration", eta_r))
           if not lo <= eta <= hi]
    flag = (f"implausible efficiency: {', '.join(bad)} outside [{lo:g}, {hi:g}] (a base mismatch the efficiency "
            "absorbs: mass, road load or the torque signal)") if bad else None
    return PhysicalValue(eta_sim, eta_t, "eta in traction (eta in regeneration: calibrated_regen)", eta_r, flag)


def _physical(model: SimForceModel, candidate: str, v: float) -> PhysicalValue:
    """The calibrated base value in the sim's own terms (mass [kg], drag area [m²], factors)."""
    if candidate == "mass_offset":
        return PhysicalValue(model.mass, model.mass + v, "kg")
    if candidate == "drag_area":
        return PhysicalValue(model.drag_area, model.drag_area + v, "m^2")
    if candidate == "rolling_scale":
        return PhysicalValue(1.0, 1.0 + v, "x f_r(v)")
    if candidate == "cornering":
        return PhysicalValue(0.0, v, "kg^2 rad/N (added to m_V^2/c_yW, eq. 2.15)")
    if candidate == "rotational_inertia":
        return PhysicalValue(0.0, v, "kg (added to the sim's reduced mass)")
    if candidate == "drive_efficiency":
        return efficiency_value(model.drivetrain_efficiency, v)
    return PhysicalValue(1.0, 1.0 + v, "x X_B")


def base_calibration(table: pd.DataFrame, target: RobustTarget, split: Split, model: SimForceModel,
                     min_size: float = 15.0) -> tuple[BaseBlock, np.ndarray]:
    """The base block (see module doc) and the base design (n x k) for the effects beyond it."""
    A, info = base_columns(table, model, target.braking, split.valid)
    if A.shape[1] == 0:
        return BaseBlock(note="no base parameter can be fitted on these trips"), A
    rows = split.train
    w = target.weight
    X = weighted_fit(A, target.r_w, w, rows)
    resid = target.r_w - A @ X
    cov = cluster_covariance(A[rows], resid[rows], split.blocks[rows], w[rows])
    se = np.sqrt(np.clip(np.diag(cov), 0, None))
    out = []
    for j, meta in enumerate(info):
        contrib = A[rows, j] * X[j]
        size = float(np.sqrt(np.mean(contrib ** 2)))
        out.append(BaseParameter(meta["name"], meta["candidate"], meta["parameter"], meta["unit"], float(X[j]),
                                 float(se[j]), size, bool(abs(X[j]) >= Z_SIGNIFICANT * se[j] and size >= min_size),
                                 physical=_physical(model, meta["candidate"], float(X[j]))))
    bias = accelerometer_bias_from_elevation(table, split, model.mass, min_size)
    if bias is not None:    # reported with the block, not part of its force fit (see the function)
        out.append(bias)
    return BaseBlock(out, method="weighted least squares on the robust residual (training rows), cluster-robust "
                                 "standard errors over 10 s blocks", z=Z_SIGNIFICANT, min_size=min_size), A


ENERGY_PARAMETERS: tuple[tuple[str, str, str, str], ...] = (
    ("auxiliary_power", "auxiliary power P_aux", "delta P_aux", "W"),
    ("motor_efficiency", "motor / inverter losses", "loss scale error of P_loss(omega_E, T_E)", "1"),
    ("torque_scale", "drive-torque signal gain", "drive-torque signal gain error g", "1"),
    ("torque_offset", "drive-torque signal offset", "drive-torque signal offset T_off", "N*m"))


def energy_base_calibration(table: pd.DataFrame, power_residual: np.ndarray, split: Split, spec,
                            min_power_size: float = 100.0, clip: float = 5.0) -> BaseBlock:
    """The energy side's base block (battery-electric trips): the battery-power residual P_el,measured -
    P_el,sim [W] fitted on the calibration's energy model (:func:`.energy.energy_columns`: a constant, the sim's
    motor loss P_loss, -T_E ω_E and -ω_E: auxiliary power, loss scale, drive-torque signal gain g and offset) by
    least squares on the training rows, the residual winsorised at ``clip`` MAD scales as the calibration fits it
    — so the block reads 0 on the calibration's own trips and a signal gain g as g —, cluster-robust standard
    errors over 10 s blocks; significant as on the force side (|value| >= z SE and contribution RMS >=
    ``min_power_size`` W). With an unmatched preset an auxiliary load is a shift of this block (as a payload is
    of the mass), which the selftest's scoring compares against its reference drive; with ``base_first`` the
    energy-side effects are judged over this block (:func:`roadload.sim2real.diagnose.diagnose`)."""
    A = energy_columns(table, spec)
    y = np.asarray(power_residual, dtype=float)
    p_motor = table["drive_torque"].to_numpy(dtype=float) * table[MOTOR_SPEED].to_numpy(dtype=float)
    rows = split.train & np.isfinite(y) & np.isfinite(p_motor)
    if rows.sum() < 100:
        return BaseBlock(note="too few rows with battery power")
    yw, w = winsorised(np.where(rows, y, 0.0), rows, clip)
    X = weighted_fit(A, yw, w, rows)
    cov = cluster_covariance(A[rows], yw[rows] - A[rows] @ X, split.blocks[rows], w[rows])
    se = np.sqrt(np.clip(np.diag(cov), 0, None))
    out = []
    for j, (cand, label, param, unit) in enumerate(ENERGY_PARAMETERS):
        size = float(np.sqrt(np.mean((A[rows, j] * X[j]) ** 2)))
        out.append(BaseParameter(label, cand, param, unit, float(X[j]), float(se[j]), size,
                                 bool(abs(X[j]) >= Z_SIGNIFICANT * se[j] and size >= min_power_size)))
    return BaseBlock(out, method=f"least squares on the battery-power residual winsorised at {clip:g} MAD scales "
                                 "(training rows), cluster-robust standard errors over 10 s blocks",
                     z=Z_SIGNIFICANT, min_size=min_power_size, unit_of_size="W")


ELEVATION = "elevation"
MIN_BIAS_SEGMENTS = 10


def accelerometer_bias_from_elevation(table: pd.DataFrame, split: Split, mass: float,
                                      min_size: float = 15.0) -> BaseParameter | None:
    """The accelerometer bias b [m/s²] as a base parameter, from the logged elevation h (GNSS, map) instead of
    the force balance: eq. 5.2 turns a bias into a grade error, sin θ̂ = sin θ + b/g, so the elevation climbed
    along the grade, ∫ sin θ̂ ds, drifts from the logged one by (b/g) s. Per split segment (60 s) the drift
    increment e = Δ∫ sin θ̂ ds - Δh is regressed on the distance increment Δs through the origin,
    b = g x (slope), by a Huber M-estimate over the training segments, with the segments' sandwich standard error
    (increments of different segments are independent: the grade noise integrates within a segment, the GNSS
    error enters at its ends). Size: the force m_V |b| [N] the sim's climbing term is off by. On the force side a
    constant m_V b is, over an unmatched preset's nearly flat f_r(v), the rolling-resistance factor; the
    elevation separates the two. None without a logged elevation."""
    if ELEVATION not in table.columns:
        return None
    h = table[ELEVATION].to_numpy(dtype=float)
    if not np.isfinite(h).any():
        return None
    trip = table["trip"].to_numpy()
    th = np.nan_to_num(table["gradient_angle"].to_numpy(dtype=float))
    dist = table["distance"].to_numpy(dtype=float)
    seg = np.asarray(split.segments)
    train = split.train
    e_list, s_list = [], []
    for k in pd.unique(trip):
        rows = np.flatnonzero(trip == k)
        ds = np.diff(dist[rows], prepend=dist[rows][0])
        climb = np.cumsum(np.sin(th[rows]) * ds)
        hk, sk, tr = h[rows], seg[rows], train[rows]
        for s_id in np.unique(sk[tr]):
            idx = np.flatnonzero((sk == s_id) & np.isfinite(hk))
            if idx.size < 2:
                continue
            i0, i1 = idx[0], idx[-1]
            e_list.append((climb[i1] - climb[i0]) - (hk[i1] - hk[i0]))
            s_list.append(dist[rows][i1] - dist[rows][i0])
    e, s = np.asarray(e_list), np.asarray(s_list)
    moving = s > 1.0
    e, s = e[moving], s[moving]
    if e.size < MIN_BIAS_SEGMENTS:
        return None
    # Huber M-estimate through the origin (a segment with an elevation glitch — a GNSS jump, a trip turned at the
    # end of the road — must not decide it), sandwich standard error with the final weights
    try:
        fit = m_estimate(s[:, None], e, "huber", max_iter=30, tol=1e-8)
        slope, wts = float(fit.X[0]), np.asarray(fit.weights, dtype=float)
    except BatchInputError:
        slope, wts = float(np.sum(e * s) / np.sum(s ** 2)), np.ones_like(s)
    resid = e - slope * s
    se_slope = float(np.sqrt(np.sum((wts * s * resid) ** 2)) / np.sum(wts * s ** 2))
    b, se = G * slope, G * se_slope
    size = float(mass * abs(b))
    return BaseParameter("accelerometer bias (from the logged elevation)", "accel_bias", "accelerometer bias b",
                         "m/s^2", b, se, size, bool(abs(b) >= Z_SIGNIFICANT * se and size >= min_size), in_fit=False,
                         physical=PhysicalValue(0.0, b, "m/s^2 (eq. 5.2 grade offset b/g)"),
                         method=f"drift of the eq. 5.2 climb against the logged elevation over {e.size} training "
                                "segments")
