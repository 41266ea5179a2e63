"""The jitted vehicle model: one 10-ms substep of longitudinal + lateral dynamics, drive-train, brakes and the
drifting quantities, with an exact energy ledger.

Longitudinal force balance (eq. 2.5-2.16), vehicle speed v >= 0:
    M a = F_W - F_B - F_cl - F_r - F_a - F_Wc - F_Wt
    F_cl = m_V g sin(theta)                                          climbing force (2.5)
    M = m_V + (4 I_W + I_red(G)) / r_W^2 (clutch engaged)             acceleration force with I_red(G) (2.6, 2.17)
    F_a = rho_a/2 c_w A_V u_x v_a (1 + k sin^2 psi_a)                 aero drag (2.7), approach velocity (2.8a):
          u_x = v - v_w cos psi_w, u_y = -v_w sin psi_w, v_a = |u|, rho_a = p_a / (R_a T_a)
    F_r = f_r(v) m_V g cos(theta) cos(phi_r) tanh(v / 0.1 m/s)      rolling resistance (2.9, 2.10), smoothed at 0
    F_Wc = F_y12 sin(alpha_12) + F_y34 sin(alpha_34)                  cornering resistance (2.13; 2.14/2.15 for the
                                                                     steady state), from the single-track model
    F_Wt = X_12 delta_toe sin(delta_toe)                              toe-in resistance (section 2.4.5)
    F_W = T_W / r_W (drive-train, eq. 2.17), F_B = sum p_B A_B r_B X_B / r_W (brakes)
The tractive force of eq. 2.16b is F_xV = m_V a + F_cl + F_r + F_a + F_Wc + F_Wt and the rim torque
T_R = F_xV r_W + 4 I_W a / r_W.

Lateral: linear single-track model (section 2.5.1, eq. 2.12) with slip angles alpha_12 = delta - beta - l_12 r/v,
alpha_34 = -beta + l_34 r/v, integrated implicitly (stable at any speed), kinematic below 1 m/s, plus the lateral
gravity of the road bank. Valid up to |a_y| ~ 4 m/s^2; samples above are counted for a warning.

Drive-train modes (ICE): open clutch (engine idles), slipping clutch (launch, shifts; clutch torque in the
direction of slip, engine speed governed towards the gearbox input speed), locked. Locking is an inelastic
coupling (momentum conserved, the energy difference goes to the clutch). Gear changes happen with the clutch
slipping; the gear-dependent inertia I_G(G) is lumped on the engine side and the engine speed rescaled so its
kinetic energy is unchanged. BEV: always locked, single gear; gear request 0 = zero motor torque (sailing).

Energy ledger (cumulative, J): source energy (fuel or battery), shaft work T_E omega_E, dissipation in gearbox,
differential, clutch, brakes (incl. hill-hold), rolling, aero, cornering/toe-in, and the climbing work. With the
midpoint speed used for every power term, drive work = delta kinetic + climbing + dissipation holds to round-off.
"""

from __future__ import annotations

import math

from roadload.units import G, R_AIR

from typing import NamedTuple

from ._jit import jit, stage
from .driver import driver_force, steering_law
from .drivetrain import (
    allocate,
    battery_current,
    forward_wheel_torque,
    forward_wheel_torque_at,
    fuel_power,
    inverse_wheel_torque_at,
    loss_map_speeds,
    motor_electric_power,
    oil_loss_factor,
    regen_capacity,
    source_side_inertia,
    speed_ratio,
    torque_limits,
    wheel_side_mass,
)
from .layout import (
    L_A, L_ACC_X_SENS, L_ACC_Y_SENS, L_AY, L_BANK, L_BETA, L_CLUTCH, L_CSF, L_CSR, L_CURV, L_CXA, L_DELTA, L_DISC_T,
    L_DRAGF, L_ELEV, L_ESRC, L_FAERO, L_FBRAKE, L_FCLIMB, L_FCORNER, L_FR, L_FR0, L_FR1, L_FR4, L_FROLL, L_FX, L_GEAR,
    L_GRADE, L_HEAD, L_IBAT, L_LOSSF, L_MASS, L_MU, L_OIL, L_PAMB, L_PATHCURV, L_PBF, L_PBR, L_POS, L_PSRC, L_RHO,
    L_RIM, L_SOC, L_T, L_TAMB, L_TE, L_V, L_VBAT, L_WE, L_WFL, L_WFR, L_WIND_A, L_WIND_S, L_WRL, L_WRR, L_YAW,
    MODE_LOCKED, MODE_OPEN, MODE_SLIP, R_BANK, R_CURV, R_ELEV, R_GRADE, R_HEAD, R_S, Route, Tables,
)
from .numerics import (cos_small, rng_normal, rng_uniform, road_blend, road_locate, road_value, road_weight,
                       sin_small, tan_small)

LATERAL_VALIDITY_LIMIT = 4.0  # m/s^2, single-track model validity (section 2.5.1)


# ================================================================================ what the stages hand on
class RoadHere(NamedTuple):
    """The road at the vehicle: segment index, grade theta [rad], curvature kappa [1/m], heading [rad],
    elevation [m], bank phi_r [rad]."""

    segment: int
    grade: float
    curvature: float
    heading: float
    elevation: float
    bank: float


class Conditions(NamedTuple):
    """Air, tyres, wind and oil in this substep: ambient pressure [Pa], air density rho_a [kg/m^3], rolling
    coefficients f_r0, f_r1, f_r4, cornering stiffnesses front / rear [N/rad], drag area c_w A_V [m^2], wind speed
    v_w [m/s] and angle psi_w [rad], drive-train loss factor phi [-]."""

    pressure: float
    density: float
    f0: float
    f1: float
    f4: float
    cornering_front: float
    cornering_rear: float
    drag_area: float
    wind_speed: float
    wind_angle: float
    loss_factor: float


class Lateral(NamedTuple):
    """Single-track result: steer angle delta, side slip beta [rad], yaw rate r [rad/s], slip angles alpha_12,
    alpha_34 [rad], axle forces F_y12, F_y34 [N], sensed specific force and lateral acceleration a_y [m/s^2]."""

    steer_angle: float
    side_slip: float
    yaw_rate: float
    slip_front: float
    slip_rear: float
    force_front: float
    force_rear: float
    specific_force: float
    acceleration: float


class Shaft(NamedTuple):
    """The engaged drive-train: gear G, clutch mode, speed ratio k(G) [rad/s per m/s], gearbox input speed k v
    [rad/s], source-side inertia I_src [kg m^2], engine speed omega_E [rad/s], and where the loss maps are read at
    the input speed (drivetrain.loss_map_speeds; zeros in neutral)."""

    gear: int
    mode: int
    ratio: float
    input_speed: float
    inertia: float
    engine_speed: float
    loss_map_speeds: tuple


