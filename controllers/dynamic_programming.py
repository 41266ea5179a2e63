"""Dynamic programming on a (distance, speed) grid: an independent check of the full-route optimum's NLP.

The same discrete problem as :mod:`.optimum` (nodes, segment grade / curvature / wind, speed caps, the stop nodes,
comfort acceleration limits, drive limits, the source-energy model and the road load), solved by a different
method: Bellman's recursion over a speed grid at every node instead of an interior-point method, so the two can
only agree when both find the global optimum of the discretised problem.

    V_N(v) = terminal value;   V_k(v_i) = min_j [ E_k(v_i, v_j) + mu dt_k(v_i, v_j) + V_{k+1}(v_j) ]

with dt_k = ds_k / v_mid, a_k = (v_j^2 - v_i^2) / (2 ds_k) within [-decel_max, accel_max], the wheel force
F = (m + m_rot) a_k + F_resist(v_mid) split into traction (within the torque and power limits) or regeneration (the
amount that minimises the source power, within its limits; friction brakes for the rest) and E_k the source energy
P_source ds_k / v_mid. The time multiplier mu [J/s] is found by bisection so that the trip takes the target time.
The jerk limit is not part of the DP (it would need the previous speed as a second state); compare it with the
NLP solved with ``OptimumSettings(jerk=False)``.

ICE with ``gear_choice``: every transition's fuel is that of the best gear for its wheel force and speed, with fuel
cut while braking (:meth:`~.energy.SourceEnergyModel.best_gear_fuel_power`: any gear whose engine speed is in range
and whose full load gives the force). The NLP prices fuel at the shift rule's gear and charges the engine's
friction while braking too, so on a heavy truck, which brakes on descents and kicks down on climbs, the NLP's
optimum is no bound on the plant; this DP's energy is one up to the Willans fit's error and the grid.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from roadload.road_load import RoadLoadParameters, crosswind_drag_increase

from .energy import SourceEnergyModel
from .force_model import resistance_force
from .mpc import Preview
from .optimum import OptimumError, OptimumSettings
from .vehicle_models import INFEASIBLE_FUEL


@dataclass
class DpSolution:
    """The DP's speed profile over the nodes, its energy and time and the time multiplier it used."""

    s: np.ndarray  # node positions [m]
    v: np.ndarray  # speed [m/s] per node
    energy_J: float
    model_time: float  # [s]
    multiplier: float  # mu [J/s]
    speed_step: float  # grid resolution [m/s]


FuelTable = tuple[np.ndarray, np.ndarray, np.ndarray]  # (speeds [m/s], wheel forces [N], fuel [W] per gear)


def fuel_table_power(table: FuelTable, v, force) -> np.ndarray:
    """The least fuel power [W] over the gears of a (speed, wheel force) table (bilinear in each gear's; inf where
    no gear can: a gear's value at or above :data:`~.vehicle_models.INFEASIBLE_FUEL` is refused)."""
    from scipy.interpolate import RegularGridInterpolator

    speeds, forces, fuel = table
    v, force = np.broadcast_arrays(np.asarray(v, float), np.asarray(force, float))
    points = np.stack([v.ravel(), force.ravel()], axis=-1)
    best = np.full(points.shape[0], np.inf)
    for gear in fuel:
        value = RegularGridInterpolator((speeds, forces), gear, bounds_error=False, fill_value=INFEASIBLE_FUEL)(points)
        best = np.minimum(best, np.where(value < 0.1 * INFEASIBLE_FUEL, value, np.inf))
    return best.reshape(v.shape)


