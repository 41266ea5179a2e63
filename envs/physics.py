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

from ._jit import jit, stage
from .driver import driver_force, steering_law
from .drivetrain import (
    allocate,
    battery_current,
    forward_wheel_torque,
    fuel_power,
    inverse_wheel_torque,
    motor_electric_power,
    oil_loss_factor,
    regen_capacity,
    source_side_inertia,
    speed_ratio,
    torque_limits,
    wheel_side_mass,
)
from .layout import (
    C_FRICTION,
    C_GEAR_REQ,
    C_REGEN,
    C_STEER,
    C_TRACTION,
    C_USE_DRIVER,
    L_A,
    L_ACC_X_SENS,
    L_ACC_Y_SENS,
    L_AY,
    L_BANK,
    L_BETA,
    L_CLUTCH,
    L_CSF,
    L_CSR,
    L_CURV,
    L_CXA,
    L_DELTA,
    L_DISC_T,
    L_DRAGF,
    L_ELEV,
    L_ESRC,
    L_FAERO,
    L_FBRAKE,
    L_FCLIMB,
    L_FCORNER,
    L_FR,
    L_FR0,
    L_FR1,
    L_FR4,
    L_FROLL,
    L_FX,
    L_GEAR,
    L_GRADE,
    L_HEAD,
    L_IBAT,
    L_LOSSF,
    L_MASS,
    L_MU,
    L_OIL,
    L_PAMB,
    L_PATHCURV,
    L_PBF,
    L_PBR,
    L_POS,
    L_PSRC,
    L_RHO,
    L_RIM,
    L_SOC,
    L_T,
    L_TAMB,
    L_TE,
    L_V,
    L_VBAT,
    L_WE,
    L_WFL,
    L_WFR,
    L_WIND_A,
    L_WIND_S,
    L_WRL,
    L_WRR,
    L_YAW,
    MODE_LOCKED,
    MODE_OPEN,
    MODE_SLIP,
    P_AB_F,
    P_AB_R,
    P_AREA,
    P_AUX_EXTRA,
    P_AUX_ON,
    P_AUX_P,
    P_BANK_GAIN,
    P_BANK_MAX,
    P_BANK_ON,
    P_BANK_SCALE,
    P_BARO_H,
    P_BARO_ON,
    P_BAT_CAP,
    P_BAT_R,
    P_BAT_VOC,
    P_BRAKE_SHARE,
    P_BRAKE_TAU,
    P_CF,
    P_CR,
    P_CW,
    P_CX_SLIP,
    P_DISC_C,
    P_DISC_H,
    P_DISC_HV,
    P_DN_HI,
    P_DN_LO,
    P_DRAG_ON,
    P_DRAG_RATE,
    P_DRAG_ROOFBOX,
    P_DRAG_SUN,
    P_DRAG_WIN,
    P_DRIVEN,
    P_DT,
    P_FR0,
    P_FR1,
    P_FR4,
    P_ID,
    P_IDLE,
    P_IW4,
    P_IZ,
    P_KIND_BEV,
    P_L,
    P_LAUNCH,
    P_LF,
    P_LOCK_SLIP,
    P_LR,
    P_MASS0,
    P_MAX_SLIP,
    P_MAX_SPEED,
    P_MU0,
    P_N_GEARS,
    P_OIL_ON,
    P_OIL_TAU,
    P_OIL_WARM,
    P_P_AMB,
    P_P_MAX,
    P_PAD_ON,
    P_PAD_RW_STD,
    P_PAD_TCOEF,
    P_PAD_TREF,
    P_PAYLOAD_MAX,
    P_PAYLOAD_MIN,
    P_PAYLOAD_ON,
    P_PAYLOAD_STD,
    P_PITCH_GRAD,
    P_RATIO0,
    P_RB_F,
    P_RB_R,
    P_ROAD_LEN,
    P_ROLL_GRAD,
    P_RW,
    P_S_END,
    P_SHIFT_MIN,
    P_STEER_MAX,
    P_SYNC_TAU,
    P_T_AMB,
    P_T_END,
    P_TOE,
    P_TRACK_F,
    P_TRACK_R,
    P_UP_HI,
    P_UP_LO,
    P_WARM_DIST,
    P_WARM_FACTOR,
    P_WARM_ON,
    P_WET_F1,
    P_WET_FACTOR,
    P_WET_ON,
    P_WIND_DIR,
    P_WIND_DIR_STD,
    P_WIND_GUST_STD,
    P_WIND_GUST_TAU,
    P_WIND_MEAN,
    P_WIND_ON,
    P_WINTER_CS,
    P_WINTER_ON,
    P_WINTER_RR,
    P_YAW_DRAG,
    R_BANK,
    R_CURV,
    R_ELEV,
    R_GRADE,
    R_HEAD,
    R_S,
    S_A,
    S_AY,
    S_AY_MAX,
    S_AY_WARN_N,
    S_BETA,
    S_D_AERO,
    S_D_BRAKE,
    S_D_CLUTCH,
    S_D_CORNER,
    S_D_DIFF,
    S_D_GEARBOX,
    S_D_ROLL,
    S_DELTA,
    S_DISC_T,
    S_DRAGF,
    S_E_PAYLOAD_PE,
    S_E_SOURCE,
    S_EPSI,
    S_EY,
    S_GEAR,
    S_GUST,
    S_LAST_SHIFT,
    S_MASS,
    S_MODE,
    S_MU_RW,
    S_NLOG,
    S_OIL_T,
    S_OMEGA_E,
    S_PAYLOAD_STOP,
    S_PBF,
    S_PBR,
    S_POS,
    S_RIDX,
    S_SLIP_TIMER,
    S_SOC,
    S_SUN_OPEN,
    S_T,
    S_TC,
    S_TE,
    S_V,
    S_W_CLIMB,
    S_W_SHAFT,
    S_WIN_OPEN,
    S_WIND_DIR_DEV,
    S_YAW,
)
from .numerics import rng_normal, rng_uniform, road_blend, road_locate, road_value, road_weight

