"""The compiled batch-step API (roadload.envs.batch): a kernel outside the simulator that sets commands, advances
and reads named state fields gets the Simulator's trajectories bit for bit; the fleet's input errors are named."""

from __future__ import annotations

import math

import numpy as np
import pytest
from numba import njit

from roadload.envs import Action, SimulationError, Simulator
from roadload.envs.batch import (Fleet, FleetStarts, advance_vehicle, advance_vehicles, command_driver,
                                 command_forces, command_wheel_force, effects_random_state, start_vehicle, state_of,
                                 vehicle_done)
from roadload.road_profiles import DriveCycle, load_profile


@njit(cache=True)
def _drive(records, forces, n_substeps, out):
    """A user kernel: every vehicle gets its signed wheel force (built-in steering), advances, and reports speed,
    position, mass and source energy by name."""
    for i in range(records.vehicles.shape[0]):
        command_wheel_force(records, i, forces[i], np.nan)
        advance_vehicle(records, i, n_substeps)
        x = state_of(records, i)
        out[i, 0] = x.speed
        out[i, 1] = x.position
        out[i, 2] = x.mass
        out[i, 3] = x.source_energy


def _without_log_rows(state: dict[str, float]) -> dict[str, float]:
    return {k: v for k, v in state.items() if k != "log_rows"}


def test_a_compiled_kernel_advances_a_fleet_exactly_as_the_simulators_step():
    setups = (("city", 1, None, 0.0), ("hilly", 2, "all", 8.0), ("motorway", 3, "wind", 20.0))
    sims = [Simulator("bmw_i3", load_profile(road, seed=seed, length=3000.0), effects=eff, seed=seed,
                      initial_speed=v0) for road, seed, eff, v0 in setups]
    fleet = Fleet(len(sims))
    for i, sim in enumerate(sims):
        fleet.load(i, sim)
    out = np.zeros((3, 4))
    for k in range(120):
        forces = np.array([1500.0 * math.sin(0.1 * k + i) for i in range(3)])
        _drive(fleet.records, forces, 10, out)
        for i, sim in enumerate(sims):
            st = sim.step(float(forces[i]), 10)
            assert (out[i, 0], out[i, 1], out[i, 2], out[i, 3]) == (st.v, st.s, sim.vehicle_state.mass,
                                                                    st.source_energy_total)
    for i, sim in enumerate(sims):
        assert _without_log_rows(fleet.state(i).to_dict()) == _without_log_rows(sim.vehicle_state.to_dict())
    assert fleet.state(1).position > 100.0


def test_explicit_forces_and_the_built_in_driver_from_python():
    road = load_profile("city", seed=4, length=2000.0)
    sim, twin = (Simulator("gt_rwd", road, effects="payload", seed=5, initial_speed=6.0) for _ in range(2))
    fleet = Fleet(1)
    fleet.load(0, twin)
    records = fleet.records
    for _ in range(30):
        command_forces(records, 0, 2200.0, 0.0, 0.0, np.nan, -1.0)
        advance_vehicle(records, 0, 10)
        sim.step(Action(traction_force=2200.0), 10)
    command_forces(records, 0, 0.0, 600.0, 900.0, 0.01, 2.0)
    advance_vehicle(records, 0, 20)
    sim.step(Action(regen_force=600.0, friction_brake_force=900.0, steer=0.01, gear=2), 20)
    command_driver(records, 0)
    advance_vehicles(records, np.ones(1, dtype=bool), 500)
    sim.step(None, 500)
    assert _without_log_rows(fleet.state(0).to_dict()) == _without_log_rows(sim.vehicle_state.to_dict())
    assert not vehicle_done(records, 0) and sim.vehicle_state.gear >= 1


def test_a_sharing_fleet_is_the_simulator():
    sim = Simulator("bmw_i3", load_profile("hilly", seed=6, length=2000.0), seed=7, log_capacity=16)
    ref = Simulator("bmw_i3", load_profile("hilly", seed=6, length=2000.0), seed=7)
    fleet = Fleet.sharing(sim)
    out = np.zeros((1, 4))
    for k in range(40):  # the log grows from 16 substeps: the records follow the simulator's new arrays
        sim.reserve_log(10)
        _drive(fleet.records, np.array([900.0 - 40.0 * k]), 10, out)
        st = sim.refresh()
        assert st == ref.step(900.0 - 40.0 * k, 10)
    assert np.array_equal(sim.truth_log(), ref.truth_log())
    assert fleet.state(0).speed == sim.state.v


