"""An independent energy check of the controller comparison: every run's driven speed trace (with its grade)
through FASTSim 3's vehicle model.

Vehicle mapping (:func:`fastsim_vehicle`): FASTSim 3.1's battery-electric resource without a
thermal model, ``2022_Renault_Zoe_ZE50_R135.yaml`` (FASTSim's efficiency-vs-power curve of its motor, its battery
and a 0.92 transmission; the vehicle of the project's FASTSim world,
:data:`~roadload.experiments.worlds.fastsim_world.BEV_VARIANT`), with the preset's (``bmw_i3``)

- road load: total mass 1400 kg, c_d A_V = 0.29 x 2.38 m^2 (c_d scaled on the Zoe's frontal area), rolling
  resistance coefficient 0.0085, auxiliary power 300 W;
- motor power: 125 kW (FASTSim's ``em.pwr_out_max_watts``; its efficiency curve is over the fraction of it);
- regeneration limit: 50 kW and 87 N m at the motor, the preset's. FASTSim 3.1 has one motor power for both
  directions and no friction-brake blend for a battery-electric vehicle (``vehicle_model.rs`` hands the whole
  negative tractive power to the motor, which refuses any above its regeneration limit: "edrv charge power exceeds
  current max charge power"), so a lower limit cannot be set inside FASTSim. It is applied to FASTSim's result:
  at every step where the motor's mechanical power P_m < 0 exceeds P_r = min(50 kW, 87 N m x omega_M), the
  regenerated electrical power is scaled by P_r / |P_m| (FASTSim's efficiency at that step) and the rest is
  friction braking;
- the battery starts at a state of charge of 0.5 (:data:`INITIAL_SOC`): FASTSim's ``walk`` starts at max_soc = 0.98,
  where 3.1 cuts the charge power to a few kW after seconds of regeneration and then fails the run (the two hilly
  seeds that failed before, on their first long descent).

The resources closer in power and drag (2020 Bolt EV, 149 kW, c_d A 0.74 m^2; 2016 Leaf 30 kWh) carry FASTSim's
thermal battery model, which refuses regeneration above ~2.5 kW at 22 degC in 3.1.0; none of the resources is a
truck, so the check is for the car. FASTSim drives the trace with its own drive-train (no wind, no lateral
dynamics, a constant rolling coefficient); the energy is the battery's electrical output, integrated over the run
up to the road end (:func:`roadload.experiments.worlds.fastsim_world.run_fastsim`).
"""

from __future__ import annotations

import functools
from typing import Any

import numpy as np

from roadload.experiments.worlds.fastsim_world import BEV_VARIANT, STEP, base_vehicle_dict, run_fastsim
from roadload.envs import get_preset

INITIAL_SOC = 0.5  # [-] the battery's state of charge at the start of every FASTSim run (module docstring)


@functools.lru_cache(maxsize=4)
def _mapped(preset: str) -> dict[str, Any]:
    spec = get_preset(preset)
    d = base_vehicle_dict(BEV_VARIANT)
    area = float(d["chassis"]["frontal_area_square_meters"])
    d["chassis"]["drag_coef"] = float(spec.aero.drag_coefficient * spec.aero.frontal_area / area)
    d["chassis"]["wheel_rr_coef"] = float(spec.tires.rolling_resistance_f0)
    d["mass_kilograms"] = float(spec.body.mass)
    d["pwr_aux_base_watts"] = float(spec.drivetrain.require_battery().auxiliary_power)
    d["pt_type"]["BEV"]["em"]["pwr_out_max_watts"] = float(spec.drivetrain.require_motor().max_power)
    return d


def regeneration_limit(preset: str, v) -> np.ndarray:
    """The preset's regeneration limit at the motor [W] at vehicle speed v [m/s]:
    P_r = min(P_regen,max, T_regen,max omega_M), omega_M = v i / r_W (the mapping's limit, module docstring)."""
    spec = get_preset(preset)
    d, motor = spec.drivetrain, spec.drivetrain.require_motor()
    omega = np.asarray(v, float) * float(d.gear_ratios[0] * d.final_drive) / float(spec.tires.dynamic_radius)
    return np.minimum(float(motor.regen_power_limit), float(motor.regen_torque_limit) * omega)


def limited_battery_power(out: dict[str, np.ndarray], limit: np.ndarray) -> np.ndarray:
    """FASTSim's battery output [W] with the motor's regeneration held to ``limit`` [W] per step: where the
    motor's mechanical power P_m < -limit, the regenerated electrical power is scaled by limit / |P_m| (the rest
    of the braking is friction braking, which returns nothing)."""
    mech, elec = np.asarray(out["source_mech"], float), np.asarray(out["motor_electrical"], float)
    over = (mech < 0) & (-mech > limit)
    kept = np.where(over, limit / np.where(over, -mech, 1.0), 1.0)
    return np.asarray(out["battery_electrical"], float) - np.where(elec < 0, elec * (1.0 - kept), 0.0)


def fastsim_vehicle(preset: str = "bmw_i3") -> dict[str, Any]:
    """The FASTSim vehicle dict of the mapping (module docstring), a copy."""
    import copy

    return copy.deepcopy(_mapped(preset))


