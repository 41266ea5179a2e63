"""The energy side of the gap (battery-electric vehicles): the measured traction-battery power against the sim's.

P_el,measured = U_bat I_bat [W] at the battery terminals; P_el,sim = T_E ω_E + P_loss(ω_E, T_E) + P_aux for the
recorded motor torque T_E and speed ω_E (the sim's motor loss map, its auxiliary power and the sim config's
``auxiliary_load``). The power residual P_el,measured - P_el,sim is what auxiliary loads (heater, air
conditioning) and motor-map errors leave; candidates with ``side="power"`` in :mod:`.catalog` explain it. As on
the force side, the sim's own trips give an energy floor (:data:`POWER_BASIS`, e.g. the drive-torque sensor's
gain and offset errors times the motor speed) that is added to P_el,sim.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from roadload.trip import Trip

from .simconfig import SimConfig

ELECTRIC_POWER = "electric_power"
SIM_ELECTRIC_POWER = "sim_electric_power"
POWER_RESIDUAL = "power_residual"
AUX_LOGGED = "aux_power_logged"
MOTOR_SPEED = "motor_speed"
SPEED_DERIVED = "motor_speed_from_vehicle_speed"
LOSS_TORQUE_SLOPE = "loss_torque_slope"
LOSS_SPEED_SLOPE = "loss_speed_slope"


def _sample(trip: Trip, name: str, t: np.ndarray) -> np.ndarray:
    if not trip.has(name):
        return np.full(t.shape, np.nan)
    x = trip.channel(name)
    ok = np.isfinite(x)
    if ok.sum() < 2:
        return np.full(t.shape, np.nan)
    return np.interp(t, trip.t[ok], x[ok])


def power_columns(trip: Trip, frame: pd.DataFrame, sim: SimConfig) -> dict[str, np.ndarray]:
    """electric_power, sim_electric_power, power_residual, aux_power_logged [W] on the frame's times (NaN where the
    trip or the sim's vehicle has no traction battery), the motor speed ω_E [rad/s], whether it was derived
    from the vehicle speed (no motor-speed channel), and the loss map's slopes T_E ∂P_loss/∂T_E and
    ω_E ∂P_loss/∂ω_E [W] (central differences): what a torque or speed signal reading 1 % high adds to the sim's
    losses, per 1 %."""
    t = frame["t"].to_numpy(dtype=float)
    nan = np.full(t.shape, np.nan)
    d = sim.vehicle.drivetrain
    if d.kind != "bev" or d.motor is None or d.battery is None or not (trip.has("battery_voltage")
                                                                       and trip.has("battery_current")):
        return {ELECTRIC_POWER: nan, SIM_ELECTRIC_POWER: nan, POWER_RESIDUAL: nan, AUX_LOGGED: nan, MOTOR_SPEED: nan,
                SPEED_DERIVED: np.zeros(t.shape, dtype=bool), LOSS_TORQUE_SLOPE: nan, LOSS_SPEED_SLOPE: nan}
    p_meas = _sample(trip, "battery_voltage", t) * _sample(trip, "battery_current", t)
    torque = frame["drive_torque"].to_numpy(dtype=float)
    if trip.has("engine_speed"):
        omega = _sample(trip, "engine_speed", t)
    else:
        omega = frame["speed"].to_numpy(dtype=float) / sim.vehicle.wheel_radius * d.gear_ratios[0] * d.final_drive
    aux = d.battery.auxiliary_power
    if sim.effects.enabled("auxiliary_load"):
        aux += float(sim.effects.params("auxiliary_load")["power"])
    p_sim = torque * omega + np.asarray(d.motor.loss_map(np.abs(omega), torque), dtype=float) + aux
    logged = np.zeros(t.shape)
    have = False
    for c in ("heating_power", "aircon_power"):
        if trip.has(c):
            logged = logged + np.nan_to_num(_sample(trip, c, t))
            have = True
    return {ELECTRIC_POWER: p_meas, SIM_ELECTRIC_POWER: p_sim, POWER_RESIDUAL: p_meas - p_sim,
            AUX_LOGGED: logged if have else nan, MOTOR_SPEED: omega,
            SPEED_DERIVED: np.full(t.shape, not trip.has("engine_speed")),
            LOSS_TORQUE_SLOPE: _loss_slope(d.motor.loss_map, omega, torque, "torque"),
            LOSS_SPEED_SLOPE: _loss_slope(d.motor.loss_map, omega, torque, "speed")}


def _loss_slope(loss_map, omega: np.ndarray, torque: np.ndarray, along: str, rel: float = 0.01) -> np.ndarray:
    """x ∂P_loss/∂x [W] for x the torque or the speed: (P_loss at (1 + rel) x - at (1 - rel) x) / (2 rel)."""
    w, tq = np.abs(omega), np.asarray(torque, dtype=float)
    up, down = (1.0 + rel, 1.0 - rel)
    if along == "torque":
        hi, lo = loss_map(w, tq * up), loss_map(w, tq * down)
    else:
        hi, lo = loss_map(w * up, tq), loss_map(w * down, tq)
    return (np.asarray(hi, dtype=float) - np.asarray(lo, dtype=float)) / (2.0 * rel)


def energy_columns(table: pd.DataFrame, spec) -> np.ndarray:
    """The energy side's base regressors (n x 4) for the residual P_el,measured - P_el,sim ≈ ΔP_aux + (s - 1)
    P_loss - Δg T_E ω_E - ΔT_off ω_E: 1 [-], the sim's motor loss P_loss(ω_E, T_E) [W], -T_E ω_E [W] and -ω_E
    [rad/s]. P_el,sim is computed from the *logged* torque, so a signal reading (1 + Δg) T + ΔT_off over-predicts
    the power by Δg T ω + ΔT_off ω (signed: positive in traction, negative in regeneration), where a motor loss
    error scales P_loss and an auxiliary load is constant. The calibration fits these four
    (:mod:`.calibrate`), the diagnosis' energy base block reports them (:mod:`.base`)."""
    omega = table[MOTOR_SPEED].to_numpy(dtype=float)
    torque = table["drive_torque"].to_numpy(dtype=float)
    motor = spec.drivetrain.require_motor()
    loss = np.asarray(motor.loss_map(np.abs(omega), torque), dtype=float)
    return np.nan_to_num(np.column_stack([np.ones(len(table)), loss, -torque * omega, -omega]))


POWER_BASIS: tuple[str, ...] = ("1", "omega", "T omega", "|T omega|", "T^2")


def power_basis(frame: pd.DataFrame) -> np.ndarray:
    """Columns of the sim's energy floor (what its sensors and loss map do that P_el,sim does not say)."""
    om = frame[MOTOR_SPEED].to_numpy(dtype=float)
    tq = frame["drive_torque"].to_numpy(dtype=float)
    p = tq * om
    return np.nan_to_num(np.column_stack([np.ones_like(om), om, p, np.abs(p), tq ** 2]))


def electric_energy_per_distance(frame: pd.DataFrame, power: np.ndarray, rows: np.ndarray) -> float:
    """∫ P dt / ∫ v dt over ``rows`` [kWh/100 km] (equal sample spacing assumed)."""
    v = frame["speed"].to_numpy(dtype=float)[rows]
    p = np.asarray(power, dtype=float)[rows]
    ok = np.isfinite(p)
    if not ok.any() or np.sum(v[ok]) <= 0:
        return float("nan")
    return float(np.sum(p[ok]) / np.sum(v[ok]) * 100e3 / 3.6e6)