class SourceTorques(NamedTuple):
    """Engine / motor speed omega_E [rad/s] (the gearbox input speed when locked), source torque T_E and clutch
    torque T_C [N m] of this substep."""

    engine_speed: float
    engine_torque: float
    clutch_torque: float


class Resistances(NamedTuple):
    """Driving resistances [N]: climbing F_cl, rolling F_r (with its coefficient f_r(v) [-]), aero F_a, cornering
    and toe-in F_Wc + F_Wt."""

    climbing: float
    rolling_coefficient: float
    rolling: float
    aero: float
    cornering: float


class Braking(NamedTuple):
    """Pad friction coefficient mu [-], front and rear brake forces [N] at the wheels."""

    friction_coefficient: float
    front: float
    rear: float


class Source(NamedTuple):
    """Source power P_src [W] (fuel or battery), battery voltage [V] and current [A] (BEV)."""

    power: float
    battery_voltage: float
    battery_current: float


@jit
def _clip(x, lo, hi):
    if x < lo:
        return lo
    if x > hi:
        return hi
    return x


@stage
def _gear_for_speed(p, v):
    """The highest gear whose gearbox input speed at v [m/s] is above the full-load downshift speed (1 at least)."""
    k_base = p.final_drive / p.wheel_radius
    best = 1
    for g in range(1, int(p.n_gears) + 1):
        if p.gear_ratio[g - 1] * k_base * v >= p.downshift_speed_high:
            best = g
    return best


@stage
def _full_load_wheel_torque(p, tables, gear, omega, v, phi):
    """Wheel torque T_W [N m] of the full-load source torque in ``gear`` at engine speed omega [rad/s] (eq. 2.17)."""
    _, t_max = torque_limits(p, tables, omega, v)
    return forward_wheel_torque(p, tables, gear, t_max, omega, phi)[0]


@stage
def _upshift(p, tables, gear, omega_e, v, f_req, phi):
    """gear + 1 when the next gear's engine speed stays above its load-dependent downshift speed (x 1.05), or at
    the rev limit; else gear."""
    r = p.wheel_radius
    w_next = v * (p.final_drive / r) * p.gear_ratio[gear]
    fn = _full_load_wheel_torque(p, tables, gear + 1, w_next, v, phi)
    load_n = _clip(f_req / (fn / r), 0.0, 1.0) if fn > r else 1.0
    dn_n = p.downshift_speed_low + load_n * (p.downshift_speed_high - p.downshift_speed_low)
    if w_next > 1.05 * dn_n or omega_e > p.max_engine_speed:
        return gear + 1
    return gear


@stage
def _downshift(p, tables, gear, omega_e, v, f_req, phi, dn, f_max):
    """gear - 1 below the load-dependent downshift speed dn [rad/s] (when the lower gear stays below 0.95 x the
    full-load upshift speed), or as a kickdown when the request needs > 0.97 of the full-load force f_max [N] and
    the lower gear gives 2 % more; else gear."""
    r = p.wheel_radius
    w_prev = v * (p.final_drive / r) * p.gear_ratio[gear - 2]
    if omega_e < dn and w_prev < 0.95 * p.upshift_speed_high:
        return gear - 1
    if f_req > 0.97 * f_max and w_prev < 0.9 * p.upshift_speed_high:
        fp = _full_load_wheel_torque(p, tables, gear - 1, w_prev, v, phi)
        if fp / r > 1.02 * f_max:
            return gear - 1  # kickdown
    return gear


@jit
def _select_gear(p, tables, gear, mode, omega_e, v, f_req, phi, t, last_shift):
    """Shift strategy: load-dependent up/downshift speeds with hysteresis guards, kickdown, gear choice when the
    clutch is open. Returns the wanted gear."""
    if gear < 1:
        return 1
    if t - last_shift < p.shift_interval:
        return gear
    if mode == MODE_OPEN or (mode == MODE_SLIP and v < 3.0):
        return _gear_for_speed(p, v) if mode == MODE_OPEN else gear
    if mode != MODE_LOCKED:
        return gear
    f_max = _full_load_wheel_torque(p, tables, gear, omega_e, v, phi) / p.wheel_radius
    load = _clip(f_req / f_max, 0.0, 1.0) if f_max > 1.0 else 1.0
    up = p.upshift_speed_low + load * (p.upshift_speed_high - p.upshift_speed_low)
    dn = p.downshift_speed_low + load * (p.downshift_speed_high - p.downshift_speed_low)
    if omega_e > up and gear < int(p.n_gears):
        return _upshift(p, tables, gear, omega_e, v, f_req, phi)
    if gear > 1:
        return _downshift(p, tables, gear, omega_e, v, f_req, phi, dn, f_max)
    return gear


# ================================================================================ road and environment
@stage
def road_attributes(x, p, road, s):
    """Road at position s [m] (RoadHere): segment index (kept in x for the next search), grade theta [rad],
    curvature kappa [1/m], heading [rad], elevation [m] and bank phi_r [rad] (measured bank, scaled, plus the
    curvature-proportional design bank, limited)."""
    ridx = road_locate(road[R_S], s, int(x.road_index))
    x.road_index = ridx
    w = road_weight(road, ridx, s)
    theta = road_blend(road, R_GRADE, ridx, w)
    kappa = road_blend(road, R_CURV, ridx, w)
    heading = road_blend(road, R_HEAD, ridx, w)
    elev = road_blend(road, R_ELEV, ridx, w)
    bank = 0.0
    if p.road_bank_on > 0.5:
        bank = p.bank_scale * road_blend(road, R_BANK, ridx, w) + _clip(p.superelevation_gain * kappa, -p.bank_max,
                                                                         p.bank_max)
    return RoadHere(ridx, theta, kappa, heading, elev, bank)


@stage
def air_density(p, elev):
    """Ambient pressure p_a [Pa] (barometric with height when enabled) and air density rho_a = p_a / (R_a T_a)
    [kg/m^3] (eq. 2.7)."""
    p_amb = p.ambient_pressure
    if p.barometric_on > 0.5:
        p_amb = p_amb * math.exp(-elev / p.barometric_scale_height)
    return p_amb, p_amb / (R_AIR * p.ambient_temperature)


