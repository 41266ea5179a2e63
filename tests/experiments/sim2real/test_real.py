"""The real i3 world's data rule: a trip whose logged HVAC power its own battery does not deliver at standstill is
left out of the HVAC reference, by one rule for every trip."""

from __future__ import annotations

import numpy as np
import pytest

from roadload.experiments.sim2real.real import hvac_contradiction
from roadload.sim2real import SimConfig
from roadload.sim2real.diagnose import sim_trips


@pytest.fixture(scope="module")
def city_trip():
    trip = sim_trips(SimConfig.load("bmw_i3"), (("city", 91),), 300.0)[0]
    still = (np.abs(trip.channel("vehicle_speed")) < 0.3) & (np.abs(trip.channel("drive_torque")) < 2.0)
    assert still.sum() > 10.0 * trip.sample_rate      # the city road stops at lights
    return trip, still


def test_hvac_channel_that_the_battery_delivers_passes(city_trip):
    trip, still = city_trip
    battery = trip.channel("battery_voltage") * trip.channel("battery_current")
    hvac = np.where(still, np.median(battery[still]) - 300.0, 2000.0)   # 300 W of 12 V loads besides the HVAC
    assert hvac_contradiction(trip, hvac) is None
    assert hvac_contradiction(trip, np.zeros(len(trip))) is None


def test_hvac_channel_above_the_battery_power_at_standstill_is_named(city_trip):
    trip, still = city_trip
    battery = trip.channel("battery_voltage") * trip.channel("battery_current")
    drawn = float(np.median(battery[still]))
    why = hvac_contradiction(trip, np.full(len(trip), drawn + 4000.0))
    assert why is not None and f"{drawn + 4000.0:.0f} W" in why and f"delivers {drawn:.0f} W" in why


def test_too_short_a_standstill_says_nothing(city_trip):
    trip, still = city_trip
    moving = trip.copy()
    moving.measured["vehicle_speed"] = np.where(still, 5.0, trip.channel("vehicle_speed"))
    assert hvac_contradiction(moving, np.full(len(trip), 1e5)) is None
