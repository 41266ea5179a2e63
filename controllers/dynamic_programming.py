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

import json
import math
from dataclasses import dataclass

import numpy as np

from roadload.road_load import RoadLoadParameters, crosswind_drag_increase

from .energy import PlantFuelModel, SourceEnergyModel
from .force_model import resistance_force
from .mpc import Preview
from .optimum import OptimumError, OptimumSettings


@dataclass
class DpSolution:
    """The DP's speed profile over the nodes, its energy and time and the time multiplier it used."""

    s: np.ndarray  # node positions [m]
    v: np.ndarray  # speed [m/s] per node
    energy_J: float
    model_time: float  # [s]
    multiplier: float  # mu [J/s]
    speed_step: float  # grid resolution [m/s]
    # the same profile's energy [J] in the problem's price table (DpProblem's price_table: e.g. the MPC's smooth
    # fuel model optimised, its profile booked in the plant's raw map); None without one
    priced_energy_J: float | None = None


def _cell(grid: np.ndarray, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(index i of the grid cell [grid[i], grid[i + 1]] that holds each ``x``, clipped to the grid, and the weight
    of grid[i + 1] in [0, 1]): linear interpolation on an increasing grid."""
    x = np.clip(x, grid[0], grid[-1])
    i = np.clip(np.searchsorted(grid, x, side="right") - 1, 0, grid.size - 2)
    return i, (x - grid[i]) / (grid[i + 1] - grid[i])


@dataclass(frozen=True)
class PlantFuelMap:
    """An ICE plant's own quasi-static fuel power per gear over (speed [m/s], wheel force [N]), with each gear's
    feasible set given exactly rather than by interpolating towards a refusal value (which would cut off a grid
    cell of full load, where a heavy truck climbs):

    - fuel[g, i, j] = P_fuel(omega, T_E) [W], omega = k_g v_i, T_E = T_E(F_j r_W) the exact inverse of the
      drive-train losses (:meth:`~roadload.envs.powertrain.Powertrain.source_torque`), clamped to [drag, full
      load] and omega to [idle, rev limit] (0 at or below the drag curve: fuel cut, the brakes take the rest);
    - a gear can where k_g v is within [idle, rev limit] and F <= max_force[g](v), its full load at the wheels
      (:meth:`~roadload.envs.powertrain.Powertrain.wheel_torque` of the full-load torque / r_W), linear in v.

    Bilinear interpolation between the grid points (0.25 m/s x 250 N in :func:`plant_fuel_map`). Quasi-static:
    no rotating-mass, shift or clutch transients, warm gearbox oil."""

    speeds: np.ndarray  # [m/s]
    forces: np.ndarray  # [N]
    fuel: np.ndarray  # [W], (gears, speeds, forces)
    max_force: np.ndarray  # [N], (gears, speeds)
    drag_force: np.ndarray  # [N] (< 0), (gears, speeds): the engine's drag at the wheels in overrun, fuel cut
    speed_ratio: np.ndarray  # k_g [rad/s per m/s], (gears,)
    engine_speed_range: tuple[float, float]  # [rad/s]

    def gear_power(self, v, force, clamp_speed: bool = False) -> np.ndarray:
        """Every gear's fuel power [W] at speed ``v`` [m/s] and net wheel force ``force`` [N], shape (gears,
        *broadcast shape), bilinear in the map, inf where the gear cannot (its engine speed k_g v outside the range,
        or the force above its full load); a braking force below the table's lowest is the brakes' beyond the
        engine's drag (fuel 0). Outside the map's speeds: inf (the bound refuses a speed it has no data for), or
        with ``clamp_speed`` the map's edge speed used for the look-up and the gears' range (the MPC's gear
        request, which must name a gear at any measured speed; the gears' engine speed still at the true speed)."""
        v, force = np.broadcast_arrays(np.asarray(v, float), np.asarray(force, float))
        vf, ff = v.ravel(), force.ravel()
        i, wv = _cell(self.speeds, vf)  # _cell clamps to the map's speeds
        j, wf = _cell(self.forces, ff)
        # bilinear in every gear's table at once: the cell's four corners, (gears, points)
        fuel = ((1 - wv) * ((1 - wf) * self.fuel[:, i, j] + wf * self.fuel[:, i, j + 1])
                + wv * ((1 - wf) * self.fuel[:, i + 1, j] + wf * self.fuel[:, i + 1, j + 1]))
        max_force = (1 - wv) * self.max_force[:, i] + wv * self.max_force[:, i + 1]
        omega = self.speed_ratio[:, None] * vf
        lo, hi = self.engine_speed_range
        inside = ff <= self.forces[-1]
        if not clamp_speed:
            inside &= (vf >= self.speeds[0]) & (vf <= self.speeds[-1])
        ok = inside & (omega >= lo) & (omega <= hi) & (ff <= max_force)
        return np.where(ok, fuel, np.inf).reshape((-1, *v.shape))

    def power(self, v, force) -> np.ndarray:
        """The least fuel power [W] over the gears that can give ``force`` [N] at ``v`` [m/s] (inf where none
        can; :meth:`gear_power`)."""
        return self.gear_power(v, force).min(axis=0)

    def boundary_forces(self, v) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """At speed ``v`` [m/s]: (the largest full-load wheel force over the gears [N], its fuel power [W], the
        least overrun drag over the gears [N], fuel 0); -inf / inf / -inf where no gear's engine speed is in
        range."""
        v = np.asarray(v, float)
        lo, hi = self.engine_speed_range
        full, coast = np.full(v.shape, -np.inf), np.full(v.shape, -np.inf)
        inside = (v >= self.speeds[0]) & (v <= self.speeds[-1])
        for g in range(self.fuel.shape[0]):
            omega = self.speed_ratio[g] * v
            ok = inside & (omega >= lo) & (omega <= hi)
            full = np.where(ok, np.maximum(full, np.interp(v, self.speeds, self.max_force[g])), full)
            coast = np.where(ok, np.maximum(coast, np.interp(v, self.speeds, self.drag_force[g])), coast)
        fuel = np.where(np.isfinite(full), self.power(v, np.where(np.isfinite(full), full, 0.0) - 1e-6), np.inf)
        return full, fuel, coast


def plant_fuel_map(vehicle, speeds: np.ndarray, forces: np.ndarray) -> PlantFuelMap:
    """The :class:`PlantFuelMap` of an ICE vehicle spec over the given speed [m/s] and wheel-force [N] grids."""
    from roadload.envs.powertrain import Powertrain

    pt = Powertrain(vehicle)
    d = vehicle.drivetrain
    engine = d.require_engine()
    if engine is None:
        raise OptimumError(f"{vehicle.name}: a plant fuel map needs an ICE")
    r = float(vehicle.tires.dynamic_radius)
    lo, hi = float(engine.idle_speed), float(engine.max_speed)
    speeds, forces = np.asarray(speeds, float), np.asarray(forces, float)
    fuel = np.zeros((d.n_gears, speeds.size, forces.size))
    max_force = np.zeros((d.n_gears, speeds.size))
    drag_force = np.zeros((d.n_gears, speeds.size))
    ratios = np.array([pt.speed_ratio(g) for g in range(1, d.n_gears + 1)])
    for g in range(1, d.n_gears + 1):
        for i, v in enumerate(speeds):
            omega = min(max(ratios[g - 1] * float(v), lo), hi)
            t_drag, t_max = pt.torque_limits(omega, float(v))
            max_force[g - 1, i] = f_max = pt.wheel_torque(g, t_max, omega) / r
            drag_force[g - 1, i] = f_drag = pt.wheel_torque(g, t_drag, omega) / r
            fuel[g - 1, i, forces >= f_max] = pt.fuel_power(omega, t_max)  # beyond full load: refused by max_force
            for j in np.flatnonzero((forces > f_drag) & (forces < f_max)):  # at or below the drag: fuel cut, 0
                t_e = min(max(pt.source_torque(g, float(forces[j]) * r, omega), t_drag), t_max)
                fuel[g - 1, i, j] = pt.fuel_power(omega, t_e)
    return PlantFuelMap(speeds, forces, fuel, max_force, drag_force, ratios, (lo, hi))


def smoothed_fuel_map(fuel_map: PlantFuelMap, sigma_speed: float = 0.5, sigma_force: float = 500.0,
                      cut_power: float = 1.0) -> PlantFuelMap:
    """The MPC's own fuel model (``MpcSettings.fuel_model = "plant_map"``) as a one-row :class:`PlantFuelMap`:
    fuel phi(v, F) [W] = :meth:`~.energy.PlantFuelModel.smooth_table` of ``fuel_map`` (the least fuel over the
    gears, smoothed by a Gaussian of sigma_speed [m/s] x sigma_force [N]; bilinear between its grid points where the
    NLP passes a cubic B-spline through them), the traction limit F <= F_max(v), the best gear's full load
    (:meth:`~.energy.PlantFuelModel.full_load_envelope`), and as its overrun edge the largest force at which
    phi <= ``cut_power`` [W] (the smooth model's fuel cut, below the raw map's least drag: the smoothing fills in
    the step there). One pseudo-gear of ratio 1 whose engine speed range is the map's speeds (every speed in it)."""
    model = PlantFuelModel(fuel_map, "smoothed")
    speeds, forces, phi = model.smooth_table(sigma_speed, sigma_force)
    _, envelope = model.full_load_envelope()
    first_fuelled = np.argmax(phi > cut_power, axis=1)  # the first force of each speed with fuel above cut_power
    edge = forces[np.maximum(first_fuelled - 1, 0)]
    return PlantFuelMap(speeds, forces, phi[None], envelope[None], edge[None], np.ones(1),
                        (float(speeds[0]), float(speeds[-1])))


def _stage_costs(preview: Preview, energy: SourceEnergyModel, params: RoadLoadParameters,
                 settings: OptimumSettings, grid: np.ndarray, offsets: np.ndarray, k: int, gear_choice: bool = False,
                 fuel_table: PlantFuelMap | None = None) -> tuple[np.ndarray, np.ndarray]:
    """(source energy [J], time [s]) of every transition v_i -> v_{i+d} of segment k (energy inf where
    infeasible; the time ds / v_mid everywhere)."""
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
    if fuel_table is None:  # the energy model's drive limits (the map has the plant's own)
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
    if fuel_table is not None:  # the plant's own fuel map, the gear of least fuel
        power = fuel_table.power(vm, force)
        ok &= np.isfinite(power)
    elif energy.kind == "ice" and gear_choice:  # the gear of least fuel for the net wheel force, fuel cut in braking
        power = energy.best_gear_fuel_power(force, vm)[0]
        ok &= np.isfinite(power)
    else:
        power = np.asarray(energy.source_power(traction, x_opt * limit, vm, ratio_obj), float)
    ok &= need - x_opt * limit <= energy.brake_force_limit(params.mass) + 1e-6
    dt = ds / vm
    cost = np.where(ok, power * dt, np.inf)
    # the time stays finite where a transition is infeasible (its cost is inf): an inf time would make the
    # recursion's mu dt = 0 x inf = nan at mu = 0, and argmin would pick that nan as the best transition
    return cost, dt


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
               fuel_table: PlantFuelMap | None = None) -> DpSolution:
    """The minimum-energy speed profile over the preview's nodes with trip time ``model_time`` [s] (module
    docstring). arrival_speed [m/s]: the end speed (nearest grid speed); None: the kinetic energy left is worth
    ``terminal_value`` [J per J]. speed_step [m/s]: grid resolution. gear_choice (ICE): fuel at the best gear
    with fuel cut (module docstring). energy_step [m^2/s^2]: a grid uniform in E = v^2/2 instead, so the
    accelerations a segment can take are spaced energy_step / ds at every speed (a speed grid spaces them
    v dv / ds: at 20 m/s, 0.05 m/s and 10 m apart, 0.1 m/s^2, too coarse for a heavy truck climbing at full load,
    whose deceleration there is a few hundredths of a m/s^2). fuel_table (ICE): the plant's own fuel map per gear
    (:func:`plant_fuel_map`) instead of the energy model, the gear of least fuel, its drive limits the plant's
    own, with the full-load and overrun transitions off the grid (:func:`_boundary_actions`)."""
    problem = DpProblem(preview, energy, params, settings, speed_step, gear_choice, energy_step, fuel_table)
    return problem.solve(model_time, start_speed, arrival_speed, time_tol, terminal_value)


