"""The sim's own floor: what the simulator does that its analytic force balance (:mod:`.forcemodel`) does not
say, measured on trips the sim itself produced and processed exactly like the recorded ones.

Even a trip of the sim leaves a residual F_xV,measured - F_xV,sim: the pipeline's simplified drive-train loss
tables, the accelerometer's pitch under acceleration, smoothing delays, toe-in drag. The floor is a least-squares
fit of that residual on a small generic basis; the sim's force balance used for the diagnosis is then
F_xV,sim + floor, so the gap that remains is the one between the simulator and the data, not between the
simulator and its own equations. Sim trips are reduced to the channels the recorded trips have, so both sides
go through the same pipeline steps.

The basis is nearly collinear: F_sim,drive = m_V (v̇ + g sin θ) + resistances, and 1, v, v², v̇, g sin θ span
almost all of it; on the sim's own trips (one air density, one rolling law) only a direction of relative singular
value ~3e-5 separates them. A plain least-squares fit puts coefficients of ±2e4 on that direction that cancel on
the sim's trips and extrapolate to tens of N on any recorded trip whose air density differs a little (a 2 K
warmer logged ambient gave 47 N at 130 km/h). The fit is therefore a truncated SVD (:data:`RCOND`): directions
the sim's own trips do not determine are left out of the floor.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd

from roadload.trip import Trip
from roadload.units import G

from .errors import DiagnosisError
from .catalog import get_candidate
from .forcemodel import columns_of
from .selection import design
from .energy import power_basis

RCOND = 1e-4      # relative singular value below which a direction of the scaled floor basis is not fitted
BASIS: tuple[str, ...] = ("1", "v", "v^2", "dv/dt", "g sin(theta)", "F_sim,drive", "|F_sim,drive|",
                          "dF_sim,drive/dt", "v^4/r^2", "F_brake")


def basis(frame: pd.DataFrame, sim_force: np.ndarray) -> np.ndarray:
    """Columns of the floor basis (NaN entries of curvature / brake force count as 0)."""
    v = frame["speed"].to_numpy(dtype=float)
    fb = np.nan_to_num(frame["brake_force"].to_numpy(dtype=float))
    drive = np.asarray(sim_force, dtype=float) + fb
    rate = np.zeros_like(drive)
    for k in pd.unique(frame["trip"]):
        sel = (frame["trip"] == k).to_numpy()
        if sel.sum() > 2:
            rate[sel] = np.gradient(drive[sel], frame["t"].to_numpy(dtype=float)[sel])
    kappa = np.nan_to_num(frame["path_curvature"].to_numpy(dtype=float))
    cols = [np.ones_like(v), v, v ** 2, frame["acceleration"].to_numpy(dtype=float),
            G * np.sin(frame["gradient_angle"].to_numpy(dtype=float)), drive, np.abs(drive), rate,
            v ** 4 * kappa ** 2, fb]
    return np.nan_to_num(np.column_stack(cols))


def _extra_columns(frame: pd.DataFrame, extra, model) -> np.ndarray:
    if not extra:
        return np.zeros((len(frame), 0))

    return design([(get_candidate(n), sh) for n, sh in extra], model, columns_of(frame)).A


@dataclass
class SimFloor:
    """Coefficients of the floor basis [N per unit] (then of the ``extra`` candidates' regressors, built with
    ``model``: used when an identified effect is switched on in the sim, so the floor can follow what the
    simulator does with it), the floor's residual scale [N] and how many samples."""

    coefficients: np.ndarray
    scale: float
    n: int
    extra: tuple = ()
    model: object = None
    power_coefficients: np.ndarray | None = None

    @classmethod
    def none(cls) -> "SimFloor":
        return cls(np.zeros(len(BASIS)), float("nan"), 0)

    @property
    def is_none(self) -> bool:
        return self.n == 0

    @classmethod
    def fit(cls, frame: pd.DataFrame, sim_force: np.ndarray, residual: np.ndarray, valid: np.ndarray,
            extra: tuple = (), model=None, rcond: float = RCOND) -> "SimFloor":
        """Least squares on the RMS-scaled basis, truncated at ``rcond`` relative singular value (see module doc;
        1e-8 was the old, ill-conditioned fit)."""
        A = np.hstack([basis(frame, sim_force), _extra_columns(frame, extra, model)])[valid]
        y = np.asarray(residual, dtype=float)[valid]
        if y.size < 10 * A.shape[1]:
            raise DiagnosisError(f"the sim's floor needs more valid samples of sim trips ({y.size})")
        scale = np.sqrt(np.mean(A ** 2, axis=0))
        scale[~(scale > 0)] = 1.0
        x, *_ = np.linalg.lstsq(A / scale, y, rcond=rcond)
        x = x / scale
        r = y - A @ x
        return cls(x, float(np.sqrt(np.mean(r ** 2))), int(y.size), tuple(extra), model,
                   _fit_power_floor(frame, valid))

    def predict(self, frame: pd.DataFrame, sim_force: np.ndarray) -> np.ndarray:
        A = np.hstack([basis(frame, sim_force), _extra_columns(frame, self.extra, self.model)])
        return A @ self.coefficients

    def predict_power(self, frame: pd.DataFrame) -> np.ndarray:
        """The energy floor [W] (0 when the sim trips had no battery power)."""
        if self.power_coefficients is None or "motor_speed" not in frame.columns:
            return np.zeros(len(frame))
        return power_basis(frame) @ self.power_coefficients

    def to_dict(self) -> dict:
        names = list(BASIS) + [f"{n} regressors" for n, _ in self.extra]
        return {"basis": names, "coefficients": [float(c) for c in self.coefficients],
                "residual_rms": self.scale, "n": self.n,
                "power_coefficients": None if self.power_coefficients is None
                else [float(c) for c in self.power_coefficients]}


def _fit_power_floor(frame: pd.DataFrame, valid: np.ndarray) -> np.ndarray | None:
    if "power_residual" not in frame.columns:
        return None
    y = frame["power_residual"].to_numpy(dtype=float)
    ok = np.asarray(valid, bool) & np.isfinite(y)
    if ok.sum() < 100:
        return None
    A = power_basis(frame)[ok]
    scale = np.sqrt(np.mean(A ** 2, axis=0))
    scale[~(scale > 0)] = 1.0
    x, *_ = np.linalg.lstsq(A / scale, y[ok], rcond=RCOND)
    return x / scale


def reduce_channels(trip: Trip, channels: set[str], rate: float | None = None) -> Trip:
    """A copy of a (sim) trip with only the measured channels in ``channels`` (plus t), taken every k-th sample
    when ``rate`` [Hz] is lower than the trip's (k = the nearest whole ratio): a logger sampling at 10 Hz makes the
    pipeline smooth and differentiate at 10 Hz, and the sim's floor must see the same."""
    keep = ["t"] + [c for c in trip.channels if c in channels]
    units = {c: trip.units[c] for c in keep}
    k = int(round(trip.sample_rate / rate)) if rate is not None and np.isfinite(rate) and rate > 0 else 1
    measured = trip.measured[keep].iloc[::max(k, 1)].reset_index(drop=True)
    truth = trip.truth
    if k > 1 and truth is not None and len(truth) == len(trip.measured):
        truth = truth.iloc[::k].reset_index(drop=True)
    elif k > 1:
        truth = None
    return Trip(measured, units, dict(trip.meta), truth, dict(trip.truth_units) if truth is not None else {})
