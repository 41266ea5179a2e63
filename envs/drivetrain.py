"""Drive-train model (eq. 2.17), jitted: loss maps, forward / inverse torque transmission, torque limits,
fuel and electric power, and the wheel-force allocator.

Torque path with the clutch engaged (eq. 2.17):
    T_G = T_E,   T_D = T_G i_G(G) - phi f(T_G, omega_G, G),   omega_D = omega_G / i_G(G),
    T_W = T_D i_D - phi f(T_D, omega_D),
where f are the gearbox / differential loss maps [N m at the output side] and phi >= 1 the oil-temperature loss
factor. Loss torques fade linearly to zero below 1 rad/s shaft speed so nothing sticks at standstill.
The rotational-inertia term -I_red(G) theta_ddot_W and the brake torques of eq. 2.17 are applied in
``physics.substep``.
"""

from __future__ import annotations

import math

from roadload.units import STANDARD_TEMPERATURE

from ._jit import jit

from .layout import MODE_LOCKED, T_DIFFLOSS, T_DRAG, T_FUEL, T_FULLLOAD, T_GBLOSS, T_MOTORLOSS
from .numerics import invert_through_map_at, segment, table1, table2, table2_at


@jit(inline=True)
def gear_ratio(p, gear):
    """i_G(G); 0 for neutral."""
    if gear < 1:
        return 0.0
    return p.gear_ratio[gear - 1]


@jit(inline=True)
def source_side_inertia(p, gear):
    """Inertia on the engine side of the clutch [kg m^2]: I_E + I_C + I_G(G) (I_G lumped to the input side)."""
    j = p.source_inertia + p.clutch_inertia
    if gear >= 1:
        j += p.gear_inertia[gear - 1]
    return j


@jit(inline=True)
def wheel_side_mass(p, mass):
    """m_V + (4 I_W + i_D^2 I_D) / r_W^2 [kg]: translational mass plus the inertias that always turn with the
    wheels."""
    r = p.wheel_radius
    return mass + (p.wheel_inertia_4 + p.final_drive * p.final_drive * p.differential_inertia) / (r * r)


@jit(inline=True)
def speed_ratio(p, gear):
    """k(G) = i_G i_D / r_W: gearbox input speed [rad/s] per vehicle speed [m/s]."""
    return gear_ratio(p, gear) * p.final_drive / p.wheel_radius


@jit(inline=True)
def _fade(omega):
    if omega >= 1.0:
        return 1.0
    if omega <= 0.0:
        return 0.0
    return omega


@jit(inline=True)
def oil_loss_factor(p, oil_temperature):
    """phi(T_oil) = 1 + (phi_cold - 1) clip((T_warm - T_oil)/(T_warm - 293.15), 0, 1.5)."""
    x = (p.oil_warm_temperature - oil_temperature) / (p.oil_warm_temperature - STANDARD_TEMPERATURE)
    if x < 0.0:
        x = 0.0
    elif x > 1.5:
        x = 1.5
    return 1.0 + (p.oil_cold_loss_factor - 1.0) * x


@jit(inline=True)
def loss_map_speeds(tables, i_g, gear, omega_in):
    """Where the loss maps are read at gearbox input speed omega_G [rad/s] in gear G >= 1 with ratio i_G:
    (omega_D = omega_G / i_G [rad/s], its segment (j, w) on the differential map's speed axis, omega_G's segment on
    gear G's gearbox map's speed axis). A substep reads both maps at one input speed twice, inverted for the source
    torque (inverse_wheel_torque) and forward for the wheel torque (forward_wheel_torque): searched once."""
    tabs, ti = tables
    omega_d = omega_in / i_g
    j_d, w_d = segment(tabs, ti[T_DIFFLOSS, 2], ti[T_DIFFLOSS, 3], omega_d)
    k = T_GBLOSS + gear - 1
    j_g, w_g = segment(tabs, ti[k, 2], ti[k, 3], omega_in)
    return omega_d, j_d, w_d, j_g, w_g


@jit(inline=True)
def forward_wheel_torque(p, tables, gear, torque_in, omega_in, phi):
    """(T_W, gearbox loss, differential loss) for gearbox input torque T_G and speed omega_G (eq. 2.17).
    Neutral (gear 0): no input torque, only the differential's spin loss."""
    if gear < 1:
        omega_d = omega_in  # caller passes the differential input speed in neutral
        loss_d = phi * _fade(omega_d) * table2(tables, T_DIFFLOSS, 0.0, omega_d)
        return -loss_d, 0.0, loss_d
    speeds = loss_map_speeds(tables, p.gear_ratio[gear - 1], gear, omega_in)
    return forward_wheel_torque_at(p, tables, gear, torque_in, omega_in, phi, speeds)


