"""The ``fastsim`` worlds: NREL's FASTSim 3 (Rust core, ``fastsim`` 3.1.0) drives its own vehicle models over
roadload's road profiles, and a logger of our own writes what it computed as 100 Hz CSV. Two variants:
``fastsim`` (the battery-electric Zoe below) and ``fastsim_conv`` (the conventional 2012 Ford Fusion: 130 kW engine
with FASTSim's power-ramp lag, transmission 0.875, friction brakes only; the logger adds a 6-speed gear schedule of
its own, engine speed and net engine torque = FASTSim's propulsion power / engine speed, brake pressures from the
friction-brake power; no battery, so the energy side is absent).

- Vehicle: the FASTSim resource ``2022_Renault_Zoe_ZE50_R135.yaml`` (battery-electric, 1600 kg, c_d 0.33,
  A 2.51 m², f_r 0.009, transmission efficiency 0.92, 100 kW motor with an efficiency-vs-power-fraction curve,
  250 W auxiliary power). The vehicle files ship inside the wheel (``Vehicle.list_resources()``); nothing is
  fetched at run time.
- Cycle: our own driver (:func:`.common.planned_speed`) on a road profile's speed limits, curves and stops, at
  0.1 s steps, with the profile's grade (FASTSim's climbing force is m g · grade, so we pass sin θ).
- Logger: speed [km/h], longitudinal acceleration incl. g sin θ [m/s2], motor torque [Nm] = motor mechanical power
  / motor speed (a fixed reduction ratio of 9.3 of our logger: FASTSim has no shaft speeds), motor speed [rpm],
  brake pressures [bar] from the friction-brake power P_trans,out - P_tractive (the Zoe regenerates every braking
  demand in FASTSim 3.1, so they read 0; FASTSim's own ``pwr_brake_watts`` of the conventional car is -P_tractive
  while driving and 0 while braking in 3.1.0, so it is not used), GNSS elevation [m],
  battery voltage [V] / current [A] from FASTSim's electrical and chemical power, ambient temperature [degC];
  step averages placed at the step mid-points, interpolated to 100 Hz, noise and quantisation added.
- Withheld effects are FASTSim parameter changes (mass, drag coefficient, rolling coefficient, auxiliary power,
  transmission efficiency) or logger faults (accelerometer bias, torque latency, torque-map band error).
- The matched roadload vehicle (:func:`matched_vehicle`) is calibrated from FASTSim's own steady-state output
  (its drag power is 0.977 · ½ · 1.2 kg/m³ · c_d A v³ for this resource: the YAML's c_d is not exactly what FASTSim
  drives).
"""

from __future__ import annotations

import copy
import functools
import math
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

import numpy as np
from roadload.units import KELVIN, STANDARD_PRESSURE, G, air_density
from roadload.vehicle import (
    AeroSpec,
    BatterySpec,
    BodySpec,
    BrakeSpec,
    ChannelSensorSpec,
    Curve,
    DrivetrainSpec,
    EngineSpec,
    Map2D,
    MotorSpec,
    SensorSpec,
    ShiftSpec,
    SteeringSpec,
    TireSpec,
    VehicleSpec,
)

from .common import (
    NONE,
    OUTSIDE,
    Column,
    Withheld,
    WorldError,
    delayed,
    planned_speed,
    quantise,
    resample_to_log,
    road,
    sensor,
    speed_trace,
    write_log,
)

STEP = 0.1                   # s, FASTSim time step
AMBIENT = 295.15             # K, FASTSim's default ambient air temperature
AIR_PRESSURE = STANDARD_PRESSURE
BATTERY_RESISTANCE = 0.08    # Ohm, the logger's battery model (U = U_oc - R I)
RPM = 2 * np.pi / 60
T_PEAK = 250.0               # N m, the conventional engine's peak torque (FASTSim gives power only)
# logger's friction-brake geometry (also the matched vehicles'): per-wheel piston area, radius, pad friction
BRAKE = {"front_area": 3.2e-3, "rear_area": 1.5e-3, "front_radius": 0.12, "rear_radius": 0.11,
         "pad_friction": 0.4, "front_share": 0.7}
