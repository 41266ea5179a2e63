"""The spatial MPC's problem data, formulation and reports checked against hand-derived values on short horizons
(6-10 segments, solves of a few milliseconds): settings validation, the comfort-braking reach, the bounds and
parameter vector, the constraint and objective functions at a given point, warm and cold starts of both solve
paths, and each kind of relaxed or infeasible report with its numbers. Fast enough to rerun for every mutant of
``controllers/mpc.py`` (``scripts/mutation_score.py``)."""

import math
from dataclasses import replace

import casadi as ca
import numpy as np
import pytest

from roadload.controllers.energy import SourceEnergyModel, generic_ev
from roadload.controllers.force_model import resistance_force
from roadload.controllers.mpc import (CONSTRAINTS, SEGMENT0_FRACTIONS, ConstraintViolation, MpcError, MpcSettings,
                                      OcpSolver, Plan, Preview)
from roadload.road_load import RoadLoadParameters, crosswind_drag_increase

G = 9.81
EV = generic_ev()
# rotational mass and a headwind, so inertial mass and the per-segment wind are told apart from mass and 0
PARAMS = RoadLoadParameters.from_physical(1420.0, 0.009, 0.0, 0.0, 0.7, 1.2, 60000.0, headwind=1.5,
                                          rotational_mass=60.0)
ICE = SourceEnergyModel(kind="ice", wheel_radius=0.5, gear_ratios=(20.0, 10.0, 5.0), shift_speeds=(5.0, 12.0),
                        loss=(2000.0, 1.0, 0.01, 0.02, 0.0), max_power=150e3, max_torque=800.0,
                        indicated_efficiency=0.4, auxiliary_power=1500.0, full_load_power=(1e4, 300.0, 0.5),
                        max_brake_deceleration=3.0)
N, DS = 6, 20.0


def settings(**kw):
    return MpcSettings(**{"n_nodes": N, "ds": DS, **kw})


def solver(energy=EV, **kw):
    return OcpSolver(settings(**kw), energy)


def preview(cap=20.0, grade=0.0, n=N, step=DS, **kw):
    cap = np.broadcast_to(np.asarray(cap, float), (n + 1,)).copy()
    return Preview(s=step * np.arange(n + 1), grade=np.broadcast_to(np.asarray(grade, float), (n,)).copy(),
                   curvature=np.zeros(n), speed_cap=cap, ratio=np.full(n, 9.665), **kw)


# ------------------------------------------------------------------------------------------------ settings
def test_settings_accept_their_boundary_values():
    st = MpcSettings(n_nodes=2, ds=5.0, speed_margin=0.0, accel_weight=0.0, time_weight=0.0, speed_floor=1.0,
                     stop_speed=1.0, max_iterations=1, sqp_iterations=1, warm_tol=0.5, terminal_value="none",
                     solver="osqp")
    assert st.horizon == 10.0 and MpcSettings().horizon == 2000.0


@pytest.mark.parametrize("kw, message", [
    ({"n_nodes": 1}, r"^n_nodes must be >= 2, got 1$"),
    ({"speed_margin": -0.1}, r"^MpcSettings.speed_margin: must be >= 0 \[m/s\] \(a negative margin plans above the "
                             r"limit\), got -0.1$"),
    ({"accel_weight": -0.01}, r"^MpcSettings.accel_weight: must be >= 0, got -0.01$"),
    ({"qp_tolerance": 0.0}, r"^MpcSettings: qp_tolerance must be > 0 and max_iterations, cold_max_iterations, "
                            r"sqp_iterations >= 1, got 0.0, 500, 500, 1$"),
    ({"max_iterations": 0}, r"got 0.001, 0, 500, 1$"),
    ({"cold_max_iterations": 0}, r"got 0.001, 500, 0, 1$"),
    ({"sqp_iterations": 0}, r"got 0.001, 500, 500, 0$"),
    ({"ds": 0.0}, r"^ds must be positive, got 0.0$"),
    ({"ds": -20.0}, r"^ds must be positive, got -20.0$"),
    ({"accel_max": 0.0}, r"^accel_max must be positive, got 0.0$"),
    ({"decel_max": 0.0}, r"^decel_max must be positive, got 0.0$"),
    ({"jerk_max": 0.0}, r"^jerk_max must be positive, got 0.0$"),
    ({"lateral_accel_max": 0.0}, r"^lateral_accel_max must be positive, got 0.0$"),
    ({"speed_floor": 0.0}, r"^speed_floor must be positive, got 0.0$"),
    ({"stop_speed": 0.0}, r"^stop_speed must be positive, got 0.0$"),
    ({"time_weight": -1.0}, r"^time_weight must be >= 0, got -1.0$"),
    ({"warm_tol": 0.0}, r"^warm_tol must be in \(0, 1\), got 0.0$"),
    ({"warm_tol": 1.0}, r"^warm_tol must be in \(0, 1\), got 1.0$"),
    ({"terminal_value": "kinetic"}, r"^MpcSettings.terminal_value: choose one of \('source', 'wheel', 'none'\), "
                                    r"got 'kinetic'$"),
    ({"solver": "gurobi"}, r"^unknown solver 'gurobi'; choose one of \('ipopt', 'osqp'\)$"),
    ({"stop_speed": 0.9}, r"^stop_speed must be >= speed_floor$"),
    ({"ds": float("nan")}, r"ds"),
])
def test_settings_refuse_each_bad_value_by_name(kw, message):
    with pytest.raises(MpcError, match=message):
        MpcSettings(**kw)


# ------------------------------------------------------------------------------------------------ reports
def test_violation_amount_and_description():
    v = ConstraintViolation("stop", 100.0, 1.0, 13.5, "m/s", 3.125, "comfort limit 2 m/s^2")
    assert v.amount == 12.5
    assert v.describe() == ("stop at 100 m: 13.5 m/s against a limit of 1 m/s (off by 12.5 m/s), needs 3.12 m/s^2 "
                            "of deceleration; comfort limit 2 m/s^2")
    low = ConstraintViolation("jerk", 0.0, 2.0, 1.25, "m/s^3")
    assert low.amount == 0.75 and math.isnan(low.required_decel)
    assert low.describe() == "jerk at 0 m: 1.25 m/s^3 against a limit of 2 m/s^3 (off by 0.75 m/s^3)"
    assert set(CONSTRAINTS) >= {"stop", "stop_node", "speed_cap", "speed_margin", "speed_floor", "acceleration",
                                "jerk", "dynamics", "traction_force", "brake_force", "solver"}


def test_plan_derived_quantities():
    plan = Plan(s=np.array([0.0, 10.0, 30.0]), v=np.array([10.0, 12.0, 8.0]), t=np.zeros(3),
                traction=np.array([500.0, 0.0]), regen=np.array([0.0, 300.0]), brake=np.array([0.0, 200.0]),
                success=True, status="ok", solve_time=0.0, iterations=3)
    np.testing.assert_allclose(plan.accel, [(72.0 - 50.0) / 10.0, (32.0 - 72.0) / 20.0])
    np.testing.assert_allclose(plan.wheel_force, [500.0, -500.0])
    # v^2 is linear in s inside a segment (constant force): sqrt((10^2 + 12^2) / 2), sqrt((12^2 + 8^2) / 2)
    assert plan.speed_at(5.0) == pytest.approx(math.sqrt(122.0))
    assert plan.speed_at(20.0) == pytest.approx(math.sqrt(104.0))
    assert [plan.segment_at(x) for x in (-5.0, 0.0, 9.99, 10.0, 29.0, 30.0, 99.0)] == [0, 0, 0, 1, 1, 1, 1]
    assert plan.feasibility == "feasible" and not plan.relaxed and math.isnan(plan.objective)
    plan.relaxed_nodes = 1
    plan.violations = (ConstraintViolation("speed_cap", 10.0, 11.0, 12.0, "m/s"),)
    assert plan.relaxed and plan.feasibility == "relaxed"
    plan.converged = False
    assert plan.feasibility == "infeasible"


