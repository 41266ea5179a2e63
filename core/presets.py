"""Vehicle presets: ``get_preset(name)`` for "gt_rwd", "gt_awd" (the text's two grand tourers, section 5.1) and
"bmw_i3" (the battery-electric car of the shared real-data set) and "truck_40t" (a 40 t long-haul
tractor-semitrailer, :func:`truck_spec` for other gross masses).

Values are published-like or typical, not manufacturer data: the two grand tourers follow section 5.1 (rear-drive
228 kW V6 and all-wheel-drive 419 kW V8, 7-speed dual-clutch gearbox, ~1.9 t / ~2.1 t); the i3 uses published
figures (c_w 0.29, A 2.38 m^2, 155/70 R19 tires with r_W ~ 0.35 m, 125 kW / 250 N m motor, single gear 9.665,
~1.4 t with driver) and a regen torque limit of 87 N m, where the real i3 logs floor.
Loss maps are generated from simple physical models (mesh efficiency + speed-dependent spin loss; Willans-type
engine fuel map; copper/iron/windage motor losses) and stored as tables in the spec.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from roadload.registry import did_you_mean
from roadload.vehicle import (AeroSpec, BatterySpec, BodySpec, BrakeSpec, ChannelSensorSpec, Curve, DrivetrainSpec,
                              EngineSpec, Map2D, MotorSpec, SensorSpec, ShiftSpec, SteeringSpec, TireSpec,
                              VehicleSpec, VehicleSpecError)

RPM = 2.0 * np.pi / 60.0


def gear_loss_map(ratio: float, efficiency: float, spin_torque: float, spin_slope: float,
                  torque_axis, speed_axis) -> Map2D:
    """Loss torque at the output [N m] of a gear stage: (1 - eta) |T_in| i + (c0 + c1 omega_in) i."""
    torque_axis = np.union1d(np.asarray(torque_axis, float), [0.0])  # the |T| kink on a grid point
    t = torque_axis[:, None]
    w = np.asarray(speed_axis, float)[None, :]
    values = (1.0 - efficiency) * np.abs(t) * ratio + (spin_torque + spin_slope * w) * ratio
    return Map2D(list(map(float, torque_axis)), list(map(float, speed_axis)), values.round(4).tolist())


def willans_fuel_map(speed_axis, torque_axis, drag: Curve, peak_efficiency: float) -> Map2D:
    """Fuel power [W]: (T + T_fric(omega)) omega / eta_i(omega, T), T_fric = -drag(omega); zero below drag."""
    w = np.asarray(speed_axis, float)[:, None]
    t = np.asarray(torque_axis, float)[None, :]
    t_fric = -np.interp(w, drag.x, drag.y)
    indicated = np.maximum(t + t_fric, 0.0)
    eta = peak_efficiency * (1.0 - 0.25 * np.exp(-indicated / 80.0)) * (1.0 - 0.1 * ((w - 300.0) / 400.0) ** 2)
    values = np.where(t > -t_fric, indicated * w / eta, 0.0)
    return Map2D(list(map(float, speed_axis)), list(map(float, torque_axis)), values.round(2).tolist())


def motor_loss_map(speed_axis, torque_axis, k_copper: float, k_iron: float, k_windage: float,
                   p_const: float) -> Map2D:
    """Motor loss [W] = k_cu T^2 + k_fe omega + k_w omega^2 + P_0."""
    w = np.asarray(speed_axis, float)[:, None]
    t = np.asarray(torque_axis, float)[None, :]
    values = k_copper * t ** 2 + k_iron * w + k_windage * w ** 2 + p_const + 0.0 * t
    return Map2D(list(map(float, speed_axis)), list(map(float, torque_axis)), values.round(2).tolist())


def steering_table(center_ratio: float, lock_ratio: float, max_wheel_angle_deg: float = 540.0) -> SteeringSpec:
    """Variable steering ratio: center_ratio at straight ahead, lock_ratio at +-max_wheel_angle_deg of the wheel."""
    ds = np.linspace(-np.radians(max_wheel_angle_deg), np.radians(max_wheel_angle_deg), 37)
    x = np.abs(ds) / np.radians(max_wheel_angle_deg)
    ratio = center_ratio + (lock_ratio - center_ratio) * x ** 2
    dw = ds / ratio
    return SteeringSpec(ds.round(6).tolist(), dw.round(8).tolist())


def default_sensors(kind: str, with_elevation: bool = False) -> SensorSpec:
    """A CAN sensor set with typical noise / resolution / latency (SI units)."""
    ch = {
        "wheel_speed_fl": ChannelSensorSpec(0.03, 0.0, 0.02, 0.02, 5.0),
        "wheel_speed_fr": ChannelSensorSpec(0.03, 0.0, 0.02, 0.02, 5.0),
        "wheel_speed_rl": ChannelSensorSpec(0.03, 0.0, 0.02, 0.02, 5.0),
        "wheel_speed_rr": ChannelSensorSpec(0.03, 0.0, 0.02, 0.02, 5.0),
        "vehicle_speed": ChannelSensorSpec(0.02, 0.0, 0.01, 0.03, 3.0),
        "accel_x": ChannelSensorSpec(0.08, 0.0, 0.02, 0.02, 2.0),
        "accel_y": ChannelSensorSpec(0.08, 0.0, 0.02, 0.02, 2.0),
        "yaw_rate": ChannelSensorSpec(0.003, 0.0, 0.001, 0.02, 0.1),
        "steering_wheel_angle": ChannelSensorSpec(0.002, 0.0, 0.0017, 0.02, 0.3),
        "drive_torque": ChannelSensorSpec(2.0, 0.0, 0.5, 0.03, 80.0),
        "engine_speed": ChannelSensorSpec(0.5, 0.0, 0.25, 0.01, 50.0),
        "gear": ChannelSensorSpec(0.0, 0.0, 0.0, 0.02, 0.0),
        "clutch": ChannelSensorSpec(0.0, 0.0, 0.0, 0.02, 0.0),
        "brake_pressure_front": ChannelSensorSpec(2e3, 0.0, 1e4, 0.02, 5e5),
        "brake_pressure_rear": ChannelSensorSpec(2e3, 0.0, 1e4, 0.02, 5e5),
        "ambient_temperature": ChannelSensorSpec(0.05, 0.0, 0.5, 1.0, 5.0),
    }
    if kind == "bev":
        ch["battery_voltage"] = ChannelSensorSpec(0.2, 0.0, 0.1, 0.05, 20.0)
        ch["battery_current"] = ChannelSensorSpec(0.5, 0.0, 0.1, 0.05, 50.0)
    if with_elevation:
        ch["elevation"] = ChannelSensorSpec(0.3, 0.0, 1.0, 1.0, 20.0)
    return SensorSpec(100.0, ch, drive_torque_gain_error=0.02, drive_torque_offset=-2.0, speed_scale_error=0.003)


def _ice_drivetrain(full_load_rpm, full_load_nm, drag_c0, drag_c1, peak_eff, final_drive, driven, diff_eff,
                    diff_spin, engine_inertia, diff_inertia, max_rpm) -> DrivetrainSpec:
    ratios = [5.97, 3.31, 2.08, 1.42, 1.00, 0.84, 0.68]  # 7-speed dual-clutch gearbox
    full = Curve([float(x * RPM) for x in full_load_rpm], list(map(float, full_load_nm)))
    speed_axis = np.array([0, 400, 600, 800, 1000, 1500, 2000, 2500, 3000, 3500, 4000, 4500, 5000, 5500, 6000,
                           6500, 7000, 7500]) * RPM
    drag = Curve([float(x) for x in speed_axis], [float(-(drag_c0 + drag_c1 * x)) for x in speed_axis])
    t_max = max(full_load_nm)
    torque_axis = np.linspace(-100.0, t_max + 100.0, 25)
    fuel = willans_fuel_map(speed_axis, torque_axis, drag, peak_eff)
    gb_torque = np.linspace(-300.0, t_max + 200.0, 9)
    gb_speed = [0.0, 50.0, 100.0, 200.0, 300.0, 400.0, 500.0, 600.0, 800.0]
    gb_loss = [gear_loss_map(i, 0.985 if i == 1.0 else 0.975, 0.8, 0.0015, gb_torque, gb_speed) for i in ratios]
    d_torque = np.linspace(-300.0 * ratios[0], (t_max + 200.0) * ratios[0], 9)
    d_speed = [0.0, 25.0, 50.0, 100.0, 150.0, 200.0, 300.0, 400.0, 600.0, 900.0]
    diff = gear_loss_map(final_drive, diff_eff, diff_spin, 0.003, d_torque, d_speed)
    engine = EngineSpec(idle_speed=750 * RPM, max_speed=max_rpm * RPM, full_load=full, drag=drag, fuel_power=fuel,
                        inertia=engine_inertia)
    shift = ShiftSpec(upshift_speed_low=2000 * RPM, upshift_speed_high=6200 * RPM, downshift_speed_low=1000 * RPM,
                      downshift_speed_high=3000 * RPM, min_interval=1.0, sync_time_constant=0.08,
                      max_slip_time=1.5, launch_speed=1300 * RPM, lock_slip_speed=5.0)
    return DrivetrainSpec(kind="ice", driven_axle=driven, gear_ratios=ratios, final_drive=final_drive,
                          gearbox_inertia=[0.015, 0.012, 0.010, 0.009, 0.008, 0.008, 0.007], clutch_inertia=0.05,
                          differential_inertia=diff_inertia, gearbox_loss=gb_loss, differential_loss=diff,
                          engine=engine, shift=shift, oil_warm_temperature=363.15, oil_cold_loss_factor=1.6,
                          oil_time_constant=1200.0)


def _gt_rwd() -> VehicleSpec:
    dt = _ice_drivetrain([600, 1000, 1500, 2000, 2500, 3000, 3750, 4500, 5000, 5500, 6300, 6700, 7000],
                         [180, 250, 300, 340, 365, 385, 400, 395, 385, 372, 345, 320, 250],
                         drag_c0=15.0, drag_c1=0.065, peak_eff=0.40, final_drive=3.09, driven="rear",
                         diff_eff=0.97, diff_spin=0.6, engine_inertia=0.20, diff_inertia=0.08, max_rpm=6800)
    return VehicleSpec(
        name="gt_rwd",
        description="rear-drive grand tourer, 228 kW 3.6 l V6, 7-speed dual-clutch (like the text's test vehicle)",
        body=BodySpec(mass=1900.0, wheelbase=2.92, cg_to_front_axle=1.40, cg_height=0.52, track_front=1.66,
                      track_rear=1.65, yaw_inertia=3300.0, pitch_gradient=0.004, roll_gradient=0.006),
        aero=AeroSpec(drag_coefficient=0.29, frontal_area=2.36, yaw_drag_factor=0.3),
        tires=TireSpec(dynamic_radius=0.34, rolling_resistance_f0=0.009, rolling_resistance_f1=5.0e-5,
                       rolling_resistance_f4=5.0e-10, cornering_stiffness_front=1.4e5,
                       cornering_stiffness_rear=1.9e5, longitudinal_stiffness=9.0e4, wheel_inertia=1.3,
                       toe_in=0.0015),
        drivetrain=dt,
        brakes=BrakeSpec(front_area=3.4e-3, rear_area=2.0e-3, front_radius=0.15, rear_radius=0.14,
                         pad_friction=0.4, front_share=0.65, max_pressure=1.6e7),
        steering=steering_table(15.5, 12.5),
        sensors=default_sensors("ice"),
    )


def _gt_awd() -> VehicleSpec:
    """The rear-drive grand tourer with the V8 twin-turbo, all-wheel drive and the heavier body, tires and brakes
    (only the values that differ from ``gt_rwd``)."""
    rwd = _gt_rwd()
    dt = _ice_drivetrain([600, 1000, 1500, 2250, 4500, 5000, 5500, 6000, 6500, 7000],
                         [250, 400, 560, 750, 750, 720, 690, 660, 600, 450],
                         drag_c0=20.0, drag_c1=0.08, peak_eff=0.38, final_drive=3.0, driven="all",
                         diff_eff=0.96, diff_spin=1.0, engine_inertia=0.25, diff_inertia=0.12, max_rpm=7000)
    return dataclasses.replace(
        rwd, name="gt_awd",
        description="all-wheel-drive grand tourer, 419 kW 4.8 l V8 twin-turbo, 7-speed dual-clutch",
        body=dataclasses.replace(rwd.body, mass=2100.0, cg_to_front_axle=1.38, cg_height=0.53, track_rear=1.66,
                                 yaw_inertia=3700.0, pitch_gradient=0.0035, roll_gradient=0.005),
        aero=dataclasses.replace(rwd.aero, drag_coefficient=0.30, frontal_area=2.40),
        tires=dataclasses.replace(rwd.tires, dynamic_radius=0.35, rolling_resistance_f0=0.0105,
                                  rolling_resistance_f4=6.0e-10, cornering_stiffness_front=1.6e5,
                                  cornering_stiffness_rear=2.2e5, longitudinal_stiffness=1.0e5, wheel_inertia=1.5),
        drivetrain=dt,
        brakes=dataclasses.replace(rwd.brakes, front_area=3.8e-3, rear_area=2.2e-3, front_radius=0.16,
                                   rear_radius=0.15, pad_friction=0.42),
    )


def _bmw_i3() -> VehicleSpec:
    ratio = 9.665
    speed_axis = np.linspace(0.0, 1250.0, 26)
    torque_axis = np.linspace(-250.0, 250.0, 21)
    motor = MotorSpec(max_torque=250.0, max_power=125e3, max_speed=11400 * RPM, regen_torque_limit=87.0,
                      regen_power_limit=50e3, inertia=0.035,
                      loss_map=motor_loss_map(speed_axis, torque_axis, 0.12, 1.5, 2.5e-3, 150.0))
    gb_torque = np.linspace(-300.0, 300.0, 7)
    gb_speed = [0.0, 100.0, 200.0, 400.0, 600.0, 800.0, 1000.0, 1250.0]
    gb = gear_loss_map(ratio, 0.975, 0.15, 0.0004, gb_torque, gb_speed)
    diff = gear_loss_map(1.0, 0.995, 0.5, 0.002, np.linspace(-3000.0, 3000.0, 7), [0.0, 50.0, 100.0, 150.0])
    dt = DrivetrainSpec(kind="bev", driven_axle="rear", gear_ratios=[ratio], final_drive=1.0,
                        gearbox_inertia=[0.005], clutch_inertia=0.0, differential_inertia=0.02,
                        gearbox_loss=[gb], differential_loss=diff, motor=motor,
                        battery=BatterySpec(capacity=27.2e3 * 3600.0, open_circuit_voltage=360.0,
                                            internal_resistance=0.1, auxiliary_power=300.0, initial_soc=0.9),
                        oil_warm_temperature=343.15, oil_cold_loss_factor=1.4, oil_time_constant=1500.0)
    return VehicleSpec(
        name="bmw_i3",
        description="battery-electric city car like the BMW i3 (single gear 9.665, 125 kW / 250 N m, ~1.4 t)",
        body=BodySpec(mass=1400.0, wheelbase=2.57, cg_to_front_axle=1.36, cg_height=0.55, track_front=1.571,
                      track_rear=1.577, yaw_inertia=2000.0, pitch_gradient=0.005, roll_gradient=0.007),
        aero=AeroSpec(drag_coefficient=0.29, frontal_area=2.38, yaw_drag_factor=0.3),
        tires=TireSpec(dynamic_radius=0.35, rolling_resistance_f0=0.0085, rolling_resistance_f1=3.0e-5,
                       rolling_resistance_f4=4.0e-10, cornering_stiffness_front=0.9e5,
                       cornering_stiffness_rear=1.1e5, longitudinal_stiffness=6.0e4, wheel_inertia=0.9,
                       toe_in=0.0015),
        drivetrain=dt,
        brakes=BrakeSpec(front_area=3.45e-3, rear_area=1.6e-3, front_radius=0.12, rear_radius=0.11,
                         pad_friction=0.4, front_share=0.7, max_pressure=1.6e7),
        steering=steering_table(14.4, 13.0),
        sensors=default_sensors("bev", with_elevation=True),
    )


TRUCK_RATIOS = [16.69, 12.92, 9.93, 7.67, 5.90, 4.57, 3.66, 2.83, 2.17, 1.68, 1.29, 1.00]  # 12-speed AMT
TRUCK_MASS_RANGE = (15_000.0, 40_000.0)  # gross vehicle mass [kg]: empty tractor-semitrailer .. 40 t (EU)
TRUCK_NOMINAL_MASS = 27_500.0  # half load: what a fleet operator's abc model assumes [kg]


def truck_fuel_map(speed_axis, torque_axis, friction: Curve, peak_indicated_efficiency: float) -> Map2D:
    """Diesel fuel power [W]: (T + T_fric(omega)) omega / eta_i(omega, T) (Willans form), T_fric = -friction(omega);
    eta_i peaks around 1300 rpm and falls at low indicated torque; zero at or below the friction curve."""
    w = np.asarray(speed_axis, float)[:, None]
    t = np.asarray(torque_axis, float)[None, :]
    t_fric = -np.interp(w, friction.x, friction.y)
    indicated = np.maximum(t + t_fric, 0.0)
    eta = (peak_indicated_efficiency * (1.0 - 0.2 * np.exp(-indicated / 400.0))
           * (1.0 - 0.12 * ((w - 136.0) / 110.0) ** 2))
    values = np.where(t > -t_fric, indicated * w / np.maximum(eta, 0.05), 0.0)
    return Map2D(list(map(float, speed_axis)), list(map(float, torque_axis)), values.round(2).tolist())


def truck_spec(gross_mass: float = 40_000.0) -> VehicleSpec:
    """Long-haul tractor-semitrailer (4x2 tractor, 3-axle trailer) at ``gross_mass`` [kg] (15-40 t).

    Typical published-like values, not one manufacturer's: 13 l diesel, 330 kW / 2300 N m (1000-1400 rpm), 12-speed
    automated manual gearbox (16.69 .. 1.00) and axle 2.53 (85 km/h at ~1170 rpm in 12th), 315/70 R22.5 tyres
    (r_W 0.49 m, f_r0 0.0055: low-rolling-resistance long-haul tyres), c_w A = 0.57 x 10 m^2 = 5.7 m^2. The
    equivalent rotating inertia of all 12 wheel positions is lumped into the simulator's four wheels
    (4 I_W = 200 kg m^2). Engine brake + hydraulic retarder: modelled as the engine's drag (motoring) curve, i.e.
    the braking torque the drive-train can put on the wheels in fuel cut (the simulator's regen-capacity path of
    an ICE): friction torque plus up to 2400 N m of combined engine-brake/retarder torque at 1800 rpm (~450 kW);
    the fuel map uses the friction part only. Sensors: the car's CAN set with the drive-torque offset and noise
    scaled by the engine size (10x: -20 N m offset, +2 % gain error).
    """
    lo, hi = TRUCK_MASS_RANGE
    if not lo <= gross_mass <= hi:
        raise VehicleSpecError(f"truck gross_mass: {gross_mass} kg outside {lo:.0f}..{hi:.0f} kg")
    ratios = TRUCK_RATIOS
    final_drive = 2.53
    full_load_rpm = [600, 800, 1000, 1400, 1600, 1800, 1900, 2100]
    full_load_nm = [1300, 1900, 2300, 2300, 2100, 1800, 1650, 900]
    full = Curve([float(x * RPM) for x in full_load_rpm], list(map(float, full_load_nm)))
    speed_axis = np.array([0, 400, 500, 600, 800, 1000, 1200, 1400, 1600, 1800, 2000, 2100, 2300]) * RPM
    friction = Curve([float(x) for x in speed_axis], [float(-(60.0 + 0.55 * x)) for x in speed_axis])
    # engine brake (decompression) + retarder, ramping in above 700 rpm, 2400 N m at 1800 rpm and above
    brake = np.clip((speed_axis / RPM - 700.0) / 1100.0, 0.0, 1.0) * 2400.0
    drag = Curve([float(x) for x in speed_axis], [float(f - b) for f, b in zip(friction.y, brake)])
    torque_axis = np.linspace(-400.0, 2600.0, 31)
    fuel = truck_fuel_map(speed_axis, torque_axis, friction, 0.49)
    gb_torque = np.linspace(-3000.0, 2800.0, 9)
    gb_speed = [0.0, 50.0, 100.0, 150.0, 200.0, 250.0]
    gb_loss = [gear_loss_map(i, 0.99 if i == 1.0 else 0.98, 3.0, 0.01, gb_torque, gb_speed) for i in ratios]
    d_torque = np.linspace(-3000.0 * ratios[0], 2800.0 * ratios[0], 9)
    d_speed = [0.0, 25.0, 50.0, 100.0, 150.0, 200.0, 250.0]
    diff = gear_loss_map(final_drive, 0.975, 6.0, 0.02, d_torque, d_speed)
    engine = EngineSpec(idle_speed=600 * RPM, max_speed=2100 * RPM, full_load=full, drag=drag, fuel_power=fuel,
                        inertia=3.5)
    shift = ShiftSpec(upshift_speed_low=1150 * RPM, upshift_speed_high=1750 * RPM, downshift_speed_low=850 * RPM,
                      downshift_speed_high=1250 * RPM, min_interval=1.5, sync_time_constant=0.25,
                      max_slip_time=2.5, launch_speed=900 * RPM, lock_slip_speed=5.0)
    drivetrain = DrivetrainSpec(kind="ice", driven_axle="rear", gear_ratios=list(ratios), final_drive=final_drive,
                                gearbox_inertia=[0.25] * len(ratios), clutch_inertia=1.5, differential_inertia=1.0,
                                gearbox_loss=gb_loss, differential_loss=diff, engine=engine, shift=shift,
                                oil_warm_temperature=353.15, oil_cold_loss_factor=1.5, oil_time_constant=2400.0)
    sensors = default_sensors("ice", with_elevation=True)
    sensors.channels["drive_torque"] = ChannelSensorSpec(20.0, 0.0, 5.0, 0.03, 800.0)
    sensors.drive_torque_offset = -20.0
    yaw = gross_mass * 16.5 ** 2 / 12.0
    return VehicleSpec(
        name="truck_40t" if gross_mass == 40_000.0 else f"truck_{gross_mass / 1000:.4g}t",
        description=f"long-haul tractor-semitrailer, {gross_mass / 1000:.4g} t gross, 330 kW 13 l diesel, "
                    "12-speed AMT, engine brake + retarder",
        body=BodySpec(mass=float(gross_mass), wheelbase=6.5, cg_to_front_axle=3.6, cg_height=1.6, track_front=2.05,
                      track_rear=1.85, yaw_inertia=float(yaw), pitch_gradient=0.002, roll_gradient=0.02),
        aero=AeroSpec(drag_coefficient=0.57, frontal_area=10.0, yaw_drag_factor=0.6),
        tires=TireSpec(dynamic_radius=0.49, rolling_resistance_f0=0.0055, rolling_resistance_f1=1.0e-5,
                       rolling_resistance_f4=0.0, cornering_stiffness_front=4.0e5,
                       cornering_stiffness_rear=1.6e6, longitudinal_stiffness=1.2e6, wheel_inertia=50.0,
                       toe_in=0.001),
        drivetrain=drivetrain,
        brakes=BrakeSpec(front_area=0.05, rear_area=0.05, front_radius=0.2, rear_radius=0.2, pad_friction=0.4,
                         front_share=0.4, max_pressure=1.0e7, disc_heat_capacity=60000.0, disc_cooling=60.0),
        steering=steering_table(20.0, 18.0),
        sensors=sensors,
    )


def _truck_40t() -> VehicleSpec:
    return truck_spec(40_000.0)


_PRESETS = {"gt_rwd": _gt_rwd, "gt_awd": _gt_awd, "bmw_i3": _bmw_i3, "truck_40t": _truck_40t}
_CACHE: dict[str, dict] = {}
PRESETS = tuple(_PRESETS)


def get_preset(name: str) -> VehicleSpec:
    """A fresh copy of a preset vehicle spec; unknown names raise VehicleSpecError listing the presets."""
    if name not in _PRESETS:
        raise VehicleSpecError(f"unknown vehicle preset {name!r}{did_you_mean(name, _PRESETS)}; presets: "
                               f"{', '.join(_PRESETS)}")
    if name not in _CACHE:
        _CACHE[name] = _PRESETS[name]().to_dict()
    # validating the cached plain form builds a fresh, independent spec (faster than a deep copy of the parts)
    return VehicleSpec.from_dict(_CACHE[name])