@stage
def rolling_coefficients(p, s):
    """Rolling-resistance coefficients f_r0, f_r1 [s/m], f_r4 [s^4/m^4] of f_r(v) = f_r0 + f_r1 v + f_r4 v^4
    (eq. 2.10) with the tyre warm-up, winter and wet-road factors; and the cornering-stiffness factor."""
    rr_mult = 1.0
    cs_mult = 1.0
    fr1_add = 0.0
    if p.tire_warmup_on > 0.5:
        rr_mult *= 1.0 + (p.tire_cold_factor - 1.0) * math.exp(-s / p.tire_warmup_distance)
    if p.winter_tires_on > 0.5:
        rr_mult *= p.winter_rolling_factor
        cs_mult *= p.winter_cornering_factor
    if p.wet_road_on > 0.5:
        rr_mult *= p.wet_rolling_factor
        fr1_add += p.wet_f1
    return p.rolling_f0 * rr_mult, p.rolling_f1 * rr_mult + fr1_add, p.rolling_f4 * rr_mult, cs_mult


@stage
def wind(x, p, heading, a_g, q_g):
    """Wind speed v_w >= 0 [m/s] and its angle psi_w to the vehicle's heading [rad] (eq. 2.8): mean wind plus
    first-order Gauss-Markov gusts of speed and direction: x_k+1 = a_g x_k + sigma q_g n_k with a_g = exp(-dt / tau_g),
    q_g = sqrt(1 - a_g^2) (substep_constants)."""
    wind_s = 0.0
    wind_a = 0.0
    if p.wind_on > 0.5:
        x.gust_speed = a_g * x.gust_speed + p.wind_gust_std * q_g * rng_normal(x)
        x.wind_direction_deviation = a_g * x.wind_direction_deviation + p.wind_direction_std * q_g * rng_normal(x)
        wind_s = p.wind_mean_speed + x.gust_speed
        wind_s = max(wind_s, 0.0)
        wind_a = p.wind_direction + x.wind_direction_deviation - (heading + x.heading_error)
        wind_a = math.atan2(math.sin(wind_a), math.cos(wind_a))
    return wind_s, wind_a


@stage
def conditions(x, p, here, a_g, q_g):
    """Conditions of this substep: air pressure and density at the elevation, rolling coefficients and cornering
    stiffnesses with the tyre effects, drag area c_w A_V times the drag-area factor, wind (draws its gusts from
    the random state), and the oil-temperature loss factor phi."""
    p_amb, rho = air_density(p, here.elevation)
    fr0, fr1, fr4, cs_mult = rolling_coefficients(p, x.position)
    c_f = p.cornering_stiffness_front * cs_mult
    c_r = p.cornering_stiffness_rear * cs_mult
    cxa = p.drag_coefficient * p.frontal_area * x.drag_area_factor
    wind_s, wind_a = wind(x, p, here.heading, a_g, q_g)
    phi = oil_loss_factor(p, x.oil_temperature) if p.oil_temperature_on > 0.5 else 1.0
    return Conditions(p_amb, rho, fr0, fr1, fr4, c_f, c_r, cxa, wind_s, wind_a, phi)


# ================================================================================ command
@stage
def _regen_capacity_if_braking(force, x, p, tables, phi):
    """regen_capacity [N] for a braking request (force < 0); 0 otherwise, where allocate() does not read it (the
    capacity costs two loss-map look-ups per substep)."""
    if force < 0.0:
        return regen_capacity(p, tables, int(x.gear), int(x.clutch_mode), x.engine_speed, x.speed, phi)
    return 0.0


@stage
def command(x, p, c, tables, route, here, phi):
    """The wheel-force request [N] split into traction, regenerative and friction braking, the steering angle
    [rad] and a gear request (-1: automatic) — from the built-in driver, a signed wheel force through the default
    allocator, or an explicit command (a NaN steering angle: the built-in steering law)."""
    gear_req = -1
    use = c.mode
    if 0.5 < use < 1.5:  # built-in driver
        f_dem = driver_force(x, p, route, here.segment, here.grade)
        traction, regen, friction = allocate(f_dem, _regen_capacity_if_braking(f_dem, x, p, tables, phi))
        steer = steering_law(x, p, route.road, here.segment)
    else:
        if use > 1.5:  # signed wheel force through the default allocator
            f_cmd = c.traction
            traction, regen, friction = allocate(f_cmd, _regen_capacity_if_braking(f_cmd, x, p, tables, phi))
        else:
            traction = c.traction
            regen = c.regen
            friction = c.friction
            gear_req = int(c.gear)
        steer = c.steer
        if math.isnan(steer):  # NaN: the built-in steering law keeps the vehicle on the road
            steer = steering_law(x, p, route.road, here.segment)
    return traction, regen, friction, steer, gear_req


# ================================================================================ lateral dynamics
@stage
def lateral_single_track(x, p, steer, mass, c_f, c_r, bank, cth):
    """Linear single-track model (section 2.5.1, eq. 2.12), integrated implicitly (stable at any speed),
    kinematic below 1 m/s, with the lateral gravity g sin(phi_r) cos(theta) of the road bank.

    Slip angles alpha_12 = delta - beta - l_12 r/v, alpha_34 = -beta + l_34 r/v [rad]; axle forces
    F_y = c alpha [N]. Updates beta, yaw rate r [rad/s], delta and the lateral-acceleration statistics in x.
    Returns Lateral(delta, beta, yaw, alpha_f, alpha_r, F_y12, F_y34, sensed specific force [m/s^2], a_y [m/s^2])."""
    v = x.speed
    dt = p.dt
    delta = _clip(steer, -p.steer_max, p.steer_max)
    x.wheel_steer_angle = delta
    lf = p.cg_to_front
    lr = p.cg_to_rear
    wb = p.wheelbase
    g_lat = G * sin_small(bank) * cth
    if v < 1.0:
        beta = lr / wb * delta
        yaw = v * tan_small(delta) / wb
        a_y_kin = v * yaw
        fy_f = mass * (a_y_kin - g_lat) * lr / wb
        fy_r = mass * (a_y_kin - g_lat) * lf / wb
        alpha_f = fy_f / c_f
        alpha_r = fy_r / c_r
    else:
        a11 = -(c_f + c_r) / (mass * v)
        a12 = -(c_f * lf - c_r * lr) / (mass * v * v) - 1.0
        a21 = -(c_f * lf - c_r * lr) / p.yaw_inertia
        a22 = -(c_f * lf * lf + c_r * lr * lr) / (p.yaw_inertia * v)
        b1 = c_f / (mass * v) * delta + g_lat / v
        b2 = c_f * lf / p.yaw_inertia * delta
        m11 = 1.0 - dt * a11
        m12 = -dt * a12
        m21 = -dt * a21
        m22 = 1.0 - dt * a22
        r1 = x.side_slip_angle + dt * b1
        r2 = x.yaw_rate + dt * b2
        det = m11 * m22 - m12 * m21
        beta = (r1 * m22 - m12 * r2) / det
        yaw = (m11 * r2 - m21 * r1) / det
        alpha_f = delta - beta - lf * yaw / v
        alpha_r = -beta + lr * yaw / v
        fy_f = c_f * alpha_f
        fy_r = c_r * alpha_r
    x.side_slip_angle = beta
    x.yaw_rate = yaw
    spec_fy = (fy_f * cos_small(delta) + fy_r) / mass  # what a lateral accelerometer senses (no gravity)
    a_y = spec_fy + g_lat  # kinematic lateral acceleration
    x.lateral_acceleration = a_y
    if abs(a_y) > abs(x.lateral_acceleration_peak):
        x.lateral_acceleration_peak = a_y
    if abs(a_y) > LATERAL_VALIDITY_LIMIT:
        x.lateral_warning_count += 1.0
    return Lateral(delta, beta, yaw, alpha_f, alpha_r, fy_f, fy_r, spec_fy, a_y)


