"""Force models for the eco-driving MPC: the resistance ``F_resist(v, grade, curvature; params)`` plus the mass.

The resistance and the wheel force are :func:`roadload.road_load.road_load` and
:func:`~roadload.road_load.tractive_force` on the lumped :class:`~roadload.road_load.RoadLoadParameters`
(eq. 2.5-2.16, 5.4-5.6), evaluated numerically or as CasADi expressions.

Three sources of parameters sit behind one interface (:class:`ForceModel`), re-read by the controller every
step: ``abc`` (fixed coast-down coefficients, M0), ``oracle`` (the simulator's true current parameters) and
``online`` (an estimator running on the CAN stream, :mod:`roadload.controllers.online`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from types import ModuleType
from typing import Any, Protocol, runtime_checkable

import numpy as np

from roadload.road_load import RoadLoadParameters, road_load, tractive_force
from roadload.units import G

ca: ModuleType | None
try:  # casadi is a hard dependency, but keep numpy-only callers importable without it loaded
    import casadi as ca
except ImportError:  # pragma: no cover
    ca = None


class ForceModelError(ValueError):
    """An unknown force-model name or a force model that returns no road-load parameters."""


def resistance_force(v, grade, curvature, p):
    """F_resist [N] of :func:`roadload.road_load.road_load` for speed v [m/s], grade theta [rad], curvature
    1/r [1/m]; numeric (numpy) or symbolic (CasADi SX/MX/DM) depending on the arguments."""
    return road_load(v, grade, curvature, p, xp=_namespace(v, grade, curvature, p))


def wheel_force(v, acceleration, grade, curvature, p):
    """Wheel (tractive) force F_xV [N] needed for acceleration dv/dt [m/s^2]: F_resist + (m + m_rot) dv/dt."""
    return tractive_force(v, acceleration, grade, curvature, p, xp=_namespace(v, grade, curvature, p))


def _namespace(*args):
    """casadi for symbolic arguments, numpy otherwise."""
    if ca is not None and any(isinstance(x, (ca.SX, ca.MX, ca.DM)) for x in args):
        return ca
    return np


def road_heading(road, s) -> np.ndarray:
    """Heading psi(s) [rad] of the road at distance(s) s [m] in the road's own frame (psi(0) = 0, positive left):
    the integral of the curvature over distance (trapezoid on the profile's grid, as the simulator's road)."""
    d = np.asarray(road.distance, float)
    kappa = np.asarray(road.curvature, float)
    psi = np.concatenate([[0.0], np.cumsum(0.5 * (kappa[1:] + kappa[:-1]) * np.diff(d))])
    return np.interp(s, d, psi)


@dataclass(frozen=True)
class WindEstimate:
    """A wind vector in the road's frame: speed v_w [m/s] and the direction it blows towards psi_w [rad] (0 = along
    the road's initial heading, i.e. a tailwind at the start; pi = a headwind), with the vehicle's yaw drag factor
    k [1] of c_x(psi_a) (eq. 2.7-2.8)."""

    speed: float
    direction: float
    yaw_drag_factor: float = 0.0

    def __post_init__(self) -> None:
        if not (math.isfinite(self.speed) and self.speed >= 0 and math.isfinite(self.direction)):
            raise ForceModelError(f"WindEstimate: speed must be finite >= 0 m/s and direction finite [rad], got "
                                  f"{self.speed}, {self.direction}")
        if not (math.isfinite(self.yaw_drag_factor) and self.yaw_drag_factor >= 0):
            raise ForceModelError(f"WindEstimate.yaw_drag_factor: finite >= 0, got {self.yaw_drag_factor}")

    def components(self, heading) -> tuple[np.ndarray, np.ndarray]:
        """(headwind, crosswind) [m/s] for a vehicle heading psi [rad]: the approach velocity of eq. 2.8a is
        u_x = v + headwind, u_y = crosswind, with headwind = -v_w cos(psi_w - psi), crosswind = -v_w sin(...)."""
        rel = self.direction - np.asarray(heading, float)
        return -self.speed * np.cos(rel), -self.speed * np.sin(rel)

    @classmethod
    def from_vector(cls, east: float, north: float, yaw_drag_factor: float = 0.0) -> "WindEstimate":
        """From the components [m/s] along the road's initial heading (x) and to its left (y)."""
        return cls(float(math.hypot(east, north)), float(math.atan2(north, east)), yaw_drag_factor)