LATERAL_VALIDITY_LIMIT = 4.0  # m/s^2, single-track model validity (section 2.5.1)


@jit
def _clip(x, lo, hi):
    if x < lo:
        return lo
    if x > hi:
        return hi
    return x


@jit
def _select_gear(P, tabs, ti, gear, mode, omega_e, v, f_req, phi, t, last_shift):
    """Shift strategy: load-dependent up/downshift speeds with hysteresis guards, kickdown, gear choice when the
    clutch is open. Returns the wanted gear."""
    n = int(P[P_N_GEARS])
    if gear < 1:
        return 1
    if t - last_shift < P[P_SHIFT_MIN]:
        return gear
    r = P[P_RW]
    k_base = P[P_ID] / r
    if mode == MODE_OPEN or (mode == MODE_SLIP and v < 3.0):
        # choose the gear for the current speed: highest gear whose input speed is above the downshift speed
        best = 1
        for g in range(1, n + 1):
            if P[P_RATIO0 + g - 1] * k_base * v >= P[P_DN_HI]:
                best = g
        return best if mode == MODE_OPEN else gear
    if mode != MODE_LOCKED:
        return gear
    _, t_max = torque_limits(P, tabs, ti, omega_e, v)
    f_max = forward_wheel_torque(P, tabs, ti, gear, t_max, omega_e, phi)[0] / r
    load = _clip(f_req / f_max, 0.0, 1.0) if f_max > 1.0 else 1.0
    up = P[P_UP_LO] + load * (P[P_UP_HI] - P[P_UP_LO])
    dn = P[P_DN_LO] + load * (P[P_DN_HI] - P[P_DN_LO])
    if omega_e > up and gear < n:
        w_next = v * k_base * P[P_RATIO0 + gear]
        _, tn_max = torque_limits(P, tabs, ti, w_next, v)
        fn = forward_wheel_torque(P, tabs, ti, gear + 1, tn_max, w_next, phi)[0]
        load_n = _clip(f_req / (fn / r), 0.0, 1.0) if fn > r else 1.0
        dn_n = P[P_DN_LO] + load_n * (P[P_DN_HI] - P[P_DN_LO])
        if w_next > 1.05 * dn_n or omega_e > P[P_MAX_SPEED]:
            return gear + 1
        return gear
    if gear > 1:
        w_prev = v * k_base * P[P_RATIO0 + gear - 2]
        if omega_e < dn and w_prev < 0.95 * P[P_UP_HI]:
            return gear - 1
        if f_req > 0.97 * f_max and w_prev < 0.9 * P[P_UP_HI]:
            _, tp_max = torque_limits(P, tabs, ti, w_prev, v)
            fp = forward_wheel_torque(P, tabs, ti, gear - 1, tp_max, w_prev, phi)[0]
            if fp / r > 1.02 * f_max:
                return gear - 1  # kickdown
    return gear


# ================================================================================ road and environment
@stage
def road_attributes(X, P, road, s):
    """Road at position s [m]: index (kept in X for the next search), grade theta [rad], curvature kappa [1/m],
    heading [rad], elevation [m] and bank phi_r [rad] (measured bank, scaled, plus the curvature-proportional
    design bank, limited)."""
    ridx = road_locate(road[R_S], s, int(X[S_RIDX]))
    X[S_RIDX] = ridx
    w = road_weight(road, ridx, s)
    theta = road_blend(road, R_GRADE, ridx, w)
    kappa = road_blend(road, R_CURV, ridx, w)
    heading = road_blend(road, R_HEAD, ridx, w)
    elev = road_blend(road, R_ELEV, ridx, w)
    bank = 0.0
    if P[P_BANK_ON] > 0.5:
        bank = P[P_BANK_SCALE] * road_blend(road, R_BANK, ridx, w) + _clip(P[P_BANK_GAIN] * kappa, -P[P_BANK_MAX],
                                                                         P[P_BANK_MAX])
    return ridx, theta, kappa, heading, elev, bank


@stage
def air_density(P, elev):
    """Ambient pressure p_a [Pa] (barometric with height when enabled) and air density rho_a = p_a / (R_a T_a)
    [kg/m^3] (eq. 2.7)."""
    p_amb = P[P_P_AMB]
    if P[P_BARO_ON] > 0.5:
        p_amb = p_amb * math.exp(-elev / P[P_BARO_H])
    return p_amb, p_amb / (R_AIR * P[P_T_AMB])


@stage
def rolling_coefficients(P, s):
    """Rolling-resistance coefficients f_r0, f_r1 [s/m], f_r4 [s^4/m^4] of f_r(v) = f_r0 + f_r1 v + f_r4 v^4
    (eq. 2.10) with the tyre warm-up, winter and wet-road factors; and the cornering-stiffness factor."""
    rr_mult = 1.0
    cs_mult = 1.0
    fr1_add = 0.0
    if P[P_WARM_ON] > 0.5:
        rr_mult *= 1.0 + (P[P_WARM_FACTOR] - 1.0) * math.exp(-s / P[P_WARM_DIST])
    if P[P_WINTER_ON] > 0.5:
        rr_mult *= P[P_WINTER_RR]
        cs_mult *= P[P_WINTER_CS]
    if P[P_WET_ON] > 0.5:
        rr_mult *= P[P_WET_FACTOR]
        fr1_add += P[P_WET_F1]
    return P[P_FR0] * rr_mult, P[P_FR1] * rr_mult + fr1_add, P[P_FR4] * rr_mult, cs_mult