@stage
def cornering_resistance(fy_f, fy_r, alpha_f, alpha_r, c_f, toe, sin_toe, v):
    """F_Wc + F_Wt [N]: cornering resistance F_y12 sin(alpha_12) + F_y34 sin(alpha_34) (eq. 2.13-2.15) plus the
    toe-in resistance c_12 delta_toe sin(delta_toe) (section 2.4.5), faded in below 0.5 m/s."""
    return fy_f * sin_small(alpha_f) + fy_r * sin_small(alpha_r) + c_f * toe * sin_toe * min(1.0, v / 0.5)


@stage
def path_following(x, v, beta, yaw, kappa, dt):
    """Lateral offset e_y [m] and heading error e_psi [rad] relative to the road centre line."""
    x.lateral_offset += v * sin_small(x.heading_error + beta) * dt
    x.heading_error += (yaw - v * kappa) * dt


# ================================================================================ drive-train (eq. 2.17)
@stage
def gear_and_clutch(x, p, tables, f_req, phi, gear_req):
    """ICE gear selection (or the requested gear) and clutch mode (open / slipping / locked). A gear change
    opens a locked clutch into slip and rescales the engine speed so the source-side kinetic energy
    1/2 I_G(G) omega_E^2 is unchanged. Returns (gear, mode, omega_E [rad/s])."""
    gear = int(x.gear)
    mode = int(x.clutch_mode)
    omega_e = x.engine_speed
    v = x.speed
    t = x.time
    new_gear = gear
    if gear_req >= 0:
        new_gear = min(gear_req, int(p.n_gears))
    else:
        new_gear = _select_gear(p, tables, gear, mode, omega_e, v, f_req, phi, t, x.last_shift_time)
    if new_gear != gear:
        if mode == MODE_LOCKED:
            mode = MODE_SLIP
        j_old = source_side_inertia(p, gear)
        j_new = source_side_inertia(p, new_gear)
        omega_e = omega_e * math.sqrt(j_old / j_new)
        gear = new_gear
        x.slip_time = 0.0
        x.last_shift_time = t
    if gear == 0:
        mode = MODE_OPEN
    else:
        w_in0 = speed_ratio(p, gear) * v
        if mode == MODE_LOCKED and omega_e < 0.9 * p.idle_speed:
            mode = MODE_SLIP if f_req > 0.0 else MODE_OPEN  # avoid stalling
            x.slip_time = 0.0
        elif mode == MODE_OPEN and (f_req > 0.0 or w_in0 > 1.2 * p.idle_speed):
            mode = MODE_SLIP
            x.slip_time = 0.0
    return gear, mode, omega_e


@stage
def engage(x, p, tables, f_req, phi, gear_req):
    """The engaged drive-train of this substep (Shaft): BEV locked in its single gear; ICE through
    gear_and_clutch; speed ratio k(G) = i_G i_D / r_W, gearbox input speed omega_G = k v, source-side inertia, and
    the loss maps' speed segments at omega_G (in gear, both the source torque and the wheel torque read the maps
    there)."""
    if p.is_bev > 0.5:
        gear, mode, omega_e = 1, MODE_LOCKED, x.engine_speed
    else:
        gear, mode, omega_e = gear_and_clutch(x, p, tables, f_req, phi, gear_req)
    k = speed_ratio(p, gear)
    w_in = k * x.speed
    speeds = (0.0, 0, 0.0, 0, 0.0)
    if gear >= 1:
        speeds = loss_map_speeds(tables, p.gear_ratio[gear - 1], gear, w_in)
    return Shaft(gear, mode, k, w_in, source_side_inertia(p, gear), omega_e, speeds)


@stage
def source_torques(x, p, tables, shaft, gear_req, f_req, phi):
    """Source torque T_E and clutch torque T_C [N m]: locked (BEV always) — the torque that yields the wheel
    force request through eq. 2.17 within the source limits; slipping — clutch torque in the direction of slip,
    the engine speed governed towards the gearbox input (launch) speed; open — idle governor.
    Returns SourceTorques(omega_E [rad/s], T_E, T_C)."""
    bev = p.is_bev > 0.5
    gear, mode, w_in, j_src, omega_e = shaft.gear, shaft.mode, shaft.input_speed, shaft.inertia, shaft.engine_speed
    r = p.wheel_radius
    v = x.speed
    dt = p.dt
    t_c = 0.0
    t_e = 0.0
    locked = bev or mode == MODE_LOCKED
    if locked:
        omega_e = w_in
    t_min, t_max = torque_limits(p, tables, omega_e, v)
    # the source torque that yields the wheel force request (eq. 2.17 inverted at the gearbox input speed), where
    # the mode uses it: locked (a BEV unless sailing) or slipping
    t_req = 0.0
    if (bev and gear_req != 0) or (not bev and (mode == MODE_LOCKED or mode == MODE_SLIP)):
        t_req = _clip(inverse_wheel_torque_at(p, tables, gear, f_req * r, w_in, phi, shaft.loss_map_speeds), t_min,
                      t_max)
    if locked:
        t_e = t_req
        t_c = t_e
    else:
        target = p.idle_speed
        if mode == MODE_SLIP:
            slip = omega_e - w_in
            if slip > 0.0:
                t_c = max(0.0, t_req)
            elif slip < 0.0:
                t_c = min(0.0, t_req)
            if f_req > 0.0 and w_in < p.launch_speed:
                target = p.launch_speed
            elif w_in > p.idle_speed:
                target = w_in
            x.slip_time += dt
        t_e = _clip(t_c + j_src * (target - omega_e) / p.sync_time_constant, t_min, t_max)
    return SourceTorques(omega_e, t_e, t_c)


