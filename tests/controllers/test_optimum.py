"""The full-route optimum (NLP) and its dynamic-programming cross-check."""

import numpy as np
import pytest

from roadload.controllers.base import DriveContext
from roadload.controllers.closed_loop import run_closed_loop
from roadload.controllers.cruise import CruiseController, CruiseSettings
from roadload.controllers.dynamic_programming import dp_optimum
from roadload.controllers.energy import generic_ev
from roadload.controllers.force_model import FixedForceModel, WindEstimate, resistance_force
from roadload.controllers.mpc import MpcSettings
from roadload.controllers.mpc_controller import MpcController, MpcControllerSettings
from roadload.controllers.optimum import FullRouteOptimum, OptimumError, OptimumSettings, route_nodes
from roadload.controllers.plant import ModelPlant
from roadload.road_load import RoadLoadParameters
from roadload.road_profiles import RoadProfile

PARAMS = RoadLoadParameters.from_physical(1420.0, 0.009, 0.0, 0.0, 0.7, 1.2, 60000.0, rotational_mass=60.0)
ENERGY = generic_ev()


def flat_road(length=1500.0, limit=40.0):
    s = np.arange(0.0, length + 1, 5.0)
    z = np.zeros_like(s)
    return RoadProfile("flat", s, z, z, z, np.full_like(s, limit))


def hilly_road(length=1500.0, stops=()):
    s = np.arange(0.0, length + 1, 5.0)
    grade = 0.05 * np.sin(2 * np.pi * s / 700.0) * (s > 200)
    limit = np.where((s > 800) & (s < 1100), 50 / 3.6, 90 / 3.6)
    curvature = np.where((s > 1200) & (s < 1300), 1 / 120.0, 0.0)
    return RoadProfile("hills", s, grade, curvature, np.zeros_like(s), limit, stops=np.asarray(stops, float))


def test_flat_road_without_limits_constant_speed_is_optimal_for_nlp_and_dp():
    road = flat_road()
    v_bar = 20.0
    trip_time = road.length / v_bar
    settings = OptimumSettings(ds=10.0, jerk=False)
    opt = FullRouteOptimum(road, ENERGY, PARAMS, settings)
    sol = opt.solve(trip_time, start_speed=v_bar, arrival_speed=v_bar)
    assert sol.success
    assert np.max(np.abs(sol.plan.v - v_bar)) < 1e-3  # constant speed
    # analytic energy: the source power of the road load at v_bar for the trip time
    force = float(resistance_force(v_bar, 0.0, 0.0, PARAMS))
    analytic = float(ENERGY.source_power(force, 0.0, v_bar, ENERGY.gear_ratios[0])) * trip_time
    assert sol.energy_J == pytest.approx(analytic, rel=1e-4)
    # time multiplier: dE/dT = d/dT [P(L/T) T], a slower trip needs less energy
    assert sol.time_slope < 0
    dp = dp_optimum(opt.preview, ENERGY, PARAMS, trip_time, v_bar, v_bar, settings, speed_step=0.1)
    assert np.max(np.abs(dp.v - v_bar)) <= 0.1 + 1e-9
    assert dp.energy_J == pytest.approx(sol.energy_J, rel=0.005)


def test_dp_and_nlp_agree_on_a_hilly_ev_route_with_limits_and_a_stop():
    road = hilly_road(stops=(600.0,))
    settings = OptimumSettings(ds=10.0, jerk=False)
    opt = FullRouteOptimum(road, ENERGY, PARAMS, settings)
    assert np.any(np.isclose(opt.preview.s, 600.0))  # a node at the stop, capped at the stop speed
    sol = opt.solve(110.0, start_speed=0.0, arrival_speed=15.0)
    assert sol.success and sol.stops == 1
    assert np.all(sol.plan.v <= np.maximum(opt.preview.speed_cap - settings.speed_margin, 1.0) + 1e-3)
    dp = dp_optimum(opt.preview, ENERGY, PARAMS, sol.model_time, 0.0, 15.0, settings, speed_step=0.05)
    assert dp.energy_J == pytest.approx(sol.energy_J, rel=0.005)
    assert dp.multiplier == pytest.approx(-sol.time_slope, rel=0.05)  # the same slope of the time-energy curve


