"""The channel catalogue: one place that names every Trip channel, its SI unit and meaning.

Measured channels are what a vehicle's CAN bus (or a logger) delivers; truth channels exist only
for simulated trips and are stored apart so no estimator reads them by accident.
Importers and the simulator must use these names; unknown names are allowed (extra signals) but
must carry a unit.
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Channel:
    name: str
    unit: str
    description: str


_MEASURED = [
    Channel("t", "s", "time since trip start"),
    Channel("wheel_speed_fl", "rad/s", "front-left wheel angular speed (ABS sensor)"),
    Channel("wheel_speed_fr", "rad/s", "front-right wheel angular speed"),
    Channel("wheel_speed_rl", "rad/s", "rear-left wheel angular speed"),
    Channel("wheel_speed_rr", "rad/s", "rear-right wheel angular speed"),
    Channel("vehicle_speed", "m/s", "ESP vehicle speed v_V (section 5.2.2)"),
    Channel("accel_x", "m/s^2", "body-fixed longitudinal accelerometer, includes g*sin(theta) (eq. 4.4/5.2)"),
    Channel("accel_y", "m/s^2", "body-fixed lateral accelerometer, includes gravity of bank/roll"),
    Channel("yaw_rate", "rad/s", "yaw rate, positive counter-clockwise (left turn)"),
    Channel("steering_wheel_angle", "rad", "steering-wheel angle delta_S, positive left"),
    Channel("drive_torque", "N*m", "engine / motor shaft torque T_E from the engine model (with model error)"),
    Channel("engine_speed", "rad/s", "engine / motor shaft speed"),
    Channel("gear", "1", "engaged gear G (0 = neutral / clutch open)"),
    Channel("clutch", "1", "clutch state: 1 engaged, 0 open, between = slipping"),
    Channel("brake_pressure_front", "Pa", "front axle brake pressure p_B"),
    Channel("brake_pressure_rear", "Pa", "rear axle brake pressure p_B"),
    Channel("ambient_temperature", "K", "ambient air temperature T_a"),
    Channel("rim_torque", "N*m", "sum of rim torques T_R, where a log provides it (e.g. from motor torque)"),
    Channel("elevation", "m", "GNSS / map elevation"),
    Channel("latitude", "deg", "GNSS latitude"),
    Channel("longitude", "deg", "GNSS longitude"),
    Channel("heading", "rad", "GNSS course over ground"),
    Channel("gnss_speed", "m/s", "GNSS speed over ground"),
    Channel("battery_voltage", "V", "traction battery voltage"),
    Channel("battery_current", "A", "traction battery current, positive = discharge"),
    Channel("accelerator_pedal", "1", "accelerator pedal position 0..1"),
    Channel("heating_power", "W", "cabin heater / auxiliary power"),
    Channel("distance", "m", "travelled distance from a log's odometer or integrated speed"),
    # derived or logger channels of real logs (roadload.io)
    Channel("grade", "rad", "road gradient angle theta derived from elevation smoothed over distance (real logs)"),
    Channel("curvature", "1/m", "road curvature 1/r from yaw rate or heading rate over speed, positive left"),
    Channel("pitch", "rad", "vehicle pitch angle from a GNSS/IMU unit, positive nose up"),
    Channel("roll", "rad", "vehicle roll angle from a GNSS/IMU unit"),
    Channel("engine_torque_fraction", "1", "engine torque as a fraction of an (unlogged) reference torque (OBD-II)"),
    Channel("throttle_position", "1", "throttle valve position 0..1 (OBD-II)"),
    Channel("ambient_pressure", "Pa", "ambient (barometric) air pressure p_a"),
    Channel("battery_temperature", "K", "traction battery temperature"),
    Channel("state_of_charge", "1", "traction battery state of charge 0..1"),
    Channel("brake_pedal", "1", "brake pedal switch / position 0..1"),
    Channel("regen_braking", "1", "regenerative braking active 0/1"),
]

_TRUTH = [
    Channel("t", "s", "time since trip start"),
    Channel("position", "m", "distance travelled along the road s"),
    Channel("speed", "m/s", "true longitudinal speed v_V"),
    Channel("acceleration", "m/s^2", "true dv/dt"),
    Channel("tractive_force", "N", "true vehicle tractive force F_xV (eq. 2.16b)"),
    Channel("rim_torque", "N*m", "true sum of rim torques T_R (eq. 2.17)"),
    Channel("mass", "kg", "true vehicle mass m_V incl. payload"),
    Channel("rolling_resistance_coefficient", "1", "true f_r(v) (eq. 2.10)"),
    Channel("drag_area", "m^2", "true c_x*A_V"),
    Channel("air_density", "kg/m^3", "rho_a = p_a/(R_a T_a)"),
    Channel("grade", "rad", "gradient angle theta"),
    Channel("curvature", "1/m", "road curvature 1/r, positive left"),
    Channel("bank", "rad", "road bank angle"),
    Channel("wind_speed", "m/s", "wind speed v_w"),
    Channel("wind_angle", "rad", "wind angle psi_w (0 = tailwind along x_V, eq. 2.8)"),
    Channel("cornering_stiffness", "N/rad", "cornering stiffness per axle c_y"),
    # simulator truth beyond the lumped parameters (roadload.envs)
    Channel("rolling_resistance_f0", "1", "current f_r0 incl. warm-up / winter / wet effects (eq. 2.10)"),
    Channel("rolling_resistance_f1", "s/m", "current f_r1 (eq. 2.10)"),
    Channel("rolling_resistance_f4", "s^4/m^4", "current f_r4 (eq. 2.10)"),
    Channel("rolling_resistance_force", "N", "rolling resistance F_Wr (eq. 2.9)"),
    Channel("aero_force", "N", "longitudinal aerodynamic resistance F_xa (eq. 2.7)"),
    Channel("climbing_force", "N", "climbing force F_cl (eq. 2.5)"),
    Channel("cornering_resistance", "N", "cornering + toe-in resistance F_Wc + F_Wt (eq. 2.13)"),
    Channel("brake_force", "N", "friction brake force at the wheels sum(T_B)/r_W"),
    Channel("cornering_stiffness_front", "N/rad", "front axle cornering stiffness X_12 (eq. 2.12)"),
    Channel("cornering_stiffness_rear", "N/rad", "rear axle cornering stiffness X_34 (eq. 2.12)"),
    Channel("path_curvature", "1/m", "curvature of the driven path psi_dot / v, positive left"),
    Channel("lateral_acceleration", "m/s^2", "kinematic lateral acceleration of the CG"),
    Channel("yaw_rate", "rad/s", "true yaw rate"),
    Channel("side_slip_angle", "rad", "vehicle side slip angle beta_V"),
    Channel("wheel_steer_angle", "rad", "front wheel steer angle delta_W12"),
    Channel("specific_force_x", "m/s^2", "error-free body-fixed longitudinal accelerometer reading"),
    Channel("specific_force_y", "m/s^2", "error-free body-fixed lateral accelerometer reading"),
    Channel("engine_torque", "N*m", "true engine / motor torque T_E"),
    Channel("engine_speed", "rad/s", "true engine / motor speed"),
    Channel("gear", "1", "engaged gear G (0 = neutral)"),
    Channel("clutch", "1", "clutch state: 1 locked, 0.5 slipping, 0 open"),
    Channel("brake_pressure_front", "Pa", "true front brake pressure"),
    Channel("brake_pressure_rear", "Pa", "true rear brake pressure"),
    Channel("brake_friction_coefficient", "1", "brake pad friction X_B"),
    Channel("brake_disc_temperature", "K", "lumped brake disc temperature"),
    Channel("oil_temperature", "K", "drive-train oil temperature"),
    Channel("drivetrain_loss_factor", "1", "multiplier of the drive-train loss maps from oil temperature"),
    Channel("source_power", "W", "fuel power (ICE) or battery chemical power V_oc I (BEV)"),
    Channel("source_energy", "J", "cumulative fuel / battery energy since the start"),
    Channel("ambient_temperature", "K", "ambient air temperature T_a"),
    Channel("air_pressure", "Pa", "ambient air pressure p_a"),
    Channel("elevation", "m", "road elevation (integrated grade)"),
    Channel("heading", "rad", "vehicle heading"),
    Channel("wheel_speed_fl", "rad/s", "true front-left wheel speed"),
    Channel("wheel_speed_fr", "rad/s", "true front-right wheel speed"),
    Channel("wheel_speed_rl", "rad/s", "true rear-left wheel speed"),
    Channel("wheel_speed_rr", "rad/s", "true rear-right wheel speed"),
    Channel("battery_voltage", "V", "battery terminal voltage"),
    Channel("battery_current", "A", "battery current, positive = discharge"),
    Channel("state_of_charge", "1", "battery state of charge"),
    Channel("drag_area_factor", "1", "c_x A_V relative to nominal (windows, sunroof, roof box)"),
]

MEASURED: dict[str, Channel] = {c.name: c for c in _MEASURED}
TRUTH: dict[str, Channel] = {c.name: c for c in _TRUTH}


def unit_of(name: str, truth: bool = False) -> str | None:
    """SI unit of a catalogued channel, or None for a channel the catalogue does not know."""
    table = TRUTH if truth else MEASURED
    return table[name].unit if name in table else None