# ------------------------------------------------------------------------------------------------ comfort reach
def test_braking_reach_ramps_at_the_jerk_limit_then_holds_the_comfort_deceleration():
    ocp = solver(jerk_max=0.5)
    speed = ocp.braking_reach(20.0, preview())
    # a_1 = 0 - 0.5 * 20 / 20 = -0.5; a_2 = -0.5 - 10 / v_1 with v_1 = sqrt(400 - 20)
    e1 = 200.0 - 0.5 * 20.0
    a2 = -0.5 - 10.0 / math.sqrt(2 * e1)
    assert speed[0] == 20.0 and speed[1] == pytest.approx(math.sqrt(2 * e1), rel=1e-12)
    assert speed[2] == pytest.approx(math.sqrt(2 * (e1 + 20.0 * a2)), rel=1e-12)
    assert len(speed) == N + 1 and np.all(np.diff(speed) < 0)
    _, accel = ocp._braking(20.0, N + 1, 0.0)
    assert accel[0] == -0.5 and accel[1] == pytest.approx(a2, rel=1e-12)
    assert accel.min() == -2.0 and accel[-1] == -2.0  # held at decel_max once reached


def test_braking_reach_clips_the_previous_acceleration_and_floors_the_speed():
    ocp = solver()
    # a_prev above accel_max starts from 1.5: a_1 = 1.5 - 2 * 20 / 20 = -0.5
    assert ocp.braking_reach(20.0, preview(), 5.0)[1] == pytest.approx(math.sqrt(400.0 - 20.0))
    # below -decel_max starts from -2 and stays there: E drops by 40 m^2/s^2 per segment
    np.testing.assert_allclose(ocp.braking_reach(20.0, preview(), -5.0),
                               np.sqrt(np.maximum(400.0 - 80.0 * np.arange(N + 1), 1.0)))
    # a slow start hits the speed floor (1 m/s), and a start below it begins at the floor
    np.testing.assert_allclose(ocp.braking_reach(5.0, preview(), -2.0), [5.0] + [1.0] * N)
    assert ocp.braking_reach(0.5, preview(), 0.0)[0] == 1.0


def test_planning_and_reachable_caps():
    ocp = solver()
    cap = np.array([30.0, 25.0, 10.0, 10.0, 1.0, 1.2, 30.0])
    np.testing.assert_allclose(ocp.planning_cap(preview(cap)), [29.7, 24.7, 9.7, 9.7, 1.0, 1.0, 29.7])
    reach = ocp.braking_reach(20.0, preview(cap))  # sqrt(400 - 80 k) from 20 m/s at -2 m/s^2
    raised = ocp.reachable_cap(20.0, preview(cap))
    planned = ocp.planning_cap(preview(cap))
    expect = np.where(reach > planned, reach + 0.1, planned)
    np.testing.assert_allclose(raised, expect)
    assert raised[2] == pytest.approx(math.sqrt(240.0) + 0.1) and raised[1] == pytest.approx(24.7)
    # nodes 2..4 cannot be reached under their caps (node 0 is the current state and never counts)
    assert ocp.relaxed_nodes(20.0, preview(cap)) == 3  # node 5: the floor meets its cap
    assert ocp.relaxed_nodes(20.0, preview(30.0)) == 0
    assert ocp.relaxed_nodes(20.5, preview(np.array([20.0] + [30.0] * N))) == 0


# ------------------------------------------------------------------------------------------------ problem data
def test_bounds_hold_the_state_force_and_comfort_limits():
    ocp = solver()
    lbx, ubx, lbg, ubg = ocp._bounds(12.0, preview(20.0), PARAMS, 0.0)
    assert lbx.shape == ubx.shape == (4 * N + 1,) and lbg.shape == ubg.shape == (5 * N,)
    assert lbx[0] == ubx[0] == 72.0  # E_0 = v0^2 / 2, fixed
    np.testing.assert_allclose(lbx[1:N + 1], 0.5)  # speed floor 1 m/s
    np.testing.assert_allclose(ubx[1:N + 1], 0.5 * 19.7 ** 2)  # cap less the margin
    np.testing.assert_allclose(lbx[N + 1:], 0.0)
    np.testing.assert_allclose(ubx[N + 1:2 * N + 1], 250.0 * 9.665 / 0.35 / 1000.0)  # torque-limited traction kN
    np.testing.assert_allclose(ubx[2 * N + 1:3 * N + 1], 150.0 * 9.665 / 0.35 / 1000.0)  # regeneration kN
    np.testing.assert_allclose(ubx[3 * N + 1:], 0.8 * G * 1420.0 / 1000.0, rtol=1e-3)  # friction brake kN
    np.testing.assert_array_equal(lbg, np.concatenate([np.zeros(N), np.full(N, -2.0), np.full(N, -2.0),
                                                       np.full(2 * N, -np.inf)]))
    np.testing.assert_array_equal(ubg, np.concatenate([np.zeros(N), np.full(N, 1.5), np.full(N, 2.0), np.zeros(N),
                                                       np.full(N, 50.0)]))
    # below the floor the state starts at the floor; a drive without regeneration gets no regenerative power
    assert solver()._bounds(0.2, preview(20.0), PARAMS)[0][0] == 0.5
    no_regen = OcpSolver(settings(), ICE)._bounds(12.0, preview(20.0), PARAMS)
    np.testing.assert_array_equal(no_regen[3][4 * N:], 0.0)
    np.testing.assert_array_equal(no_regen[1][2 * N + 1:3 * N + 1], 0.0)
    np.testing.assert_allclose(no_regen[1][3 * N + 1:], 3.0 * 1420.0 / 1000.0)


def test_segment0_cap_bounds_the_first_node():
    ocp = solver()
    high = np.full(len(SEGMENT0_FRACTIONS), 30.0)
    # a cap 9.5 m/s at the end of segment 0 only: E_1 <= (9.5 - 0.3)^2 / 2
    cap = high.copy()
    cap[-1] = 9.5
    ubx = ocp._bounds(10.0, preview(20.0, segment0_cap=cap), PARAMS)[1]
    assert ubx[1] == pytest.approx(0.5 * 9.2 ** 2) and ubx[2] == pytest.approx(0.5 * 19.7 ** 2)
    # the same cap half way along: E0 (1 - x) + E1 x <= c -> E1 <= E0 + (c - E0) / 0.5
    cap = high.copy()
    cap[4] = 9.5
    ubx = ocp._bounds(10.0, preview(20.0, segment0_cap=cap), PARAMS)[1]
    assert ubx[1] == pytest.approx(50.0 + (0.5 * 9.2 ** 2 - 50.0) / 0.5)
    # a cap right ahead that braking cannot meet: E1 is bounded by the comfort-braking reach (E0 - 2 * 20)
    cap = high.copy()
    cap[0] = 5.0
    ubx = ocp._bounds(10.0, preview(20.0, segment0_cap=cap), PARAMS)[1]
    assert ubx[1] == pytest.approx(10.0 + 1e-3)
    # a cap above the current speed leaves node 1 alone
    ubx = ocp._bounds(10.0, preview(20.0, segment0_cap=high), PARAMS)[1]
    assert ubx[1] == pytest.approx(0.5 * 19.7 ** 2)
    # from just above the floor the bound stays above the floor energy
    cap = high.copy()
    cap[0] = 0.5
    ubx = solver(decel_max=10.0, jerk_max=50.0)._bounds(1.2, preview(20.0, segment0_cap=cap), PARAMS)[1]
    assert ubx[1] == pytest.approx(0.5 + 1e-3)


