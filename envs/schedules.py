"""Time- or distance-scheduled effects (wind onset, parameter ramps), applied between substeps of the jitted core.

A schedule moves a quantity linearly from its start value to its final value:
    q(x) = q_0 + (q_1 - q_0) clip((x - onset) / ramp, 0, 1)     (ramp = 0: a step at x = onset),
with x the time t [s] or the distance s [m] driven (``onset_unit``). This module packs the ramps into the
parameter record; the compiled core (``physics.apply_schedules``) writes q into the parameters before every 10-ms
substep, so the truth channels (wind_speed, wind_angle, mass, drag_area, rolling_resistance_f0/f1/f4, ...) and
the tractive force follow the schedule.

Effects (``roadload.envs.effects.EFFECTS``): ``wind_ramp`` (mean wind speed and direction; with ``wind`` on, its
gusts and direction wander ride on top, its mean_speed and direction are replaced), ``mass_ramp`` (payload m_V
+ magnitude [kg]), ``drag_area_ramp`` (c_x A_V x (1 + magnitude)), ``rolling_resistance_ramp``
(f_r0, f_r1, f_r4 x (1 + magnitude)).
"""

from __future__ import annotations

import numpy as np

from .effects import EffectsConfig

SCHEDULE_EFFECTS = ("wind_ramp", "mass_ramp", "drag_area_ramp", "rolling_resistance_ramp")


def _ramp(params: np.void, name: str, p: dict, start: float, final: float) -> None:
    """Fill the RAMP record ``name`` of a parameter record from an effect's timing (onset, ramp, onset_unit)."""
    ramp = params[name]
    ramp["on"] = 1.0
    ramp["onset"] = float(p["onset"])
    ramp["length"] = float(p["ramp"])
    ramp["by_distance"] = 1.0 if p["onset_unit"] == "m" else 0.0
    ramp["start"] = start
    ramp["final"] = final


def pack_schedules(effects: EffectsConfig, params: np.void) -> bool:
    """Write the scheduled effects into a parameter record (already holding the vehicle and the other effects):
    their ramps, the unscheduled values they start from, and ``schedules_on``. With wind_ramp but no 'wind' effect
    the wind process runs without gusts or wander (exactly the scheduled wind). Returns whether any is enabled."""
    for name in ("mass_nominal", "drag_coefficient", "rolling_f0", "rolling_f1", "rolling_f4"):
        params["base_" + name] = params[name]
    if effects.enabled("wind_ramp"):
        p = effects.params("wind_ramp")
        _ramp(params, "ramp_wind_speed", p, float(p["start_speed"]), float(p["final_speed"]))
        _ramp(params, "ramp_wind_direction", p, float(p["start_direction"]), float(p["final_direction"]))
        if params["wind_on"] < 0.5:
            params["wind_on"], params["wind_gust_std"], params["wind_direction_std"] = 1.0, 0.0, 0.0
    for effect, ramp in (("mass_ramp", "ramp_mass"), ("drag_area_ramp", "ramp_drag"),
                         ("rolling_resistance_ramp", "ramp_rolling")):
        if effects.enabled(effect):
            p = effects.params(effect)
            _ramp(params, ramp, p, 0.0, float(p["magnitude"]))
    active = any(effects.enabled(name) for name in SCHEDULE_EFFECTS)
    params["schedules_on"] = 1.0 if active else 0.0
    return active
