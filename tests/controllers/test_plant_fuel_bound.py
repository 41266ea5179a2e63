"""The plant-fuel bound of a truck's drive (the dynamic programme in the plant's own fuel map at the gear of least
fuel, fuel cut in overrun): equal to the plant's fuel at steady constant speed, below every controller on a short
route with a climb and a descent, and the recursion's time multiplier at 0 (a slow trip) still solves."""

from dataclasses import replace

import numpy as np
import pytest
from scipy.interpolate import RegularGridInterpolator

from roadload.controllers.drive import drive
from roadload.controllers.dynamic_programming import DpProblem, PlantFuelBound, dp_optimum
from roadload.controllers.energy import generic_ev
from roadload.controllers.force_model import resistance_force
from roadload.controllers.optimum import FullRouteOptimum, OptimumError, OptimumSettings
from roadload.controllers.sim_plant import SimulatorPlant
from roadload.controllers.vehicle_models import rotational_mass
from roadload.experiments.optimum_benchmark import OptimumTask, _settings
from roadload.presets import truck_spec
from roadload.road_load import RoadLoadParameters
from roadload.road_profiles import RoadProfile

WARMUP = 800.0  # [m] cruise control before the measured segment, as the benchmark's truck warm-up


def _road(name: str, grade_of_s, warmup: float = WARMUP, length: float = 2400.0) -> RoadProfile:
    s = np.arange(0.0, warmup + length + 1.0, 10.0)
    z = np.zeros_like(s)
    return RoadProfile(name, s, np.array([grade_of_s(x) for x in s]), z, z, np.full_like(s, 25.0))


def _bound(road: RoadProfile, spec, warmup: float = WARMUP) -> PlantFuelBound:
    params = replace(SimulatorPlant(spec, road, seed=0).true_parameters(), rotational_mass=rotational_mass(spec))
    return PlantFuelBound(road, spec, params, start=warmup)


def _run(road: RoadProfile, controller: str, warmup: float = WARMUP) -> dict:
    task = OptimumTask("truck_40t", "long_grades", 0, controllers=(controller,), warmup=warmup)
    res, _ = drive(truck_spec(40000.0), road, seed=0, settings=_settings(task, controller))
    assert res.metrics["arrived"]
    return {**res.metrics, "peak_speed": float(res.log["v"][res.log["s"] >= warmup].max())}


def _flat_ev(length: float):
    """(the full-route optimum's problem, energy model, road load, settings) of an EV on a flat road of ``length``
    [m] with a 30 m/s limit: the DP's analytic setting."""
    params = RoadLoadParameters.from_physical(1420.0, 0.009, 0.0, 0.0, 0.7, 1.2, 60000.0, rotational_mass=60.0)
    energy = generic_ev()
    s = np.arange(0.0, length + 1.0, 5.0)
    z = np.zeros_like(s)
    road = RoadProfile("flat", s, z, z, z, np.full_like(s, 30.0))
    settings = OptimumSettings(ds=20.0, jerk=False)
    return FullRouteOptimum(road, energy, params, settings), energy, params, settings


@pytest.mark.slow
@pytest.mark.nightly  # 33-44 s of CPU each; the 15-minute CI runs the fast tests of the same code
def test_bound_equals_the_plants_fuel_at_steady_constant_speed():
    """A flat road driven by cruise control at its set speed (settled after 2 km): the bound's map at the run's
    speed and road load gives the plant's fuel within 0.2 % in one of the gears in range; the bound at the run's
    time, start and arrival speed lies below it by less than 1 % (its freedom: any gear, and pulsing at full load
    then coasting with fuel cut, which the quasi-static map rewards at part load)."""
    spec = truck_spec(40000.0)
    road = _road("flat", lambda s: 0.0, warmup=2000.0, length=1500.0)
    m = _run(road, "cruise", warmup=2000.0)
    assert abs(m["arrival_speed"] - m["segment_start_speed"]) < 0.05  # steady
    bound = _bound(road, spec, warmup=2000.0)
    v = m["arrival_speed"]
    fmap = bound.problem.fuel_table
    res = float(resistance_force(v, 0.0, 0.0, bound.params.as_vector()))
    omega = fmap.speed_ratio * v
    in_range = (omega >= fmap.engine_speed_range[0]) & (omega <= fmap.engine_speed_range[1])
    per_gear = np.array([RegularGridInterpolator((fmap.speeds, fmap.forces), f)([[v, res]])[0] for f in fmap.fuel])
    error = np.abs(per_gear[in_range] * m["segment_time"] / m["segment_energy_J"] - 1.0)
    print(f"map vs plant in the nearest gear: {100 * error.min():.3f} %")
    assert error.min() < 0.002  # the plant's fuel is the map's in one of the gears it can drive
    e_bound, _ = bound.solve(m["segment_time"], m["segment_start_speed"], m["arrival_speed"])
    print(f"bound {e_bound:.0f} J, plant {m['segment_energy_J']:.0f} J, "
          f"{100 * (e_bound / m['segment_energy_J'] - 1):+.3f} %")
    assert e_bound <= m["segment_energy_J"]
    assert e_bound == pytest.approx(m["segment_energy_J"], rel=0.01)


