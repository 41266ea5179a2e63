"""The receding-horizon MPC controller step by step on short roads with a short horizon (8-16 segments): settings and
schedule validation, the preview it builds (grid, caps, stops, wind), when it re-plans, the tracking command with
its comfort and jerk limits, the fallback brake's force levels, the fallbacks after a failed solve, the multistart,
the scheduled time weight and the run statistics. Each check is a number derived by hand or a behaviour a bug would
change; fast enough to rerun for every mutant of ``controllers/mpc_controller.py`` (``scripts/mutation_score.py``)."""

import math
import warnings

import numpy as np
import pytest

from roadload.controllers.base import ControllerError, DriveContext, Observation
from roadload.controllers.energy import SourceEnergyModel, generic_ev
from roadload.controllers.force_model import FixedForceModel, OracleForceModel, WindEstimate, road_heading
from roadload.controllers import mpc_controller
from roadload.controllers.mpc import ConstraintViolation, MpcSettings, OcpSolver, Plan
from roadload.controllers.mpc_controller import MpcController, MpcControllerSettings, TripSchedule, get_solver
from roadload.road_load import RoadLoadParameters
from roadload.road_profiles import RoadProfile

EV = generic_ev()
PARAMS = RoadLoadParameters.from_physical(1420.0, 0.009, 0.0, 0.0, 0.7, 1.2, 60000.0)
M = PARAMS.inertial_mass
N, DS = 8, 20.0


def road(length=600.0, limit=20.0, low=None, stops=(), grade=None, curve=None):
    """1 m grid (caps change within a metre); ``low`` = (from, to, speed) lowers the limit on [from, to]."""
    s = np.arange(0.0, length + 1.0)
    lim = np.full_like(s, limit)
    if low is not None:
        lim[(s >= low[0]) & (s <= low[1])] = low[2]
    kappa = np.zeros_like(s)
    if curve is not None:
        kappa[(s >= curve[0]) & (s <= curve[1])] = curve[2]
    theta = np.zeros_like(s) if grade is None else grade(s)
    return RoadProfile("test", s, theta, kappa, np.zeros_like(s), lim, stops=np.asarray(stops, float))


def controller(rd, n=N, force_model=None, energy=EV, mpc=None, dt=0.1, **kw):
    mpc = mpc or {}
    ctl = MpcController(MpcControllerSettings(mpc=MpcSettings(n_nodes=n, ds=DS, time_weight=8000.0, **mpc), **kw))
    ctl.reset(DriveContext(rd, energy, force_model or FixedForceModel(PARAMS), dt=dt))
    return ctl


def obs(t, s, v, a=0.0):
    return Observation(t=t, s=s, v=v, a=a)


# ------------------------------------------------------------------------------------------------ settings
def test_solvers_are_built_once_per_settings_and_powertrain(monkeypatch):
    monkeypatch.setattr(mpc_controller, "_SOLVERS", {})  # an empty cache: the first request builds
    a = get_solver(MpcSettings(n_nodes=N, ds=DS), EV)
    assert isinstance(a, OcpSolver) and a.n == N and len(mpc_controller._SOLVERS) == 1
    assert get_solver(MpcSettings(n_nodes=N, ds=DS), generic_ev()) is a
    assert get_solver(MpcSettings(n_nodes=N, ds=25.0), EV) is not a
    assert get_solver(MpcSettings(n_nodes=N, ds=DS), generic_ev(mass=1800.0)) is a  # same powertrain values
    assert a.settings == MpcSettings(n_nodes=N, ds=DS) and a.energy == EV


@pytest.mark.parametrize("name", ["start", "end", "duration", "gain", "integral_gain", "time_floor",
                                  "max_log_change"])
@pytest.mark.parametrize("bad", [float("nan"), float("inf"), "10"])
def test_schedule_refuses_a_non_number(name, bad):
    kw = {"start": 0.0, "end": 100.0, "duration": 10.0, name: bad}
    with pytest.raises(ControllerError, match=rf"^TripSchedule.{name}: must be a finite number, got "):
        TripSchedule(**kw)


@pytest.mark.parametrize("kw, message", [
    ({"start": -1.0}, r"^TripSchedule: need 0 <= start < end \[m\], got start=-1.0, end=100.0$"),
    ({"start": 100.0}, r"got start=100.0, end=100.0$"),
    ({"duration": 0.0}, r"^TripSchedule: duration and time_floor must be > 0 \[s\], gain and max_log_change >= 0, "
                        r"got 0.0, 30.0, 20.0, 4.0$"),
    ({"time_floor": 0.0}, r"got 10.0, 0.0, 20.0, 4.0$"),
    ({"gain": -1.0}, r"got 10.0, 30.0, -1.0, 4.0$"),
    ({"max_log_change": -0.5}, r"got 10.0, 30.0, 20.0, -0.5$"),
    ({"integral_gain": -0.01}, r"duration and time_floor"),
    ({"shape_s": (0.0, 50.0)}, r"^TripSchedule.shape_s / shape_fraction: equal lengths"),
    ({"shape_s": (0.0, 50.0, 50.0), "shape_fraction": (0.0, 0.5, 1.0)}, r"strictly increasing"),
    ({"shape_s": (0.0, 60.0, 50.0), "shape_fraction": (0.0, 0.5, 1.0)}, r"strictly increasing"),
    ({"shape_s": (0.0, 50.0, 100.0), "shape_fraction": (0.0, 0.6, 0.5)}, r"fractions non-decreasing"),
])
def test_schedule_refuses_each_bad_value(kw, message):
    with pytest.raises(ControllerError, match=message):
        TripSchedule(**{"start": 0.0, "end": 100.0, "duration": 10.0, **kw})


def test_schedule_fraction_lateness_and_time_weight():
    ok = TripSchedule(start=0.0, end=1.0, duration=1.0, gain=0.0, integral_gain=0.0, max_log_change=0.0,
                      shape_s=(0.0, 0.5, 1.0), shape_fraction=(0.0, 0.5, 0.5))
    assert ok.time_weight(100.0, 5.0, 0.5, 0.0, 3.0) == 100.0  # no gain, no change
    lin = TripSchedule(start=100.0, end=300.0, duration=100.0)
    assert [lin.fraction(x) for x in (50.0, 100.0, 150.0, 300.0, 400.0)] == [0.0, 0.0, 0.25, 1.0, 1.0]
    assert lin.lateness(60.0, 200.0, 5.0) == 60.0 - (5.0 + 50.0)
    shaped = TripSchedule(start=100.0, end=300.0, duration=100.0, shape_s=(100.0, 150.0, 300.0),
                          shape_fraction=(-0.2, 0.8, 1.5))
    assert shaped.fraction(125.0) == pytest.approx(0.3)
    assert shaped.fraction(100.0) == 0.0 and shaped.fraction(290.0) == 1.0 and shaped.fraction(90.0) == 0.0
    sched = TripSchedule(start=0.0, end=1000.0, duration=100.0, gain=20.0, time_floor=30.0)
    # half way, 2 s late: 20 * 2 / 50 s left
    assert sched.time_weight(1000.0, 52.0, 500.0, 0.0) == pytest.approx(1000.0 * math.exp(0.8))
    # near the end the time left is floored at 30 s: 20 * 5 / 30
    assert sched.time_weight(1000.0, 95.0, 900.0, 0.0) == pytest.approx(1000.0 * math.exp(20 * 5 / 30))
    assert sched.time_weight(1000.0, 45.0, 500.0, 0.0) == pytest.approx(1000.0 * math.exp(-2.0))
    assert sched.time_weight(1000.0, 500.0, 500.0, 0.0) == pytest.approx(1000.0 * math.exp(4.0))
    assert sched.time_weight(1000.0, 0.0, 500.0, 0.0) == pytest.approx(1000.0 * math.exp(-4.0))
    pi = TripSchedule(start=0.0, end=1000.0, duration=100.0, gain=20.0, integral_gain=0.01)
    assert pi.time_weight(1000.0, 52.0, 500.0, 0.0, 50.0) == pytest.approx(1000.0 * math.exp(0.8 + 0.5))