@stage
def wheel_torque(p, tables, shaft, src, v, phi):
    """Wheel torque T_W [N m] through gearbox and differential (eq. 2.17, with their load-dependent losses):
    from T_E when locked, from the clutch torque T_C when slipping, both at the gearbox input speed (when locked
    the source turns at it). Returns (T_W, gearbox loss, diff. loss)."""
    gear = shaft.gear
    if gear == 0:  # neutral: the differential's spin loss at its input speed
        return forward_wheel_torque(p, tables, gear, 0.0, p.final_drive / p.wheel_radius * v, phi)
    torque_in = src.engine_torque if p.is_bev > 0.5 or shaft.mode == MODE_LOCKED else src.clutch_torque
    return forward_wheel_torque_at(p, tables, gear, torque_in, shaft.input_speed, phi, shaft.loss_map_speeds)


# ================================================================================ brakes
@stage
def brakes(x, p, friction, r, a_b):
    """Friction brakes: the command F_B = sum p_B A_B r_B mu / r_W [N] is split front/rear, the line pressures
    p_B [Pa] follow with a first-order lag, the pad friction mu depends on the disc temperature (and a random
    walk) when enabled; a_b = exp(-dt / tau_B) (substep_constants). Returns Braking(mu, F_B front [N], F_B rear
    [N])."""
    mu = p.pad_friction
    if p.pad_drift_on > 0.5:
        mu = (p.pad_friction * (1.0 + p.pad_temperature_coefficient
                                * (x.brake_disc_temperature - p.pad_reference_temperature)) + x.pad_friction_walk)
        mu = max(mu, 0.05)
    f_brk = max(0.0, friction)
    pf_cmd = _clip(p.brake_front_share * f_brk * r / (2.0 * p.brake_area_front * p.brake_radius_front * p.pad_friction),
                   0.0, p.brake_pressure_max)
    pr_cmd = _clip((1.0 - p.brake_front_share) * f_brk * r
                   / (2.0 * p.brake_area_rear * p.brake_radius_rear * p.pad_friction), 0.0, p.brake_pressure_max)
    x.brake_pressure_front = a_b * x.brake_pressure_front + (1.0 - a_b) * pf_cmd
    x.brake_pressure_rear = a_b * x.brake_pressure_rear + (1.0 - a_b) * pr_cmd
    f_bf = 2.0 * x.brake_pressure_front * p.brake_area_front * p.brake_radius_front * mu / r
    f_br = 2.0 * x.brake_pressure_rear * p.brake_area_rear * p.brake_radius_rear * mu / r
    return Braking(mu, f_bf, f_br)


# ================================================================================ driving resistances
@stage
def climbing_force(mass, sth):
    """F_cl = m_V g sin(theta) [N] (eq. 2.5)."""
    return mass * G * sth


@stage
def rolling_resistance(fr0, fr1, fr4, v, mass, cth, bank):
    """F_r = f_r(v) m_V g cos(theta) cos(phi_r) tanh(v / 0.1 m/s) [N] with f_r(v) = f_r0 + f_r1 v + f_r4 v^4
    (eq. 2.9, 2.10), smoothed at standstill. Returns (f_r(v), F_r)."""
    fr = fr0 + fr1 * v + fr4 * v * v * v * v
    # cos(0) = 1 and tanh(x) = 1 for x >= 22 are exact in double precision: both calls are skipped there
    cos_bank = math.cos(bank) if bank != 0.0 else 1.0
    smooth = math.tanh(v / 0.1) if v < 2.5 else 1.0
    return fr, fr * mass * G * cth * cos_bank * smooth


@stage
def aero_drag(rho, cxa, v, wind_s, wind_a, yaw_drag):
    """F_a = rho_a/2 c_w A_V u_x v_a (1 + k sin^2 psi_a) [N] (eq. 2.7) with the approach velocity (eq. 2.8a)
    u_x = v - v_w cos psi_w, u_y = -v_w sin psi_w, v_a = |u| [m/s]."""
    u_x = v
    u_y = 0.0
    if wind_s != 0.0:  # in still air u = (v, 0) exactly: no trigonometry
        u_x = v - wind_s * math.cos(wind_a)
        u_y = -wind_s * math.sin(wind_a)
    v_a = math.sqrt(u_x * u_x + u_y * u_y)
    sin2 = (u_y * u_y) / (v_a * v_a) if v_a > 1e-9 else 0.0
    return 0.5 * rho * cxa * u_x * v_a * (1.0 + yaw_drag * sin2)


# ================================================================================ integration and ledger
@stage
def integrate_speed(v, f_drive, f_b, f_nb, m_eff, dt):
    """Explicit Euler step of M a = F_W - F_B - F_cl - F_r - F_a - F_Wc - F_Wt with v >= 0 (brakes / hill-hold
    hold the vehicle; it never rolls backwards). Returns (v_new [m/s], a [m/s^2], hold force [N], midpoint speed
    [m/s])."""
    acc = (f_drive - f_b - f_nb) / m_eff
    v_new = v + acc * dt
    v_new = max(v_new, 0.0)
    a_act = (v_new - v) / dt
    f_hold = f_drive - f_b - f_nb - m_eff * a_act
    return v_new, a_act, f_hold, 0.5 * (v + v_new)


@stage
def book_resistance_work(x, p, res, f_b, f_hold, loss_g, loss_d, ds):
    """Energy ledger [J]: work of rolling, aero, cornering resistance, climbing, brakes (incl. hold force),
    gearbox and differential losses over the midpoint distance ds [m]."""
    r = p.wheel_radius
    x.rolling_loss += res.rolling * ds
    x.aero_loss += res.aero * ds
    x.cornering_loss += res.cornering * ds
    x.climbing_work += res.climbing * ds
    x.brake_loss += (f_b + f_hold) * ds
    x.gearbox_loss += loss_g * p.final_drive / r * ds
    x.differential_loss += loss_d / r * ds


