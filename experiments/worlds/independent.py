"""The ``independent`` world: a longitudinal + lateral vehicle model written for the test from chapter 2 of the
reference text, sharing no code with ``roadload.envs``: its own equations, driver, drive-train, brakes, battery
and logger.

Physics (SI, one numba-compiled loop at 100 Hz, semi-implicit Euler):

- climbing F_cl = m g sin θ (eq. 2.5); acceleration with the rotating parts' reduced mass
  (m + (4 I_W + i² I_M) / r_W²) v̇ (eq. 2.6 + 2.17);
- aerodynamics F_xa = ρ_a/2 c_x A v_a |v_a| with the air approach velocity v_a = v + w cos(ψ - ψ_w) of a
  wind fixed in the world frame (eq. 2.7/2.8), ρ_a = p_a / (R_a T_a) of a drifting ambient temperature;
- rolling F_Wr = m g cos θ (f_r0 + f_r1 v + f_r4 v⁴) (eq. 2.9/2.10);
- cornering F_Wc = m² v⁴ κ² (l_34² / X_12 + l_12² / X_34) / l² (eq. 2.14, r_12 = r_34 = r), κ of the road plus
  lane changes; steering from the single-track steady state δ_W = κ (l + EG v²), EG = m/l (l_34/X_12 - l_12/X_34);
- drive-train: wheel torque i η T_M - i T_0 in traction, i T_M / η - i T_0 in regeneration (one reduction i,
  mesh efficiency η, drag torque T_0 at the motor side); motor torque follows the demand with 50 ms lag, limited
  by torque and power (motoring / regenerating); motor losses k_cu T² + k_fe ω + P_0; battery U = U_oc(soc) - R I;
- friction brakes T_B = p_B A_B r_B X_B per wheel (section 2.7), two wheels per axle, hydraulic lag 40 ms.

Driver: its own speed plan (:func:`.common.planned_speed`), a look-ahead speed controller with the driver's own
force estimate, regeneration first and the friction brake on top in steps (pedal held, re-set in 5 bar steps at
most every 0.6 s), occasional brake taps on fast roads, lane changes (3.5 m over 4 s) on country roads and
motorways.

Logger quirks: elevation from GNSS rounded to whole metres, battery voltage and current (discharge negative, as
the BMS sends it) instead of power, raw un-smoothed brake pressures in bar, an ambient temperature drifting over
the trip (read through a slow sensor, 0.5 K steps), speed in km/h, steering-wheel angle and yaw rate in degrees.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

from roadload.jitcache import cached_njit
import numpy as np
from roadload.units import KELVIN, R_AIR, STANDARD_PRESSURE, G
from roadload.vehicle import (
    AeroSpec,
    BatterySpec,
    BodySpec,
    BrakeSpec,
    ChannelSensorSpec,
    DrivetrainSpec,
    Map2D,
    MotorSpec,
    SensorSpec,
    SteeringSpec,
    TireSpec,
    VehicleSpec,
)

from .common import (
    NONE,
    OUTSIDE,
    Column,
    Withheld,
    _ou,
    delayed,
    planned_speed,
    quantise,
    road,
    sensor,
    write_log,
)

DT = 0.01
PITCH_GRADIENT = 0.004     # rad per m/s², body pitch under longitudinal acceleration
AIR_PRESSURE = STANDARD_PRESSURE
#: the world's driver's own rounded air density in its force feed-forward [kg/m^3] (a driver's estimate, not the
#: world's air: that follows from AIR_PRESSURE and the ambient temperature)
DRIVER_AIR_DENSITY = 1.2
AMBIENT_START_C = (2.0, 14.0)     # °C, a trip's initial ambient temperature is drawn uniformly from this range
AMBIENT_DRIFT_K = (-3.0, 4.0)     # K, its linear drift over the trip, drawn uniformly
# the world's nominal ambient [K]: the mean over trips and time of T_a(t) = T_0 + drift t / duration (+ zero-mean
# noise); the matched sim config runs at it, so the sim's own trips see the world's air density (eq. 2.8)
NOMINAL_AMBIENT = KELVIN + sum(AMBIENT_START_C) / 2 + sum(AMBIENT_DRIFT_K) / 4


@dataclass(frozen=True)
class IndependentVehicle:
    """The world's vehicle in its own terms (SI): mass, geometry (l_12 CG to front axle), axle cornering
    stiffness X_12/X_34 [N/rad], rolling f_r0/f_r1/f_r4, c_x A [m²], r_W [m], I_W per wheel, motor (ratio i, η,
    drag torque T_0 [N m], rotor inertia, limits, loss coefficients), battery (U_oc = u0 + u1 soc, R, capacity
    [J], aux [W]), brakes (areas, radii, pad friction X_B, front share), steering ratio."""

    mass: float = 1750.0
    wheelbase: float = 2.70
    l12: float = 1.25
    x12: float = 1.1e5
    x34: float = 1.3e5
    f_r0: float = 0.0095
    f_r1: float = 4.0e-5
    f_r4: float = 3.0e-10
    drag_area: float = 0.644
    r_w: float = 0.33
    i_w: float = 1.1
    ratio: float = 8.5
    eta: float = 0.96
    t_drag: float = 0.6
    i_m: float = 0.04
    t_max: float = 300.0
    p_max: float = 130e3
    t_regen: float = 120.0
    p_regen: float = 60e3
    k_cu: float = 0.10
    k_fe: float = 1.2
    p_0: float = 150.0
    u0: float = 320.0
    u1: float = 80.0
    r_bat: float = 0.09
    capacity: float = 64e3 * 3600.0
    aux: float = 400.0
    a_front: float = 3.4e-3
    a_rear: float = 1.7e-3
    r_front: float = 0.13
    r_rear: float = 0.12
    pad: float = 0.38
    front_share: float = 0.68
    steering_ratio: float = 15.0

    @property
    def l34(self) -> float:
        return self.wheelbase - self.l12

    def understeer_gradient(self) -> float:
        """EG = m / l (l_34 / X_12 - l_12 / X_34) [rad s²/m]."""
        return self.mass / self.wheelbase * (self.l34 / self.x12 - self.l12 / self.x34)

    def cornering_factor(self) -> float:
        """F_Wc / (v⁴ κ²) = m² (l_34² / X_12 + l_12² / X_34) / l² [kg² rad/N] (eq. 2.14)."""
        return self.mass ** 2 * (self.l34 ** 2 / self.x12 + self.l12 ** 2 / self.x34) / self.wheelbase ** 2

    def brake_gain(self) -> float:
        """F_B per pressure with the front share applied [N/Pa] at p_front = p, p_rear = p (2 wheels per axle)."""
        return 2 * (self.a_front * self.r_front + self.a_rear * self.r_rear) * self.pad / self.r_w


BASE = IndependentVehicle()

EFFECTS: dict[str, Withheld] = {w.name: w for w in (
    Withheld("wind", ("wind", "wind_world"), {"speed_m_s": 6.0, "from_heading_rad": 0.0},
             "wind 6 m/s fixed in the world, from the trip's initial heading (a headwind at the start)"),
    Withheld("payload", ("mass_offset",), {"mass_kg": 200.0}, "two passengers and luggage, +200 kg"),
    Withheld("tire_warmup", ("tire_warmup",), {"cold_factor": 1.8, "distance_m": 5000.0},
             "cold tires: f_r x (1 + 0.8 exp(-s / 5 km))"),
    Withheld("cold_drivetrain", ("drivetrain_oil",), {"cold_loss_factor": 2.0, "tau_s": 900.0},
             "cold gear oil: mesh loss (1 - η) and drag T_0 x (1 + exp(-t / 900 s))"),
    Withheld("accel_bias", ("accel_bias",), {"bias_m_s2": 0.1}, "accelerometer reads +0.1 m/s²"),
    Withheld("cornering", ("cornering",), {"stiffness_factor": 0.7}, "winter tires: X_12, X_34 x 0.7"),
    Withheld("auxiliary_load", ("auxiliary_power", "logged_aux_power"), {"power_w": 1500.0},
             "cabin heater +1500 W on the battery (not logged)"),
    Withheld("torque_scale", ("torque_scale", "drive_efficiency"), {"gain": 1.05},
             "inverter's torque estimate reads 5 % high"),
    Withheld("torque_latency", ("latency",), {"latency_s": 0.25}, "torque signal 0.25 s late on the bus"),
    Withheld("drag_area", ("drag_area",), {"factor": 1.25}, "roof box: c_x A x 1.25"),
    Withheld(OUTSIDE, (), {"offset_nm": 5.0, "low_kmh": 50.0, "high_kmh": 70.0},
             "torque estimate +5 N m between 50 and 70 km/h (outside the catalog)"),
    Withheld(NONE, (), {}, "nothing withheld"),
)}
NOT_EXPRESSIBLE: dict[str, str] = {}

COLUMNS = (
    Column("Vref [km/h]", "vehicle_speed", "km/h", 2, required=True),
    Column("AccLong [m/s2]", "accel_x", "m/s^2", 2, required=True),
    Column("TqMot [Nm]", "drive_torque", "N*m", 2, required=True),
    Column("nMot [rpm]", "engine_speed", "rpm", 0),
    Column("pBrkF [bar]", "brake_pressure_front", "bar", 1),
    Column("pBrkR [bar]", "brake_pressure_rear", "bar", 1),
    Column("StWhlAng [deg]", "steering_wheel_angle", "deg", 1),
    Column("YawRate [deg/s]", "yaw_rate", "deg/s", 2),
    Column("GNSS_Alt [m]", "elevation", "m", 0),
    Column("U_HV [V]", "battery_voltage", "V", 1),
    Column("T_amb [degC]", "ambient_temperature", "degC", 1),
)
CURRENT = Column("I_HV [A]", "battery_current", "A", 1)
TIME_HEADER = "t [s]"


@cached_njit
def _interp_uniform(x, ds, y):
    k = x / ds
    i = int(k)
    if i >= y.size - 1:
        return y[-1]
    if i < 0:
        return y[0]
    f = k - i
    return y[i] * (1 - f) + y[i + 1] * f


@cached_njit
def _stop_state(s, v, dt, stops, j, passing, wait, dwell):
    """Driver at stops: skip the stops behind, wait ``dwell`` [s] at standstill before the next, then pass it.
    Returns (next stop index, passing, time waited [s])."""
    while j < stops.size and stops[j] < s - 10.0:
        j += 1
        passing = False
    if j < stops.size and not passing and s > stops[j] - 8.0 and v < 0.3:
        wait += dt
        if wait > dwell:
            passing = True
            wait = 0.0
    return j, passing, wait


@cached_njit
def _motor_limits(omega, tmax, pmax, treg, preg):
    """Motor torque limits [N m] at motor speed ω [rad/s]: min(T_max, P_max/ω) motoring, min(T_reg, P_reg/ω)
    regenerating (power limits only above 1 rad/s)."""
    lim_reg = treg
    if omega > 1.0 and preg / omega < lim_reg:
        lim_reg = preg / omega
    lim_mot = tmax
    if omega > 1.0 and pmax / omega < lim_mot:
        lim_mot = pmax / omega
    return lim_mot, lim_reg


@cached_njit
def _demand(f_d, v, v_t, tap, omega, p):
    """Driver's motor torque demand T_dem = F_d r_W / (i η) [N m] and brake pressure demand [Pa]: regeneration
    first up to its limit, the rest F_rest / brake gain on the friction brake; held at standstill; brake taps."""
    rw, ratio, eta = p[5], p[7], p[8]
    lim_mot, lim_reg = _motor_limits(omega, p[11], p[12], p[13], p[14])
    t_dem = f_d * rw / (ratio * eta)
    p_dem = 0.0
    if t_dem < -lim_reg:
        f_rest = -(t_dem + lim_reg) * ratio * eta / rw
        p_dem = f_rest / p[23]
        t_dem = -lim_reg
    t_dem = min(t_dem, lim_mot)
    if v < 0.3 and v_t < 0.5:
        t_dem = 0.0
        p_dem = 1.5e6     # holding at standstill
    if tap > 0 and v > 12.0:
        p_dem = p_dem + tap
    return t_dem, p_dem


@cached_njit
def _pedal(p_dem, p_held, t_since, dt):
    """Step-like brake pedal: hold the pressure [Pa], re-set in 5 bar steps at most every 0.6 s (release after
    0.3 s). Returns (held pressure [Pa], time since the last re-set [s])."""
    t_since += dt
    if (abs(p_dem - p_held) > 5e5 and t_since > 0.6) or (p_dem == 0.0 and p_held > 0.0 and t_since > 0.3):
        p_held = np.round(p_dem / 5e5) * 5e5
        t_since = 0.0
    return p_held, t_since


@cached_njit
def _wheel_torque(tm, v, t, p, eff):
    """Drive-train: wheel torque i η T_M - i T_0 in traction, i T_M / η - i T_0 in regeneration [N m], with cold
    oil raising the mesh loss and the drag torque by 1 + c e^(-t/τ); none backwards at standstill."""
    ratio, eta, tdrag = p[7], p[8], p[9]
    cold = 1.0 + eff[3] * np.exp(-t / eff[4])
    eta_t = 1.0 - (1.0 - eta) * cold
    t0 = tdrag * cold
    if tm >= 0:
        t_w = ratio * eta_t * tm - ratio * t0
    else:
        t_w = ratio * tm / eta_t - ratio * t0
    if v < 0.05 and t_w < 0:
        t_w = 0.0
    return t_w


@cached_njit
def _resistances(v, s, th, ka, psi, t_amb, m, kc, p, eff):
    """Driving resistances [N] (eq. 2.5-2.14): air ρ_a/2 c_x A v_a |v_a| with ρ_a = p_a/(R_a T_a) and the wind's
    approach speed, rolling m g cos θ f_r(v) (tire warm-up over distance), cornering k_c v⁴ κ², climbing
    m g sin θ. Returns (F_res, ρ_a [kg/m³])."""
    fr0, fr1, fr4, cxa = p[1], p[2], p[3], p[4]
    rho = AIR_PRESSURE / (R_AIR * t_amb)
    v_a = v + eff[8] * np.cos(psi - eff[9])
    f_air = 0.5 * rho * cxa * eff[7] * v_a * abs(v_a)
    fr = (fr0 + fr1 * v + fr4 * v ** 4) * (1.0 + eff[1] * np.exp(-s / eff[2]))
    f_roll = m * G * np.cos(th) * fr
    f_corner = kc * v ** 4 * ka * ka
    f_cl = m * G * np.sin(th)
    return f_air + f_roll + f_corner + f_cl, rho


@cached_njit
def _acceleration(t_w, f_res, f_brake, v, rw, m_eff):
    """v̇ = (T_W / r_W - F_res - F_B) / m_eff [m/s²] (eq. 2.6 + 2.17); static friction holds the car when the
    brake force exceeds the net force; no rolling backwards."""
    f_net = t_w / rw - f_res
    if v > 0.01:
        f_net -= f_brake
    elif abs(f_net) <= f_brake:     # static friction holds
        f_net = 0.0
    else:
        f_net -= np.sign(f_net) * f_brake
    a = f_net / m_eff
    if v <= 0.0 and a < 0:
        a = 0.0
    return a


@cached_njit
def _battery_current(tm, omega, soc, aux_add, p):
    """Battery current I [A] drawing P_el = T ω + k_cu T² + k_fe ω + P_0 + P_aux from U_oc(soc) = u0 + u1 soc
    through R: I = (U_oc - sqrt(U_oc² - 4 R P_el)) / (2 R). Returns (I, U_oc [V])."""
    kcu, kfe, p0, u0, u1, rbat, aux = p[15], p[16], p[17], p[18], p[19], p[20], p[22]
    p_el = tm * omega + kcu * tm * tm + kfe * omega + p0 + aux + aux_add
    u_oc = u0 + u1 * soc
    disc = u_oc * u_oc - 4 * rbat * p_el
    disc = max(disc, 1.0)
    return (u_oc - np.sqrt(disc)) / (2 * rbat), u_oc


@cached_njit
def _drive(n, dt, ds, road, v_plan, v_free, stops, taps, p, eff, ambient, dwell):
    """The numba loop, one named stage per step: stops, driver's target and force demand, torque and brake
    demand, pedal, motor and brake lags, drive-train, resistances, acceleration, battery, log, integration.
    road: grade [rad] and curvature [1/m] over distance (rows, grid step ds [m]);
    p: vehicle parameters (see :func:`_params`); eff: (mass add, f_r cold factor - 1, d_tire, loss cold factor - 1,
    tau_oil, aux add, cornering factor scale, drag factor, wind speed, wind from); ambient: T_a(t) [K];
    v_plan / v_free: target speeds over distance with / without the stops; stops [m]; dwell [s] at each stop.
    Returns an array of states per step."""
    m0, fr0, cxa, rw, iw, ratio, im, cap, brake_gain = p[0], p[1], p[4], p[5], p[6], p[7], p[10], p[21], p[23]
    l, l34, l12, x12, x34 = p[25], p[26], p[27], p[28], p[29]
    m = m0 + eff[0]
    x12e = x12 * eff[6]
    x34e = x34 * eff[6]
    kc = m * m * (l34 * l34 / x12e + l12 * l12 / x34e) / (l * l)
    m_eff = m + (4 * iw + ratio * ratio * im) / (rw * rw)
    out = np.zeros((n, 16))
    v = s = psi = tm = pb = p_held = wait = 0.0
    t_since = 10.0
    soc = 0.8
    j = 0
    passing = False
    for k in range(n):
        t = k * dt
        th = _interp_uniform(s, ds, road[0])
        ka = _interp_uniform(s, ds, road[1])
        j, passing, wait = _stop_state(s, v, dt, stops, j, passing, wait, dwell)
        # driver: look-ahead target, own force estimate, regeneration first
        v_t = _interp_uniform(s + 1.5 * v + 2.0, ds, v_free if passing else v_plan)
        a_d = max(min(0.8 * (v_t - v), 2.0), -3.0)
        f_est = m0 * G * np.sin(th) + m0 * G * fr0 + 0.5 * DRIVER_AIR_DENSITY * cxa * v * v
        omega = v / rw * ratio
        t_dem, p_dem = _demand(m0 * a_d + f_est, v, v_t, _interp_uniform(t, 1.0, taps), omega, p)
        p_held, t_since = _pedal(p_dem, p_held, t_since, dt)
        pb += (p_held - pb) * dt / 0.04
        tm += (t_dem - tm) * dt / 0.05
        t_w = _wheel_torque(tm, v, t, p, eff)
        f_res, rho = _resistances(v, s, th, ka, psi, ambient[k], m, kc, p, eff)
        f_brake = pb * brake_gain
        a = _acceleration(t_w, f_res, f_brake, v, rw, m_eff)
        cur, u_oc = _battery_current(tm, omega, soc, eff[5], p)
        soc -= u_oc * cur * dt / cap
        row = out[k]
        row[0], row[1], row[2], row[3], row[4], row[5], row[6], row[7] = t, s, v, a, th, ka, tm, omega
        row[8], row[9], row[10], row[11] = pb, u_oc - p[20] * cur, cur, f_res
        row[12] = t_w / rw - (4 * iw + ratio * ratio * im) / (rw * rw) * a   # tractive force F_xV
        row[13], row[14], row[15] = f_brake, psi, rho
        v += a * dt
        if v < 0:
            v = 0.0
        s += v * dt
        psi += v * ka * dt
    return out


def _params(veh: IndependentVehicle) -> np.ndarray:
    return np.array([veh.mass, veh.f_r0, veh.f_r1, veh.f_r4, veh.drag_area, veh.r_w, veh.i_w, veh.ratio, veh.eta,
                     veh.t_drag, veh.i_m, veh.t_max, veh.p_max, veh.t_regen, veh.p_regen, veh.k_cu, veh.k_fe,
                     veh.p_0, veh.u0, veh.u1, veh.r_bat, veh.capacity, veh.aux, veh.brake_gain(),
                     veh.front_share, veh.wheelbase, veh.l34, veh.l12, veh.x12, veh.x34])


def effect_vector(withheld: str) -> np.ndarray:
    """The loop's effect switches for a withheld effect (physical ones; logger ones act in :func:`log_channels`)."""
    e = np.array([0.0, 0.0, 1e9, 0.0, 1e9, 0.0, 1.0, 1.0, 0.0, 0.0])
    p = EFFECTS[withheld].params if withheld in EFFECTS else {}
    if withheld == "payload":
        e[0] = p["mass_kg"]
    elif withheld == "tire_warmup":
        e[1], e[2] = p["cold_factor"] - 1.0, p["distance_m"]
    elif withheld == "cold_drivetrain":
        e[3], e[4] = p["cold_loss_factor"] - 1.0, p["tau_s"]
    elif withheld == "auxiliary_load":
        e[5] = p["power_w"]
    elif withheld == "cornering":
        e[6] = p["stiffness_factor"]
    elif withheld == "drag_area":
        e[7] = p["factor"]
    elif withheld == "wind":
        e[8], e[9] = p["speed_m_s"], p["from_heading_rad"]
    return e


