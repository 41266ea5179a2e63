"""The receding-horizon eco-driving controller around :class:`~.mpc.OcpSolver`.

Every ``replan_period`` seconds it previews the road ahead (grade, curvature, caps, stops) on the MPC grid,
re-reads the force model's parameters, and solves warm-started from the previous plan. Between re-plans it
tracks the plan by distance: the segment's planned wheel force (looked up ``lookahead_time`` ahead) plus speed
feedback, F = F_plan(s + v tau) + m k_v (v_plan(s) - v), clipped so the model acceleration stays within the
comfort bounds, with |dF/dt| <= m j_max.

On a solver failure (not converged, infeasible, exception) it returns a safe command and counts the event:
first the shifted previous plan (while it still covers ``min_plan_left`` metres and the speed is within
``plan_tolerance`` of it), otherwise the cruise-control law (:mod:`.cruise`) until the next successful solve.

When a stop or a speed cap ahead cannot be met within the comfort limits (the plan is relaxed or infeasible with
a ``stop`` / ``speed_cap`` violation, :class:`~.mpc.ConstraintViolation`), the plan is not followed. Instead:

1. maximum-comfort brake: F = F_resist - m decel_max (jerk-limited like every command), while braking at
   decel_max from the current state still meets the violated constraint's actual value (the margin is given up);
2. emergency brake: F = F_resist - m a_req, a_req = (v^2 - v_lim^2) / (2 d) the constant deceleration that meets
   it d metres ahead (v_lim = 0 at a stop line), at most ``DriveContext.emergency_decel``, without the comfort jerk
   limit, once comfort braking no longer suffices.

The controller re-plans every control step while it brakes and returns to the plan as soon as one meets every
stop and cap again. Events: ``relaxed_plans`` / ``infeasible_plans`` (solves that did not meet every constraint),
``fallback_brake`` (solves that started or continued a fallback brake), ``comfort_brake_steps`` and
``emergency_brake_steps`` (control steps in each); ``stats()['worst_violation']`` describes the largest violation
of the run. The safety envelope of :class:`~.base.ControllerBase` clips every command as well, so no fallback can
exceed a limit the envelope can still keep.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from roadload.schema import check_field_types
from .base import Command, ControllerBase, ControllerError, DriveContext, Observation
from .cruise import CruiseLaw, CruiseSettings
from .energy import SourceEnergyModel
from .force_model import road_heading
from .mpc import SEGMENT0_FRACTIONS, ConstraintViolation, MpcSettings, OcpSolver, Plan, Preview
from .safety import speed_cap

# a kicked-down gear is kept until the road force is below this share of the shift rule's gear's full load
KICK_DOWN_RETURN = 0.95

_SOLVERS: dict[tuple[MpcSettings, SourceEnergyModel], OcpSolver] = {}


def get_solver(settings: MpcSettings, energy: SourceEnergyModel) -> OcpSolver:
    """The built solver for these settings and powertrain (built once per process, reused across runs)."""
    key = (settings, energy)
    if key not in _SOLVERS:
        _SOLVERS[key] = OcpSolver(settings, energy)
    return _SOLVERS[key]


@dataclass(frozen=True)
class TripSchedule:
    """A trip-time target for the measured segment [start, end] [m]: ``duration`` [s] from the moment the vehicle
    passes ``start`` (the continuous time knob of the truck comparison).

    The controller keeps lambda of the MPC objective on schedule by feedback on the lateness
    e = t - t_sched(s), t_sched linear in distance over the segment [s]:
        ln lambda = ln lambda_0 + clip(gain e / max(T_left, time_floor), +-max_log_change),
    T_left the scheduled time still to go [s]. Where the fixed-lambda closed loop jumps between two branches
    (a truck's speed-dependent gear makes the fuel per metre non-convex in speed), lambda then moves to the
    crossover and the vehicle mixes the two cruising speeds, so the segment time follows ``duration``
    continuously. Before ``start`` lambda is lambda_0."""

    start: float
    end: float
    duration: float
    gain: float = 20.0
    # k_i [1/s^2]: ln lambda += k_i * integral of e dt; 0 = off (0.01 wound lambda up to 30 x on a power-limited
    # truck and made energy a rough function of time: fit residual 0.98 %)
    integral_gain: float = 0.0
    time_floor: float = 30.0  # [s]
    max_log_change: float = 4.0
    # shape of t_sched: the fraction of ``duration`` scheduled at the positions ``shape_s`` [m] (increasing from
    # 0 at start to 1 at end, e.g. a cruise-control run's time profile, so a power-limited climb is scheduled
    # slow); empty: linear in distance
    shape_s: tuple[float, ...] = ()
    shape_fraction: tuple[float, ...] = ()

    def __post_init__(self) -> None:
        for name in ("start", "end", "duration", "gain", "integral_gain", "time_floor", "max_log_change"):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and math.isfinite(value)):
                raise ControllerError(f"TripSchedule.{name}: must be a finite number, got {value!r}")
        if not 0 <= self.start < self.end:
            raise ControllerError(f"TripSchedule: need 0 <= start < end [m], got start={self.start}, end={self.end}")
        if (not self.duration > 0 or not self.time_floor > 0 or self.gain < 0 or self.max_log_change < 0
                or self.integral_gain < 0):
            raise ControllerError(f"TripSchedule: duration and time_floor must be > 0 [s], gain and max_log_change "
                                  f">= 0, got {self.duration}, {self.time_floor}, {self.gain}, {self.max_log_change}")
        if len(self.shape_s) != len(self.shape_fraction) or (self.shape_s and (
                np.any(np.diff(self.shape_s) <= 0) or np.any(np.diff(self.shape_fraction) < 0))):
            raise ControllerError("TripSchedule.shape_s / shape_fraction: equal lengths, positions [m] strictly "
                                  "increasing and fractions non-decreasing")

    def fraction(self, s: float) -> float:
        """Scheduled fraction [-] of ``duration`` elapsed at position s [m] (0 at start, 1 at end)."""
        x = min(max((s - self.start) / (self.end - self.start), 0.0), 1.0)
        if not self.shape_s:
            return x
        return float(np.clip(np.interp(s, self.shape_s, self.shape_fraction), 0.0, 1.0))

    def lateness(self, t: float, s: float, t_start: float) -> float:
        """e = t - t_sched(s) [s] (> 0: behind schedule)."""
        return t - (t_start + self.fraction(s) * self.duration)

    def time_weight(self, lam0: float, t: float, s: float, t_start: float, integral: float = 0.0) -> float:
        """lambda [J/s] at time t [s] and position s [m] of a vehicle that passed ``start`` at t_start [s];
        ``integral``: the running integral of the lateness [s^2] (integral_gain)."""
        left = max((1.0 - self.fraction(s)) * self.duration, self.time_floor)
        x = self.gain * self.lateness(t, s, t_start) / left + self.integral_gain * integral
        return lam0 * math.exp(float(np.clip(x, -self.max_log_change, self.max_log_change)))


@dataclass(frozen=True)
class MpcControllerSettings:
    mpc: MpcSettings = field(default_factory=MpcSettings)
    replan_period: float = 1.0  # [s]
    speed_gain: float = 1.0  # k_v [1/s]
    lookahead_time: float = 0.3  # [s] the segment force is applied this early (the jerk limit ramps it)
    plan_tolerance: float = 2.0  # [m/s] previous plan usable as fallback while |v - v_plan| below this
    min_plan_left: float = 300.0  # [m] of previous plan ahead needed to keep using it
    fallback: CruiseSettings = field(default_factory=lambda: CruiseSettings(fraction=0.9))
    schedule: TripSchedule | None = None  # trip-time target: lambda by feedback (TripSchedule); None: fixed lambda
    # [s] every this often a second IPOPT solve starts cold from a plan cruising ``multistart_step`` [m/s] faster or
    # slower (behind / ahead of schedule; alternating without one) and replaces the warm-started plan when its
    # objective is lower: the truck's NLP has two local cruise optima (gears), and warm starts never leave one.
    # 0 = off
    multistart_period: float = 0.0
    multistart_step: float = 4.0  # [m/s]
    # ICE: request the gear of the MPC's own shift rule (SourceEnergyModel.shift_speeds, the gear its fuel model
    # plans with) instead of leaving the transmission to its load-dependent strategy, as predictive powertrain
    # control does; held within +-gear_band [m/s] of a shift speed, from gear_min_speed [m/s] up (below: the
    # transmission's launch and low gears). Without it, the plant downshifts under load where the plan assumed
    # the higher gear, and a 0.1 m/s difference in cruise speed changes the fuel of a whole climb
    gear_command: bool = False  # (and a lower gear where the shift rule's full load cannot give the road's force)
    gear_band: float = 0.5  # [m/s]
    gear_min_speed: float = 10.0  # [m/s]
    # with MpcSettings.fuel_model "plant_map" the request is instead the plant map's gear of least fuel at the
    # measured speed and the commanded wheel force (energy.PlantFuelModel.least_fuel_gear: a gear shifted into
    # gives the force within gear_load_margin of its full load), the engaged request kept while its full load gives
    # the force and its fuel is within (1 + gear_fuel_hysteresis) of the least, and for at least gear_hold_time [s]
    # after a shift (no hunting)
    gear_fuel_hysteresis: float = 0.005  # [-] (3 % kept the plant in a gear 3 % above the least on a 40 t climb)
    gear_load_margin: float = 0.98  # [-] (0.95 refused the least-fuel gear where the plan rides its full load)
    gear_hold_time: float = 2.0  # [s]

    def __post_init__(self) -> None:
        check_field_types(self, ControllerError)
        for name in ("replan_period", "speed_gain", "lookahead_time", "plan_tolerance", "min_plan_left",
                     "multistart_period", "multistart_step", "gear_band", "gear_min_speed", "gear_fuel_hysteresis",
                     "gear_hold_time"):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value >= 0):
                raise ControllerError(f"MpcControllerSettings.{name}: must be a finite number >= 0, got {value!r}")
        if not 0 < self.gear_load_margin <= 1:
            raise ControllerError(f"MpcControllerSettings.gear_load_margin: a share of full load in (0, 1], got "
                                  f"{self.gear_load_margin!r}")
        if not self.replan_period > 0:
            raise ControllerError(f"MpcControllerSettings.replan_period: must be > 0 [s], got {self.replan_period}")


class MpcController(ControllerBase):
    """Spatial MPC eco-driving controller (module docstring). ``force_model`` comes with the DriveContext."""

    name = "mpc"

    def __init__(self, settings: MpcControllerSettings | None = None) -> None:
        super().__init__()
        self.settings = settings or MpcControllerSettings()

    # ------------------------------------------------------------------ lifecycle
    def reset(self, ctx: DriveContext) -> None:
        st = self.settings.mpc
        if not ctx.emergency_decel >= st.decel_max:
            raise ControllerError(f"DriveContext.emergency_decel: must be >= the MPC's comfort deceleration "
                                  f"decel_max = {st.decel_max:g} m/s^2, got {ctx.emergency_decel}")
        super().reset(ctx)
        self.ocp = get_solver(st, ctx.energy)
        self.plan: Plan | None = None
        self.mode = "mpc"
        self._next_replan = -np.inf
        self._last_force: float | None = None
        self.solve_times: list[float] = []
        self.iterations: list[int] = []
        self.cruise = CruiseLaw(self.settings.fallback, ctx, ctx.force_model.parameters())
        road = ctx.road
        self._fine_s = np.arange(0.0, road.length + st.horizon + 2 * st.ds, 2.0)
        self._fine_cap = speed_cap(road, st.lateral_accel_max, np.minimum(self._fine_s, road.length))
        self._unserved = list(np.sort(np.asarray(road.stops, dtype=float)))
        self._next_multistart = 0.0
        self._multistart_sign = 1.0
        self._gear: int | None = None  # 0-based gear of the shift rule (with hysteresis)
        self._requested: int | None = None  # 1-based gear of the last request (a kick-down below _gear)
        self._traction_sent: float | None = None  # [N] traction of the last command
        self._shifted_at = -np.inf  # [s] time of the last change of the least-fuel gear request
        self._brake_target: ConstraintViolation | None = None  # the stop / cap the fallback brake is meeting
        self._worst: ConstraintViolation | None = None
        self.reset_schedule()

    def reset_schedule(self) -> None:
        """Forgets the trip schedule's state (start crossing, lateness and its integral, lambda history)."""
        self._schedule_start: float | None = None  # time [s] the vehicle passed the schedule's start
        self._late = 0.0
        self._late_integral = 0.0  # [s^2]
        self._last_s: tuple[float, float] | None = None  # (t [s], s [m]) of the previous solve
        self.time_weights: list[float] = []

    def serve_stop(self, index: int) -> None:
        super().serve_stop(index)
        self.cruise.serve_stop(index)
        stop = float(self.envelope.stops[index])
        self._unserved = [x for x in self._unserved if abs(x - stop) > 1e-9]
        self.plan = None  # re-plan from standstill
        self._next_replan = -np.inf

    def stats(self) -> dict[str, Any]:
        out = dict(self.events)
        times = np.asarray(self.solve_times)
        out.update(solves=int(times.size),
                   solve_time_median=float(np.median(times)) if times.size else float("nan"),
                   solve_time_p99=float(np.percentile(times, 99)) if times.size else float("nan"),
                   iterations_median=float(np.median(self.iterations)) if self.iterations else float("nan"),
                   time_weight_median=float(np.median(self.time_weights)) if self.time_weights else float("nan"),
                   fallbacks=int(self.events["fallback_shifted_plan"] + self.events["fallback_cruise"]
                                 + self.events["fallback_brake"]),
                   relaxed_plans=int(self.events["relaxed_plans"]),
                   infeasible_plans=int(self.events["infeasible_plans"]),
                   worst_violation=self._worst.describe() if self._worst is not None else "")
        return out

    # ------------------------------------------------------------------ preview
    def preview(self, s0: float, v0: float) -> Preview:
        st, road, en = self.settings.mpc, self.ctx.road, self.ctx.energy
        n, ds = st.n_nodes, st.ds
        grid = st.grid_lengths()
        s = s0 + np.concatenate([[0.0], np.cumsum(grid)])
        at_stop = self._nodes_at_stops(s)
        segment_lengths = None if not at_stop and np.all(grid == ds) else np.diff(s)
        if st.horizon_to_route_end and s[-1] > road.length:  # nodes past the road end collapse onto it
            beyond = s > road.length
            s[beyond] = road.length + 1e-3 * (1.0 + np.arange(int(beyond.sum())))
            segment_lengths = np.diff(s)
        mid = np.minimum(s[:-1] + 0.5 * ds if segment_lengths is None else 0.5 * (s[:-1] + s[1:]), road.length)
        at = road.at(mid)
        # node cap: the lowest cap over both adjacent segments, so the (monotone within a segment) planned
        # speed respects the cap everywhere between nodes, wherever the moving grid falls
        lo = np.searchsorted(self._fine_s, np.concatenate([[s[0] - ds], s[:-1]]))
        hi = np.searchsorted(self._fine_s, np.concatenate([s[1:], [s[-1] + ds]]), side="right")
        cap = np.array([self._fine_cap[a:max(b, a + 1)].min() for a, b in zip(lo, hi)])
        for stop in self._unserved:
            if stop in at_stop:
                cap[at_stop[stop]] = st.stop_speed
            elif s[0] - 1.0 <= stop <= s[-1]:
                k = int(np.searchsorted(s, stop, side="right")) - 1  # the segment the line lies in
                cap[max(k, 0):min(k + 2, n + 1)] = st.stop_speed
        inside = s0 + SEGMENT0_FRACTIONS * (s[1] - s0)  # sampled points of segment 0 (a node may sit at a stop)
        seg0 = np.interp(inside, self._fine_s, self._fine_cap)
        for stop in self._unserved:
            if s0 - 1.0 <= stop <= s[1] and stop not in at_stop:
                seg0 = np.where(inside >= stop - 1e-9, np.minimum(seg0, st.stop_speed), seg0)
        if self.plan is not None:
            v_guess = self.plan.speed_at(mid)
        else:
            v_guess = np.full(n, max(v0, st.speed_floor))
        ratio = np.full(n, en.gear_ratios[0]) if en.kind == "ice" else en.ratio_for_speed(v_guess)  # ICE: lowest
        # gear for the traction-force bound (the power constraint limits the rest); the objective's gear follows
        # the planned speed through the smooth shift rule
        stops = np.array([x for x in self._unserved if s[0] - 1.0 <= x <= s[-1]], dtype=float)
        headwind = crosswind = None
        yaw = 0.0
        wind = self.ctx.force_model.wind() if hasattr(self.ctx.force_model, "wind") else None
        if wind is not None:  # a force model that knows the wind vector: the wind of the road's heading ahead
            headwind, crosswind = wind.components(road_heading(road, mid))
            yaw = wind.yaw_drag_factor
        return Preview(s=s, grade=at["grade"], curvature=at["curvature"], speed_cap=cap, ratio=ratio,
                       segment0_cap=seg0, stops=stops, headwind=headwind, crosswind=crosswind,
                       yaw_drag_factor=yaw, ds=segment_lengths)

    def _nodes_at_stops(self, s: np.ndarray) -> dict[float, int]:
        """Moves the grid node nearest to each unserved stop onto its line (in place; node 0 is the current state
        and stays), so the plan's stop speed holds at the line itself rather than on the whole segment before it:
        a cap on the node before the line made the plan crawl up to ds metres and the tracker slow down early.
        Each segment keeps at least half its grid length (MpcSettings.grid_lengths); a stop that would leave a
        shorter one (within half a segment of the vehicle, or next to another stop) keeps the caps on both nodes
        around it, and one beyond the last node stays out of view. Returns {stop: node index}."""
        n = len(s) - 1
        lengths = np.diff(s)  # the grid's lengths before any node moves
        moved: dict[float, int] = {}
        for stop in self._unserved:
            if not s[0] <= stop <= s[-1]:  # behind the vehicle, or beyond the horizon (which stays where it ends)
                continue
            j = int(round(float(np.interp(stop, s, np.arange(n + 1)))))  # the nearest node (0: the vehicle's)
            if j < 1 or j in moved.values():
                continue
            right = s[j + 1] - stop if j < n else lengths[-1]
            if stop - s[j - 1] >= 0.5 * lengths[j - 1] and right >= 0.5 * lengths[min(j, n - 1)]:
                s[j] = stop
                moved[stop] = j
        return moved

    # ------------------------------------------------------------------ control
    def _replan(self, obs: Observation) -> None:
        """Solve the OCP from the current state; on trouble brake, shift the old plan or cruise (module docstring)."""
        a_prev = self._current_accel(obs)
        plan, ok = self._solve(obs, a_prev)
        if plan is not None:
            self._count_plan(plan)
            if self._brake_for(plan, ok, obs):
                return
        self._brake_target = None
        if ok and plan is not None:
            self.plan = plan
            if self.mode != "mpc":
                self.mode = "mpc"
            return
        self._fall_back(obs)

    def _current_accel(self, obs: Observation) -> float:
        """The acceleration [m/s^2] the new plan starts from: the current plan's at this position, else the
        measured one clipped to the comfort bounds."""
        st = self.settings.mpc
        if self.plan is not None and self.plan.s[0] <= obs.s <= self.plan.s[-1]:
            return float(np.interp(obs.s, 0.5 * (self.plan.s[1:] + self.plan.s[:-1]), self.plan.accel))
        return float(np.clip(obs.a, -st.decel_max, st.accel_max))

    def _solve(self, obs: Observation, a_prev: float) -> tuple[Plan | None, bool]:
        """(plan, converged) of this step's solve (with the periodic multistart); (None, False) on a solver crash.
        Records the solve time."""
        preview = self.preview(obs.s, obs.v)
        params = self.params()
        lam = self.time_weight(obs)
        t0 = time.perf_counter()
        plan: Plan | None
        try:
            plan = self.ocp.solve(obs.v, a_prev, preview, params, warm=self.plan, time_weight=lam)
            ok = plan.converged
            if self.settings.multistart_period > 0 and obs.t >= self._next_multistart and self.plan is not None:
                self._next_multistart = obs.t + self.settings.multistart_period
                plan, ok = self._multistart(obs, a_prev, preview, params, lam, plan, ok)
        except Exception as exc:  # any solver crash becomes a counted fallback, never an exception upstream
            self.events["solver_exception"] += 1
            self.last_error = repr(exc)
            plan, ok = None, False
        self.solve_times.append(plan.solve_time if plan is not None else time.perf_counter() - t0)
        return plan, ok

    def _count_plan(self, plan: Plan) -> None:
        """Count the plan's iterations and constraint relaxations."""
        self.iterations.append(plan.iterations)
        if plan.violations:  # counted in the run metrics (ctl_relaxed_plans, ctl_infeasible_plans)
            self.events["relaxed_plans" if plan.converged else "infeasible_plans"] += 1
            self._record_worst(plan.violations)

    def _brake_for(self, plan: Plan, ok: bool, obs: Observation) -> bool:
        """Switch to the fallback brake when the plan leaves a stop or cap out of comfort reach (module
        docstring); True when it did."""
        target = self._brake_target_of(plan, obs)
        if target is None:
            return False
        self.events["fallback_brake"] += 1
        self._brake_target = target
        self.plan = plan if ok else self.plan  # kept as the next warm start
        self.mode = "brake"
        return True

    def _fall_back(self, obs: Observation) -> None:
        """After a failed solve: keep following the old plan while it is usable, else cruise control."""
        self.events["solver_failures"] += 1
        old = self.plan
        usable = (old is not None and old.s[-1] - obs.s >= self.settings.min_plan_left and obs.s >= old.s[0]
                  and abs(old.speed_at(obs.s) - obs.v) <= self.settings.plan_tolerance)
        if usable:
            self.events["fallback_shifted_plan"] += 1
            self.mode = "shifted"
            return
        self.events["fallback_cruise"] += 1
        if self.mode != "cruise":
            self.cruise.restart(obs.v)
        self.mode = "cruise"
        self.plan = None

    def _multistart(self, obs, a_prev, preview, params, lam, plan, ok):
        """A second, cold IPOPT solve from a guess cruising multistart_step faster (late / alternating) or slower;
        the lower objective wins (counted in events ``multistart_switches``)."""
        if self.settings.schedule is not None and self._schedule_start is not None:
            sign = 1.0 if self._late > 0 else -1.0
        else:
            sign = self._multistart_sign
            self._multistart_sign = -sign
        ref = self.plan if self.plan is not None else plan
        target = float(np.mean(ref.v)) + sign * self.settings.multistart_step
        alt = self.ocp.solve(obs.v, a_prev, preview, params, time_weight=lam, target_speed=target)
        if alt.converged and (not ok or alt.objective < plan.objective - 1e-6 * abs(plan.objective)):
            self.events["multistart_switches"] += 1
            return alt, True
        return plan, ok

    def _record_worst(self, violations: tuple[ConstraintViolation, ...]) -> None:
        for v in violations:
            if v.constraint in ("stop", "speed_cap") and (self._worst is None or self._worst.constraint not in (
                    "stop", "speed_cap") or v.amount > self._worst.amount):
                self._worst = v
            elif self._worst is None:
                self._worst = v

    @staticmethod
    def _brake_target_of(plan: Plan, obs: Observation) -> ConstraintViolation | None:
        """The stop / speed-cap violation of a plan that needs the hardest braking (None: the plan meets every
        stop and cap; a margin-only relaxation is not one)."""
        hard = [v for v in plan.violations if v.constraint in ("stop", "speed_cap") and v.position > obs.s
                and v.value > v.limit and obs.v > v.limit]
        if not hard:
            return None
        return max(hard, key=lambda v: (obs.v ** 2 - v.limit ** 2) / (2.0 * (v.position - obs.s)))

    def _fallback_brake(self, obs: Observation, resistance: float, m: float) -> float | None:
        """The fallback brake's force [N] this step (module docstring), None when its target is met or passed."""
        target = self._brake_target
        if target is None:
            return None
        d = target.position - obs.s
        v_lim = 0.0 if target.constraint == "stop" else target.limit
        if d <= 0.0 or obs.v <= target.limit:
            return None
        required = (obs.v ** 2 - v_lim ** 2) / (2.0 * d)
        st = self.settings
        if required <= st.mpc.decel_max:
            self.events["comfort_brake_steps"] += 1
            self.mode = "brake"
            return resistance - m * st.mpc.decel_max
        self.events["emergency_brake_steps"] += 1
        self.mode = "emergency"
        return resistance - m * min(required, self.ctx.emergency_decel)

    def time_weight(self, obs: Observation) -> float:
        """lambda [J/s] of this solve: the settings' fixed value, or the schedule's feedback (TripSchedule)."""
        lam0 = self.settings.mpc.time_weight
        sched = self.settings.schedule
        if sched is None:
            return lam0
        previous, self._last_s = self._last_s, (obs.t, obs.s)
        if self._schedule_start is None and obs.s >= sched.start:
            if previous is not None and obs.s > previous[1]:  # interpolate the crossing of ``start``
                t1, s1 = previous
                self._schedule_start = t1 + (obs.t - t1) * (sched.start - s1) / (obs.s - s1)
            else:
                self._schedule_start = obs.t
        if self._schedule_start is None:
            return lam0
        late = sched.lateness(obs.t, obs.s, self._schedule_start)
        if sched.integral_gain > 0:  # anti-windup: the integral term alone stays within +-max_log_change
            # lateness integrated over time since the previous solve, from the crossing of ``start`` on
            since = max(self._schedule_start, previous[0]) if previous is not None else self._schedule_start
            bound = sched.max_log_change / sched.integral_gain
            self._late_integral = float(np.clip(self._late_integral + late * (obs.t - since), -bound, bound))
        lam = sched.time_weight(lam0, obs.t, obs.s, self._schedule_start, self._late_integral)
        self.time_weights.append(lam)  # the stats' time_weight_median covers the scheduled segment only
        self._late = late
        return lam

    def gear_request(self, obs: Observation) -> int | None:
        """With ``gear_command`` on an ICE: the shift rule's gear (1-based) at the measured speed, with hysteresis,
        or a lower one where its full load cannot give the force the road takes (:meth:`road_force`; back up below
        KICK_DOWN_RETURN of it), the request held while a shift is under way; None (the transmission decides)
        otherwise and below ``gear_min_speed``."""
        st = self.settings
        en = self.ctx.energy
        if not st.gear_command or en.kind != "ice" or obs.v < st.gear_min_speed:
            self._gear = self._requested = None
            return None
        if st.mpc.fuel_model in ("plant_map", "plant_map_no_cut") and en.plant_fuel is not None:
            return self._least_fuel_gear(obs)
        self._gear = en.gear_with_hysteresis(obs.v, self._gear, st.gear_band)
        shifting = obs.sample.get("clutch", 1.0) < 1.0 or (self._requested is not None and obs.gear != self._requested)
        if shifting and self._requested is not None and abs(self._requested - 1 - self._gear) <= 1:
            return self._requested  # no new decision while the clutch slips: the force then says nothing
        force = self.road_force(obs)
        if self._requested is not None and self._requested - 1 < self._gear:  # kicked down: back up with a margin
            force /= KICK_DOWN_RETURN
        self._requested = en.gear_for_force(obs.v, force, self._gear) + 1
        return self._requested

    def _least_fuel_gear(self, obs: Observation) -> int:
        """The plant map's gear of least fuel (1-based) at the measured speed and the plan's wheel force here (the
        command's off the plan; MpcControllerSettings.gear_fuel_hysteresis, gear_load_margin, gear_hold_time); the
        request is held while a shift is under way and for gear_hold_time after one, unless its engine speed leaves
        the range or its full load no longer gives the force."""
        st, pf = self.settings, self.ctx.energy.plant_fuel
        assert pf is not None
        force = self._last_force if self._last_force is not None else 0.0
        if self.mode == "mpc" and self.plan is not None and self.plan.s[0] <= obs.s <= self.plan.s[-1]:
            # the plan's force, not the command: the tracking feedback after a shift's traction gap asked for a
            # downshift to full load for 2 s (0.7 % of a 40 t climb's fuel)
            force = float(self.plan.wheel_force[self.plan.segment_at(obs.s + obs.v * st.lookahead_time)])
        current = self._requested - 1 if self._requested is not None else max(obs.gear - 1, 0)
        shifting = obs.sample.get("clutch", 1.0) < 1.0 or (self._requested is not None and obs.gear != self._requested)
        able = np.isfinite(pf.gear_fuel_power(obs.v, force)[current])
        if able and (shifting or obs.t - self._shifted_at < st.gear_hold_time):
            return current + 1
        gear = pf.least_fuel_gear(obs.v, force, current, st.gear_fuel_hysteresis, st.gear_load_margin)
        if gear != current:
            self._shifted_at = obs.t
        self._requested = gear + 1
        return self._requested

    def road_force(self, obs: Observation) -> float:
        """The wheel force [N] the drive-train must deliver on the road to follow the plan, from what it delivers:
        F = F_d + m (a_plan - a), F_d the traction sent last step limited to the engaged gear's full load (the
        engine's actual torque, which a transmission controller reads), a the measured acceleration it gave and
        a_plan the plan's acceleration here (0 off the plan). F_d - m a is the road's resistance as measured, so a
        force model's error enters only through m times (a_plan - a), not through its resistance (a heavier model
        commands more force than the road takes, and a kick-down on that command shifts where no gear is needed)."""
        en = self.ctx.energy
        sent = self._traction_sent if self._traction_sent is not None else max(self._last_force or 0.0, 0.0)
        delivered = min(sent, en.full_load_force(obs.v, obs.gear - 1)) if obs.gear >= 1 else 0.0
        a_plan = 0.0
        if self.mode == "mpc" and self.plan is not None and self.plan.s[0] <= obs.s <= self.plan.s[-1]:
            a_plan = float(self.plan.accel[self.plan.segment_at(obs.s)])
        return delivered + self.params().inertial_mass * (a_plan - obs.a)

    def act(self, obs: Observation) -> Command:
        cmd = super().act(obs)
        self._traction_sent = cmd.traction  # what the drive-train is asked for; road_force reads it next step
        return cmd

    def reference_speed(self, obs: Observation) -> float:
        """The speed [m/s] the tracking law's feedback aims at: the plan's speed at the current position."""
        return float(self.plan.speed_at(obs.s)) if self.plan is not None else obs.v

    def wheel_force(self, obs: Observation) -> float:
        stale = self.plan is not None and obs.s > self.plan.s[-2]
        braking = self.mode in ("brake", "emergency")
        if obs.t >= self._next_replan or stale or braking or (self.plan is None and self.mode == "mpc"):
            self._next_replan = obs.t + self.settings.replan_period
            self._replan(obs)
        m = self.params().inertial_mass
        st = self.settings.mpc
        res = self.resistance(obs.v, obs.s)
        brake = None
        if self.mode in ("brake", "emergency"):
            brake = self._fallback_brake(obs, res, m)
            if brake is None:  # target met or passed: back to the plan (or cruise control), re-plan next step
                self._brake_target, self._next_replan = None, -np.inf
                self.mode = "mpc" if self.plan is not None else "cruise"
                if self.plan is None:
                    self.cruise.restart(obs.v)
        if brake is not None and self.mode == "emergency":  # no comfort bounds, no comfort jerk limit
            self._last_force = brake
            return brake
        if brake is not None:
            force = brake
        elif self.mode == "cruise" or self.plan is None:
            force = self.cruise.force(obs)
        else:
            plan = self.plan
            ahead = obs.s + obs.v * self.settings.lookahead_time
            force = float(plan.wheel_force[plan.segment_at(ahead)])
            force += m * self.settings.speed_gain * (self.reference_speed(obs) - obs.v)
        # comfort: the acceleration this force gives under the controller's model stays within the bounds
        force = float(np.clip(force, res - m * st.decel_max, res + m * st.accel_max))
        # jerk limit on the command: |dF/dt| <= m j_max (the plan's accel is piecewise constant per segment)
        if self._last_force is not None:
            step = m * st.jerk_max * self.ctx.dt
            force = float(np.clip(force, self._last_force - step, self._last_force + step))
        self._last_force = force
        return force