@stage
def wind(X, P, heading, a_g, q_g, rng):
    """Wind speed v_w >= 0 [m/s] and its angle psi_w to the vehicle's heading [rad] (eq. 2.8): mean wind plus
    first-order Gauss-Markov gusts of speed and direction: x_k+1 = a_g x_k + sigma q_g n_k with a_g = exp(-dt / tau_g),
    q_g = sqrt(1 - a_g^2) (substep_constants)."""
    wind_s = 0.0
    wind_a = 0.0
    if P[P_WIND_ON] > 0.5:
        X[S_GUST] = a_g * X[S_GUST] + P[P_WIND_GUST_STD] * q_g * rng_normal(rng)
        X[S_WIND_DIR_DEV] = a_g * X[S_WIND_DIR_DEV] + P[P_WIND_DIR_STD] * q_g * rng_normal(rng)
        wind_s = P[P_WIND_MEAN] + X[S_GUST]
        wind_s = max(wind_s, 0.0)
        wind_a = P[P_WIND_DIR] + X[S_WIND_DIR_DEV] - (heading + X[S_EPSI])
        wind_a = math.atan2(math.sin(wind_a), math.cos(wind_a))
    return wind_s, wind_a


# ================================================================================ command
@stage
def _regen_capacity_if_braking(force, P, tabs, ti, gear, mode, omega_e, v, phi):
    """regen_capacity [N] for a braking request (force < 0); 0 otherwise, where allocate() does not read it (the
    capacity costs two loss-map look-ups per substep)."""
    return regen_capacity(P, tabs, ti, gear, mode, omega_e, v, phi) if force < 0.0 else 0.0


@stage
def command(X, P, tabs, ti, road, stops, cycle, rng, cmd, ridx, s, v, theta, dt, gear, mode, omega_e, phi):
    """The wheel-force request [N] split into traction, regenerative and friction braking, the steering angle
    [rad] and a gear request (-1: automatic) — from the built-in driver, a signed wheel force through the default
    allocator, or an explicit command (a NaN steering angle: the built-in steering law)."""
    gear_req = -1
    use = cmd[C_USE_DRIVER]
    if 0.5 < use < 1.5:  # built-in driver
        f_dem = driver_force(X, P, road, stops, cycle, rng, ridx, s, v, theta, dt)
        traction, regen, friction = allocate(f_dem, _regen_capacity_if_braking(f_dem, P, tabs, ti, gear, mode,
                                                                                omega_e, v, phi))
        steer = steering_law(X, P, road, ridx, s, v)
    else:
        if use > 1.5:  # signed wheel force through the default allocator
            f_cmd = cmd[C_TRACTION]
            traction, regen, friction = allocate(f_cmd, _regen_capacity_if_braking(f_cmd, P, tabs, ti, gear, mode,
                                                                                    omega_e, v, phi))
        else:
            traction = cmd[C_TRACTION]
            regen = cmd[C_REGEN]
            friction = cmd[C_FRICTION]
            gear_req = int(cmd[C_GEAR_REQ])
        steer = cmd[C_STEER]
        if math.isnan(steer):  # NaN: the built-in steering law keeps the vehicle on the road
            steer = steering_law(X, P, road, ridx, s, v)
    return traction, regen, friction, steer, gear_req


# ================================================================================ lateral dynamics
@stage
def lateral_single_track(X, P, steer, v, mass, c_f, c_r, bank, cth, dt):
    """Linear single-track model (section 2.5.1, eq. 2.12), integrated implicitly (stable at any speed),
    kinematic below 1 m/s, with the lateral gravity g sin(phi_r) cos(theta) of the road bank.

    Slip angles alpha_12 = delta - beta - l_12 r/v, alpha_34 = -beta + l_34 r/v [rad]; axle forces
    F_y = c alpha [N]. Updates beta, yaw rate r [rad/s], delta and the lateral-acceleration statistics in X.
    Returns (delta, beta, yaw, alpha_f, alpha_r, F_y12, F_y34, sensed specific force [m/s^2], a_y [m/s^2])."""
    delta = _clip(steer, -P[P_STEER_MAX], P[P_STEER_MAX])
    X[S_DELTA] = delta
    lf = P[P_LF]
    lr = P[P_LR]
    wb = P[P_L]
    g_lat = G * math.sin(bank) * cth
    if v < 1.0:
        beta = lr / wb * delta
        yaw = v * math.tan(delta) / wb
        a_y_kin = v * yaw
        fy_f = mass * (a_y_kin - g_lat) * lr / wb
        fy_r = mass * (a_y_kin - g_lat) * lf / wb
        alpha_f = fy_f / c_f
        alpha_r = fy_r / c_r
    else:
        a11 = -(c_f + c_r) / (mass * v)
        a12 = -(c_f * lf - c_r * lr) / (mass * v * v) - 1.0
        a21 = -(c_f * lf - c_r * lr) / P[P_IZ]
        a22 = -(c_f * lf * lf + c_r * lr * lr) / (P[P_IZ] * v)
        b1 = c_f / (mass * v) * delta + g_lat / v
        b2 = c_f * lf / P[P_IZ] * delta
        m11 = 1.0 - dt * a11
        m12 = -dt * a12
        m21 = -dt * a21
        m22 = 1.0 - dt * a22
        r1 = X[S_BETA] + dt * b1
        r2 = X[S_YAW] + dt * b2
        det = m11 * m22 - m12 * m21
        beta = (r1 * m22 - m12 * r2) / det
        yaw = (m11 * r2 - m21 * r1) / det
        alpha_f = delta - beta - lf * yaw / v
        alpha_r = -beta + lr * yaw / v
        fy_f = c_f * alpha_f
        fy_r = c_r * alpha_r
    X[S_BETA] = beta
    X[S_YAW] = yaw
    spec_fy = (fy_f * math.cos(delta) + fy_r) / mass  # what a lateral accelerometer senses (no gravity)
    a_y = spec_fy + g_lat  # kinematic lateral acceleration
    X[S_AY] = a_y
    if abs(a_y) > abs(X[S_AY_MAX]):
        X[S_AY_MAX] = a_y
    if abs(a_y) > LATERAL_VALIDITY_LIMIT:
        X[S_AY_WARN_N] += 1.0
    return delta, beta, yaw, alpha_f, alpha_r, fy_f, fy_r, spec_fy, a_y


