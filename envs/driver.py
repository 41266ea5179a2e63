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
from .layout import R_CRUISE, R_CURV, R_VPLAN
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


def pack_driver(params: np.void, cfg: DriverConfig, understeer_gradient: float, rho_nominal: float) -> None:
    """Write the driver settings (and the vehicle's understeer gradient [s^2/m], the air density [kg/m^3] the driver
    assumes) into a parameter record."""
    values = {
        "driver_lateral_acceleration": cfg.lateral_acceleration_limit, "driver_max_acceleration": cfg.max_acceleration,
        "driver_max_deceleration": cfg.max_deceleration, "driver_planning_deceleration": cfg.planning_deceleration,
        "driver_speed_time_constant": cfg.speed_time_constant, "driver_integral_gain": cfg.integral_gain,
        "driver_variation_std": cfg.speed_variation_std,
        "driver_variation_time_constant": cfg.speed_variation_time_constant,
        "steering_lookahead_time": cfg.steering_lookahead_time, "steering_preview_time": cfg.steering_preview_time,
        "dwell_min": cfg.dwell_min, "dwell_max": cfg.dwell_max, "driver_speed_margin": cfg.speed_margin,
        "pedal_time_constant": cfg.pedal_time_constant, "understeer_gradient": understeer_gradient,
        "driver_air_density": rho_nominal,
    }
    for name, value in values.items():
        params[name] = value


@jit(inline=True)
def steering_law(x, p, road, ridx):
    """Wheel steer angle delta_W [rad] from curvature preview and look-ahead lateral error (module doc); ridx: the
    road segment at the vehicle's position, where the preview search starts."""
    s = x.position
    v = x.speed
    gain = p.wheelbase + p.understeer_gradient * v * v
    kappa = road_value_near(road, R_CURV, s + p.steering_preview_time * v, ridx)
    look = p.steering_lookahead_time * v
    if look < 5.0:
        look = 5.0
    e_l = x.lateral_offset + look * (x.heading_error + x.side_slip_angle)
    return gain * kappa - gain * 2.0 * e_l / (look * look)


@jit(inline=True)
def _cycle_target(x, cycle):
    """Drive-cycle mode: (desired speed [m/s] 0.1 s ahead, feed-forward acceleration [m/s^2] over the next second,
    hold at standstill)."""
    t = x.time
    v_des = road_value_at(cycle, 1, t + 0.1)
    v_next = road_value_at(cycle, 1, t + 1.1)
    return v_des, v_next - v_des, v_des < 0.05 and v_next < 0.05


@jit(inline=True)
def _stop_speed(x, p, stops):
    """Speed limit [m/s] of the next stop line: sqrt(2 b_plan d) on the approach, 0 while dwelling (the dwell is
    drawn uniform in [dwell_min, dwell_max] on arrival); a stop passed without halting is skipped. 1e9: none."""
    s = x.position
    dt = p.dt
    k = int(x.stop_index)
    n_stops = stops.shape[0]
    while k < n_stops and x.dwelling < 0.5 and s > stops[k] + 2.0:
        k += 1  # passed a stop without halting (e.g. external control before)
    v_stop = 1e9
    if k < n_stops:
        if x.dwelling > 0.5:
            v_stop = 0.0
            x.dwell_left -= dt
            if x.dwell_left <= 0.0:
                x.dwelling = 0.0
                k += 1
        else:
            d = stops[k] - s - 1.0
            if d < 0.0:
                d = 0.0
            v_stop = math.sqrt(2.0 * p.driver_planning_deceleration * d)
            if d < 4.0 and x.speed < 0.3:
                x.dwelling = 1.0
                x.dwell_left = p.dwell_min + (p.dwell_max - p.dwell_min) * rng_uniform(x)
                v_stop = 0.0
    x.stop_index = k
    return v_stop