@pytest.mark.parametrize("name", ["replan_period", "speed_gain", "lookahead_time", "plan_tolerance",
                                  "min_plan_left", "multistart_period", "multistart_step", "gear_band",
                                  "gear_min_speed"])
def test_controller_settings_refuse_negative_values(name):
    with pytest.raises(ControllerError, match=rf"^MpcControllerSettings.{name}: must be a finite number >= 0, "
                                              rf"got -1.0$"):
        MpcControllerSettings(**{name: -1.0})
    if name != "replan_period":
        assert getattr(MpcControllerSettings(**{name: 0.0}), name) == 0.0


def test_controller_settings_refuse_a_zero_replan_period():
    with pytest.raises(ControllerError, match=r"^MpcControllerSettings.replan_period: must be > 0 \[s\], got 0.0$"):
        MpcControllerSettings(replan_period=0.0)
    with pytest.raises(ControllerError, match=r"speed_gain"):
        MpcControllerSettings(speed_gain=float("nan"))


def test_reset_checks_the_emergency_deceleration_and_starts_clean():
    rd = road(stops=(450.0, 150.0))
    ctl = MpcController(MpcControllerSettings(mpc=MpcSettings(n_nodes=N, ds=DS)))
    with pytest.raises(ControllerError, match=r"^DriveContext.emergency_decel: must be >= the MPC's comfort "
                                              r"deceleration decel_max = 2 m/s\^2, got 1.9$"):
        ctl.reset(DriveContext(rd, EV, FixedForceModel(PARAMS), emergency_decel=1.9))
    ctl.reset(DriveContext(rd, EV, FixedForceModel(PARAMS), emergency_decel=2.0))
    assert ctl.plan is None and ctl.mode == "mpc" and ctl.solve_times == [] and ctl.iterations == []
    assert ctl._unserved == [150.0, 450.0] and ctl.ocp is get_solver(ctl.settings.mpc, EV)
    assert ctl._fine_s[0] == 0.0 and ctl._fine_s[1] == 2.0 and ctl._fine_s[-1] == 600.0 + 160.0 + 38.0
    assert ctl._fine_cap[-1] == 20.0 and ctl.time_weights == [] and ctl.stats()["worst_violation"] == ""


# ------------------------------------------------------------------------------------------------ preview
def test_preview_grid_caps_and_stops():
    rd = road(limit=20.0, low=(200.0, 260.0, 10.0), stops=(300.0, 30.0), grade=lambda s: 1e-4 * s,
              curve=(100.0, 140.0, 0.02))
    ctl = controller(rd, n=16)
    pv = ctl.preview(37.0, 15.0)
    grid = 37.0 + 20.0 * np.arange(17)
    grid[13] = 300.0  # the node nearest to the stop at 300 m (297 m) sits on its line
    np.testing.assert_allclose(pv.s, grid)
    np.testing.assert_allclose(pv.ds, np.diff(grid))
    np.testing.assert_allclose(pv.grade, 1e-4 * 0.5 * (grid[1:] + grid[:-1]))  # at each segment's midpoint
    np.testing.assert_allclose(pv.curvature[[2, 3, 4, 5]], [0.0, 0.02, 0.02, 0.0])  # midpoints 97, 117, 137, 157
    # each node: the lowest cap within one segment either side (curve cap sqrt(2 / 0.02) = 10 m/s on 100..140)
    cap = pv.speed_cap
    np.testing.assert_allclose(cap[:8], [20.0, 20.0, 20.0, 10.0, 10.0, 10.0, 10.0, 20.0])  # 37 ... 177 m
    np.testing.assert_allclose(cap[[8, 11, 12]], [10.0, 10.0, 10.0])  # 197 | 257, 277 (the 10 m/s to 260 m)
    # the stop at 300 m caps its own node at stop_speed, not the next one; the one behind is not in view
    np.testing.assert_allclose(cap[[13, 14, 15]], [1.0, 20.0, 20.0])
    np.testing.assert_array_equal(pv.stops, [300.0])
    np.testing.assert_allclose(pv.ratio, 9.665)
    assert pv.headwind is None and pv.crosswind is None and pv.yaw_drag_factor == 0.0
    # inside segment 0 the cap is sampled every 2 m (39..57 m: the limit)
    np.testing.assert_allclose(pv.segment0_cap, 20.0)
    near = ctl.preview(85.0, 15.0)
    # 87..105 m: 99 m lies between the 2 m grid's 98 m (20) and 100 m (10 m/s in the curve)
    np.testing.assert_allclose(near.segment0_cap, [20.0, 20.0, 20.0, 20.0, 20.0, 20.0, 15.0, 10.0, 10.0, 10.0])


def test_preview_of_a_stop_at_and_just_behind_the_start():
    rd = road(stops=(40.0, 300.0))
    ctl = controller(rd)
    pv = ctl.preview(30.0, 10.0)  # the line 10 m ahead, inside segment 0: nodes 0 and 1 at stop_speed
    np.testing.assert_allclose(pv.speed_cap[:3], [1.0, 1.0, 20.0])
    np.testing.assert_allclose(pv.segment0_cap, [20.0] * 4 + [1.0] * 6)  # from 40 m on
    np.testing.assert_array_equal(pv.stops, [40.0])
    behind = ctl.preview(40.9, 0.5)  # standing 0.9 m past the line: node 0 still capped
    np.testing.assert_allclose(behind.speed_cap[:2], [1.0, 20.0])
    np.testing.assert_allclose(behind.segment0_cap, 1.0)
    assert list(ctl.preview(41.5, 5.0).stops) == []  # 1.5 m past: no longer in view
    assert list(ctl.preview(40.0 - 160.0, 5.0).stops) == [40.0]  # exactly at the horizon end
    assert list(ctl.preview(40.0 - 161.0, 5.0).stops) == []


def test_preview_stop_edges():
    ctl = controller(road(stops=(40.0, 300.0)))
    # exactly 1 m past the line: still in view (node 0 and segment 0 capped); 2 m past: gone
    on = ctl.preview(41.0, 0.5)
    assert list(on.stops) == [40.0] and on.speed_cap[0] == 1.0
    np.testing.assert_allclose(on.segment0_cap, 1.0)
    off = ctl.preview(42.0, 0.5)
    assert list(off.stops) == [] and off.speed_cap[0] == 20.0
    np.testing.assert_allclose(off.segment0_cap, 20.0)
    assert list(ctl.preview(39.5, 3.0).stops) == [40.0]  # half a metre before it
    # the line exactly at the end of segment 0: node 1 sits on it and alone carries the stop speed
    at_node = ctl.preview(20.0, 10.0)
    np.testing.assert_allclose(at_node.segment0_cap, 20.0)
    np.testing.assert_allclose(at_node.speed_cap[:3], [20.0, 1.0, 20.0])
    # samples of segment 0 half a metre before the line are not capped (33.5, ..., 39.5 | 41.5, ... m)
    np.testing.assert_allclose(ctl.preview(31.5, 10.0).segment0_cap, [20.0] * 4 + [1.0] * 6)
    # the line exactly at the horizon end caps the last node; inside the last segment the last two
    horizon = ctl.preview(40.0 - 160.0, 10.0)
    assert horizon.speed_cap[-1] == 1.0 and horizon.speed_cap[-2] == 20.0
    # 10 m before the horizon end: the last node moves back onto the line (a 10 m last segment), only it capped
    inside = ctl.preview(40.0 - 150.0, 10.0)
    np.testing.assert_allclose(inside.speed_cap[-3:], [20.0, 20.0, 1.0])
    assert inside.s[-1] == 40.0 and inside.ds[-1] == 10.0