def fastsim_energy(t: np.ndarray, s: np.ndarray, v: np.ndarray, road, preset: str = "bmw_i3",
                   start: float = 0.0) -> dict[str, float]:
    """FASTSim's battery energy [J] for a run's trace (t [s], s [m], v [m/s] at the control steps, the final
    state included) from position ``start`` [m] to the road end, on a 0.1 s grid, with the road's grade at the
    trace's positions; also the speed FASTSim reached at the end and how far it fell behind the trace (an
    under-powered step)."""
    t, s, v = (np.asarray(a, float) for a in (t, s, v))
    t_start = float(np.interp(start, s, t)) if start > 0 else float(t[0])
    t_end = float(np.interp(road.length, s, t))
    grid = np.arange(t_start, t_end + STEP / 2, STEP)
    grid[-1] = min(grid[-1], t_end)
    speed = np.interp(grid, t, v)
    position = np.interp(grid, t, s)
    grade = np.sin(np.asarray(road.at(position)["grade"], float))
    out = run_fastsim(_mapped(preset), grid - grid[0], speed, grade, initial_soc=INITIAL_SOC)
    power = limited_battery_power(out, regeneration_limit(preset, out["speed"]))
    energy = float(np.sum(power[1:] * np.diff(grid)))  # a step's value holds over the step that ends at it
    return {"energy_J": energy, "speed_end": float(out["speed"][-1]),
            "trace_miss": float(np.max(np.abs(out["speed"] - speed)))}


def fastsim_efficiency_power(wheel_power, v, preset: str = "bmw_i3") -> np.ndarray:
    """Battery power [W] of FASTSim's efficiency chain in the mapping (module docstring) for the power the
    drive-train delivers at the wheels, P_W [W] (< 0: regeneration), at vehicle speed v [m/s]:

    - motor mechanical power P_M = P_W / eta_T (drive) or P_W eta_T (regeneration), eta_T FASTSim's transmission
      efficiency (one constant);
    - motor electrical power P_E = P_M / eta_M(x) (drive) or P_M eta_M(0) (regeneration), eta_M FASTSim's one
      efficiency curve over the fraction x = P_M / P_M,max of the motor power (no dependence on speed or torque;
      3.1 regenerates at its value at x = 0, 0.84 for this motor, at any power);
    - the regeneration held to the preset's limit as :func:`limited_battery_power` does;
    - plus the auxiliary power.

    It is FASTSim's own chain (``tests/experiments/test_fastsim_check.py`` drives a trace through FASTSim and
    through this), applied to any trace's wheel power: roadload's traces scored with FASTSim's efficiency."""
    d = _mapped(preset)
    em, eta_t = d["pt_type"]["BEV"]["em"], float(d["pt_type"]["BEV"]["transmission"]["eff_interp"])
    curve = em["eff_interp_achieved"]["data"]
    x_grid, eta_grid = (np.asarray(curve[k]["data"] if k == "values" else curve[k][0]["data"], float)
                        for k in ("grid", "values"))
    wheel_power = np.asarray(wheel_power, float)
    mech = np.where(wheel_power > 0, wheel_power / eta_t, wheel_power * eta_t)
    # regeneration at the curve's value at x = 0 whatever the power: FASTSim 3.1 looks the efficiency up at the
    # fraction of the propulsion output, which is 0 while regenerating (P_E / P_M = 0.840 in every regenerating
    # step of a hilly run up to -57 kW)
    eta_m = np.interp(np.minimum(np.maximum(mech, 0.0) / float(em["pwr_out_max_watts"]), 1.0), x_grid, eta_grid)
    elec = np.where(mech > 0, mech / eta_m, mech * eta_m)
    out = {"source_mech": mech, "motor_electrical": elec, "battery_electrical": elec + float(d["pwr_aux_base_watts"])}
    return limited_battery_power(out, regeneration_limit(preset, v))


def roadload_trace_fastsim_efficiency(truth: np.ndarray, start: float, end: float, preset: str = "bmw_i3"
                                      ) -> dict[str, float]:
    """A roadload run scored twice from its simulator truth log (rows = 10 ms substeps, columns
    ``roadload.envs.TRUTH_LOG_COLUMNS``) between positions ``start`` and ``end`` [m]: roadload's own source energy
    [J] and the same wheel power through FASTSim's efficiency chain (:func:`fastsim_efficiency_power`). The wheel
    power of the drive-train is P_W = (T_R / r_W + F_B) v: the rim torque T_R (tractive force and wheel inertia)
    less the friction brakes' share F_B [N]; also both split into the steps where the drive-train drives
    (P_W > 0) and the rest (regeneration, coasting)."""
    from roadload.envs import TRUTH_LOG_COLUMNS

    col = {name: truth[:, i] for i, name in enumerate(TRUTH_LOG_COLUMNS)}
    radius = float(get_preset(preset).tires.dynamic_radius)
    keep = (col["POS"] >= start) & (col["POS"] <= end)
    dt = np.diff(col["T"], prepend=col["T"][0] - (col["T"][1] - col["T"][0]))[keep]
    wheel = ((col["RIM"] / radius + col["FBRAKE"]) * col["V"])[keep]
    battery = fastsim_efficiency_power(wheel, col["V"][keep], preset)
    source, driving = col["PSRC"][keep], wheel > 0
    return {"roadload_J": float(np.sum(source * dt)), "fastsim_efficiency_J": float(np.sum(battery * dt)),
            "wheel_drive_J": float(np.sum(np.maximum(wheel, 0) * dt)),
            "wheel_regeneration_J": float(np.sum(np.minimum(wheel, 0) * dt)),
            # the same split by what the drive-train does: drives (P_W > 0), or regenerates / coasts
            "roadload_driving_J": float(np.sum((source * dt)[driving])),
            "fastsim_efficiency_driving_J": float(np.sum((battery * dt)[driving])),
            "roadload_not_driving_J": float(np.sum((source * dt)[~driving])),
            "fastsim_efficiency_not_driving_J": float(np.sum((battery * dt)[~driving]))}
