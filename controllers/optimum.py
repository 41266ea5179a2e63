"""The full-route optimum: the best drive physics allows, with perfect knowledge, at a fixed trip time.

One optimal-control problem over the whole route (or the measured segment [start, end]) in the spatial domain,
built from the MPC's own NLP (:meth:`roadload.controllers.mpc.OcpSolver._formulate`: the same states E = v^2/2,
the same traction / regeneration / friction-brake forces, the same source-energy model, drive limits, comfort
limits and speed caps), with three differences that make it the reference rather than a controller:

- the horizon is the whole route, known in advance: grade, curvature, speed limits, stops (a node exactly at each
  stop, where the speed is at the stop speed) and, with a wind vector, the headwind and crosswind of every segment;
- the objective is the source energy alone (no time weight, no comfort term): the trip time is a constraint,
  t_N = T - (stops x dwell), so every controller is compared at its own trip time;
- the end state is fixed (``terminal="speed"``: the arrival speed of the controller it is compared with), or the
  kinetic energy left is valued at its source cost (``"source"``) or at nothing (``"none"``, the cost of an RL
  episode, which ends at the road end).

The force model is the oracle's (the simulator's true parameters at the segment start) unless another is given.
The time constraint's multiplier is dE*/dT [J/s], the slope of the time-energy curve (``time_slope``).

What the optimum's model includes, and what the simulator (the plant every controller drives) has beyond it:
the road load of :func:`roadload.road_load.road_load` with the true parameters (rolling resistance with f_r1, f_r4,
drag with the headwind and crosswind of each segment, climbing, steady-state cornering resistance), the
rotating masses, and the source energy as the MPC's smooth fit of the drive-train maps (EV: motor / inverter /
battery loss polynomial; ICE: Willans line with the shift rule's gear as a smooth function of speed). The plant
adds what the model does not have: the drive-train maps themselves (the fit residual), the gearbox's own shift
strategy and shift transients (the tracker below requests the shift rule's gear), tyre slip and the lateral
dynamics (steering, side slip, the path the driver model follows), wind gusts, the control period and the
tracking error. So the optimum's trajectory, driven on the plant (:class:`OptimumTracker`), is the best trajectory
the model knows, measured on the same plant as the controllers; it bounds every controller only up to the model's
error on the plant (:func:`roadload.controllers.vehicle_models.FIT_QUALITY`), which is why a controller can come
out slightly below it.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, replace
from typing import Any

import casadi as ca
import numpy as np

from roadload.road_load import RoadLoadParameters
from roadload.road_profiles import RoadProfile

from .base import ControllerError, DriveContext, Observation
from .energy import SourceEnergyModel
from .force_model import WindEstimate, road_heading
from .mpc import MpcSettings, OcpSolver, Plan, Preview
from .mpc_controller import MpcController, MpcControllerSettings
from .safety import speed_cap

TERMINALS = ("speed", "source", "none")
TIME_FLOOR = 20.0  # [s] the tracker's time correction spreads a lateness over at least this much time
MAX_TIME_CORRECTION = 0.1  # [-] largest relative change of the tracked speed for the time correction


class OptimumError(ValueError):
    """Invalid optimum settings or an infeasible trip time (the message names the field and the value)."""


@dataclass(frozen=True)
class OptimumSettings:
    """Grid, comfort limits and solver settings of the full-route optimum (SI). The comfort limits, speed floor,
    stop speed and lateral acceleration default to the MPC's (:class:`~.mpc.MpcSettings`); ``speed_margin`` to
    the closed loop's safety guard, which keeps every controller 0.3 m/s under the speed envelope on the plant."""

    ds: float = 5.0  # target segment length [m]; each leg between stops is split into equal segments (5 m: within
    # 0.01 % of 2.5 m on a test road, 10 m is 0.2 % above)
    accel_max: float = MpcSettings.accel_max
    decel_max: float = MpcSettings.decel_max
    jerk_max: float = MpcSettings.jerk_max
    jerk: bool = True  # False: no jerk constraint (the dynamic-programming cross-check has none)
    lateral_accel_max: float = MpcSettings.lateral_accel_max
    speed_floor: float = MpcSettings.speed_floor
    stop_speed: float = MpcSettings.stop_speed
    speed_margin: float = MpcSettings.speed_margin
    stop_dwell: float = 5.0  # standstill per stop [s] (DriveContext.stop_dwell), not part of the spatial model
    accel_weight: float = 0.0  # comfort term of the objective (the MPC's accel_weight); 0: energy alone
    tol: float = 1e-8  # IPOPT tolerance
    max_iterations: int = 3000

    def __post_init__(self) -> None:
        for name in ("ds", "accel_max", "decel_max", "jerk_max", "lateral_accel_max", "speed_floor", "stop_speed",
                     "tol"):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
                raise OptimumError(f"OptimumSettings.{name}: must be a finite number > 0, got {value!r}")
        for name in ("speed_margin", "stop_dwell", "accel_weight"):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value >= 0):
                raise OptimumError(f"OptimumSettings.{name}: must be a finite number >= 0, got {value!r}")
        if self.max_iterations < 1:
            raise OptimumError(f"OptimumSettings.max_iterations: at least 1, got {self.max_iterations}")

    def mpc_settings(self, n_nodes: int) -> MpcSettings:
        """The MPC settings whose NLP (with n_nodes segments) the optimum composes its problem from."""
        return MpcSettings(n_nodes=n_nodes, ds=self.ds, accel_max=self.accel_max, decel_max=self.decel_max,
                           jerk_max=self.jerk_max, lateral_accel_max=self.lateral_accel_max,
                           speed_floor=self.speed_floor, stop_speed=self.stop_speed, speed_margin=self.speed_margin,
                           accel_weight=self.accel_weight, max_iterations=self.max_iterations,
                           cold_max_iterations=self.max_iterations, warm_tol=self.tol)