def _boundary_actions(preview: Preview, params: RoadLoadParameters, st: OptimumSettings, fuel: PlantFuelMap,
                      grid: np.ndarray, k: int, cap_next: float, price: PlantFuelMap | None = None
                      ) -> list[tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]]:
    """Two transitions of segment k from every grid speed whose end speed the grid would only approximate: full
    load in the gear of the largest force, and coasting in overrun (fuel cut) in the gear of the least drag, each
    [(end energy E = v^2/2 [m^2/s^2], fuel [J], time [s])], inf fuel where infeasible. Without them a grid's
    quantised accelerations cut off a full-load climb or a coast (a heavy truck's decelerations there are
    hundredths of a m/s^2, a grid of 0.5 m^2/s^2 over 20 m spaces them 0.025 m/s^2 apart), which puts the DP
    above the plant's optimum by up to 1 % (docs/results/controllers.md). Each action also carries its fuel [J]
    booked in ``price`` (another map: at the same force, capped at that map's full load; None: the same fuel)."""
    ds = float(preview.ds[k]) if preview.ds is not None else float(preview.s[k + 1] - preview.s[k])
    m_in, e0 = params.inertial_mass, 0.5 * grid ** 2
    p = params.as_vector()
    out = []
    for action in ("full", "coast"):
        v1 = grid.copy()
        for _ in range(3):  # fixed point in the segment's mean speed
            vm = 0.5 * (grid + v1)
            full, fuel_full, coast = fuel.boundary_forces(vm)
            force = full if action == "full" else coast
            res = resistance_force(vm, float(preview.grade[k]), float(preview.curvature[k]), p)
            with np.errstate(invalid="ignore"):
                e1 = e0 + ds * (force - res) / m_in
            v1 = np.sqrt(np.clip(np.nan_to_num(e1, nan=0.0, neginf=0.0), 0.5 * st.speed_floor ** 2, None) * 2.0)
        acc = (e1 - e0) / ds
        ok = (np.isfinite(e1) & (e1 >= 0.5 * st.speed_floor ** 2 - 1e-9) & (e1 <= 0.5 * cap_next ** 2 + 1e-9)
              & (acc >= -st.decel_max) & (acc <= st.accel_max))
        dt = ds / vm
        power = fuel_full if action == "full" else np.zeros_like(vm)
        cost = np.where(ok & np.isfinite(power), power * dt, np.inf)
        booked = cost
        if price is not None:  # the same force in the other map (at most its own full load, a few N apart)
            with np.errstate(invalid="ignore"):
                f_price = np.minimum(force, price.boundary_forces(vm)[0] - 1e-6)
                booked = np.where(ok, price.power(vm, np.nan_to_num(f_price, neginf=0.0)) * dt, np.inf)
        out.append((np.where(ok, e1, 0.0), cost, dt, booked))
    return out


