"""Constant-speed cruise control (PI) at the allowed speed: the baseline, and the MPC's last-resort fallback.

Reference: the set speed v_set(s) = fraction * min(limit, sqrt(a_y,max/|kappa|)) (stops: 0), preceded by a
braking envelope at ``decel`` [m/s^2] so the car slows down *before* a lower limit (map-based cruise control),
and rate-limited to ``accel`` [m/s^2] when speeding up. Control law:
F = F_ff(v) + m (dv_ref/dt + k_p e + integral k_i e dt), e = v_ref - v, with the flat-road feed-forward
F_ff = a_V + b_V v + c_V v^2 of the nominal coast-down coefficients, the reference's own acceleration as
feed-forward (low-pass filtered; no tracking lag when the reference slows down before a lower limit), a clamped
(anti-windup) integrator and the same jerk limit on the command as the MPC (|dF/dt| <= m j_max).
A truck's cruise control (``overspeed`` > 0) has a speed band: where the law would brake (downhill) it coasts
instead and brakes only above v_ref + overspeed ("downhill speed control").
"""

from __future__ import annotations

import math

from dataclasses import dataclass

import numpy as np

from roadload.road_load import RoadLoadParameters
from roadload.schema import check_field_types
from .base import ControllerBase, ControllerError, DriveContext, Observation
from .force_model import resistance_force
from .safety import SpeedEnvelope


@dataclass(frozen=True)
class CruiseSettings:
    """fraction of the allowed speed used as set speed; PI gains k_p [1/s], k_i [1/s^2]; reference limits."""

    fraction: float = 0.9
    margin: float = 0.3  # [m/s] below the allowed speed
    kp: float = 0.8
    ki: float = 0.08
    accel: float = 1.0  # [m/s^2] reference rate when speeding up
    decel: float = 1.0  # [m/s^2] reference braking envelope before lower limits
    integral_limit: float = 2.0  # [m/s^2] anti-windup clamp of the integral term
    jerk_max: float = 2.0  # [m/s^3] comfort: |dF/dt| <= m j_max on the command (as the MPC's)
    accel_filter: float = 0.5  # [s] time constant of the reference-acceleration feed-forward filter
    overspeed: float = 0.0  # [m/s] truck speed band: downhill, no braking below v_ref + overspeed (0 = off)

    def __post_init__(self) -> None:
        check_field_types(self, ControllerError)
        for name, value in self.__dict__.items():
            if isinstance(value, float) and not math.isfinite(value):
                raise ControllerError(f"cruise {name}: must be a finite number, got {value}")
        if not 0 < self.fraction <= 1:
            raise ControllerError(f"cruise fraction must be in (0, 1], got {self.fraction}")
        for name in ("kp", "accel", "decel", "integral_limit"):
            if not getattr(self, name) > 0:
                raise ControllerError(f"cruise {name} must be positive, got {getattr(self, name)}")
        if self.ki < 0:
            raise ControllerError(f"cruise ki must be >= 0, got {self.ki}")
        if self.overspeed < 0:
            raise ControllerError(f"cruise overspeed must be >= 0 m/s, got {self.overspeed}")


class CruiseLaw:
    """The PI law with its speed reference; used by :class:`CruiseController` and as the MPC's fallback."""

    def __init__(self, settings: CruiseSettings, ctx: DriveContext, feedforward: RoadLoadParameters) -> None:
        self.settings = settings
        self.ctx = ctx
        self.ff = feedforward
        self.reference = SpeedEnvelope(ctx.road, ctx.lateral_accel_max, settings.decel,
                                       cap_fraction=settings.fraction, cap_margin=settings.margin)
        self.v_ref: float | None = None
        self.integral = 0.0
        self.a_ref = 0.0
        self.last_force: float | None = None

    def serve_stop(self, index: int) -> None:
        self.reference.serve(index)

    def restart(self, v: float) -> None:
        """Bumpless start from the current speed (reference = v, integral cleared)."""
        self.v_ref = v
        self.integral = 0.0
        self.a_ref = 0.0
        self.last_force = None

    def force(self, obs: Observation) -> float:
        st, dt = self.settings, self.ctx.dt
        target = float(self.reference(obs.s))
        if self.v_ref is None:
            self.v_ref = obs.v
        previous = self.v_ref
        self.v_ref = min(target, max(self.v_ref, obs.v - 0.5) + st.accel * dt)
        a_raw = float(np.clip((self.v_ref - previous) / dt, -3.0, st.accel))  # the reference's own acceleration
        self.a_ref += (a_raw - self.a_ref) * min(dt / st.accel_filter, 1.0)
        err = self.v_ref - obs.v
        self.integral = float(np.clip(self.integral + st.ki * err * dt, -st.integral_limit, st.integral_limit))
        ff = float(resistance_force(obs.v, 0.0, 0.0, self.ff))
        m = self.ff.inertial_mass
        force = ff + m * (self.a_ref + st.kp * err + self.integral)
        if st.overspeed > 0 and force < 0 and self.a_ref >= 0:
            # speed band [v_ref, v_ref + overspeed]: coast downhill (no traction, no brake) and let the speed rise;
            # above the band a P law on v_ref + overspeed brakes (engine brake / retarder first); no wind-up
            self.integral = min(self.integral, 0.0)
            force = min(0.0, ff + m * st.kp * (self.v_ref + st.overspeed - obs.v))
        if self.last_force is not None:
            step = m * st.jerk_max * dt
            force = float(np.clip(force, self.last_force - step, self.last_force + step))
        self.last_force = force
        return force


class CruiseController(ControllerBase):
    """Baseline: PI cruise control at ``fraction`` of the allowed speed (module docstring)."""

    name = "cruise"

    def __init__(self, settings: CruiseSettings | None = None) -> None:
        super().__init__()
        self.settings = settings or CruiseSettings()

    def reset(self, ctx: DriveContext) -> None:
        super().reset(ctx)
        self.law = CruiseLaw(self.settings, ctx, ctx.force_model.parameters())

    def serve_stop(self, index: int) -> None:
        super().serve_stop(index)
        self.law.serve_stop(index)
        self.law.restart(0.0)

    def wheel_force(self, obs: Observation) -> float:
        return self.law.force(obs)
