"""An independent energy check of the controller comparison: every run's driven speed trace (with its grade)
through FASTSim 3's vehicle model.

Vehicle mapping: FASTSim 3.1's battery-electric resource without a thermal model, ``2022_Renault_Zoe_ZE50_R135.yaml``
(1600 kg, 100 kW motor with FASTSim's efficiency-vs-power curve, its battery and a 0.92 transmission; the vehicle of
the project's FASTSim world, :data:`~roadload.experiments.worlds.fastsim_world.BEV_VARIANT`), with the ``bmw_i3``
preset's road load: total mass 1400 kg, c_d A_V = 0.29 x 2.38 m^2 (c_d scaled on the Zoe's frontal area), rolling
resistance coefficient 0.0085 and auxiliary power 300 W. The resources closer in power and drag (2020 Bolt EV, 149 kW,
c_d A 0.74 m^2; 2016 Leaf 30 kWh) carry FASTSim's thermal battery model, which refuses regeneration above ~2.5 kW
at 22 degC in 3.1.0 (``edrv charge power exceeds current max charge power``); none of the resources is a truck, so
the check is for the car. FASTSim drives the trace with its own drive-train (no wind, no lateral dynamics, a
constant rolling coefficient) and regenerates every braking demand up to its motor power (the i3 preset: 50 kW and
150 N m), the largest difference between the two models; the energy is the battery's electrical output, integrated
over the run up to the road end (:func:`roadload.experiments.worlds.fastsim_world.run_fastsim`).
"""

from __future__ import annotations

import functools
from typing import Any

import numpy as np

from roadload.experiments.worlds.fastsim_world import BEV_VARIANT, STEP, base_vehicle_dict, run_fastsim
from roadload.envs import get_preset

@functools.lru_cache(maxsize=4)
def _mapped(preset: str) -> dict[str, Any]:
    spec = get_preset(preset)
    d = base_vehicle_dict(BEV_VARIANT)
    area = float(d["chassis"]["frontal_area_square_meters"])
    d["chassis"]["drag_coef"] = float(spec.aero.drag_coefficient * spec.aero.frontal_area / area)
    d["chassis"]["wheel_rr_coef"] = float(spec.tires.rolling_resistance_f0)
    d["mass_kilograms"] = float(spec.body.mass)
    d["pwr_aux_base_watts"] = float(spec.drivetrain.require_battery().auxiliary_power)
    return d


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
    out = run_fastsim(_mapped(preset), grid - grid[0], speed, grade)
    power = np.asarray(out["battery_electrical"], float)
    energy = float(np.sum(power[1:] * np.diff(grid)))  # a step's value holds over the step that ends at it
    return {"energy_J": energy, "speed_end": float(out["speed"][-1]),
            "trace_miss": float(np.max(np.abs(out["speed"] - speed)))}
