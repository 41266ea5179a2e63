"""A point-mass plant built from the controllers' own force and energy models.

It integrates m dv/dt = F_traction - F_regen - F_brake - F_resist(v, theta(s), kappa(s); p(t, s)) and the source
energy of :class:`~.energy.SourceEnergyModel`, so the controller's model is exact when it is given the same
parameters. It is for tests and solver benchmarks (a model-matched setting); the closed-loop comparison drives
the full simulator (:mod:`roadload.envs`) through :mod:`.sim_plant`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

from roadload.road_load import RoadLoadParameters
from roadload.road_profiles import RoadProfile
from roadload.units import G

from .base import Command, Observation
from .energy import SourceEnergyModel
from .force_model import resistance_force


@dataclass
class PlantStep:
    obs: Observation
    energy: float  # source energy over the step [J]
    done: bool


class ModelPlant:
    """Point-mass plant (module docstring). ``params`` is fixed or a function (t, s) -> RoadLoadParameters (drift)."""

    def __init__(self, road: RoadProfile, params: RoadLoadParameters | Callable[[float, float], RoadLoadParameters],
                 energy: SourceEnergyModel, dt: float = 0.1, substeps: int = 10, v0: float = 0.0) -> None:
        if dt <= 0 or substeps < 1:
            raise ValueError(f"dt must be > 0 and substeps >= 1, got dt={dt}, substeps={substeps}")
        self.road, self.energy, self.dt, self.substeps, self.v0 = road, energy, dt, substeps, v0
        self._params = params if callable(params) else (lambda t, s, p=params: p)

    def true_parameters(self) -> RoadLoadParameters:
        return self._params(self.t, self.s)

    def reset(self) -> Observation:
        self.t, self.s, self.v, self.a = 0.0, 0.0, float(self.v0), 0.0
        return self._obs()

    def _obs(self) -> Observation:
        grade = float(self.road.at(self.s)["grade"])
        sample = {"vehicle_speed": self.v, "accel_x": self.a + G * np.sin(grade)}
        return Observation(t=self.t, s=self.s, v=self.v, a=self.a, gear=0, sample=sample)

    def step(self, cmd: Command) -> PlantStep:
        h = self.dt / self.substeps
        energy = 0.0
        for _ in range(self.substeps):
            p = self._params(self.t, self.s)
            at = self.road.at(self.s)
            ratio = float(self.energy.ratio_for_speed(self.v))
            res = float(resistance_force(self.v, at["grade"], at["curvature"], p))
            net = cmd.traction - cmd.regen - cmd.brake - res
            acc = net / p.inertial_mass
            if self.v <= 0.0 and acc < 0.0:  # standing: brakes/static friction hold the car (no roll-back)
                acc = 0.0
            power = float(self.energy.source_power(cmd.traction, cmd.regen, max(self.v, 0.0), ratio))
            v_new = max(self.v + acc * h, 0.0)
            self.s += 0.5 * (self.v + v_new) * h
            self.a = (v_new - self.v) / h
            self.v = v_new
            self.t += h
            energy += power * h
        return PlantStep(self._obs(), energy, self.s >= self.road.length)