TIME_HEADER = "Time [s]"

_COMMON_EFFECTS = (
    Withheld("payload", ("mass_offset",), {"mass_kg": 200.0}, "FASTSim vehicle mass +200 kg"),
    Withheld("drag_area", ("drag_area",), {"drag_coef_factor": 1.2}, "FASTSim drag coefficient x1.2"),
    Withheld("rolling_resistance", ("rolling_scale",), {"rr_coef_factor": 1.3},
             "FASTSim wheel rolling-resistance coefficient x1.3 (not one of the user's ten)"),
    Withheld("torque_scale", ("torque_scale", "drive_efficiency"), {"transmission_eff_factor": 0.95},
             "FASTSim transmission efficiency x0.95 (the motor / engine works 5 % harder for the same wheel power)"),
    Withheld("accel_bias", ("accel_bias",), {"bias_m_s2": 0.1}, "logger: accelerometer bias +0.1 m/s²"),
    Withheld("torque_latency", ("latency",), {"latency_s": 0.25}, "logger: torque signal 0.25 s late"),
    Withheld(OUTSIDE, (), {"offset_nm": 5.0, "low_kmh": 50.0, "high_kmh": 70.0},
             "logger: drive torque reads +5 N m between 50 and 70 km/h (outside the catalog)"),
    Withheld(NONE, (), {}, "nothing withheld"),
)
_AUX = Withheld("auxiliary_load", ("auxiliary_power", "logged_aux_power"), {"aux_power_w": 1500.0},
                "FASTSim base auxiliary power +1500 W")
_NOT_EXPRESSIBLE = {
    "wind": "FASTSim 3 has no wind input (its drag uses the vehicle speed only)",
    "tire_warmup": "FASTSim's rolling coefficient is one constant per vehicle (no tire temperature)",
    "cold_drivetrain": "the transmission efficiency is one constant (no oil temperature)",
    "cornering": "FASTSim is longitudinal only (no curvature, no lateral forces)",
}


@dataclass(frozen=True)
class Variant:
    """One FASTSim vehicle with its logger: resource, kind ('bev' | 'conv'), the logger's gear ratios and final
    drive (FASTSim is power-based: shaft speeds are the logger's), the matched spec's name and the driver's limits
    (acceleration [m/s²], power per mass [W/kg])."""

    world: str
    resource: str
    kind: str
    gears: tuple[float, ...]
    final_drive: float
    spec_name: str
    accel: float
    power_to_mass: float


BEV_VARIANT = Variant("fastsim", "2022_Renault_Zoe_ZE50_R135.yaml", "bev", (9.3,), 1.0, "fastsim_zoe", 1.5, 35.0)
CONV_VARIANT = Variant("fastsim_conv", "2012_Ford_Fusion.yaml", "conv", (4.58, 2.96, 1.91, 1.45, 1.00, 0.75), 3.07,
                       "fastsim_fusion", 1.2, 25.0)
RATIO = BEV_VARIANT.gears[0]


def _fastsim():
    try:
        import fastsim
    except ImportError as exc:   # pragma: no cover - depends on the environment
        raise WorldError(f"the fastsim world needs the 'fastsim' package (3.1): {exc}") from None
    return fastsim


@functools.lru_cache(maxsize=4)
def _resource(resource: str) -> dict:
    fs = _fastsim()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return fs.Vehicle.from_resource(resource).to_dict()


def base_vehicle_dict(variant: Variant = BEV_VARIANT) -> dict:
    """FASTSim's vehicle (resource shipped in the wheel) as a dict (a copy)."""
    return copy.deepcopy(_resource(variant.resource))


def _pt(d: dict) -> dict:
    return d["pt_type"]["BEV"] if "BEV" in d["pt_type"] else d["pt_type"]["Conv"]