def test_preview_to_the_route_end_collapses_the_nodes_past_it():
    rd = road(length=100.0, grade=lambda s: 1e-3 * s)
    ctl = controller(rd, mpc={"horizon_to_route_end": True})
    pv = ctl.preview(30.0, 10.0)
    np.testing.assert_allclose(pv.s[:4], [30.0, 50.0, 70.0, 90.0])
    np.testing.assert_allclose(pv.s[4:], 100.0 + 1e-3 * np.arange(1, 6))
    np.testing.assert_allclose(pv.ds, np.diff(pv.s))
    # grade at each segment's midpoint: 90 -> 100.001 m has its middle at 95.0005 m, the collapsed ones at the end
    np.testing.assert_allclose(pv.grade, 1e-3 * np.array([40.0, 60.0, 80.0, 95.0005, 100.0, 100.0, 100.0, 100.0]))
    on_node = ctl.preview(20.0, 10.0)  # a node exactly at the road end stays there
    np.testing.assert_allclose(on_node.s[3:6], [80.0, 100.0, 100.001])
    last = controller(road(length=150.0), mpc={"horizon_to_route_end": True}).preview(0.0, 10.0)
    assert last.s[-2] == 140.0 and last.s[-1] == pytest.approx(150.001)  # only the last node is beyond
    ends = controller(road(length=160.0), mpc={"horizon_to_route_end": True}).preview(0.0, 10.0)
    assert ends.ds is None and ends.s[-1] == 160.0  # the horizon ends exactly at the road end
    open_end = controller(rd).preview(30.0, 10.0)
    assert open_end.ds is None and open_end.s[-1] == 190.0
    inside = controller(road(length=400.0), mpc={"horizon_to_route_end": True}).preview(0.0, 10.0)
    assert inside.ds is None and inside.s[-1] == 160.0  # the horizon ends before the road does: uniform


def test_preview_with_a_wind_vector_and_an_ice():
    rd = road(curve=(0.0, 600.0, 0.001))
    wind = WindEstimate(speed=5.0, direction=math.pi, yaw_drag_factor=0.7)
    ctl = controller(rd, force_model=OracleForceModel(lambda: PARAMS, wind=lambda: wind))
    pv = ctl.preview(37.0, 15.0)
    head, cross = wind.components(road_heading(rd, 47.0 + 20.0 * np.arange(N)))
    np.testing.assert_allclose(pv.headwind, head) and np.testing.assert_allclose(pv.crosswind, cross)
    assert pv.yaw_drag_factor == 0.7 and pv.headwind[0] > 4.0 and abs(pv.crosswind[-1]) > 0.1
    still = controller(rd, force_model=OracleForceModel(lambda: PARAMS)).preview(37.0, 15.0)
    assert still.headwind is None and still.yaw_drag_factor == 0.0
    ice = SourceEnergyModel(kind="ice", wheel_radius=0.5, gear_ratios=(20.0, 10.0, 5.0), shift_speeds=(5.0, 12.0),
                            loss=(2000.0, 1.0, 0.01, 0.02, 0.0), max_power=150e3, max_torque=800.0,
                            indicated_efficiency=0.4)
    np.testing.assert_allclose(controller(rd, energy=ice).preview(37.0, 15.0).ratio, 20.0)  # the lowest gear


# ------------------------------------------------------------------------------------------------ tracking
def test_first_command_follows_the_plan_with_speed_feedback_and_lookahead():
    ctl = controller(road(), speed_gain=0.5, lookahead_time=3.5)
    o = obs(0.0, 0.0, 12.0)
    force = ctl.wheel_force(o)
    plan = ctl.plan
    assert plan is not None and ctl.mode == "mpc" and ctl.stats()["solves"] == 1
    k = plan.segment_at(42.0)  # 3.5 s ahead at 12 m/s: segment 2 (the plan eases off its 1.5 m/s^2 there)
    assert k == 2 and plan.wheel_force[2] < plan.wheel_force[1] - 300.0
    assert force == pytest.approx(plan.wheel_force[2] + M * 0.5 * (plan.speed_at(0.0) - 12.0))
    assert ctl.reference_speed(o) == plan.speed_at(0.0)
    assert controller(road()).reference_speed(obs(0.0, 0.0, 7.0)) == 7.0  # no plan yet: the measured speed
    # between re-plans the plan is tracked: 1.5 m/s below the plan's speed adds m k_v 1.5, jerk-limited
    o2 = obs(0.1, 1.2, plan.speed_at(1.2) - 1.5)
    f2 = ctl.wheel_force(o2)
    assert ctl.stats()["solves"] == 1
    step = M * 2.0 * 0.1
    assert f2 == pytest.approx(force + step)  # the feedback asks for 1065 N more than one step allows
    f3 = ctl.wheel_force(obs(0.2, 2.4, plan.speed_at(2.4) + 0.1))
    assert f3 == pytest.approx(f2 - step)


def test_command_stays_within_the_comfort_bounds():
    ctl = controller(road(), mpc={"jerk_max": 500.0}, speed_gain=20.0)
    ctl.wheel_force(obs(0.0, 0.0, 12.0))
    res = ctl.resistance(6.0, 1.2)
    assert ctl.wheel_force(obs(0.1, 1.2, 6.0)) == pytest.approx(res + M * 1.5)
    res = ctl.resistance(19.0, 2.4)
    assert ctl.wheel_force(obs(0.2, 2.4, 19.0)) == pytest.approx(res - M * 2.0)


def test_replans_every_period_when_stale_and_without_a_plan():
    ctl = controller(road(), replan_period=0.5)
    for t, s in ((0.0, 0.0), (0.2, 2.4), (0.49, 6.0), (0.5, 6.1), (0.9, 11.0), (1.0, 12.0)):
        ctl.wheel_force(obs(t, s, 12.0))
    assert ctl.stats()["solves"] == 3  # at 0, 0.5 and 1.0 s
    assert ctl.solve_times[-1] == ctl.plan.solve_time and len(ctl.solve_times) == 3
    for at in (float(ctl.plan.s[3]), float(ctl.plan.s[-3]) + 1.0, float(ctl.plan.s[-2])):
        ctl.wheel_force(obs(1.05, at, 12.0))  # on the plan up to its last segment's start: no new solve
    assert ctl.stats()["solves"] == 3
    stale_at = float(ctl.plan.s[-2]) + 0.5
    ctl.wheel_force(obs(1.1, stale_at, 12.0))  # past the plan's last segment start: a new plan now
    assert ctl.stats()["solves"] == 4 and ctl.plan.s[0] == stale_at
    ctl.wheel_force(obs(1.2, stale_at + 1.0, 12.0))
    assert ctl.stats()["solves"] == 4
    ctl.plan = None  # without a plan in mpc mode it solves whatever the clock
    ctl.wheel_force(obs(1.3, stale_at + 2.0, 12.0))
    assert ctl.stats()["solves"] == 5


def test_the_new_plan_starts_from_the_acceleration_of_the_current_one():
    ctl = controller(road())
    ctl.wheel_force(obs(0.0, 0.0, 8.0))
    plan = ctl.plan
    mid = 0.5 * (plan.s[1:] + plan.s[:-1])
    assert np.ptp(plan.accel) > 0.5  # accelerates, then eases off
    for x in np.linspace(0.0, float(plan.s[-1]), 17):  # between the segment midpoints
        assert ctl._current_accel(obs(0.5, x, 8.0, a=-3.0)) == pytest.approx(np.interp(x, mid, plan.accel))
    assert ctl._current_accel(obs(0.5, plan.s[0], 8.0, a=-3.0)) == pytest.approx(plan.accel[0])
    assert ctl._current_accel(obs(0.5, plan.s[-1], 8.0, a=-3.0)) == pytest.approx(plan.accel[-1])
    # outside the plan: the measured acceleration clipped to the comfort bounds
    assert ctl._current_accel(obs(0.5, plan.s[-1] + 1.0, 8.0, a=-3.0)) == -2.0
    assert ctl._current_accel(obs(0.5, plan.s[0] - 1.0, 8.0, a=3.0)) == 1.5
    ctl.plan = None
    assert ctl._current_accel(obs(0.5, 25.0, 8.0, a=0.7)) == 0.7
    seen = []
    real = ctl.ocp.solve

    def spy(v0, a_prev, *args, **kw):
        seen.append((v0, a_prev, kw.get("time_weight")))
        return real(v0, a_prev, *args, **kw)
    ctl.ocp = type("Spy", (), {"solve": staticmethod(spy)})()
    ctl.wheel_force(obs(0.6, 30.0, 9.0, a=5.0))
    assert seen == [(9.0, 1.5, 8000.0)]


