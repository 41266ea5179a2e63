"""The MPC never claims a plan it cannot keep: a stop inside the comfort braking distance, a cap below the current
speed and contradictory limits are reported relaxed or infeasible with the constraint and its amount, never as a
success; the closed loop brakes (maximum comfort, then emergency) instead of following such a plan."""

import numpy as np
import pytest

from roadload.controllers.base import ControllerError, DriveContext
from roadload.controllers.closed_loop import VIOLATION_TOLERANCE, run_closed_loop
from roadload.controllers.energy import generic_ev
from roadload.controllers.force_model import FixedForceModel
from roadload.controllers.mpc import CONSTRAINTS, MpcSettings, Preview
from roadload.controllers.mpc_controller import MpcController, MpcControllerSettings, get_solver
from roadload.controllers.plant import ModelPlant
from roadload.road_load import RoadLoadParameters
from roadload.road_profiles import RoadProfile

PARAMS = RoadLoadParameters.from_physical(1420.0, 0.009, 0.0, 0.0, 0.7, 1.2, 60000.0)
ENERGY = generic_ev()
N, DS = 40, 20.0


def preview(cap, grade=0.0, stops=None):
    cap = np.broadcast_to(np.asarray(cap, float), (N + 1,)).copy()
    return Preview(s=DS * np.arange(N + 1), grade=np.full(N, grade), curvature=np.zeros(N), speed_cap=cap,
                   ratio=ENERGY.ratio_for_speed(np.full(N, 15.0)), stops=stops)


@pytest.fixture(scope="module", params=["ipopt", "osqp"])
def ocp(request):
    return get_solver(MpcSettings(n_nodes=N, ds=DS, solver=request.param), ENERGY)