@dataclass
class OptimumSolution:
    """A solved full-route optimum: the plan (speed, time and forces over the nodes), its model energy, the time
    it was solved for and the slope of the time-energy curve there."""

    plan: Plan
    energy_J: float  # model source energy over the route [J]
    trip_time: float  # the target trip time [s] (model time + stops x dwell)
    model_time: float  # t_N of the spatial model [s]
    time_slope: float  # dE*/dT [J/s] (< 0: a slower trip needs less energy), from the constraint's multiplier
    start_speed: float  # [m/s]
    arrival_speed: float  # [m/s]
    terminal: str
    status: str
    solve_time: float  # wall [s]
    stops: int = 0

    @property
    def success(self) -> bool:
        return self.plan.success


def route_nodes(start: float, end: float, stops, ds: float) -> np.ndarray:
    """Node positions [m] from start to end: a node at every stop in (start, end), each leg between them split
    into equal segments of at most ``ds`` [m]."""
    if not (math.isfinite(start) and math.isfinite(end) and end > start):
        raise OptimumError(f"route: need start < end [m], got start={start}, end={end}")
    cuts = [start] + sorted(float(x) for x in stops if start + 1e-6 < float(x) < end - 1e-6) + [end]
    nodes = [start]
    for a, b in zip(cuts[:-1], cuts[1:]):
        n = max(1, int(math.ceil((b - a) / ds - 1e-9)))
        nodes.extend(a + (b - a) * np.arange(1, n + 1) / n)
    return np.asarray(nodes, float)


