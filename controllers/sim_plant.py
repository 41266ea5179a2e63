"""The simulator (:mod:`roadload.envs`) as the closed-loop plant, and the human-like driver baseline.

:class:`SimulatorPlant` steps ``Simulator`` with the controller's Action every ``dt`` (n_substeps x 10 ms),
returns the observation (position, speed, acceleration, gear, latest CAN sample), the source energy of the step
(battery J for the BEV, fuel J for the ICE), the oracle's true parameters and, for the online force model, the
100 Hz CAN samples since a given time (a Trip window built by the simulator's own sensor model).
:class:`HumanDriver` hands every step to the simulator's built-in driver (``Simulator.step(None)``).
"""

from __future__ import annotations

from typing import Any

import pandas as pd

from roadload.road_load import RoadLoadParameters
from roadload.road_profiles import RoadProfile
from roadload.trip import Trip

from .base import Command, Observation

from .force_model import WindEstimate
from .plant import PlantStep
from .vehicle_models import oracle_parameters
from roadload.envs import Simulator
from roadload.envs import Action
from roadload.envs.simulator import TRUTH_COLUMNS

SIM_DT = 0.01  # the simulator's substep [s]


class SimulatorPlant:
    """Closed-loop adapter around ``roadload.envs.Simulator`` (module docstring)."""

    def __init__(self, vehicle, road: RoadProfile, effects=None, seed: int = 0, dt: float = 0.1) -> None:

        self.substeps = int(round(dt / SIM_DT))
        if self.substeps < 1 or abs(self.substeps * SIM_DT - dt) > 1e-9:
            raise ValueError(f"dt must be a positive multiple of {SIM_DT} s, got {dt}")
        self.dt = dt
        self.sim = Simulator(vehicle, road, effects=effects, seed=seed)
        self.spec = self.sim.vehicle
        self.road = road

    def reset(self) -> Observation:
        return self._obs(self.sim.reset())

    def _obs(self, r) -> Observation:
        sample = self.sim.observe() or {"t": r.t}
        return Observation(t=float(r.t), s=float(r.s), v=float(r.v), a=float(r.a), gear=int(r.gear), sample=sample)

    def step(self, cmd: Command | None) -> PlantStep:

        action = None if cmd is None else Action(cmd.traction, cmd.regen, cmd.brake, gear=cmd.gear)
        r = self.sim.step(action, n_substeps=self.substeps)
        return PlantStep(self._obs(r), float(r.source_energy), bool(r.done))

    def true_parameters(self) -> RoadLoadParameters:
        return oracle_parameters(self.sim.true_parameters(), self.spec)

    def true_wind(self) -> WindEstimate | None:
        """The true wind vector now in the road's frame (speed, direction it blows towards = the wind's angle to
        the vehicle plus the vehicle's heading) with the vehicle's yaw drag factor; None in still air."""
        truth = self.sim.true_parameters()
        speed = float(truth.get("wind_speed", 0.0))
        if speed <= 0.0:
            return None
        n = self.sim.truth_log().shape[0]
        heading = float(self.sim.truth_log()[n - 1, TRUTH_COLUMNS["heading"]]) if n else 0.0
        return WindEstimate(speed, float(truth["wind_angle"]) + heading, float(self.spec.aero.yaw_drag_factor))

    def can_window(self, t_from: float) -> Trip | None:
        """The 100 Hz CAN samples with t >= t_from as a Trip (None when fewer than 10)."""
        log = self.sim.truth_log().T  # column-major (N_LOG, n) view, as the sensor model reads it
        n = log.shape[1]
        if n == 0:
            return None
        t, channels, keep = self.sim.sensor_model.measure(log, n)
        sel = (t >= t_from) & keep
        if sel.sum() < 10:
            return None
        frame = pd.DataFrame({"t": t[sel], **{k: v[sel] for k, v in channels.items()}})
        units = {"t": "s", **self.sim.sensor_model.units}
        return Trip(frame, units, {"name": f"can-window-{t_from:.1f}"})


class HumanDriver:
    """Baseline: the simulator's built-in human-like driver (speed limits, curves, stops, speed variation)."""

    name = "human"

    def __init__(self) -> None:
        self.events: dict[str, Any] = {}

    def reset(self, ctx) -> None:
        self.ctx = ctx

    def act(self, obs: Observation) -> None:
        return None  # SimulatorPlant.step(None): the built-in driver decides

    def stats(self) -> dict[str, Any]:
        return {}