@stage
def cornering_resistance(fy_f, fy_r, alpha_f, alpha_r, c_f, toe, sin_toe, v):
    """F_Wc + F_Wt [N]: cornering resistance F_y12 sin(alpha_12) + F_y34 sin(alpha_34) (eq. 2.13-2.15) plus the
    toe-in resistance c_12 delta_toe sin(delta_toe) (section 2.4.5), faded in below 0.5 m/s."""
    return fy_f * math.sin(alpha_f) + fy_r * math.sin(alpha_r) + c_f * toe * sin_toe * min(1.0, v / 0.5)


@stage
def path_following(X, v, beta, yaw, kappa, dt):
    """Lateral offset e_y [m] and heading error e_psi [rad] relative to the road centre line."""
    X[S_EY] += v * math.sin(X[S_EPSI] + beta) * dt
    X[S_EPSI] += (yaw - v * kappa) * dt


# ================================================================================ drive-train (eq. 2.17)
@stage
def gear_and_clutch(X, P, tabs, ti, gear, mode, omega_e, v, f_req, phi, t, gear_req):
    """ICE gear selection (or the requested gear) and clutch mode (open / slipping / locked). A gear change
    opens a locked clutch into slip and rescales the engine speed so the source-side kinetic energy
    1/2 I_G(G) omega_E^2 is unchanged. Returns (gear, mode, omega_E [rad/s])."""
    new_gear = gear
    if gear_req >= 0:
        new_gear = min(gear_req, int(P[P_N_GEARS]))
    else:
        new_gear = _select_gear(P, tabs, ti, gear, mode, omega_e, v, f_req, phi, t, X[S_LAST_SHIFT])
    if new_gear != gear:
        if mode == MODE_LOCKED:
            mode = MODE_SLIP
        j_old = source_side_inertia(P, gear)
        j_new = source_side_inertia(P, new_gear)
        omega_e = omega_e * math.sqrt(j_old / j_new)
        gear = new_gear
        X[S_SLIP_TIMER] = 0.0
        X[S_LAST_SHIFT] = t
    if gear == 0:
        mode = MODE_OPEN
    else:
        w_in0 = speed_ratio(P, gear) * v
        if mode == MODE_LOCKED and omega_e < 0.9 * P[P_IDLE]:
            mode = MODE_SLIP if f_req > 0.0 else MODE_OPEN  # avoid stalling
            X[S_SLIP_TIMER] = 0.0
        elif mode == MODE_OPEN and (f_req > 0.0 or w_in0 > 1.2 * P[P_IDLE]):
            mode = MODE_SLIP
            X[S_SLIP_TIMER] = 0.0
    return gear, mode, omega_e


@stage
def source_torques(X, P, tabs, ti, bev, gear, mode, gear_req, omega_e, w_in, j_src, f_req, r, phi, v, dt):
    """Source torque T_E and clutch torque T_C [N m]: locked (BEV always) — the torque that yields the wheel
    force request through eq. 2.17 within the source limits; slipping — clutch torque in the direction of slip,
    the engine speed governed towards the gearbox input (launch) speed; open — idle governor.
    Returns (omega_E [rad/s], T_E, T_C)."""
    t_c = 0.0
    t_e = 0.0
    locked = bev or mode == MODE_LOCKED
    if locked:
        omega_e = w_in
    t_min, t_max = torque_limits(P, tabs, ti, omega_e, v)
    # the source torque that yields the wheel force request (eq. 2.17 inverted at the gearbox input speed), where
    # the mode uses it: locked (a BEV unless sailing) or slipping
    t_req = 0.0
    if (bev and gear_req != 0) or (not bev and (mode == MODE_LOCKED or mode == MODE_SLIP)):
        t_req = _clip(inverse_wheel_torque(P, tabs, ti, 1 if bev else gear, f_req * r, w_in, phi), t_min, t_max)
    if locked:
        t_e = t_req
        t_c = t_e
    else:
        target = P[P_IDLE]
        if mode == MODE_SLIP:
            slip = omega_e - w_in
            if slip > 0.0:
                t_c = max(0.0, t_req)
            elif slip < 0.0:
                t_c = min(0.0, t_req)
            if f_req > 0.0 and w_in < P[P_LAUNCH]:
                target = P[P_LAUNCH]
            elif w_in > P[P_IDLE]:
                target = w_in
            X[S_SLIP_TIMER] += dt
        t_e = _clip(t_c + j_src * (target - omega_e) / P[P_SYNC_TAU], t_min, t_max)
    return omega_e, t_e, t_c