@stage
def engine_side(x, p, locked, shaft, m_w, src, v_new, v_avg, ds):
    """Source speed and shaft work: locked — omega_E = k v; otherwise omega_E integrates (T_E - T_C)/I_src,
    the clutch dissipates T_C (omega_E - k v), and a slipping clutch locks up inelastically (generalised momentum
    conserved, the energy difference dissipated in the clutch). Returns (v_new, omega_new, omega_avg, mode)."""
    mode, gear, k, j_src = shaft.mode, shaft.gear, shaft.ratio, shaft.inertia
    omega_e, t_e, t_c = src
    dt = p.dt
    if locked:
        omega_new = k * v_new
        x.shaft_work += t_e * k * ds
        omega_avg = k * v_avg
    else:
        omega_new = omega_e + (t_e - t_c) / j_src * dt
        omega_new = max(omega_new, 0.0)
        omega_avg = 0.5 * (omega_e + omega_new)
        x.shaft_work += t_e * omega_avg * dt
        x.clutch_loss += t_c * (omega_avg - k * v_avg) * dt
        # energy the omega >= 0 clamp removed (never happens with the idle governor) goes to the clutch too
        x.clutch_loss += 0.5 * j_src * ((omega_e + (t_e - t_c) / j_src * dt) ** 2 - omega_new ** 2)
        if mode == MODE_SLIP and gear > 0:
            w_sync = k * v_new
            if w_sync >= 0.9 * p.idle_speed and (abs(omega_new - w_sync) < p.lock_slip_speed
                                              or x.slip_time > p.max_slip_time):
                # inelastic lock-up: generalised momentum conserved, energy difference dissipated in the clutch
                p_tot = m_w * v_new + j_src * k * omega_new
                v_lock = p_tot / (m_w + j_src * k * k)
                e_before = 0.5 * m_w * v_new * v_new + 0.5 * j_src * omega_new * omega_new
                e_after = 0.5 * (m_w + j_src * k * k) * v_lock * v_lock
                x.clutch_loss += e_before - e_after
                v_new = v_lock
                omega_new = k * v_lock
                mode = MODE_LOCKED
    return v_new, omega_new, omega_avg, mode


@stage
def source_energy(x, p, tables, bev, omega_avg, t_e, dt):
    """Source power [W] and energy [J]: battery terminal power of motor + auxiliaries (current, voltage, state of
    charge) for a BEV; fuel power from the consumption map (auxiliaries at 30 % efficiency) for an ICE.
    Returns (P_src [W], V_bat [V], I_bat [A])."""
    aux = p.auxiliary_load if p.auxiliary_load_on > 0.5 else 0.0
    v_bat = 0.0
    i_bat = 0.0
    if bev:
        p_term = motor_electric_power(p, tables, omega_avg, t_e) + p.auxiliary_power + aux
        i_bat = battery_current(p, p_term)
        v_bat = p.battery_open_circuit_voltage - p.battery_resistance * i_bat
        p_src = p.battery_open_circuit_voltage * i_bat
        x.state_of_charge -= p_src * dt / p.battery_capacity
    else:
        p_src = fuel_power(p, tables, omega_avg, t_e) + aux / 0.3
    x.source_energy += p_src * dt
    return p_src, v_bat, i_bat


# ================================================================================ vehicle mass
@stage
def set_mass(x, p, mass_nominal, mass):
    """The one writer of the vehicle mass m_V [kg] and of the nominal mass m_V,0 [kg] its payload is counted from:
    at the start m_V = m_V,0 + the initial payload, at a stop m_V,0 + the new payload (payload effect), and the
    mass_ramp schedule moves m_V,0 and m_V together."""
    p.mass_nominal = mass_nominal
    x.mass = mass


@jit(refcount=False)
def set_initial_mass(vehicle, payload):
    """Vehicle 0 of ``vehicle`` (a VEHICLE array) starts with m_V = m_V,0 + payload [kg] (Simulator.reset)."""
    v = vehicle[0]
    set_mass(v.state, v.params, v.params.mass_nominal, v.params.mass_nominal + payload)


# ================================================================================ slow (drifting) states
@stage
def slow_states(x, p, route, mass, v, v_new, v_avg, f_b, f_hold, ridx):
    """Drifting quantities: gearbox oil temperature, brake-disc temperature [K] (brake power in, convective
    cooling out), pad-friction random walk, window / sunroof toggles (drag factor), payload changes at stops
    (the potential energy of a changed payload is booked in the ledger)."""
    bev = p.is_bev > 0.5
    dt = p.dt
    stops = route.stops
    t_amb = p.ambient_temperature
    if p.oil_temperature_on > 0.5 and (not bev or v > 0.1):
        x.oil_temperature += (p.oil_warm_temperature - x.oil_temperature) / p.oil_time_constant * dt
    p_brake = (f_b + f_hold) * v_avg
    h = p.disc_cooling + p.disc_cooling_speed * v
    x.brake_disc_temperature += (p_brake - h * (x.brake_disc_temperature - t_amb)) / p.disc_heat_capacity * dt
    if p.pad_drift_on > 0.5 and p.pad_random_walk_std > 0.0:
        x.pad_friction_walk = _clip(x.pad_friction_walk + p.pad_random_walk_std * math.sqrt(dt) * rng_normal(x),
                                    -0.25 * p.pad_friction, 0.25 * p.pad_friction)
    if p.drag_area_on > 0.5:
        p_toggle = p.drag_toggle_rate / 3600.0 * dt
        if rng_uniform(x) < p_toggle:
            x.windows_open = 1.0 - x.windows_open
        if rng_uniform(x) < p_toggle:
            x.sunroof_open = 1.0 - x.sunroof_open
        x.drag_area_factor = 1.0 + p.drag_roof_box + x.windows_open * p.drag_windows + x.sunroof_open * p.drag_sunroof
    if p.payload_on > 0.5 and v_new < 0.05:
        kst = int(x.payload_stop_index)
        n_stops = stops.shape[0]
        s_now = x.position
        while kst < n_stops and s_now > stops[kst] + 30.0:
            kst += 1
        if kst < n_stops and abs(s_now - stops[kst]) <= 30.0:
            payload = mass - p.mass_nominal
            new_payload = payload + p.payload_change_std * rng_normal(x)
            if new_payload < p.payload_min:  # reflect at the bounds, so a stop always changes something
                new_payload = 2.0 * p.payload_min - new_payload
            elif new_payload > p.payload_max:
                new_payload = 2.0 * p.payload_max - new_payload
            new_payload = _clip(new_payload, p.payload_min, p.payload_max)
            set_mass(x, p, p.mass_nominal, p.mass_nominal + new_payload)
            x.payload_potential_energy += (new_payload - payload) * G * road_value(route.road, R_ELEV, ridx, s_now)
            kst += 1
        x.payload_stop_index = kst


# ================================================================================ scheduled effects
@stage
def ramp_value(ramp, t, s):
    """q = start + (final - start) clip((x - onset) / length, 0, 1) with x = t [s] or s [m] (by_distance); a
    step at the onset for length 0 (schedules.py)."""
    at = s if ramp.by_distance > 0.5 else t
    if ramp.length <= 0.0:
        frac = 1.0 if at >= ramp.onset else 0.0
    else:
        frac = min(1.0, max(0.0, (at - ramp.onset) / ramp.length))
    return ramp.start + (ramp.final - ramp.start) * frac