def test_parameter_vector_layout():
    ocp = solver(time_weight=2500.0)
    pv = preview(20.0, grade=0.01)
    p = ocp._params(0.3, pv, PARAMS)
    assert p.shape == (1 + 3 * N + 8 + 1 + 2 * N + 1 + N,)
    assert p[0] == 0.3
    np.testing.assert_array_equal(p[1:N + 1], 0.01)
    np.testing.assert_array_equal(p[2 * N + 1:3 * N + 1], 9.665)
    np.testing.assert_array_equal(p[3 * N + 1:3 * N + 9], PARAMS.as_vector())
    assert p[3 * N + 9] == 2500.0
    np.testing.assert_array_equal(p[3 * N + 10:4 * N + 10], 1.5)  # the force model's scalar headwind
    np.testing.assert_array_equal(p[4 * N + 10:5 * N + 10], 0.0)  # no crosswind
    assert p[5 * N + 10] == 0.0
    np.testing.assert_array_equal(p[5 * N + 11:], DS)
    wind = preview(20.0, step=15.0, headwind=np.arange(N, dtype=float), crosswind=np.full(N, 2.0),
                   yaw_drag_factor=0.4, ds=np.full(N, 15.0))
    p = ocp._params(0.0, wind, PARAMS, time_weight=0.0)
    assert p[3 * N + 9] == 0.0
    np.testing.assert_array_equal(p[3 * N + 10:4 * N + 10], np.arange(N))
    np.testing.assert_array_equal(p[4 * N + 10:5 * N + 10], 2.0)
    assert p[5 * N + 10] == 0.4
    np.testing.assert_array_equal(p[5 * N + 11:], 15.0)
    np.testing.assert_array_equal(ocp.segment_lengths(wind), 15.0)
    np.testing.assert_array_equal(ocp.segment_lengths(pv), np.full(N, DS))
    for bad in (float("nan"), -1.0, float("inf")):
        with pytest.raises(MpcError, match=r"^time_weight: must be a finite number >= 0 \[J/s\], got "):
            ocp._params(0.0, pv, PARAMS, time_weight=bad)


@pytest.mark.parametrize("change, message", [
    ({"grade": np.zeros(N - 1)}, r"^preview.grade: expected shape \(6,\), got \(5,\)$"),
    ({"s": np.arange(N, dtype=float)}, r"^preview.s: expected shape \(7,\), got \(6,\)$"),
    ({"curvature": np.zeros(N + 1)}, r"^preview.curvature: expected shape"),
    ({"speed_cap": np.zeros(N)}, r"^preview.speed_cap: expected shape"),
    ({"ratio": np.zeros(2)}, r"^preview.ratio: expected shape"),
    ({"headwind": np.zeros(N + 1)}, r"^preview.headwind: expected shape"),
    ({"crosswind": np.zeros(1)}, r"^preview.crosswind: expected shape"),
    ({"ds": np.full(N + 1, 20.0)}, r"^preview.ds: expected shape"),
    ({"ds": np.array([20.0, 20.0, 0.0, 20.0, 20.0, 20.0])}, r"^preview.ds: segment lengths must be > 0 m$"),
    ({"yaw_drag_factor": -0.1}, r"^preview.yaw_drag_factor: a finite number >= 0 \[1\], got -0.1$"),
    ({"yaw_drag_factor": float("nan")}, r"^preview.yaw_drag_factor"),
    ({"grade": np.array([0.0, np.nan, 0, 0, 0, 0])}, r"^preview.grade contains NaN/inf$"),
    ({"crosswind": np.array([0.0, np.inf, 0, 0, 0, 0])}, r"^preview.crosswind contains NaN/inf$"),
])
def test_solve_refuses_a_malformed_preview_by_field(change, message):
    pv = preview(20.0)
    for key, value in change.items():
        setattr(pv, key, value)
    with pytest.raises(MpcError, match=message):
        solver().solve(10.0, 0.0, pv, PARAMS)


def test_solve_refuses_a_non_finite_state():
    ocp = solver()
    with pytest.raises(MpcError, match=r"^initial speed/acceleration not finite \(v0=nan, a_prev=0.0\)$"):
        ocp.solve(float("nan"), 0.0, preview(), PARAMS)
    with pytest.raises(MpcError, match=r"a_prev=inf"):
        ocp.solve(10.0, float("inf"), preview(), PARAMS)
    # optional fields left None and zero yaw drag are accepted
    assert ocp.solve(10.0, 0.0, preview(yaw_drag_factor=0.0), PARAMS).success


def test_initial_guess_ramps_comfortably_under_the_caps():
    ocp = solver()
    cap = np.array([30.0, 30.0, 30.0, 30.0, 30.0, 30.0, 8.3])
    grade = np.array([0.0, 0.0, 0.0, 0.0, 0.0, -0.4])  # a steep last segment: more braking than regeneration
    x = ocp.initial_guess(10.0, preview(cap, grade=grade), PARAMS)
    v = np.sqrt(2 * x[:N + 1])
    # forward: v_{k+1}^2 = v_k^2 + accel_max ds (half the comfort acceleration), capped at the last node (8 m/s)
    forward = np.sqrt(100.0 + 30.0 * np.arange(N + 1))
    # backward: v_k^2 <= v_{k+1}^2 + decel_max ds (half the comfort deceleration); node 0 is the current state
    expect = forward.copy()
    expect[-1] = 8.0
    for k in range(N - 1, 0, -1):
        expect[k] = min(expect[k], math.sqrt(expect[k + 1] ** 2 + 40.0))
    np.testing.assert_allclose(v, expect)
    vm = 0.5 * (v[1:] + v[:-1])
    force = PARAMS.inertial_mass * np.diff(x[:N + 1]) / DS + resistance_force(vm, grade, np.zeros(N), PARAMS)
    regen_max = 150.0 * 9.665 / 0.35
    np.testing.assert_allclose(x[N + 1:2 * N + 1], np.clip(force, 0, None) / 1000.0)
    np.testing.assert_allclose(x[2 * N + 1:3 * N + 1], np.clip(-force, 0, regen_max) / 1000.0)
    np.testing.assert_allclose(x[3 * N + 1:], (np.clip(-force, 0, None) - np.clip(-force, 0, regen_max)) / 1000.0)
    assert force[-1] < -regen_max  # the last segment needs the friction brake too
    # a target speed caps the guess (floored at the speed floor); a start below the floor starts at it
    slow = np.sqrt(2 * ocp.initial_guess(10.0, preview(30.0), PARAMS, target_speed=12.0)[:N + 1])
    assert slow.max() == pytest.approx(12.0) and slow[1] == pytest.approx(math.sqrt(130.0))
    crawl = np.sqrt(2 * ocp.initial_guess(3.0, preview(30.0), PARAMS, target_speed=0.2)[:N + 1])
    np.testing.assert_allclose(crawl[1:], 1.0)
    assert np.sqrt(2 * ocp.initial_guess(0.0, preview(30.0), PARAMS)[0]) == 1.0
    uneven = Preview(s=np.array([0.0, 10.0, 30.0, 60.0, 100.0, 150.0, 210.0]), grade=np.zeros(N),
                     curvature=np.zeros(N), speed_cap=np.full(N + 1, 30.0), ratio=np.full(N, 9.665),
                     ds=np.array([10.0, 20.0, 30.0, 40.0, 50.0, 60.0]))
    v = np.sqrt(2 * ocp.initial_guess(10.0, uneven, PARAMS)[:N + 1])
    np.testing.assert_allclose(v ** 2, 100.0 + 1.5 * np.concatenate([[0.0], np.cumsum(uneven.ds)]))


