"""Pack a VehicleSpec into the parameter record and the drive-train tables of the jitted core (see ``layout.py``)."""

from __future__ import annotations

import numpy as np

from roadload.units import STANDARD_PRESSURE, STANDARD_TEMPERATURE
from roadload.vehicle import Curve, Map2D, VehicleSpec, VehicleSpecError

from .layout import (N_TABLES, PARAMS, T_DIFFLOSS, T_DRAG, T_FUEL, T_FULLLOAD, T_GBLOSS, T_MOTORLOSS, T_STEER,
                     Tables)

_DRIVEN = {"rear": 0.0, "front": 1.0, "all": 2.0}
_DUMMY_MAP = Map2D(x=[0.0, 1.0], y=[0.0, 1.0], values=[[0.0, 0.0], [0.0, 0.0]])
_DUMMY_CURVE = Curve(x=[0.0, 1.0], y=[0.0, 0.0])


class _TablePacker:
    def __init__(self) -> None:
        self.chunks: list[np.ndarray] = []
        self.size = 0
        self.ti = np.zeros((N_TABLES, 5), dtype=np.int64)

    def _add(self, arr) -> int:
        a = np.ascontiguousarray(np.asarray(arr, dtype=np.float64).ravel())
        off = self.size
        self.chunks.append(a)
        self.size += a.size
        return off

    def curve(self, k: int, c: Curve) -> None:
        ox = self._add(c.x)
        oy = self._add(c.y)
        self.ti[k] = (ox, len(c.x), oy, 0, 0)

    def map2(self, k: int, m: Map2D) -> None:
        ox = self._add(m.x)
        oy = self._add(m.y)
        ov = self._add(m.values)
        self.ti[k] = (ox, len(m.x), oy, len(m.y), ov)

    def result(self) -> Tables:
        return Tables(np.concatenate(self.chunks), self.ti)


def pack_vehicle(spec: VehicleSpec, dt: float = 0.01) -> tuple[np.ndarray, Tables]:
    """(parameter record, tables) of a vehicle spec: a 0-d PARAMS array with every vehicle parameter filled (effect,
    driver and run entries at neutral defaults) and the drive-train tables."""
    b, a, t, d, br = spec.body, spec.aero, spec.tires, spec.drivetrain, spec.brakes
    P = np.zeros((), PARAMS)
    values = {
        "dt": dt, "is_bev": 1.0 if d.kind == "bev" else 0.0, "driven_axle": _DRIVEN[d.driven_axle],
        "n_gears": d.n_gears, "mass_nominal": b.mass, "wheelbase": b.wheelbase, "cg_to_front": b.cg_to_front_axle,
        "cg_to_rear": b.cg_to_rear_axle, "yaw_inertia": b.yaw_inertia, "track_front": b.track_front,
        "track_rear": b.track_rear, "pitch_gradient": b.pitch_gradient, "roll_gradient": b.roll_gradient,
        "wheel_radius": t.dynamic_radius, "wheel_inertia_4": 4.0 * t.wheel_inertia,
        "rolling_f0": t.rolling_resistance_f0, "rolling_f1": t.rolling_resistance_f1,
        "rolling_f4": t.rolling_resistance_f4, "cornering_stiffness_front": t.cornering_stiffness_front,
        "cornering_stiffness_rear": t.cornering_stiffness_rear, "longitudinal_stiffness": t.longitudinal_stiffness,
        "toe_in": t.toe_in, "drag_coefficient": a.drag_coefficient, "frontal_area": a.frontal_area,
        "yaw_drag_factor": a.yaw_drag_factor, "final_drive": d.final_drive,
        "differential_inertia": d.differential_inertia, "clutch_inertia": d.clutch_inertia,
        "source_inertia": d.source_inertia, "oil_warm_temperature": d.oil_warm_temperature,
        "oil_cold_loss_factor": d.oil_cold_loss_factor, "oil_time_constant": d.oil_time_constant,
        "brake_area_front": br.front_area, "brake_area_rear": br.rear_area, "brake_radius_front": br.front_radius,
        "brake_radius_rear": br.rear_radius, "pad_friction": br.pad_friction, "brake_front_share": br.front_share,
        "brake_pressure_max": br.max_pressure, "disc_heat_capacity": br.disc_heat_capacity,
        "disc_cooling": br.disc_cooling, "disc_cooling_speed": br.disc_cooling_speed, "brake_time_constant": 0.03,
        "ambient_temperature": STANDARD_TEMPERATURE, "ambient_pressure": STANDARD_PRESSURE, "time_end": np.inf,
        "distance_end": np.inf, "steer_max": 0.6,
        **_source_values(d),
    }
    for name, value in values.items():
        P[name] = value
    for g, (ratio, inertia) in enumerate(zip(d.gear_ratios, d.gearbox_inertia)):
        P["gear_ratio"][g] = ratio
        P["gear_inertia"][g] = inertia
    return P, _pack_tables(spec)


def _source_values(d) -> dict[str, float]:
    """Engine and shift strategy (ICE) or motor and battery (BEV) parameters."""
    e, sh, m, bat = d.engine, d.shift, d.motor, d.battery
    if d.kind == "ice":
        if e is None or sh is None:
            raise VehicleSpecError("drivetrain.engine and drivetrain.shift: required for kind 'ice', got None")
        return {"idle_speed": e.idle_speed, "max_engine_speed": e.max_speed, "max_torque": max(e.full_load.y),
                "upshift_speed_low": sh.upshift_speed_low, "upshift_speed_high": sh.upshift_speed_high,
                "downshift_speed_low": sh.downshift_speed_low, "downshift_speed_high": sh.downshift_speed_high,
                "shift_interval": sh.min_interval, "sync_time_constant": sh.sync_time_constant,
                "max_slip_time": sh.max_slip_time, "launch_speed": sh.launch_speed,
                "lock_slip_speed": sh.lock_slip_speed}
    if m is None or bat is None:
        raise VehicleSpecError("drivetrain.motor and drivetrain.battery: required for kind 'bev', got None")
    return {"max_engine_speed": m.max_speed, "max_torque": m.max_torque, "max_power": m.max_power,
            "regen_torque_limit": m.regen_torque_limit, "regen_power_limit": m.regen_power_limit,
            "battery_capacity": bat.capacity, "battery_open_circuit_voltage": bat.open_circuit_voltage,
            "battery_resistance": bat.internal_resistance, "auxiliary_power": bat.auxiliary_power}


def _pack_tables(spec: VehicleSpec) -> Tables:
    """Full-load, drag and fuel curves / maps (ICE) or the motor loss map (BEV), differential and gearbox loss maps,
    the steering ratio curve."""
    d = spec.drivetrain
    e, m = d.engine, d.motor
    tp = _TablePacker()
    if e is not None and d.kind == "ice":
        tp.curve(T_FULLLOAD, e.full_load)
        tp.curve(T_DRAG, e.drag)
        tp.map2(T_FUEL, e.fuel_power)
        tp.map2(T_MOTORLOSS, _DUMMY_MAP)
    elif m is not None:
        tp.curve(T_FULLLOAD, _DUMMY_CURVE)
        tp.curve(T_DRAG, _DUMMY_CURVE)
        tp.map2(T_FUEL, _DUMMY_MAP)
        tp.map2(T_MOTORLOSS, m.loss_map)
    tp.map2(T_DIFFLOSS, d.differential_loss)
    tp.curve(T_STEER, Curve(spec.steering.steering_wheel_angle, spec.steering.wheel_angle))
    for g, loss_map in enumerate(d.gearbox_loss):
        tp.map2(T_GBLOSS + g, loss_map)
    return tp.result()