def fastsim_vehicle(withheld: str = NONE, variant: Variant = BEV_VARIANT) -> dict:
    """The FASTSim vehicle dict with the withheld FASTSim-parameter effect applied."""
    d = base_vehicle_dict(variant)
    p = next((w.params for w in _COMMON_EFFECTS + (_AUX,) if w.name == withheld), {})
    if withheld == "payload":
        d["mass_kilograms"] = float(d["mass_kilograms"]) + p["mass_kg"]
    elif withheld == "drag_area":
        d["chassis"]["drag_coef"] *= p["drag_coef_factor"]
    elif withheld == "rolling_resistance":
        d["chassis"]["wheel_rr_coef"] *= p["rr_coef_factor"]
    elif withheld == "auxiliary_load":
        d["pwr_aux_base_watts"] = float(d["pwr_aux_base_watts"]) + p["aux_power_w"]
    elif withheld == "torque_scale":
        _pt(d)["transmission"]["eff_interp"] *= p["transmission_eff_factor"]
    return d


def run_fastsim(vehicle: dict, t: np.ndarray, v: np.ndarray, grade_sin: np.ndarray,
                initial_soc: float | None = None) -> dict[str, np.ndarray]:
    """FASTSim's SimDrive on the cycle (t [s], v [m/s], grade = sin θ); its histories (SI) by short names.
    ``source_mech``: motor mechanical power (BEV) or engine propulsion power (conventional) [W].
    initial_soc (BEV): the battery's state of charge at the start [-]; None: FASTSim's ``walk``, which starts at
    the battery's max_soc, where 3.1 cuts the charge power to nothing within seconds of regeneration and then
    refuses any braking the motor would regenerate (it has no friction-brake blend for a BEV)."""
    fs = _fastsim()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        vehicle = copy.deepcopy(vehicle)
        if initial_soc is not None:
            if "BEV" not in vehicle["pt_type"] or not (math.isfinite(initial_soc) and 0.0 < initial_soc < 1.0):
                raise WorldError(f"initial_soc: a battery-electric vehicle's state of charge in (0, 1), got "
                                 f"{initial_soc!r}")
            vehicle["pt_type"]["BEV"]["res"]["state"]["soc"] = float(initial_soc)
        veh = fs.Vehicle.from_dict(vehicle)
        veh.set_save_interval(1)
        cyc = fs.Cycle.from_dict({"time_seconds": t.tolist(), "speed_meters_per_second": v.tolist(),
                                  "grade": grade_sin.tolist(), "init_elev_meters": 0.0})
        params = fs.SimParams.default().to_dict()
        params["trace_miss_opts"] = "Allow"     # an under-powered case falls behind the trace (logged as driven)
        sd = fs.SimDrive(veh, cyc, fs.SimParams.from_dict(params))
        if initial_soc is None:
            sd.walk()
        else:
            sd.walk_once()  # walk() would reset the state of charge to max_soc
        df = sd.to_dataframe()
    h = "veh.history."
    bev = "BEV" in vehicle["pt_type"]
    b = "veh.pt_type.BEV." if bev else "veh.pt_type.Conv."
    out = {
        "speed": df[h + "speed_ach_meters_per_second"].to_numpy(float),
        "tractive": df[h + "pwr_tractive_watts"].to_numpy(float),
        "drag": df[h + "pwr_drag_watts"].to_numpy(float),
        "rolling": df[h + "pwr_rr_watts"].to_numpy(float),
        "ascent": df[h + "pwr_ascent_watts"].to_numpy(float),
        "accel": df[h + "pwr_accel_watts"].to_numpy(float),
        "wheel_inertia": df[h + "pwr_whl_inertia_watts"].to_numpy(float),
        "brake_fastsim": df[h + "pwr_brake_watts"].to_numpy(float),
        "air_density": df[h + "air_density_kilograms_per_cubic_meter"].to_numpy(float),
        "transmission_out": df[b + "transmission.history.pwr_out_watts"].to_numpy(float),
        "mass": df[h + "mass_kilograms"].to_numpy(float),
        "grade": df[h + "grade_curr"].to_numpy(float),
        "elevation": df[h + "elev_curr_meters"].to_numpy(float),
    }
    if bev:
        out["source_mech"] = (df[b + "em.history.pwr_mech_prop_out_watts"].to_numpy(float)
                              + df[b + "em.history.pwr_mech_dyn_brake_watts"].to_numpy(float))
        out["battery_electrical"] = df[b + "res.history.pwr_out_electrical_watts"].to_numpy(float)
        out["motor_electrical"] = (df[b + "em.history.pwr_elec_prop_in_watts"].to_numpy(float)
                                   - df[b + "em.history.pwr_elec_dyn_brake_watts"].to_numpy(float))
        out["soc"] = df[b + "res.history.soc"].to_numpy(float)
    else:
        out["source_mech"] = df[b + "fc.history.pwr_prop_watts"].to_numpy(float)
        out["fuel"] = df[b + "fc.history.pwr_fuel_watts"].to_numpy(float)
    # friction brakes take what the transmission does not deliver (FASTSim's pwr_brake is not used, see doc)
    out["brake"] = np.minimum(out["tractive"] - out["transmission_out"], 0.0)
    return out