@jit(inline=True)
def _varied_speed(x, p, road, ridx, v_target):
    """The desired speed below the target by the margin, with the natural speed variation (Ornstein-Uhlenbeck,
    low-passed over 4 s; frozen in the cruise stretches of poor excitation), limited to [0, v_target]."""
    dt = p.dt
    if road_value(road, R_CRUISE, ridx, x.position) < 0.5:
        a = math.exp(-dt / p.driver_variation_time_constant)
        x.driver_speed_variation = (a * x.driver_speed_variation
                                    + p.driver_variation_std * math.sqrt(1.0 - a * a) * rng_normal(x))
        # smooth the variation (4 s low-pass)
        x.driver_speed_variation_smooth += (x.driver_speed_variation - x.driver_speed_variation_smooth) * dt / 4.0
        v_des = v_target - p.driver_speed_margin + x.driver_speed_variation_smooth
    else:
        v_des = v_target - p.driver_speed_margin
    if v_des > v_target:
        v_des = v_target
    if v_des < 0.0:
        v_des = 0.0
    return v_des


@jit(inline=True)
def _road_target(x, p, road, stops, ridx):
    """Road mode: (desired speed [m/s] from the speed plan 0.7 s ahead, the next stop and the speed variation,
    feed-forward deceleration anticipating the plan v dv/ds over ~2 s [m/s^2], hold at standstill)."""
    s = x.position
    v = x.speed
    v_plan = road_value_near(road, R_VPLAN, s + 0.7 * v, ridx)
    v_stop = _stop_speed(x, p, stops)
    v_target = v_plan if v_plan < v_stop else v_stop
    v_des = _varied_speed(x, p, road, ridx, v_target)
    hold = False
    if v_stop == 0.0 or v_target < 0.3:
        v_des = 0.0
        hold = v < 0.05
    a_ff = 0.0
    look = 2.0 * v + 5.0
    v_ahead = road_value_near(road, R_VPLAN, s + look, ridx)
    if v_stop < v_ahead:
        v_ahead = v_stop
    if v_ahead < v_des:
        a_ff = (v_ahead * v_ahead - v_des * v_des) / (2.0 * look)
    return v_des, a_ff, hold


@jit(inline=True)
def _desired_acceleration(x, p, v_des, a_ff):
    """a_des = clip(a_ff + (v_des - v) / tau, -b_max, a_max(v)) (-0.6 m/s^2 at least on the final approach to a
    stop), and the integral term of the speed error while unsaturated (limited to 0.3 g)."""
    v = x.speed
    err = v_des - v
    a_max = p.driver_max_acceleration * (1.0 - 0.5 * min(1.0, v / 40.0))
    a_des = a_ff + err / p.driver_speed_time_constant
    if v_des == 0.0 and a_des > -0.6:
        a_des = -0.6  # final approach to a stop: gentle constant deceleration
    saturated = False
    if a_des > a_max:
        a_des = a_max
        saturated = True
    elif a_des < -p.driver_max_deceleration:
        a_des = -p.driver_max_deceleration
        saturated = True
    if not saturated and v_des > 0.5:
        x.driver_integral += p.driver_integral_gain * err * p.dt / p.driver_speed_time_constant
        lim = 0.3 * G
        if x.driver_integral > lim:
            x.driver_integral = lim
        elif x.driver_integral < -lim:
            x.driver_integral = -lim
    return a_des


@jit
def driver_force(x, p, route, ridx, theta):
    """Signed wheel-force demand [N] of the built-in driver (road mode or drive-cycle mode; module doc): the
    desired acceleration with the nominal vehicle's resistances F = 1.05 m a_des + m g (sin theta + f_r0 cos theta)
    + rho/2 c_w A v^2 + m I, through the pedal lag; at standstill a hold force -0.3 m g. ridx: the road segment at
    the vehicle's position, theta: the grade there [rad]."""
    road, stops, cycle = route
    m = p.mass_nominal
    if p.cycle_mode > 0.5:
        v_des, a_ff, hold = _cycle_target(x, cycle)
    else:
        v_des, a_ff, hold = _road_target(x, p, road, stops, ridx)
    if hold:
        x.driver_integral = 0.0
        x.driver_force = -0.3 * m * G
        return x.driver_force
    v = x.speed
    dt = p.dt
    a_des = _desired_acceleration(x, p, v_des, a_ff)
    f_res = (m * G * (math.sin(theta) + p.rolling_f0 * math.cos(theta))
             + 0.5 * p.driver_air_density * p.drag_coefficient * p.frontal_area * v * v)
    f = 1.05 * m * a_des + f_res + m * x.driver_integral
    x.driver_force += (f - x.driver_force) * dt / (p.pedal_time_constant + dt)  # pedal / brake actuation lag
    return x.driver_force