@stage
def wheel_torque(P, tabs, ti, bev, gear, mode, t_e, t_c, omega_e, w_in, r, v, phi):
    """Wheel torque T_W [N m] through gearbox and differential (eq. 2.17, with their load-dependent losses):
    from T_E when locked, from the clutch torque T_C when slipping. Returns (T_W, gearbox loss, diff. loss)."""
    if gear == 0:  # neutral: the differential's spin loss at its input speed
        torque_in = 0.0
        omega_in = P[P_ID] / r * v
    elif bev or mode == MODE_LOCKED:
        torque_in = t_e
        omega_in = omega_e
    else:
        torque_in = t_c
        omega_in = w_in
    return forward_wheel_torque(P, tabs, ti, gear, torque_in, omega_in, phi)


# ================================================================================ brakes
@stage
def brakes(X, P, friction, r, a_b):
    """Friction brakes: the command F_B = sum p_B A_B r_B mu / r_W [N] is split front/rear, the line pressures
    p_B [Pa] follow with a first-order lag, the pad friction mu depends on the disc temperature (and a random
    walk) when enabled; a_b = exp(-dt / tau_B) (substep_constants). Returns (mu, F_B front [N], F_B rear [N])."""
    mu = P[P_MU0]
    if P[P_PAD_ON] > 0.5:
        mu = P[P_MU0] * (1.0 + P[P_PAD_TCOEF] * (X[S_DISC_T] - P[P_PAD_TREF])) + X[S_MU_RW]
        mu = max(mu, 0.05)
    f_brk = max(0.0, friction)
    pf_cmd = _clip(P[P_BRAKE_SHARE] * f_brk * r / (2.0 * P[P_AB_F] * P[P_RB_F] * P[P_MU0]), 0.0, P[P_P_MAX])
    pr_cmd = _clip((1.0 - P[P_BRAKE_SHARE]) * f_brk * r / (2.0 * P[P_AB_R] * P[P_RB_R] * P[P_MU0]), 0.0, P[P_P_MAX])
    X[S_PBF] = a_b * X[S_PBF] + (1.0 - a_b) * pf_cmd
    X[S_PBR] = a_b * X[S_PBR] + (1.0 - a_b) * pr_cmd
    f_bf = 2.0 * X[S_PBF] * P[P_AB_F] * P[P_RB_F] * mu / r
    f_br = 2.0 * X[S_PBR] * P[P_AB_R] * P[P_RB_R] * mu / r
    return mu, f_bf, f_br


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
def book_resistance_work(X, P, f_roll, f_aero, f_corner, f_cl, f_b, f_hold, loss_g, loss_d, r, ds):
    """Energy ledger [J]: work of rolling, aero, cornering resistance, climbing, brakes (incl. hold force),
    gearbox and differential losses over the midpoint distance ds [m]."""
    X[S_D_ROLL] += f_roll * ds
    X[S_D_AERO] += f_aero * ds
    X[S_D_CORNER] += f_corner * ds
    X[S_W_CLIMB] += f_cl * ds
    X[S_D_BRAKE] += (f_b + f_hold) * ds
    X[S_D_GEARBOX] += loss_g * P[P_ID] / r * ds
    X[S_D_DIFF] += loss_d / r * ds


@stage
def engine_side(X, P, locked, mode, gear, k, j_src, m_w, t_e, t_c, omega_e, v_new, v_avg, ds, dt):
    """Source speed and shaft work: locked — omega_E = k v; otherwise omega_E integrates (T_E - T_C)/I_src,
    the clutch dissipates T_C (omega_E - k v), and a slipping clutch locks up inelastically (generalised momentum
    conserved, the energy difference dissipated in the clutch). Returns (v_new, omega_new, omega_avg, mode)."""
    if locked:
        omega_new = k * v_new
        X[S_W_SHAFT] += t_e * k * ds
        omega_avg = k * v_avg
    else:
        omega_new = omega_e + (t_e - t_c) / j_src * dt
        omega_new = max(omega_new, 0.0)
        omega_avg = 0.5 * (omega_e + omega_new)
        X[S_W_SHAFT] += t_e * omega_avg * dt
        X[S_D_CLUTCH] += t_c * (omega_avg - k * v_avg) * dt
        # energy the omega >= 0 clamp removed (never happens with the idle governor) goes to the clutch too
        X[S_D_CLUTCH] += 0.5 * j_src * ((omega_e + (t_e - t_c) / j_src * dt) ** 2 - omega_new ** 2)
        if mode == MODE_SLIP and gear > 0:
            w_sync = k * v_new
            if w_sync >= 0.9 * P[P_IDLE] and (abs(omega_new - w_sync) < P[P_LOCK_SLIP]
                                              or X[S_SLIP_TIMER] > P[P_MAX_SLIP]):
                # inelastic lock-up: generalised momentum conserved, energy difference dissipated in the clutch
                p_tot = m_w * v_new + j_src * k * omega_new
                v_lock = p_tot / (m_w + j_src * k * k)
                e_before = 0.5 * m_w * v_new * v_new + 0.5 * j_src * omega_new * omega_new
                e_after = 0.5 * (m_w + j_src * k * k) * v_lock * v_lock
                X[S_D_CLUTCH] += e_before - e_after
                v_new = v_lock
                omega_new = k * v_lock
                mode = MODE_LOCKED
    return v_new, omega_new, omega_avg, mode