@jit(inline=True)
def forward_wheel_torque_at(p, tables, gear, torque_in, omega_in, phi, speeds):
    """forward_wheel_torque in gear G >= 1 with the loss maps' speed segments ``speeds`` = loss_map_speeds(...,
    omega_in): T_D = T_G i_G - phi f_G(T_G, omega_G), T_W = T_D i_D - phi f_D(T_D, omega_D)."""
    omega_d, j_d, w_d, j_g, w_g = speeds
    i_d = p.final_drive
    i_g = p.gear_ratio[gear - 1]
    loss_g = phi * _fade(omega_in) * table2_at(tables, T_GBLOSS + gear - 1, torque_in, j_g, w_g)
    t_d = torque_in * i_g - loss_g
    loss_d = phi * _fade(omega_d) * table2_at(tables, T_DIFFLOSS, t_d, j_d, w_d)
    return t_d * i_d - loss_d, loss_g, loss_d


@jit(inline=True)
def inverse_wheel_torque(p, tables, gear, wheel_torque, omega_in, phi):
    """Gearbox input torque T_G that delivers the wheel torque T_W at input speed omega_G (exact inverse of
    ``forward_wheel_torque``)."""
    speeds = loss_map_speeds(tables, p.gear_ratio[gear - 1], gear, omega_in)
    return inverse_wheel_torque_at(p, tables, gear, wheel_torque, omega_in, phi, speeds)


@jit(inline=True)
def inverse_wheel_torque_at(p, tables, gear, wheel_torque, omega_in, phi, speeds):
    """inverse_wheel_torque with the loss maps' speed segments ``speeds`` = loss_map_speeds(..., omega_in)."""
    omega_d, j_d, w_d, j_g, w_g = speeds
    i_g = p.gear_ratio[gear - 1]
    t_d = invert_through_map_at(tables, T_DIFFLOSS, p.final_drive, phi * _fade(omega_d), j_d, w_d, wheel_torque)
    return invert_through_map_at(tables, T_GBLOSS + gear - 1, i_g, phi * _fade(omega_in), j_g, w_g, t_d)


@jit(inline=True)
def torque_limits(p, tables, omega, v):
    """(T_min, T_max) of the engine / motor at shaft speed omega [rad/s]; ICE: drag and full-load curves with a
    rev limit; BEV: torque/power limits and the regen limit, regen faded out below 1.5 m/s."""
    if p.is_bev > 0.5:
        w = omega if omega > 1.0 else 1.0
        t_max = min(p.max_torque, p.max_power / w)
        if omega > p.max_engine_speed:
            t_max = 0.0
        fade = v / 1.5
        if fade > 1.0:
            fade = 1.0
        elif fade < 0.0:
            fade = 0.0
        t_min = -min(p.regen_torque_limit, p.regen_power_limit / w) * fade
        return t_min, t_max
    t_drag = table1(tables, T_DRAG, omega)
    t_max = table1(tables, T_FULLLOAD, omega)
    if omega > p.max_engine_speed:
        t_max = t_drag
    return t_drag, t_max


@jit(inline=True)
def fuel_power(p, tables, omega, torque):
    """Fuel power P_fuel(omega, T_E) [W] from the fuel map; zero at or below the drag curve (fuel cut)."""
    if torque <= table1(tables, T_DRAG, omega) + 1e-6:
        return 0.0
    p = table2(tables, T_FUEL, omega, torque)
    return p if p > 0.0 else 0.0


@jit(inline=True)
def motor_electric_power(p, tables, omega, torque):
    """Electric power of the motor P_el = T omega + P_loss(omega, T) [W] (positive = drawn from the battery)."""
    return torque * omega + table2(tables, T_MOTORLOSS, omega, torque)


@jit(inline=True)
def battery_current(p, terminal_power):
    """Battery current I [A] for terminal power p = V_oc I - R I^2 (positive = discharge)."""
    voc = p.battery_open_circuit_voltage
    res = p.battery_resistance
    if res <= 0.0:
        return terminal_power / voc
    disc = voc * voc - 4.0 * res * terminal_power
    if disc < 0.0:
        disc = 0.0
    return (voc - math.sqrt(disc)) / (2.0 * res)


@jit(inline=True)
def regen_capacity(p, tables, gear, mode, omega_e, v, phi):
    """Largest braking force [N] the engine (drag, fuel cut) or motor (regen limit) can put on the wheels now."""
    if gear < 1 or (mode != MODE_LOCKED and p.is_bev < 0.5):
        return 0.0
    t_min, t_max = torque_limits(p, tables, omega_e, v)
    t_w, lg, ld = forward_wheel_torque(p, tables, gear, t_min, omega_e, phi)
    f = -t_w / p.wheel_radius
    return f if f > 0.0 else 0.0


@jit(inline=True)
def allocate(force, capacity):
    """Split a signed wheel force [N] into (traction, regen, friction): regen first, friction for the rest."""
    if force >= 0.0:
        return force, 0.0, 0.0
    regen = -force
    if regen > capacity:
        regen = capacity
    return 0.0, regen, -force - regen