def route_preview(road: RoadProfile, nodes: np.ndarray, energy: SourceEnergyModel, settings: OptimumSettings,
                  wind: WindEstimate | None = None, stops=None) -> Preview:
    """The route on the optimum's grid: segment grade / curvature at the midpoints, per-node speed caps (the
    lowest cap over both adjacent segments; the stop speed at a stop's node), the shift-rule ratio bound and,
    with a wind vector, the headwind / crosswind of every segment from the road's heading there."""
    nodes = np.asarray(nodes, float)
    mid = 0.5 * (nodes[1:] + nodes[:-1])
    at = road.at(np.minimum(mid, road.length))
    fine_s = np.arange(0.0, road.length + 2.0, 1.0)
    fine_cap = speed_cap(road, settings.lateral_accel_max, np.minimum(fine_s, road.length))
    lo = np.searchsorted(fine_s, np.concatenate([[nodes[0]], nodes[:-1]]))
    hi = np.searchsorted(fine_s, np.concatenate([nodes[1:], [nodes[-1]]]), side="right")
    cap = np.array([fine_cap[a:max(b, a + 1)].min() for a, b in zip(lo, hi)])
    stop_list = np.asarray(road.stops if stops is None else stops, float)
    for stop in stop_list:
        k = np.flatnonzero(np.abs(nodes - stop) < 1e-6)
        cap[k] = settings.stop_speed
    n = nodes.size - 1
    ratio = np.full(n, energy.gear_ratios[0])  # ICE: the lowest gear bounds the traction force (as the MPC)
    headwind = crosswind = None
    yaw = 0.0
    if wind is not None:
        headwind, crosswind = wind.components(road_heading(road, mid))
        yaw = wind.yaw_drag_factor
    return Preview(s=nodes, grade=at["grade"], curvature=at["curvature"], speed_cap=cap, ratio=ratio,
                   headwind=headwind, crosswind=crosswind, yaw_drag_factor=yaw, ds=np.diff(nodes))


class TimedOcp(OcpSolver):
    """The MPC's NLP over a fixed grid with the trip time as an equality constraint and the source energy as the
    objective (module docstring); built once per (settings, powertrain, number of segments)."""

    def __init__(self, settings: MpcSettings, energy: SourceEnergyModel, jerk: bool = True) -> None:
        self.jerk = jerk
        super().__init__(settings, energy)

    def _build(self) -> None:
        f = self._formulate()
        x, p, g = f["x"], f["p"], f["g"]
        ke_value = ca.SX.sym("ke_value")  # value of the kinetic energy left at the end [J per J]
        obj = f["energy"] - ke_value * f["terminal_energy"] + f["comfort"] + f["regularisation"]
        self._nx, self._ng, self._np = x.numel(), g.numel() + 1, p.numel() + 1
        self._blocks_x = [self.n + 1, self.n, self.n, self.n]
        self._energy_fun = ca.Function("energy", [x, p], [f["energy"] * 1000.0])
        self._time_fun = ca.Function("time", [x, p], [f["t_end"]])
        nlp = {"x": x, "p": ca.vertcat(p, ke_value), "f": obj, "g": ca.vertcat(g, f["t_end"])}
        st = self.settings
        opts: dict[str, Any] = {"expand": True, "print_time": False, "error_on_fail": False,
                                "ipopt": {"print_level": 0, "sb": "yes", "max_iter": st.max_iterations,
                                          "tol": st.warm_tol, "acceptable_tol": 1e-6, "acceptable_iter": 10,
                                          "mu_strategy": "adaptive"}}
        self._solver = ca.nlpsol("optimum", "ipopt", nlp, opts)

    def solve_timed(self, v0: float, preview: Preview, params: RoadLoadParameters, model_time: float,
                    ke_value: float = 0.0, arrival_speed: float | None = None, a_prev: float = 0.0,
                    x0: np.ndarray | None = None) -> tuple[Plan, float]:
        """Minimum source energy from speed v0 [m/s] with t_N = model_time [s]; arrival_speed [m/s] fixes E_N,
        ke_value [1] values the kinetic energy left otherwise. Returns (plan, dE/dT [J/s])."""
        self._check(v0, a_prev, preview)
        lbx, ubx, lbg, ubg = self._bounds(v0, preview, params, a_prev)
        n = self.n
        if not self.jerk:
            lbg[2 * n:3 * n], ubg[2 * n:3 * n] = -np.inf, np.inf
        if arrival_speed is not None:  # at most the cap at the end (a run may arrive above cap - margin; the
            # caller books the difference of the kinetic energy)
            lbx[n] = ubx[n] = min(0.5 * max(arrival_speed, self.settings.speed_floor) ** 2, ubx[n])
        lbg = np.append(lbg, model_time)
        ubg = np.append(ubg, model_time)
        p = np.append(self._params(a_prev, preview, params, 0.0), ke_value)
        if x0 is None:
            length = float(preview.s[-1] - preview.s[0])
            x0 = self.initial_guess(v0, preview, params, a_prev, target_speed=1.1 * length / model_time)
        t0 = time.perf_counter()
        res = self._solver(x0=np.clip(x0, lbx, ubx), lbx=lbx, ubx=ubx, lbg=lbg, ubg=ubg, p=p)
        elapsed = time.perf_counter() - t0
        stats = self._solver.stats()
        status = str(stats.get("return_status", "unknown"))
        x = np.asarray(res["x"]).ravel()
        ok = (bool(stats.get("success", False)) or status == "Solved_To_Acceptable_Level") and bool(
            np.all(np.isfinite(x)))
        lam_g = np.asarray(res["lam_g"]).ravel()
        plan = self._plan_from_x(x, preview, ok, status, elapsed, int(stats.get("iter_count", -1)), float(res["f"]),
                                 np.asarray(res["lam_x"]).ravel(), lam_g[:-1])
        # d(objective [kJ])/d(t_N [s]) = -lam_g of the time row (the Lagrangian f + lam_g g)
        return plan, -1000.0 * float(lam_g[-1])


