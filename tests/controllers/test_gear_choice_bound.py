"""The gear-aware lower bound of a truck's drive: fuel at the best gear with fuel cut, the plant's own fuel map per
gear, and the dynamic programme on a grid uniform in v^2/2."""

from dataclasses import replace

import numpy as np
import pytest

from roadload.controllers.dynamic_programming import PlantFuelMap, dp_optimum, plant_fuel_map
from roadload.controllers.energy import generic_ev
from roadload.controllers.optimum import FullRouteOptimum, OptimumSettings
from roadload.controllers.vehicle_models import energy_model_from_spec
from roadload.envs.powertrain import Powertrain
from roadload.presets import truck_spec
from roadload.road_load import RoadLoadParameters
from roadload.road_profiles import RoadProfile


@pytest.fixture(scope="module")
def truck():
    spec = truck_spec(40000.0)
    return spec, energy_model_from_spec(spec)


def test_best_gear_fuel_cuts_fuel_when_braking_and_refuses_a_force_no_gear_gives(truck):
    _, en = truck
    v = np.full(4, 20.0)
    power, gear = en.best_gear_fuel_power(np.array([-20e3, 0.0, 8e3, 60e3]), v)
    assert power[0] == 0.0  # the engine's drag and the brakes take it: fuel cut
    # coasting in the highest gear whose engine speed is in range: (P_loss(omega, 0)) / eta_i, below the shift rule's
    omega = 20.0 * en.gear_ratios[gear[1]] / en.wheel_radius
    assert power[1] == pytest.approx(en.loss_power(omega, 0.0) / en.indicated_efficiency)
    rule = float(en.source_power(0.0, 0.0, 20.0, en.smooth_ratio(20.0)))
    assert power[1] < rule
    # a traction force: the highest gear whose full load gives it (the friction grows with the engine speed)
    feasible = [g for g in range(len(en.gear_ratios)) if en.full_load_force(20.0, g) >= 8e3
                and 20.0 * en.gear_ratios[g] / en.wheel_radius >= en.engine_speed_range[0]]
    assert gear[2] == min(feasible, key=lambda g: en.gear_ratios[g])
    assert np.isinf(power[3]) and gear[3] == -1  # 60 kN at 20 m/s = 1.2 MW


def _one_gear(fmap: PlantFuelMap, g: int) -> PlantFuelMap:
    """The map with gear index ``g`` alone (its feasible set seen through ``power``)."""
    return replace(fmap, fuel=fmap.fuel[g:g + 1], max_force=fmap.max_force[g:g + 1],
                   drag_force=fmap.drag_force[g:g + 1], speed_ratio=fmap.speed_ratio[g:g + 1])


@pytest.fixture(scope="module")
def small_map(truck):
    """The 40 t truck's plant fuel map on a coarse grid (the full one takes ~10 s to build)."""
    spec, _ = truck
    return plant_fuel_map(spec, np.array([4.5, 8.0, 15.0, 22.0, 26.5]), np.arange(-40e3, 80e3 + 1.0, 2500.0))