@functools.lru_cache(maxsize=4)
def calibration(variant: Variant = BEV_VARIANT) -> dict[str, float]:
    """FASTSim's own road load, measured like a coast-down on its steady-state output: F = P_tractive / v at
    constant speeds on a flat road -> a + c v²; f_r0 = a / (m g), c_x A_V = 2 c / ρ (ρ of the logged ambient)."""
    veh = base_vehicle_dict(variant)
    speeds = np.array([5.0, 10.0, 15.0, 20.0, 25.0, 30.0, 35.0])
    knots_t, knots_v = [0.0], [0.0]
    for vs in speeds:
        knots_t += [knots_t[-1] + 20.0, knots_t[-1] + 40.0]
        knots_v += [vs, vs]
    t = np.arange(0.0, knots_t[-1] + STEP / 2, STEP)
    v = np.interp(t, knots_t, knots_v)
    out = run_fastsim(veh, t, v, np.zeros_like(t))
    f, vv = [], []
    for k in range(speeds.size):
        sel = (t > knots_t[2 * k + 1] + 5) & (t < knots_t[2 * k + 2] - 1)
        f.append(np.mean(out["tractive"][sel] / out["speed"][sel]))
        vv.append(float(np.mean(out["speed"][sel])))
    c, _, a = np.polyfit(vv, f, 2)
    m = float(veh["mass_kilograms"])
    rho = float(air_density(AMBIENT, AIR_PRESSURE))
    return {"mass": m, "f_r0": float(a / (m * G)), "drag_area": float(2 * c / rho), "a_N": float(a),
            "c_N_s2_m2": float(c)}


def _eff_curve(d: dict) -> tuple[np.ndarray, np.ndarray, float]:
    """(power fraction, efficiency, max power [W]) of the motor (BEV) or the engine (conventional)."""
    pt = _pt(d)
    if "em" in pt:
        data = pt["em"]["eff_interp_achieved"]["data"]
        p_max = float(pt["em"]["pwr_out_max_watts"])
    else:
        data = pt["fc"]["eff_interp_from_pwr_out"]["data"]
        p_max = float(pt["fc"]["pwr_out_max_watts"])
    return np.asarray(data["grid"][0]["data"], float), np.asarray(data["values"]["data"], float), p_max


def _motor_loss_map(d: dict) -> Map2D:
    """FASTSim's motor efficiency over the power fraction as a loss table P_loss(ω, T) [W] (motoring:
    P (1/η - 1), generating: |P| (1 - η), η at |P| / P_max)."""
    frac, eff, p_max = _eff_curve(d)
    speed = np.linspace(0.0, 1250.0, 26)
    torque = np.union1d(np.linspace(-300.0, 300.0, 25), [0.0])
    p = speed[:, None] * torque[None, :]
    eta = np.interp(np.abs(p) / p_max, frac, eff)
    loss = np.where(p >= 0, p * (1 / eta - 1), -p * (1 - eta))
    return Map2D(speed.tolist(), torque.tolist(), loss.round(2).tolist())


