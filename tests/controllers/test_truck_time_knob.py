"""Why the truck's closed-loop trip time jumps with the time weight, and the fixes.

Cause 1 (a defect): the MPC valued the kinetic energy left at the horizon end at m E_N (wheel work) although the
objective counts fuel; on a diesel (eta_i ~ 0.47) each J of kinetic energy costs ~2.1 J of fuel, so the plan
coasted off its speed over the last kilometre of every horizon. Cause 2 (the physics of the shift rule): the
fuel per metre is not convex in speed (an upshift drops engine speed and friction), so the NLP has two local
cruise optima and a warm start never leaves the one it is in. The fixes: ``terminal_value="source"``, cold
multi-start solves, and the trip-time schedule (a knob the segment time follows continuously)."""

from dataclasses import replace

import numpy as np
import pytest

from roadload.controllers.base import ControllerError, Observation
from roadload.controllers.mpc import MpcError, MpcSettings, OcpSolver, Preview
from roadload.controllers.mpc_controller import MpcController, MpcControllerSettings, TripSchedule
from roadload.controllers.vehicle_models import abc_parameters, energy_model_from_spec
from roadload.experiments.controller_comparison import TRUCK_MPC, PairedTask
from roadload.presets import truck_spec

LAM = 100_000.0  # [J/s], between the 15 t truck's two cruise optima (~19 and ~23.6 m/s)


@pytest.fixture(scope="module")
def truck15():
    spec = truck_spec(15_000.0)
    return energy_model_from_spec(spec), abc_parameters(spec)


def _flat(en, s0: float = 0.0) -> Preview:
    n, ds = TRUCK_MPC.n_nodes, TRUCK_MPC.ds
    return Preview(s=s0 + ds * np.arange(n + 1), grade=np.zeros(n), curvature=np.zeros(n),
                   speed_cap=np.full(n + 1, 25.0), ratio=np.full(n, en.gear_ratios[0]))


def test_fuel_per_metre_of_the_shift_rule_has_two_cruise_optima(truck15):
    """(P_fuel(v) + lambda) / v on a flat road: a local minimum below the 11 -> 12 upshift (22.8 m/s) and one
    above it, for every lambda between 40 and 140 kJ/s: the trip time of a fixed lambda must jump."""
    en, p = truck15
    from roadload.controllers.force_model import resistance_force

    v = np.linspace(15.0, 25.0, 201)
    fuel = en.source_power(np.maximum(resistance_force(v, 0 * v, 0 * v, p), 0.0), 0 * v, v, en.smooth_ratio(v))
    for lam in (40e3, 100e3, 140e3):
        cost = (fuel + lam) / v
        minima = v[1:-1][(cost[1:-1] < cost[:-2]) & (cost[1:-1] < cost[2:])]
        assert len(minima) == 2, (lam, minima)
        assert minima[0] < en.shift_speeds[-1] < minima[1]


def test_terminal_value_at_source_cost_keeps_the_cruise_speed_to_the_horizon_end(truck15):
    en, p = truck15
    plans = {tv: OcpSolver(replace(TRUCK_MPC, terminal_value=tv, time_weight=LAM), en).solve(23.5, 0.0, _flat(en), p)
             for tv in ("wheel", "source")}
    assert all(pl.success for pl in plans.values())
    # m E_N / eta_i: steady cruise on a flat road holds its speed over the whole 2 km horizon
    assert np.ptp(plans["source"].v[5:]) < 0.1
    # m E_N (the earlier terminal value): the plan sells kinetic energy it paid 1/eta_i for -> coasts down > 5 m/s
    # at the end
    assert plans["wheel"].v[5] - plans["wheel"].v[-1] > 5.0
    with pytest.raises(MpcError, match="terminal_value"):
        MpcSettings(terminal_value="fuel")