@stage
def source_energy(X, P, tabs, ti, bev, omega_avg, t_e, dt):
    """Source power [W] and energy [J]: battery terminal power of motor + auxiliaries (current, voltage, state of
    charge) for a BEV; fuel power from the consumption map (auxiliaries at 30 % efficiency) for an ICE.
    Returns (P_src [W], V_bat [V], I_bat [A])."""
    aux = P[P_AUX_EXTRA] if P[P_AUX_ON] > 0.5 else 0.0
    v_bat = 0.0
    i_bat = 0.0
    if bev:
        p_term = motor_electric_power(P, tabs, ti, omega_avg, t_e) + P[P_AUX_P] + aux
        i_bat = battery_current(P, p_term)
        v_bat = P[P_BAT_VOC] - P[P_BAT_R] * i_bat
        p_src = P[P_BAT_VOC] * i_bat
        X[S_SOC] -= p_src * dt / P[P_BAT_CAP]
    else:
        p_src = fuel_power(P, tabs, ti, omega_avg, t_e) + aux / 0.3
    X[S_E_SOURCE] += p_src * dt
    return p_src, v_bat, i_bat


# ================================================================================ slow (drifting) states
@stage
def slow_states(X, P, road, stops, rng, bev, mass, v, v_new, v_avg, f_b, f_hold, ridx, dt):
    """Drifting quantities: gearbox oil temperature, brake-disc temperature [K] (brake power in, convective
    cooling out), pad-friction random walk, window / sunroof toggles (drag factor), payload changes at stops
    (the potential energy of a changed payload is booked in the ledger)."""
    t_amb = P[P_T_AMB]
    if P[P_OIL_ON] > 0.5 and (not bev or v > 0.1):
        X[S_OIL_T] += (P[P_OIL_WARM] - X[S_OIL_T]) / P[P_OIL_TAU] * dt
    p_brake = (f_b + f_hold) * v_avg
    h = P[P_DISC_H] + P[P_DISC_HV] * v
    X[S_DISC_T] += (p_brake - h * (X[S_DISC_T] - t_amb)) / P[P_DISC_C] * dt
    if P[P_PAD_ON] > 0.5 and P[P_PAD_RW_STD] > 0.0:
        X[S_MU_RW] = _clip(X[S_MU_RW] + P[P_PAD_RW_STD] * math.sqrt(dt) * rng_normal(rng),
                           -0.25 * P[P_MU0], 0.25 * P[P_MU0])
    if P[P_DRAG_ON] > 0.5:
        p_toggle = P[P_DRAG_RATE] / 3600.0 * dt
        if rng_uniform(rng) < p_toggle:
            X[S_WIN_OPEN] = 1.0 - X[S_WIN_OPEN]
        if rng_uniform(rng) < p_toggle:
            X[S_SUN_OPEN] = 1.0 - X[S_SUN_OPEN]
        X[S_DRAGF] = 1.0 + P[P_DRAG_ROOFBOX] + X[S_WIN_OPEN] * P[P_DRAG_WIN] + X[S_SUN_OPEN] * P[P_DRAG_SUN]
    if P[P_PAYLOAD_ON] > 0.5 and v_new < 0.05:
        kst = int(X[S_PAYLOAD_STOP])
        n_stops = stops.shape[0]
        s_now = X[S_POS]
        while kst < n_stops and s_now > stops[kst] + 30.0:
            kst += 1
        if kst < n_stops and abs(s_now - stops[kst]) <= 30.0:
            payload = mass - P[P_MASS0]
            new_payload = payload + P[P_PAYLOAD_STD] * rng_normal(rng)
            if new_payload < P[P_PAYLOAD_MIN]:  # reflect at the bounds, so a stop always changes something
                new_payload = 2.0 * P[P_PAYLOAD_MIN] - new_payload
            elif new_payload > P[P_PAYLOAD_MAX]:
                new_payload = 2.0 * P[P_PAYLOAD_MAX] - new_payload
            new_payload = _clip(new_payload, P[P_PAYLOAD_MIN], P[P_PAYLOAD_MAX])
            X[S_MASS] = P[P_MASS0] + new_payload
            X[S_E_PAYLOAD_PE] += (new_payload - payload) * G * road_value(road, R_ELEV, ridx, s_now)
            kst += 1
        X[S_PAYLOAD_STOP] = kst


# ================================================================================ log row
@stage
def log_longitudinal(row, X, P, t_new, v_new, a_act, mass, f_cl, f_roll, f_aero, f_corner, fr, fr0, fr1, fr4, cxa,
                     rho, theta, p_amb, elev):
    """Longitudinal truth: kinematics, tractive force F_xV = m_V a + F_cl + F_r + F_a + F_Wc + F_Wt (eq. 2.16b),
    rim torque T_R = F_xV r_W + 4 I_W a / r_W [N m], the driving resistances and their drifting parameters."""
    r = P[P_RW]
    f_xv = mass * a_act + f_cl + f_roll + f_aero + f_corner
    row[L_T] = t_new
    row[L_POS] = X[S_POS]
    row[L_V] = v_new
    row[L_A] = a_act
    row[L_FX] = f_xv
    row[L_RIM] = f_xv * r + P[P_IW4] * a_act / r
    row[L_MASS] = mass
    row[L_FR] = fr
    row[L_FR0] = fr0
    row[L_FR1] = fr1
    row[L_FR4] = fr4
    row[L_CXA] = cxa
    row[L_RHO] = rho
    row[L_GRADE] = theta
    row[L_TAMB] = P[P_T_AMB]
    row[L_PAMB] = p_amb
    row[L_ELEV] = elev
    row[L_FROLL] = f_roll
    row[L_FAERO] = f_aero
    row[L_FCLIMB] = f_cl
    row[L_FCORNER] = f_corner
    row[L_DRAGF] = X[S_DRAGF]
    pitch = P[P_PITCH_GRAD] * a_act
    row[L_ACC_X_SENS] = a_act + G * math.sin(theta + pitch)