def _engine(d: dict) -> EngineSpec:
    """FASTSim's engine as a roadload EngineSpec: full load min(T_peak, P_max / ω), no drag torque (FASTSim's
    engine delivers 0 when the wheels brake), fuel power P / η(P / P_max)."""
    frac, eff, p_max = _eff_curve(d)
    speed = np.array([0, 600, 750, 1000, 1500, 2000, 2500, 3000, 3500, 4000, 4500, 5000, 5500, 6000, 6500]) * RPM
    t_peak = T_PEAK
    full = np.minimum(t_peak, p_max / np.maximum(speed, 1.0))
    full[0] = 80.0
    torque = np.linspace(-50.0, 300.0, 15)
    p = np.clip(speed[:, None] * torque[None, :], 0.0, None)
    fuel = p / np.interp(p / p_max, frac, eff)
    return EngineSpec(idle_speed=750 * RPM, max_speed=6500 * RPM, full_load=Curve(speed.tolist(), full.tolist()),
                      drag=Curve(speed.tolist(), [0.0] * speed.size),
                      fuel_power=Map2D(speed.tolist(), torque.tolist(), fuel.round(2).tolist()), inertia=1e-3)


def _loss_table(ratio: float, efficiency: float, torque_max: float, speed_max: float) -> Map2D:
    tq = np.union1d(np.linspace(-torque_max, torque_max, 7), [0.0])
    sp = np.linspace(0.0, speed_max, 5)
    values = (1 - efficiency) * np.abs(tq)[:, None] * ratio + 0.0 * sp[None, :]
    return Map2D(tq.tolist(), sp.tolist(), values.round(5).tolist())


def matched_vehicle(variant: Variant = BEV_VARIANT) -> VehicleSpec:
    """The roadload vehicle spec matched to FASTSim's base vehicle (what the diagnosis' sim side knows): mass,
    road load from :func:`calibration`, transmission efficiency, motor losses / engine map, aux power, the
    logger's ratios and brakes; sensor model like the logger's."""
    d = base_vehicle_dict(variant)
    cal = calibration(variant)
    ch = d["chassis"]
    pt = _pt(d)
    r = float(ch["wheel_radius_meters"])
    eta_tr = float(pt["transmission"]["eff_interp"])
    gears = list(variant.gears)
    engine: EngineSpec | None = None
    shift: ShiftSpec | None = None
    motor: MotorSpec | None = None
    battery: BatterySpec | None = None
    kind: Literal["ice", "bev"]
    if variant.kind == "bev":
        _, _, p_max = _eff_curve(d)
        motor = MotorSpec(max_torque=245.0, max_power=p_max, max_speed=1190.0, regen_torque_limit=245.0,
                          regen_power_limit=p_max, inertia=1e-4, loss_map=_motor_loss_map(d))
        battery = BatterySpec(capacity=float(pt["res"]["energy_capacity_joules"]), open_circuit_voltage=380.0,
                              internal_resistance=0.0, auxiliary_power=float(d["pwr_aux_base_watts"]),
                              initial_soc=0.9)
        kind = "bev"
    else:
        engine = _engine(d)
        shift = ShiftSpec(upshift_speed_low=2300 * RPM, upshift_speed_high=4500 * RPM,
                          downshift_speed_low=1200 * RPM, downshift_speed_high=2500 * RPM, launch_speed=1300 * RPM)
        kind = "ice"
    dt = DrivetrainSpec(kind=kind, driven_axle="front", gear_ratios=gears, final_drive=variant.final_drive,
                        gearbox_inertia=[0.0] * len(gears), clutch_inertia=0.0, differential_inertia=0.0,
                        gearbox_loss=[_loss_table(g, eta_tr, 400.0, 1250.0) for g in gears],
                        differential_loss=_loss_table(variant.final_drive, 1.0, 3000.0, 300.0),
                        engine=engine, motor=motor, battery=battery, shift=shift)
    wb = float(ch["wheel_base_meters"])
    front = float(ch["drive_axle_weight_frac"])
    sw = np.radians(np.linspace(-540.0, 540.0, 13))
    channels = {
        "vehicle_speed": ChannelSensorSpec(0.03 / 3.6, 0.0, 0.01 / 3.6, 0.0),
        "accel_x": ChannelSensorSpec(0.05, 0.0, 0.001, 0.0),
        "drive_torque": ChannelSensorSpec(1.0, 0.0, 0.1, 0.0),
        "engine_speed": ChannelSensorSpec(2.0 * RPM, 0.0, RPM, 0.0),
        "brake_pressure_front": ChannelSensorSpec(0.0, 0.0, 1e3, 0.0),
        "brake_pressure_rear": ChannelSensorSpec(0.0, 0.0, 1e3, 0.0),
        "elevation": ChannelSensorSpec(0.3, 0.0, 0.1, 0.0),
        "ambient_temperature": ChannelSensorSpec(0.05, 0.0, 0.1, 0.0),
    }
    if kind == "bev":
        channels["battery_voltage"] = ChannelSensorSpec(0.2, 0.0, 0.1, 0.0)
        channels["battery_current"] = ChannelSensorSpec(0.3, 0.0, 0.1, 0.0)
    else:
        channels["gear"] = ChannelSensorSpec(0.0, 0.0, 0.0, 0.0)
    return VehicleSpec(
        name=variant.spec_name,
        description=f"roadload spec matched to FASTSim 3's {d['name']} resource (calibrated road load, "
                    f"transmission {eta_tr:g}, FASTSim efficiency curve, logger ratios {gears} x "
                    f"{variant.final_drive:g})",
        body=BodySpec(mass=cal["mass"], wheelbase=wb, cg_to_front_axle=wb * (1 - front),
                      cg_height=float(ch["cg_height_meters"]), yaw_inertia=2200.0,
                      pitch_gradient=0.0, roll_gradient=0.0),   # FASTSim has no body motion
        aero=AeroSpec(drag_coefficient=cal["drag_area"] / float(ch["frontal_area_square_meters"]),
                      frontal_area=float(ch["frontal_area_square_meters"]), yaw_drag_factor=0.0),
        tires=TireSpec(dynamic_radius=r, rolling_resistance_f0=cal["f_r0"], rolling_resistance_f1=0.0,
                       rolling_resistance_f4=0.0, cornering_stiffness_front=9.0e4,
                       cornering_stiffness_rear=1.0e5, wheel_inertia=float(ch["wheel_inertia_kilogram_square_meters"]),
                       toe_in=0.0),
        drivetrain=dt,
        brakes=BrakeSpec(**BRAKE),
        steering=SteeringSpec(sw.tolist(), (sw / 14.0).tolist()),
        sensors=SensorSpec(100.0, channels, 0.0, 0.0, 0.0),
    )


