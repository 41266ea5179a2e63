"""The MPC's plan speed at the speed floor, the regeneration-power report and the speed-floor tolerance, checked
against hand-derived values (the mutants of ``controllers/mpc.py`` the fast tests of ``test_mpc_mutants.py`` let
live after the plan-speed change; ``scripts/mutation_score.py --module controllers/mpc.py``)."""

import math

import numpy as np
import pytest

from roadload.controllers.energy import generic_ev
from roadload.controllers.force_model import resistance_force
from roadload.controllers.mpc import MpcSettings, OcpSolver, Plan, Preview
from roadload.road_load import RoadLoadParameters

EV = generic_ev()
PARAMS = RoadLoadParameters.from_physical(1420.0, 0.009, 0.0, 0.0, 0.7, 1.2, 60000.0, headwind=1.5,
                                          rotational_mass=60.0)
N, DS = 6, 20.0


def solver(**kw):
    return OcpSolver(MpcSettings(**{"n_nodes": N, "ds": DS, **kw}), EV)


def preview(cap=20.0):
    cap = np.broadcast_to(np.asarray(cap, float), (N + 1,)).copy()
    return Preview(s=DS * np.arange(N + 1), grade=np.zeros(N), curvature=np.zeros(N), speed_cap=cap,
                   ratio=np.full(N, 9.665))


def test_plan_speed_at_the_stop_speed_is_exact_between_nodes():
    """A plan that crawls at the stop speed (1 m/s, E = 0.5 m^2/s^2) reads 1 m/s between its nodes, and the
    v^2-linear speed leaving it: sqrt((1 + 9) / 2) = sqrt(5) halfway to a node at 3 m/s."""
    plan = Plan(s=np.array([0.0, 10.0, 20.0]), v=np.array([1.0, 1.0, 3.0]), t=np.zeros(3), traction=np.zeros(2),
                regen=np.zeros(2), brake=np.zeros(2), success=True, status="ok", solve_time=0.0, iterations=1)
    assert plan.speed_at(5.0) == pytest.approx(1.0, rel=1e-12)
    assert plan.speed_at(15.0) == pytest.approx(math.sqrt(5.0), rel=1e-12)
    np.testing.assert_allclose(plan.speed_at(np.array([0.0, 10.0, 20.0])), [1.0, 1.0, 3.0], rtol=1e-12)


def test_diagnose_names_regeneration_beyond_its_power_in_kilowatts():
    """A point that regenerates 5 kN at 15 m/s (75 kW) against the drive's 50 kW, the force balance met by
    traction: exactly one violation, the regeneration power, with its numbers and unit."""
    ocp = solver()
    pv = preview(30.0)
    v = np.full(N + 1, 15.0)
    res = float(resistance_force(15.0, 0.0, 0.0, PARAMS)) / 1000.0  # kN at constant speed
    regen = np.zeros(N)
    regen[2] = 5.0
    x = np.concatenate([0.5 * v ** 2, res + regen, regen, np.zeros(N)])
    plan = ocp._plan_from_x(x, pv, False, "Infeasible_Problem_Detected", 0.0, 0, 0.0)
    (found,) = ocp.diagnose(plan, 0.0, pv, PARAMS)
    assert (found.constraint, found.unit, found.position) == ("regen_power", "kW", 40.0)
    assert found.limit == pytest.approx(EV.max_regen_power / 1000.0) and found.value == pytest.approx(75.0)


def test_a_cap_within_a_nanometre_per_second_of_the_floor_is_not_a_contradiction():
    """The speed-floor check allows 1e-9 m/s of rounding: a cap exactly that far below the 1 m/s floor is the
    floor; one 2e-9 m/s below is named."""
    ocp = solver()
    floor = ocp.settings.speed_floor
    assert ocp.contradictions(5.0, 0.0, preview(np.array([30.0] + [floor - 1e-9] * N))) == []
    (low,) = ocp.contradictions(5.0, 0.0, preview(np.array([30.0] + [floor - 2e-9] * N)))
    assert (low.constraint, low.position, low.limit, low.value) == ("speed_cap", DS, floor - 2e-9, floor)


def test_a_car_below_the_cap_that_cannot_stop_accelerating_in_time_needs_no_deceleration():
    """29.9 m/s, accelerating at the 1.5 m/s^2 limit, under a 30 m/s cap on 5 m segments: the jerk limit lets the
    acceleration fall by only 2 * 5 / 29.9 m/s^2 a segment, so the speed peaks at node 4 (30.34 m/s) above the cap.
    The violation is there; from the current speed (below the cap) no deceleration is needed: 0, not negative."""
    ocp = OcpSolver(MpcSettings(n_nodes=N, ds=5.0), EV)
    pv = Preview(s=5.0 * np.arange(N + 1), grade=np.zeros(N), curvature=np.zeros(N), speed_cap=np.full(N + 1, 30.0),
                 ratio=np.full(N, 9.665))
    reach = ocp.braking_reach(29.9, pv, 1.5)
    assert int(np.argmax(reach)) == 4 and reach[4] == pytest.approx(30.3439, abs=1e-4)
    (v,) = ocp.relaxations(29.9, 1.5, pv)
    assert (v.constraint, v.position, v.limit, v.value) == ("speed_cap", 20.0, 30.0, reach[4])
    assert v.required_decel == 0.0