# ------------------------------------------------------------------------------------------------ fallback brake
def test_a_cap_reachable_only_at_full_comfort_braking_gets_the_comfort_brake():
    """20 m/s rising at 1.5 m/s^2, 10 m/s limit from 100 m: the jerk ramp leaves 11.8 m/s at the node before it
    (80 m), so the plan is relaxed there; braking at a constant 300 / 160 = 1.875 m/s^2 from here meets it."""
    ctl = controller(road(low=(100.0, 600.0, 10.0)))
    o = obs(0.0, 0.0, 20.0, a=1.5)
    force = ctl.wheel_force(o)
    target = ctl._brake_target
    assert target is not None and (target.constraint, target.position, target.limit) == ("speed_cap", 80.0, 10.0)
    assert ctl.mode == "brake" and ctl.plan is not None
    st = ctl.stats()
    assert (st["fallback_brake"], st["comfort_brake_steps"], st["relaxed_plans"], st["fallbacks"]) == (1, 1, 1, 1)
    assert st.get("emergency_brake_steps", 0) == 0 and st["worst_violation"].startswith("speed_cap at 80 m")
    assert force == pytest.approx(ctl.resistance(20.0, 0.0) - M * 2.0)
    # braking re-plans every step, whatever the period
    ctl.wheel_force(obs(0.1, 2.0, 19.8, a=-2.0))
    assert ctl.stats()["solves"] == 2 and ctl.mode == "mpc"  # from -2 m/s^2 the cap is within the plan's reach
    assert ctl._brake_target is None
    # the comfort brake is ramped from the previous command at the jerk limit
    ramp = controller(road(low=(100.0, 600.0, 10.0)))
    ramp._last_force = 0.0
    assert ramp.wheel_force(o) == pytest.approx(-M * 2.0 * 0.1) and ramp.mode == "brake"


def test_a_cap_beyond_comfort_braking_gets_the_emergency_brake_without_the_jerk_limit():
    ctl = controller(road(low=(60.0, 600.0, 10.0)))
    f0 = ctl.wheel_force(obs(0.0, 0.0, 20.0, a=0.0))
    target = ctl._brake_target
    assert (target.constraint, target.limit) == ("speed_cap", 10.0)
    required = (400.0 - 100.0) / (2.0 * target.position)
    assert required > 2.0 and ctl.mode == "emergency"
    assert f0 == pytest.approx(ctl.resistance(20.0, 0.0) - M * required)
    assert ctl.stats()["emergency_brake_steps"] == 1 and ctl._last_force == f0  # the next command ramps from it
    # capped at the context's emergency deceleration (6 m/s^2), and not ramped from the previous command
    f1 = ctl.wheel_force(obs(0.1, 2.0, 25.0, a=-3.0))
    t1 = ctl._brake_target
    need = (625.0 - 100.0) / (2.0 * (t1.position - 2.0))
    assert need > 6.0 and f1 == pytest.approx(ctl.resistance(25.0, 2.0) - M * 6.0)
    assert ctl.stats()["emergency_brake_steps"] == 2 and ctl.stats()["fallback_brake"] == 2
    assert ctl.stats()["relaxed_plans"] == 2


def test_a_stop_out_of_reach_is_braked_for_to_standstill_at_the_line():
    ctl = controller(road(stops=(90.0,)))
    force = ctl.wheel_force(obs(0.0, 0.0, 20.0))
    target = ctl._brake_target
    assert target.constraint == "stop" and target.position == 90.0
    assert ctl.mode == "emergency"
    assert force == pytest.approx(ctl.resistance(20.0, 0.0) - M * 400.0 / (2 * 90.0))  # v_lim = 0 at a line


def test_the_fallback_brake_ends_when_its_target_is_met_or_passed(monkeypatch):
    ctl = controller(road())
    ctl.wheel_force(obs(0.0, 0.0, 12.0))
    monkeypatch.setattr(ctl, "_replan", lambda o: None)  # noqa: ARG005  # only the brake's own exit is looked at here
    cap = ConstraintViolation("speed_cap", 100.0, 10.0, 12.0, "m/s")
    res = ctl.resistance(12.0, 10.0)
    ctl._brake_target, ctl.mode = cap, "brake"
    assert ctl._fallback_brake(obs(0.1, 10.0, 12.0), res, M) == pytest.approx(res - M * 2.0)  # 0.24 m/s^2 needed
    for o in (obs(0.1, 10.0, 10.0), obs(0.1, 100.0, 12.0), obs(0.1, 101.0, 12.0)):  # met, reached, passed
        assert ctl._fallback_brake(o, res, M) is None
    ctl._last_force = None
    force = ctl.wheel_force(obs(0.2, 50.0, 9.0))
    assert ctl.mode == "mpc" and ctl._brake_target is None and ctl._next_replan == -np.inf
    raw = ctl.plan.wheel_force[ctl.plan.segment_at(50.0 + 9.0 * 0.3)] + M * (ctl.plan.speed_at(50.0) - 9.0)
    assert force == pytest.approx(min(raw, ctl.resistance(9.0, 50.0) + M * 1.5)) and raw > force  # comfort bound
    ctl._brake_target, ctl.mode, ctl.plan = cap, "emergency", None
    ctl.cruise.v_ref, ctl.cruise.integral = 15.0, 0.5  # a cruise-control state from long ago
    ctl.wheel_force(obs(0.3, 60.0, 9.0))
    assert ctl.mode == "cruise" and ctl._brake_target is None
    assert ctl.cruise.v_ref < 9.5 and abs(ctl.cruise.integral) < 0.1  # restarted from the current 9 m/s
    assert ctl._fallback_brake(obs(0.3, 60.0, 9.0), res, M) is None  # no target


def test_brake_target_is_the_stop_or_cap_needing_the_hardest_braking():
    def viol(kind, pos, limit, value):
        return ConstraintViolation(kind, pos, limit, value, "m/s")
    plan = Plan(s=np.zeros(2), v=np.zeros(2), t=np.zeros(2), traction=np.zeros(1), regen=np.zeros(1),
                brake=np.zeros(1), success=False, status="", solve_time=0.0, iterations=0)
    o = obs(0.0, 10.0, 20.0)
    plan.violations = (viol("speed_margin", 50.0, 5.0, 9.0), viol("speed_cap", 5.0, 5.0, 9.0),
                       viol("speed_cap", 60.0, 25.0, 26.0), viol("speed_cap", 70.0, 8.0, 8.0),
                       viol("jerk", 30.0, 2.0, 3.0))
    plan.violations += (viol("speed_cap", 10.0, 5.0, 9.0), viol("stop", 90.0, 20.0, 25.0))  # here; at this speed
    assert MpcController._brake_target_of(plan, o) is None  # margin only, behind, above the speed, met, not a cap
    a, b = viol("speed_cap", 110.0, 10.0, 15.0), viol("stop", 210.0, 1.0, 9.0)
    plan.violations += (a, b)
    # 300 / 200 = 1.5 m/s^2 for the cap against 399 / 400 for the stop's cap value
    assert MpcController._brake_target_of(plan, o) is a
    c = viol("speed_cap", 60.0, 12.0, 14.0)  # 256 / 100 = 2.56 m/s^2
    plan.violations += (c,)
    assert MpcController._brake_target_of(plan, o) is c
    # at 11 m/s the 12 m/s cap is met; the stop (120 / 400) needs more than the 10 m/s cap (21 / 200)
    assert MpcController._brake_target_of(plan, obs(0.0, 10.0, 11.0)) is b
    # far along the road: a cap 10 m ahead (76 / 20) needs more than a stop 200 m ahead (399 / 400)
    near, far = viol("speed_cap", 1010.0, 18.0, 19.0), viol("stop", 1200.0, 1.0, 5.0)
    plan.violations = (far, near)
    assert MpcController._brake_target_of(plan, obs(0.0, 1000.0, 20.0)) is near


