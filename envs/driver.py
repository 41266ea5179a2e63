"""The built-in driver: speed tracking with preview (speed limits, curves, stops) or drive-cycle following,
and a preview steering law that follows the road curvature. Jitted; runs inside the simulator's substep loop.

Speed plan (computed once per road): v_allow(s) = min(speed_limit_factor v_limit(s), sqrt(a_lat,max / |kappa(s)|)),
then a backward pass v_plan(s) = min(v_allow(s), sqrt(v_plan(s + ds)^2 + 2 b_plan ds)) so the driver brakes in time
for curves and lower limits. Stops: v <= sqrt(2 b_plan d_stop), dwell uniform in [dwell_min, dwell_max] seconds.

Speed control: a_des = clip(a_ff + (v_des - v)/tau, -b_max, a_max(v)); wheel force
F = m_nom a_des + m_nom g (sin theta + f_r0 cos theta) + rho/2 c_w A v^2 + m_nom I with an integral term I (the
driver knows only the nominal vehicle). v_des carries a natural speed variation (Ornstein-Uhlenbeck) except in
'poor excitation' cruise stretches.

Steering: delta_W = (l + EG v^2) kappa(s + t_p v) - (l + EG v^2) 2 e_L / L^2, with the lateral error
e_L = e_y + L (e_psi + beta) at the look-ahead distance L = max(5 m, t_L v) (pure-pursuit-like feedback).
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import numpy as np
from roadload.units import G

from ._jit import jit
from .layout import (
    P_AREA, P_CW, P_CYCLE_MODE, P_DRV_ALAT, P_DRV_AMAX, P_DRV_BMAX, P_DRV_BPLAN, P_DRV_DWELL_MAX, P_DRV_DWELL_MIN,
    P_DRV_EG, P_DRV_KI, P_DRV_LOOKAHEAD, P_DRV_MARGIN, P_DRV_PEDAL_TAU, P_DRV_PREVIEW, P_DRV_RHO, P_DRV_TAU,
    P_DRV_VAR_STD, P_DRV_VAR_TAU, P_FR0, P_L, P_MASS0, R_CRUISE, R_CURV, R_VPLAN, S_BETA, S_DRV_F, S_DRV_I,
    S_DRV_VAR, S_DRV_VAR2, S_DWELL, S_DWELL_LEFT, S_EPSI, S_EY, S_STOP_IDX, S_T,
)
from .numerics import rng_normal, rng_uniform, road_value, road_value_at, road_value_near


@dataclass
class DriverConfig:
    """Driver parameters (SI): lateral acceleration limit for curve speeds [m/s^2], max acceleration / braking
    [m/s^2], planning deceleration [m/s^2], speed time constant [s], integral gain [1/s], speed variation std [m/s]
    and time constant [s], steering look-ahead / preview times [s], stop dwell range [s], margin below the plan
    [m/s], speed-limit factor [-], pedal/brake actuation time constant [s]."""

    lateral_acceleration_limit: float = 2.0
    max_acceleration: float = 1.8
    max_deceleration: float = 4.0
    planning_deceleration: float = 1.2
    speed_time_constant: float = 1.5
    integral_gain: float = 0.3
    speed_variation_std: float = 0.6
    speed_variation_time_constant: float = 20.0
    steering_lookahead_time: float = 1.0
    steering_preview_time: float = 0.3
    dwell_min: float = 3.0
    dwell_max: float = 15.0
    speed_margin: float = 0.5
    speed_limit_factor: float = 1.0
    pedal_time_constant: float = 0.25

    def __post_init__(self) -> None:
        for k, v in asdict(self).items():
            if not isinstance(v, (int, float)) or not math.isfinite(v) or v < 0:
                raise ValueError(f"driver.{k}: must be a finite number >= 0, got {v!r}")
        for k in ("lateral_acceleration_limit", "max_acceleration", "max_deceleration", "planning_deceleration",
                  "speed_time_constant", "speed_variation_time_constant", "steering_lookahead_time",
                  "speed_limit_factor"):
            if getattr(self, k) <= 0:
                raise ValueError(f"driver.{k}: must be > 0")
        if self.dwell_max < self.dwell_min:
            raise ValueError("driver.dwell_max: must be >= dwell_min")


def speed_plan(distance: np.ndarray, curvature: np.ndarray, speed_limit: np.ndarray, cfg: DriverConfig) -> np.ndarray:
    """v_plan(s) [m/s]: speed limits and curve speeds with a backward deceleration pass (see module doc)."""
    v_allow = speed_limit * cfg.speed_limit_factor
    with np.errstate(divide="ignore"):
        v_curve = np.sqrt(cfg.lateral_acceleration_limit / np.maximum(np.abs(curvature), 1e-9))
    v_allow = np.minimum(v_allow, v_curve)
    return _backward_pass(np.asarray(distance, float), np.asarray(v_allow, float), cfg.planning_deceleration)


@jit
def _backward_pass(s, v_allow, decel):
    out = v_allow.copy()
    for i in range(s.size - 2, -1, -1):
        lim = math.sqrt(out[i + 1] ** 2 + 2.0 * decel * (s[i + 1] - s[i]))
        if lim < out[i]:
            out[i] = lim
    return out


def cruise_stretches(distance: np.ndarray, fraction: float, stretch_length: float,
                     rng: np.random.Generator) -> np.ndarray:
    """0/1 flags over the road grid: non-overlapping cruise stretches covering about ``fraction`` of the road."""
    length = float(distance[-1])
    flags = np.zeros(distance.size)
    if fraction <= 0 or length <= 0:
        return flags
    n_slots = max(1, int(length // stretch_length))
    n_on = int(round(fraction * n_slots))
    for slot in rng.choice(n_slots, size=n_on, replace=False):
        a = slot * stretch_length
        flags[(distance >= a) & (distance < a + stretch_length)] = 1.0
    return flags


def pack_driver(P: np.ndarray, cfg: DriverConfig, understeer_gradient: float, rho_nominal: float) -> None:
    P[P_DRV_ALAT] = cfg.lateral_acceleration_limit
    P[P_DRV_AMAX] = cfg.max_acceleration
    P[P_DRV_BMAX] = cfg.max_deceleration
    P[P_DRV_BPLAN] = cfg.planning_deceleration
    P[P_DRV_TAU] = cfg.speed_time_constant
    P[P_DRV_KI] = cfg.integral_gain
    P[P_DRV_VAR_STD] = cfg.speed_variation_std
    P[P_DRV_VAR_TAU] = cfg.speed_variation_time_constant
    P[P_DRV_LOOKAHEAD] = cfg.steering_lookahead_time
    P[P_DRV_PREVIEW] = cfg.steering_preview_time
    P[P_DRV_DWELL_MIN] = cfg.dwell_min
    P[P_DRV_DWELL_MAX] = cfg.dwell_max
    P[P_DRV_MARGIN] = cfg.speed_margin
    P[P_DRV_PEDAL_TAU] = cfg.pedal_time_constant
    P[P_DRV_EG] = understeer_gradient
    P[P_DRV_RHO] = rho_nominal


@jit(inline=True)
def steering_law(X, P, road, ridx, s, v):
    """Wheel steer angle delta_W [rad] from curvature preview and look-ahead lateral error (module doc); ridx: the
    road segment at s, where the preview search starts."""
    gain = P[P_L] + P[P_DRV_EG] * v * v
    kappa = road_value_near(road, R_CURV, s + P[P_DRV_PREVIEW] * v, ridx)
    look = P[P_DRV_LOOKAHEAD] * v
    if look < 5.0:
        look = 5.0
    e_l = X[S_EY] + look * (X[S_EPSI] + X[S_BETA])
    return gain * kappa - gain * 2.0 * e_l / (look * look)


@jit
def driver_force(X, P, road, stops, cycle, rng, ridx, s, v, theta, dt):
    """Signed wheel-force demand [N] of the built-in driver (road mode or drive-cycle mode)."""
    g = G
    m = P[P_MASS0]
    t = X[S_T]
    a_ff = 0.0
    hold = False
    if P[P_CYCLE_MODE] > 0.5:
        v_des = road_value_at(cycle, 1, t + 0.1)
        v_next = road_value_at(cycle, 1, t + 1.1)
        a_ff = v_next - v_des
        if v_des < 0.05 and v_next < 0.05:
            hold = True
    else:
        v_plan = road_value_near(road, R_VPLAN, s + 0.7 * v, ridx)
        k = int(X[S_STOP_IDX])
        n_stops = stops.shape[0]
        while k < n_stops and X[S_DWELL] < 0.5 and s > stops[k] + 2.0:
            k += 1  # passed a stop without halting (e.g. external control before)
        v_stop = 1e9
        if k < n_stops:
            if X[S_DWELL] > 0.5:
                v_stop = 0.0
                X[S_DWELL_LEFT] -= dt
                if X[S_DWELL_LEFT] <= 0.0:
                    X[S_DWELL] = 0.0
                    k += 1
            else:
                d = stops[k] - s - 1.0
                if d < 0.0:
                    d = 0.0
                v_stop = math.sqrt(2.0 * P[P_DRV_BPLAN] * d)
                if d < 4.0 and v < 0.3:
                    X[S_DWELL] = 1.0
                    X[S_DWELL_LEFT] = P[P_DRV_DWELL_MIN] + (P[P_DRV_DWELL_MAX] - P[P_DRV_DWELL_MIN]) * rng_uniform(rng)
                    v_stop = 0.0
        X[S_STOP_IDX] = k
        v_target = v_plan if v_plan < v_stop else v_stop
        # natural speed variation, frozen in cruise stretches (poor excitation)
        if road_value(road, R_CRUISE, ridx, s) < 0.5:
            a = math.exp(-dt / P[P_DRV_VAR_TAU])
            X[S_DRV_VAR] = a * X[S_DRV_VAR] + P[P_DRV_VAR_STD] * math.sqrt(1.0 - a * a) * rng_normal(rng)
            X[S_DRV_VAR2] += (X[S_DRV_VAR] - X[S_DRV_VAR2]) * dt / 4.0  # smooth the variation (4 s low-pass)
            v_des = v_target - P[P_DRV_MARGIN] + X[S_DRV_VAR2]
        else:
            v_des = v_target - P[P_DRV_MARGIN]
        if v_des > v_target:
            v_des = v_target
        if v_des < 0.0:
            v_des = 0.0
        if v_stop == 0.0 or v_target < 0.3:
            v_des = 0.0
            hold = v < 0.05
        # anticipate the plan's deceleration (v dv/ds over the next ~2 s)
        look = 2.0 * v + 5.0
        v_ahead = road_value_near(road, R_VPLAN, s + look, ridx)
        if v_stop < v_ahead:
            v_ahead = v_stop
        if v_ahead < v_des:
            a_ff = (v_ahead * v_ahead - v_des * v_des) / (2.0 * look)
    if hold:
        X[S_DRV_I] = 0.0
        X[S_DRV_F] = -0.3 * m * g
        return X[S_DRV_F]
    err = v_des - v
    a_max = P[P_DRV_AMAX] * (1.0 - 0.5 * min(1.0, v / 40.0))
    a_des = a_ff + err / P[P_DRV_TAU]
    if v_des == 0.0 and a_des > -0.6:
        a_des = -0.6  # final approach to a stop: gentle constant deceleration
    saturated = False
    if a_des > a_max:
        a_des = a_max
        saturated = True
    elif a_des < -P[P_DRV_BMAX]:
        a_des = -P[P_DRV_BMAX]
        saturated = True
    if not saturated and v_des > 0.5:
        X[S_DRV_I] += P[P_DRV_KI] * err * dt / P[P_DRV_TAU]
        lim = 0.3 * g
        if X[S_DRV_I] > lim:
            X[S_DRV_I] = lim
        elif X[S_DRV_I] < -lim:
            X[S_DRV_I] = -lim
    f_res = m * g * (math.sin(theta) + P[P_FR0] * math.cos(theta)) + 0.5 * P[P_DRV_RHO] * P[P_CW] * P[P_AREA] * v * v
    f = 1.05 * m * a_des + f_res + m * X[S_DRV_I]
    X[S_DRV_F] += (f - X[S_DRV_F]) * dt / (P[P_DRV_PEDAL_TAU] + dt)  # pedal / brake actuation lag
    return X[S_DRV_F]