def test_dp_converges_to_the_nlp_from_above_on_a_downhill_route_that_regenerates():
    """A 5 % descent: the optimum's net source energy is negative (more regenerated than drawn). The DP solves the
    same discrete problem on a speed grid, so it is never below the NLP's optimum and its excess shrinks with the
    grid step (the NLP is the global optimum, not a local one)."""
    s = np.arange(0.0, 1501.0, 5.0)
    z = np.zeros_like(s)
    road = RoadProfile("descent", s, np.full_like(s, -0.05), z, z, np.full_like(s, 25.0))
    settings = OptimumSettings(ds=10.0, jerk=False)
    opt = FullRouteOptimum(road, ENERGY, PARAMS, settings)
    sol = opt.solve(110.0, start_speed=0.0, arrival_speed=10.0)
    assert sol.success and sol.energy_J < 0
    excess = [dp_optimum(opt.preview, ENERGY, PARAMS, sol.model_time, 0.0, 10.0, settings, speed_step=h).energy_J
              - sol.energy_J for h in (0.2, 0.05)]
    assert excess[0] > excess[1] > -1e-6 * abs(sol.energy_J)
    assert excess[1] < 0.005 * abs(sol.energy_J)


def test_time_slope_is_the_derivative_of_the_optimal_energy():
    opt = FullRouteOptimum(hilly_road(), ENERGY, PARAMS, OptimumSettings(ds=10.0))
    a, b = opt.solve(100.0, 0.0, 15.0), opt.solve(101.0, 0.0, 15.0)
    assert (b.energy_J - a.energy_J) == pytest.approx(0.5 * (a.time_slope + b.time_slope), rel=0.05)


def test_the_optimum_is_below_every_controller_on_a_short_route():
    road = hilly_road()
    ctx = DriveContext(road, ENERGY, FixedForceModel(PARAMS))
    controllers = {"cruise": CruiseController(),
                   "cruise_slow": CruiseController(CruiseSettings(fraction=0.8)),
                   "mpc": MpcController(MpcControllerSettings(mpc=MpcSettings(time_weight=8000.0)))}
    opt = FullRouteOptimum(road, ENERGY, PARAMS, OptimumSettings(ds=5.0))
    for name, ctl in controllers.items():
        m = run_closed_loop(ctl, ModelPlant(road, PARAMS, ENERGY), ctx).metrics
        sol = opt.solve(m["arrival_time"], 0.0, m["arrival_speed"])
        assert sol.success, name
        assert sol.energy_J < m["arrival_energy_J"], name  # at the controller's own trip time and arrival speed
    # a trip time no drive can make is refused with the reason
    with pytest.raises(OptimumError, match="shorter than"):
        opt.solve(10.0, 0.0, 15.0)


def test_wind_vector_gives_headwind_per_segment_from_the_road_heading():
    s = np.arange(0.0, 2001.0, 5.0)
    # a left turn by pi in the middle: the second half runs back the other way
    kappa = np.where(np.abs(s - 1000.0) < 50.0 * np.pi, 1 / 100.0, 0.0)
    z = np.zeros_like(s)
    road = RoadProfile("u-turn", s, z, kappa, z, np.full_like(s, 25.0))
    wind = WindEstimate(6.0, np.pi, 0.3)  # blowing against the initial heading: a headwind at the start
    opt = FullRouteOptimum(road, ENERGY, PARAMS, OptimumSettings(), wind=wind)
    head = opt.preview.headwind
    assert head[0] == pytest.approx(6.0) and head[-1] == pytest.approx(-6.0, abs=0.01)  # tailwind after the turn
    assert np.max(np.abs(opt.preview.crosswind)) == pytest.approx(6.0, abs=0.01)  # a pure crosswind mid-turn
    sol = opt.solve(100.0, 15.0, 15.0)
    calm = FullRouteOptimum(road, ENERGY, PARAMS, OptimumSettings()).solve(100.0, 15.0, 15.0)
    v = sol.plan.v
    # slower into the headwind, faster with the tailwind than the calm plan; the wind costs energy on the round trip
    def gain(u):
        return np.mean(u[-len(u) // 4:]) - np.mean(u[: len(u) // 4])
    assert gain(v) > gain(calm.plan.v) + 1.0
    assert sol.energy_J > calm.energy_J


def test_route_nodes_place_a_node_at_every_stop():
    nodes = route_nodes(0.0, 1000.0, [333.3, 1000.0, -5.0], 50.0)
    assert nodes[0] == 0.0 and nodes[-1] == 1000.0 and np.any(np.isclose(nodes, 333.3))
    assert np.max(np.diff(nodes)) <= 50.0 + 1e-9
    with pytest.raises(OptimumError, match="start < end"):
        route_nodes(10.0, 5.0, [], 10.0)
    with pytest.raises(OptimumError, match="ds"):
        OptimumSettings(ds=0.0)
