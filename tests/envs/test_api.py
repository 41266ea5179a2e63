"""Simulator step API, Trip contract, determinism, bad input."""

import json
import warnings

import numpy as np
import pytest

from roadload import Trip
from roadload.envs import (Action, EffectsConfig, EffectsError, LateralValidityWarning, SimulationError, Simulator,
                           get_preset, simulate)
from roadload.road_profiles import RoadProfile
from roadload.vehicle import VehicleSpec, VehicleSpecError, load_vehicle


def test_same_seed_identical_trip_and_different_seed_different_noise(rolling_road):
    road = rolling_road()
    a = simulate("gt_rwd", road, effects=["wind", "sensor_outliers"], seed=3)
    b = simulate("gt_rwd", road, effects=["wind", "sensor_outliers"], seed=3)
    c = simulate("gt_rwd", road, effects=["wind", "sensor_outliers"], seed=4)
    assert a.equals(b)
    n = min(len(a), len(c))
    diff = a.measured["accel_x"].to_numpy()[:n] - c.measured["accel_x"].to_numpy()[:n]
    assert np.mean(np.abs(diff) > 0) > 0.5  # noise differs in most samples
    assert not np.allclose(a.truth["wind_speed"].to_numpy()[:n], c.truth["wind_speed"].to_numpy()[:n])


def test_trip_contract_measured_truth_and_meta(tmp_path, rolling_road):
    trip = simulate("bmw_i3", rolling_road(stops=[800.0]), effects=["payload", "tire_warmup"], seed=1)
    for ch in ("wheel_speed_fl", "wheel_speed_rr", "vehicle_speed", "accel_x", "accel_y", "yaw_rate",
               "steering_wheel_angle", "drive_torque", "engine_speed", "gear", "clutch", "brake_pressure_front",
               "brake_pressure_rear", "ambient_temperature", "battery_voltage", "battery_current"):
        assert ch in trip.measured.columns, ch
    for ch in ("tractive_force", "mass", "rolling_resistance_coefficient", "drag_area", "grade", "curvature",
               "wind_speed", "cornering_stiffness", "air_density"):
        assert ch in trip.truth.columns, ch
        assert ch not in trip.measured.columns
    assert trip.sample_rate == pytest.approx(100.0)
    assert trip.meta["source"] == "sim" and trip.meta["seed"] == 1
    assert trip.meta["effects"]["effects"].keys() == {"payload", "tire_warmup"}
    assert VehicleSpec.from_dict(trip.meta["vehicle"]).name == "bmw_i3"
    # payload changed at the stop, and the truth says so
    mass = trip.true("mass")
    assert mass[0] == pytest.approx(1400.0) and abs(mass[-1] - mass[0]) > 1.0
    # f_r falls as the tires warm up
    fr0 = trip.true("rolling_resistance_f0")
    assert fr0[0] > fr0[-1] > get_preset("bmw_i3").tires.rolling_resistance_f0
    path = trip.save(tmp_path / "t.parquet")
    assert Trip.load(path).equals(trip)


def test_step_api_observe_matches_trip_rows_and_done_at_end(rolling_road):
    sim = Simulator("gt_rwd", rolling_road(600.0), effects=["sensor_bias", "sensor_dropouts"], seed=2)
    assert sim.observe() is None
    obs = []
    while not sim.state.done:
        r = sim.step(None, n_substeps=10)
        obs.append(sim.observe())
    trip = sim.to_trip()
    assert r.s >= 600.0 - 1e-6
    m = trip.measured.set_index(np.round(trip.measured["t"].to_numpy(), 6))
    for o in obs[::7]:
        row = m.loc[round(o["t"], 6)]
        for k in ("vehicle_speed", "accel_x", "drive_torque", "gear"):
            assert (np.isnan(o[k]) and np.isnan(row[k])) or o[k] == row[k], k


def test_step_api_actions_and_true_parameters(rolling_road):
    sim = Simulator("bmw_i3", rolling_road(3000.0), seed=0, initial_speed=15.0)
    r0 = sim.step(Action(traction_force=1500.0), n_substeps=50)
    assert r0.a > 0.3 and r0.source_energy > 0  # accelerating draws battery energy
    r1 = sim.step(-1200.0, n_substeps=50)  # signed force: regen first
    assert r1.a < -0.5 and r1.source_energy < 0  # regenerating puts energy back
    cap = sim.regen_capacity()
    assert 0 < cap < 5000
    r2 = sim.step(Action(friction_brake_force=3000.0), n_substeps=20)
    assert sim.vehicle_state.brake_pressure_front > 1e5  # friction braking shows as brake pressure
    assert sim.to_trip().truth["brake_pressure_front"].iloc[-1] == sim.vehicle_state.brake_pressure_front
    p = sim.true_parameters()
    spec = get_preset("bmw_i3")
    assert p["mass"] == spec.body.mass
    assert p["drag_area"] == pytest.approx(spec.aero.drag_area)
    assert p["rolling_resistance_f0"] == pytest.approx(spec.tires.rolling_resistance_f0)
    assert p["c"] == pytest.approx(0.5 * p["air_density"] * p["drag_area"])
    assert r2.t == pytest.approx(1.2)
    with pytest.raises(SimulationError, match="action"):
        sim.step(Action(traction_force=-1.0))
    with pytest.raises(SimulationError, match="action.gear"):
        sim.step(Action(gear=3))
    first = sim.reset()
    assert first.t == 0.0 and first.s == 0.0