def gear_schedule(speed: np.ndarray, power: np.ndarray, variant: Variant, dt: float) -> np.ndarray:
    """The logger-side ECU's gear (1..n, 0 at standstill): upshift above 2300 rpm (+1000 rpm at full power) unless
    the next gear would need over 80 % of the peak torque, downshift below 1200 rpm (+800 rpm at full power) or when
    the engine would need over 90 % of its peak torque, at most one shift per second."""
    r_w = float(base_vehicle_dict(variant)["chassis"]["wheel_radius_meters"])
    _, _, p_max = _eff_curve(base_vehicle_dict(variant))
    g = np.zeros(speed.size, dtype=int)
    gear, last = 1, -10.0
    ratios = np.asarray(variant.gears) * variant.final_drive
    for k in range(speed.size):
        if speed[k] < 0.5:
            gear = 1
            g[k] = 0
            continue
        load = min(max(power[k], 0.0) / p_max, 1.0)
        w = speed[k] / r_w * ratios[gear - 1]
        lugging = power[k] / max(w, 1.0) > 0.9 * T_PEAK
        if k * dt - last > 1.0:
            if gear < ratios.size and w > (2300 + 1000 * load) * RPM \
                    and power[k] / max(w * ratios[gear] / ratios[gear - 1], 1.0) < 0.8 * T_PEAK:
                gear += 1
                last = k * dt
            elif gear > 1 and (w < (1200 + 800 * load) * RPM
                               or (lugging and w * ratios[gear - 2] / ratios[gear - 1] < 5500 * RPM)):
                gear -= 1
                last = k * dt
        g[k] = gear
    return g