def test_fleet_input_errors_are_named(straight_road):
    with pytest.raises(SimulationError, match="n_vehicles"):
        Fleet(0)
    with pytest.raises(SimulationError, match="log_capacity"):
        Fleet(2, log_capacity=-1)
    fleet = Fleet(2)
    with pytest.raises(SimulationError, match="no vehicle loaded"):
        fleet.records
    with pytest.raises(SimulationError, match="slot"):
        fleet.load(2, Simulator("bmw_i3", straight_road()))
    with pytest.raises(SimulationError, match="expected a roadload.envs.Simulator"):
        fleet.load(0, "bmw_i3")
    fleet.load(0, Simulator("bmw_i3", straight_road()))
    with pytest.raises(SimulationError, match="vehicle spec differs"):
        fleet.load(1, Simulator("gt_rwd", straight_road()))
    cycle = DriveCycle(name="ramp", time=np.arange(0.0, 30.0, 1.0), speed=np.linspace(0.0, 10.0, 30))
    with pytest.raises(SimulationError, match="drive-cycle"):
        fleet.load(1, Simulator("bmw_i3", cycle))
    with pytest.raises(ValueError, match="speed"):
        fleet.state(0).speed = -1.0
    with pytest.raises(AttributeError, match="read-only"):
        fleet.state(0).mass = 1000.0  # type: ignore[misc]


@njit(cache=True)
def _start(records, index, starts, rows, random_states):
    """A user kernel: episode starts of vehicles ``index`` from the packed starts."""
    for r in range(index.size):
        start_vehicle(records, index[r], starts, rows[r], random_states[r])


def test_a_compiled_start_is_the_simulators_reset_and_load():
    """start_vehicle from a FleetStarts row equals Simulator.reset(seed) + Fleet.load, record and road bit for bit
    (random effects on, so the random state matters), and the vehicles then drive the same trajectories; a longer
    road than the fleet's grows its arrays."""
    roads = (load_profile("motorway", seed=1, length=2500.0), load_profile("hilly", seed=2, length=4000.0))
    sims = [Simulator("bmw_i3", road, effects=["wind", "brake_pad_drift", "payload"], seed=0, initial_speed=v0)
            for road, v0 in zip(roads, (20.0, 12.0))]
    fleet, twin = Fleet(3), Fleet(3)
    starts = FleetStarts(fleet)
    rows = np.array([starts.add(sims[0]), starts.add(sims[1]), 0])
    seeds = [11, 2 ** 62 + 3, 12]
    _start(fleet.records, np.arange(3), starts.records, rows, np.array([effects_random_state(s) for s in seeds],
                                                                      dtype=np.uint64))
    for i, (row, seed) in enumerate(zip(rows, seeds)):
        sims[row].reset(seed=seed)
        twin.load(i, sims[row])
    assert fleet.records.vehicles.tobytes() == twin.records.vehicles.tobytes()
    for i in range(3):
        n = int(fleet.records.vehicles[i]["road_points"])
        assert np.array_equal(fleet.records.roads[i, :, :n], twin.records.roads[i, :, :n])
    assert fleet.records.vehicles[0]["state"]["random_state"] != fleet.records.vehicles[2]["state"]["random_state"]
    out, out_twin = np.zeros((3, 4)), np.zeros((3, 4))
    for k in range(200):
        forces = np.array([1200.0 * math.sin(0.05 * k + i) for i in range(3)])
        _drive(fleet.records, forces, 10, out)
        _drive(twin.records, forces, 10, out_twin)
        assert np.array_equal(out, out_twin)
    assert fleet.records.vehicles.tobytes() == twin.records.vehicles.tobytes()  # bitwise (the commands hold NaN)


def test_fleet_start_errors_are_named(straight_road):
    fleet = Fleet(2)
    starts = FleetStarts(fleet)
    with pytest.raises(SimulationError, match="expected a roadload.envs.Simulator"):
        starts.add("bmw_i3")  # type: ignore[arg-type]
    with pytest.raises(SimulationError, match="depends on the seed"):
        starts.add(Simulator("bmw_i3", straight_road(), effects="poor_excitation"))
    starts.add(Simulator("bmw_i3", straight_road()))
    with pytest.raises(SimulationError, match="vehicle spec differs"):
        starts.add(Simulator("gt_rwd", straight_road()))
    with pytest.raises(SimulationError, match="shares its simulator"):
        FleetStarts(Fleet.sharing(Simulator("bmw_i3", straight_road())))