def test_warm_start_stays_on_the_worse_branch_and_a_cold_multistart_leaves_it(truck15):
    en, p = truck15
    ocp = OcpSolver(replace(TRUCK_MPC, terminal_value="source", time_weight=LAM), en)
    slow = ocp.solve(19.0, 0.0, _flat(en), p, target_speed=19.0)
    warm = ocp.solve(19.0, 0.0, _flat(en), p, warm=slow)
    fast = ocp.solve(19.0, 0.0, _flat(en), p, target_speed=24.0)
    assert slow.success and warm.success and fast.success
    assert warm.v[20] < 20.0 and fast.v[20] > 23.0  # two local optima of the same NLP
    assert warm.objective == pytest.approx(slow.objective, rel=1e-6)  # the warm start never leaves its branch
    assert fast.objective < warm.objective - 50.0  # ... although the other branch is better by > 50 kJ
    # lambda per solve is a parameter of the built NLP: a larger time weight plans faster
    lazy = ocp.solve(19.0, 0.0, _flat(en), p, target_speed=19.0, time_weight=20_000.0)
    assert lazy.v[20] < slow.v[20] - 0.3
    with pytest.raises(MpcError, match="time_weight"):
        ocp.solve(19.0, 0.0, _flat(en), p, time_weight=-1.0)


def test_trip_schedule_raises_lambda_when_late_and_lowers_it_when_early():
    sched = TripSchedule(start=2000.0, end=6000.0, duration=200.0)
    lam0 = 1e5
    assert sched.time_weight(lam0, 100.0, 4000.0, 0.0) == pytest.approx(lam0)  # on time at half way
    late = sched.time_weight(lam0, 105.0, 4000.0, 0.0)  # 5 s late, 100 s to go: ln change 20 * 5 / 100 = 1
    assert late == pytest.approx(lam0 * np.e)
    assert sched.time_weight(lam0, 95.0, 4000.0, 0.0) == pytest.approx(lam0 / np.e)
    assert sched.time_weight(lam0, 400.0, 4000.0, 0.0) == pytest.approx(lam0 * np.exp(4.0))  # clipped
    # near the end the remaining time is floored at 30 s
    assert sched.time_weight(lam0, 199.5 + 3.0, 5990.0, 0.0) == pytest.approx(lam0 * np.exp(20 * 3.0 / 30.0))
    shaped = replace(sched, shape_s=(2000.0, 3000.0, 6000.0), shape_fraction=(0.0, 0.5, 1.0))
    assert shaped.fraction(3000.0) == pytest.approx(0.5) and sched.fraction(3000.0) == pytest.approx(0.25)
    with pytest.raises(ControllerError, match="start < end"):
        TripSchedule(start=10.0, end=5.0, duration=100.0)
    with pytest.raises(ControllerError, match="duration"):
        TripSchedule(start=0.0, end=5.0, duration=0.0)
    with pytest.raises(ValueError, match="knob"):
        PairedTask("truck_15t", "long_grades", 0, knob="speed")
    with pytest.raises(ValueError, match="net"):
        PairedTask("truck_15t", "long_grades", 0, knob="schedule", metric="raw")


def test_schedule_feedback_crosses_start_between_solves_and_integrates_lateness_from_there():
    """The controller's lambda feedback: the start crossing is interpolated between two solves, and the integral
    term sums lateness x time since the previous solve, counted from the crossing (not from the solve before it)."""
    sched = TripSchedule(start=1000.0, end=3000.0, duration=100.0, integral_gain=0.002)
    ctrl = MpcController(MpcControllerSettings(mpc=replace(TRUCK_MPC, time_weight=1e5), schedule=sched))
    ctrl.reset_schedule()
    lam = [ctrl.time_weight(Observation(t=t, s=s, v=20.0, a=0.0)) for t, s in
           [(0.0, 960.0), (4.0, 1040.0), (9.0, 1130.0), (15.0, 1250.0)]]
    assert lam[0] == 1e5 and ctrl._schedule_start == pytest.approx(2.0)  # 1000 m crossed half way between solves
    late = [sched.lateness(t, s, 2.0) for t, s in [(4.0, 1040.0), (9.0, 1130.0), (15.0, 1250.0)]]
    integral = late[0] * (4.0 - 2.0) + late[1] * 5.0 + late[2] * 6.0
    assert ctrl._late_integral == pytest.approx(integral)
    assert lam[3] == pytest.approx(sched.time_weight(1e5, 15.0, 1250.0, 2.0, integral))
    assert ctrl.time_weights == pytest.approx(lam[1:])