def test_lateral_validity_warning_above_4_mps2():
    s = np.array([0.0, 3000.0])
    road = RoadProfile("straight", s, [0, 0], [0, 0], [0, 0], [40, 40])
    sim = Simulator("gt_rwd", road, seed=0, initial_speed=25.0)
    with warnings.catch_warnings(record=True) as rec:
        warnings.simplefilter("always")
        for _ in range(30):
            sim.step(Action(traction_force=800.0, steer=0.03), n_substeps=10)
    assert any(issubclass(w.category, LateralValidityWarning) for w in rec)
    assert sim.to_trip().meta["warnings"]


def test_bad_inputs_name_the_field(tmp_path, rolling_road):
    spec = get_preset("gt_rwd")
    d = spec.to_dict()
    d["body"]["mass"] = -5.0
    with pytest.raises(VehicleSpecError, match=r"vehicle\.body\.mass: must be > 0"):
        VehicleSpec.from_dict(d)
    d = spec.to_dict()
    d["aero"]["drag_coeff"] = 0.3
    with pytest.raises(VehicleSpecError, match=r"vehicle\.aero\.drag_coeff: unknown field"):
        VehicleSpec.from_dict(d)
    d = spec.to_dict()
    d["drivetrain"]["gearbox_loss"][2]["values"][0][0] = float("nan")
    with pytest.raises(VehicleSpecError, match=r"vehicle\.drivetrain\.gearbox_loss\[2\]\.values"):
        VehicleSpec.from_dict(d)
    bad = tmp_path / "v.json"
    bad.write_text('{"name": "x", "body": {"mass": 1}')
    with pytest.raises(VehicleSpecError, match="not valid JSON"):
        load_vehicle(bad)
    d = spec.to_dict()
    d["tires"]["dynamic_radius"] = "big"
    bad.write_text(json.dumps(d))
    with pytest.raises(VehicleSpecError, match=r"vehicle\.tires\.dynamic_radius: expected a number"):
        load_vehicle(bad)
    with pytest.raises(EffectsError, match="unknown effect 'rain'.*known effects"):
        EffectsConfig.parse(["rain"])
    with pytest.raises(EffectsError, match="'wind' has no parameter 'speed'"):
        EffectsConfig.parse("wind:speed=3")
    with pytest.raises(EffectsError, match="mean_speed"):
        EffectsConfig.parse("wind:mean_speed=-3")
    with pytest.raises(VehicleSpecError, match="unknown vehicle preset"):
        get_preset("porsche")
    with pytest.raises(SimulationError, match="seed"):
        Simulator("gt_rwd", rolling_road(), seed=-1)
    with pytest.raises(SimulationError, match="distance"):
        simulate("gt_rwd", rolling_road(), distance=5000.0)


def test_vehicle_json_round_trip(tmp_path):
    for name in ("gt_rwd", "gt_awd", "bmw_i3"):
        spec = get_preset(name)
        path = spec.save(tmp_path / f"{name}.json")
        again = load_vehicle(path)
        assert again == spec
        assert again.replace(**{"body.mass": 2000.0}).body.mass == 2000.0


def test_effects_parse_forms():
    cfg = EffectsConfig.parse("wind:mean_speed=5,gust_std=2,payload")
    assert cfg.names == ["payload", "wind"]
    assert cfg.params("wind")["mean_speed"] == 5.0 and cfg.params("wind")["gust_std"] == 2.0
    again = EffectsConfig.from_dict(json.loads(json.dumps(cfg.to_dict())))
    assert again.to_dict() == cfg.to_dict()
    assert EffectsConfig.parse("all").names == sorted(EffectsConfig.parse("all").names)


