"""The simulator's steady road load of a vehicle spec, as a coast-down in neutral would measure it.

F_road(v) = m g f_r(v) (eq. 2.9/2.10) + rho_a/2 c_x A_V v^2 (eq. 2.7, no wind) + X_12 delta_toe sin(delta_toe)
(toe-in, section 2.4.5) + the drive-train's zero-load spin losses (warm oil, eq. 2.17), at the wheels [N].
The spin losses come from the simulator's loss maps (:mod:`.powertrain`), which is why this lives in envs and not
with the lumped road-load model of :mod:`roadload.road_load`.
"""

from __future__ import annotations

import math

import numpy as np

from roadload.units import G, STANDARD_AIR_DENSITY
from roadload.vehicle import VehicleSpec

from .powertrain import Powertrain

__all__ = ["neutral_road_load", "road_load_coefficients"]


def neutral_road_load(spec: VehicleSpec, speed, air_density: float = STANDARD_AIR_DENSITY,
                      mass: float | None = None) -> np.ndarray:
    """Steady flat-road resistance [N] at the wheels in neutral / zero drive torque at ``speed`` [m/s]."""
    m = spec.body.mass if mass is None else mass
    v = np.asarray(speed, dtype=float)
    t = spec.tires
    toe = t.cornering_stiffness_front * t.toe_in * math.sin(t.toe_in)
    return (m * G * t.rolling_resistance_coefficient(v) + 0.5 * air_density * spec.aero.drag_area * v ** 2 + toe
            + Powertrain(spec).neutral_drag_force(v))


def road_load_coefficients(spec: VehicleSpec, v_min: float = 15 / 3.6, v_max: float = 130 / 3.6,
                           air_density: float = STANDARD_AIR_DENSITY, speeds=None) -> tuple[float, float, float]:
    """Coast-down coefficients (a [N], b [N s/m], c [N s^2/m^2]): least-squares fit of a + b v + c v^2 to
    :func:`neutral_road_load` at 200 speeds over [v_min, v_max] [m/s] or at the given ``speeds`` (the f_r4 v^4
    term and the drive-train drag fold into a, b, c)."""
    v = np.linspace(v_min, v_max, 200) if speeds is None else np.asarray(speeds, dtype=float)
    coef = np.polyfit(v, neutral_road_load(spec, v, air_density), 2)
    return float(coef[2]), float(coef[1]), float(coef[0])