class FastsimWorld:
    """One FASTSim variant as a test world (the interface of :mod:`.cases`)."""

    TIME_HEADER = TIME_HEADER
    NOMINAL_AMBIENT = AMBIENT       # K, the logged ambient (FASTSim's own air density is constant)

    def __init__(self, variant: Variant):
        self.variant = variant
        effects = _COMMON_EFFECTS if variant.kind == "conv" else _COMMON_EFFECTS[:3] + (_AUX,) + _COMMON_EFFECTS[3:]
        self.EFFECTS = {w.name: w for w in effects}
        self.NOT_EXPRESSIBLE = dict(_NOT_EXPRESSIBLE)
        if variant.kind == "conv":
            self.NOT_EXPRESSIBLE["auxiliary_load"] = ("no traction battery: the energy side needs battery voltage "
                                                      "and current, and the logged engine torque is net of the "
                                                      "alternator load (eq. 2.17's T_E)")
        drive = "MotorTorque [Nm]" if variant.kind == "bev" else "EngineTorque [Nm]"
        speed = "MotorSpeed [rpm]" if variant.kind == "bev" else "EngineSpeed [rpm]"
        cols = [Column("Speed [km/h]", "vehicle_speed", "km/h", 2, required=True),
                Column("LongAcc [m/s2]", "accel_x", "m/s^2", 3, required=True),
                Column(drive, "drive_torque", "N*m", 1, required=True),
                Column(speed, "engine_speed", "rpm", 0),
                Column("BrakePressFront [bar]", "brake_pressure_front", "bar", 2),
                Column("BrakePressRear [bar]", "brake_pressure_rear", "bar", 2),
                Column("GNSS_Alt [m]", "elevation", "m", 1)]
        if variant.kind == "bev":
            cols += [Column("HV_Voltage [V]", "battery_voltage", "V", 1),
                     Column("HV_Current [A]", "battery_current", "A", 1)]
        else:
            cols += [Column("Gear [-]", "gear", "1", 0, resample="hold")]
        cols += [Column("AmbientTemp [degC]", "ambient_temperature", "degC", 1)]
        self.COLUMNS = tuple(cols)

    def matched_vehicle(self) -> VehicleSpec:
        return matched_vehicle(self.variant)

    def simulate_trip(self, road_name: str, road_seed: int, rng: np.random.Generator, duration: float,
                      withheld: str = NONE) -> dict[str, Any]:
        return simulate_trip(road_name, road_seed, rng, duration, withheld, self.variant)

    def write_trip(self, path: Path, trip: dict[str, Any]) -> Path:
        return write_log(path, trip["t"], self.COLUMNS, trip["logged"], TIME_HEADER)


