"""The controller interface shared by the MPC and the baselines, and what every controller does alike.

Each control step the closed loop passes an :class:`Observation` (time, position, speed, acceleration, the latest
CAN sample) and gets a :class:`Command` (traction / regenerative / friction-brake wheel forces, all >= 0 [N]).
:class:`ControllerBase` implements the shared parts once: feeding the force model the CAN sample, stopping at the
road's stops (constant-deceleration stop, dwell, then go), clipping every command by the safety envelope
(:mod:`.safety`) and splitting the net wheel force into traction, regeneration (within the drive's limits)
and friction braking. Subclasses only provide ``wheel_force(obs)`` [N].

The stop manoeuvre brakes at the constant deceleration v^2 / (2 d) that stops the car at the line, and the
envelope guard at what brings the speed back under the envelope; both at most ``DriveContext.emergency_decel``
(an emergency brake when a stop or cap appears inside the comfort braking distance: the last step of the
fallback chain, after the MPC's maximum-comfort brake, :mod:`.mpc_controller`).
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from roadload.road_load import RoadLoadParameters
from roadload.road_profiles import RoadProfile

from .energy import SourceEnergyModel
from .force_model import ForceModel, resistance_force
from .safety import SpeedEnvelope


CREEP_SPEED = 0.5  # [m/s] a vehicle that stopped more than 2 m before a stop line creeps on towards it below this


class ControllerError(ValueError):
    """Invalid controller settings or an unknown controller name."""


@dataclass
class Observation:
    """What the controller sees each step (SI): time t [s], position s [m], speed v [m/s], measured
    acceleration a [m/s^2], engaged gear (0 = neutral/EV) and the latest CAN sample (channel -> value)."""

    t: float
    s: float
    v: float
    a: float
    gear: int = 0
    sample: dict[str, float] = field(default_factory=dict)


@dataclass(frozen=True)
class Command:
    """Wheel forces [N], each >= 0: traction, regenerative braking and friction braking; ``gear``: a requested gear
    (1-based, the plant's numbering) or None for the transmission's own shift strategy."""

    traction: float
    regen: float
    brake: float
    gear: int | None = None

    @property
    def net(self) -> float:
        return self.traction - self.regen - self.brake


@dataclass
class DriveContext:
    """What a controller knows about the vehicle and the road before the trip."""

    road: RoadProfile
    energy: SourceEnergyModel
    force_model: ForceModel
    dt: float = 0.1  # control period of the closed loop [s]
    lateral_accel_max: float = 2.0  # [m/s^2], curve speed cap
    guard_decel: float = 2.5  # deceleration the safety envelope assumes [m/s^2]
    stop_decel: float = 1.5  # comfortable deceleration of the final stop manoeuvre [m/s^2]
    stop_dwell: float = 5.0  # standstill time at each stop [s]
    emergency_decel: float = 6.0  # strongest deceleration any controller commands [m/s^2] (about 0.6 g: hard,
    # still within what tyres give on a wet road)


def split_wheel_force(force: float, v: float, energy: SourceEnergyModel, ratio: float) -> Command:
    """Net wheel force [N] -> Command: positive = traction (within torque/power limits), negative = regeneration
    up to the drive's torque/power limits, the rest friction braking."""
    if force >= 0:
        limit = min(float(energy.max_traction_force(v, ratio)), energy.max_power / max(v, 0.5))
        return Command(min(force, limit), 0.0, 0.0)
    need = -force
    regen_limit = 0.0
    if energy.regenerates and v > 1.0:
        regen_limit = min(float(energy.max_regen_force(ratio)), energy.max_regen_power / v)
    regen = min(need, regen_limit)
    return Command(0.0, regen, need - regen)


class ControllerBase:
    """Shared behaviour (module docstring). Subclasses implement ``wheel_force`` and may extend ``reset``."""

    name = "base"

    def __init__(self) -> None:
        self._ctx: DriveContext | None = None
        self.events: Counter = Counter()

    @property
    def ctx(self) -> DriveContext:
        """The drive context of the current run; ControllerError before ``reset(ctx)``."""
        if self._ctx is None:
            raise ControllerError(f"controller {self.name!r}: call reset(ctx) before act()")
        return self._ctx

    # ------------------------------------------------------------------ lifecycle
    def reset(self, ctx: DriveContext) -> None:
        self._ctx = ctx
        self.events = Counter()
        self.envelope = SpeedEnvelope(ctx.road, ctx.lateral_accel_max, ctx.guard_decel)
        self._stop_hold_since: float | None = None
        self._stopping = False
        ctx.force_model.reset()

    def serve_stop(self, index: int) -> None:
        """A stop was served (the car stood still there); subclasses drop it from their references too."""
        self.envelope.serve(index)

    def stats(self) -> dict[str, Any]:
        return dict(self.events)

    # ------------------------------------------------------------------ helpers
    def params(self) -> RoadLoadParameters:
        return self.ctx.force_model.parameters()

    def resistance(self, v: float, s: float, params: RoadLoadParameters | None = None) -> float:
        """F_resist [N] at the current position under the controller's force model."""
        at = self.ctx.road.at(s)
        return float(resistance_force(v, at["grade"], at["curvature"], params or self.params()))

    def ratio(self, obs: Observation) -> float:
        en = self.ctx.energy
        if en.kind == "ev":
            return en.gear_ratios[0]
        if obs.gear >= 1:
            return en.gear_ratios[min(obs.gear, len(en.gear_ratios)) - 1]
        return float(en.ratio_for_speed(obs.v))

    # ------------------------------------------------------------------ the step
    def wheel_force(self, obs: Observation) -> float:  # pragma: no cover - abstract
        raise NotImplementedError

    def act(self, obs: Observation) -> Command:
        if self._ctx is None:
            raise ControllerError(f"controller {self.name!r}: call reset(ctx) before act()")
        if not (np.isfinite(obs.v) and np.isfinite(obs.s)):
            raise ControllerError(f"observation not finite (s={obs.s}, v={obs.v})")
        self.ctx.force_model.observe(obs.sample)
        force = self._stop_force(obs)
        if force is None:
            force = float(self.wheel_force(obs))
            if not np.isfinite(force):
                self.events["non_finite_command"] += 1
                force = -self.params().mass * 1.0
        force = self._guard(obs, force)
        cmd = split_wheel_force(force, obs.v, self.ctx.energy, self.ratio(obs))
        gear = self.gear_request(obs)
        return cmd if gear is None else replace(cmd, gear=gear)

    def gear_request(self, obs: Observation) -> int | None:
        """The gear to request this step (1-based), or None: the transmission shifts by its own strategy."""
        return None

    def _stop_force(self, obs: Observation) -> float | None:
        """Final stop manoeuvre at the next stop: constant deceleration to the stop line, hold, dwell, go."""
        ctx = self.ctx
        env = self.envelope
        for i, stop in enumerate(env.stops):  # passed without standing still: count it, drop it
            if not env.served[i] and stop < obs.s - 1.0:
                self.events["stops_missed"] += 1
                self._stopping = False
                self.serve_stop(i)
        nxt = env.next_stop(obs.s)
        if nxt is None:
            return None
        index, pos = nxt
        d = pos - obs.s
        m = self.params().inertial_mass
        if self._stop_hold_since is not None:
            if obs.t - self._stop_hold_since >= ctx.stop_dwell:
                self._stop_hold_since = None
                self._stopping = False
                self.events["stops_served"] += 1
                self.serve_stop(index)
                return None
            return -m * 2.0  # hold the car with the brakes
        if obs.v < 0.1 and d < 2.0:
            self._stop_hold_since = obs.t
            return -m * 2.0
        if self._stopping or d <= obs.v ** 2 / (2.0 * ctx.stop_decel) + 0.5:
            self._stopping = True
            if obs.v < CREEP_SPEED and d >= 2.0:  # came to rest short of the line: creep up to it
                return self.resistance(obs.v, obs.s) + m * (CREEP_SPEED - obs.v)
            decel = obs.v ** 2 / (2.0 * max(d, 0.2))
            if d < 0.3:
                decel = max(decel, 2.0)
            return self.resistance(obs.v, obs.s) - m * min(decel, ctx.emergency_decel)
        return None

    def _guard(self, obs: Observation, force: float) -> float:
        """Clip the command so the speed stays under the safety envelope (module docstring of .safety)."""
        v_env = float(self.envelope(obs.s))
        excess = obs.v - (v_env - 0.3)
        if excess <= 0:
            return force
        params = self.params()
        env_decel = max(0.0, -self.envelope.slope(obs.s) * obs.v)
        decel = min(env_decel + 5.0 * excess, self.ctx.emergency_decel)
        limit = self.resistance(obs.v, obs.s, params) - params.inertial_mass * decel
        if force > limit:
            self.events["guard_active_steps"] += 1
            return limit
        return force