class DpProblem:
    """The discretised problem of :func:`dp_optimum` with every segment's transition costs computed once, so that
    it can be solved for many trip times, start and arrival speeds (one per controller run). Memory: the energy of
    every transition, float32, segments x grid speeds x (2 width + 1) x 4 bytes."""

    def __init__(self, preview: Preview, energy: SourceEnergyModel, params: RoadLoadParameters,
                 settings: OptimumSettings | None = None, speed_step: float = 0.05, gear_choice: bool = False,
                 energy_step: float | None = None, fuel_table: PlantFuelMap | None = None,
                 overspeed: float = 0.0, price_table: PlantFuelMap | None = None,
                 price_costs: np.ndarray | None = None) -> None:
        st = settings or OptimumSettings()
        if not (math.isfinite(speed_step) and speed_step > 0):
            raise OptimumError(f"speed_step: a finite step > 0 m/s, got {speed_step!r}")
        self.settings, self.speed_step, self.inertial_mass = st, float(speed_step), params.inertial_mass
        self.fuel_table = fuel_table
        self.s = np.asarray(preview.s, float)
        self.n = n = len(preview.s) - 1
        cap = np.maximum(np.asarray(preview.speed_cap, float) - st.speed_margin, st.speed_floor)
        grid, width = _speed_grid(st, float(cap.max()) + overspeed, float(np.max(np.diff(preview.s))), speed_step,
                                  energy_step)
        self.cap, self.overspeed = cap, float(overspeed)
        self.grid = grid
        self.offsets = offsets = np.arange(-width, width + 1)
        self.cost = np.empty((n, grid.size, offsets.size), np.float32)
        self.ds = np.diff(self.s) if preview.ds is None else np.asarray(preview.ds, float)
        for k in range(n):
            self.cost[k] = _stage_costs(preview, energy, params, st, grid, offsets, k, gear_choice, fuel_table)[0]
        # price_table: the chosen profile's energy also booked in another fuel map (the optimum of one model, its
        # fuel in another); the price of a transition that map refuses is inf. price_costs: that map's transition
        # costs already computed on this grid (another DpProblem's ``cost`` with the same settings and caps)
        self.price = None
        if price_table is not None and price_costs is not None:
            if price_costs.shape != self.cost.shape:
                raise OptimumError(f"price_costs: shape {price_costs.shape}, expected {self.cost.shape} (the same "
                                   f"nodes, grid and limits)")
            self.price = price_costs
        elif price_table is not None:
            self.price = np.empty_like(self.cost)
            for k in range(n):
                self.price[k] = _stage_costs(preview, energy, params, st, grid, offsets, k, gear_choice,
                                             price_table)[0]
        self.allowed = self._allowed = grid[None, :] <= cap[:, None] + 1e-9
        idx = np.arange(grid.size)[:, None] + offsets[None, :]
        self.inside = (idx >= 0) & (idx < grid.size)
        self.idx = np.clip(idx, 0, grid.size - 1)
        # time of a transition per metre: 1 / v_mid (the same at every segment; dt_k = ds_k / v_mid)
        self.pace = 2.0 / (grid[:, None] + grid[self.idx])
        self.energies = 0.5 * grid ** 2
        self.extra = ([_boundary_actions(preview, params, st, fuel_table, grid, k, cap[k + 1] + overspeed,
                                         price_table) for k in range(n)]
                      if fuel_table is not None else [])

    def _sweep(self, mu: float, final: np.ndarray, i0: int) -> tuple[np.ndarray, float, float, float]:
        """Bellman's recursion at the time multiplier mu [J/s]: (path of grid indices, energy [J], time [s], the
        path's energy booked in the price table [J]: the energy without one). With boundary actions (full load,
        overrun coasting; :func:`_boundary_actions`) their end state lies between grid points: the value, energies
        and time to go are interpolated linearly there, and the path records the nearest grid point."""
        n, rows = self.n, np.arange(self.grid.size)
        value = final
        books = 1 if self.price is None else 2  # rows of the energy to go: the objective's, the booked one
        e_go, t_go = np.zeros((books, self.grid.size)), np.zeros(self.grid.size)
        nxt = np.zeros((n, self.grid.size), dtype=np.int32)
        for k in range(n - 1, -1, -1):
            dt = self.ds[k] * self.pace
            q = self.cost[k] + mu * dt + np.where(self.inside, value[self.idx], np.inf)
            best = np.argmin(q, axis=1)
            best_q = q[rows, best]
            j = self.idx[rows, best]
            tables = (self.cost[k],) if self.price is None else (self.cost[k], self.price[k])
            new_e = np.stack([t[rows, best] for t in tables]) + e_go[:, j]
            new_t = dt[rows, best] + t_go[j]
            nxt[k] = j
            for e_end, cost, dt_b, booked in self.extra[k] if self.extra else ():
                lo = np.clip(np.searchsorted(self.energies, e_end) - 1, 0, self.grid.size - 2)
                w = np.clip((e_end - self.energies[lo]) / (self.energies[lo + 1] - self.energies[lo]), 0.0, 1.0)
                finite = np.isfinite(value[lo]) & np.isfinite(value[lo + 1]) & np.isfinite(cost)
                with np.errstate(invalid="ignore"):
                    cand = np.where(finite, cost + mu * dt_b + (1 - w) * value[lo] + w * value[lo + 1], np.inf)
                    take = cand < best_q
                    spent = np.stack((cost, booked)[:books]) + (1 - w) * e_go[:, lo] + w * e_go[:, lo + 1]
                best_q = np.where(take, cand, best_q)
                new_e = np.where(take, spent, new_e)
                new_t = np.where(take, dt_b + (1 - w) * t_go[lo] + w * t_go[lo + 1], new_t)
                nxt[k] = np.where(take, np.where(w < 0.5, lo, lo + 1), nxt[k])
            value = np.where(self._allowed[k], best_q, np.inf)
            e_go, t_go = np.where(np.isfinite(value), new_e, 0.0), np.where(np.isfinite(value), new_t, 0.0)
        if not np.isfinite(value[i0]):
            raise OptimumError("dynamic programming: no feasible speed profile on the grid (caps, limits or "
                               "arrival speed)")
        path = np.empty(n + 1, dtype=int)
        path[0] = i0
        for k in range(n):
            path[k + 1] = nxt[k, path[k]]
        return path, float(e_go[0, i0]), float(t_go[i0]), float(e_go[-1, i0])

    def solve(self, model_time: float, start_speed: float, arrival_speed: float | None = None,
              time_tol: float = 1e-4, terminal_value: float = 0.0, over_cap: float = 0.0,
              least_at_any_time: bool = False) -> DpSolution:
        """The minimum-energy profile in ``model_time`` [s] from ``start_speed`` [m/s] to ``arrival_speed`` [m/s]
        (nearest grid speeds; None: the kinetic energy left worth ``terminal_value`` [J per J]), the time
        multiplier found by bisection. over_cap [m/s]: every speed cap raised by this much (at most the problem's
        ``overspeed``), for a run that drove above the limit. least_at_any_time: a ``model_time`` slower than the
        least-energy trip (multiplier 0) returns that trip (its own time) instead of an error: no profile at any
        time uses less, so it is still a lower bound for the slower run."""
        if not (math.isfinite(model_time) and model_time > 0):
            raise OptimumError(f"model_time: a finite time > 0 s, got {model_time!r}")
        st, grid = self.settings, self.grid
        i0 = int(np.argmin(np.abs(grid - max(start_speed, st.speed_floor))))
        if arrival_speed is None:
            final = -terminal_value * self.inertial_mass * 0.5 * grid ** 2
        else:
            final = np.full(grid.size, np.inf)
            final[int(np.argmin(np.abs(grid - max(arrival_speed, st.speed_floor))))] = 0.0
        self._allowed = self.grid[None, :] <= self.cap[:, None] + min(max(over_cap, 0.0), self.overspeed) + 1e-9
        final = np.where(self._allowed[self.n], final, np.inf)
        lo, hi = 0.0, 1.0e3
        fast = self._sweep(hi, final, i0)
        while fast[2] > model_time and hi < 1e9:  # mu too small: the trip is still too slow
            lo, hi = hi, hi * 4.0
            fast = self._sweep(hi, final, i0)
        if fast[2] > model_time:
            raise OptimumError(f"model_time: {model_time:.1f} s is faster than the grid's fastest trip "
                               f"({fast[2]:.1f} s)")
        slow = self._sweep(lo, final, i0)
        if slow[2] < model_time and least_at_any_time and lo == 0.0:
            return DpSolution(s=self.s, v=grid[slow[0]], energy_J=slow[1], model_time=slow[2], multiplier=0.0,
                              speed_step=self.speed_step, priced_energy_J=None if self.price is None else slow[3])
        if slow[2] < model_time:
            raise OptimumError(f"model_time: {model_time:.1f} s is slower than the grid's slowest trip "
                               f"({slow[2]:.1f} s)")
        for _ in range(60):  # bisection on mu; the grid's time jumps, so keep the two runs around the target
            if min(abs(fast[2] / model_time - 1.0), abs(slow[2] / model_time - 1.0)) <= time_tol or hi - lo < 1e-6:
                break
            mid = 0.5 * (lo + hi)
            run = self._sweep(mid, final, i0)
            if run[2] > model_time:
                lo, slow = mid, run
            else:
                hi, fast = mid, run
        # the energy at exactly the target time: linear between the two runs that bracket it
        (p1, e1, t1, b1), (p2, e2, t2, b2) = fast, slow
        w = 0.0 if t2 == t1 else (model_time - t1) / (t2 - t1)
        path = p1 if w <= 0.5 else p2
        return DpSolution(s=self.s, v=grid[path], energy_J=float(e1 + w * (e2 - e1)), model_time=float(model_time),
                          multiplier=float(0.5 * (lo + hi)), speed_step=self.speed_step,
                          priced_energy_J=None if self.price is None else float(b1 + w * (b2 - b1)))