@stage
def apply_schedules(x, p):
    """The scheduled effects at the current t, s, applied before every substep: mean wind speed and direction,
    the nominal mass m_V,0 + ramp (the vehicle mass moves with it), the drag coefficient c_w (1 + ramp) and f_r0,
    f_r1, f_r4 (1 + ramp) from their unscheduled values."""
    t = x.time
    s = x.position
    if p.ramp_wind_speed.on > 0.5:
        p.wind_mean_speed = ramp_value(p.ramp_wind_speed, t, s)
        p.wind_direction = ramp_value(p.ramp_wind_direction, t, s)
    if p.ramp_mass.on > 0.5:  # the payload changed at stops stays on top of the ramped nominal mass
        d = ramp_value(p.ramp_mass, t, s)
        set_mass(x, p, p.base_mass_nominal + d, x.mass + (d - x.mass_ramp_applied))
        x.mass_ramp_applied = d
    if p.ramp_drag.on > 0.5:
        p.drag_coefficient = p.base_drag_coefficient * (1.0 + ramp_value(p.ramp_drag, t, s))
    if p.ramp_rolling.on > 0.5:
        k = 1.0 + ramp_value(p.ramp_rolling, t, s)
        p.rolling_f0 = p.base_rolling_f0 * k
        p.rolling_f1 = p.base_rolling_f1 * k
        p.rolling_f4 = p.base_rolling_f4 * k


@jit(refcount=False)
def start_schedules(vehicle):
    """apply_schedules on vehicle 0 of a VEHICLE array (Simulator.reset)."""
    v = vehicle[0]
    if v.params.schedules_on > 0.5:
        apply_schedules(v.state, v.params)


# ================================================================================ log row
@stage
def log_longitudinal(row, x, p, mass, res, cond, here):
    """Longitudinal truth: kinematics, tractive force F_xV = m_V a + F_cl + F_r + F_a + F_Wc + F_Wt (eq. 2.16b),
    rim torque T_R = F_xV r_W + 4 I_W a / r_W [N m], the driving resistances and their drifting parameters."""
    r = p.wheel_radius
    a_act = x.acceleration
    theta = here.grade
    f_xv = mass * a_act + res.climbing + res.rolling + res.aero + res.cornering
    row[L_T] = x.time
    row[L_POS] = x.position
    row[L_V] = x.speed
    row[L_A] = a_act
    row[L_FX] = f_xv
    row[L_RIM] = f_xv * r + p.wheel_inertia_4 * a_act / r
    row[L_MASS] = mass
    row[L_FR] = res.rolling_coefficient
    row[L_FR0] = cond.f0
    row[L_FR1] = cond.f1
    row[L_FR4] = cond.f4
    row[L_CXA] = cond.drag_area
    row[L_RHO] = cond.density
    row[L_GRADE] = theta
    row[L_TAMB] = p.ambient_temperature
    row[L_PAMB] = cond.pressure
    row[L_ELEV] = here.elevation
    row[L_FROLL] = res.rolling
    row[L_FAERO] = res.aero
    row[L_FCLIMB] = res.climbing
    row[L_FCORNER] = res.cornering
    row[L_DRAGF] = x.drag_area_factor
    pitch = p.pitch_gradient * a_act
    row[L_ACC_X_SENS] = a_act + G * math.sin(theta + pitch)


@stage
def log_lateral(row, x, p, here, cond, lat):
    """Lateral truth: curvatures [1/m], yaw rate, slip and steering angles [rad], bank, wind, cornering
    stiffnesses [N/rad], lateral acceleration and the sensed one (with body roll), heading."""
    v_new = x.speed
    yaw = lat.yaw_rate
    row[L_CURV] = here.curvature
    row[L_PATHCURV] = yaw / v_new if v_new > 0.5 else (math.tan(lat.steer_angle) / p.wheelbase)
    row[L_BANK] = here.bank
    row[L_WIND_S] = cond.wind_speed
    row[L_WIND_A] = cond.wind_angle
    row[L_CSF] = cond.cornering_front
    row[L_CSR] = cond.cornering_rear
    row[L_AY] = lat.acceleration
    roll = p.roll_gradient * lat.acceleration
    row[L_ACC_Y_SENS] = lat.specific_force + G * math.sin(roll)
    row[L_YAW] = yaw
    row[L_BETA] = lat.side_slip
    row[L_DELTA] = lat.steer_angle
    row[L_HEAD] = here.heading + x.heading_error


@stage
def log_drivetrain(row, x, p, yaw, phi, f_drive, brk, src):
    """Drive-train and brake truth: source torque and speed, gear, clutch state, brake pressures and friction,
    oil and disc temperatures, source power / energy, battery, and the wheel speeds — kinematic (yaw) plus
    longitudinal slip s = F_x / c_xW (eq. 2.2, 2.3a)."""
    r = p.wheel_radius
    v_new = x.speed
    mode = x.clutch_mode
    f_bf = brk.front
    f_br = brk.rear
    row[L_TE] = x.engine_torque
    row[L_WE] = x.engine_speed
    row[L_GEAR] = x.gear
    row[L_CLUTCH] = 1.0 if mode == MODE_LOCKED else (0.5 if mode == MODE_SLIP else 0.0)
    row[L_PBF] = x.brake_pressure_front
    row[L_PBR] = x.brake_pressure_rear
    row[L_MU] = brk.friction_coefficient
    row[L_OIL] = x.oil_temperature
    row[L_LOSSF] = phi
    row[L_PSRC] = src.power
    row[L_ESRC] = x.source_energy
    driven = p.driven_axle
    n_dr = 4.0 if driven > 1.5 else 2.0
    cx = p.longitudinal_stiffness
    slip_drv = f_drive / n_dr / cx
    slip_f = -0.5 * f_bf / cx + (slip_drv if driven > 0.5 else 0.0)
    slip_r = -0.5 * f_br / cx + (slip_drv if (driven < 0.5 or driven > 1.5) else 0.0)
    half_f = 0.5 * p.track_front * yaw
    half_r = 0.5 * p.track_rear * yaw
    row[L_WFL] = max(0.0, (v_new - half_f) / r * (1.0 + slip_f))
    row[L_WFR] = max(0.0, (v_new + half_f) / r * (1.0 + slip_f))
    row[L_WRL] = max(0.0, (v_new - half_r) / r * (1.0 + slip_r))
    row[L_WRR] = max(0.0, (v_new + half_r) / r * (1.0 + slip_r))
    row[L_VBAT] = src.battery_voltage
    row[L_IBAT] = src.battery_current
    row[L_SOC] = x.state_of_charge
    row[L_FBRAKE] = f_bf + f_br
    row[L_DISC_T] = x.brake_disc_temperature