def lane_changes(profile, v_plan: np.ndarray, rng: np.random.Generator, width: float = 3.5,
                 duration: float = 4.0, every: float = 90.0) -> np.ndarray:
    """Curvature [1/m] of lane changes over the profile grid: y(x) = ±w (x/L - sin(2π x/L) / (2π)),
    κ = y'' = ±w 2π / L² sin(2π x / L), L = v · duration, one every ~``every`` seconds where v > 15 m/s."""
    s = profile.distance
    kap = np.zeros_like(s)
    x = float(rng.exponential(every * 25.0))
    side = 1.0
    while x < s[-1]:
        v = float(np.interp(x, s, v_plan))
        if v > 15.0:
            L = v * duration
            sel = (s >= x) & (s < x + L)
            kap[sel] += side * width * 2 * np.pi / L ** 2 * np.sin(2 * np.pi * (s[sel] - x) / L)
            side = -side
            x += L
        x += float(rng.exponential(every)) * max(v, 10.0)
    return kap


def replace_stops(profile):
    """The profile without its stops (the target speed after a stop has been served)."""
    return replace(profile, stops=np.zeros(0))


def simulate_trip(road_name: str, road_seed: int, rng: np.random.Generator, duration: float,
                  withheld: str = NONE, vehicle: IndependentVehicle = BASE) -> dict[str, Any]:
    """One trip: plan, lane changes, brake taps, ambient drift, the loop, the logger."""
    prof = road(road_name, road_seed, duration)
    ds = float(prof.distance[1] - prof.distance[0])
    if not np.allclose(np.diff(prof.distance), ds):
        raise ValueError("the independent world needs a uniformly sampled road profile")
    plan_seed = int(rng.integers(2 ** 31))
    v_plan = planned_speed(prof, np.random.default_rng(plan_seed), accel=1.8, power_to_mass=45.0, decel=2.3,
                           brake_power_to_mass=80.0)
    kappa = prof.curvature + (lane_changes(prof, v_plan, rng) if road_name != "city" else 0.0)
    n = round(duration / DT) + 1
    n_s = int(duration) + 2
    taps = np.zeros(n_s)
    if road_name != "city":
        for t0 in np.cumsum(rng.exponential(120.0, 20)):
            if t0 < n_s - 2:
                taps[int(t0)] = 10e5
    t_amb0 = float(rng.uniform(*AMBIENT_START_C)) + KELVIN
    drift = float(rng.uniform(*AMBIENT_DRIFT_K))
    tt = np.arange(n) * DT
    ambient = t_amb0 + drift * tt / max(duration, 1.0) + _ou(rng, n // 100 + 2, 1.0, 60.0, 0.3)[tt.astype(int)]
    v_free = planned_speed(replace_stops(prof), np.random.default_rng(plan_seed), accel=1.8, power_to_mass=45.0,
                           decel=2.3, brake_power_to_mass=80.0)
    out = _drive(n, DT, ds, np.vstack((prof.grade, kappa)), v_plan, v_free, np.asarray(prof.stops, float), taps,
                 _params(vehicle), effect_vector(withheld), ambient, float(rng.uniform(5.0, 12.0)))
    return log_channels(out, prof, ambient, rng, withheld, vehicle)


def log_channels(out: np.ndarray, prof, ambient: np.ndarray, rng: np.random.Generator, withheld: str,
                 veh: IndependentVehicle) -> dict[str, Any]:
    t, s, v, a, th, ka, tm, om, pb, u, cur, f_res, f_x, f_b, psi, rho = out.T
    torque = tm.copy()
    if withheld == "torque_scale":
        torque = torque * EFFECTS["torque_scale"].params["gain"]
    if withheld == "torque_latency":
        torque = delayed(t, torque, EFFECTS["torque_latency"].params["latency_s"])
    if withheld == OUTSIDE:
        p = EFFECTS[OUTSIDE].params
        kmh = v * 3.6
        torque = torque + np.where((kmh >= p["low_kmh"]) & (kmh < p["high_kmh"]), p["offset_nm"], 0.0)
    bias = EFFECTS["accel_bias"].params["bias_m_s2"] if withheld == "accel_bias" else 0.0
    pitch = PITCH_GRADIENT * a     # body pitch: nose up under acceleration, down when braking
    delta_w = ka * (veh.wheelbase + veh.understeer_gradient() * v ** 2)
    n = t.size
    gnss = prof.elevation()
    elev = np.interp(s, prof.distance, gnss) + _ou(rng, n // 100 + 2, 1.0, 30.0, 0.8)[t.astype(int)]
    amb_sensor = np.empty_like(ambient)
    amb_sensor[0] = ambient[0]
    alpha = DT / 20.0
    for k in range(1, n):      # slow sensor (20 s)
        amb_sensor[k] = amb_sensor[k - 1] + alpha * (ambient[k] - amb_sensor[k - 1])
    logged = {
        "vehicle_speed": np.clip(sensor(rng, v * 3.6, 0.05, 0.05), 0.0, None),
        "accel_x": sensor(rng, a + G * np.sin(th + pitch), 0.06, 0.01, bias),
        "drive_torque": sensor(rng, torque, 0.8, 0.25),
        "engine_speed": sensor(rng, om * 60 / (2 * np.pi), 1.0, 1.0),
        "brake_pressure_front": np.clip(sensor(rng, pb / 1e5, 0.05, 0.1), 0.0, None),
        "brake_pressure_rear": np.clip(sensor(rng, pb / 1e5, 0.05, 0.1), 0.0, None),
        "steering_wheel_angle": sensor(rng, np.degrees(delta_w * veh.steering_ratio), 0.1, 0.1),
        "yaw_rate": sensor(rng, np.degrees(v * ka), 0.05, 0.01),
        "elevation": np.round(elev),
        "battery_voltage": sensor(rng, u, 0.2, 0.1),
        "battery_current": sensor(rng, -cur, 0.3, 0.1),      # the BMS sends discharge negative
        "ambient_temperature": quantise(amb_sensor - KELVIN, 0.5),
    }
    truth = {"t": t, "distance": s, "speed": v, "acceleration": a, "grade": th, "curvature": ka,
             "motor_torque": tm, "motor_speed": om, "brake_pressure": pb, "brake_force": f_b,
             "resistance": f_res, "tractive_force": f_x, "heading": psi, "air_density": rho,
             "ambient_temperature": ambient, "battery_power": u * cur}
    return {"t": t, "logged": logged, "truth": truth}


def write_trip(path: Path, trip: dict[str, Any]) -> Path:
    return write_log(path, trip["t"], COLUMNS + (CURRENT,), trip["logged"], TIME_HEADER)


MAPPING_EXTRA = [{"source": CURRENT.header, "channel": "battery_current", "unit": "A", "scale": -1,
                  "resample": "linear", "note": "the BMS sends discharge negative"}]


def _gear_table(ratio: float, efficiency: float, drag: float) -> Map2D:
    tq = np.union1d(np.linspace(-400.0, 400.0, 9), [0.0])
    sp = np.linspace(0.0, 1400.0, 5)
    values = (1 - efficiency) * np.abs(tq)[:, None] * ratio + drag * ratio + 0.0 * sp[None, :]
    return Map2D(tq.tolist(), sp.tolist(), values.round(5).tolist())


def matched_vehicle(veh: IndependentVehicle = BASE) -> VehicleSpec:
    """The roadload vehicle spec with the world's base parameters (what the diagnosis' sim side knows)."""
    speed = np.linspace(0.0, 1400.0, 29)
    torque = np.union1d(np.linspace(-400.0, 400.0, 33), [0.0])
    loss = veh.k_cu * torque[None, :] ** 2 + veh.k_fe * speed[:, None] + veh.p_0
    motor = MotorSpec(max_torque=veh.t_max, max_power=veh.p_max, max_speed=1400.0, regen_torque_limit=veh.t_regen,
                      regen_power_limit=veh.p_regen, inertia=veh.i_m,
                      loss_map=Map2D(speed.tolist(), torque.tolist(), loss.round(3).tolist()))
    dt = DrivetrainSpec(kind="bev", driven_axle="rear", gear_ratios=[veh.ratio], final_drive=1.0,
                        gearbox_inertia=[0.0], clutch_inertia=0.0, differential_inertia=0.0,
                        gearbox_loss=[_gear_table(veh.ratio, veh.eta, veh.t_drag)],
                        differential_loss=_gear_table(1.0, 1.0, 0.0), motor=motor,
                        battery=BatterySpec(capacity=veh.capacity, open_circuit_voltage=veh.u0 + 0.8 * veh.u1,
                                            internal_resistance=veh.r_bat, auxiliary_power=veh.aux,
                                            initial_soc=0.8),
                        oil_warm_temperature=353.15, oil_cold_loss_factor=2.0, oil_time_constant=900.0)
    sw = np.radians(np.linspace(-540.0, 540.0, 13))
    ch = {
        "vehicle_speed": ChannelSensorSpec(0.05 / 3.6, 0.0, 0.05 / 3.6, 0.0),
        "accel_x": ChannelSensorSpec(0.06, 0.0, 0.01, 0.0),
        "drive_torque": ChannelSensorSpec(0.8, 0.0, 0.25, 0.0),
        "engine_speed": ChannelSensorSpec(0.1, 0.0, 0.1, 0.0),
        "brake_pressure_front": ChannelSensorSpec(5e3, 0.0, 1e4, 0.0),
        "brake_pressure_rear": ChannelSensorSpec(5e3, 0.0, 1e4, 0.0),
        "steering_wheel_angle": ChannelSensorSpec(0.002, 0.0, 0.0017, 0.0),
        "yaw_rate": ChannelSensorSpec(0.001, 0.0, 0.0002, 0.0),
        "elevation": ChannelSensorSpec(0.8, 0.0, 1.0, 0.0),
        "battery_voltage": ChannelSensorSpec(0.2, 0.0, 0.1, 0.0),
        "battery_current": ChannelSensorSpec(0.3, 0.0, 0.1, 0.0),
        "ambient_temperature": ChannelSensorSpec(0.0, 0.0, 0.5, 0.0),
    }
    return VehicleSpec(
        name="independent_bev",
        description="roadload spec with the base parameters of the independent test world (chapter-2 model)",
        body=BodySpec(mass=veh.mass, wheelbase=veh.wheelbase, cg_to_front_axle=veh.l12, yaw_inertia=2600.0,
                      pitch_gradient=PITCH_GRADIENT, roll_gradient=0.0),
        aero=AeroSpec(drag_coefficient=0.28, frontal_area=veh.drag_area / 0.28, yaw_drag_factor=0.0),
        tires=TireSpec(dynamic_radius=veh.r_w, rolling_resistance_f0=veh.f_r0, rolling_resistance_f1=veh.f_r1,
                       rolling_resistance_f4=veh.f_r4, cornering_stiffness_front=veh.x12,
                       cornering_stiffness_rear=veh.x34, wheel_inertia=veh.i_w, toe_in=0.0),
        drivetrain=dt,
        brakes=BrakeSpec(front_area=veh.a_front, rear_area=veh.a_rear, front_radius=veh.r_front,
                         rear_radius=veh.r_rear, pad_friction=veh.pad, front_share=veh.front_share),
        steering=SteeringSpec(sw.tolist(), (sw / veh.steering_ratio).tolist()),
        sensors=SensorSpec(100.0, ch, 0.0, 0.0, 0.0),
    )


def with_params(**changes) -> IndependentVehicle:
    return replace(BASE, **changes)