def test_a_relaxed_run_that_reaches_the_last_node_is_reported_there():
    """A 5 m/s cap on the horizon's last node only (120 m ahead), from 25 m/s: comfort braking needs more than
    156 m, so the last node is raised; the run ends at the horizon and is reported at its last node."""
    ocp = solver()
    cap = np.full(N + 1, 30.0)
    cap[-1] = 5.0
    pv = preview(cap)
    reach = ocp.braking_reach(25.0, pv)
    assert reach[-1] > 5.0 + 0.1 and np.all(reach[:-1] <= 30.0 - 0.3)
    (v,) = ocp.relaxations(25.0, 0.0, pv)
    assert (v.constraint, v.position, v.limit, v.value) == ("speed_cap", N * DS, 5.0, reach[-1])
    assert v.required_decel == pytest.approx((25.0 ** 2 - 5.0 ** 2) / (2.0 * N * DS))


# ------------------------------------------------------------------------------------------------ QP path
def qp_solver(**kw):
    return solver(**{"time_weight": 6000.0, "solver": "osqp", "qp_tolerance": 1e-6, **kw})


def hill_preview():
    return preview(np.array([30.0, 30.0, 30.0, 16.0, 16.0, 30.0, 30.0]))


def test_the_qp_tolerance_reaches_osqp_as_absolute_and_relative():
    """OSQP stops when a residual is below eps_abs + eps_rel * scale: a tighter tolerance iterates longer only if
    both are set (with eps_abs left at OSQP's 1e-3 the absolute part dominates and 1e-6 and 1e-8 stop together)."""
    pv = hill_preview()
    iterations = [qp_solver(qp_tolerance=tol).solve(14.0, 0.0, pv, PARAMS).iterations for tol in (1e-3, 1e-6, 1e-8)]
    assert iterations[0] < iterations[1] < iterations[2]


def test_the_previous_plans_multipliers_warm_start_the_qp_duals():
    """Re-solving the same problem from its converged plan: with the plan's multipliers as OSQP's dual start the
    eight SQP rounds take fewer iterations than from the same primal point without them."""
    pv = hill_preview()
    counts = []
    for keep_duals in (True, False):
        ocp = qp_solver(sqp_iterations=8)
        first = ocp.solve(14.0, 0.0, pv, PARAMS)
        assert first.lam_x is not None and first.lam_g is not None
        if not keep_duals:
            first.lam_x = None
        counts.append(ocp.solve(14.0, 0.0, pv, PARAMS, warm=first).iterations)
    assert counts[0] < counts[1]


@pytest.mark.parametrize("v0", [13.5, 14.5])
def test_the_qp_warm_start_is_clipped_into_the_bounds_before_it_is_linearised(v0):
    """A warm plan whose node 0 holds another speed than the car's (14 m/s planned, v0 now): the start is clipped
    to the current state's energy first, so the step is the one from a warm plan that already held it."""
    pv = hill_preview()
    plans = []
    for fix_node0 in (False, True):
        ocp = qp_solver()
        warm = ocp.solve(14.0, 0.0, pv, PARAMS)
        assert warm.x[0] == pytest.approx(0.5 * 14.0 ** 2)
        if fix_node0:
            warm.x = warm.x.copy()
            warm.x[0] = 0.5 * v0 ** 2
        plans.append(ocp.solve(v0, 0.0, pv, PARAMS, warm=warm))
    assert plans[0].v[0] == pytest.approx(v0)
    np.testing.assert_array_equal(plans[0].x, plans[1].x)


def test_braking_reach_over_unequal_segments_uses_each_segments_own_length():
    """From 20 m/s on segments of 5 m then 40 m (a node moved onto a stop line): segment 0 ramps the acceleration
    by 2 * 5 / 20 to -0.5 m/s^2, E = 200 - 2.5 = 197.5; segment 1 would ramp by 2 * 40 / sqrt(395) past the comfort
    limit, so it brakes at -2 m/s^2: E = 197.5 - 80 = 117.5 m^2/s^2."""
    ocp = solver()
    s = np.array([0.0, 5.0, 45.0, 65.0, 85.0, 105.0, 125.0])
    pv = Preview(s=s, grade=np.zeros(N), curvature=np.zeros(N), speed_cap=np.full(N + 1, 30.0),
                 ratio=np.full(N, 9.665), ds=np.diff(s))
    reach = ocp.braking_reach(20.0, pv)
    assert reach[:3] == pytest.approx([20.0, math.sqrt(395.0), math.sqrt(235.0)], rel=1e-12)