def test_plan_from_x_and_shift():
    ocp = solver()
    E = 0.5 * np.array([10.0, 11.0, 12.0, 13.0, 14.0, 15.0, 16.0]) ** 2
    x = np.concatenate([E, np.arange(N) + 1.0, np.full(N, 0.5), np.full(N, 0.25)])
    lam_x, lam_g = np.arange(4 * N + 1.0), np.arange(5 * N + 0.0)
    plan = ocp._plan_from_x(x, preview(), True, "ok", 0.1, 7, 3.0, lam_x, lam_g)
    np.testing.assert_allclose(plan.v, [10, 11, 12, 13, 14, 15, 16])
    np.testing.assert_allclose(plan.t, np.concatenate([[0.0], np.cumsum(20.0 / np.arange(10.5, 16.0))]))
    np.testing.assert_allclose(plan.traction, 1000.0 * (np.arange(N) + 1))
    np.testing.assert_allclose(plan.regen, 500.0)
    np.testing.assert_allclose(plan.brake, 250.0)
    assert (plan.success, plan.status, plan.solve_time, plan.iterations, plan.objective) == (True, "ok", 0.1, 7, 3.0)
    x[0] = lam_x[0] = lam_g[0] = -1.0  # the plan holds copies
    assert plan.x[0] == 50.0 and plan.lam_x[0] == 0.0 and plan.lam_g[0] == 0.0
    assert ocp._plan_from_x(np.concatenate([[-1.0], x[1:]]), preview(), False, "", 0, 0, 0).v[0] == 0.0
    assert ocp._plan_from_x(x, preview(), False, "", 0, 0, 0).lam_x is None
    # shifting by one segment moves every block one node on, the last value held
    plan.x[0] = 50.0
    xs, lxs, lgs = ocp.shift(plan, 20.0)
    np.testing.assert_allclose(xs[:N + 1], np.append(E[1:], E[-1]))
    np.testing.assert_allclose(xs[N + 1:2 * N + 1], [2, 3, 4, 5, 6, 6])
    np.testing.assert_allclose(lxs[:N + 1], [1, 2, 3, 4, 5, 6, 6])
    np.testing.assert_allclose(lgs[:N], [1, 2, 3, 4, 5, 5])
    np.testing.assert_allclose(lgs[N:2 * N], [7, 8, 9, 10, 11, 11])
    half = ocp.shift(plan, 10.0)[0]
    assert half[0] == pytest.approx(0.5 * (E[0] + E[1]))
    plan.lam_x = plan.lam_g = None
    assert ocp.shift(plan, 0.0)[1:] == (None, None)


# ------------------------------------------------------------------------------------------------ formulation
def _numpy_g_and_f(ocp, energy, x, a_prev, pv, lam, ke_value):
    """Constraint vector and objective of the module docstring, written out in numpy."""
    n, st, p = ocp.n, ocp.settings, PARAMS
    E, ft, fr, fb = x[:n + 1], x[n + 1:2 * n + 1], x[2 * n + 1:3 * n + 1], x[3 * n + 1:]
    ds = np.asarray(pv.ds, float)
    v = np.sqrt(2 * E)
    vm = 0.5 * (v[1:] + v[:-1])
    acc = np.diff(E) / ds
    fres = np.array([
        resistance_force(vm[k], pv.grade[k], pv.curvature[k], p.with_(headwind=float(pv.headwind[k])))
        + crosswind_drag_increase(p.c2, vm[k] + pv.headwind[k], pv.crosswind[k], pv.yaw_drag_factor)
        for k in range(n)])
    m_in = p.mass + p.rotational_mass
    dyn = (m_in * acc + fres) / 1000.0 - (ft - fr - fb)
    jerk = np.concatenate([[(acc[0] - a_prev) * v[0] / ds[0]], np.diff(acc) * v[1:-1] / (0.5 * (ds[:-1] + ds[1:]))])
    power = ft * vm - energy.traction_power_limit(vm) / 1000.0
    g = np.concatenate([dyn, acc, jerk, power, fr * vm])
    ratio = energy.smooth_ratio(vm) if energy.kind == "ice" else pv.ratio
    source = energy.source_power(1000 * ft, 1000 * fr, vm, ratio)
    t_end = np.sum(ds / vm)
    f = (np.sum(source * ds / vm) / 1000.0 + lam * t_end / 1000.0 - ke_value * m_in * E[-1] / 1000.0
         + st.accel_weight * p.mass / 1000.0 * np.sum(acc ** 2) + 1e-6 * np.dot(ds, ft + fr + fb))
    return g, f, np.sum(source * ds / vm)


@pytest.mark.parametrize("energy, terminal, ke_value", [(EV, "source", 1.0), (ICE, "source", 1 / 0.4),
                                                        (ICE, "wheel", 1.0), (ICE, "none", 0.0)])
def test_constraints_and_objective_match_the_written_out_problem(energy, terminal, ke_value):
    ocp = OcpSolver(settings(terminal_value=terminal, accel_weight=0.2), energy)
    ds = np.array([10.0, 20.0, 30.0, 20.0, 25.0, 15.0])
    pv = Preview(s=np.concatenate([[0.0], np.cumsum(ds)]), grade=np.array([0.02, -0.01, 0.0, 0.04, 0.01, -0.03]),
                 curvature=np.array([0.0, 0.01, 0.0, -0.02, 0.0, 0.0]), speed_cap=np.full(N + 1, 30.0),
                 ratio=np.full(N, 9.665), headwind=np.array([1.0, 2.0, -1.0, 0.0, 3.0, 0.5]),
                 crosswind=np.array([0.0, 3.0, -2.0, 1.0, 0.0, 4.0]), yaw_drag_factor=0.6, ds=ds)
    v = np.array([10.0, 11.0, 13.0, 12.0, 14.0, 15.0, 13.5])
    x = np.concatenate([0.5 * v ** 2, [0.8, 1.2, 0.0, 2.0, 0.3, 0.0], [0.0, 0.0, 0.4, 0.0, 0.0, 0.6],
                        [0.0, 0.1, 0.2, 0.0, 0.0, 0.3]])
    p = ocp._params(0.4, pv, PARAMS, time_weight=4000.0)
    f_fun = ca.Function("f", [ocp._nlp["x"], ocp._nlp["p"]], [ocp._nlp["f"]])
    g_expect, f_expect, energy_expect = _numpy_g_and_f(ocp, energy, x, 0.4, pv, 4000.0, ke_value)
    np.testing.assert_allclose(np.asarray(ocp._g_fun(x, p)).ravel(), g_expect, rtol=1e-9, atol=1e-9)
    assert float(f_fun(x, p)) == pytest.approx(f_expect, rel=1e-9)
    plan = ocp._plan_from_x(x, pv, True, "", 0.0, 0, 0.0)
    assert ocp.source_energy(plan, 0.4, pv, PARAMS) == pytest.approx(energy_expect, rel=1e-9)


def test_source_energy_needs_a_primal_vector():
    plan = Plan(s=np.zeros(N + 1), v=np.ones(N + 1), t=np.zeros(N + 1), traction=np.zeros(N), regen=np.zeros(N),
                brake=np.zeros(N), success=False, status="fallback", solve_time=0.0, iterations=0)
    with pytest.raises(MpcError, match=r"^source_energy: the plan has no primal vector x \(a fallback plan\); "
                                       r"solve one first$"):
        solver().source_energy(plan, 0.0, preview(), PARAMS)


# ------------------------------------------------------------------------------------------------ solves
def _check_plan_limits(plan, st, cap):
    assert plan.v.max() <= cap - st.speed_margin + 1e-6
    assert plan.accel.min() >= -st.decel_max - 1e-6 and plan.accel.max() <= st.accel_max + 1e-6
    # the force balance of every segment holds at the solution (m_in dE/ds + F_resist = F_t - F_r - F_b)
    vm = 0.5 * (plan.v[1:] + plan.v[:-1])
    need = PARAMS.inertial_mass * plan.accel + resistance_force(vm, np.zeros(len(vm)), np.zeros(len(vm)), PARAMS)
    np.testing.assert_allclose(plan.wheel_force, need, atol=2.0)