# the plant-fuel bound of a truck: 40 m nodes, a grid uniform in v^2/2 of 0.5 m^2/s^2 from 5 m/s to the speed cap
# (no safety margin: a bound allows every speed the plant may drive), the fuel map over 4.5-26.5 m/s x -30...+80 kN
TRUCK_BOUND_SETTINGS = OptimumSettings(ds=40.0, accel_max=1.0, decel_max=1.0, speed_floor=5.0, speed_margin=0.0,
                                       jerk=False)
TRUCK_BOUND_ENERGY_STEP = 0.5  # [m^2/s^2]
BOUND_OVERSPEED = 2.0  # [m/s] the grid reaches this far above the speed limit, for runs that drove above it
_FUEL_MAPS: dict[str, PlantFuelMap] = {}
BOUND_MODELS = ("plant", "smooth")  # PlantFuelBound's fuel model: the plant's raw map, the MPC's smoothed one


def cached_plant_fuel_map(vehicle, smooth: bool = False) -> PlantFuelMap:
    """:func:`plant_fuel_map` of an ICE vehicle spec over 4.5-26.5 m/s (0.25 m/s) and -30 ... +80 kN (250 N),
    once per process and spec; ``smooth``: its :func:`smoothed_fuel_map` (the MPC's model)."""
    key = json.dumps(vehicle.to_dict(), sort_keys=True)
    if key not in _FUEL_MAPS:
        _FUEL_MAPS[key] = plant_fuel_map(vehicle, np.arange(4.5, 26.5 + 1e-9, 0.25),
                                         np.arange(-30e3, 80e3 + 1.0, 250.0))
    if smooth and "smooth:" + key not in _FUEL_MAPS:
        _FUEL_MAPS["smooth:" + key] = smoothed_fuel_map(_FUEL_MAPS[key])
    return _FUEL_MAPS[("smooth:" if smooth else "") + key]