@pytest.mark.slow
@pytest.mark.nightly  # 33-44 s of CPU each; the 15-minute CI runs the fast tests of the same code
def test_bound_lies_below_every_controller_on_a_short_truck_route_at_40_t():
    """A 4 % climb of 800 m, flat, a 4 % descent of 600 m: the speed-band cruise, the oracle MPC and the human-like
    driver each use at least the bound's fuel (measured: 19 %, 10 % and 35 % above it) at their own trip time,
    start and arrival speed (the bound's speed caps raised to a run's peak speed where it drove above the limit)."""
    spec = truck_spec(40000.0)

    def grade(s: float) -> float:
        x = s - WARMUP
        return 0.04 if 200 <= x < 1000 else (-0.04 if 1500 <= x < 2100 else 0.0)

    road = _road("climb_descent", grade)
    bound = _bound(road, spec)
    for controller in ("cruise_band", "mpc:oracle", "human"):
        m = _run(road, controller)
        e_bound, _ = bound.solve(m["segment_time"], m["segment_start_speed"], m["arrival_speed"], m["peak_speed"])
        print(controller, f"{m['segment_time']:.1f} s, peak {m['peak_speed']:.2f} m/s, "
              f"plant {m['segment_energy_J']:.0f} J, bound {e_bound:.0f} J")
        assert e_bound <= m["segment_energy_J"], controller
        assert e_bound > 0.0, controller  # the climb takes fuel (how tight the bound is: the steady test)


def test_dp_solves_a_trip_slow_enough_for_a_zero_time_multiplier():
    """The recursion at mu = 0 (a target time the DP's mu = 1000 J/s already meets): infeasible transitions carry an
    infinite energy and a finite time, so mu dt is never 0 x inf = nan (which argmin took for the best transition
    and the DP reported "no feasible speed profile")."""
    opt, energy, params, settings = _flat_ev(1000.0)
    slow = dp_optimum(opt.preview, energy, params, 1000.0 / 9.0, 6.0, None, settings, speed_step=0.1)
    fast = dp_optimum(opt.preview, energy, params, 1000.0 / 15.0, 6.0, None, settings, speed_step=0.1)
    assert np.isfinite(slow.energy_J) and slow.multiplier < 1e3
    assert slow.energy_J < fast.energy_J


def test_a_trip_slower_than_the_least_energy_trip_is_bounded_by_that_trip_not_refused():
    """A run slower than the DP's least-energy trip (multiplier 0): as a bound (least_at_any_time) the DP returns
    that trip, with its own shorter time and multiplier 0, the least energy at any time; as an optimum at equal
    time it is refused with the two times named."""
    opt, energy, params, settings = _flat_ev(600.0)
    problem = DpProblem(opt.preview, energy, params, settings, speed_step=0.1)
    least = problem.solve(1e4, 8.0, 8.0, least_at_any_time=True)  # 600 m in 10,000 s: slower than any grid trip
    assert least.multiplier == 0.0 and least.model_time < 1e4
    faster = problem.solve(0.9 * least.model_time, 8.0, 8.0)  # an equal-time optimum the grid reaches
    assert least.energy_J < faster.energy_J
    assert problem.solve(least.model_time, 8.0, 8.0).energy_J == pytest.approx(least.energy_J, rel=1e-3)
    with pytest.raises(OptimumError, match="slower than the grid's slowest trip"):
        problem.solve(1e4, 8.0, 8.0)