def test_ipopt_plan_accelerates_to_the_cap_within_the_comfort_limits_and_is_silent(capfd):
    ocp = solver(time_weight=20000.0)
    plan = ocp.solve(10.0, 0.0, preview(15.0), PARAMS)
    assert plan.success and plan.status == "Solve_Succeeded" == plan.solver_status and plan.converged
    assert plan.feasibility == "feasible" and plan.violations == () and plan.relaxed_nodes == 0
    _check_plan_limits(plan, ocp.settings, 15.0)
    assert plan.v[-1] == pytest.approx(14.7, abs=1e-3)  # a high time weight: up to the cap less the margin
    jerk = np.diff(plan.accel) * plan.v[1:-1] / DS
    assert np.abs(jerk).max() <= 2.0 + 1e-6
    assert plan.t[-1] == pytest.approx(np.sum(DS / (0.5 * (plan.v[1:] + plan.v[:-1]))))
    assert plan.objective == pytest.approx(float(ca.Function("f", [ocp._nlp["x"], ocp._nlp["p"]],
                                                             [ocp._nlp["f"]])(plan.x, ocp._params(
                                                                 0.0, preview(15.0), PARAMS, 20000.0))), rel=1e-9)
    assert 0 < plan.iterations < 100 and plan.cpu_time >= 0.0 and plan.solve_time >= 0.0
    assert plan.lam_x.shape == (4 * N + 1,) and plan.lam_g.shape == (5 * N,)
    ocp.solve(10.0, 0.0, preview(15.0), PARAMS, warm=plan)
    qp = solver(solver="osqp")
    qp.solve(10.0, 0.0, preview(15.0), PARAMS, warm=qp.solve(10.0, 0.0, preview(15.0), PARAMS))
    out = capfd.readouterr()
    assert out.out == "" and out.err == ""  # neither solver prints, cold or warm


def test_time_weight_per_solve_overrides_the_settings():
    ocp = solver(time_weight=0.0)
    lazy = ocp.solve(15.0, 0.0, preview(30.0), PARAMS)
    hurried = ocp.solve(15.0, 0.0, preview(30.0), PARAMS, time_weight=50000.0)
    assert hurried.t[-1] < lazy.t[-1] - 0.2 and hurried.v[-1] > lazy.v[-1] + 2.0
    again = ocp.solve(15.0, 0.0, preview(30.0), PARAMS, time_weight=0.0)
    np.testing.assert_allclose(again.v, lazy.v, atol=1e-6)


def test_warm_start_from_the_previous_plan_converges_at_once_to_the_same_plan():
    ocp = solver(time_weight=6000.0)
    pv = preview(np.array([30.0, 30.0, 30.0, 16.0, 16.0, 30.0, 30.0]))
    cold = ocp.solve(14.0, 0.0, pv, PARAMS)
    warm = ocp.solve(14.0, 0.0, pv, PARAMS, warm=cold)
    assert cold.success and warm.success and warm.iterations <= 2 < cold.iterations
    np.testing.assert_allclose(warm.v, cold.v, atol=1e-3)
    # moved one segment on, the shifted plan is the start: still converged quickly, still within the caps
    moved = Preview(s=pv.s + DS, grade=pv.grade, curvature=pv.curvature,
                    speed_cap=np.append(pv.speed_cap[1:], 30.0), ratio=pv.ratio)
    nxt = ocp.solve(float(cold.v[1]), float(cold.accel[0]), moved, PARAMS, warm=cold)
    assert nxt.success and nxt.iterations < cold.iterations and nxt.v[2] <= 15.7 + 1e-6
    # a target speed forces a cold start from a guess cruising at it, even with a warm plan at hand
    target = ocp.solve(14.0, 0.0, pv, PARAMS, warm=cold, target_speed=14.0)
    assert target.iterations > 2 and target.success
    np.testing.assert_allclose(target.v, cold.v, atol=1e-3)


def test_an_iteration_cap_is_reported_as_not_converged():
    ocp = solver(cold_max_iterations=1)
    plan = ocp.solve(5.0, 0.0, preview(np.array([30.0] * 4 + [3.0] * 3)), PARAMS)
    assert not plan.converged and not plan.success and plan.feasibility == "infeasible"
    assert plan.solver_status == "Maximum_Iterations_Exceeded" and plan.iterations == 1
    assert plan.status.startswith("infeasible: ") and plan.status.endswith("[solver: Maximum_Iterations_Exceeded]")


def test_a_cold_solve_has_its_own_iteration_cap():
    """The warm solves' cap (max_iterations) does not cut a cold solve short: the first plan of a run starts from
    a guess, not from a converged plan, and needs more iterations (a 40 t truck at 23 m/s on its 2 km horizon:
    about 170, against the warm cap of 100; cut there, the controller fell back to its cruise control)."""
    pv = preview(np.array([30.0] * 4 + [3.0] * 3))
    ocp = solver(max_iterations=1)
    cold = ocp.solve(5.0, 0.0, pv, PARAMS)
    assert cold.converged and cold.iterations > 1
    moved = Preview(s=pv.s + DS, grade=pv.grade, curvature=pv.curvature,
                    speed_cap=np.append(pv.speed_cap[1:], 3.0), ratio=pv.ratio)
    warm = ocp.solve(float(cold.v[1]) + 0.5, float(cold.accel[0]), moved, PARAMS, warm=cold)
    assert warm.iterations == 1  # the warm cap still applies
    assert solver(cold_max_iterations=1).solve(5.0, 0.0, pv, PARAMS).iterations == 1


def test_a_warm_solve_far_from_its_previous_plan_converges_within_the_warm_cap():
    """A warm start whose previous plan no longer fits the problem (here: a plan of another road and speed) takes
    IPOPT more than 100 iterations; within the warm cap it still ends at the plan a cold solve reaches (at the old
    cap of 100 it ended unconverged and the controller followed its shifted old plan: 26-108 warm solves per run on
    a 40 t truck's long grades)."""
    n = 8
    first = preview(np.array([22.0, 4.0, 27.0, 19.0, 18.0, 25.0, 7.0, 11.0, 17.0]),
                    grade=np.array([-0.08, -0.02, 0.06, 0.04, 0.02, 0.05, 0.03, 0.02]), n=n)
    second = preview(np.array([16.0, 27.0, 22.0, 13.0, 26.0, 18.0, 3.0, 29.0, 15.0]),
                     grade=np.array([0.05, 0.07, -0.06, 0.04, 0.02, 0.06, -0.03, -0.06]), n=n)
    ocp = solver(ICE, n_nodes=n, time_weight=4000.0)
    previous = ocp.solve(4.0, 0.0, first, PARAMS)
    warm = ocp.solve(19.0, -0.9, second, PARAMS, warm=previous)
    cold = ocp.solve(19.0, -0.9, second, PARAMS)
    assert previous.converged and cold.converged and warm.converged and warm.iterations > 100
    np.testing.assert_allclose(warm.v, cold.v, atol=1e-2)
    capped = solver(ICE, n_nodes=n, time_weight=4000.0, max_iterations=100)
    stuck = capped.solve(19.0, -0.9, second, PARAMS, warm=capped.solve(4.0, 0.0, first, PARAMS))
    assert not stuck.converged and stuck.iterations == 100 and np.abs(stuck.v - cold.v).max() > 1.0


