"""Gap measures between the sim and recorded trips, on any subset of the diagnosis table (e.g. held-out rows).

- force residual F_xV,measured - F_xV,sim [N]: n, mean, median, MAD, MEDSE, RMSE (robust first);
- replay through the simulator (:mod:`.replay`, with a sim config given): recorded drive force, brakes and road
  fed into the simulator, speed trace compared [m/s];
- replay speed error, linearised [m/s]: the recorded force fed through the sim's longitudinal balance over windows of
  ``window`` seconds starting at the recorded speed; to first order the replayed speed departs from the recorded
  one by e(t) = ∫ (F_xV,measured - F_xV,sim) / m_V dt, so the measure is the RMS of e over the windows (the
  speed trace the sim would drive with the recorded drive torque, brakes and road);
- traction energy per distance [kWh/100 km]: ∫ max(F, 0) v dt / ∫ v dt for the measured and the sim's force.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd

from .records import Record, RobustSummary, optional
from .replay import ReplayError, simulator_replay, windows
from .simconfig import SimConfig

J_PER_M_TO_KWH_PER_100KM = 100e3 / 3.6e6


@dataclass
class EnergyPerDistance(Record):
    """Traction energy per distance of the measured and the sim's force, and the sim's relative error."""

    measured: float
    sim: float
    relative_error: float
    unit: str = "kWh/100 km"


@dataclass
class GapMeasures(Record):
    """The gap measures of a residual on a set of rows (see module doc); ``sim``: the sim config the measures
    were taken with when it is not the diagnosed one (the re-simulation)."""

    force_residual: RobustSummary
    replay_speed_error: ReplayError
    replay_simulator: ReplayError | None
    energy_per_distance: EnergyPerDistance
    sim: SimConfig | None = optional()


def replay_speed_error(frame: pd.DataFrame, residual: np.ndarray, mass: float, rows: np.ndarray,
                       window: float = 20.0) -> ReplayError:
    """RMS and final-value median of the windowed replay speed error e(t) = ∫ r / m dt on ``rows`` [m/s]."""
    r = np.asarray(residual, dtype=float)
    t = frame["t"].to_numpy(dtype=float)
    trip = frame["trip"].to_numpy()
    sq, ends, n = 0.0, [], 0
    for k in pd.unique(trip[rows]):
        sel = np.flatnonzero(rows & (trip == k))
        if sel.size < 2:
            continue
        tk, rk = t[sel], r[sel]
        key = windows(tk, window)
        dt = np.concatenate([[0.0], np.diff(tk)])
        for w in np.unique(key):
            idx = key == w
            e = np.cumsum(rk[idx] * dt[idx]) / mass
            e -= e[0]
            sq += float(np.sum(e ** 2))
            n += e.size
            ends.append(abs(e[-1]))
    return ReplayError.from_windows(sq, n, ends)


def energy_per_distance(frame: pd.DataFrame, force: np.ndarray, rows: np.ndarray) -> float:
    """Traction energy per distance ∫ max(F, 0) v dt / ∫ v dt [kWh/100 km] over ``rows``."""
    v = frame["speed"].to_numpy(dtype=float)[rows]
    f = np.asarray(force, dtype=float)[rows]
    dist = float(np.sum(v))
    if dist <= 0:
        return float("nan")
    return float(np.sum(np.clip(f, 0, None) * v) / dist * J_PER_M_TO_KWH_PER_100KM)


def gap_measures(frame: pd.DataFrame, residual: np.ndarray, mass: float, rows: np.ndarray,
                 replay_sim: SimConfig | None = None) -> GapMeasures:
    """All gap measures of ``residual`` on ``rows`` (see module doc); with ``replay_sim`` (a SimConfig) also the
    replay through the simulator itself (:func:`roadload.sim2real.replay.simulator_replay`)."""
    r = np.asarray(residual, dtype=float)
    measured = frame["tractive_force"].to_numpy(dtype=float)
    e_meas = energy_per_distance(frame, measured, rows)
    e_sim = energy_per_distance(frame, measured - r, rows)
    out_replay = simulator_replay(frame, rows, replay_sim) if replay_sim is not None else None
    return GapMeasures(RobustSummary.of(r[rows]), replay_speed_error(frame, r, mass, rows), out_replay,
                       EnergyPerDistance(e_meas, e_sim, (e_sim - e_meas) / e_meas if e_meas else float("nan")))