def test_presets_are_plausible_and_expose_the_estimating_side_quantities():
    rwd, awd, i3 = get_preset("gt_rwd"), get_preset("gt_awd"), get_preset("bmw_i3")
    assert 1800 <= rwd.mass <= 2000 and awd.mass > rwd.mass and 1300 <= i3.mass <= 1450
    assert rwd.drivetrain.n_gears == 7 and awd.drivetrain.driven_axle == "all"
    p_rwd = max(np.asarray(rwd.drivetrain.engine.full_load.x) * rwd.drivetrain.engine.full_load.y)
    p_awd = max(np.asarray(awd.drivetrain.engine.full_load.x) * awd.drivetrain.engine.full_load.y)
    assert 200e3 < p_rwd < 250e3 and 390e3 < p_awd < 440e3
    assert i3.drivetrain.gear_ratios[0] * i3.drivetrain.final_drive == pytest.approx(9.665)
    assert i3.wheel_radius == pytest.approx(0.35, abs=0.01) and i3.aero.drag_coefficient == 0.29
    assert i3.aero.frontal_area == 2.38
    m = i3.drivetrain.motor
    assert m.max_power == 125e3 and m.max_torque == 250.0 and m.regen_torque_limit > 0
    w, tq = np.meshgrid(np.linspace(200, 1100, 30), np.linspace(20, 250, 30))
    eta = m.efficiency(w, tq)
    assert 0.93 < eta.max() < 0.975 and eta.min() > 0.6
    # best brake efficiency of the engines: 30-40 % (BSFC ~ 210-290 g/kWh at 43 MJ/kg)
    for spec in (rwd, awd):
        e = spec.drivetrain.engine
        w, tq = np.meshgrid(np.linspace(150, 500, 30), np.linspace(100, 0.95 * min(e.full_load.y[3:]), 30))
        eff = w * tq / e.fuel_power(w, tq)
        assert 0.30 < eff.max() < 0.40
    # what the estimating side needs, straight from the spec
    assert rwd.body.cg_to_front_axle + rwd.body.cg_to_rear_axle == pytest.approx(rwd.body.wheelbase)
    assert rwd.drivetrain.reduced_inertia(1) > rwd.drivetrain.reduced_inertia(7) > 0
    assert rwd.effective_mass(1) > rwd.effective_mass(7) > rwd.mass
    assert rwd.steering.wheel_from_steering_wheel(np.radians(90)) == pytest.approx(np.radians(90) / 15.5, rel=0.02)
    assert rwd.understeer_gradient() > 0  # the presets understeer
    assert rwd.tires.cornering_stiffness_front > 0 and rwd.aero.drag_area == pytest.approx(0.29 * 2.36)


@pytest.mark.parametrize("vehicle, effects", [("bmw_i3", None), ("gt_rwd", {"wind": {"mean_speed": 6.0}, "payload": {},
                                                                             "poor_excitation": {}})])
def test_on_road_equals_a_new_simulator_bitwise(vehicle, effects):
    """Simulator.on_road (the native vector env's episode setup) gives the state and trajectory of a simulator built
    from scratch on that road, bit for bit, and leaves the simulator it came from untouched."""
    from roadload.road_profiles import load_profile

    first = Simulator(vehicle, load_profile("hilly", seed=1), effects, seed=3, initial_speed=5.0)
    x_first = first.vehicle_state.to_dict()
    road = load_profile("city", seed=7)
    swapped = first.on_road(road, seed=11, initial_speed=8.0)
    fresh = Simulator(vehicle, road, effects, seed=11, initial_speed=8.0)
    for name in ("_vehicle", "_road", "_stops", "_cycle", "_vplan_base"):  # state, parameters, command, route
        assert getattr(swapped, name).tobytes() == getattr(fresh, name).tobytes(), name
    rng = np.random.default_rng(0)
    for _ in range(300):
        force = float(rng.uniform(-3000.0, 3000.0))
        a, b = swapped.step(force, 10), fresh.step(force, 10)
        assert swapped.vehicle_state == fresh.vehicle_state
        assert a.source_energy == b.source_energy
    assert swapped.vehicle_state.position > 100.0  # it drove
    assert first.vehicle_state.to_dict() == x_first  # the template did not move
    assert swapped.observe() == fresh.observe()


def test_on_road_refuses_a_drive_cycle_simulator_and_bad_roads():
    from roadload.road_profiles import load_profile

    sim = Simulator("bmw_i3", load_profile("hilly", seed=1))
    with pytest.raises(SimulationError, match="road"):
        sim.on_road("hilly", seed=1)
    with pytest.raises(SimulationError, match="seed"):
        sim.on_road(load_profile("hilly", seed=2), seed=-1)
    from roadload.road_profiles import DriveCycle

    t = np.arange(0.0, 60.0, 1.0)
    cycle_sim = Simulator("bmw_i3", DriveCycle("ramp", t, np.minimum(t, 15.0)))
    with pytest.raises(SimulationError, match="drive-cycle"):
        cycle_sim.on_road(load_profile("hilly", seed=2), seed=1)


def test_a_copied_or_pickled_simulator_keeps_its_state_views(straight_road):
    import copy
    import pickle

    sim = Simulator("bmw_i3", straight_road(), seed=2, initial_speed=10.0)
    sim.step(800.0, 20)
    for clone in (copy.deepcopy(sim), pickle.loads(pickle.dumps(sim))):
        assert clone.vehicle_state == sim.vehicle_state
        a, b = clone.step(-500.0, 30), sim.step(-500.0, 30)
        assert a == b and clone.vehicle_state.speed == a.v  # the view follows the clone's own record
        sim.reset(seed=2, initial_speed=10.0)
        sim.step(800.0, 20)
