"""The closed loop (controller <-> plant) and the per-run metrics of the comparison.

Metrics of one run: source energy [J] (and kWh), trip time [s] (first time s >= road length), speed-limit
violations (samples with v above the posted limit + ``VIOLATION_TOLERANCE``: number of separate episodes, time
above, largest excess), RMS jerk [m/s^3] of the true acceleration, solver time median / p99 [s] and the number of
fallbacks (MPC only), plus the controller's event counters.

Arrival: ``trip_time`` is the first control step with s >= road length, so it is quantised to the
control period dt (0.1 s = 0.08 % of a 2 min trip, worth ~0.2 % of energy on the steep energy-time curve).
``arrival_time`` / ``arrival_energy_J`` / ``arrival_speed`` interpolate the crossing of the road end (or of any
position, :func:`crossing`) linearly inside that last step.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Any, Protocol

import numpy as np
import pandas as pd

from .base import Command, DriveContext, Observation
from .force_model import ForceModel
from .safety import VIOLATION_TOLERANCE


class Plant(Protocol):
    dt: float

    def reset(self) -> Observation: ...

    def step(self, cmd: Command | None): ...  # None: the plant's own driver; -> object with .obs, .energy [J], .done


@dataclass
class RunResult:
    """Time series of one closed-loop run (``log``) and its metrics."""

    log: pd.DataFrame
    metrics: dict[str, Any] = field(default_factory=dict)


class Controller(Protocol):
    """What ``run_closed_loop`` drives: a ControllerBase subclass or the plant's built-in HumanDriver
    (``act`` returns None: the plant's own driver decides)."""

    name: str

    def reset(self, ctx: DriveContext) -> None: ...

    def act(self, obs: Observation) -> Command | None: ...

    def stats(self) -> dict[str, Any]: ...


class Handover:
    """``first`` drives until position ``switch`` [m], ``second`` from there on (e.g. cruise control drives the
    warm-up of every paired run, so each MPC starts the measured segment in the same state and the online estimator
    has learnt from the same samples). ``first_force_model``: the force model ``first`` plans with (e.g. the fixed
    abc model, so the warm-up does not depend on the run's force model); the run's own force model still observes
    every sample once, through ``first`` or ``second``. Stats are the second's."""

    def __init__(self, first: Controller, second: Controller, switch: float,
                 first_force_model: ForceModel | None = None) -> None:
        if not (math.isfinite(switch) and switch >= 0):
            raise ValueError(f"Handover.switch: a finite position >= 0 m, got {switch}")
        self.first, self.second, self.switch = first, second, float(switch)
        self.first_force_model = first_force_model
        self.name = second.name
        self._ctx: DriveContext | None = None

    def reset(self, ctx: DriveContext) -> None:
        self._ctx = ctx
        self.second.reset(ctx)
        self.first.reset(ctx if self.first_force_model is None else replace(ctx, force_model=self.first_force_model))

    def act(self, obs: Observation) -> Command | None:
        if obs.s >= self.switch:
            return self.second.act(obs)
        if self.first_force_model is not None and self._ctx is not None:
            self._ctx.force_model.observe(obs.sample)  # the run's model learns from the warm-up too
        return self.first.act(obs)

    def stats(self) -> dict[str, Any]:
        return self.second.stats()


def run_closed_loop(controller: Controller, plant: Plant, ctx: DriveContext, max_time: float | None = None,
                    progress=None, measure_from: float = 0.0) -> RunResult:
    """Drive the road once; ``max_time`` [s] aborts a run that does not arrive (default: 4x the time at 5 m/s).
    ``measure_from`` [m]: start of the measured segment (a warm-up before it, e.g. for an online estimator);
    metrics ``segment_time`` [s], ``segment_energy_J`` and the speeds ``segment_start_speed`` /
    ``arrival_speed`` [m/s] cover [measure_from, road end], crossings interpolated inside the step."""
    if not 0.0 <= measure_from < ctx.road.length:
        raise ValueError(f"measure_from must be in [0, road length = {ctx.road.length:.0f}) m, got {measure_from}")
    road = ctx.road
    if max_time is None:
        max_time = 4.0 * road.length / 5.0 + 600.0
    obs = plant.reset()
    controller.reset(ctx)
    rows = []
    energy = 0.0
    done = False
    while not done and obs.t < max_time:
        cmd = controller.act(obs)  # None: the plant's own driver decides (human-driver baseline)
        step = plant.step(cmd)
        energy += step.energy
        forces = (np.nan, np.nan, np.nan) if cmd is None else (cmd.traction, cmd.regen, cmd.brake)
        row = (obs.t, obs.s, obs.v, *forces, energy)
        obs, done = step.obs, step.done
        rows.append((*row, obs.a))  # the acceleration that resulted from this step's command
        if progress is not None:
            progress(min(obs.s / road.length, 1.0))
    log = pd.DataFrame(rows, columns=["t", "s", "v", "traction", "regen", "brake", "energy", "a_next"])
    log["a"] = log["a_next"]
    log = log.drop(columns="a_next")
    log["speed_limit"] = road.at(log["s"].to_numpy())["speed_limit"]
    log["grade"] = road.at(log["s"].to_numpy())["grade"]
    metrics = run_metrics(log, plant.dt, arrived=done)
    stats = controller.stats()
    metrics.update({f"ctl_{k}": v for k, v in stats.items()})
    metrics["fallbacks"] = int(stats.get("fallbacks", 0))
    metrics["solve_time_median"] = float(stats.get("solve_time_median", float("nan")))
    metrics["solve_time_p99"] = float(stats.get("solve_time_p99", float("nan")))
    metrics["energy_J"] = float(energy)
    metrics["energy_kWh"] = float(energy) / 3.6e6
    metrics["trip_time"] = float(obs.t) if done else float("nan")
    track = trajectory(log, obs, energy)
    metrics["start_speed"] = float(track[2][0]) if track[0].size else float("nan")
    t_arr, e_arr, v_arr = crossing(track, road.length) if done else (float("nan"),) * 3
    metrics.update(arrival_time=t_arr, arrival_energy_J=e_arr, arrival_speed=v_arr)
    t_a, e_a, v_a = crossing(track, measure_from) if measure_from > 0 else (0.0, 0.0, metrics["start_speed"])
    metrics.update(measure_from=float(measure_from), segment_time=t_arr - t_a, segment_energy_J=e_arr - e_a,
                   segment_start_speed=v_a)
    return RunResult(log, metrics)


def trajectory(log: pd.DataFrame, final: Observation, energy: float
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(t [s], s [m], v [m/s], cumulative source energy [J]) at every step boundary, the final state included
    (the log's ``energy`` column is the cumulative energy at the END of its step)."""
    e_cum = log["energy"].to_numpy(float)
    t = np.append(log["t"].to_numpy(float), final.t)
    s = np.append(log["s"].to_numpy(float), final.s)
    v = np.append(log["v"].to_numpy(float), final.v)
    e = np.concatenate([[0.0], e_cum]) if e_cum.size else np.array([energy])
    return t, s, v, e


def crossing(track: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray], position: float
             ) -> tuple[float, float, float]:
    """(time [s], cumulative source energy [J], speed [m/s]) where the vehicle first reaches ``position`` [m],
    linear inside the step that crosses it; NaNs when it never does."""
    t, s, v, e = track
    idx = np.flatnonzero(s >= position)
    if not idx.size:
        return float("nan"), float("nan"), float("nan")
    k = int(idx[0])
    if k == 0 or s[k] <= s[k - 1]:
        return float(t[k]), float(e[k]), float(v[k])
    f = (position - s[k - 1]) / (s[k] - s[k - 1])
    return (float(t[k - 1] + f * (t[k] - t[k - 1])), float(e[k - 1] + f * (e[k] - e[k - 1])),
            float(v[k - 1] + f * (v[k] - v[k - 1])))


def run_metrics(log: pd.DataFrame, dt: float, arrived: bool = True) -> dict[str, Any]:
    """Violations, RMS jerk and distance from a run log with columns t, s, v, a, speed_limit."""
    v, limit = log["v"].to_numpy(), log["speed_limit"].to_numpy()
    over = v > limit + VIOLATION_TOLERANCE
    episodes = int(np.sum(over[1:] & ~over[:-1]) + (1 if over.size and over[0] else 0))
    a = log["a"].to_numpy()
    jerk = np.diff(a) / dt if a.size > 1 else np.zeros(1)
    return {"arrived": bool(arrived), "distance": float(log["s"].iloc[-1]) if len(log) else 0.0,
            "speed_violations": episodes, "violation_time": float(over.sum() * dt),
            "max_excess_kmh": float(max(0.0, np.max(v - limit, initial=0.0)) * 3.6),
            "rms_jerk": float(np.sqrt(np.mean(jerk ** 2))), "max_abs_accel": float(np.max(np.abs(a), initial=0.0)),
            "mean_speed_kmh": float(log["s"].iloc[-1] / max(log["t"].iloc[-1] + dt, dt) * 3.6) if len(log) else 0.0}