# ================================================================================ one substep
@stage
def substep_constants(p):
    """Factors that depend on p only, computed once per advance / run call instead of once per substep (the same
    expressions, so the results are bitwise those of the per-substep form): brake-pressure lag a_b = exp(-dt /
    tau_B), sin(delta_toe), gust factors a_g = exp(-dt / tau_g), q_g = sqrt(1 - a_g^2) (0, 0 without wind)."""
    dt = p.dt
    a_b = math.exp(-dt / p.brake_time_constant)
    sin_toe = math.sin(p.toe_in)
    a_g = 0.0
    q_g = 0.0
    if p.wind_on > 0.5:
        a_g = math.exp(-dt / p.wind_gust_time_constant)
        q_g = math.sqrt(1.0 - a_g * a_g)
    return a_b, sin_toe, a_g, q_g


@jit(refcount=False)
def substep(x, p, c, tables, route, log, constants):
    """Advance the state x by one step dt = p.dt and write one log row while the log has room (a sequence of the
    stages above); ``constants`` = substep_constants(p)."""
    dt = p.dt
    a_b, sin_toe, a_g, q_g = constants
    t = x.time
    s = x.position
    v = x.speed
    r = p.wheel_radius
    mass = x.mass

    here = road_attributes(x, p, route.road, s)
    sth = math.sin(here.grade)
    cth = math.cos(here.grade)
    cond = conditions(x, p, here, a_g, q_g)
    phi = cond.loss_factor

    traction, regen, friction, steer, gear_req = command(x, p, c, tables, route, here, phi)
    f_req = traction - regen

    lat = lateral_single_track(x, p, steer, mass, cond.cornering_front, cond.cornering_rear, here.bank, cth)
    f_corner = cornering_resistance(lat.force_front, lat.force_rear, lat.slip_front, lat.slip_rear,
                                    cond.cornering_front, p.toe_in, sin_toe, v)
    path_following(x, v, lat.side_slip, lat.yaw_rate, here.curvature, dt)

    shaft = engage(x, p, tables, f_req, phi, gear_req)
    m_w = wheel_side_mass(p, mass)
    src_t = source_torques(x, p, tables, shaft, gear_req, f_req, phi)
    t_w, loss_g, loss_d = wheel_torque(p, tables, shaft, src_t, v, phi)
    f_drive = t_w / r

    brk = brakes(x, p, friction, r, a_b)
    f_b = brk.front + brk.rear

    f_cl = climbing_force(mass, sth)
    fr, f_roll = rolling_resistance(cond.f0, cond.f1, cond.f4, v, mass, cth, here.bank)
    f_aero = aero_drag(cond.density, cond.drag_area, v, cond.wind_speed, cond.wind_angle, p.yaw_drag_factor)
    res = Resistances(f_cl, fr, f_roll, f_aero, f_corner)

    # integrate (midpoint-consistent ledger: drive work = delta kinetic + climbing + dissipation to round-off)
    gear = shaft.gear
    k = shaft.ratio
    j_src = shaft.inertia
    locked = p.is_bev > 0.5 or (shaft.mode == MODE_LOCKED and gear > 0)
    m_eff = m_w + j_src * k * k if locked else m_w
    v_new, a_act, f_hold, v_avg = integrate_speed(v, f_drive, f_b, f_cl + f_roll + f_aero + f_corner, m_eff, dt)
    ds = v_avg * dt
    book_resistance_work(x, p, res, f_b, f_hold, loss_g, loss_d, ds)
    v_new, omega_new, omega_avg, mode = engine_side(x, p, locked, shaft, m_w, src_t, v_new, v_avg, ds)
    t_e = src_t.engine_torque
    x.position = s + ds
    x.speed = v_new
    x.acceleration = a_act
    x.time = t + dt
    x.gear = gear
    x.clutch_mode = mode
    x.engine_speed = omega_new
    x.engine_torque = t_e
    x.clutch_torque = src_t.clutch_torque

    p_src, v_bat, i_bat = source_energy(x, p, tables, p.is_bev > 0.5, omega_avg, t_e, dt)
    src = Source(p_src, v_bat, i_bat)
    slow_states(x, p, route, mass, v, v_new, v_avg, f_b, f_hold, here.segment)
    n_log = int(x.log_rows)
    if n_log < log.shape[1]:  # one row of truth at this substep; column-major: one contiguous array per channel
        row = log[:, n_log]
        log_longitudinal(row, x, p, mass, res, cond, here)
        log_lateral(row, x, p, here, cond, lat)
        log_drivetrain(row, x, p, lat.yaw_rate, phi, f_drive, brk, src)
    x.log_rows = n_log + 1


@jit
def is_done(x, p):
    """End of the road (or drive cycle), the time limit or the distance limit reached."""
    return x.position >= p.road_length - 1e-6 or x.time >= p.time_end - 1e-9 or x.position >= p.distance_end


@jit(refcount=False)
def advance(x, p, c, tables, route, log, n_substeps):
    """n_substeps substeps with a constant command (the step API), the scheduled effects applied before each."""
    constants = substep_constants(p)
    for _ in range(n_substeps):
        if p.schedules_on > 0.5:
            apply_schedules(x, p)
        substep(x, p, c, tables, route, log, constants)


@jit(refcount=False)
def run(x, p, c, tables, route, log, max_substeps):
    """Substeps until the trip is done (end of road / cycle, duration, distance) or max_substeps; returns the
    number of substeps run."""
    n = 0
    constants = substep_constants(p)
    while n < max_substeps and not is_done(x, p):
        if p.schedules_on > 0.5:
            apply_schedules(x, p)
        substep(x, p, c, tables, route, log, constants)
        n += 1
    return n


# ================================================================================ entry points (one vehicle)
@jit(refcount=False)
def advance_one(vehicle, tabs, ti, road, stops, cycle, log, n_substeps):
    """``advance`` on vehicle 0 of a VEHICLE array (the Simulator's step)."""
    v = vehicle[0]
    advance(v.state, v.params, v.command, Tables(tabs, ti), Route(road, stops, cycle), log, n_substeps)


@jit(refcount=False)
def run_one(vehicle, tabs, ti, road, stops, cycle, log, max_substeps):
    """``run`` on vehicle 0 of a VEHICLE array (the Simulator's whole trips); returns the substeps run."""
    v = vehicle[0]
    return run(v.state, v.params, v.command, Tables(tabs, ti), Route(road, stops, cycle), log, max_substeps)


@jit
def done_one(vehicle):
    """``is_done`` of vehicle 0 of a VEHICLE array."""
    return is_done(vehicle[0].state, vehicle[0].params)