def test_qp_path_reaches_the_ipopt_plan():
    pv = preview(np.array([30.0, 30.0, 30.0, 16.0, 16.0, 30.0, 30.0]))
    exact = solver(time_weight=6000.0).solve(14.0, 0.0, pv, PARAMS)
    qp = solver(time_weight=6000.0, solver="osqp", sqp_iterations=8, qp_tolerance=1e-6)
    first = qp.solve(14.0, 0.0, pv, PARAMS)
    assert first.success and first.status == "solved" and first.iterations > 0
    np.testing.assert_allclose(first.v, exact.v, atol=0.02)
    np.testing.assert_allclose(first.wheel_force, exact.wheel_force, atol=30.0)
    assert math.isnan(first.objective) and first.cpu_time >= 0
    _check_plan_limits(first, qp.settings, 30.0)
    # a cold start does not depend on the solve before it
    np.testing.assert_array_equal(qp.solve(14.0, 0.0, pv, PARAMS).x, first.x)
    # one real-time iteration warm-started from the converged plan stays on it
    rti = solver(time_weight=6000.0, solver="osqp", qp_tolerance=1e-6)
    start = rti.solve(14.0, 0.0, pv, PARAMS)
    for _ in range(6):
        start = rti.solve(14.0, 0.0, pv, PARAMS, warm=start)
    assert start.success
    np.testing.assert_allclose(start.v, exact.v, atol=0.02)
    warm_lam = rti.solve(14.0, 0.0, pv, PARAMS, warm=first)
    assert warm_lam.lam_g.shape == (5 * N,) and warm_lam.lam_x.shape == (4 * N + 1,)
    assert warm_lam.iterations < first.iterations


def test_qp_failure_is_not_a_plan():
    ocp = solver(solver="osqp")
    ocp.solve(14.0, 0.0, preview(20.0), PARAMS)
    ocp._osqp.update_settings(max_iter=1)
    plan = ocp.solve(14.0, 0.0, preview(20.0), PARAMS, warm=None)
    # the cold start rebuilds the workspace with the full iteration budget
    assert plan.success
    ocp._osqp.update_settings(max_iter=1)
    failed = ocp.solve(14.0, 0.0, preview(20.0), PARAMS, warm=plan)
    assert not failed.converged and not failed.success and failed.solver_status == "maximum iterations reached"
    assert failed.status.startswith("infeasible: ")
    # a failed QP moves nothing: the plan is the clipped warm start
    lbx, ubx, _, _ = ocp._bounds(14.0, preview(20.0), PARAMS)
    np.testing.assert_allclose(failed.x, np.clip(ocp.shift(plan, 0.0)[0], lbx, ubx))


def test_qp_iterations_add_up_over_the_sqp_rounds():
    pv = preview(np.array([30.0, 30.0, 30.0, 16.0, 16.0, 30.0, 30.0]))
    one = solver(time_weight=6000.0, solver="osqp", qp_tolerance=1e-6).solve(14.0, 0.0, pv, PARAMS)
    eight = solver(time_weight=6000.0, solver="osqp", qp_tolerance=1e-6, sqp_iterations=8).solve(14.0, 0.0, pv, PARAMS)
    assert eight.iterations >= one.iterations + 7  # the first round is the same solve, each later one adds >= 1