def test_plant_fuel_map_is_the_plants_fuel_at_the_exact_inverse_torque_with_fuel_cut_in_overrun(truck, small_map):
    """Every grid point of every gear in range: P_fuel(omega, T_E) of the plant at the exact inverse of the
    drive-train losses (Powertrain.source_torque), 0 at or below the engine's drag at the wheels (fuel cut); the
    least over the gears equals the least over the gears the plant can drive it in."""
    spec, _ = truck
    pt, fmap = Powertrain(spec), small_map
    e = spec.drivetrain.require_engine()
    r = float(spec.tires.dynamic_radius)
    best = fmap.power(fmap.speeds[:, None], fmap.forces[None, :])
    checked = cut = 0
    for i, v in enumerate(fmap.speeds):
        for j, f in enumerate(fmap.forces):
            fuel = []
            for g in range(1, spec.drivetrain.n_gears + 1):
                omega = pt.speed_ratio(g) * v
                if not e.idle_speed <= omega <= e.max_speed:
                    continue
                t_drag, t_max = pt.torque_limits(omega, v)
                t_e = max(pt.source_torque(g, f * r, omega), t_drag)
                if t_e > t_max:
                    continue
                expected = pt.fuel_power(omega, t_e)
                assert fmap.fuel[g - 1, i, j] == pytest.approx(expected, rel=1e-9, abs=1e-9), (g, v, f)
                if f <= fmap.drag_force[g - 1, i]:
                    assert fmap.fuel[g - 1, i, j] == 0.0  # overrun: fuel cut, the brakes take the rest
                    cut += 1
                fuel.append(expected)
                checked += 1
            assert best[i, j] == (pytest.approx(min(fuel), rel=1e-9, abs=1e-9) if fuel else np.inf), (v, f)
    assert checked > 500 and cut > 50
    # braking far beyond the grid's lowest force: the engine's drag in fuel cut and the brakes, fuel 0
    assert np.all(fmap.power(fmap.speeds, -100e3) == 0.0)


def test_plant_fuel_map_refuses_a_gear_exactly_outside_its_engine_speed_range_and_full_load(small_map):
    """A gear's feasible set is exact between the grid points: an engine speed 0.1 % outside [idle, rev limit] or a
    force 0.1 % above its full load at the wheels is refused, 0.1 % inside it is priced (interpolating towards a
    refusal value would cut off a grid cell at full load, where a heavy truck climbs)."""
    fmap = small_map
    lo, hi = fmap.engine_speed_range
    edges = 0
    for g in range(fmap.fuel.shape[0]):
        one = _one_gear(fmap, g)
        for w, inside in ((lo * 0.999, False), (lo * 1.001, True), (hi * 0.999, True), (hi * 1.001, False)):
            v = w / fmap.speed_ratio[g]
            if not fmap.speeds[0] <= v <= fmap.speeds[-1]:
                continue
            assert np.isfinite(one.power(v, 0.0)) == inside, (g, w)
            edges += 1
        v = 0.5 * (lo + hi) / fmap.speed_ratio[g]  # mid engine speed, between grid speeds
        if fmap.speeds[0] <= v <= fmap.speeds[-1] and v not in fmap.speeds:
            f_max = float(np.interp(v, fmap.speeds, fmap.max_force[g]))
            assert np.isfinite(one.power(v, 0.999 * f_max)) and np.isinf(one.power(v, 1.001 * f_max)), g
            edges += 1
    assert edges >= 12
    assert np.isinf(fmap.power(fmap.speeds[-1] + 0.1, 0.0))  # beyond the map's speeds: refused
    assert np.isinf(fmap.power(fmap.speeds[2], fmap.forces[-1] + 1.0))  # beyond its forces: refused


def test_dp_on_an_energy_grid_keeps_the_constant_speed_optimum_of_a_flat_road():
    params = RoadLoadParameters.from_physical(1420.0, 0.009, 0.0, 0.0, 0.7, 1.2, 60000.0, rotational_mass=60.0)
    energy = generic_ev()
    s = np.arange(0.0, 601, 5.0)  # 600 m: the constant-speed optimum does not depend on the length
    z = np.zeros_like(s)
    road = RoadProfile("flat", s, z, z, z, np.full_like(s, 40.0))
    settings = OptimumSettings(ds=10.0, jerk=False)
    opt = FullRouteOptimum(road, energy, params, settings)
    nlp = opt.solve(road.length / 20.0, start_speed=20.0, arrival_speed=20.0)
    dp = dp_optimum(opt.preview, energy, params, road.length / 20.0, 20.0, 20.0, settings, energy_step=0.5)
    assert np.max(np.abs(dp.v - 20.0)) < 0.02  # the grid's speeds near 20 m/s are 0.025 m/s apart
    assert dp.energy_J == pytest.approx(nlp.energy_J, rel=0.005)
    with pytest.raises(ValueError, match="energy_step"):
        dp_optimum(opt.preview, energy, params, 75.0, 20.0, 20.0, settings, energy_step=0.0)
