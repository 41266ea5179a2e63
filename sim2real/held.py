"""Directions the calibration held at a physical bound, and the check that keeps the diagnosis from naming them.

The calibration (:mod:`.calibrate`) fits the base vehicle's changes within their physical ranges: a change the
data pull beyond its range is held at the bound and the others are refitted given it. What the bound held back
stays in every trip diagnosed against that calibration, along the held parameter's own regressor: a motor whose
losses the data want below the loss scale's lower bound leaves -(s_low - s_wanted) P_loss on every trip. An
effect whose fitted contribution lies along such a direction, with the sign the data wanted, is not separable
from that base error, whatever its held-out gain: the reference trips showed the same.

The calibrated sim carries the held directions (:attr:`.simconfig.SimConfig.held_at_bound`: the fitted
parameter's name -> what the bound held back, Δ = fitted change beyond the bound - the bound, recorded only
where the data wanted beyond it by at least 2.58 standard errors). :func:`separability_check` builds the
diagnosis' check: the candidate's fitted contribution c on the training rows is regressed on the held directions'
regressors a_j with coefficients 0 <= β_j <= |Δ_j| along sign(Δ_j) a_j (each only in the direction, and at most
by the amount, the reference trips showed; bounded least squares); when they explain at least
:data:`NOT_SEPARABLE_SHARE` of ‖c‖² the candidate is reported as not separable from the calibration's base
error instead of being accepted.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping

import numpy as np
import pandas as pd
from scipy.optimize import lsq_linear

from roadload.estimators.models import ACCELERATION, GRADIENT_ANGLE, PATH_CURVATURE, SPEED
from roadload.units import G

from .catalog import BRAKE_FORCE, DRIVE_FORCE
from .energy import energy_columns
from .forcemodel import AIR_DENSITY, SimForceModel, columns_of
from .selection import NOT_SEPARABLE, design

#: the fitted drive-train parameter of the force side: the mesh-loss error ε of the column |F_drive|
DRIVETRAIN_LOSS = "drivetrain_loss"
#: the energy side's fitted parameters, in the order of :func:`.energy.energy_columns`
ENERGY_NAMES = ("auxiliary_power", "motor_loss_scale", "torque_signal_gain", "torque_signal_offset")
#: share of a candidate's fitted contribution (‖·‖²) the held directions must explain to make it inseparable
NOT_SEPARABLE_SHARE = 0.5


def force_columns(table: pd.DataFrame, model: SimForceModel) -> tuple[np.ndarray, list[str]]:
    """The calibration's force-side regressors and the fitted parameter each belongs to (:mod:`.calibrate`):
    mass g sin θ + v̇ + g cos θ f_r(v), rolling resistance m g cos θ (1, v, v⁴), drag area ρ/2 v², the drive-train
    loss error |F_drive|, rotating inertia v̇; brake gain F_B and cornering v⁴ κ²/4 only where the trips log brake
    pressure / a path curvature."""
    c = {k: table[k].to_numpy(dtype=float) for k in (SPEED, ACCELERATION, GRADIENT_ANGLE, AIR_DENSITY, DRIVE_FORCE)}
    th, v, a = c[GRADIENT_ANGLE], c[SPEED], c[ACCELERATION]
    f = np.nan_to_num(c[DRIVE_FORCE])
    m_g_cos = model.mass * G * np.cos(th)
    cols = {"mass": G * np.sin(th) + a + G * np.cos(th) * model.rolling_resistance_coefficient(v),
            "rolling_resistance_f0": m_g_cos, "rolling_resistance_f1": m_g_cos * v,
            "rolling_resistance_f4": m_g_cos * v ** 4,
            "drag_area": 0.5 * c[AIR_DENSITY] * v ** 2,
            DRIVETRAIN_LOSS: np.abs(f), "rotating_inertia": a}
    if table.get("has_brake_pressure", pd.Series([False])).any():
        cols["brake_gain"] = np.nan_to_num(table[BRAKE_FORCE].to_numpy(dtype=float))
    kappa = np.nan_to_num(table[PATH_CURVATURE].to_numpy(dtype=float))
    if np.any(kappa != 0):
        cols["cornering"] = v ** 4 * kappa ** 2 / 4.0
    names = list(cols)
    return np.nan_to_num(np.column_stack([cols[n] for n in names])), names


def held_directions(table: pd.DataFrame, model: SimForceModel, spec, held: Mapping[str, float], side: str
                    ) -> tuple[np.ndarray, np.ndarray, list[str]]:
    """The regressors of the ``held`` parameters of ``side`` ("force" / "power"), each times the sign of what
    its bound held back (n x k), that amount |Δ| per column (k) and the names; k = 0 when none of them is on that
    side."""
    if side == "force":
        A, names = force_columns(table, model)
    else:
        A, names = energy_columns(table, spec), list(ENERGY_NAMES)
    pick = [(names.index(n), float(d), n) for n, d in held.items() if n in names and d and np.isfinite(d)]
    if not pick:
        return np.zeros((len(table), 0)), np.zeros(0), []
    return (np.column_stack([A[:, j] * np.sign(d) for j, d, _ in pick]), np.array([abs(d) for _, d, _ in pick]),
            [n for _, _, n in pick])


def held_share(contribution: np.ndarray, directions: np.ndarray, amounts: np.ndarray) -> float:
    """Share of ‖c‖² the held directions explain with coefficients in [0, amount] (0 without any)."""
    cc = float(contribution @ contribution)
    if directions.shape[1] == 0 or not cc > 0:
        return 0.0
    fit = lsq_linear(directions, contribution, bounds=(np.zeros(amounts.size), np.asarray(amounts, dtype=float)))
    r = contribution - directions @ fit.x
    return float(1.0 - (r @ r) / cc)


def separability_check(held: Mapping[str, float], table: pd.DataFrame, rows: np.ndarray, model: SimForceModel,
                       spec, side: str) -> Callable | None:
    """(candidate, fitted parameters, shape, size) -> None, or why the candidate is not separable from the
    calibration's base error (module doc); None when the calibration held nothing on this side."""
    P, amounts, names = held_directions(table, model, spec, held, side)
    if not names:
        return None
    P = P[rows]
    cols = columns_of(table)

    def check(cand, params: dict, shape, size: float) -> str | None:
        d = design([(cand, shape)], model, cols)
        x = np.array([params.get(n, 0.0) for n in d.names], dtype=float)
        share = held_share(d.A[rows] @ x, P, amounts)
        if share >= NOT_SEPARABLE_SHARE:
            return (f"{NOT_SEPARABLE}: the calibration held {', '.join(names)} at a physical bound, and those "
                    f"directions explain {share:.0%} of the fitted {cand.name}")
        return None

    return check
