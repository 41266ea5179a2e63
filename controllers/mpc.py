"""Spatial-domain (distance-indexed) eco-driving optimal control problem and its two solve paths.

Grid: N segments of length ds [m] starting at the vehicle's position s0; node k at s0 + k ds (the segment lengths
are a parameter of the NLP: the full-route optimum, :mod:`.optimum`, places nodes at the stops).
States per node: E_k = v_k^2 / 2 (kinetic energy per unit mass) [m^2/s^2] and time t_k [s].
Inputs per segment (piecewise constant, in kN): traction F_t, regenerative F_r and friction-brake F_b force.

Dynamics (v_mid = (v_k + v_{k+1})/2, resistance at the segment midpoint, grade/curvature at the midpoint):
    (m + m_rot) (E_{k+1} - E_k) / ds = F_t - F_r - F_b - F_resist(v_mid, theta_k, kappa_k; p, w_k)
    t_{k+1} - t_k = ds / v_mid
Comfort: a_k = (E_{k+1} - E_k)/ds in [a_min, a_max]; jerk (a_k - a_{k-1}) v_k / ds in [-j_max, j_max]
(k = 0 uses the acceleration the previous plan commanded). Wind w_k per segment: the headwind component
(the force model's scalar headwind, or from its wind vector and the road's heading ahead) and the crosswind
component, whose drag :func:`roadload.road_load.crosswind_drag_increase` adds. Drive limits: F_t <= T_max i / r_W,
F_t v_mid <= P_max, F_r likewise for regeneration. Speed cap as a bound E_k <= v_cap,k^2/2 (limit less a margin,
curve and stop caps). The time state is substituted (t_N = sum ds / v_mid), leaving E and the three forces as
decision variables.

Feasibility: a cap the car cannot get under from its current state even braking as hard as the comfort limits
allow (the acceleration ramping from a_prev down to -decel_max at jerk_max, :meth:`OcpSolver.braking_reach`) is
raised to that reach, so the solver still returns the best plan the comfort limits permit; such a plan is
*relaxed*, never a success: ``Plan.success`` is False, ``Plan.status`` starts with ``relaxed:`` and
``Plan.violations`` names each constraint not met (stop, speed cap, speed margin) with its position, limit and the
planned value. Contradictory limits (a cap below the speed floor, a previous acceleration the jerk limit cannot
bring inside the comfort bounds) are reported the same way, and a solve that does not converge is ``infeasible:``
with the constraint that is violated most at the point where the solver stopped. The closed loop then applies its
fallback (:mod:`.mpc_controller`: a maximum-comfort brake, then an emergency brake).

Objective [kJ]: sum_k P_source(F_t, F_r, v_mid, i_k) ds / v_mid   (energy at the source, :mod:`.energy`)
    + lambda t_N  (time weight [J/s]) - m E_N  (kinetic energy left at the horizon end is worth its value)
    + small comfort/regularisation terms.

Solve paths behind :class:`OcpSolver`: ``ipopt`` (interior-point NLP, warm-started primal-dual from the
shifted previous solution) and ``osqp`` (sequential QP: the NLP linearised at the shifted previous solution,
a convexified Lagrangian Hessian, OSQP warm-started, fixed sparsity so matrices are updated in place).
The CasADi functions are built once per (settings, powertrain) and reused every step.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field, fields
from typing import Any

import casadi as ca
import numpy as np
import scipy.sparse as sp

from .energy import SourceEnergyModel
from roadload.road_load import RoadLoadParameters, crosswind_drag_increase
from roadload.schema import check_field_types

from .force_model import resistance_force
from .safety import VIOLATION_TOLERANCE


class MpcError(ValueError):
    """Invalid MPC settings or inputs (the message names the field)."""


SOLVERS = ("ipopt", "osqp")
# the ICE's fuel model in the objective (MpcSettings.fuel_model); an EV's battery model is the same under both
FUEL_MODELS = ("willans", "plant_map", "plant_map_no_cut", "plant_map_shift_rule")
TERMINAL_VALUES = ("source", "wheel", "none")
QP_E_SCALE = 30.0  # QP path: kinetic-energy variables in units of 30 m^2/s^2 (forces are in kN)


@dataclass(frozen=True)
class MpcSettings:
    """Horizon, comfort limits and weights of the spatial MPC (SI units)."""

    n_nodes: int = 100  # N segments
    ds: float = 20.0  # segment length [m] -> horizon N*ds
    # the first near_segments segments of the receding grid are near_ds long (the rest ds; at most n_nodes - 1 of
    # them, never longer than ds): a plan reaches a cap at a node at the earliest, so on a uniform grid each re-plan
    # spreads the remaining climb to a cap over the whole next segment and the vehicle approaches it exponentially
    # with ds as length scale (a launch from a stop took 60 m to the turn's cap on 20 m, against 10 m for the
    # optimum's 5 m grid); 0: uniform (the car's drives use 4: DriveSettings)
    near_segments: int = 0
    near_ds: float = 5.0  # [m]
    accel_max: float = 1.5  # [m/s^2]
    decel_max: float = 2.0  # comfort deceleration [m/s^2] (a_min = -decel_max)
    jerk_max: float = 2.0  # [m/s^3]
    lateral_accel_max: float = 2.0  # speed cap in curves v <= sqrt(a_y,max / |kappa|) [m/s^2]
    speed_floor: float = 1.0  # lowest planned speed [m/s] (the spatial form needs v > 0)
    stop_speed: float = 1.0  # speed cap at a stop node [m/s]; the closed loop stops the car from there
    speed_margin: float = 0.3  # planned speed stays this far below the limit [m/s]
    time_weight: float = 3000.0  # lambda [J/s]: energy worth one second of trip time
    # value of the kinetic energy left at the horizon end: "source" = m E_N / eta_i (what it costs at the source,
    # Willans line; = m E_N for an EV), "wheel" = m E_N (the earlier value: undervalues it by eta_i on an ICE)
    terminal_value: str = "source"  # "none": worth nothing (an episode's cost that ends at the road end)
    # the horizon ends at the road end: nodes beyond it collapse onto it (1 mm segments), so the terminal value
    # applies there (a trip that ends at the road end); False: the road continues with its last values
    horizon_to_route_end: bool = False
    accel_weight: float = 0.05  # comfort term [kJ per (m/s^2)^2 per segment, times mass/1000]
    solver: str = "ipopt"
    # IPOPT iteration cap of a warm-started solve / SQP iterations cap per call (osqp path uses sqp_iterations):
    # the truck's plant-map NLP needs more than 100 iterations on 10-45 % of its warm solves on long grades (a
    # previous plan whose active set no longer fits); at 100 they ended unconverged and the controller followed its
    # shifted old plan (40 t long-grade seed 8: 3.2 % more fuel at the same time); a capped warm solve re-solved
    # cold gave worse plans at the same CPU (docs/results/controllers.md, the warm solves at their cap)
    max_iterations: int = 500
    # IPOPT iteration cap of a cold solve (no previous plan: the first step, after a fallback to cruise control, a
    # multistart): the truck's first plan at 23 m/s on a 2 km horizon takes 170 iterations, and at the warm solves'
    # cap of 100 the controller fell back to its cruise control, which braked the 40 t truck from 23.3 to 21.3 m/s
    # at the hand-over and drove it back up (2.9 MJ, 12 % of a real 8 km window's fuel)
    cold_max_iterations: int = 500
    warm_tol: float = 1e-4  # IPOPT tol of warm-started solves (cold solves: 1e-6); scripts/bench_mpc.py shows the
    # closed-loop energy equal to 1e-6 within 0.1 %
    qp_tolerance: float = 1e-3  # OSQP eps_abs = eps_rel
    sqp_iterations: int = 1  # QP path: linearise-solve rounds per control step (1 = real-time iteration)
    # ICE fuel power in the objective [W]: "willans" = the fitted Willans line at the shift rule's smoothed ratio,
    # P = (F_t v + P_loss(omega, T)) / eta_i, engine friction charged while braking; "plant_map" = the plant's own
    # quasi-static map at the gear of least fuel per move, P = phi(v_mid, F_t - F_r - F_b) (0 in overrun: fuel cut,
    # the brakes free), phi a cubic B-spline through the smoothed least-over-gears table
    # (energy.PlantFuelModel.smooth_table), with the traction limit F_t <= F_max(v_mid) of the best gear's full load
    # in place of the power limit; the controller then requests the map's least-fuel gear
    # (MpcControllerSettings.gear_command). Variants that separate what each part buys: "plant_map_no_cut" (a
    # braking force charged the fuel of F = 0, the engine's friction fuelled) and "plant_map_shift_rule" (the map
    # in the shift rule's gear, kick-down where it cannot, and the shift rule's gear requested: no gear choice).
    # An EV ignores it.
    fuel_model: str = "willans"

    def __post_init__(self) -> None:
        check_field_types(self, MpcError)
        for f in fields(self):
            value = getattr(self, f.name)
            if isinstance(value, float) and not math.isfinite(value):
                raise MpcError(f"MpcSettings.{f.name}: must be a finite number, got {value}")
        if self.n_nodes < 2:
            raise MpcError(f"n_nodes must be >= 2, got {self.n_nodes}")
        if self.speed_margin < 0:
            raise MpcError(f"MpcSettings.speed_margin: must be >= 0 [m/s] (a negative margin plans above the "
                           f"limit), got {self.speed_margin}")
        if self.accel_weight < 0:
            raise MpcError(f"MpcSettings.accel_weight: must be >= 0, got {self.accel_weight}")
        if not self.qp_tolerance > 0 or min(self.max_iterations, self.cold_max_iterations, self.sqp_iterations) < 1:
            raise MpcError(f"MpcSettings: qp_tolerance must be > 0 and max_iterations, cold_max_iterations, "
                           f"sqp_iterations >= 1, got {self.qp_tolerance}, {self.max_iterations}, "
                           f"{self.cold_max_iterations}, {self.sqp_iterations}")
        if self.ds <= 0:
            raise MpcError(f"ds must be positive, got {self.ds}")
        if not (self.near_segments >= 0 and self.near_ds > 0):
            raise MpcError(f"MpcSettings.near_segments / near_ds: need near_segments >= 0 and near_ds > 0 [m], got "
                           f"{self.near_segments}, {self.near_ds:g} m")
        for name in ("accel_max", "decel_max", "jerk_max", "lateral_accel_max", "speed_floor", "stop_speed"):
            if not getattr(self, name) > 0:
                raise MpcError(f"{name} must be positive, got {getattr(self, name)}")
        if self.time_weight < 0:
            raise MpcError(f"time_weight must be >= 0, got {self.time_weight}")
        if not 0 < self.warm_tol < 1:
            raise MpcError(f"warm_tol must be in (0, 1), got {self.warm_tol}")
        self._check_choices()
        if self.stop_speed < self.speed_floor:
            raise MpcError("stop_speed must be >= speed_floor")

    def _check_choices(self) -> None:
        """The named choices (terminal value, fuel model, solver) are known ones."""
        for name, choices in (("terminal_value", TERMINAL_VALUES), ("fuel_model", FUEL_MODELS)):
            if getattr(self, name) not in choices:
                raise MpcError(f"MpcSettings.{name}: choose one of {choices}, got {getattr(self, name)!r}")
        if self.solver not in SOLVERS:
            raise MpcError(f"unknown solver {self.solver!r}; choose one of {SOLVERS}")

    @property
    def horizon(self) -> float:
        """Length [m] of the receding grid: near_segments x near_ds, then ds."""
        return float(self.grid_lengths().sum())

    def grid_lengths(self) -> np.ndarray:
        """Segment lengths [m] (n_nodes) of the receding grid before any node moves onto a stop line."""
        lengths = np.full(self.n_nodes, self.ds)
        lengths[:min(self.near_segments, self.n_nodes - 1)] = min(self.near_ds, self.ds)
        return lengths


@dataclass
class Preview:
    """The road ahead on the MPC grid: node positions s (N+1) [m], per-segment grade [rad], curvature [1/m]
    and shaft/wheel ratio (N), and the per-node speed cap (N+1) [m/s] (limit, curve and stop caps combined)."""

    s: np.ndarray
    grade: np.ndarray
    curvature: np.ndarray
    speed_cap: np.ndarray
    ratio: np.ndarray
    segment0_cap: np.ndarray | None = None  # cap [m/s] at s0 + x ds, x = SEGMENT0_FRACTIONS (inside segment 0)
    stops: np.ndarray | None = None  # positions [m] of the stop lines whose caps the preview holds (reporting)
    # wind per segment (N) from a force model that knows the wind vector and the road's heading ahead: headwind
    # component [m/s] (None: the force model's scalar headwind) and crosswind component [m/s] (None: 0), with the
    # yaw drag factor k [1] of c_x(psi_a) (road_load.crosswind_drag_increase)
    headwind: np.ndarray | None = None
    crosswind: np.ndarray | None = None
    yaw_drag_factor: float = 0.0
    ds: np.ndarray | None = None  # segment lengths [m] (N) = diff(s); None: the settings' uniform ds


SEGMENT0_FRACTIONS = np.linspace(0.0, 1.0, 11)[1:]


#: what each constraint name of :class:`ConstraintViolation` means
CONSTRAINTS = {
    "stop": "stop line: the speed at the stop may not exceed stop_speed",
    "stop_node": "the grid node before a stop line (capped at stop_speed), while the line itself is within reach",
    "speed_cap": "speed cap: posted limit or curve cap sqrt(a_y,max / |kappa|)",
    "speed_margin": "speed margin: the plan keeps speed_margin below each cap",
    "speed_floor": "speed floor: the plan never goes slower than speed_floor",
    "acceleration": "comfort acceleration bounds [-decel_max, accel_max]",
    "jerk": "comfort jerk bound jerk_max",
    "dynamics": "force balance: traction - regen - brake = inertial force + resistance",
    "traction_force": "drive force limit (torque or power at the wheels)",
    "brake_force": "friction-brake plus regenerative force limit",
    "traction_power": "drive power limit",
    "regen_power": "regenerative power limit",
    "solver": "the solver stopped without converging",
}


@dataclass(frozen=True)
class ConstraintViolation:
    """A constraint of the MPC problem that a plan does not meet, or that contradicts another one.

    ``constraint``: a key of :data:`CONSTRAINTS`; ``position`` [m] where (node or segment start); ``limit`` the
    constraint's bound and ``value`` the plan's (for a relaxed cap: the planned speed; for an unreachable stop or
    cap: the lowest speed reachable within the comfort limits), both in ``unit``; ``amount`` = how far beyond the
    bound; ``required_decel`` [m/s^2]: the constant deceleration from the current state that would meet it
    (NaN where not a speed bound)."""

    constraint: str
    position: float
    limit: float
    value: float
    unit: str
    required_decel: float = float("nan")
    detail: str = ""

    @property
    def amount(self) -> float:
        """How far the value lies beyond the bound [unit] (>= 0)."""
        return abs(self.value - self.limit)

    def describe(self) -> str:
        text = (f"{self.constraint} at {self.position:.0f} m: {self.value:.3g} {self.unit} against a limit of "
                f"{self.limit:.3g} {self.unit} (off by {self.amount:.3g} {self.unit})")
        if math.isfinite(self.required_decel):
            text += f", needs {self.required_decel:.2f} m/s^2 of deceleration"
        return text + (f"; {self.detail}" if self.detail else "")


@dataclass
class Plan:
    """A solved (or fallback) speed/force trajectory over distance.

    ``success`` is True only when the solver converged *and* the plan meets every constraint of the preview;
    ``converged`` is the solver's own verdict (``solver_status`` its message); ``violations`` lists what a relaxed
    or infeasible plan does not meet (module docstring, Feasibility)."""

    s: np.ndarray  # node positions [m] (N+1)
    v: np.ndarray  # planned speed [m/s] (N+1)
    t: np.ndarray  # planned time from the plan start [s] (N+1)
    traction: np.ndarray  # [N] per segment (N)
    regen: np.ndarray  # [N]
    brake: np.ndarray  # [N]
    success: bool
    status: str
    solve_time: float  # wall-clock [s]
    iterations: int
    objective: float = float("nan")
    cpu_time: float = float("nan")  # process CPU time of the solve [s] (robust to a loaded machine)
    x: np.ndarray | None = field(default=None, repr=False)  # raw primal (for warm start)
    lam_x: np.ndarray | None = field(default=None, repr=False)
    lam_g: np.ndarray | None = field(default=None, repr=False)
    relaxed_nodes: int = 0  # nodes ahead whose speed cap was raised to the comfort-braking reach (0 = none)
    converged: bool = True  # the solver's verdict, whatever the constraints
    solver_status: str = ""  # the solver's message (IPOPT return status / OSQP status)
    violations: tuple[ConstraintViolation, ...] = ()

    @property
    def relaxed(self) -> bool:
        """True when the plan could not honour every speed cap / stop of the preview (caps were relaxed)."""
        return self.relaxed_nodes > 0

    @property
    def feasibility(self) -> str:
        """'feasible', 'relaxed' (converged on relaxed constraints) or 'infeasible' (no converged plan)."""
        if not self.converged:
            return "infeasible"
        return "relaxed" if self.violations else "feasible"

    @property
    def accel(self) -> np.ndarray:
        return np.diff(0.5 * self.v ** 2) / np.diff(self.s)

    @property
    def wheel_force(self) -> np.ndarray:
        return self.traction - self.regen - self.brake

    def speed_at(self, s) -> np.ndarray:
        """Planned speed [m/s] at position(s) s [m]. The NLP holds the force, hence the acceleration, constant over
        a segment, so E = v^2 / 2 is linear in s between the nodes: v(s) = sqrt(v_k^2 + 2 a_k (s - s_k)), not the
        chord of v (which lies below it where the plan brakes into a stop and drags the tracked speed down early)."""
        energy = np.interp(s, self.s, 0.5 * np.asarray(self.v, float) ** 2)
        return np.sqrt(2.0 * np.maximum(energy, 0.0))

    def segment_at(self, s: float) -> int:
        return int(np.clip(np.searchsorted(self.s, s, side="right") - 1, 0, len(self.traction) - 1))


class OcpSolver:
    """The NLP of the module docstring built once; ``solve`` fills in the preview and parameters."""

    def __init__(self, settings: MpcSettings, energy: SourceEnergyModel) -> None:
        self.settings = settings
        self.energy = energy
        n = settings.n_nodes
        self.n = n
        self.plant_map = (self._plant_map() if settings.fuel_model.startswith("plant_map") and energy.kind == "ice"
                          else None)
        self._build()
        self._osqp: Any = None  # osqp.OSQP workspace (osqp ships no type information)
        self._qp_x = None

    # ------------------------------------------------------------------ formulation
    def _plant_map(self) -> tuple[ca.Function, ca.Function]:
        """(phi(v [m/s], F [kN]) [W], F_max(v [m/s]) [N]): cubic B-splines through the smoothed least-fuel table
        and the best gear's full load of the energy model's plant map (MpcSettings.fuel_model)."""
        pf = self.energy.plant_fuel
        if pf is None:
            raise MpcError(f"MpcSettings.fuel_model 'plant_map': the energy model {self.energy.name!r} carries no "
                           f"plant fuel map (SourceEnergyModel.plant_fuel; controllers.drive attaches it)")
        model = self.settings.fuel_model
        speeds = np.asarray(pf.map.speeds, float)
        speeds, forces, table = pf.smooth_table(
            fuel_cut=model != "plant_map_no_cut",
            rule_gear=self.energy.gear_for_speed(speeds) if model == "plant_map_shift_rule" else None)
        env_speeds, envelope = pf.full_load_envelope()
        self._map_speeds = (float(speeds[0]), float(speeds[-1]))
        self._ft_max = float(envelope.max()) / 1000.0  # [kN]
        fuel = ca.interpolant("plant_fuel", "bspline", [speeds, forces / 1000.0], table.ravel(order="F"))
        full = ca.interpolant("full_load", "bspline", [env_speeds], envelope)
        return fuel, full

    def _formulate(self) -> dict[str, Any]:
        """The NLP's symbols: decision vector x, parameter vector p, constraint vector g and the objective's
        parts (source energy [kJ], time t_N [s], kinetic energy left at the end m E_N [kJ], comfort and
        regularisation terms [kJ]); the MPC (:meth:`_build`) and the full-route optimum (:mod:`.optimum`)
        compose their objectives from them."""
        st, en, n = self.settings, self.energy, self.n
        E = ca.SX.sym("E", n + 1)
        ft = ca.SX.sym("Ft", n)
        fr = ca.SX.sym("Fr", n)
        fb = ca.SX.sym("Fb", n)
        x = ca.vertcat(E, ft, fr, fb)
        a_prev = ca.SX.sym("a_prev")
        grade = ca.SX.sym("grade", n)
        curv = ca.SX.sym("curv", n)
        ratio = ca.SX.sym("ratio", n)
        fp = ca.SX.sym("fp", len(RoadLoadParameters.FIELDS))
        lam = ca.SX.sym("lam")
        headwind = ca.SX.sym("headwind", n)
        crosswind = ca.SX.sym("crosswind", n)
        yaw_drag = ca.SX.sym("yaw_drag")
        ds = ca.SX.sym("ds", n)  # segment lengths [m] (the MPC: uniform; the full-route optimum: nodes at stops)
        p = ca.vertcat(a_prev, grade, curv, ratio, fp, lam, headwind, crosswind, yaw_drag, ds)
        m = fp[0]

        v = ca.sqrt(2.0 * E)
        vm = 0.5 * (v[:-1] + v[1:])
        dt = ds / vm
        # the road load with the headwind of each segment, plus what its crosswind adds to the drag
        fp_wind = [fp[i] for i in range(6)] + [headwind, fp[7]]
        fres = (resistance_force(vm, grade, curv, fp_wind)
                + crosswind_drag_increase(fp[3], vm + headwind, crosswind, yaw_drag, xp=ca))
        acc = (E[1:] - E[:-1]) / ds
        m_in = m + fp[7]  # inertial mass m_V + m_rot
        dyn = (m_in * acc + fres) / 1000.0 - (ft - fr - fb)
        t_end = ca.sum1(dt)  # time state t_N, substituted: t_{k+1} = t_k + ds / v_mid
        jerk = ca.vertcat((acc[0] - a_prev) * v[0] / ds[0],
                          (acc[1:] - acc[:-1]) * v[1:-1] / (0.5 * (ds[:-1] + ds[1:])))
        regen_power = fr * vm
        if self.plant_map is not None:  # the plant's fuel at the gear of least fuel, the best gear's full load
            fuel, full_load = self.plant_map
            v_in = ca.fmin(ca.fmax(vm, self._map_speeds[0]), self._map_speeds[1])
            power = (ft - full_load(v_in.T).T / 1000.0) * vm  # kW above the best gear's full load (<= 0)
            psrc = fuel(ca.vertcat(v_in.T, (ft - fr - fb).T)).T
        else:
            power = ft * vm - en.traction_power_limit(vm) / 1000.0  # kW above the drive's limit at this speed (<= 0)
            # ICE: gear from the speed-based shift rule, smooth in the planned speed; EV: the fixed ratio
            ratio_obj = en.smooth_ratio(vm) if en.kind == "ice" else ratio
            psrc = en.source_power(1000.0 * ft, 1000.0 * fr, vm, ratio_obj)
        g = ca.vertcat(dyn, acc, jerk, power, regen_power)

        energy = ca.sum1(psrc * dt) / 1000.0  # kJ
        return {"x": x, "p": p, "g": g, "energy": energy, "t_end": t_end, "lam": lam,
                "terminal_energy": m_in * E[n] / 1000.0,
                "comfort": st.accel_weight * m / 1000.0 * ca.sumsqr(acc),
                "regularisation": 1e-3 / 1000.0 * ca.dot(ds, ft + fr + fb)}

    def _build(self) -> None:
        st, en, n = self.settings, self.energy, self.n
        f = self._formulate()
        x: ca.SX = f["x"]
        p: ca.SX = f["p"]
        g: ca.SX = f["g"]
        energy: ca.SX = f["energy"]
        ke_value = {"source": 1.0 / en.indicated_efficiency, "wheel": 1.0, "none": 0.0}[st.terminal_value]
        obj = (energy + f["lam"] * f["t_end"] / 1000.0 - ke_value * f["terminal_energy"] + f["comfort"]
               + f["regularisation"])
        self._nx, self._ng, self._np = x.numel(), g.numel(), p.numel()
        self._blocks_x = [n + 1, n, n, n]
        self._blocks_g = [n, n, n, n, n]
        self._nlp = {"x": x, "p": p, "f": obj, "g": g}
        self._energy_fun = ca.Function("energy", [x, p], [energy * 1000.0])
        self._g_fun = ca.Function("constraints", [x, p], [g])  # diagnosis of a solve that did not converge
        opts: dict[str, Any] = {"expand": True, "print_time": False, "error_on_fail": False,
                "ipopt": {"print_level": 0, "sb": "yes", "max_iter": st.cold_max_iterations, "tol": 1e-6,
                          "acceptable_tol": 1e-4, "acceptable_iter": 5, "mu_strategy": "adaptive",
                          "mumps_permuting_scaling": 0, "mumps_scaling": 0}}
        warm_ipopt = {**opts["ipopt"], "max_iter": st.max_iterations, "tol": st.warm_tol,
                      "warm_start_init_point": "yes", "mu_init": 1e-5,
                      "warm_start_bound_push": 1e-7, "warm_start_mult_bound_push": 1e-7,
                      "warm_start_slack_bound_push": 1e-7, "mu_strategy": "monotone"}
        warm: dict[str, Any] = {**opts, "ipopt": warm_ipopt}
        if st.solver == "ipopt":
            self._cold = ca.nlpsol("mpc_cold", "ipopt", self._nlp, opts)
            self._warm = ca.nlpsol("mpc_warm", "ipopt", self._nlp, warm)
        else:
            lam_g = ca.SX.sym("lam_g", self._ng)
            jac = ca.jacobian(g, x)
            hess = ca.hessian(obj + ca.dot(lam_g, g), x)[0]
            hess_u = ca.triu(hess)
            self._qp_fun = ca.Function("qp_data", [x, p, lam_g],
                                       [ca.gradient(obj, x), g, jac, hess_u]).expand()
            jsp, hsp = jac.sparsity(), hess_u.sparsity()
            self._jac_sp = (np.array(jsp.colind()), np.array(jsp.row()))
            h_col = np.repeat(np.arange(self._nx), np.diff(np.array(hsp.colind())))
            h_row = np.array(hsp.row())
            self._h_rowcol = (h_row, h_col)
            # P pattern: triu(H) plus the full diagonal
            keys = set(zip(h_row.tolist(), h_col.tolist())) | {(i, i) for i in range(self._nx)}
            pr, pc = np.array(sorted(keys, key=lambda rc: (rc[1], rc[0]))).T
            self._p_rows, self._p_cols = pr, pc
            index = {(r, c): i for i, (r, c) in enumerate(zip(pr.tolist(), pc.tolist()))}
            self._p_from_h = np.array([index[(r, c)] for r, c in zip(h_row.tolist(), h_col.tolist())], dtype=int)
            self._p_diag = np.array([index[(i, i)] for i in range(self._nx)], dtype=int)
            self._p_indptr = np.concatenate([[0], np.cumsum(np.bincount(pc, minlength=self._nx))])
            # A = [J; I] pattern in CSC (column by column: J's rows then the identity row)
            jcol, jrow = self._jac_sp
            cols_a, rows_a = [], []
            for c in range(self._nx):
                r = jrow[jcol[c]:jcol[c + 1]].tolist()
                rows_a.extend(r + [self._ng + c])
                cols_a.extend([c] * (len(r) + 1))
            self._a_rows = np.array(rows_a)
            self._a_indptr = np.concatenate([[0], np.cumsum(np.bincount(cols_a, minlength=self._nx))])
            # position of each J nonzero (casadi order) and of each identity entry inside A's data
            a_index = {}
            for i, (r, c) in enumerate(zip(rows_a, cols_a)):
                a_index[(r, c)] = i
            jcols = np.repeat(np.arange(self._nx), np.diff(jcol))
            self._a_from_j = np.array([a_index[(r, c)] for r, c in zip(jrow.tolist(), jcols.tolist())], dtype=int)
            self._a_eye = np.array([a_index[(self._ng + c, c)] for c in range(self._nx)], dtype=int)
            self._a_cols = np.array(cols_a, dtype=int)
            self._qp_scale = np.ones(self._nx)
            self._qp_scale[:n + 1] = QP_E_SCALE

    # ------------------------------------------------------------------ problem data
    def braking_reach(self, v0: float, preview: Preview, a_prev: float = 0.0) -> np.ndarray:
        """Lowest speed [m/s] at each node the plan can reach from v0 within the comfort limits: the acceleration
        ramps from a_prev down to -decel_max as fast as the NLP's jerk constraint allows,
        a_k = max(a_{k-1} - j_max ds / v_k, -decel_max), E_{k+1} = E_k + a_k ds (floored at the speed floor).
        Braking harder at every segment lowers every later speed, so this greedy sequence is the lowest."""
        return self._braking(v0, len(preview.s), a_prev, np.diff(np.asarray(preview.s, float)))[0]

    def _braking(self, v0: float, n_nodes: int, a_prev: float,
                 lengths: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """(speed [m/s] at each node, acceleration [m/s^2] of each segment) of :meth:`braking_reach`; ``lengths``:
        the segment lengths [m] (None: the settings' uniform ds)."""
        st = self.settings
        ds = np.full(max(n_nodes - 1, 0), st.ds) if lengths is None else np.asarray(lengths, float)
        e_floor = 0.5 * st.speed_floor ** 2
        e = 0.5 * max(v0, st.speed_floor) ** 2
        a = min(max(a_prev, -st.decel_max), st.accel_max)
        speed, accel = np.empty(n_nodes), np.empty(max(n_nodes - 1, 0))
        speed[0] = math.sqrt(2.0 * e)
        for k in range(1, n_nodes):
            a = max(a - st.jerk_max * ds[k - 1] / math.sqrt(2.0 * e), -st.decel_max)
            accel[k - 1] = a
            e = max(e + a * ds[k - 1], e_floor)
            speed[k] = math.sqrt(2.0 * e)
        return speed, accel

    def planning_cap(self, preview: Preview) -> np.ndarray:
        """The cap [m/s] the plan is asked to meet at each node: the preview cap less the margin, floored at the
        speed floor (the spatial form needs v > 0)."""
        st = self.settings
        return np.maximum(np.asarray(preview.speed_cap, float) - st.speed_margin, st.speed_floor)

    def reachable_cap(self, v0: float, preview: Preview, a_prev: float = 0.0) -> np.ndarray:
        """Per-node speed cap [m/s] used as a bound: :meth:`planning_cap`, raised (to the reach + 0.1 m/s) only
        where the car cannot get below it from v0 even braking as hard as the comfort limits allow
        (:meth:`braking_reach`), so a problem started above a cap stays solvable; the plan is then reported
        relaxed (module docstring, Feasibility) and the closed loop brakes (:mod:`.mpc_controller`)."""
        cap = self.planning_cap(preview)
        reach = self.braking_reach(v0, preview, a_prev)
        return np.where(reach > cap, reach + 0.1, cap)

    def _bounds(self, v0: float, preview: Preview, params: RoadLoadParameters, a_prev: float = 0.0):
        st, en, n = self.settings, self.energy, self.n
        inf = np.inf
        e_floor = 0.5 * st.speed_floor ** 2
        e0 = 0.5 * max(v0, st.speed_floor) ** 2
        lbx = np.concatenate([np.full(n + 1, e_floor), np.zeros(3 * n)])
        traction = (np.full(n, self._ft_max) if self.plant_map is not None
                    else np.asarray(en.max_traction_force(None, preview.ratio), float) / 1000.0)
        ubx = np.concatenate([0.5 * self.reachable_cap(v0, preview, a_prev) ** 2, traction,
                              np.full(n, 0.0) + np.asarray(en.max_regen_force(preview.ratio), float) / 1000.0,
                              np.full(n, en.brake_force_limit(params.mass) / 1000.0)])
        lbx[0] = ubx[0] = e0
        if preview.segment0_cap is not None:
            # inside segment 0 E is linear in s: E0 (1 - x) + E1 x <= c(x)^2/2 for every sampled x where the cap
            # is below the current speed -> an upper bound on E1 (kept reachable within the comfort limits)
            c = 0.5 * np.maximum(np.asarray(preview.segment0_cap, float) - st.speed_margin, st.speed_floor) ** 2
            x = SEGMENT0_FRACTIONS
            low = c < e0
            if low.any():
                bound = float(np.min(e0 + (c[low] - e0) / x[low]))
                e1_reach = 0.5 * float(self.braking_reach(v0, preview, a_prev)[1]) ** 2
                ubx[1] = min(ubx[1], max(bound, e1_reach + 1e-3, e_floor + 1e-6))
        lbg = np.concatenate([np.zeros(n), np.full(n, -st.decel_max), np.full(n, -st.jerk_max),
                              np.full(2 * n, -inf)])
        ubg = np.concatenate([np.zeros(n), np.full(n, st.accel_max), np.full(n, st.jerk_max),
                              np.zeros(n),
                              np.full(n, (en.max_regen_power if en.regenerates else 0.0) / 1000.0)])
        return lbx, ubx, lbg, ubg

    def _params(self, a_prev: float, preview: Preview, params: RoadLoadParameters,
                time_weight: float | None = None) -> np.ndarray:
        lam = self.settings.time_weight if time_weight is None else time_weight
        if not (math.isfinite(lam) and lam >= 0):
            raise MpcError(f"time_weight: must be a finite number >= 0 [J/s], got {lam}")
        n = self.n
        headwind = np.full(n, params.headwind) if preview.headwind is None else np.asarray(preview.headwind, float)
        crosswind = np.zeros(n) if preview.crosswind is None else np.asarray(preview.crosswind, float)
        return np.concatenate([[a_prev], preview.grade, preview.curvature, preview.ratio, params.as_vector(),
                               [lam], headwind, crosswind, [float(preview.yaw_drag_factor)],
                               self.segment_lengths(preview)])

    def segment_lengths(self, preview: Preview) -> np.ndarray:
        """Segment lengths [m] (N): the preview's own (``Preview.ds``), else the settings' uniform ds."""
        return np.full(self.n, self.settings.ds) if preview.ds is None else np.asarray(preview.ds, float)

    def _check(self, v0: float, a_prev: float, preview: Preview) -> None:
        n = self.n
        if not (np.isfinite(v0) and np.isfinite(a_prev)):
            raise MpcError(f"initial speed/acceleration not finite (v0={v0}, a_prev={a_prev})")
        shapes = {"s": (preview.s, n + 1), "grade": (preview.grade, n), "curvature": (preview.curvature, n),
                  "speed_cap": (preview.speed_cap, n + 1), "ratio": (preview.ratio, n)}
        shapes.update({k: (getattr(preview, k), n) for k in ("headwind", "crosswind", "ds")
                       if getattr(preview, k) is not None})
        if preview.ds is not None and not np.all(np.asarray(preview.ds, float) > 0):
            raise MpcError("preview.ds: segment lengths must be > 0 m")
        if not (math.isfinite(preview.yaw_drag_factor) and preview.yaw_drag_factor >= 0):
            raise MpcError(f"preview.yaw_drag_factor: a finite number >= 0 [1], got {preview.yaw_drag_factor}")
        for name, (arr, size) in shapes.items():
            arr = np.asarray(arr, float)
            if arr.shape != (size,):
                raise MpcError(f"preview.{name}: expected shape ({size},), got {arr.shape}")
            if not np.all(np.isfinite(arr)):
                raise MpcError(f"preview.{name} contains NaN/inf")

    def initial_guess(self, v0: float, preview: Preview, params: RoadLoadParameters, a_prev: float = 0.0,
                      target_speed: float | None = None) -> np.ndarray:
        """A feasible-ish cold start: speed ramps (comfortably) from v0 towards the cap (or towards
        ``target_speed`` [m/s] where that is lower), quasi-static forces."""
        st, n, ds = self.settings, self.n, self.segment_lengths(preview)
        cap = self.reachable_cap(v0, preview, a_prev)
        if target_speed is not None:
            cap = np.maximum(np.minimum(cap, target_speed), st.speed_floor)
        v = np.empty(n + 1)
        v[0] = max(v0, st.speed_floor)
        for k in range(n):
            v[k + 1] = min(np.sqrt(v[k] ** 2 + 2 * 0.5 * st.accel_max * ds[k]), cap[k + 1])
        for k in range(n - 1, -1, -1):  # backward pass: comfortable deceleration before caps
            v[k] = min(v[k], np.sqrt(v[k + 1] ** 2 + 2 * 0.5 * st.decel_max * ds[k])) if k > 0 else v[k]
        E = 0.5 * v ** 2
        vm = 0.5 * (v[1:] + v[:-1])
        f = params.inertial_mass * np.diff(E) / ds + resistance_force(vm, preview.grade, preview.curvature, params)
        ft = np.clip(f, 0, None) / 1000.0
        fr = np.clip(-f, 0, np.asarray(self.energy.max_regen_force(preview.ratio), float)) / 1000.0
        fb = np.clip(-f, 0, None) / 1000.0 - fr
        return np.concatenate([E, ft, fr, fb])

    def shift(self, plan: Plan, s0: float, s: np.ndarray | None = None
              ) -> tuple[np.ndarray, np.ndarray | None, np.ndarray | None]:
        """Previous primal/dual solution moved onto the grid s [m] (N+1 nodes; None: uniform ds from s0), linear
        interpolation by position: node values (E) at the nodes, segment values (forces, constraint multipliers)
        at the segment midpoints, the last value held beyond the old plan's end."""
        new = self.settings.ds * np.arange(self.n + 1) + s0 if s is None else np.asarray(s, float)
        old = np.asarray(plan.s, float)
        at = {self.n + 1: (new, old), self.n: (0.5 * (new[1:] + new[:-1]), 0.5 * (old[1:] + old[:-1]))}

        def move(vec, blocks):
            out, i = [], 0
            for size in blocks:
                out.append(np.interp(*at[size], vec[i:i + size]))
                i += size
            return np.concatenate(out)

        x = move(plan.x, self._blocks_x)
        lam_x = None if plan.lam_x is None else move(plan.lam_x, self._blocks_x)
        lam_g = None if plan.lam_g is None else move(plan.lam_g, self._blocks_g)
        return x, lam_x, lam_g

    def _plan_from_x(self, x, preview, success, status, solve_time, iters, obj, lam_x=None, lam_g=None) -> Plan:
        n = self.n
        v = np.sqrt(2.0 * np.maximum(x[:n + 1], 0.0))
        vm = np.maximum(0.5 * (v[1:] + v[:-1]), 1e-6)
        return Plan(s=np.asarray(preview.s, float).copy(), v=v,
                    t=np.concatenate([[0.0], np.cumsum(self.segment_lengths(preview) / vm)]),
                    traction=1000.0 * x[n + 1:2 * n + 1],
                    regen=1000.0 * x[2 * n + 1:3 * n + 1], brake=1000.0 * x[3 * n + 1:4 * n + 1],
                    success=success, status=status, solve_time=solve_time, iterations=iters, objective=obj,
                    x=x.copy(), lam_x=None if lam_x is None else lam_x.copy(),
                    lam_g=None if lam_g is None else lam_g.copy())

    def source_energy(self, plan: Plan, a_prev: float, preview: Preview, params: RoadLoadParameters) -> float:
        """Source energy [J] of a plan under the model (for reporting and tests)."""
        if plan.x is None:
            raise MpcError("source_energy: the plan has no primal vector x (a fallback plan); solve one first")
        return float(self._energy_fun(plan.x, self._params(a_prev, preview, params)))

    # ------------------------------------------------------------------ solve
    def solve(self, v0: float, a_prev: float, preview: Preview, params: RoadLoadParameters,
              warm: Plan | None = None, time_weight: float | None = None,
              target_speed: float | None = None) -> Plan:
        """Solve from speed v0 [m/s] with the previous commanded acceleration a_prev [m/s^2]; ``time_weight``
        [J/s] overrides the settings' lambda for this solve (a parameter of the built NLP, no rebuild);
        ``target_speed`` [m/s]: a cold start (IPOPT) whose guess cruises at that speed (multi-start, see
        MpcControllerSettings.multistart_period)."""
        self._check(v0, a_prev, preview)
        if self.settings.solver == "ipopt":
            plan = self._solve_ipopt(v0, a_prev, preview, params, warm, time_weight, target_speed)
        else:
            plan = self._solve_qp(v0, a_prev, preview, params, warm, time_weight)
        plan.relaxed_nodes = self.relaxed_nodes(v0, preview, a_prev)
        plan.converged, plan.solver_status = plan.success, plan.status
        found = self.contradictions(v0, a_prev, preview) + self.relaxations(v0, a_prev, preview, plan)
        if not plan.converged:
            found += self.diagnose(plan, a_prev, preview, params, time_weight)
        plan.violations = tuple(found)
        plan.success = plan.converged and not found
        if found:
            plan.status = (f"{plan.feasibility}: " + "; ".join(v.describe() for v in found[:3])
                           + (f" (+{len(found) - 3} more)" if len(found) > 3 else "")
                           + f" [solver: {plan.solver_status}]")
        return plan

    def relaxed_nodes(self, v0: float, preview: Preview, a_prev: float = 0.0) -> int:
        """Nodes ahead (node 0 is the current state) whose cap :meth:`reachable_cap` had to raise: the car cannot
        brake below them from v0 within the comfort limits."""
        raised = self.reachable_cap(v0, preview, a_prev) > self.planning_cap(preview) + 1e-9
        return int(np.sum(raised[1:]))

    def relaxations(self, v0: float, a_prev: float, preview: Preview, plan: Plan | None = None
                    ) -> list[ConstraintViolation]:
        """One violation per run of consecutive relaxed nodes (a stop, a stretch of a lower cap): the node where
        the plan (or, without a converged plan, the comfort-braking reach) exceeds the cap most. A stop line out of
        comfortable reach, or a cap exceeded by more than VIOLATION_TOLERANCE, is a ``stop`` / ``speed_cap``
        violation; one met only by eating into the margin is ``speed_margin``, and a stop whose line is within
        reach while the grid node before it is not is ``stop_node``."""
        st = self.settings
        cap = self.planning_cap(preview)
        reach = self.braking_reach(v0, preview, a_prev)
        raised = reach > cap + 1e-9
        raised[0] = False  # node 0 is the current state, not a decision
        if not raised.any():
            return []
        s = np.asarray(preview.s, float)
        actual = np.asarray(preview.speed_cap, float)
        speed = plan.v if plan is not None and plan.converged else reach
        stops = np.asarray(preview.stops if preview.stops is not None else [], float)
        out: list[ConstraintViolation] = []
        k = 1
        while k < len(s):
            if not raised[k]:
                k += 1
                continue
            end = k
            while end + 1 < len(s) and raised[end + 1]:
                end += 1
            run = np.arange(k, end + 1)
            worst = int(run[np.argmax(speed[run] - actual[run])])
            near = stops[(stops >= s[k] - st.ds) & (stops <= s[end] + st.ds)]
            dist = max(float(s[worst] - s[0]), 1e-9)
            if near.size:
                stop = float(near[0])
                need = v0 ** 2 / (2.0 * max(stop - float(s[0]), 1e-9))
                # the grid caps the node before the line: the line itself may still be within comfortable reach
                at_line = self._reach_at(v0, a_prev, s, stop)
                if at_line <= float(actual[worst]) + VIOLATION_TOLERANCE:
                    out.append(ConstraintViolation("stop_node", stop, float(actual[worst]), float(speed[worst]),
                                                   "m/s", need, f"the line itself is reached at {at_line:.3g} m/s "
                                                   f"within the comfort limits"))
                else:
                    out.append(ConstraintViolation("stop", stop, float(actual[worst]), float(speed[worst]), "m/s",
                                                   need, f"comfort limit {st.decel_max:g} m/s^2"))
            elif speed[worst] > actual[worst] + VIOLATION_TOLERANCE:
                need = max(v0 ** 2 - actual[worst] ** 2, 0.0) / (2.0 * dist)
                out.append(ConstraintViolation("speed_cap", float(s[worst]), float(actual[worst]),
                                               float(speed[worst]), "m/s", need,
                                               f"comfort limit {st.decel_max:g} m/s^2"))
            else:
                need = max(v0 ** 2 - cap[worst] ** 2, 0.0) / (2.0 * dist)
                out.append(ConstraintViolation("speed_margin", float(s[worst]), float(cap[worst]),
                                               float(speed[worst]), "m/s", need,
                                               f"the cap itself ({actual[worst]:.3g} m/s) is met within "
                                               f"{VIOLATION_TOLERANCE:g} m/s"))
            k = end + 1
        return out

    def _reach_at(self, v0: float, a_prev: float, s: np.ndarray, position: float) -> float:
        """Lowest speed [m/s] reachable at ``position`` [m] inside the grid s within the comfort limits (the braking
        of :meth:`braking_reach` continued to that point; 0 if it stops before)."""
        speed, accel = self._braking(v0, len(s), a_prev, np.diff(s))
        k = int(np.clip(np.searchsorted(s, position, side="right") - 1, 0, len(accel) - 1))
        e = 0.5 * speed[k] ** 2 + accel[k] * (position - float(s[k]))  # E = v^2 / 2 [m^2/s^2]
        return math.sqrt(2.0 * max(e, 0.0))

    def contradictions(self, v0: float, a_prev: float, preview: Preview) -> list[ConstraintViolation]:
        """Limits that contradict each other before any solve: a cap ahead below the speed floor (the plan cannot
        go that slow), and a previous acceleration a_prev [m/s^2] that the jerk limit cannot bring inside the
        comfort bounds within the first segment."""
        st = self.settings
        out: list[ConstraintViolation] = []
        actual = np.asarray(preview.speed_cap, float)
        low = np.flatnonzero(actual[1:] < st.speed_floor - 1e-9) + 1
        if low.size:
            k = int(low[np.argmin(actual[low])])
            out.append(ConstraintViolation("speed_cap", float(preview.s[k]), float(actual[k]), st.speed_floor,
                                           "m/s", detail=f"below the speed floor {st.speed_floor:g} m/s (the "
                                           "planned speed cannot go lower)"))
        ds0 = float(preview.s[1] - preview.s[0])
        step = st.jerk_max * ds0 / max(v0, st.speed_floor)  # the largest acceleration change in segment 0
        if a_prev - step > st.accel_max + 1e-9 or a_prev + step < -st.decel_max - 1e-9:
            bound = st.accel_max if a_prev > 0 else -st.decel_max
            out.append(ConstraintViolation("jerk", float(preview.s[0]), st.jerk_max,
                                           abs(a_prev - bound) * max(v0, st.speed_floor) / ds0, "m/s^3",
                                           detail=f"the previous acceleration {a_prev:.3g} m/s^2 cannot reach the "
                                           f"comfort bounds [-{st.decel_max:g}, {st.accel_max:g}] m/s^2 within "
                                           f"the first {ds0:g} m"))
        return out

    def diagnose(self, plan: Plan, a_prev: float, preview: Preview, params: RoadLoadParameters,
                 time_weight: float | None = None) -> list[ConstraintViolation]:
        """A solve that did not converge: the constraint violated most (relative to its bound's scale) at the
        point where the solver stopped, one entry per constraint kind; the solver's status when none is."""
        if plan.x is None or not np.all(np.isfinite(plan.x)):
            return [ConstraintViolation("solver", float(preview.s[0]), 0.0, float("nan"), "-",
                                        detail=plan.solver_status or plan.status)]
        n = self.n
        _, _, lbg, ubg = self._bounds(float(plan.v[0]), preview, params, a_prev)
        g = np.asarray(self._g_fun(plan.x, self._params(a_prev, preview, params, time_weight))).ravel()
        over = np.maximum(g - ubg, 0.0) + np.maximum(lbg - g, 0.0)
        blocks = (("dynamics", "kN"), ("acceleration", "m/s^2"), ("jerk", "m/s^3"), ("traction_power", "kW"),
                  ("regen_power", "kW"))
        found = []
        for b, (name, unit) in enumerate(blocks):
            rows = over[b * n:(b + 1) * n]
            k = int(np.argmax(rows))
            if rows[k] > 1e-4:
                i = b * n + k
                bound = ubg[i] if g[i] > ubg[i] else lbg[i]
                violation = ConstraintViolation(name, float(preview.s[k]), float(bound), float(g[i]), unit)
                if name == "dynamics":  # the force the balance needs beyond what the drive or brakes give
                    violation = self._force_limit(plan, k, float(g[i]), preview, params)
                found.append((rows[k] / max(abs(bound), 1.0), violation))
        if not found:
            return [ConstraintViolation("solver", float(preview.s[0]), 0.0, 0.0, "-",
                                        detail=plan.solver_status or plan.status)]
        return [v for _, v in sorted(found, key=lambda f: -f[0])]

    def _force_limit(self, plan: Plan, k: int, residual: float, preview: Preview,
                     params: RoadLoadParameters) -> ConstraintViolation:
        """A force-balance residual [kN] of segment k read as the force limit it runs into: > 0, the motion needs
        more traction than the drive gives (e.g. a climb too steep to hold the speed floor); < 0, more braking
        than the brakes and regeneration give."""
        en = self.energy
        vm = max(0.5 * (float(plan.v[k]) + float(plan.v[k + 1])), 1e-3)
        grade = float(preview.grade[k])
        if residual > 0:
            limit = min(float(np.asarray(en.max_traction_force(None, preview.ratio), float)[k]),
                        en.max_power / vm) / 1000.0
            return ConstraintViolation("traction_force", float(preview.s[k]), limit,
                                       float(plan.traction[k]) / 1000.0 + residual, "kN",
                                       detail=f"at {vm:.3g} m/s on a grade of {100 * math.tan(grade):.3g} %, the "
                                       f"drive cannot give the force the speed floor {self.settings.speed_floor:g} "
                                       f"m/s and the deceleration bound need")
        # a drive without regeneration gives a scalar 0: broadcast to one value per segment
        regen = np.broadcast_to(np.asarray(en.max_regen_force(preview.ratio), float), np.shape(preview.ratio))
        limit = (en.brake_force_limit(params.mass) + float(regen[k])) / 1000.0
        return ConstraintViolation("brake_force", float(preview.s[k]), limit,
                                   float(plan.regen[k] + plan.brake[k]) / 1000.0 - residual, "kN",
                                   detail=f"on a grade of {100 * math.tan(grade):.3g} %")

    def _solve_ipopt(self, v0, a_prev, preview, params, warm, time_weight=None, target_speed=None) -> Plan:
        lbx, ubx, lbg, ubg = self._bounds(v0, preview, params, a_prev)
        p = self._params(a_prev, preview, params, time_weight)
        args = {"lbx": lbx, "ubx": ubx, "lbg": lbg, "ubg": ubg, "p": p}
        if target_speed is None and warm is not None and warm.x is not None and warm.lam_g is not None:
            x0, lam_x0, lam_g0 = self.shift(warm, float(preview.s[0]), preview.s)
            x0 = np.clip(x0, lbx, ubx)
            solver = self._warm
            args.update(x0=x0, lam_x0=lam_x0, lam_g0=lam_g0)
        else:
            solver = self._cold
            args.update(x0=self.initial_guess(v0, preview, params, a_prev, target_speed))
        t0, c0 = time.perf_counter(), time.process_time()
        res = solver(**args)
        elapsed, cpu = time.perf_counter() - t0, time.process_time() - c0
        stats = solver.stats()
        status = str(stats.get("return_status", "unknown"))
        ok = bool(stats.get("success", False)) or status == "Solved_To_Acceptable_Level"
        x = np.asarray(res["x"]).ravel()
        if not np.all(np.isfinite(x)):
            ok = False
        plan = self._plan_from_x(x, preview, ok, status, elapsed, int(stats.get("iter_count", -1)),
                                 float(res["f"]), np.asarray(res["lam_x"]).ravel(), np.asarray(res["lam_g"]).ravel())
        plan.cpu_time = cpu
        return plan

    def _qp_matrices(self, x, p, lam_g):
        grad, gval, jac, hess = self._qp_fun(x, p, lam_g)
        grad = np.asarray(grad).ravel()
        gval = np.asarray(gval).ravel()
        jnz = np.asarray(jac.nonzeros()) if hasattr(jac, "nonzeros") else np.asarray(jac).ravel()
        hnz = np.asarray(hess.nonzeros())
        # convexify: Gershgorin shift makes the Hessian diagonally dominant (hence PSD) + proximal term
        h_row, h_col = self._h_rowcol
        off = h_row != h_col
        rowsum = np.zeros(self._nx)
        np.add.at(rowsum, h_row[off], np.abs(hnz[off]))
        np.add.at(rowsum, h_col[off], np.abs(hnz[off]))
        diag = np.zeros(self._nx)
        np.add.at(diag, h_row[~off], hnz[~off])
        shift = np.maximum(rowsum - diag, 0.0) + 1e-4 * (1.0 + np.abs(diag))
        pdata = np.zeros(len(self._p_rows))
        pdata[self._p_from_h] = hnz
        pdata[self._p_diag] += shift
        adata = np.zeros(len(self._a_rows))
        adata[self._a_from_j] = jnz
        adata[self._a_eye] = 1.0
        # variable scaling dx = D z (E in units of QP_E_SCALE): P -> D P D, q -> D q, A -> A D
        d = self._qp_scale
        pdata *= d[self._p_rows] * d[self._p_cols]
        adata *= d[self._a_cols]
        return grad * d, gval, pdata, adata

    def _solve_qp(self, v0, a_prev, preview, params, warm, time_weight=None) -> Plan:
        import osqp

        lbx, ubx, lbg, ubg = self._bounds(v0, preview, params, a_prev)
        p = self._params(a_prev, preview, params, time_weight)
        t0, c0 = time.perf_counter(), time.process_time()
        if warm is not None and warm.x is not None:
            x, lam_x, lam_g = self.shift(warm, float(preview.s[0]), preview.s)
            lam_g = np.zeros(self._ng) if lam_g is None else lam_g
            y_warm = None if lam_x is None else np.concatenate([lam_g, lam_x])
        else:
            x, lam_g = self.initial_guess(v0, preview, params, a_prev), np.zeros(self._ng)
            y_warm = None
            self._osqp = None  # cold start: fresh OSQP state, so a run does not depend on the previous one
        x = np.clip(x, lbx, ubx)
        status, iters, ok = "not run", 0, False
        y = None
        for _ in range(max(1, self.settings.sqp_iterations)):
            grad, gval, pdata, adata = self._qp_matrices(x, p, lam_g)
            lo = np.concatenate([lbg - gval, lbx - x])  # bound rows carry D: lbx - x <= D z <= ubx - x
            hi = np.concatenate([ubg - gval, ubx - x])
            lo = np.where(np.isfinite(lo), lo, -1e20)
            hi = np.where(np.isfinite(hi), hi, 1e20)
            if self._osqp is None:
                P = sp.csc_matrix((pdata, self._p_rows, self._p_indptr), shape=(self._nx, self._nx))
                A = sp.csc_matrix((adata, self._a_rows, self._a_indptr), shape=(self._ng + self._nx, self._nx))
                self._osqp = osqp.OSQP()
                self._osqp.setup(P, grad, A, lo, hi, verbose=False, warm_starting=True, polishing=False,
                                 eps_abs=self.settings.qp_tolerance, eps_rel=self.settings.qp_tolerance,
                                 max_iter=4000, adaptive_rho=True, rho=3.0)
            else:
                self._osqp.update(q=grad, l=lo, u=hi, Px=pdata, Ax=adata)
            if y_warm is not None:
                self._osqp.warm_start(x=np.zeros(self._nx), y=y_warm)
                y_warm = None
            res = self._osqp.solve(raise_error=False)
            status = str(res.info.status)
            iters += int(res.info.iter)
            ok = res.info.status_val in (1, 2)  # solved / solved inaccurate
            if not ok or res.x is None or not np.all(np.isfinite(res.x)):
                ok = False
                break
            x = np.clip(x + self._qp_scale * res.x, lbx, ubx)
            y = res.y
            lam_g = y[:self._ng]
        elapsed, cpu = time.perf_counter() - t0, time.process_time() - c0
        lam_full = None if y is None else y
        plan = self._plan_from_x(x, preview, ok, status, elapsed, iters, float("nan"), None if lam_full is None
                                 else lam_full[self._ng:], None if lam_full is None else lam_full[:self._ng])
        plan.cpu_time = cpu
        return plan
