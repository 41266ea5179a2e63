"""Pack a VehicleSpec into the flat parameter / table arrays of the jitted core (see ``layout.py``)."""

from __future__ import annotations

import numpy as np

from roadload.units import STANDARD_PRESSURE, STANDARD_TEMPERATURE
from roadload.vehicle import Curve, Map2D, VehicleSpec, VehicleSpecError

from .layout import (
    N_P_TOTAL, N_TABLES, P_AB_F, P_AB_R, P_AREA, P_AUX_P, P_BAT_CAP, P_BAT_R, P_BAT_VOC, P_BRAKE_SHARE, P_BRAKE_TAU,
    P_CF, P_CR, P_CW, P_CX_SLIP, P_DISC_C, P_DISC_H, P_DISC_HV, P_DN_HI, P_DN_LO, P_DRIVEN, P_DT, P_FR0, P_FR1,
    P_FR4, P_ID, P_IDLE, P_IGEAR0, P_IW4, P_IZ, P_I_CLUTCH, P_I_DIFF, P_I_SOURCE, P_KIND_BEV, P_L, P_LAUNCH, P_LF,
    P_LOCK_SLIP, P_LR, P_MASS0, P_MAX_POWER, P_MAX_SLIP, P_MAX_SPEED, P_MAX_TORQUE, P_MU0, P_N_GEARS,
    P_OIL_COLD_FACTOR, P_OIL_TAU, P_OIL_WARM, P_PITCH_GRAD, P_P_AMB, P_P_MAX, P_RATIO0, P_RB_F, P_RB_R, P_REGEN_P,
    P_REGEN_T, P_ROLL_GRAD, P_RW, P_SHIFT_MIN, P_STEER_MAX, P_SYNC_TAU, P_S_END, P_TOE, P_TRACK_F, P_TRACK_R,
    P_T_AMB, P_T_END, P_UP_HI, P_UP_LO, P_YAW_DRAG, T_DIFFLOSS, T_DRAG, T_FUEL, T_FULLLOAD, T_GBLOSS, T_MOTORLOSS,
    T_STEER,
)

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

    def result(self) -> tuple[np.ndarray, np.ndarray]:
        return np.concatenate(self.chunks), self.ti


def pack_vehicle(spec: VehicleSpec, dt: float = 0.01) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(P, tabs, ti) with all vehicle parameters filled; effect / driver / run entries at neutral defaults."""
    b, a, t, d, br = spec.body, spec.aero, spec.tires, spec.drivetrain, spec.brakes
    P = np.zeros(N_P_TOTAL)
    P[P_DT] = dt
    P[P_KIND_BEV] = 1.0 if d.kind == "bev" else 0.0
    P[P_DRIVEN] = _DRIVEN[d.driven_axle]
    P[P_N_GEARS] = d.n_gears
    P[P_MASS0] = b.mass
    P[P_L] = b.wheelbase
    P[P_LF] = b.cg_to_front_axle
    P[P_LR] = b.cg_to_rear_axle
    P[P_IZ] = b.yaw_inertia
    P[P_TRACK_F] = b.track_front
    P[P_TRACK_R] = b.track_rear
    P[P_PITCH_GRAD] = b.pitch_gradient
    P[P_ROLL_GRAD] = b.roll_gradient
    P[P_RW] = t.dynamic_radius
    P[P_IW4] = 4.0 * t.wheel_inertia
    P[P_FR0] = t.rolling_resistance_f0
    P[P_FR1] = t.rolling_resistance_f1
    P[P_FR4] = t.rolling_resistance_f4
    P[P_CF] = t.cornering_stiffness_front
    P[P_CR] = t.cornering_stiffness_rear
    P[P_CX_SLIP] = t.longitudinal_stiffness
    P[P_TOE] = t.toe_in
    P[P_CW] = a.drag_coefficient
    P[P_AREA] = a.frontal_area
    P[P_YAW_DRAG] = a.yaw_drag_factor
    P[P_ID] = d.final_drive
    P[P_I_DIFF] = d.differential_inertia
    P[P_I_CLUTCH] = d.clutch_inertia
    P[P_I_SOURCE] = d.source_inertia
    for g, (ratio, inertia) in enumerate(zip(d.gear_ratios, d.gearbox_inertia)):
        P[P_RATIO0 + g] = ratio
        P[P_IGEAR0 + g] = inertia
    e, sh, m, bat = d.engine, d.shift, d.motor, d.battery
    if d.kind == "ice":
        if e is None or sh is None:
            raise VehicleSpecError("drivetrain.engine and drivetrain.shift: required for kind 'ice', got None")
        P[P_IDLE] = e.idle_speed
        P[P_MAX_SPEED] = e.max_speed
        P[P_MAX_TORQUE] = max(e.full_load.y)
        P[P_UP_LO], P[P_UP_HI] = sh.upshift_speed_low, sh.upshift_speed_high
        P[P_DN_LO], P[P_DN_HI] = sh.downshift_speed_low, sh.downshift_speed_high
        P[P_SHIFT_MIN] = sh.min_interval
        P[P_SYNC_TAU] = sh.sync_time_constant
        P[P_MAX_SLIP] = sh.max_slip_time
        P[P_LAUNCH] = sh.launch_speed
        P[P_LOCK_SLIP] = sh.lock_slip_speed
    else:
        if m is None or bat is None:
            raise VehicleSpecError("drivetrain.motor and drivetrain.battery: required for kind 'bev', got None")
        P[P_MAX_SPEED] = m.max_speed
        P[P_MAX_TORQUE] = m.max_torque
        P[P_MAX_POWER] = m.max_power
        P[P_REGEN_T] = m.regen_torque_limit
        P[P_REGEN_P] = m.regen_power_limit
        P[P_BAT_CAP] = bat.capacity
        P[P_BAT_VOC] = bat.open_circuit_voltage
        P[P_BAT_R] = bat.internal_resistance
        P[P_AUX_P] = bat.auxiliary_power
    P[P_OIL_WARM] = d.oil_warm_temperature
    P[P_OIL_COLD_FACTOR] = d.oil_cold_loss_factor
    P[P_OIL_TAU] = d.oil_time_constant
    P[P_AB_F], P[P_AB_R] = br.front_area, br.rear_area
    P[P_RB_F], P[P_RB_R] = br.front_radius, br.rear_radius
    P[P_MU0] = br.pad_friction
    P[P_BRAKE_SHARE] = br.front_share
    P[P_P_MAX] = br.max_pressure
    P[P_DISC_C] = br.disc_heat_capacity
    P[P_DISC_H] = br.disc_cooling
    P[P_DISC_HV] = br.disc_cooling_speed
    P[P_BRAKE_TAU] = 0.03
    P[P_T_AMB] = STANDARD_TEMPERATURE
    P[P_P_AMB] = STANDARD_PRESSURE
    P[P_T_END] = np.inf
    P[P_S_END] = np.inf
    P[P_STEER_MAX] = 0.6

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
    tabs, ti = tp.result()
    return P, tabs, ti
