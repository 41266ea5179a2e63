"""The sim's force balance as a white-box model structure of the chapter-5 model registry.

F_xV = m_V (g sin θ + v̇) + m_V g cos θ (f_r0 + f_r1 v + f_r4 v⁴) + ρ_a/2 c_x A_V v² + m_V² v⁴/(4 r² c_yW)

(eq. 2.5-2.10, 2.15; the measured side F_xV of eq. 5.5c comes from the drive torque through the drive-train
model minus the friction-brake force). Every summand is one :class:`roadload.estimators.models.Term` with its
parameter fixed from the sim's :class:`roadload.vehicle.VehicleSpec`; the structure is registered as
``sim:<vehicle>`` so candidate effects extend it through the same registry (:mod:`.catalog`).

Columns read (diagnosis table, :mod:`.table`): speed [m/s], acceleration [m/s²], gradient_angle [rad],
path_curvature [1/m] (0 where unknown), air_density [kg/m³].
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
import pandas as pd

from roadload.estimators.models import (ACCELERATION, GRADIENT_ANGLE, PATH_CURVATURE, SPEED, ModelStructure,
                                        Term, register_model)
from roadload.road_load import RoadLoadParameters, rolling_resistance_coefficient
from roadload.units import G, STANDARD_AIR_DENSITY

from .errors import DiagnosisError

AIR_DENSITY = "air_density"


def _c(s, name):
    return np.asarray(s[name], dtype=float)


def columns_of(table: pd.DataFrame) -> dict[str, np.ndarray]:
    """The table as the name -> array mapping the model terms read."""
    return {c: table[c].to_numpy() for c in table.columns}


@dataclass(frozen=True)
class SimForceModel:
    """Parameters of the sim's force balance: the vehicle's road load (:class:`roadload.road_load.RoadLoadParameters`
    at the standard air density, from which m_V [kg], f_r0 [1], f_r1 [s/m], f_r4 [s⁴/m⁴], c_x A_V [m²] and c_yW
    [N/rad] of eq. 2.15 are read), drive-train efficiency η (for converting loss fractions), r_W [m], number of
    gears, the drive-train oil's warm temperature [K], cold loss factor φ_cold and time constant [s]."""

    vehicle: str
    road_load: RoadLoadParameters
    drivetrain_efficiency: float = 0.93
    wheel_radius: float = 0.3
    n_gears: int = 1
    oil_warm_temperature: float = 363.15
    oil_cold_loss_factor: float = 1.6
    oil_time_constant: float = 1200.0

    def __post_init__(self) -> None:
        for name, value in (("drag area", self.road_load.c2), ("cornering k", self.road_load.k_corner),
                            ("wheel_radius", self.wheel_radius)):
            if not (np.isfinite(value) and value > 0):
                raise DiagnosisError(f"SimForceModel: {name} must be a positive number, got {value!r}")

    @classmethod
    def from_physical(cls, vehicle: str, mass: float, rolling_resistance_f0: float, rolling_resistance_f1: float,
                      rolling_resistance_f4: float, drag_area: float, cornering_stiffness: float,
                      **drivetrain: Any) -> "SimForceModel":
        """From m_V [kg], f_r0, f_r1, f_r4, c_x A_V [m²], c_yW [N/rad] and the drive-train fields."""
        if not (np.isfinite(mass) and mass > 0):
            raise DiagnosisError(f"SimForceModel: mass must be a positive number [kg], got {mass!r}")
        road = RoadLoadParameters.from_physical(mass, rolling_resistance_f0, rolling_resistance_f1,
                                                rolling_resistance_f4, drag_area,
                                                cornering_stiffness=cornering_stiffness)
        return cls(vehicle, road, **drivetrain)

    @classmethod
    def from_spec(cls, spec, mass: float | None = None) -> "SimForceModel":
        """From a :class:`roadload.vehicle.VehicleSpec` (mass overrides m_V, e.g. with a payload)."""
        d = spec.drivetrain
        return cls(vehicle=spec.name, road_load=RoadLoadParameters.from_spec(spec, mass=mass),
                   wheel_radius=spec.wheel_radius, n_gears=int(d.n_gears),
                   oil_warm_temperature=float(d.oil_warm_temperature),
                   oil_cold_loss_factor=float(d.oil_cold_loss_factor), oil_time_constant=float(d.oil_time_constant))

    @property
    def mass(self) -> float:
        return self.road_load.mass

    @property
    def rolling_resistance_f0(self) -> float:
        return self.road_load.c0 / (self.mass * G)

    @property
    def rolling_resistance_f1(self) -> float:
        return self.road_load.c1 / (self.mass * G)

    @property
    def rolling_resistance_f4(self) -> float:
        return self.road_load.c4 / (self.mass * G)

    @property
    def drag_area(self) -> float:
        return self.road_load.drag_area(STANDARD_AIR_DENSITY)

    @property
    def cornering_stiffness(self) -> float:
        return self.mass ** 2 / self.road_load.k_corner

    def rolling_resistance_coefficient(self, speed: np.ndarray) -> np.ndarray:
        """f_r(v) (eq. 2.10)."""
        return rolling_resistance_coefficient(np.asarray(speed, dtype=float), self.rolling_resistance_f0,
                                              self.rolling_resistance_f1, self.rolling_resistance_f4)

    def structure(self) -> ModelStructure:
        """The white-box structure ``sim:<vehicle>`` (registered, replacing an older one of that name)."""
        terms = (
            Term("g sin(theta) + dv/dt", "m_V", "kg",
                 lambda s: G * np.sin(_c(s, GRADIENT_ANGLE)) + _c(s, ACCELERATION), (GRADIENT_ANGLE, ACCELERATION),
                 lambda n: n.mass),
            Term("g cos(theta)", "m_V f_r0", "kg", lambda s: G * np.cos(_c(s, GRADIENT_ANGLE)), (GRADIENT_ANGLE,),
                 lambda n: n.mass * n.rolling_resistance_coefficient),
            Term("g cos(theta) v", "m_V f_r1", "kg s/m",
                 lambda s: G * np.cos(_c(s, GRADIENT_ANGLE)) * _c(s, SPEED), (GRADIENT_ANGLE, SPEED),
                 lambda n: 0.0),
            Term("g cos(theta) v^4", "m_V f_r4", "kg s^4/m^4",
                 lambda s: G * np.cos(_c(s, GRADIENT_ANGLE)) * _c(s, SPEED) ** 4, (GRADIENT_ANGLE, SPEED),
                 lambda n: 0.0),
            Term("rho_a/2 v^2", "c_x A_V", "m^2", lambda s: 0.5 * _c(s, AIR_DENSITY) * _c(s, SPEED) ** 2,
                 (AIR_DENSITY, SPEED), lambda n: n.drag_area),
            Term("v^4/(4 r^2)", "m_V^2/c_yW", "kg^2 rad/N",
                 lambda s: _c(s, SPEED) ** 4 * np.nan_to_num(_c(s, PATH_CURVATURE)) ** 2 / 4.0,
                 (SPEED, PATH_CURVATURE), lambda n: n.mass ** 2 / n.cornering_stiffness),
        )
        # requires_output=(): the regressors are built on tables with or without the measured force
        model = ModelStructure(name=f"sim:{self.vehicle}", terms=terms, white_box=True, requires_output=(),
                               description=f"force balance of the sim {self.vehicle!r} (eq. 2.5-2.10, 2.15)")
        return register_model(model, replace_existing=True)

    def parameters(self) -> np.ndarray:
        """X of :meth:`structure` (fixed)."""
        m = self.mass
        return np.array([m, m * self.rolling_resistance_f0, m * self.rolling_resistance_f1,
                         m * self.rolling_resistance_f4, self.drag_area, m ** 2 / self.cornering_stiffness])

    def predict(self, table: pd.DataFrame) -> np.ndarray:
        """F_xV the sim's force balance gives for the motion in ``table`` [N]."""
        return self.structure().predict(columns_of(table), self.parameters())
