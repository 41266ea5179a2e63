"""The gear-aware lower bound of a truck's drive: fuel at the best gear with fuel cut, the plant's own fuel map per
gear, and the dynamic programme on a grid uniform in v^2/2."""

import numpy as np
import pytest

from roadload.controllers.dynamic_programming import dp_optimum, fuel_table_power
from roadload.controllers.energy import generic_ev
from roadload.controllers.optimum import FullRouteOptimum, OptimumSettings
from roadload.controllers.vehicle_models import energy_model_from_spec, plant_fuel_table
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


def test_plant_fuel_table_is_the_plants_quasi_static_fuel_in_the_best_gear(truck):
    spec, _ = truck
    pt = Powertrain(spec)
    speeds, forces = np.array([15.0, 22.0]), np.array([-15e3, 5e3, 12e3])
    table = plant_fuel_table(spec, speeds, forces)
    best = fuel_table_power((speeds, forces, table), speeds[:, None], forces[None, :])
    assert np.all(best[:, 0] == 0.0)  # braking beyond the drag: fuel cut
    r = float(spec.tires.dynamic_radius)
    for i, v in enumerate(speeds):
        for j, f in enumerate(forces[1:], start=1):
            fuel = []
            for g in range(1, spec.drivetrain.n_gears + 1):
                omega = pt.speed_ratio(g) * v
                e = spec.drivetrain.require_engine()
                t_e = pt.source_torque(g, f * r, omega)
                if e.idle_speed <= omega <= e.max_speed and t_e <= pt.torque_limits(omega, v)[1]:
                    fuel.append(pt.fuel_power(omega, t_e))
            assert best[i, j] == pytest.approx(min(fuel), rel=1e-9)


def test_dp_on_an_energy_grid_keeps_the_constant_speed_optimum_of_a_flat_road():
    params = RoadLoadParameters.from_physical(1420.0, 0.009, 0.0, 0.0, 0.7, 1.2, 60000.0, rotational_mass=60.0)
    energy = generic_ev()
    s = np.arange(0.0, 1501, 5.0)
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