def test_worst_violation_prefers_stops_and_caps_by_amount():
    ctl = controller(road())
    margin = ConstraintViolation("speed_margin", 10.0, 9.7, 9.9, "m/s")
    small = ConstraintViolation("speed_cap", 20.0, 10.0, 10.5, "m/s")
    large = ConstraintViolation("stop", 30.0, 1.0, 6.0, "m/s")
    ctl._record_worst((margin,))
    assert ctl._worst is margin
    ctl._record_worst((ConstraintViolation("jerk", 0.0, 2.0, 9.0, "m/s^3"),))
    assert ctl._worst is margin  # a first entry stays until a stop or a cap comes
    ctl._record_worst((small,))
    assert ctl._worst is small
    ctl._record_worst((margin, large))
    assert ctl._worst is large
    ctl._record_worst((small,))
    assert ctl._worst is large
    assert ctl.stats()["worst_violation"] == large.describe()


# ------------------------------------------------------------------------------------------------ failed solves
def test_a_crashing_solver_falls_back_to_the_shifted_plan_then_cruise(monkeypatch):
    ctl = controller(road(), min_plan_left=100.0, plan_tolerance=1.0)
    f0 = ctl.wheel_force(obs(0.0, 0.0, 12.0))
    plan = ctl.plan

    def crash(*args, **kw):
        raise RuntimeError("solver crashed")
    monkeypatch.setattr(ctl.ocp, "solve", crash)
    v = float(plan.speed_at(60.0))
    force = ctl.wheel_force(obs(1.0, 60.0, v - 1.0))  # 100 m of plan left, 1 m/s off it: still usable
    st = ctl.stats()
    assert (st["solver_exception"], st["solver_failures"], st["fallback_shifted_plan"]) == (1, 1, 1)
    assert ctl.mode == "shifted" and ctl.plan is plan and ctl.last_error == "RuntimeError('solver crashed')"
    assert st["solves"] == 2 and st["fallbacks"] == 1 and math.isfinite(st["solve_time_median"])
    raw = plan.wheel_force[plan.segment_at(60.0 + (v - 1.0) * 0.3)] + M * 1.0  # the old plan, 1 m/s feedback
    raw = min(raw, ctl.resistance(v - 1.0, 60.0) + M * 1.5)
    assert force == pytest.approx(float(np.clip(raw, f0 - M * 0.2, f0 + M * 0.2)))
    ctl.wheel_force(obs(2.0, 61.0, v))  # 99 m left: too little
    assert ctl.mode == "cruise" and ctl.plan is None and ctl.stats()["fallback_cruise"] == 1
    ctl.wheel_force(obs(3.0, 62.0, v))
    assert ctl.stats()["fallback_cruise"] == 2 and ctl.mode == "cruise"
    assert ctl.stats()["solver_exception"] == 3 and 0.0 <= ctl.solve_times[-1] < 60.0  # the wall time of the try
    monkeypatch.undo()
    ctl.wheel_force(obs(4.0, 63.0, v))  # the solver works again: back on a plan
    assert ctl.mode == "mpc" and ctl.plan is not None and ctl.plan.s[0] == 63.0


@pytest.mark.parametrize("s, dv, usable", [(0.0, 0.0, True), (-1.0, 0.0, False), (30.0, 2.0, True),
                                           (30.0, 2.01, False), (30.0, -2.01, False), (61.0, 0.0, False)])
def test_shifted_plan_usable_only_on_it_near_its_speed_with_enough_left(s, dv, usable):
    ctl = controller(road(), min_plan_left=100.0)
    ctl.wheel_force(obs(0.0, 0.0, 12.0))
    plan = ctl.plan
    ctl._fall_back(obs(1.0, s, float(plan.speed_at(s)) + dv))
    assert ctl.mode == ("shifted" if usable else "cruise")
    assert (ctl.plan is plan) == usable


def unconverged_solves(monkeypatch, ctl, violation):
    """From now on every solve of ``ctl`` reports no convergence with ``violation`` (its plan otherwise real)."""
    real = ctl.ocp.solve

    def unconverged(*args, **kw):
        plan = real(*args, **kw)
        plan.converged = plan.success = False
        plan.violations = (violation,)
        plan.traction[:] = 1e5
        return plan
    monkeypatch.setattr(ctl.ocp, "solve", unconverged)


def test_an_unconverged_plan_is_counted_and_never_applied(monkeypatch):
    ctl = controller(road(), min_plan_left=100.0)
    ctl.wheel_force(obs(0.0, 0.0, 12.0))
    good = ctl.plan
    unconverged_solves(monkeypatch, ctl, ConstraintViolation("dynamics", 0.0, 0.0, 1.0, "kN"))
    force = ctl.wheel_force(obs(1.0, 12.0, float(good.speed_at(12.0))))
    st = ctl.stats()
    assert ctl.plan is good and ctl.mode == "shifted" and force < 5e3
    assert (st["infeasible_plans"], st["relaxed_plans"], st["solver_failures"]) == (1, 0, 1)
    assert st["worst_violation"].startswith("dynamics at 0 m")
    assert st["iterations_median"] > 0


# ------------------------------------------------------------------------------------------------ multistart
def record_targets(monkeypatch, ctl, weights=None):
    """The target_speed of every solve the controller asks for (None: the warm-started solve); the time weight of
    each appended to ``weights``."""
    calls = []
    real = ctl.ocp.solve

    def spy(*args, **kw):
        calls.append(kw.get("target_speed"))
        if weights is not None:
            weights.append(kw.get("time_weight"))
        return real(*args, **kw)
    monkeypatch.setattr(ctl.ocp, "solve", spy)
    return calls


def test_multistart_tries_a_faster_then_a_slower_cold_start(monkeypatch):
    ctl = controller(road(), multistart_period=1.5, multistart_step=3.0, replan_period=0.5)
    calls = record_targets(monkeypatch, ctl)
    ctl.wheel_force(obs(0.0, 0.0, 12.0))
    assert calls == [None]  # no plan yet: no second start
    mean = float(np.mean(ctl.plan.v))
    ctl.wheel_force(obs(0.5, 6.0, 12.5))  # the first one is due as soon as there is a plan
    assert calls[1:] == [None, pytest.approx(mean + 3.0)]
    ctl.wheel_force(obs(1.5, 19.0, 13.0))  # the next one is due at 2.0 s
    assert len(calls) == 4
    mean = float(np.mean(ctl.plan.v))
    ctl.wheel_force(obs(2.0, 25.0, 13.5))
    assert calls[4:] == [None, pytest.approx(mean - 3.0)]
    off = controller(road())  # multistart_period 0: never
    calls = record_targets(monkeypatch, off)
    for t in (0.0, 1.0, 2.0):
        off.wheel_force(obs(t, 12.0 * t, 12.0))
    assert calls == [None, None, None]


def test_each_solve_is_warm_started_from_the_plan_before(monkeypatch):
    ctl = controller(road())
    warm = []
    real = ctl.ocp.solve

    def spy(*args, **kw):
        warm.append(kw.get("warm"))
        return real(*args, **kw)
    monkeypatch.setattr(ctl.ocp, "solve", spy)
    ctl.wheel_force(obs(0.0, 0.0, 12.0))
    first = ctl.plan
    ctl.wheel_force(obs(1.0, 12.0, float(first.speed_at(12.0))))
    assert warm[0] is None and warm[1] is first and ctl.plan is not first