class PlantFuelBound:
    """A bound on an ICE plant's fuel [J] over the road segment [start, end] [m] at a given trip time, start
    and arrival speed: the dynamic programme with every transition's fuel at the gear of least fuel in the plant's
    own map (:class:`PlantFuelMap`: fuel cut in overrun, the brakes' force free), the true road-load parameters
    ``params`` (their rotating mass: the top gear's, the least), every speed from 5 m/s to the speed cap (no safety
    margin), accelerations within +-1 m/s^2, no jerk limit. Not converged in its grid: a finer energy step lowers
    it further (40 m nodes: 0.31 % lower at 0.25 m^2/s^2 on a 40 t climb; docs/results/controllers.md), so it lies
    above the plant's quasi-static optimum by about that much; the map leaves out in the plant's favour a lower
    gear's larger rotating mass when braking. Roads with stops are refused.

    ``model`` "smooth": the same programme optimised in the MPC's own fuel model instead (:func:`smoothed_fuel_map`:
    the smoothed least-over-gears table and its traction limit), and that profile's fuel booked in the plant's raw
    map (:meth:`solve` returns the booked fuel, the solution's ``energy_J`` the smooth model's): the optimum of the
    MPC's model over the whole route, in the plant's currency; no bound (it lies at or above the plant-fuel
    bound, whose optimisation the raw map is). ``plant_bound``: the plant-fuel bound of the same segment and
    settings, whose transition costs are the raw map's booking (computed once for both)."""

    problem: DpProblem

    def __init__(self, road, vehicle, params: RoadLoadParameters, start: float = 0.0, end: float | None = None,
                 settings: OptimumSettings = TRUCK_BOUND_SETTINGS,
                 energy_step: float = TRUCK_BOUND_ENERGY_STEP, model: str = "plant",
                 plant_bound: PlantFuelBound | None = None) -> None:
        from .optimum import route_nodes, route_preview
        from .vehicle_models import energy_model_from_spec

        if model not in BOUND_MODELS:
            raise OptimumError(f"PlantFuelBound model: choose one of {BOUND_MODELS}, got {model!r}")
        end = float(road.length if end is None else end)
        if any(start + 1e-6 < float(x) <= end + 1e-6 for x in np.asarray(road.stops, float)):
            raise OptimumError(f"road {road.name!r}: the plant-fuel bound takes roads without stops")
        energy = energy_model_from_spec(vehicle)
        if energy.kind != "ice":
            raise OptimumError(f"{vehicle.name}: the plant-fuel bound needs an ICE vehicle")
        self.eta = energy.indicated_efficiency
        self.inertial_mass = params.inertial_mass
        self.params = params
        preview = route_preview(road, route_nodes(start, end, [], settings.ds), energy, settings)
        self.speed_limit = float(np.max(preview.speed_cap))
        raw = cached_plant_fuel_map(vehicle)
        smooth = model == "smooth"
        self.problem = DpProblem(preview, energy, params, settings, gear_choice=True, energy_step=energy_step,
                                 fuel_table=cached_plant_fuel_map(vehicle, smooth=True) if smooth else raw,
                                 overspeed=BOUND_OVERSPEED, price_table=raw if smooth else None,
                                 price_costs=plant_bound.problem.cost if smooth and plant_bound is not None else None)

    def solve(self, trip_time: float, start_speed: float, arrival_speed: float, peak_speed: float = 0.0
              ) -> tuple[float, DpSolution]:
        """(the bound's fuel [J] from ``start_speed`` to ``arrival_speed`` [m/s] in ``trip_time`` [s], the DP's
        solution). The DP starts and ends at the nearest grid speeds; the kinetic-energy difference to the exact
        ones is booked at 1/eta_i (<= 0.25 m^2/s^2 x the inertial mass). peak_speed [m/s]: the run's highest speed;
        above the speed limit, the bound's caps are raised to it (at most :data:`BOUND_OVERSPEED`), so that it
        allows what the run did. A run slower than the least-fuel trip is bounded by that trip (the least fuel at
        any time; the solution's ``model_time`` is then shorter than ``trip_time``)."""
        sol = self.problem.solve(trip_time, start_speed, arrival_speed,
                                 over_cap=max(0.0, peak_speed - self.speed_limit), least_at_any_time=True)
        snap = (float(sol.v[0]) ** 2 - start_speed ** 2) + (arrival_speed ** 2 - float(sol.v[-1]) ** 2)
        fuel = sol.energy_J if sol.priced_energy_J is None else sol.priced_energy_J
        return fuel + 0.5 * self.inertial_mass * snap / self.eta, sol