@stage
def log_lateral(row, X, P, v_new, kappa, yaw, delta, beta, bank, wind_s, wind_a, c_f, c_r, a_y, spec_fy, heading):
    """Lateral truth: curvatures [1/m], yaw rate, slip and steering angles [rad], bank, wind, cornering
    stiffnesses [N/rad], lateral acceleration and the sensed one (with body roll), heading."""
    row[L_CURV] = kappa
    row[L_PATHCURV] = yaw / v_new if v_new > 0.5 else (math.tan(delta) / P[P_L])
    row[L_BANK] = bank
    row[L_WIND_S] = wind_s
    row[L_WIND_A] = wind_a
    row[L_CSF] = c_f
    row[L_CSR] = c_r
    row[L_AY] = a_y
    roll = P[P_ROLL_GRAD] * a_y
    row[L_ACC_Y_SENS] = spec_fy + G * math.sin(roll)
    row[L_YAW] = yaw
    row[L_BETA] = beta
    row[L_DELTA] = delta
    row[L_HEAD] = heading + X[S_EPSI]


@stage
def log_drivetrain(row, X, P, v_new, yaw, t_e, omega_new, gear, mode, mu, phi, p_src, f_drive, f_bf, f_br, f_b,
                   v_bat, i_bat):
    """Drive-train and brake truth: source torque and speed, gear, clutch state, brake pressures and friction,
    oil and disc temperatures, source power / energy, battery, and the wheel speeds — kinematic (yaw) plus
    longitudinal slip s = F_x / c_xW (eq. 2.2, 2.3a)."""
    r = P[P_RW]
    row[L_TE] = t_e
    row[L_WE] = omega_new
    row[L_GEAR] = gear
    row[L_CLUTCH] = 1.0 if mode == MODE_LOCKED else (0.5 if mode == MODE_SLIP else 0.0)
    row[L_PBF] = X[S_PBF]
    row[L_PBR] = X[S_PBR]
    row[L_MU] = mu
    row[L_OIL] = X[S_OIL_T]
    row[L_LOSSF] = phi
    row[L_PSRC] = p_src
    row[L_ESRC] = X[S_E_SOURCE]
    driven = P[P_DRIVEN]
    n_dr = 4.0 if driven > 1.5 else 2.0
    cx = P[P_CX_SLIP]
    slip_drv = f_drive / n_dr / cx
    slip_f = -0.5 * f_bf / cx + (slip_drv if driven > 0.5 else 0.0)
    slip_r = -0.5 * f_br / cx + (slip_drv if (driven < 0.5 or driven > 1.5) else 0.0)
    half_f = 0.5 * P[P_TRACK_F] * yaw
    half_r = 0.5 * P[P_TRACK_R] * yaw
    row[L_WFL] = max(0.0, (v_new - half_f) / r * (1.0 + slip_f))
    row[L_WFR] = max(0.0, (v_new + half_f) / r * (1.0 + slip_f))
    row[L_WRL] = max(0.0, (v_new - half_r) / r * (1.0 + slip_r))
    row[L_WRR] = max(0.0, (v_new + half_r) / r * (1.0 + slip_r))
    row[L_VBAT] = v_bat
    row[L_IBAT] = i_bat
    row[L_SOC] = X[S_SOC]
    row[L_FBRAKE] = f_b
    row[L_DISC_T] = X[S_DISC_T]


# ================================================================================ one substep
@stage
def substep_constants(P):
    """Factors that depend on P only, computed once per advance / run call instead of once per substep (the same
    expressions, so the results are bitwise those of the per-substep form): brake-pressure lag a_b = exp(-dt /
    tau_B), sin(delta_toe), gust factors a_g = exp(-dt / tau_g), q_g = sqrt(1 - a_g^2) (0, 0 without wind)."""
    dt = P[P_DT]
    a_b = math.exp(-dt / P[P_BRAKE_TAU])
    sin_toe = math.sin(P[P_TOE])
    a_g = 0.0
    q_g = 0.0
    if P[P_WIND_ON] > 0.5:
        a_g = math.exp(-dt / P[P_WIND_GUST_TAU])
        q_g = math.sqrt(1.0 - a_g * a_g)
    return a_b, sin_toe, a_g, q_g