def _stage_costs(preview: Preview, energy: SourceEnergyModel, params: RoadLoadParameters,
                 settings: OptimumSettings, grid: np.ndarray, offsets: np.ndarray, k: int, gear_choice: bool = False,
                 fuel_table: FuelTable | None = None) -> tuple[np.ndarray, np.ndarray]:
    """(source energy [J], time [s]) of every transition v_i -> v_{i+d} of segment k (inf where infeasible)."""
    ds = float(preview.ds[k]) if preview.ds is not None else float(preview.s[k + 1] - preview.s[k])
    i = np.arange(grid.size)[:, None]
    j = i + offsets[None, :]
    ok = (j >= 0) & (j < grid.size)
    jc = np.clip(j, 0, grid.size - 1)
    v0, v1 = np.broadcast_to(grid[:, None], jc.shape), grid[jc]
    vm = 0.5 * (v0 + v1)
    acc = (v1 ** 2 - v0 ** 2) / (2.0 * ds)
    ok &= (acc >= -settings.decel_max - 1e-9) & (acc <= settings.accel_max + 1e-9)
    p = params.as_vector()
    headwind = p[6] if preview.headwind is None else float(preview.headwind[k])
    p = np.concatenate([p[:6], [headwind], p[7:]])
    res = resistance_force(vm, float(preview.grade[k]), float(preview.curvature[k]), p)
    if preview.crosswind is not None:
        res = res + crosswind_drag_increase(params.c2, vm + headwind, float(preview.crosswind[k]),
                                            preview.yaw_drag_factor)
    force = params.inertial_mass * acc + res
    ratio = float(preview.ratio[k])
    ratio_obj = energy.smooth_ratio(vm) if energy.kind == "ice" else ratio
    traction = np.maximum(force, 0.0)
    ok &= traction <= float(energy.max_traction_force(None, ratio)) + 1e-6
    ok &= traction * vm <= energy.max_power + 1e-6
    need = np.maximum(-force, 0.0)
    limit = np.minimum(float(energy.max_regen_force(ratio)),
                       (energy.max_regen_power if energy.regenerates else 0.0) / vm)
    limit = np.minimum(need, limit)
    # the regenerative force that minimises the source power (convex, quadratic in the force): parabola through 3 points
    f0, fh, f1 = (np.asarray(energy.source_power(traction, x * limit, vm, ratio_obj), float) for x in (0.0, 0.5, 1.0))
    curv = f0 - 2.0 * fh + f1
    with np.errstate(divide="ignore", invalid="ignore"):
        x_opt = np.where(curv > 1e-12, 0.5 + 0.25 * (f0 - f1) / curv, np.where(f1 <= f0, 1.0, 0.0))
    x_opt = np.clip(np.nan_to_num(x_opt, nan=1.0), 0.0, 1.0)
    if fuel_table is not None:  # the plant's own fuel map, the gear of least fuel (module docstring)
        power = fuel_table_power(fuel_table, vm, force)
        ok &= np.isfinite(power)
    elif energy.kind == "ice" and gear_choice:  # the gear of least fuel for the net wheel force, fuel cut in braking
        power = energy.best_gear_fuel_power(force, vm)[0]
        ok &= np.isfinite(power)
    else:
        power = np.asarray(energy.source_power(traction, x_opt * limit, vm, ratio_obj), float)
    ok &= need - x_opt * limit <= energy.brake_force_limit(params.mass) + 1e-6
    dt = ds / vm
    cost = np.where(ok, power * dt, np.inf)
    return cost, np.where(ok, dt, np.inf)


def _speed_grid(st: OptimumSettings, top: float, ds_max: float, speed_step: float, energy_step: float | None
                ) -> tuple[np.ndarray, int]:
    """(speeds of the grid [m/s] from the floor to ``top``, the largest index change of one segment): uniform in
    speed, or in E = v^2/2 with ``energy_step`` [m^2/s^2]."""
    if energy_step is not None:
        if not (math.isfinite(energy_step) and energy_step > 0):
            raise OptimumError(f"energy_step: a finite step > 0 m^2/s^2, got {energy_step!r}")
        e_grid = np.arange(0.5 * st.speed_floor ** 2, 0.5 * top ** 2 + energy_step, energy_step)
        return np.sqrt(2.0 * e_grid), int(math.ceil(max(st.accel_max, st.decel_max) * ds_max / energy_step)) + 1
    grid = np.arange(st.speed_floor, top + speed_step, speed_step)
    # the largest speed change of one segment: speeding up from the floor, braking to a stop
    reach = max(math.sqrt(st.speed_floor ** 2 + 2 * st.accel_max * ds_max) - st.speed_floor,
                math.sqrt(2 * st.decel_max * ds_max))
    return grid, int(math.ceil(min(reach, grid[-1]) / speed_step)) + 1