_TIMED: dict[tuple[MpcSettings, SourceEnergyModel, bool], TimedOcp] = {}


def timed_solver(settings: MpcSettings, energy: SourceEnergyModel, jerk: bool = True) -> TimedOcp:
    """The built time-constrained NLP for these settings (its number of segments) and powertrain, once per
    process."""
    key = (settings, energy, jerk)
    if key not in _TIMED:
        _TIMED[key] = TimedOcp(settings, energy, jerk)
    return _TIMED[key]


class FullRouteOptimum:
    """The optimum on one road segment [start, end] [m] for a vehicle's energy model and road-load parameters
    (module docstring). ``wind``: the wind vector (headwind and crosswind per segment from the road's heading)."""

    def __init__(self, road: RoadProfile, energy: SourceEnergyModel, params: RoadLoadParameters,
                 settings: OptimumSettings | None = None, start: float = 0.0, end: float | None = None,
                 wind: WindEstimate | None = None) -> None:
        self.road, self.energy, self.params = road, energy, params
        self.settings = settings or OptimumSettings()
        self.start = float(start)
        self.end = float(road.length if end is None else end)
        if not 0.0 <= self.start < self.end <= road.length + 1e-9:
            raise OptimumError(f"segment: need 0 <= start < end <= road length {road.length:.1f} m, got "
                               f"[{start}, {end}]")
        self.stops = [float(x) for x in np.asarray(road.stops, float) if self.start + 1e-6 < x <= self.end + 1e-6]
        nodes = route_nodes(self.start, self.end, self.stops, self.settings.ds)
        self.preview = route_preview(road, nodes, energy, self.settings, wind, self.stops)
        self.n = nodes.size - 1
        self.ocp = timed_solver(self.settings.mpc_settings(self.n), energy, self.settings.jerk)
        self._last: dict[str, np.ndarray] = {}

    @property
    def length(self) -> float:
        return self.end - self.start

    def model_time(self, trip_time: float) -> float:
        """The spatial model's t_N [s] for a trip time [s]: the trip time less the dwell at every stop."""
        return trip_time - len(self.stops) * self.settings.stop_dwell

    def solve(self, trip_time: float, start_speed: float = 0.0, arrival_speed: float | None = None,
              terminal: str = "speed", a_prev: float = 0.0) -> OptimumSolution:
        """Minimum source energy over the segment in ``trip_time`` [s] from ``start_speed`` [m/s].
        terminal: 'speed' (arrive at ``arrival_speed`` [m/s], required), 'source' (kinetic energy left valued at
        1/eta_i, the net metric) or 'none' (worth nothing)."""
        if terminal not in TERMINALS:
            raise OptimumError(f"terminal: choose one of {TERMINALS}, got {terminal!r}")
        if terminal == "speed" and (arrival_speed is None or not math.isfinite(arrival_speed)
                                    or arrival_speed < 0):
            raise OptimumError(f"arrival_speed: terminal 'speed' needs a finite arrival speed >= 0 m/s, got "
                               f"{arrival_speed!r}")
        if not (math.isfinite(start_speed) and start_speed >= 0):
            raise OptimumError(f"start_speed: a finite speed >= 0 m/s, got {start_speed!r}")
        t_model = self.model_time(trip_time)
        if not (math.isfinite(trip_time) and t_model > 0):
            raise OptimumError(f"trip_time: a finite time [s] longer than the stops' dwell "
                               f"({len(self.stops)} x {self.settings.stop_dwell:g} s), got {trip_time!r}")
        fastest = self.length / float(np.max(self.preview.speed_cap))
        if t_model < fastest:
            raise OptimumError(f"trip_time: {trip_time:.1f} s is shorter than driving the {self.length:.0f} m at the "
                               f"highest speed cap ({fastest:.1f} s)")
        ke_value = {"speed": 0.0, "source": 1.0 / self.energy.indicated_efficiency, "none": 0.0}[terminal]
        key = terminal
        plan, slope = self.ocp.solve_timed(start_speed, self.preview, self.params, t_model, ke_value,
                                           arrival_speed if terminal == "speed" else None, a_prev)
        if not plan.success and key in self._last:  # retry from the last solution of this route
            plan, slope = self.ocp.solve_timed(start_speed, self.preview, self.params, t_model, ke_value,
                                               arrival_speed if terminal == "speed" else None, a_prev,
                                               x0=self._last[key])
        if plan.success and plan.x is not None:
            self._last[key] = plan.x
        p = np.append(self.ocp._params(a_prev, self.preview, self.params, 0.0), ke_value)
        energy = float(self.ocp._energy_fun(plan.x, p[:-1])) if plan.x is not None else float("nan")
        return OptimumSolution(plan=plan, energy_J=energy, trip_time=float(trip_time),
                               model_time=float(plan.t[-1]), time_slope=slope, start_speed=float(start_speed),
                               arrival_speed=float(plan.v[-1]), terminal=terminal, status=plan.status,
                               solve_time=plan.solve_time, stops=len(self.stops))


    def solve_weighted(self, time_weight: float, start_speed: float = 0.0, terminal: str = "none",
                       arrival_speed: float | None = None, iterations: int = 40) -> OptimumSolution:
        """The trip time is free: minimum of E + lambda T [J] (lambda = ``time_weight`` [J/s]), the objective of the
        MPC and of the RL reward. E*(T) is convex, so its minimum is where dE*/dT = -lambda: bisection on the trip
        time between the fastest feasible trip and one at 3 m/s."""
        if not (math.isfinite(time_weight) and time_weight > 0):
            raise OptimumError(f"time_weight: a finite number > 0 [J/s], got {time_weight!r}")
        stop_time = len(self.stops) * self.settings.stop_dwell
        lo = stop_time + 1.02 * self.length / float(np.max(self.preview.speed_cap))
        hi = stop_time + self.length / 3.0
        best = None
        while hi / lo > 1.0 + 1e-5 and iterations > 0:
            iterations -= 1
            mid = math.sqrt(lo * hi)
            try:
                sol = self.solve(mid, start_speed, arrival_speed, terminal)
            except OptimumError:
                sol = None
            if sol is None or not sol.success:
                lo = mid  # too fast to be feasible
                continue
            best = sol
            if sol.time_slope < -time_weight:
                lo = mid  # energy still falls faster than lambda: a slower trip is cheaper
            else:
                hi = mid
        if best is None:
            raise OptimumError(f"time_weight {time_weight:g} J/s: no feasible trip time found")
        return best


