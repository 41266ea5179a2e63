"""The parts of a truck run's gap to the plant-fuel bound: the map's per-gear look-up shared by the bound (which
refuses a speed outside the map) and the MPC's gear request (which clamps it), the dynamic programme on the MPC's
smoothed fuel model booked in the raw map (at or above the raw map's own optimum, its booking exact when the two
maps are one), and the parts' fleet totals adding up to the total."""

from dataclasses import replace

import numpy as np
import pandas as pd
import pytest

from roadload.controllers.dynamic_programming import (TRUCK_BOUND_SETTINGS, DpProblem, PlantFuelBound,
                                                      plant_fuel_map, smoothed_fuel_map)
from roadload.controllers.energy import PlantFuelModel
from roadload.controllers.optimum import OptimumError, route_nodes, route_preview
from roadload.controllers.sim_plant import SimulatorPlant
from roadload.controllers.vehicle_models import energy_model_from_spec, rotational_mass
from roadload.experiments.truck_gap import PARTS, gap_parts_markdown, gap_parts_summary
from roadload.presets import truck_spec
from roadload.road_profiles import RoadProfile

SPEEDS = np.arange(10.0, 24.0 + 1e-9, 1.0)  # [m/s] a coarse map, fast to build (the bound's: 0.25 m/s x 250 N)
FORCES = np.arange(-10e3, 40e3 + 1.0, 1000.0)  # [N]


@pytest.fixture(scope="module")
def truck():
    spec = truck_spec(40000.0)
    return spec, plant_fuel_map(spec, SPEEDS, FORCES)


def test_gear_power_refuses_a_speed_outside_the_map_and_the_gear_request_clamps_it(truck):
    """Inside the map the bound's least fuel is the minimum of every gear's, and the MPC's per-gear fuel is the
    map's; below the map's lowest speed the bound refuses every gear, the gear request looks up the edge speed's
    fuel with each gear's engine speed at the true speed."""
    _, fmap = truck
    model = PlantFuelModel(fmap, "coarse")
    for v, force in ((12.3, 8000.0), (20.0, -2000.0), (23.7, 25000.0)):
        per_gear = fmap.gear_power(v, force)
        assert per_gear.shape == (fmap.fuel.shape[0],)
        assert float(fmap.power(v, force)) == float(per_gear.min())
        np.testing.assert_array_equal(model.gear_fuel_power(v, force), per_gear)
    assert np.isinf(fmap.gear_power(9.0, 5000.0)).all()  # the bound: no data, no gear
    clamped = fmap.gear_power(9.0, 5000.0, clamp_speed=True)
    omega = fmap.speed_ratio * 9.0  # each gear's engine speed at the true 9 m/s, the table's values at 10 m/s
    in_range = (omega >= fmap.engine_speed_range[0]) & (omega <= fmap.engine_speed_range[1])
    j = int(np.flatnonzero(FORCES == 5000.0)[0])
    expected = np.where(in_range & (5000.0 <= fmap.max_force[:, 0]), fmap.fuel[:, 0, j], np.inf)
    assert np.isfinite(expected).any() and np.isinf(expected).any()
    np.testing.assert_array_equal(clamped, expected)
    np.testing.assert_array_equal(model.gear_fuel_power(9.0, 5000.0), clamped)
    assert np.isinf(model.gear_fuel_power(9.0, 5000.0, load_margin=0.0)[np.isfinite(clamped)]).all()


def _problem(spec, fmap, price=None, fuel=None, price_costs=None) -> DpProblem:
    """A 40 t truck on 160 m flat then 240 m at 3 % (the bound's grid: 40 m nodes, 0.5 m^2/s^2)."""
    s = np.arange(0.0, 401.0, 10.0)
    z = np.zeros_like(s)
    road = RoadProfile("climb", s, np.where(s < 160.0, 0.0, 0.03), z, z, np.full_like(s, 25.0))
    energy = energy_model_from_spec(spec)
    params = replace(SimulatorPlant(spec, road, seed=0).true_parameters(), rotational_mass=rotational_mass(spec))
    preview = route_preview(road, route_nodes(0.0, 400.0, [], TRUCK_BOUND_SETTINGS.ds), energy, TRUCK_BOUND_SETTINGS)
    return DpProblem(preview, energy, params, TRUCK_BOUND_SETTINGS, gear_choice=True, energy_step=0.5,
                     fuel_table=fuel if fuel is not None else fmap, price_table=price, price_costs=price_costs)