def dp_optimum(preview: Preview, energy: SourceEnergyModel, params: RoadLoadParameters, model_time: float,
               start_speed: float, arrival_speed: float | None = None, settings: OptimumSettings | None = None,
               speed_step: float = 0.05, time_tol: float = 1e-4, terminal_value: float = 0.0,
               gear_choice: bool = False, energy_step: float | None = None,
               fuel_table: FuelTable | None = None) -> DpSolution:
    """The minimum-energy speed profile over the preview's nodes with trip time ``model_time`` [s] (module
    docstring). arrival_speed [m/s]: the end speed (nearest grid speed); None: the kinetic energy left is worth
    ``terminal_value`` [J per J]. speed_step [m/s]: grid resolution. gear_choice (ICE): fuel at the best gear
    with fuel cut (module docstring). energy_step [m^2/s^2]: a grid uniform in E = v^2/2 instead, so the
    accelerations a segment can take are spaced energy_step / ds at every speed (a speed grid spaces them
    v dv / ds: at 20 m/s, 0.05 m/s and 10 m apart, 0.1 m/s^2, too coarse for a heavy truck climbing at full load,
    whose deceleration there is a few hundredths of a m/s^2). fuel_table (ICE): the plant's own fuel map per gear
    (:func:`~.vehicle_models.plant_fuel_table`) instead of the energy model, the gear of least fuel."""
    st = settings or OptimumSettings()
    if not (math.isfinite(speed_step) and speed_step > 0):
        raise OptimumError(f"speed_step: a finite step > 0 m/s, got {speed_step!r}")
    if not (math.isfinite(model_time) and model_time > 0):
        raise OptimumError(f"model_time: a finite time > 0 s, got {model_time!r}")
    n = len(preview.s) - 1
    cap = np.maximum(np.asarray(preview.speed_cap, float) - st.speed_margin, st.speed_floor)
    grid, width = _speed_grid(st, float(cap.max()), float(np.max(np.diff(preview.s))), speed_step, energy_step)
    offsets = np.arange(-width, width + 1)
    stages = [_stage_costs(preview, energy, params, st, grid, offsets, k, gear_choice, fuel_table) for k in range(n)]
    allowed = [grid <= c + 1e-9 for c in cap]
    v0 = max(start_speed, st.speed_floor)
    i0 = int(np.argmin(np.abs(grid - v0)))
    m_in = params.inertial_mass
    if arrival_speed is None:
        final = -terminal_value * m_in * 0.5 * grid ** 2
    else:
        final = np.full(grid.size, np.inf)
        final[int(np.argmin(np.abs(grid - max(arrival_speed, st.speed_floor))))] = 0.0
    final = np.where(allowed[n], final, np.inf)
    idx = np.arange(grid.size)[:, None] + offsets[None, :]
    inside = (idx >= 0) & (idx < grid.size)
    idx = np.clip(idx, 0, grid.size - 1)

    def solve(mu: float) -> tuple[np.ndarray, float, float]:
        value = final
        choice = np.zeros((n, grid.size), dtype=int)
        for k in range(n - 1, -1, -1):
            cost, dt = stages[k]
            q = cost + mu * dt + np.where(inside, value[idx], np.inf)
            best = np.argmin(q, axis=1)
            value = np.where(allowed[k], q[np.arange(grid.size), best], np.inf)
            choice[k] = best
        if not np.isfinite(value[i0]):
            raise OptimumError("dynamic programming: no feasible speed profile on the grid (caps, limits or "
                               "arrival speed)")
        path = np.empty(n + 1, dtype=int)
        path[0] = i0
        e = t = 0.0
        for k in range(n):
            d = choice[k, path[k]]
            e += stages[k][0][path[k], d]
            t += stages[k][1][path[k], d]
            path[k + 1] = path[k] + offsets[d]
        return path, e, t

    lo, hi = 0.0, 1.0e3
    fast = solve(hi)
    while fast[2] > model_time and hi < 1e9:  # mu too small: the trip is still too slow
        lo, hi = hi, hi * 4.0
        fast = solve(hi)
    if fast[2] > model_time:
        raise OptimumError(f"model_time: {model_time:.1f} s is faster than the grid's fastest trip "
                           f"({fast[2]:.1f} s)")
    slow = solve(lo)
    if slow[2] < model_time:
        raise OptimumError(f"model_time: {model_time:.1f} s is slower than the grid's slowest trip ({slow[2]:.1f} s)")
    for _ in range(60):  # bisection on mu; the grid's time jumps, so keep the two runs around the target
        if min(abs(fast[2] / model_time - 1.0), abs(slow[2] / model_time - 1.0)) <= time_tol or hi - lo < 1e-6:
            break
        mid = 0.5 * (lo + hi)
        run = solve(mid)
        if run[2] > model_time:
            lo, slow = mid, run
        else:
            hi, fast = mid, run
    # the energy at exactly the target time: linear between the two runs that bracket it
    (p1, e1, t1), (p2, e2, t2) = fast, slow
    w = 0.0 if t2 == t1 else (model_time - t1) / (t2 - t1)
    energy_at_time = e1 + w * (e2 - e1)
    path = p1 if w <= 0.5 else p2
    return DpSolution(s=np.asarray(preview.s, float), v=grid[path], energy_J=float(energy_at_time),
                      model_time=float(model_time), multiplier=float(0.5 * (lo + hi)), speed_step=float(speed_step))
