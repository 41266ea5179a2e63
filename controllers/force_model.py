"""Force models for the eco-driving MPC: the resistance ``F_resist(v, grade, curvature; params)`` plus the mass.

One polynomial form covers the text's white-box and gray-box models (eq. 5.4-5.6, 2.10, 2.15):

    F_resist = (c0 + c1 v + c4 v^4) cos(theta) + c2 (v + w)^2 + m g sin(theta) + k_c v^4 kappa^2 / 4

with c0 = m g f_r0 = a_V [N], c1 = m g f_r1 = b_V [N s/m], c4 = m g f_r4 [N s^4/m^4],
c2 = rho_a/2 A_V c_x = c_V [kg/m], w the headwind component [m/s] (0 when unknown), m = m_V [kg] and
k_c = m_V^2 / c_yW [kg^2/N] (M4's fourth parameter). The wheel force balances F_resist + (m + m_rot) dv/dt,
m_rot the equivalent mass of the rotating parts (0 where the model lumps it into m, as M3/M4 do).

Three sources of parameters sit behind one interface (:class:`ForceModel`), re-read by the controller every
step: ``abc`` (fixed coast-down coefficients, M0), ``oracle`` (the simulator's true current parameters) and
``online`` (an estimator running on the CAN stream, :mod:`roadload.controllers.online`).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, replace
from typing import Any, Protocol, runtime_checkable

import numpy as np

from roadload.units import G

try:  # casadi is a hard dependency, but keep numpy-only callers importable without it loaded
    import casadi as ca
except ImportError:  # pragma: no cover
    ca = None


class ForceModelError(ValueError):
    """Invalid force-model parameters or an unknown force-model name."""


PARAMETER_NAMES = ("mass", "c0", "c1", "c2", "c4", "k_corner", "headwind", "rotational_mass")


@dataclass(frozen=True)
class ForceParameters:
    """Parameters of the resistance polynomial (SI). See the module docstring for the symbols."""

    mass: float  # m_V [kg]
    c0: float  # a_V = m g f_r0 [N]
    c1: float = 0.0  # b_V = m g f_r1 [N s/m]
    c2: float = 0.0  # c_V = rho_a/2 A_V c_x [kg/m]
    c4: float = 0.0  # m g f_r4 [N s^4/m^4]
    k_corner: float = 0.0  # m_V^2 / c_yW [kg^2/N]
    headwind: float = 0.0  # w [m/s], positive against the direction of travel
    rotational_mass: float = 0.0  # (I_red + 4 I_W) / r_W^2 [kg]: adds to m in the acceleration term only

    def __post_init__(self) -> None:
        for name in PARAMETER_NAMES:
            value = getattr(self, name)
            if not np.isfinite(value):
                raise ForceModelError(f"force parameter {name} is not finite ({value})")
        if self.mass <= 0:
            raise ForceModelError(f"force parameter mass must be positive, got {self.mass} kg")
        if self.rotational_mass < 0:
            raise ForceModelError(f"force parameter rotational_mass must be >= 0, got {self.rotational_mass} kg")

    @property
    def inertial_mass(self) -> float:
        """m_V + rotational equivalent mass [kg] (multiplies dv/dt)."""
        return self.mass + self.rotational_mass

    def as_vector(self) -> np.ndarray:
        return np.array([getattr(self, n) for n in PARAMETER_NAMES], dtype=float)

    @classmethod
    def from_vector(cls, x) -> "ForceParameters":
        x = np.asarray(x, dtype=float).ravel()
        if x.size != len(PARAMETER_NAMES):
            raise ForceModelError(f"expected {len(PARAMETER_NAMES)} force parameters {PARAMETER_NAMES}, got {x.size}")
        return cls(**dict(zip(PARAMETER_NAMES, map(float, x))))

    @classmethod
    def from_physical(cls, mass: float, f_r0: float, f_r1: float, f_r4: float, drag_area: float,
                      air_density: float, cornering_stiffness: float | None = None,
                      headwind: float = 0.0) -> "ForceParameters":
        """From the physical quantities of chapter 2: f_r(v) = f_r0 + f_r1 v + f_r4 v^4 (eq. 2.10),
        c_x A_V [m^2], rho_a [kg/m^3], c_yW [N/rad] (None: no cornering resistance)."""
        k = 0.0 if not cornering_stiffness else mass ** 2 / float(cornering_stiffness)
        return cls(mass=mass, c0=mass * G * f_r0, c1=mass * G * f_r1, c2=0.5 * air_density * drag_area,
                   c4=mass * G * f_r4, k_corner=k, headwind=headwind)

    def to_dict(self) -> dict[str, float]:
        return asdict(self)

    def with_(self, **changes: float) -> "ForceParameters":
        return replace(self, **changes)


def resistance_force(v, grade, curvature, p):
    """F_resist [N] (module docstring) for speed v [m/s], grade theta [rad], curvature 1/r [1/m].

    ``p`` is a parameter vector in PARAMETER_NAMES order (numpy array or CasADi expression) or a
    :class:`ForceParameters`. Works elementwise on numpy arrays and symbolically on CasADi SX/MX.
    """
    if isinstance(p, ForceParameters):
        p = p.as_vector()
    symbolic = ca is not None and any(isinstance(x, (ca.SX, ca.MX, ca.DM)) for x in (v, grade, curvature, p))
    cos, sin = (ca.cos, ca.sin) if symbolic else (np.cos, np.sin)
    m, c0, c1, c2, c4, k, w = (p[i] for i in range(7))
    v2 = v * v
    return ((c0 + c1 * v + c4 * v2 * v2) * cos(grade) + c2 * (v + w) * (v + w) + m * G * sin(grade)
            + k * v2 * v2 * curvature * curvature / 4.0)


def wheel_force(v, acceleration, grade, curvature, p):
    """Wheel (tractive) force F_xV [N] needed for acceleration dv/dt [m/s^2]: F_resist + (m + m_rot) dv/dt."""
    m = p.inertial_mass if isinstance(p, ForceParameters) else p[0] + p[7]
    return resistance_force(v, grade, curvature, p) + m * acceleration


@runtime_checkable
class ForceModel(Protocol):
    """Source of force parameters; ``parameters()`` is called every controller step."""

    name: str

    def reset(self) -> None: ...

    def observe(self, sample: dict[str, float]) -> None:
        """Feed the latest CAN sample (channel name -> SI value); models that do not learn ignore it."""

    def parameters(self) -> ForceParameters: ...

    def describe(self) -> dict[str, Any]: ...


class FixedForceModel:
    """The ``abc`` model (M0): coast-down coefficients a_V, b_V, c_V and the nominal mass, never updated."""

    name = "abc"

    def __init__(self, params: ForceParameters) -> None:
        self._params = params

    def reset(self) -> None:
        pass

    def observe(self, sample: dict[str, float]) -> None:
        pass

    def parameters(self) -> ForceParameters:
        return self._params

    def describe(self) -> dict[str, Any]:
        return {"force_model": self.name, **self._params.to_dict()}


class OracleForceModel:
    """The ``oracle`` model: the simulator's true current parameters (``truth()`` returns a ForceParameters)."""

    name = "oracle"

    def __init__(self, truth) -> None:
        if not callable(truth):
            raise ForceModelError("oracle force model needs a callable returning the true ForceParameters")
        self._truth = truth

    def reset(self) -> None:
        pass

    def observe(self, sample: dict[str, float]) -> None:
        pass

    def parameters(self) -> ForceParameters:
        p = self._truth()
        if not isinstance(p, ForceParameters):
            raise ForceModelError(f"oracle truth source returned {type(p).__name__}, expected ForceParameters")
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

    def parameters(self) -> ForceParameters:
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


FORCE_MODEL_NAMES = ("abc", "online", "oracle", "wrong")