@dataclass(frozen=True)
class OptimumTarget:
    """What the tracked optimum must achieve on the segment [measure_from, road end]: its trip time [s] and the
    arrival speed [m/s] (None: the terminal value decides)."""

    trip_time: float
    arrival_speed: float | None = None
    terminal: str = "speed"
    measure_from: float = 0.0


class OptimumTracker(MpcController):
    """Drives the full-route optimum on a plant: at the segment start (its first step) it solves the optimum from
    the current speed with the oracle's parameters (and wind), then tracks the plan with the MPC's tracking law
    (segment force + speed feedback, comfort and jerk limits, the safety guard and the stop manoeuvre of
    :class:`~.base.ControllerBase`). ICE: requests the shift rule's gear, which the plan's energy model assumes, and
    a lower gear where that gear's full load cannot give the force the road takes to follow the plan
    (:meth:`~.mpc_controller.MpcController.road_force`)."""

    name = "optimum"

    def __init__(self, target: OptimumTarget, settings: OptimumSettings | None = None) -> None:
        super().__init__(MpcControllerSettings(gear_command=True))
        self.target = target
        self.optimum_settings = settings or OptimumSettings()
        self.solution: OptimumSolution | None = None

    def reset(self, ctx: DriveContext) -> None:
        super().reset(ctx)
        self.solution = None
        self._t_start: float | None = None
        self._after_stop = -np.inf  # position of the last served stop [m]

    def serve_stop(self, index: int) -> None:
        super().serve_stop(index)
        self._after_stop = float(self.envelope.stops[index])

    def wheel_force(self, obs: Observation) -> float:
        """The MPC's tracking law on the plan; after a served stop the car, at rest a few centimetres before the
        stop's node, tracks the plan from that node on (the plan's segment before it brakes into the stop)."""
        if obs.s < self._after_stop + 1e-3:
            obs = replace(obs, s=self._after_stop + 1e-3)
        return super().wheel_force(obs)

    def _replan(self, obs: Observation) -> None:
        if self.solution is None:
            ctx = self.ctx
            wind = ctx.force_model.wind() if hasattr(ctx.force_model, "wind") else None
            opt = FullRouteOptimum(ctx.road, ctx.energy, self.params(), self.optimum_settings,
                                   start=max(obs.s, self.target.measure_from), wind=wind)
            self.solution = opt.solve(self.target.trip_time, obs.v, self.target.arrival_speed, self.target.terminal)
            self._t_start = obs.t
            if not self.solution.success:
                raise ControllerError(f"full-route optimum not solved ({self.solution.status}) for trip time "
                                      f"{self.target.trip_time:.1f} s")
        self.plan = self.solution.plan
        self.mode = "mpc"

    def reference_speed(self, obs: Observation) -> float:
        """The plan's speed, raised (lowered) by the relative lateness against the plan's time at this position:
        v_ref = v_plan(s) (1 + clip(e / max(T_left, time_floor), +-max_time_correction)), e = t - t_start - t_plan(s)
        - (served stops) x dwell, so the plant arrives at the target time despite the tracking lag."""
        plan = self.plan
        if plan is None or self._t_start is None:
            return super().reference_speed(obs)
        served = int(np.sum(self.envelope.served & (self.envelope.stops > plan.s[0])))
        t_plan = float(np.interp(obs.s, plan.s, plan.t)) + served * self.ctx.stop_dwell
        late = obs.t - self._t_start - t_plan
        stops = self.solution.stops if self.solution is not None else 0
        left = max(float(plan.t[-1]) + stops * self.ctx.stop_dwell - t_plan, TIME_FLOOR)
        gain = float(np.clip(late / left, -MAX_TIME_CORRECTION, MAX_TIME_CORRECTION))
        return float(plan.speed_at(obs.s)) * (1.0 + gain)

    def stats(self) -> dict[str, Any]:
        out = super().stats()
        if self.solution is not None:
            out.update(optimum_model_energy_J=self.solution.energy_J, optimum_time_slope=self.solution.time_slope,
                       optimum_model_time=self.solution.model_time, optimum_status=self.solution.status)
        return out