def test_an_unconverged_plan_that_runs_a_cap_brakes_but_keeps_the_old_warm_start(monkeypatch):
    ctl = controller(road(low=(100.0, 600.0, 10.0)))
    ctl.wheel_force(obs(0.0, 0.0, 12.0))
    good = ctl.plan
    unconverged_solves(monkeypatch, ctl, ConstraintViolation("speed_cap", 120.0, 10.0, 14.0, "m/s"))
    ctl.wheel_force(obs(1.0, 50.0, 16.0))
    assert ctl.mode in ("brake", "emergency") and ctl.plan is good
    assert ctl.stats()["infeasible_plans"] == 1 and ctl._brake_target.position == 120.0


def test_multistart_keeps_the_lower_objective(monkeypatch):
    ctl = controller(road(), multistart_period=0.5)
    ctl.wheel_force(obs(0.0, 0.0, 12.0))
    real = ctl.ocp.solve
    better = {"by": 10.0}
    warm = {}

    def biased(*args, **kw):  # the cold start's objective set to the warm one's less better["by"]
        plan = real(*args, **kw)
        if kw.get("target_speed") is not None:
            w = warm["objective"]
            plan.objective = w - 1e-6 * abs(w) if better["by"] == "tie" else w - better["by"]
            plan.status = "alternative"
        else:
            warm["objective"] = plan.objective
        return plan
    monkeypatch.setattr(ctl.ocp, "solve", biased)
    ctl.wheel_force(obs(1.0, 12.0, 12.0))
    assert ctl.plan.status == "alternative" and ctl.stats()["multistart_switches"] == 1
    better["by"] = -10.0
    ctl.wheel_force(obs(2.0, 24.0, 12.0))
    assert ctl.plan.status != "alternative" and ctl.stats()["multistart_switches"] == 1
    # a tiny gain (below 1e-6 of the objective) is not worth a switch, a larger one is
    better["by"] = 0.5e-6 * abs(ctl.plan.objective)
    ctl.wheel_force(obs(3.0, 36.0, 12.0))
    assert ctl.stats()["multistart_switches"] == 1
    better["by"] = "tie"  # exactly 1e-6 of it: not worth it either
    ctl.wheel_force(obs(4.0, 48.0, 12.0))
    assert ctl.stats()["multistart_switches"] == 1
    better["by"] = 2e-6 * abs(ctl.plan.objective)
    ctl.wheel_force(obs(5.0, 60.0, 12.0))
    assert ctl.stats()["multistart_switches"] == 2


def test_multistart_replaces_a_failed_warm_solve(monkeypatch):
    ctl = controller(road(), multistart_period=0.5)
    ctl.wheel_force(obs(0.0, 0.0, 12.0))
    real = ctl.ocp.solve

    def warm_fails(*args, **kw):
        plan = real(*args, **kw)
        if kw.get("target_speed") is None:
            plan.converged = plan.success = False
            plan.objective = -1e9
        return plan
    monkeypatch.setattr(ctl.ocp, "solve", warm_fails)
    ctl.wheel_force(obs(1.0, 12.0, 12.0))
    st = ctl.stats()
    assert st["multistart_switches"] == 1 and st.get("solver_failures", 0) == 0 and ctl.mode == "mpc"


def test_multistart_follows_the_schedule_lateness(monkeypatch):
    sched = TripSchedule(start=0.0, end=500.0, duration=50.0)
    ctl = controller(road(), multistart_period=0.5, multistart_step=2.0, schedule=sched)
    weights = []
    calls = record_targets(monkeypatch, ctl, weights)
    ctl.wheel_force(obs(0.0, 0.0, 10.0))
    mean = float(np.mean(ctl.plan.v))
    ctl.wheel_force(obs(1.0, 15.0, 10.0))  # 15 m in 1 s: ahead of the 10 m/s schedule -> slower
    assert calls[-1] == pytest.approx(mean - 2.0)
    mean = float(np.mean(ctl.plan.v))
    ctl.wheel_force(obs(2.0, 16.0, 10.0))  # 16 m in 2 s: behind -> faster
    assert calls[-1] == pytest.approx(mean + 2.0)
    # both starts plan with the scheduled time weight of this step (raised: 0.4 s late)
    assert weights[-1] == weights[-2] == ctl.time_weights[-1] > 8000.0


# ------------------------------------------------------------------------------------------------ time weight
def test_time_weight_is_fixed_without_a_schedule():
    ctl = controller(road())
    assert ctl.time_weight(obs(0.0, 0.0, 10.0)) == 8000.0 and ctl.time_weights == []
    assert math.isnan(ctl.stats()["time_weight_median"])


def test_scheduled_time_weight_from_the_interpolated_crossing_of_start():
    sched = TripSchedule(start=100.0, end=1100.0, duration=100.0, gain=20.0)
    ctl = controller(road(length=1200.0), schedule=sched)
    assert ctl.time_weight(obs(2.0, 80.0, 10.0)) == 8000.0 and ctl._schedule_start is None
    # crossed 100 m between (2 s, 80 m) and (4 s, 120 m): at 3 s
    lam = ctl.time_weight(obs(4.0, 120.0, 10.0))
    assert ctl._schedule_start == pytest.approx(3.0)
    late = 4.0 - (3.0 + 0.02 * 100.0)
    assert ctl._late == pytest.approx(late) and late == pytest.approx(-1.0)
    lam0 = 8000.0 * math.exp(-20.0 / 98.0)
    assert lam == pytest.approx(lam0)
    lam = ctl.time_weight(obs(15.0, 200.0, 10.0))  # scheduled at 13 s: 2 s late with 90 s to go
    assert lam == pytest.approx(8000.0 * math.exp(20.0 * 2.0 / 90.0))
    assert ctl.time_weights == [pytest.approx(lam0), lam] and ctl.stats()["time_weight_median"] == \
        pytest.approx(0.5 * (lam0 + lam))
    ctl.reset_schedule()
    assert ctl._schedule_start is None and ctl.time_weights == [] and ctl._late == 0.0
    # a first solve already past the start takes that moment; a stand-still at start too
    lam = ctl.time_weight(obs(7.0, 150.0, 10.0))  # 150 m scheduled 5 s after the start: 5 s early
    assert ctl._schedule_start == 7.0 and lam == pytest.approx(8000.0 * math.exp(-20.0 * 5.0 / 95.0))
    ctl.reset_schedule()
    ctl.time_weight(obs(1.0, 100.0, 0.0))
    ctl.time_weight(obs(2.0, 100.0, 0.0))
    assert ctl._schedule_start == 1.0


def test_scheduled_integral_is_bounded_and_counted_from_the_crossing():
    sched = TripSchedule(start=0.0, end=1000.0, duration=100.0, gain=0.0, integral_gain=0.5, max_log_change=2.0)
    ctl = controller(road(length=1200.0), schedule=sched)
    ctl.time_weight(obs(0.0, 0.0, 10.0))  # crossing at 0 s, on time
    assert ctl._late_integral == 0.0
    lam = ctl.time_weight(obs(2.0, 10.0, 5.0))  # 1 s late, integrated over 2 s
    assert ctl._late_integral == pytest.approx(2.0) and lam == pytest.approx(8000.0 * math.exp(0.5 * 2.0))
    lam = ctl.time_weight(obs(4.0, 20.0, 5.0))  # 2 s late over 2 s more: 6, bounded at 2 / 0.5 = 4
    assert ctl._late_integral == pytest.approx(4.0) and lam == pytest.approx(8000.0 * math.exp(2.0))
    lam = ctl.time_weight(obs(5.0, 200.0, 5.0))  # 15 s ahead over 1 s: 4 - 15
    assert ctl._late_integral == pytest.approx(-4.0) and lam == pytest.approx(8000.0 * math.exp(-2.0))
    fresh = controller(road(length=1200.0), schedule=sched)
    fresh.time_weight(obs(0.0, 0.0, 10.0))
    fresh._last_s = None
    fresh.time_weight(obs(3.0, 25.0, 10.0))  # no previous solve: 0.5 s late integrated since the crossing (0 s)
    assert fresh._late_integral == pytest.approx(0.5 * 3.0)
    late = controller(road(length=1200.0), schedule=sched)
    late.time_weight(obs(0.0, -20.0, 10.0))
    late.time_weight(obs(2.0, 20.0, 10.0))  # crossed at 1 s; 20 m scheduled at 3 s: 1 s early since then
    assert late._schedule_start == pytest.approx(1.0) and late._late_integral == pytest.approx(-1.0)
    late.time_weight(obs(4.0, 20.0, 10.0))  # 1 s late over the 2 s since the previous solve
    assert late._late_integral == pytest.approx(-1.0 + 2.0)