@runtime_checkable
class ForceModel(Protocol):
    """Source of force parameters; ``parameters()`` is called every controller step."""

    name: str

    def reset(self) -> None: ...

    def observe(self, sample: dict[str, float]) -> None:
        """Feed the latest CAN sample (channel name -> SI value); models that do not learn ignore it."""

    def parameters(self) -> RoadLoadParameters: ...

    def describe(self) -> dict[str, Any]: ...


class FixedForceModel:
    """The ``abc`` model (M0): coast-down coefficients a_V, b_V, c_V and the nominal mass, never updated."""

    name = "abc"

    def __init__(self, params: RoadLoadParameters) -> None:
        self._params = params

    def reset(self) -> None:
        pass

    def observe(self, sample: dict[str, float]) -> None:
        pass

    def parameters(self) -> RoadLoadParameters:
        return self._params

    def describe(self) -> dict[str, Any]:
        return {"force_model": self.name, **self._params.to_dict()}


class OracleForceModel:
    """The ``oracle`` model: the simulator's true current parameters (``truth()`` returns a RoadLoadParameters) and,
    with ``wind`` (a callable returning the true :class:`WindEstimate` or None in still air), the wind vector, so
    that the MPC plans each segment with the headwind and crosswind of the road's heading there."""

    name = "oracle"

    def __init__(self, truth, wind=None) -> None:
        if not callable(truth):
            raise ForceModelError("oracle force model needs a callable returning the true RoadLoadParameters")
        if wind is not None and not callable(wind):
            raise ForceModelError("oracle force model: wind must be a callable returning a WindEstimate or None")
        self._truth = truth
        self._wind = wind

    def wind(self) -> WindEstimate | None:
        """The true wind vector now (None in still air or without a wind source)."""
        return None if self._wind is None else self._wind()

    def reset(self) -> None:
        pass

    def observe(self, sample: dict[str, float]) -> None:
        pass

    def parameters(self) -> RoadLoadParameters:
        p = self._truth()
        if not isinstance(p, RoadLoadParameters):
            raise ForceModelError(f"oracle truth source returned {type(p).__name__}, expected RoadLoadParameters")
        return p

    def describe(self) -> dict[str, Any]:
        return {"force_model": self.name}


MODEL_ERRORS = ("mass", "rolling", "drag_area", "grade_bias", "drivetrain_loss")
"""Force-model errors of the sensitivity map: relative errors of m_V (with every mass-proportional term), of the
rolling resistance (c0, c1, c4), of the drag area (c2), an absolute grade bias [rad] (a constant force
m g sin(bias) ~ m g bias, added to c0) and a relative error of the drive-train/engine loss model (applied to the
MPC's energy model, not to the forces; :func:`with_loss_error`)."""


class ErroredForceModel:
    """The oracle's true parameters with deliberate errors (sensitivity map): ``errors`` maps MODEL_ERRORS names
    to relative errors (grade_bias: rad). ``drivetrain_loss`` is ignored here (see :func:`with_loss_error`)."""

    name = "wrong"

    def __init__(self, base: ForceModel, errors: dict[str, float]) -> None:
        unknown = sorted(set(errors) - set(MODEL_ERRORS))
        if unknown:
            raise ForceModelError(f"unknown force-model errors {unknown}; known: {list(MODEL_ERRORS)}")
        for k, e in errors.items():
            if not np.isfinite(e) or (k != "grade_bias" and e <= -1.0):
                raise ForceModelError(f"force-model error {k}={e}: relative errors must be finite and > -1")
        self.base, self.errors = base, {k: float(v) for k, v in errors.items()}

    def reset(self) -> None:
        self.base.reset()

    def observe(self, sample: dict[str, float]) -> None:
        self.base.observe(sample)

    def parameters(self) -> RoadLoadParameters:
        p = self.base.parameters()
        km = 1.0 + self.errors.get("mass", 0.0)
        kr = 1.0 + self.errors.get("rolling", 0.0)
        kc = 1.0 + self.errors.get("drag_area", 0.0)
        mass = p.mass * km
        return p.with_(mass=mass, c0=p.c0 * km * kr + mass * G * np.sin(self.errors.get("grade_bias", 0.0)),
                       c1=p.c1 * km * kr, c4=p.c4 * km * kr, c2=p.c2 * kc, k_corner=p.k_corner * km * km,
                       rotational_mass=p.rotational_mass)

    def describe(self) -> dict[str, Any]:
        return {"force_model": self.name, **{f"error_{k}": v for k, v in self.errors.items()}}


FORCE_MODEL_NAMES = ("abc", "online", "online_wind", "oracle", "wrong")
