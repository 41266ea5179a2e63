"""Arrival metrics of the closed loop: crossings interpolated inside the step, net of kinetic energy."""

from dataclasses import replace

import numpy as np
import pytest

from roadload.controllers.base import Command, DriveContext, Observation
from roadload.controllers.closed_loop import crossing, run_closed_loop
from roadload.controllers.drive import net_energy_metrics
from roadload.controllers.energy import generic_ev, with_loss_error
from roadload.controllers.force_model import FixedForceModel
from roadload.controllers.plant import PlantStep
from roadload.road_load import RoadLoadParameters
from roadload.road_profiles import RoadProfile

PARAMS = RoadLoadParameters.from_physical(1420.0, 0.009, 0.0, 0.0, 0.7, 1.2)


class ConstantSpeedPlant:
    """v = 7 m/s from the start, 500 W at the source: the exact arrival time of a road of length L is L / 7."""

    def __init__(self, dt: float = 0.1, speed: float = 7.0, power: float = 500.0) -> None:
        self.dt, self.speed, self.power = dt, speed, power

    def reset(self) -> Observation:
        self.t, self.s = 0.0, 0.0
        return Observation(t=0.0, s=0.0, v=self.speed, a=0.0, gear=1, sample={"t": 0.0})

    def step(self, cmd):
        self.t += self.dt
        self.s += self.speed * self.dt
        obs = Observation(t=self.t, s=self.s, v=self.speed, a=0.0, gear=1, sample={"t": self.t})
        return PlantStep(obs, self.power * self.dt, self.s >= self.road_length)


class Idle:
    name = "idle"

    def reset(self, ctx):
        pass

    def act(self, obs):
        return Command(0.0, 0.0, 0.0)

    def stats(self):
        return {}


def _road(length: float) -> RoadProfile:
    s = np.arange(0.0, length + 1.0, 1.0)
    z = np.zeros_like(s)
    return RoadProfile("flat", s, z, z, z, np.full(s.size, 30.0))


def test_arrival_time_and_energy_are_interpolated_inside_the_last_step():
    length = 100.0  # 100 / 7 = 14.2857 s: the first step past the end is at 14.3 s
    plant = ConstantSpeedPlant()
    plant.road_length = length
    res = run_closed_loop(Idle(), plant, DriveContext(_road(length), generic_ev(), FixedForceModel(PARAMS)),
                          measure_from=30.0)
    m = res.metrics
    assert m["trip_time"] == pytest.approx(14.3)  # quantised to the control period
    assert m["arrival_time"] == pytest.approx(length / 7.0, abs=1e-9)
    assert m["arrival_energy_J"] == pytest.approx(500.0 * length / 7.0, rel=1e-9)
    assert m["segment_time"] == pytest.approx(70.0 / 7.0, abs=1e-9)
    assert m["segment_energy_J"] == pytest.approx(500.0 * 70.0 / 7.0, rel=1e-9)
    assert m["arrival_speed"] == pytest.approx(7.0) and m["segment_start_speed"] == pytest.approx(7.0)
    with pytest.raises(ValueError, match="measure_from"):
        run_closed_loop(Idle(), plant, DriveContext(_road(length), generic_ev(), FixedForceModel(PARAMS)),
                        measure_from=150.0)


def test_crossing_interpolates_and_reports_a_never_reached_position():
    track = (np.array([0.0, 1.0, 2.0]), np.array([0.0, 10.0, 30.0]), np.array([5.0, 15.0, 25.0]),
             np.array([0.0, 100.0, 300.0]))
    assert crossing(track, 20.0) == pytest.approx((1.5, 200.0, 20.0))
    assert crossing(track, 0.0) == pytest.approx((0.0, 0.0, 5.0))
    assert all(np.isnan(crossing(track, 31.0)))


def test_net_energy_books_the_kinetic_energy_left_at_arrival_at_its_marginal_source_cost():
    metrics = {"segment_energy_J": 1.0e6, "segment_start_speed": 10.0, "arrival_speed": 20.0}
    ev = generic_ev()
    out = net_energy_metrics(metrics, 1500.0, ev)
    ke = 0.5 * 1500.0 * (20.0 ** 2 - 10.0 ** 2)  # 225 kJ more kinetic energy at arrival than at the start
    assert out["kinetic_energy_change_J"] == pytest.approx(ke)
    assert out["energy_net_J"] == pytest.approx(1.0e6 - ke)
    # an ICE: each J of wheel work costs 1 / eta_i J of fuel (the Willans line)
    ice = replace(with_loss_error(ev, 0.0), kind="ice", indicated_efficiency=0.45, shift_speeds=())
    assert net_energy_metrics(metrics, 1500.0, ice)["energy_net_J"] == pytest.approx(1.0e6 - ke / 0.45)