def test_the_smooth_models_optimum_booked_in_the_raw_map_lies_at_or_above_the_raw_bound(truck):
    """The programme optimised in the smoothed map and booked in the raw map: at or above the raw map's own optimum
    (which minimises that fuel) at two trip times below the least-fuel trip's, and different from its smooth fuel
    (the smoothing's error); booked in the map it optimises, the booking equals its energy to the last joule (and
    its price table is the raw problem's costs, which the benchmark reuses)."""
    spec, fmap = truck
    raw = _problem(spec, fmap)
    same = _problem(spec, fmap, price=fmap)
    assert same.price is not None
    np.testing.assert_array_equal(same.price, raw.cost)
    smooth = _problem(spec, fmap, price=fmap, fuel=smoothed_fuel_map(fmap), price_costs=raw.cost)
    least = raw.solve(1e4, 20.0, 18.0, least_at_any_time=True).model_time
    for trip_time in (0.98 * least, 0.95 * least):
        b = raw.solve(trip_time, 20.0, 18.0)
        a = smooth.solve(trip_time, 20.0, 18.0)
        assert b.priced_energy_J is None and a.priced_energy_J is not None
        print(f"{trip_time} s: bound {b.energy_J:.0f} J, smooth optimum booked {a.priced_energy_J:.0f} J, "
              f"in phi {a.energy_J:.0f} J")
        assert a.priced_energy_J >= b.energy_J * (1.0 - 1e-4)
        assert a.priced_energy_J != pytest.approx(a.energy_J, rel=1e-6)
    one = same.solve(trip_time, 20.0, 18.0)
    assert one.priced_energy_J == one.energy_J == b.energy_J


def test_smoothed_map_fuel_cut_edge_lies_at_or_below_the_raw_least_drag(truck):
    """The smooth model's overrun edge (the largest force with phi <= 1 W) is free in the raw map too (at or below
    every in-range gear's drag: coasting there burns no fuel in either), and its traction limit is the best gear's
    full load."""
    _, fmap = truck
    sm = smoothed_fuel_map(fmap)
    for i, v in enumerate(SPEEDS[1:-1], start=1):
        edge = float(sm.drag_force[0, i])
        assert float(fmap.power(v, edge)) == 0.0
        assert float(sm.power(v, edge)) <= 1.0
        full = fmap.boundary_forces(v)[0]
        assert float(sm.max_force[0, i]) == pytest.approx(float(full), rel=1e-9)


def test_gap_parts_add_up_to_the_total_and_a_bad_model_is_refused():
    """Each part's fleet total over the bound: loop + non-convexity = total to rounding, with a CI each."""
    rng = np.random.default_rng(3)
    b = rng.uniform(80e6, 170e6, 10)
    a = b * (1 + rng.uniform(0.0, 0.01, 10))
    e = a * (1 + rng.uniform(-0.002, 0.01, 10))
    rows = pd.DataFrame({"vehicle": "truck_40t", "road": "long_grades", "controller": "mpc", "seed": range(10),
                         "time_s": 200.0, "energy_J": e, "bound_J": b, "model_optimum_J": a,
                         "model_optimum_phi_J": a * 1.001, "status": "solved", "total_J": e - b, "loop_J": e - a,
                         "nonconvex_J": a - b})
    r = gap_parts_summary(rows).iloc[0]
    assert r["loop_pct"] + r["nonconvex_pct"] == pytest.approx(r["total_pct"], abs=1e-9)
    assert r["total_pct"] == pytest.approx(100 * (e.mean() / b.mean() - 1), rel=1e-9)
    for part in PARTS:
        assert r[f"{part}_ci95_lo"] < r[f"{part}_pct"] < r[f"{part}_ci95_hi"]
    assert r["model_error_pct"] == pytest.approx(100 * 0.001 * a.mean() / b.mean(), rel=1e-9)
    assert gap_parts_summary(pd.DataFrame()).empty  # a run without a truck MPC: an empty table, not an error
    assert "no truck run" in gap_parts_markdown(pd.DataFrame())
    with pytest.raises(OptimumError, match="choose one of"):
        PlantFuelBound(None, truck_spec(40000.0), None, model="willans")


@pytest.mark.nightly
def test_gap_parts_of_a_stored_run_keep_its_bound_and_add_up():
    """The plant-map MPC's stored run on 40 t long grades seed 0 (106.611 MJ in 217.19 s): the parts re-solve its
    bound to the stored value (the booking of the smooth model leaves the plant-fuel bound as it was), the smooth
    model's optimum booked in the raw map lies between the bound and the run, and the parts add up."""
    from roadload.experiments.truck_gap import gap_parts

    task = {"case": "truck_40t", "road": "long_grades", "seed": 0, "condition": "nominal",
            "controllers": ["mpc:oracle:plant_map"], "warmup": 2000.0, "time_weight": None, "policies": None,
            "dp_step": 0.05, "optimum_ds": 5.0, "mpc": [], "replan_period": None, "label": "",
            "truck_optimum": "bound"}
    row = {"controller": "mpc:oracle:plant_map", "arrived": True, "time_s": 217.18771657310612,
           "energy_J": 106611401.4360998, "start_speed": 22.158762178142755, "arrival_speed": 21.73588151978414,
           "peak_speed": 22.156656747288746}
    parts = gap_parts([{"task": task, "rows": [row]}]).iloc[0]
    print(parts.to_dict())
    assert parts["bound_J"] == pytest.approx(105899071.48238261, abs=1.0)  # the benchmark's stored bound
    assert parts["bound_J"] < parts["model_optimum_J"] < row["energy_J"]
    assert parts["loop_J"] + parts["nonconvex_J"] == pytest.approx(parts["total_J"], abs=1e-3)