def simulate_trip(road_name: str, road_seed: int, rng: np.random.Generator, duration: float,
                  withheld: str = NONE, variant: Variant = BEV_VARIANT) -> dict[str, Any]:
    """One trip: the driver's cycle on the road, FASTSim on it, the logger's 100 Hz channels (in the CSV
    columns' units, see :class:`FastsimWorld`)."""
    veh = fastsim_vehicle(withheld, variant)
    prof = road(road_name, road_seed, duration)
    m = float(veh["mass_kilograms"])
    m0 = float(base_vehicle_dict(variant)["mass_kilograms"])
    v_plan = planned_speed(prof, rng, accel=variant.accel, power_to_mass=variant.power_to_mass, decel=1.8,
                           brake_power_to_mass=45.0 * m0 / m)
    t, v, s = speed_trace(prof, v_plan, duration, STEP, rng)
    theta = np.interp(s, prof.distance, prof.grade)
    out = run_fastsim(veh, t, v, np.sin(theta))
    va = out["speed"]
    r_w = float(veh["chassis"]["wheel_radius_meters"])
    # step i covers [t_{i-1}, t_i]: averages at the mid-points
    tm = t[1:] - STEP / 2
    v_avg = 0.5 * (va[1:] + va[:-1])
    a_mid = np.diff(va) / STEP
    theta_ach = np.arcsin(np.clip(out["grade"], -0.5, 0.5))     # the road FASTSim drove (grade = sin θ)
    tl, speed = resample_to_log(t, va, duration)

    def mid(x):
        return np.interp(tl, tm, x)

    if variant.kind == "bev":
        gear = np.ones(tl.size, dtype=int)
    else:
        gear = gear_schedule(speed, mid(out["source_mech"][1:]), variant, 1.0 / 100.0)
    ratio = np.where(gear > 0, np.asarray((variant.gears[0],) + variant.gears)[gear], variant.gears[0]) \
        * variant.final_drive
    omega = speed / r_w * ratio
    if variant.kind == "conv":      # engine at idle when declutched, launch speed while the clutch slips
        omega = np.where(gear == 0, 750 * RPM, np.maximum(omega, np.where(speed < 3.0, 1300 * RPM, 750 * RPM)))
    with np.errstate(divide="ignore", invalid="ignore"):
        f_brake = np.where(v_avg > 0.1, -out["brake"][1:] / np.maximum(v_avg, 0.1), 0.0)
    power = mid(out["source_mech"][1:])
    torque = np.where(omega > 1.0, power / np.maximum(omega, 1.0), 0.0)
    a_true = mid(a_mid)
    theta_l = np.interp(tl, t, theta_ach)
    fb = np.clip(mid(f_brake), 0.0, None)
    p_front = fb * BRAKE["front_share"] * r_w / (2 * BRAKE["front_area"] * BRAKE["front_radius"]
                                                 * BRAKE["pad_friction"])
    p_rear = fb * (1 - BRAKE["front_share"]) * r_w / (2 * BRAKE["rear_area"] * BRAKE["rear_radius"]
                                                      * BRAKE["pad_friction"])
    elevation = np.interp(tl, t, out["elevation"])
    bias = 0.1 if withheld == "accel_bias" else 0.0
    if withheld == "torque_latency":
        torque = delayed(tl, torque, 0.25)
    if withheld == OUTSIDE:
        kmh = speed * 3.6
        torque = torque + np.where((kmh >= 50.0) & (kmh < 70.0), 5.0, 0.0)
    logged = {
        "vehicle_speed": np.clip(sensor(rng, speed * 3.6, 0.03, 0.01), 0.0, None),
        "accel_x": sensor(rng, a_true + G * np.sin(theta_l), 0.05, 0.001, bias),
        "drive_torque": sensor(rng, torque, 1.0, 0.1),
        "engine_speed": sensor(rng, omega / RPM, 2.0, 1.0),
        "brake_pressure_front": quantise(p_front / 1e5, 0.01),
        "brake_pressure_rear": quantise(p_rear / 1e5, 0.01),
        "elevation": sensor(rng, elevation, 0.3, 0.1),
        "ambient_temperature": sensor(rng, np.full(tl.shape, AMBIENT - KELVIN), 0.05, 0.1),
        "gear": gear.astype(float),
    }
    if variant.kind == "bev":
        soc = np.interp(tl, t, out["soc"])
        logged["battery_voltage"], logged["battery_current"] = (
            sensor(rng, x, n, 0.1) for x, n in zip(battery_terminal(mid(out["battery_electrical"][1:]),
                                                                    330.0 + 70.0 * soc), (0.2, 0.3)))
    truth = {"t": tl, "speed": speed, "acceleration": a_true, "grade": theta_l, "drive_torque": torque,
             "tractive_force": mid(out["tractive"][1:] / np.maximum(v_avg, 0.1)), "brake_force": fb,
             "motor_speed": omega, "gear": gear, "mass": m}
    return {"t": tl, "logged": logged, "truth": truth, "fastsim": out, "cycle_t": t, "cycle_v": v}


def battery_terminal(power: np.ndarray, v_oc: np.ndarray, resistance: float = BATTERY_RESISTANCE
                     ) -> tuple[np.ndarray, np.ndarray]:
    """The logger's battery: terminal voltage U = U_oc - R I and current I [A] with U I = P (FASTSim's electrical
    power at the terminals [W]), I = (U_oc - sqrt(U_oc² - 4 R P)) / (2 R)."""
    disc = np.maximum(v_oc ** 2 - 4 * resistance * power, 1.0)
    current = (v_oc - np.sqrt(disc)) / (2 * resistance)
    return v_oc - resistance * current, current


BEV = FastsimWorld(BEV_VARIANT)
CONV = FastsimWorld(CONV_VARIANT)
EFFECTS = BEV.EFFECTS
NOT_EXPRESSIBLE = BEV.NOT_EXPRESSIBLE
COLUMNS = BEV.COLUMNS