# ------------------------------------------------------------------------------------------------ stops, stats
def test_serving_a_stop_forgets_it_and_replans_from_standstill():
    ctl = controller(road(stops=(50.0, 300.0)))
    ctl.wheel_force(obs(0.0, 0.0, 5.0))
    assert ctl.plan is not None
    ctl.serve_stop(0)
    assert ctl._unserved == [300.0] and ctl.plan is None and ctl._next_replan == -np.inf
    assert ctl.envelope.served[0] and not ctl.envelope.served[1]
    assert list(ctl.preview(45.0, 0.0).stops) == []


def test_stats_summarise_solves_and_fallbacks():
    ctl = controller(road())
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no numpy warning about empty slices: the empty cases are handled
        empty = ctl.stats()
    assert empty["solves"] == 0 and math.isnan(empty["solve_time_median"]) and math.isnan(empty["solve_time_p99"])
    assert math.isnan(empty["iterations_median"]) and math.isnan(empty["time_weight_median"])
    assert (empty["relaxed_plans"], empty["infeasible_plans"], empty["fallbacks"]) == (0, 0, 0)
    ctl.solve_times = [0.1, 0.2, 0.3, 0.4, 10.0]
    ctl.iterations = [3, 5, 40]
    ctl.events.update(fallback_shifted_plan=2, fallback_cruise=3, fallback_brake=4, relaxed_plans=5,
                      infeasible_plans=6)
    st = ctl.stats()
    assert st["solves"] == 5 and st["solve_time_median"] == 0.3
    assert st["solve_time_p99"] == pytest.approx(np.percentile([0.1, 0.2, 0.3, 0.4, 10.0], 99))
    assert st["iterations_median"] == 5.0 and st["fallbacks"] == 9
    assert (st["relaxed_plans"], st["infeasible_plans"], st["fallback_cruise"]) == (5, 6, 3)


def test_gear_request_only_with_the_gear_command_on_an_ice_above_the_minimum_speed():
    ice = SourceEnergyModel(kind="ice", wheel_radius=0.5, gear_ratios=(20.0, 10.0, 5.0), shift_speeds=(5.0, 12.0),
                            loss=(2000.0, 1.0, 0.01, 0.02, 0.0), max_power=150e3, max_torque=800.0,
                            indicated_efficiency=0.4)
    assert controller(road(), gear_command=True).gear_request(obs(0.0, 0.0, 15.0)) is None  # an EV
    assert controller(road(), energy=ice).gear_request(obs(0.0, 0.0, 15.0)) is None  # not asked to
    ctl = controller(road(), energy=ice, gear_command=True, gear_min_speed=6.0, gear_band=0.5)
    assert ctl.gear_request(obs(0.0, 0.0, 6.0)) == 2  # the first request after reset
    # the transmission engaged gear 2: held within the band of the 12 m/s shift, then up
    assert ctl.gear_request(Observation(t=0.1, s=1.0, v=12.3, a=0.0, gear=2)) == 2
    assert ctl.gear_request(Observation(t=0.2, s=2.0, v=12.6, a=0.0, gear=2)) == 3
    assert ctl.gear_request(obs(0.3, 3.0, 5.9)) is None and ctl._gear is None


# ------------------------------------------------------------------------------------------------ counts and edges
def test_each_fallback_is_counted_and_cruise_control_restarts_only_when_entered():
    ctl = controller(road(), min_plan_left=100.0)
    ctl.wheel_force(obs(0.0, 0.0, 12.0))
    plan = ctl.plan
    for k in range(2):
        ctl._fall_back(obs(1.0 + k, 10.0 + k, float(plan.speed_at(10.0 + k))))
    assert (ctl.events["solver_failures"], ctl.events["fallback_shifted_plan"]) == (2, 2)
    ctl._fall_back(obs(3.0, 70.0, 11.0))  # 90 m of plan left: cruise control, started bumplessly at 11 m/s
    assert ctl.mode == "cruise" and ctl.cruise.v_ref == 11.0 and ctl.cruise.integral == 0.0
    ctl.cruise.integral, ctl.cruise.v_ref = 0.3, 11.5  # as after some cruise-control steps
    ctl._fall_back(obs(4.0, 80.0, 11.0))
    assert ctl.cruise.integral == 0.3 and ctl.cruise.v_ref == 11.5  # already cruising: no restart
    assert (ctl.events["solver_failures"], ctl.events["fallback_cruise"]) == (4, 2)


def test_fallback_brake_edges():
    ctl = controller(road())
    ctl.wheel_force(obs(0.0, 0.0, 12.0))
    res = 200.0
    # half a metre before the cap it still brakes; exactly 2 m/s^2 needed is still the comfort brake
    ctl._brake_target = ConstraintViolation("speed_cap", 10.5, 10.0, 12.0, "m/s")
    assert ctl._fallback_brake(obs(0.1, 10.0, 10.2), res, M) == pytest.approx(res - M * 4.04)
    assert ctl.mode == "emergency"  # (10.2^2 - 10^2) / (2 * 0.5) = 4.04 m/s^2
    ctl._brake_target = ConstraintViolation("speed_cap", 11.0, 10.0, 12.0, "m/s")
    for _ in range(2):
        assert ctl._fallback_brake(obs(0.1, 0.0, 12.0), res, M) == pytest.approx(res - M * 2.0)
    assert ctl.mode == "brake" and ctl.events["comfort_brake_steps"] == 2
    assert ctl.events["emergency_brake_steps"] == 1


def test_multistart_alternates_before_the_scheduled_segment_and_is_slower_when_on_time(monkeypatch):
    sched = TripSchedule(start=400.0, end=500.0, duration=10.0)
    ctl = controller(road(), multistart_period=0.5, schedule=sched)
    calls = record_targets(monkeypatch, ctl)
    ctl.wheel_force(obs(0.0, 0.0, 10.0))
    for t in (1.0, 2.0):
        mean = float(np.mean(ctl.plan.v))
        ctl.wheel_force(obs(t, 10.0 * t, 10.0))
        assert calls[-1] == pytest.approx(mean + (4.0 if t == 1.0 else -4.0))  # not yet at the start: alternating
    on_time = TripSchedule(start=0.0, end=500.0, duration=50.0)
    ctl = controller(road(), multistart_period=0.5, schedule=on_time)
    calls = record_targets(monkeypatch, ctl)
    ctl.wheel_force(obs(0.0, 0.0, 10.0))
    mean = float(np.mean(ctl.plan.v))
    ctl.wheel_force(obs(1.0, 10.0, 10.0))  # 10 m at 1 s: exactly on schedule -> not late -> slower
    assert ctl._late == 0.0 and calls[-1] == pytest.approx(mean - 4.0)


def test_worst_violation_keeps_the_first_of_equal_amounts_and_a_larger_cap_over_a_smaller_stop():
    ctl = controller(road())
    cap = ConstraintViolation("speed_cap", 20.0, 10.0, 15.0, "m/s")
    ctl._record_worst((cap, ConstraintViolation("stop", 30.0, 1.0, 2.0, "m/s"),
                       ConstraintViolation("speed_cap", 40.0, 10.0, 15.0, "m/s")))
    assert ctl._worst is cap


