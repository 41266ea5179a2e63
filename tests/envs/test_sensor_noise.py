"""Each sensor channel draws its own white-noise sequence: on a steady cruise the sample-to-sample changes of the
measured channels (noise-dominated at 100 Hz) are uncorrelated across channels, and each has the spread of its
own noise_std."""

import numpy as np
import pytest

from roadload.envs import simulate
from roadload.presets import get_preset
from roadload.road_profiles import RoadProfile

CHANNELS = ["wheel_speed_fl", "wheel_speed_fr", "wheel_speed_rl", "wheel_speed_rr", "vehicle_speed", "accel_x",
            "accel_y", "yaw_rate", "drive_torque", "engine_speed", "battery_current", "battery_voltage",
            "steering_wheel_angle"]


@pytest.fixture(scope="module")
def steady_changes():
    s = np.arange(0.0, 4001.0, 5.0)
    z = np.zeros_like(s)
    trip = simulate("bmw_i3", RoadProfile("straight", s, z, z, z, np.full_like(s, 20.0)), seed=5, duration=90.0)
    m = trip.measured[trip.measured["t"] > 40.0]  # cruising at 20 m/s: 5000 samples
    d = np.array([np.diff(m[n].to_numpy()) for n in CHANNELS])
    return d[:, np.all(np.isfinite(d), axis=0)]


def test_channels_draw_independent_noise(steady_changes):
    rho = np.corrcoef(steady_changes)
    off = np.abs(rho[~np.eye(len(CHANNELS), dtype=bool)])
    # independent sequences: |rho| ~ 1/sqrt(5000) = 0.014 (measured max 0.04 over 78 pairs); a shared sequence
    # gives 1.0
    assert steady_changes.shape[1] > 4500
    assert off.max() < 0.1, {(CHANNELS[i], CHANNELS[j]): round(rho[i, j], 3) for i in range(len(CHANNELS))
                             for j in range(i) if abs(rho[i, j]) >= 0.1}


def test_each_channel_has_its_own_noise_level(steady_changes):
    """The change between samples of white noise has std sqrt(2) sigma (quantisation adds res^2 / 6)."""
    spec = get_preset("bmw_i3").sensors.channels
    for name, d in zip(CHANNELS[:5], steady_changes[:5]):  # the speed channels: the car's own speed is smooth
        sigma, res = spec[name].noise_std, spec[name].resolution
        expected = np.sqrt(2 * sigma ** 2 + res ** 2 / 6)
        assert np.std(d) == pytest.approx(expected, rel=0.15), name