# ------------------------------------------------------------------------------------------------ relaxed reports
def stop_preview(position, speed=30.0, n=10, cap=None):
    caps = np.full(n + 1, speed) if cap is None else np.asarray(cap, float)
    k = int(position // DS)
    caps[k:k + 2] = 1.0
    return preview(caps, n=n, stops=np.array([position]))


def test_a_stop_out_of_comfort_reach_is_named_with_its_amount():
    ocp = OcpSolver(settings(n_nodes=10), EV)
    plan = ocp.solve(25.0, 0.0, stop_preview(100.0), PARAMS)
    assert plan.converged and not plan.success and plan.feasibility == "relaxed"
    (v,) = plan.violations
    assert (v.constraint, v.position, v.limit, v.unit) == ("stop", 100.0, 1.0, "m/s")
    # the worst node of the run: the plan's speed at the node where it exceeds the stop's cap most
    assert v.value == pytest.approx(plan.v[np.argmax(plan.v[5:7] - 1.0) + 5])
    assert v.required_decel == pytest.approx(25.0 ** 2 / 200.0) and v.detail == "comfort limit 2 m/s^2"
    assert plan.status == f"relaxed: {v.describe()} [solver: Solve_Succeeded]"
    assert plan.relaxed_nodes == ocp.relaxed_nodes(25.0, stop_preview(100.0)) >= 2
    # reported from the comfort-braking reach when no converged plan is at hand
    (r,) = ocp.relaxations(25.0, 0.0, stop_preview(100.0))
    reach = ocp.braking_reach(25.0, stop_preview(100.0))
    assert r.value == pytest.approx(max(reach[5], reach[6]))
    plan.converged = False
    assert ocp.relaxations(25.0, 0.0, stop_preview(100.0), plan)[0].value == r.value


def test_a_stop_line_within_reach_behind_an_unreachable_node_is_a_stop_node():
    ocp = OcpSolver(settings(n_nodes=10), EV)
    cap = np.full(11, 30.0)
    cap[5:7] = 1.0
    pv = preview(cap, n=10, stops=np.array([118.0]))
    (v,) = ocp.relaxations(20.5, 0.0, pv)
    assert v.constraint == "stop_node" and v.position == 118.0 and v.limit == 1.0
    assert v.required_decel == pytest.approx(20.5 ** 2 / (2 * 118.0))
    assert v.detail == "the line itself is reached at 0 m/s within the comfort limits"
    # the line at 104 m is out of reach: braking from 20.5 m/s leaves 2.5 m/s there (4 m past node 5)
    far = preview(cap, n=10, stops=np.array([104.0]))
    (w,) = ocp.relaxations(20.5, 0.0, far)
    assert w.constraint == "stop" and w.position == 104.0 and w.detail == "comfort limit 2 m/s^2"
    e = 0.5 * ocp.braking_reach(20.5, far)[5] ** 2 - 2.0 * 4.0
    assert ocp._reach_at(20.5, 0.0, far.s, 104.0) == pytest.approx(math.sqrt(2 * e)) and e > 0.6
    assert ocp._reach_at(20.5, 0.0, far.s, 1000.0) == 0.0
    # before the grid: segment 0's acceleration (-2 * 20 / 20.5 m/s^2) run backwards
    assert ocp._reach_at(20.5, 0.0, far.s, -5.0) == pytest.approx(math.sqrt(20.5 ** 2 + 2 * 5.0 * 40.0 / 20.5))


def test_a_cap_below_the_current_speed_is_a_speed_cap_violation():
    ocp = OcpSolver(settings(n_nodes=10), EV)
    pv = preview(np.array([30.0] + [15.0] * 10), n=10)
    plan = ocp.solve(25.0, 0.0, pv, PARAMS)
    (v,) = plan.violations
    assert v.constraint == "speed_cap" and v.limit == 15.0 and v.unit == "m/s"
    k = int(round(v.position / DS))
    assert v.value == pytest.approx(plan.v[k]) and v.value > 15.0 + 0.1
    assert np.argmax(plan.v[1:] - 15.0) + 1 == k  # the node exceeding the cap most
    assert v.required_decel == pytest.approx((25.0 ** 2 - 15.0 ** 2) / (2 * v.position))
    assert plan.accel[1:4].min() == pytest.approx(-2.0, abs=1e-3)  # still braking as hard as comfort allows
    # two separate stretches give two violations, each with its own worst node
    two = preview(np.array([30.0, 18.0, 30.0, 30.0, 12.0, 30.0, 30.0, 30.0, 30.0, 30.0, 30.0]), n=10)
    kinds = ocp.relaxations(25.0, 0.0, two)
    assert [w.position for w in kinds] == [20.0, 80.0] and [w.limit for w in kinds] == [18.0, 12.0]


def test_a_cap_met_within_the_margin_only_is_a_margin_violation():
    ocp = OcpSolver(settings(n_nodes=10), EV)
    cap = np.full(11, 30.0)
    cap[1:] = 20.0
    plan = ocp.solve(21.8, -2.0, preview(cap, n=10), PARAMS)
    (v,) = plan.violations
    assert v.constraint == "speed_margin" and v.position == 20.0 and v.limit == pytest.approx(19.7)
    assert v.value == pytest.approx(plan.v[1]) and 19.7 < v.value <= 20.0 + 0.1
    assert v.required_decel == pytest.approx((21.8 ** 2 - 19.7 ** 2) / 40.0)
    assert v.detail == "the cap itself (20 m/s) is met within 0.1 m/s"


def test_contradictory_limits_are_named_with_their_values():
    ocp = solver()
    (low,) = ocp.contradictions(5.0, 0.0, preview(np.array([30.0, 0.9, 0.5, 0.7, 30.0, 30.0, 0.8])))
    assert (low.constraint, low.position, low.limit, low.value, low.unit) == ("speed_cap", 40.0, 0.5, 1.0, "m/s")
    assert low.detail == "below the speed floor 1 m/s (the planned speed cannot go lower)"
    assert ocp.contradictions(5.0, 0.0, preview(np.array([0.5] + [1.0] * N))) == []
    # the jerk limit moves the acceleration by 2 * 20 / max(v0, floor) in segment 0
    (jerk,) = ocp.contradictions(20.0, 5.0, preview())
    assert jerk.constraint == "jerk" and jerk.limit == 2.0 and jerk.unit == "m/s^3"
    assert jerk.value == pytest.approx(3.5 * 20.0 / 20.0)
    assert jerk.detail == ("the previous acceleration 5 m/s^2 cannot reach the comfort bounds [-2, 1.5] m/s^2 "
                           "within the first 20 m")
    (brake,) = ocp.contradictions(20.0, -5.0, preview())
    assert brake.value == pytest.approx(3.0 * 20.0 / 20.0)
    assert ocp.contradictions(20.0, 3.5, preview()) == [] == ocp.contradictions(20.0, -4.0, preview())
    assert ocp.contradictions(20.0, 4.0, preview())[0].value == pytest.approx(2.5)  # 0.5 m/s^2 beyond: named
    assert len(ocp.contradictions(0.5, 70.0, preview())) == 1  # step at the floor speed: 2 * 20 / 1 = 40
    plan = ocp.solve(20.0, 5.0, preview(), PARAMS)
    assert not plan.success and plan.violations[0].constraint == "jerk"


def test_more_than_three_violations_are_summarised_in_the_status():
    ocp = OcpSolver(settings(n_nodes=10), EV)
    cap = np.array([30.0, 22.0, 30.0, 16.0, 30.0, 11.0, 30.0, 6.0, 30.0, 0.5, 30.0])
    plan = ocp.solve(25.0, 0.0, preview(cap, n=10), PARAMS)
    assert len(plan.violations) == 5
    assert plan.status.endswith(" (+2 more) [solver: Solve_Succeeded]")
    assert plan.status.count(" at ") == 3


# ------------------------------------------------------------------------------------------------ infeasible
def test_a_climb_beyond_the_drive_names_the_traction_force():
    ocp = solver()
    plan = ocp.solve(5.0, 0.0, preview(30.0, grade=0.6), PARAMS)
    assert plan.feasibility == "infeasible" and plan.status.startswith("infeasible: traction_force")
    v = plan.violations[0]
    k = int(round(v.position / DS))
    vm = max(0.5 * (plan.v[k] + plan.v[k + 1]), 1e-3)
    assert v.unit == "kN" and v.limit == pytest.approx(min(250.0 * 9.665 / 0.35, 125e3 / vm) / 1000.0)
    assert v.value > v.limit
    assert v.detail.startswith(f"at {vm:.3g} m/s on a grade of {100 * math.tan(0.6):.3g} %, the drive cannot")
    assert all(w.constraint in CONSTRAINTS for w in plan.violations)


def test_diagnose_reads_each_violated_block_and_the_brake_limit():
    ocp = OcpSolver(settings(), ICE)
    pv = preview(30.0)
    v = np.full(N + 1, 15.0)
    x = np.concatenate([0.5 * v ** 2, np.zeros(N), np.zeros(N), np.zeros(N)])
    plan = ocp._plan_from_x(x, pv, False, "Infeasible_Problem_Detected", 0.0, 0, 0.0)
    found = ocp.diagnose(plan, 0.0, pv, PARAMS)
    # coasting at constant speed: the balance misses the resistance, a positive residual (traction needed)
    assert [f.constraint for f in found] == ["traction_force"]
    res = float(resistance_force(15.0, 0.0, 0.0, PARAMS)) / 1000.0
    assert found[0].value == pytest.approx(res) and found[0].position == 0.0
    # a steep descent at constant speed with the brakes released: more braking needed than the drive and brakes give
    down = preview(30.0, grade=-0.5)
    x_down = np.concatenate([0.5 * v ** 2, np.zeros(N), np.zeros(N), np.full(N, 2.0)])
    plan = ocp._plan_from_x(x_down, down, False, "x", 0.0, 0, 0.0)
    (brake,) = ocp.diagnose(plan, 0.0, down, PARAMS)
    need = -float(resistance_force(15.0, -0.5, 0.0, PARAMS)) / 1000.0
    assert brake.constraint == "brake_force" and brake.unit == "kN"
    assert brake.limit == pytest.approx(3.0 * 1420.0 / 1000.0) and brake.value == pytest.approx(need)
    assert brake.detail == f"on a grade of {100 * math.tan(-0.5):.3g} %"
    # an acceleration and a jerk beyond their bounds, the larger relative violation first
    w = np.array([15.0, 20.0, 15.0, 15.0, 15.0, 15.0, 15.0])
    xe = np.concatenate([0.5 * w ** 2, np.zeros(3 * N)])
    g = np.asarray(ocp._g_fun(xe, ocp._params(0.0, pv, PARAMS))).ravel()
    dyn = g[:N].copy()
    xe[N + 1:2 * N + 1] = np.clip(dyn, 0, None)  # traction meets the balance where it can
    xe[3 * N + 1:] = np.clip(-dyn, 0, None)
    fx = ocp._plan_from_x(xe, pv, False, "x", 0.0, 0, 0.0)
    found = ocp.diagnose(fx, 0.0, pv, PARAMS)
    # segment 0 accelerates at 4.375 m/s^2 (2.875 over 1.5), segment 1 brakes at 4.375 (2.375 over 2): the
    # worst of the block; the jerk between them, -8.75 m/s^3 against 2, is the larger share of its bound; the
    # traction of segment 0 (the balance's 6.5 kN at 17.5 m/s) is 40 kW above the full-load fit, the largest
    assert [f.constraint for f in found] == ["traction_power", "jerk", "acceleration"]
    power, jerk, acc = found
    assert (power.position, power.limit, power.unit) == (0.0, 0.0, "kW")
    assert power.value == pytest.approx(xe[N + 1] * 17.5 - ICE.traction_power_limit(17.5) / 1000.0)
    assert (acc.position, acc.limit, acc.unit) == (0.0, 1.5, "m/s^2") and acc.value == pytest.approx(4.375)
    assert (jerk.position, jerk.limit, jerk.unit) == (20.0, -2.0, "m/s^3") and jerk.value == pytest.approx(-8.75)


def test_diagnose_without_a_usable_point_names_the_solver():
    ocp = solver()
    pv = preview(30.0)
    nan_plan = ocp._plan_from_x(np.full(4 * N + 1, np.nan), pv, False, "Invalid_Number_Detected", 0.0, 0, 0.0)
    (v,) = ocp.diagnose(nan_plan, 0.0, pv, PARAMS)
    assert v.constraint == "solver" and v.detail == "Invalid_Number_Detected" and math.isnan(v.value)
    assert (v.position, v.limit, v.unit) == (0.0, 0.0, "-")
    ok = ocp.solve(15.0, 0.0, pv, PARAMS)
    ok.solver_status = ""
    ok.status = "Maximum_CpuTime_Exceeded"
    (w,) = ocp.diagnose(ok, 0.0, pv, PARAMS)  # a point that meets every constraint
    assert (w.constraint, w.limit, w.value, w.detail) == ("solver", 0.0, 0.0, "Maximum_CpuTime_Exceeded")
    no_x = Plan(s=pv.s, v=np.ones(N + 1), t=np.zeros(N + 1), traction=np.zeros(N), regen=np.zeros(N),
                brake=np.zeros(N), success=False, status="s", solve_time=0.0, iterations=0, solver_status="gone")
    assert ocp.diagnose(no_x, 0.0, pv, PARAMS)[0].detail == "gone"


def test_reach_at_a_node_past_the_floor_and_inside_a_ramp():
    ocp = OcpSolver(settings(n_nodes=10), EV)
    s = DS * np.arange(11)
    # from 5 m/s at -2 m/s^2 the floor (1 m/s) is reached at node 1: a line on node 2 is reached at the floor
    assert ocp._reach_at(5.0, -2.0, s, 40.0) == 1.0
    # 10 m into segment 1 of the jerk ramp from 20.5 m/s: segment 1's -2 m/s^2, not segment 0's -1.95
    speed, accel = ocp._braking(20.5, 11, 0.0)
    expect = math.sqrt(2 * (0.5 * speed[1] ** 2 - 2.0 * 10.0))
    assert accel[0] == pytest.approx(-40.0 / 20.5) and accel[1] == -2.0
    assert ocp._reach_at(20.5, 0.0, s, 30.0) == pytest.approx(expect, rel=1e-12)
    assert ocp._reach_at(20.5, 0.0, s[:3], 30.0) == pytest.approx(expect, rel=1e-12)  # the last segment


def test_force_limit_of_a_power_limited_drive():
    """At 20 m/s the EV's 125 kW give 6.25 kN, less than its 6.9 kN torque limit; a 3 kW drive at the 1 m/s floor
    gives 3 kN."""
    pv = preview(30.0, grade=0.6)
    for energy, speed, limit in ((EV, 20.0, 125e3 / 20.0), (replace(EV, max_power=3000.0), 1.0, 3000.0)):
        ocp = OcpSolver(settings(), energy)
        x = np.concatenate([np.full(N + 1, 0.5 * speed ** 2), np.full(N, 1.0), np.zeros(2 * N)])
        plan = ocp._plan_from_x(x, pv, False, "x", 0.0, 0, 0.0)
        (v,) = ocp.diagnose(plan, 0.0, pv, PARAMS)
        need = float(resistance_force(speed, 0.6, 0.0, PARAMS)) / 1000.0
        assert v.constraint == "traction_force" and v.limit == pytest.approx(limit / 1000.0, rel=1e-12)
        assert v.value == pytest.approx(need, rel=1e-9)  # the planned 1 kN plus the residual: all the balance needs


def test_initial_guess_brakes_from_node_1_and_keeps_the_current_state():
    ocp = solver()
    cap = np.array([30.0, 30.0, 5.0, 30.0, 30.0, 30.0, 30.0])
    x = ocp.initial_guess(15.0, preview(cap), PARAMS)
    v = np.sqrt(2 * x[:N + 1])
    reach2 = ocp.reachable_cap(15.0, preview(cap))[2]  # 5 m/s is out of reach: the relaxed cap
    assert v[0] == 15.0 and v[2] == pytest.approx(reach2)
    assert v[1] == pytest.approx(math.sqrt(reach2 ** 2 + 40.0))  # backward pass at half decel_max


def test_plan_of_a_standing_car_has_finite_times():
    ocp = solver()
    plan = ocp._plan_from_x(np.zeros(4 * N + 1), preview(), False, "", 0.0, 0, 0.0)
    np.testing.assert_allclose(plan.t, DS / 1e-6 * np.arange(N + 1))


def test_three_violations_are_listed_without_a_summary():
    ocp = OcpSolver(settings(n_nodes=10), EV)
    cap = np.array([30.0, 22.0, 30.0, 16.0, 30.0, 11.0, 30.0, 30.0, 30.0, 30.0, 30.0])
    plan = ocp.solve(25.0, 0.0, preview(cap, n=10), PARAMS)
    assert len(plan.violations) == 3 and "more)" not in plan.status
    assert plan.status == "relaxed: " + "; ".join(v.describe() for v in plan.violations) + \
        " [solver: Solve_Succeeded]"


def test_a_warm_plan_without_multipliers_starts_cold():
    ocp = solver(time_weight=6000.0)
    pv = preview(np.array([30.0, 30.0, 30.0, 16.0, 16.0, 30.0, 30.0]))
    cold = ocp.solve(14.0, 0.0, pv, PARAMS)
    cold.lam_g = None
    again = ocp.solve(14.0, 0.0, pv, PARAMS, warm=cold)
    assert again.iterations == ocp.solve(14.0, 0.0, pv, PARAMS).iterations > 2
    # a QP solver's first solve may start from another solver's plan (no workspace yet)
    qp = solver(time_weight=6000.0, solver="osqp", sqp_iterations=8, qp_tolerance=1e-6)
    cold.lam_g = None
    from_ipopt = qp.solve(14.0, 0.0, pv, PARAMS, warm=cold)
    assert from_ipopt.success
    np.testing.assert_allclose(from_ipopt.v, cold.v, atol=0.02)


def test_brake_force_limit_adds_regeneration_to_the_friction_brake():
    ocp = solver()
    pv = preview(30.0, grade=-0.2)
    x = np.concatenate([np.full(N + 1, 0.5 * 15.0 ** 2), np.zeros(N), np.full(N, 2.0), np.full(N, 3.0)])
    plan = ocp._plan_from_x(x, pv, False, "x", 0.0, 0, 0.0)
    v = ocp._force_limit(plan, 2, -1.5, pv, PARAMS)
    assert (v.constraint, v.position, v.unit) == ("brake_force", 40.0, "kN")
    assert v.limit == pytest.approx((0.8 * G * 1420.0 + 150.0 * 9.665 / 0.35) / 1000.0, rel=1e-3)
    assert v.value == pytest.approx(2.0 + 3.0 + 1.5)  # what the plan brakes plus what the balance still needs


def test_relaxed_nodes_count_node_1_and_start_from_the_previous_acceleration():
    ocp = solver()
    # from 20 m/s node 1 is reached at 17.9 m/s at the earliest: a 17.8 m/s cap (17.5 planned) is 0.5 m/s out of reach
    assert ocp.relaxed_nodes(20.0, preview(np.array([30.0, 17.8] + [30.0] * (N - 1)))) == 1
    # rising at 1.5 m/s^2, the jerk limit leaves 19.5 m/s at node 1: a 19 m/s cap is out of reach only then
    pv = preview(np.array([30.0, 19.0] + [30.0] * (N - 1)))
    assert ocp.relaxed_nodes(20.0, pv, 1.5) == 1 and ocp.relaxed_nodes(20.0, pv, 0.0) == 0


def test_the_qp_path_takes_the_time_weight_of_the_solve():
    ocp = solver(time_weight=0.0, solver="osqp", sqp_iterations=4, qp_tolerance=1e-6)
    lazy = ocp.solve(15.0, 0.0, preview(30.0), PARAMS)
    hurried = ocp.solve(15.0, 0.0, preview(30.0), PARAMS, time_weight=50000.0)
    assert hurried.v[-1] > lazy.v[-1] + 2.0
