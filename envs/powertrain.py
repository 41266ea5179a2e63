"""The simulator's drive-train of a vehicle spec, evaluated from Python (eq. 2.17): speed ratios, torque limits,
torque through gearbox and differential with their loss maps, fuel and electric power.

:class:`Powertrain` packs the spec once and calls the same compiled functions the simulator core runs, so a model
fitted to it (the controllers' smooth source-energy model) sees exactly the simulated drive-train.
"""

from __future__ import annotations

import numpy as np

from roadload.vehicle import VehicleSpec

from .drivetrain import (battery_current, forward_wheel_torque, fuel_power, inverse_wheel_torque,
                         motor_electric_power, speed_ratio, torque_limits)
from .packing import pack_vehicle


class Powertrain:
    """The packed drive-train of one vehicle spec (warm oil unless a loss factor phi > 1 is given)."""

    def __init__(self, spec: VehicleSpec) -> None:
        params, self._tables = pack_vehicle(spec)
        self._p = params[()]
        self.spec = spec

    def speed_ratio(self, gear: int) -> float:
        """k(G) = i_G i_D / r_W: gearbox input speed [rad/s] per vehicle speed [m/s] (0 in neutral)."""
        return float(speed_ratio(self._p, gear))

    def torque_limits(self, engine_speed: float, speed: float) -> tuple[float, float]:
        """(T_min, T_max) [N m] of the engine / motor at ``engine_speed`` [rad/s] and vehicle speed [m/s]: ICE drag
        and full-load curves with the rev limit; BEV regen and drive limits (regen faded out below 1.5 m/s)."""
        t_min, t_max = torque_limits(self._p, self._tables, engine_speed, speed)
        return float(t_min), float(t_max)

    def source_torque(self, gear: int, wheel_torque: float, engine_speed: float, loss_factor: float = 1.0) -> float:
        """Source torque T_E [N m] that delivers ``wheel_torque`` [N m] at the wheels in ``gear`` (>= 1) at the
        gearbox input speed ``engine_speed`` [rad/s] (the exact inverse of :meth:`wheel_torque`)."""
        return float(inverse_wheel_torque(self._p, self._tables, gear, wheel_torque, engine_speed, loss_factor))

    def wheel_torque(self, gear: int, source_torque: float, input_speed: float, loss_factor: float = 1.0) -> float:
        """Wheel torque T_W [N m] of ``source_torque`` [N m] at gearbox input speed [rad/s] in ``gear`` (0: neutral,
        where ``input_speed`` is the differential's input speed and only its spin loss acts)."""
        return float(forward_wheel_torque(self._p, self._tables, gear, source_torque, input_speed, loss_factor)[0])

    def fuel_power(self, engine_speed: float, torque: float) -> float:
        """Fuel power [W] from the consumption map (0 at or below the drag curve: fuel cut)."""
        return float(fuel_power(self._p, self._tables, engine_speed, torque))

    def motor_electric_power(self, motor_speed: float, torque: float) -> float:
        """Electric power of the motor [W], T omega + loss map (positive: drawn from the battery)."""
        return float(motor_electric_power(self._p, self._tables, motor_speed, torque))

    def battery_current(self, terminal_power: float) -> float:
        """Battery current [A] for a terminal power [W] (P = V_oc I - R I^2; positive: discharge)."""
        return float(battery_current(self._p, terminal_power))

    def neutral_drag_force(self, speed) -> np.ndarray:
        """Drive-train drag [N] at the wheels with zero drive torque, warm oil, at ``speed`` [m/s] (scalar or array):
        ICE in neutral (differential spin loss), BEV with zero motor torque (single-speed gearbox + differential).
        Used for the coast-down road load."""
        spec = self.spec
        r = spec.tires.dynamic_radius
        out = []
        for v in np.atleast_1d(np.asarray(speed, dtype=float)):
            if spec.drivetrain.kind == "bev":
                t_w = self.wheel_torque(1, 0.0, self.speed_ratio(1) * v)
            else:
                t_w = self.wheel_torque(0, 0.0, spec.drivetrain.final_drive * v / r)
            out.append(-t_w / r)
        res = np.asarray(out)
        return res if np.ndim(speed) else res[0]


__all__ = ["Powertrain"]
