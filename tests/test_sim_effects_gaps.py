"""Effects added for the robustness testbed: outlier bursts, single-channel dropouts, wind / parameter ramps and
long cruise stretches."""

import numpy as np
import pytest

from roadload.envs import EffectsError, SensorConfigError, Simulator, simulate
from roadload.road_profiles import RoadProfile


def road(length=3000.0, limit=25.0, stops=()):
    s = np.arange(0.0, length + 1.0, 10.0)
    lim = limit(s) if callable(limit) else np.full_like(s, limit)
    z = np.zeros_like(s)
    return RoadProfile("test", s, z, z, z, lim, stops=np.asarray(stops, float))


def runs(mask):
    """Lengths of the runs of True in a boolean array."""
    d = np.diff(np.concatenate([[0], mask.astype(int), [0]]))
    return np.flatnonzero(d == -1) - np.flatnonzero(d == 1)


def test_outlier_bursts_have_the_requested_length_on_the_selected_channel():
    sim = Simulator("gt_rwd", road(4000.0),
                    effects="sensor_outliers:rate=0.001,magnitude=5,burst_length=25,channel=drive_torque", seed=3)
    for _ in range(900):  # step API: observe() must equal the trip's rows, also across chunk boundaries
        sim.step(None)
    obs = sim.observe()
    sim.run()
    trip = sim.to_trip()
    clean = simulate("gt_rwd", road(4000.0), seed=3)
    n = min(len(trip), len(clean))
    dev = np.abs(trip.measured["drive_torque"].to_numpy()[:n] - clean.measured["drive_torque"].to_numpy()[:n])
    lengths = runs(dev > 1e-9)
    assert lengths.size >= 5
    assert lengths.min() == 25 and np.mean(lengths == 25) > 0.8  # overlapping bursts merge into longer runs
    # every other channel untouched
    for ch in ("vehicle_speed", "accel_x", "brake_pressure_front"):
        np.testing.assert_array_equal(trip.measured[ch].to_numpy()[:n], clean.measured[ch].to_numpy()[:n])
    row = trip.measured.iloc[8999]  # 900 steps x 10 substeps
    assert obs["drive_torque"] == row["drive_torque"]
    # burst_length 1 is the old behaviour, bit for bit
    a = simulate("gt_rwd", road(1500.0), effects="sensor_outliers:rate=0.01", seed=4)
    b = simulate("gt_rwd", road(1500.0), effects="sensor_outliers:rate=0.01,burst_length=1", seed=4)
    np.testing.assert_array_equal(a.measured.to_numpy(), b.measured.to_numpy())


def test_dropouts_on_a_single_channel_and_clear_errors():
    t = simulate("gt_rwd", road(3000.0), effects="sensor_dropouts:rate=600,channel=accel_x", seed=5)
    nan = t.measured.isna()
    assert 0.02 < nan["accel_x"].mean() < 0.3
    assert not nan.drop(columns=["accel_x"]).any().any()
    two = simulate("gt_rwd", road(1500.0), effects="sensor_dropouts:rate=600,channel=accel_x+yaw_rate", seed=5)
    assert two.measured["accel_x"].isna().any() and two.measured["yaw_rate"].isna().any()
    assert not two.measured["vehicle_speed"].isna().any()
    with pytest.raises(SensorConfigError, match="no_such_channel"):
        Simulator("gt_rwd", road(), effects="sensor_dropouts:channel=no_such_channel")
    with pytest.raises(SensorConfigError, match="mode 'nan'"):
        Simulator("gt_rwd", road(), effects="sensor_dropouts:channel=accel_x,mode=missing")
    with pytest.raises(SensorConfigError, match="whole number"):
        Simulator("gt_rwd", road(), effects="sensor_outliers:burst_length=2.5")
    with pytest.raises(EffectsError, match="burst_length"):
        Simulator("gt_rwd", road(), effects="sensor_outliers:burst_length=0")
