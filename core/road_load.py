"""The road load of chapter 2: one owner for the force terms and for the lumped parameters that feed them.

    F_resist = F_r + F_a + F_cl + F_Wc                                                     (eq. 2.5-2.15)
    F_r  = m_V g cos(theta) (f_r0 + f_r1 v + f_r4 v^4)      rolling resistance             (eq. 2.9, 2.10)
    F_a  = rho_a/2 c_x A_V (v + w)^2                         aerodynamic drag, headwind w   (eq. 2.7, 2.8)
    F_cl = m_V g sin(theta)                                  climbing force                 (eq. 2.5)
    F_Wc = m_V^2 v^4 kappa^2 / (4 c_yW)                      cornering resistance           (eq. 2.15)
    F_xV = F_resist + (m_V + m_rot) dv/dt                    tractive force                 (eq. 2.16b)

Lumped, the text's coast-down coefficients (eq. 5.4) are a_V = m_V g f_r0 [N], b_V = m_V g f_r1 [N s/m] and
c_V = rho_a/2 c_x A_V [kg/m]; M4 adds k = m_V^2 / c_yW [kg^2/N]. :class:`RoadLoadParameters` holds that lumped form
and is built from a vehicle spec (``from_spec``), from the simulator's current truth (``from_truth``) or from a
coast-down (``from_coast_down``). The simulator's nominal values, the estimators' prior knowledge, the controllers'
force models and the sim-to-real force balance all use it.

The functions take an array namespace ``xp`` (numpy by default; ``casadi`` works too, for symbolic expressions in
the MPC), so the same equations serve both.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, replace
from typing import Any, Mapping

import numpy as np

from .units import G, STANDARD_AIR_DENSITY

__all__ = ["RoadLoadError", "RoadLoadParameters", "aerodynamic_drag_force", "climbing_force",
           "cornering_resistance_force", "crosswind_drag_increase", "road_load", "rolling_resistance_coefficient",
           "rolling_resistance_force", "tractive_force"]


class RoadLoadError(ValueError):
    """Invalid road-load parameters."""


def rolling_resistance_coefficient(speed, f_r0, f_r1=0.0, f_r4=0.0):
    """f_r(v) = f_r0 + f_r1 v + f_r4 v^4 [1] (eq. 2.10); speed v [m/s], f_r1 [s/m], f_r4 [s^4/m^4]."""
    v2 = speed * speed
    return f_r0 + f_r1 * speed + f_r4 * v2 * v2


def rolling_resistance_force(mass, speed, grade, f_r0, f_r1=0.0, f_r4=0.0, xp=np):
    """F_r = m_V g cos(theta) f_r(v) [N] (eq. 2.9, 2.10); mass [kg], speed [m/s], grade theta [rad]."""
    return mass * G * xp.cos(grade) * rolling_resistance_coefficient(speed, f_r0, f_r1, f_r4)


def aerodynamic_drag_force(air_density, drag_area, air_speed):
    """F_a = rho_a/2 c_x A_V v_a^2 [N] (eq. 2.7) along the direction of travel; air_density [kg/m^3], drag_area
    c_x A_V [m^2], air_speed v_a = v + w [m/s] (w: headwind component, eq. 2.8)."""
    return 0.5 * air_density * drag_area * air_speed * air_speed


def crosswind_drag_increase(drag_coefficient, air_speed_x, crosswind, yaw_drag_factor, xp=np):
    """F_a(u_x, u_y) - c_V u_x^2 [N]: what a crosswind adds to the drag of the approach speed u_x = v + w [m/s].

    With the approach velocity u = (u_x, u_y) (eq. 2.8a; u_y the crosswind [m/s]), v_a = |u| and the yaw angle
    psi_a, c_x(psi_a) = c_w cos psi_a (1 + k sin^2 psi_a) (eq. 2.7, k the yaw drag factor [1]) gives
    F_a = c_V u_x v_a (1 + k u_y^2 / v_a^2), c_V = rho_a/2 c_w A_V [kg/m]; this returns
    c_V u_x ((v_a - u_x) + k u_y^2 / v_a), with v_a - u_x written without cancellation (u_y^2 / (v_a + u_x) for
    u_x >= 0). Exactly 0 without crosswind. numpy or CasADi (``xp=casadi``)."""
    uy2 = crosswind * crosswind
    air_speed = xp.sqrt(air_speed_x * air_speed_x + uy2 + 1e-12)
    excess = uy2 / (air_speed + xp.fabs(air_speed_x))  # = v_a - u_x where u_x >= 0
    if xp is np:
        excess = np.where(air_speed_x >= 0, excess, air_speed - air_speed_x)
    else:
        excess = xp.if_else(air_speed_x >= 0, excess, air_speed - air_speed_x)
    return drag_coefficient * air_speed_x * (excess + yaw_drag_factor * uy2 / air_speed)


def climbing_force(mass, grade, xp=np):
    """F_cl = m_V g sin(theta) [N] (eq. 2.5); mass [kg], grade theta [rad]."""
    return mass * G * xp.sin(grade)


def cornering_resistance_force(mass, speed, curvature, cornering_stiffness):
    """F_Wc = m_V^2 v^4 kappa^2 / (4 c_yW) [N] (eq. 2.15, steady state); curvature kappa = 1/r [1/m],
    cornering_stiffness c_yW [N/rad] (the equivalent stiffness of eq. 2.15)."""
    v2 = speed * speed
    return mass * mass * v2 * v2 * curvature * curvature / (4.0 * cornering_stiffness)


@dataclass(frozen=True)
class RoadLoadParameters:
    """Lumped road-load parameters (SI), the form of eq. 5.4-5.6 and of the MPC's force model.

    mass m_V [kg]; c0 = a_V = m_V g f_r0 [N]; c1 = b_V = m_V g f_r1 [N s/m]; c2 = c_V = rho_a/2 c_x A_V [kg/m];
    c4 = m_V g f_r4 [N s^4/m^4]; k_corner = m_V^2 / c_yW [kg^2/N] (0: no cornering resistance); headwind w [m/s]
    (positive against the direction of travel); rotational_mass = (I_red + 4 I_W) / r_W^2 [kg], which adds to m_V
    in the acceleration term only (0 where a model lumps it into m_V).
    """

    mass: float
    c0: float
    c1: float = 0.0
    c2: float = 0.0
    c4: float = 0.0
    k_corner: float = 0.0
    headwind: float = 0.0
    rotational_mass: float = 0.0

    FIELDS = ("mass", "c0", "c1", "c2", "c4", "k_corner", "headwind", "rotational_mass")

    def __post_init__(self) -> None:
        for name in self.FIELDS:
            value = getattr(self, name)
            if not np.isfinite(value):
                raise RoadLoadError(f"road-load parameter {name} is not finite ({value})")
        if self.mass <= 0:
            raise RoadLoadError(f"road-load parameter mass must be > 0 kg, got {self.mass} kg")
        if self.rotational_mass < 0:
            raise RoadLoadError(f"road-load parameter rotational_mass must be >= 0 kg, got {self.rotational_mass} kg")

    # ---------------------------------------------------------------- constructors
    @classmethod
    def from_physical(cls, mass: float, f_r0: float, f_r1: float = 0.0, f_r4: float = 0.0, drag_area: float = 0.0,
                      air_density: float = STANDARD_AIR_DENSITY, cornering_stiffness: float | None = None,
                      headwind: float = 0.0, rotational_mass: float = 0.0) -> "RoadLoadParameters":
        """From the quantities of chapter 2: f_r0 [1], f_r1 [s/m], f_r4 [s^4/m^4] (eq. 2.10), c_x A_V [m^2],
        rho_a [kg/m^3], c_yW [N/rad] (None or 0: no cornering resistance)."""
        k = 0.0 if not cornering_stiffness else mass ** 2 / float(cornering_stiffness)
        return cls(mass=float(mass), c0=mass * G * f_r0, c1=mass * G * f_r1, c2=0.5 * air_density * drag_area,
                   c4=mass * G * f_r4, k_corner=k, headwind=float(headwind), rotational_mass=float(rotational_mass))

    @classmethod
    def from_spec(cls, spec: Any, mass: float | None = None, air_density: float = STANDARD_AIR_DENSITY,
                  rotational_mass: float = 0.0) -> "RoadLoadParameters":
        """The nominal road load of a :class:`roadload.vehicle.VehicleSpec` (spec-sheet values: tires' f_r0/f_r1/
        f_r4, drag area, equivalent cornering stiffness); ``mass`` overrides m_V (e.g. with a payload)."""
        t = spec.tires
        return cls.from_physical(float(spec.body.mass if mass is None else mass), float(t.rolling_resistance_f0),
                                 float(t.rolling_resistance_f1), float(t.rolling_resistance_f4),
                                 float(spec.aero.drag_area), air_density,
                                 float(spec.equivalent_cornering_stiffness()), rotational_mass=rotational_mass)

    @classmethod
    def from_truth(cls, truth: Mapping[str, float]) -> "RoadLoadParameters":
        """From ``Simulator.true_parameters()``: the current mass, f_r0/f_r1/f_r4, drag area, air density and
        equivalent cornering stiffness; the wind's headwind component -v_w cos(psi_w) (psi_w = 0 is a tailwind);
        the rotational mass of the engaged gear (effective mass - m_V)."""
        m = float(truth["mass"])
        c_y = float(truth.get("cornering_stiffness", 0.0))
        headwind = -float(truth.get("wind_speed", 0.0)) * math.cos(float(truth.get("wind_angle", 0.0)))
        return cls.from_physical(m, float(truth["rolling_resistance_f0"]), float(truth["rolling_resistance_f1"]),
                                 float(truth["rolling_resistance_f4"]), float(truth["drag_area"]),
                                 float(truth["air_density"]), c_y if c_y > 0 else None, headwind,
                                 max(float(truth.get("effective_mass", m)) - m, 0.0))

    @classmethod
    def from_coast_down(cls, a: float, b: float, c: float, mass: float,
                        rotational_mass: float = 0.0) -> "RoadLoadParameters":
        """M0 (eq. 5.4): coast-down coefficients a_V [N], b_V [N s/m], c_V [kg/m] with the nominal mass [kg]."""
        return cls(mass=float(mass), c0=float(a), c1=float(b), c2=float(c), rotational_mass=float(rotational_mass))

    # ---------------------------------------------------------------- views
    @property
    def inertial_mass(self) -> float:
        """m_V + rotational equivalent mass [kg] (multiplies dv/dt)."""
        return self.mass + self.rotational_mass

    @property
    def coast_down(self) -> tuple[float, float, float]:
        """(a_V [N], b_V [N s/m], c_V [kg/m]) of eq. 5.4."""
        return self.c0, self.c1, self.c2

    def rolling_resistance_f0(self) -> float:
        """f_r0 = a_V / (m_V g) [1]."""
        return self.c0 / (self.mass * G)

    def drag_area(self, air_density: float = STANDARD_AIR_DENSITY) -> float:
        """c_x A_V = 2 c_V / rho_a [m^2]."""
        return 2.0 * self.c2 / air_density

    def as_vector(self) -> np.ndarray:
        """The parameters in :attr:`FIELDS` order (the MPC's parameter vector)."""
        return np.array([getattr(self, n) for n in self.FIELDS], dtype=float)

    @classmethod
    def from_vector(cls, x) -> "RoadLoadParameters":
        x = np.asarray(x, dtype=float).ravel()
        if x.size != len(cls.FIELDS):
            raise RoadLoadError(f"expected {len(cls.FIELDS)} road-load parameters {cls.FIELDS}, got {x.size}")
        return cls(**dict(zip(cls.FIELDS, map(float, x))))

    def to_dict(self) -> dict[str, float]:
        return asdict(self)

    def with_(self, **changes: float) -> "RoadLoadParameters":
        return replace(self, **changes)


def road_load(speed, grade, curvature, p, xp=np):
    """F_resist [N] (module docstring) for speed v [m/s], grade theta [rad] and curvature kappa [1/m].

    ``p``: a :class:`RoadLoadParameters` or a vector in :attr:`RoadLoadParameters.FIELDS` order (numpy array or a
    CasADi expression with ``xp=casadi``). Elementwise on arrays."""
    if isinstance(p, RoadLoadParameters):
        p = p.as_vector()
    m, c0, c1, c2, c4, k, w = (p[i] for i in range(7))
    v2 = speed * speed
    rolling = (c0 + c1 * speed + c4 * v2 * v2) * xp.cos(grade)     # = m g cos(theta) f_r(v), eq. 2.9/2.10
    aero = c2 * (speed + w) * (speed + w)                           # eq. 2.7 with the air approach speed, eq. 2.8
    cornering = k * v2 * v2 * curvature * curvature / 4.0           # eq. 2.15 with k = m^2 / c_yW
    return rolling + aero + climbing_force(m, grade, xp) + cornering


def tractive_force(speed, acceleration, grade, curvature, p, xp=np):
    """F_xV = F_resist + (m_V + m_rot) dv/dt [N] (eq. 2.16b); acceleration dv/dt [m/s^2]."""
    m = p.inertial_mass if isinstance(p, RoadLoadParameters) else p[0] + p[7]
    return road_load(speed, grade, curvature, p, xp) + m * acceleration
