"""The closed loop (controller <-> plant) and the per-run metrics of the comparison.

Metrics of one run: source energy [J] (and kWh), trip time [s] (first time s >= road length), speed-limit
violations (samples with v above the posted limit + ``VIOLATION_TOLERANCE``: number of separate episodes, time
above, largest excess), RMS jerk [m/s^3] of the true acceleration, solver time median / p99 [s] and the number of
fallbacks (MPC only), plus the controller's event counters.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np
import pandas as pd

from .base import Command, DriveContext, Observation

VIOLATION_TOLERANCE = 0.1  # [m/s] numerical tolerance above the posted limit


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


def run_closed_loop(controller: Controller, plant: Plant, ctx: DriveContext, max_time: float | None = None,
                    progress=None) -> RunResult:
    """Drive the road once; ``max_time`` [s] aborts a run that does not arrive (default: 4x the time at 5 m/s)."""
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
    return RunResult(log, metrics)


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
