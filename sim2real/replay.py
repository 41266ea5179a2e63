"""Replay: the recorded drive force, friction-brake force and road are fed into the simulator, and the speed trace
it drives is compared with the recorded one.

Per trip the road is rebuilt over the recorded distance (gradient angle θ and path curvature of the diagnosis
table, no bank); the recorded samples are cut into windows of ``window`` seconds (a window also ends at every gap
in the selected rows). Each window starts at the recorded speed and position (the simulator's state is reset
there), then every 0.1 s the simulator gets ``Action(traction, regen, friction brake)`` from the recorded forces
at the wheels. Reported: RMS of the speed difference over all windows [m/s], the median |difference| at the
window ends, and the number of windows.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass

import numpy as np
import pandas as pd

from .records import Record
from .simconfig import SimConfig
from roadload.envs.simulator import DT, Action, LateralValidityWarning, Simulator
from roadload.road_profiles import RoadProfile


MAX_GRADE = float(np.arctan(0.29))   # rad, the simulator's road profiles stop at 30 %


@dataclass
class ReplayError(Record):
    """Speed error of a replay [m/s]: RMS over all windows, median |error| at the window ends, number of windows."""

    rms: float
    median_end: float
    windows: int

    @classmethod
    def from_windows(cls, sum_of_squares: float, n: int, ends: list[float]) -> "ReplayError":
        """From the summed squared error over ``n`` samples and the |error| at each window end."""
        if n == 0:
            return cls(float("nan"), float("nan"), 0)
        return cls(float(np.sqrt(sum_of_squares / n)), float(np.median(ends)), len(ends))


def windows(t: np.ndarray, window: float) -> np.ndarray:
    """Window key of every sample: a window is ``window`` seconds long and also ends at every gap (> 0.5 s) in
    the times ``t`` [s] of the selected rows (a replay restarts at the recorded speed there)."""
    win = np.floor((t - t[0]) / window).astype(int)
    gaps = np.concatenate([[0], np.cumsum(np.diff(t) > 0.5)])
    return win * 100000 + gaps


def simulator_replay(frame: pd.DataFrame, rows: np.ndarray, sim: SimConfig, window: float = 20.0,
                     seed: int = 0) -> ReplayError:
    """Replay speed error of the simulator configured as ``sim`` on the table rows ``rows`` (see module doc)."""

    t_all = frame["t"].to_numpy(dtype=float)
    trip = frame["trip"].to_numpy()
    with warnings.catch_warnings():
        return _replay(frame, rows, sim, window, seed, t_all, trip, DT, Action, LateralValidityWarning, Simulator,
                       RoadProfile)


def _replay(frame, rows, sim, window, seed, t_all, trip, DT, Action, LateralValidityWarning, Simulator,
            RoadProfile):
    sq, n, ends = 0.0, 0, []
    for k in pd.unique(trip[rows]):
        in_trip = trip == k
        d = np.maximum.accumulate(frame["distance"].to_numpy(dtype=float)[in_trip])
        keep = np.concatenate([[True], np.diff(d) > 1e-3])
        s = d[keep] - d[0]
        if s.size < 2:
            continue
        # the measured gradient angle (eq. 5.2) is noisy where the vehicle is slow; a road stays below 30 %
        grade = np.clip(np.nan_to_num(frame["gradient_angle"].to_numpy(dtype=float)[in_trip][keep]),
                        -MAX_GRADE, MAX_GRADE)
        curv = np.nan_to_num(frame["path_curvature"].to_numpy(dtype=float)[in_trip][keep])
        s = np.concatenate([s, [s[-1] + 500.0]])
        grade, curv = np.append(grade, grade[-1]), np.append(curv, 0.0)
        road = RoadProfile(f"replay:{k}", s, grade, curv, np.zeros_like(s), np.full_like(s, 70.0))
        simulator = Simulator(sim.vehicle, road, sim.effects, seed=seed)
        sel = np.flatnonzero(rows & in_trip)
        if sel.size < 2:
            continue
        t = t_all[sel]
        v = frame["speed"].to_numpy(dtype=float)[sel]
        distance_in_trip = np.maximum.accumulate(frame["distance"].to_numpy(dtype=float)[in_trip])
        pos = distance_in_trip[np.isin(np.flatnonzero(in_trip), sel)] - d[0]
        drive = frame["drive_force"].to_numpy(dtype=float)[sel]
        brake = np.nan_to_num(frame["brake_force"].to_numpy(dtype=float)[sel])
        key = windows(t, window)
        for w in np.unique(key):
            idx = np.flatnonzero(key == w)
            if idx.size < 2:
                continue
            # the road's curvature comes from the steering signal: at a window start in a bend the single-track
            # model may exceed its validity; that is the recorded road, not an input error, so the warning is muted
            warnings.simplefilter("ignore", LateralValidityWarning)
            simulator.reset(seed, initial_speed=max(float(v[idx[0]]), 0.0))
            simulator.vehicle_state.position = pos[idx[0]]
            err = np.zeros(idx.size)
            for m in range(idx.size - 1):
                j = idx[m]
                f = float(drive[j]) if np.isfinite(drive[j]) else 0.0
                steps = max(1, int(round((t[idx[m + 1]] - t[j]) / DT)))
                st = simulator.step(Action(max(f, 0.0), max(-f, 0.0), float(max(brake[j], 0.0))), steps)
                err[m + 1] = st.v - v[idx[m + 1]]
            sq += float(np.sum(err ** 2))
            n += err.size
            ends.append(abs(err[-1]))
    return ReplayError.from_windows(sq, n, ends)