@jit(refcount=False)
def substep(X, P, tabs, ti, road, stops, cycle, rng, cmd, log, constants):
    """Advance the state X by one step dt = P[P_DT] and write one log row (a sequence of the stages above);
    ``constants`` = substep_constants(P)."""
    dt = P[P_DT]
    a_b, sin_toe, a_g, q_g = constants
    t = X[S_T]
    s = X[S_POS]
    v = X[S_V]
    bev = P[P_KIND_BEV] > 0.5
    r = P[P_RW]
    mass = X[S_MASS]

    ridx, theta, kappa, heading, elev, bank = road_attributes(X, P, road, s)
    sth = math.sin(theta)
    cth = math.cos(theta)
    p_amb, rho = air_density(P, elev)
    fr0, fr1, fr4, cs_mult = rolling_coefficients(P, s)
    c_f = P[P_CF] * cs_mult
    c_r = P[P_CR] * cs_mult
    cxa = P[P_CW] * P[P_AREA] * X[S_DRAGF]
    wind_s, wind_a = wind(X, P, heading, a_g, q_g, rng)
    phi = oil_loss_factor(P, X[S_OIL_T]) if P[P_OIL_ON] > 0.5 else 1.0
    gear = int(X[S_GEAR])
    mode = int(X[S_MODE])
    omega_e = X[S_OMEGA_E]

    traction, regen, friction, steer, gear_req = command(X, P, tabs, ti, road, stops, cycle, rng, cmd, ridx, s, v,
                                                         theta, dt, gear, mode, omega_e, phi)
    f_req = traction - regen

    delta, beta, yaw, alpha_f, alpha_r, fy_f, fy_r, spec_fy, a_y = lateral_single_track(
        X, P, steer, v, mass, c_f, c_r, bank, cth, dt)
    f_corner = cornering_resistance(fy_f, fy_r, alpha_f, alpha_r, c_f, P[P_TOE], sin_toe, v)
    path_following(X, v, beta, yaw, kappa, dt)

    if bev:
        mode = MODE_LOCKED
        gear = 1
    else:
        gear, mode, omega_e = gear_and_clutch(X, P, tabs, ti, gear, mode, omega_e, v, f_req, phi, t, gear_req)
    k = speed_ratio(P, gear)
    w_in = k * v
    j_src = source_side_inertia(P, gear)
    m_w = wheel_side_mass(P, mass)
    omega_e, t_e, t_c = source_torques(X, P, tabs, ti, bev, gear, mode, gear_req, omega_e, w_in, j_src, f_req, r,
                                       phi, v, dt)
    t_w, loss_g, loss_d = wheel_torque(P, tabs, ti, bev, gear, mode, t_e, t_c, omega_e, w_in, r, v, phi)
    f_drive = t_w / r

    mu, f_bf, f_br = brakes(X, P, friction, r, a_b)
    f_b = f_bf + f_br

    f_cl = climbing_force(mass, sth)
    fr, f_roll = rolling_resistance(fr0, fr1, fr4, v, mass, cth, bank)
    f_aero = aero_drag(rho, cxa, v, wind_s, wind_a, P[P_YAW_DRAG])

    # integrate (midpoint-consistent ledger: drive work = delta kinetic + climbing + dissipation to round-off)
    locked = bev or (mode == MODE_LOCKED and gear > 0)
    m_eff = m_w + j_src * k * k if locked else m_w
    v_new, a_act, f_hold, v_avg = integrate_speed(v, f_drive, f_b, f_cl + f_roll + f_aero + f_corner, m_eff, dt)
    ds = v_avg * dt
    book_resistance_work(X, P, f_roll, f_aero, f_corner, f_cl, f_b, f_hold, loss_g, loss_d, r, ds)
    v_new, omega_new, omega_avg, mode = engine_side(X, P, locked, mode, gear, k, j_src, m_w, t_e, t_c, omega_e,
                                                    v_new, v_avg, ds, dt)
    X[S_POS] = s + ds
    X[S_V] = v_new
    X[S_A] = a_act
    X[S_T] = t + dt
    X[S_GEAR] = gear
    X[S_MODE] = mode
    X[S_OMEGA_E] = omega_new
    X[S_TE] = t_e
    X[S_TC] = t_c

    p_src, v_bat, i_bat = source_energy(X, P, tabs, ti, bev, omega_avg, t_e, dt)
    slow_states(X, P, road, stops, rng, bev, mass, v, v_new, v_avg, f_b, f_hold, ridx, dt)
    n_log = int(X[S_NLOG])
    if n_log < log.shape[1]:  # one row of truth at this substep; column-major: one contiguous array per channel
        row = log[:, n_log]
        log_longitudinal(row, X, P, t + dt, v_new, a_act, mass, f_cl, f_roll, f_aero, f_corner, fr, fr0, fr1, fr4, cxa,
                         rho, theta, p_amb, elev)
        log_lateral(row, X, P, v_new, kappa, yaw, delta, beta, bank, wind_s, wind_a, c_f, c_r, a_y, spec_fy, heading)
        log_drivetrain(row, X, P, v_new, yaw, t_e, omega_new, gear, mode, mu, phi, p_src, f_drive, f_bf, f_br, f_b,
                       v_bat, i_bat)
    X[S_NLOG] = n_log + 1


@jit
def is_done(X, P):
    return X[S_POS] >= P[P_ROAD_LEN] - 1e-6 or X[S_T] >= P[P_T_END] - 1e-9 or X[S_POS] >= P[P_S_END]


@jit(refcount=False)
def advance(X, P, tabs, ti, road, stops, cycle, rng, cmd, log, n_substeps):
    """n_substeps substeps with a constant command (the step API)."""
    constants = substep_constants(P)
    for _ in range(n_substeps):
        substep(X, P, tabs, ti, road, stops, cycle, rng, cmd, log, constants)


@jit(refcount=False)
def run(X, P, tabs, ti, road, stops, cycle, rng, cmd, log, max_substeps):
    """Substeps until the trip is done (end of road / cycle, duration, distance) or max_substeps; returns the
    number of substeps run."""
    n = 0
    constants = substep_constants(P)
    while n < max_substeps and not is_done(X, P):
        substep(X, P, tabs, ti, road, stops, cycle, rng, cmd, log, constants)
        n += 1
    return n