def test_serving_a_stop_keeps_one_a_metre_apart_and_tells_cruise_control():
    ctl = controller(road(stops=(50.0, 50.9)))
    ctl.serve_stop(0)
    assert ctl._unserved == [50.9] and ctl.cruise.reference.served[0] and not ctl.cruise.reference.served[1]


def test_schedule_edges():
    assert TripSchedule(start=0.0, end=100.0, duration=10.0, time_floor=0.5).time_floor == 0.5
    pi = TripSchedule(start=0.0, end=1000.0, duration=100.0, gain=20.0, integral_gain=0.01)
    assert pi.time_weight(1000.0, 52.0, 500.0, 0.0) == pytest.approx(1000.0 * math.exp(0.8))  # no integral yet


def test_road_force_is_the_delivered_force_plus_the_missing_acceleration():
    """F = min(F_sent, full load of the engaged gear) + m (a_plan - a): what the road takes to follow the plan."""
    table = ((0.0, 40.0), (9000.0, 9000.0), (3000.0, 3000.0), (1500.0, 1500.0))
    ice = SourceEnergyModel(kind="ice", wheel_radius=0.5, gear_ratios=(20.0, 10.0, 5.0), shift_speeds=(5.0, 12.0),
                            loss=(2000.0, 1.0, 0.01, 0.02, 0.0), max_power=150e3, max_torque=800.0,
                            indicated_efficiency=0.4, traction_table=table)
    ctl = controller(road(), energy=ice)
    cmd = ctl.act(obs(0.0, 0.0, 8.0))
    assert ctl._traction_sent == cmd.traction > 0.0 and ctl.plan is not None
    a_plan = float(ctl.plan.accel[ctl.plan.segment_at(10.0)])
    ctl._traction_sent = 5000.0
    o = Observation(t=0.1, s=10.0, v=8.0, a=0.2, gear=2)
    assert ctl.road_force(o) == pytest.approx(3000.0 + M * (a_plan - 0.2))  # gear 2 gives 3 kN at most
    ctl._traction_sent = 2000.0
    assert ctl.road_force(o) == pytest.approx(2000.0 + M * (a_plan - 0.2))
    assert ctl.road_force(Observation(t=0.1, s=10.0, v=8.0, a=0.2, gear=0)) == pytest.approx(M * (a_plan - 0.2))
    off = Observation(t=0.1, s=float(ctl.plan.s[-1]) + 1.0, v=8.0, a=0.2, gear=2)
    assert ctl.road_force(off) == pytest.approx(2000.0 - M * 0.2)  # off the plan: a_plan = 0
    ctl.mode = "cruise"
    assert ctl.road_force(o) == pytest.approx(2000.0 - M * 0.2)
    ctl._traction_sent, ctl._last_force = None, 1200.0  # nothing sent yet: the last command's traction
    assert ctl.road_force(o) == pytest.approx(1200.0 - M * 0.2)
    ctl._last_force = -800.0
    assert ctl.road_force(o) == pytest.approx(-M * 0.2)
    ctl._last_force = None  # no command yet at all: nothing delivered
    assert ctl.road_force(o) == pytest.approx(-M * 0.2)
    ctl.mode, ctl._traction_sent = "mpc", 2000.0
    first = Observation(t=0.1, s=10.0, v=8.0, a=0.2, gear=1)  # gear 1 gives 9 kN: all 2 kN delivered
    assert ctl.road_force(first) == pytest.approx(2000.0 + M * (a_plan - 0.2))
    plan = ctl.plan
    for at, k in ((float(plan.s[0]), 0), (float(plan.s[-1]) - 5.0, N - 1), (float(plan.s[-1]), N - 1)):
        on = Observation(t=0.1, s=at, v=8.0, a=0.2, gear=2)  # the plan's first and last points count
        assert ctl.road_force(on) == pytest.approx(2000.0 + M * (float(plan.accel[k]) - 0.2))


def test_gear_request_kicks_down_holds_while_shifting_and_returns_with_a_margin(monkeypatch):
    """Full load 9 / 3 / 1.5 kN in gears 1 / 2 / 3; at 13 m/s the shift rule's gear is 3."""
    table = ((0.0, 40.0), (9000.0, 9000.0), (3000.0, 3000.0), (1500.0, 1500.0))
    ice = SourceEnergyModel(kind="ice", wheel_radius=0.5, gear_ratios=(20.0, 10.0, 5.0), shift_speeds=(5.0, 12.0),
                            loss=(2000.0, 1.0, 0.01, 0.02, 0.0), max_power=150e3, max_torque=800.0,
                            indicated_efficiency=0.4, traction_table=table)
    ctl = controller(road(), energy=ice, gear_command=True)
    force = {"F": 1000.0}
    monkeypatch.setattr(ctl, "road_force", lambda o: force["F"])

    def request(gear, clutch=1.0):
        return ctl.gear_request(Observation(t=0.0, s=0.0, v=13.0, a=0.0, gear=gear, sample={"clutch": clutch}))
    assert request(0) == 3  # 1 kN: gear 3 gives it
    force["F"] = 2000.0
    assert request(3) == 2  # 2 kN: a kick-down to gear 2
    force["F"] = 100.0
    assert request(3) == 2  # gear 2 not engaged yet: the request is held
    assert request(2, clutch=0.5) == 2  # the clutch still slips: held
    force["F"] = 1450.0
    assert request(2) == 2  # back up only below 95 % of gear 3's full load: 1450 / 0.95 > 1500
    force["F"] = 1400.0
    assert request(2) == 3  # 1400 / 0.95 = 1474 N <= 1500 N
    force["F"] = 1450.0
    assert request(3) == 3  # in the shift rule's own gear no margin: 1450 N <= 1500 N
    ctl._requested = 1  # a request two gears away from the shift rule's is not held
    force["F"] = 1000.0
    assert request(2) == 3


# --------------------------------------------------------------------------- stop nodes with several stops in view
def test_a_stop_just_behind_the_vehicle_leaves_the_next_stop_its_node():
    ctl = controller(road(stops=(40.0, 300.0)), n=16)
    pv = ctl.preview(40.5, 0.5)  # 0.5 m past the first line (still unserved); the second 259.5 m ahead
    # nearest node to 300 m: 40.5 + 13 x 20 = 300.5 m, moved onto the line, only it capped
    np.testing.assert_allclose(pv.s[12:15], [280.5, 300.0, 320.5])
    np.testing.assert_allclose(pv.speed_cap[12:15], [20.0, 1.0, 20.0])


def test_a_stop_within_half_a_segment_leaves_the_next_stop_its_node():
    ctl = controller(road(stops=(45.0, 300.0)), n=16)
    pv = ctl.preview(41.0, 5.0)  # the first line 4 m ahead: nearest node is the vehicle's, nodes 0 and 1 capped
    np.testing.assert_allclose(pv.speed_cap[:3], [1.0, 1.0, 20.0])
    np.testing.assert_allclose(pv.s[12:15], [281.0, 300.0, 321.0])  # 301 m moved onto the second line
    np.testing.assert_allclose(pv.speed_cap[12:15], [20.0, 1.0, 20.0])


def test_a_second_stop_in_the_last_segment_caps_both_its_nodes():
    ctl = controller(road(stops=(145.0, 150.0)))  # 8 segments of 20 m from 0 m
    pv = ctl.preview(0.0, 10.0)
    # 145 m takes node 7 (140 m); 150 m shares it, so it caps both nodes of the segment it lies in (145..160 m)
    np.testing.assert_allclose(pv.s, [0.0, 20.0, 40.0, 60.0, 80.0, 100.0, 120.0, 145.0, 160.0])
    np.testing.assert_allclose(pv.speed_cap, [20.0] * 7 + [1.0, 1.0])
    np.testing.assert_array_equal(pv.stops, [145.0, 150.0])