def stop_at(position, speed=30.0):
    cap = np.full(N + 1, speed)
    k = int(position // DS)
    cap[k:k + 2] = 1.0  # the controller's preview: stop_speed on the nodes around the stop line
    return preview(cap, stops=np.array([position]))


def test_a_reachable_stop_is_a_success(ocp):
    """The control case: 25 m/s with a stop 400 m ahead (comfort braking needs 156 m) is planned and met."""
    plan = ocp.solve(25.0, 0.0, stop_at(400.0), PARAMS)
    assert plan.success and plan.feasibility == "feasible" and plan.violations == ()
    assert plan.speed_at(400.0) <= 1.0 + 1e-3


def test_stop_inside_the_comfort_braking_distance_is_not_a_success(ocp):
    """25 m/s with a stop 100 m ahead: braking at decel_max = 2 m/s^2 needs 156 m, so the plan runs the stop."""
    plan = ocp.solve(25.0, 0.0, stop_at(100.0), PARAMS)
    assert plan.converged and not plan.success and plan.feasibility == "relaxed"
    assert plan.status.startswith("relaxed: stop at 100 m"), plan.status
    (v,) = [v for v in plan.violations if v.constraint == "stop"]
    assert v.position == 100.0 and v.limit == 1.0 and v.unit == "m/s"
    # the amount is what the plan really does at the stop: it passes it at > 10 m/s
    assert v.value == pytest.approx(plan.speed_at(100.0), abs=0.2) and v.value > 10.0
    assert v.amount == pytest.approx(v.value - 1.0)
    assert v.required_decel == pytest.approx(25.0 ** 2 / (2 * 100.0))  # 3.1 m/s^2 > the comfort 2 m/s^2
    assert "needs 3.12 m/s^2" in plan.status and "comfort limit 2 m/s^2" in plan.status


def test_cap_below_the_current_speed_is_not_a_success(ocp):
    plan = ocp.solve(25.0, 0.0, preview(15.0), PARAMS)
    assert not plan.success and plan.feasibility == "relaxed" and plan.relaxed_nodes >= 5
    v = plan.violations[0]
    assert v.constraint == "speed_cap" and v.limit == 15.0
    assert v.value == pytest.approx(plan.speed_at(v.position), abs=0.15) and v.value > 15.0 + VIOLATION_TOLERANCE
    # the plan still brakes as hard as comfort allows: it is the best plan under the limits, honestly labelled
    assert plan.accel[1:4].min() == pytest.approx(-2.0, abs=0.05)


def test_cap_met_by_eating_the_margin_is_a_margin_violation():
    """A cap the plan meets only within its 0.3 m/s margin: relaxed on speed_margin, not on the cap itself."""
    ocp = get_solver(MpcSettings(n_nodes=N, ds=DS), ENERGY)
    # from 21.8 m/s braking at 2 m/s^2, node 1 (20 m ahead) is reached at 19.88 m/s: above 20 - 0.3, below 20
    cap = np.full(N + 1, 30.0)
    cap[1:] = 20.0
    plan = ocp.solve(21.8, -2.0, preview(cap), PARAMS)
    assert not plan.success
    assert [v.constraint for v in plan.violations] == ["speed_margin"], plan.status
    assert plan.violations[0].value <= 20.0 + VIOLATION_TOLERANCE


def test_contradictory_limits_are_named(ocp):
    # a posted cap below the speed floor (the spatial plan cannot go slower than 1 m/s)
    plan = ocp.solve(0.8, 0.0, preview(0.5), PARAMS)
    assert not plan.success
    floor = [v for v in plan.violations if "speed floor" in v.detail]
    assert floor and floor[0].constraint == "speed_cap" and floor[0].limit == 0.5 and floor[0].value == 1.0
    # a previous acceleration the jerk limit cannot bring inside the comfort bounds in the first segment
    plan = ocp.solve(20.0, 5.0, preview(30.0), PARAMS)
    assert not plan.success
    jerk = [v for v in plan.violations if v.constraint == "jerk"]
    assert jerk and jerk[0].limit == 2.0 and jerk[0].value == pytest.approx(3.5 * 20.0 / DS)


def test_a_climb_beyond_the_drive_is_infeasible_and_names_the_force_limit():
    """68 % grade: the drive's 6.9 kN cannot hold the speed floor; the solver does not converge and the result
    names the traction force with what the force balance needed."""
    ocp = get_solver(MpcSettings(n_nodes=N, ds=DS), ENERGY)
    plan = ocp.solve(5.0, 0.0, preview(30.0, grade=0.6), PARAMS)
    assert not plan.converged and not plan.success and plan.feasibility == "infeasible"
    assert plan.status.startswith("infeasible: traction_force"), plan.status
    v = plan.violations[0]
    assert v.unit == "kN" and v.value > v.limit > 0
    assert all(v.constraint in CONSTRAINTS for v in plan.violations)


# ------------------------------------------------------------------------------------ the closed loop's fallback
def flat_road(limit_from=None, low=10.0, stops=(), length=800.0):
    s = np.arange(0.0, length + 1, 5.0)
    limit = np.where(s >= limit_from, low, 30.0) if limit_from is not None else np.full_like(s, 30.0)
    z = np.zeros_like(s)
    return RoadProfile("flat", s, z, z, z, limit, stops=np.asarray(stops, float))


def drive(road, v0=25.0, **ctx_kw):
    ctl = MpcController(MpcControllerSettings(mpc=MpcSettings(time_weight=8000.0)))
    ctx = DriveContext(road, ENERGY, FixedForceModel(PARAMS), **ctx_kw)
    return run_closed_loop(ctl, ModelPlant(road, PARAMS, ENERGY, v0=v0), ctx), ctl


def speed_at(log, position):
    return float(np.interp(position, log["s"], log["v"]))


def test_cap_below_the_current_speed_brakes_comfort_then_emergency():
    """25 m/s, 10 m/s limit from 120 m: comfort braking (2 m/s^2) reaches the cap only at 131 m (plus the jerk
    ramp); the controller brakes harder than comfort, within the emergency deceleration, and keeps the limit."""
    road = flat_road(limit_from=120.0)
    res, ctl = drive(road)
    m = res.metrics
    assert m["ctl_relaxed_plans"] >= 1 and m["ctl_fallback_brake"] >= 1 and m["ctl_emergency_brake_steps"] >= 1
    assert m["ctl_worst_violation"].startswith("speed_cap at 100 m"), m["ctl_worst_violation"]
    assert speed_at(res.log, 120.0) <= 10.0 + VIOLATION_TOLERANCE and m["speed_violations"] == 0
    a = res.log["a"].to_numpy()
    assert a.min() < -2.2 and a.min() >= -6.0 - 1e-6  # harder than comfort, never beyond the emergency limit
    assert m["arrived"] and ctl.mode == "mpc"  # back on the plan once the cap is met
    # the same drive with the emergency brake held at the comfort deceleration overshoots the cap: the fallback
    # is what keeps the limit
    soft, _ = drive(road, emergency_decel=2.0)
    assert speed_at(soft.log, 120.0) > 10.0 + 1.0


def test_stop_inside_the_comfort_braking_distance_is_met_by_the_emergency_brake():
    road = flat_road(stops=[100.0])
    res, _ = drive(road)
    m = res.metrics
    assert m["ctl_stops_served"] == 1 and m.get("ctl_stops_missed", 0) == 0
    stopped = res.log[res.log["v"] < 0.05]
    assert abs(float(stopped["s"].iloc[0]) - 100.0) < 2.0  # stands at the line
    a = res.log["a"].to_numpy()
    assert a.min() < -2.5 and a.min() >= -6.0 - 1e-6  # emergency braking, bounded at emergency_decel


def test_emergency_decel_below_comfort_is_refused():
    road = flat_road()
    ctl = MpcController(MpcControllerSettings())
    with pytest.raises(ControllerError, match=r"emergency_decel: must be >= .* decel_max = 2 m/s\^2, got 1.5"):
        ctl.reset(DriveContext(road, ENERGY, FixedForceModel(PARAMS), emergency_decel=1.5))


def test_a_stop_line_within_reach_is_not_run_though_its_grid_node_is_not():
    """20.5 m/s, stop line at 118 m: the node before it (100 m) cannot get under 1 m/s at 2 m/s^2 (4.5 m/s), but the
    line can (braking from here stops the car at 105 m): relaxed on the grid node, no hard stop violation, so the
    closed loop does not brake harder than planned."""
    ocp = get_solver(MpcSettings(n_nodes=N, ds=DS), ENERGY)
    cap = np.full(N + 1, 30.0)
    cap[5:7] = 1.0
    plan = ocp.solve(20.5, 0.0, preview(cap, stops=np.array([118.0])), PARAMS)
    assert not plan.success and [v.constraint for v in plan.violations] == ["stop_node"], plan.status
    assert "the line itself is reached at 0 m/s" in plan.status
