"""Streamed simulation (simulate(out=...)): the file holds exactly the in-memory trip's measured channels (chunk
boundaries, sensor latencies, dropouts, decimation), the truth within the storage precision, and memory is
bounded by a chunk."""

import numpy as np
import pytest

from roadload import Trip, TripError
from roadload.envs.simulator import SimulationError, Simulator, simulate
from roadload.road_profiles import load_profile
from roadload.trip import TripWriter


def _compare(mem: Trip, path, truth_rtol):
    back = Trip.load(path)
    assert list(back.measured.columns) == list(mem.measured.columns)
    assert back.measured.equals(mem.measured)           # quantised channels come back on their grid, bit for bit
    assert back.units == mem.units and back.truth_units == mem.truth_units
    assert len(back.truth) == len(mem.truth)
    for c in mem.truth.columns:
        x, y = mem.truth[c].to_numpy(), back.truth[c].to_numpy()
        assert y.dtype == np.float64
        scale = max(float(np.nanmax(np.abs(x))), 1e-12)
        err = float(np.nanmax(np.abs(x - y))) / scale if x.size else 0.0
        assert err <= truth_rtol, (c, err)
    return back


@pytest.mark.parametrize("effects, sensors_rate", [
    (None, None),
    (["sensor_dropouts:mode=missing,rate=400", "sensor_latency:extra=0.05", "wind"], None),
    (["sensor_outliers", "payload"], 50.0),
])
def test_streamed_file_equals_the_in_memory_trip(tmp_path, effects, sensors_rate):
    road = load_profile("hilly", seed=2, length=6000.0)
    sensors = None
    if sensors_rate is not None:
        from roadload.presets import get_preset
        import dataclasses
        sensors = dataclasses.replace(get_preset("bmw_i3").sensors, sample_rate=sensors_rate)
    mem = simulate("bmw_i3", road, effects=effects, sensors=sensors, seed=4, duration=150.0)
    path = simulate("bmw_i3", road, effects=effects, sensors=sensors, seed=4, duration=150.0,
                    out=tmp_path / "s.parquet", chunk_seconds=13.7)   # many chunks, boundaries mid-latency
    back = _compare(mem, path, truth_rtol=2.0 ** -15 + 2.0 ** -24)  # truth: 15 significant bits in float32
    assert back.meta == mem.meta
    exact = simulate("bmw_i3", road, effects=effects, sensors=sensors, seed=4, duration=150.0,
                     out=tmp_path / "e.parquet", precision="exact", chunk_seconds=40.0)
    assert Trip.load(exact).equals(mem)                  # precision 'exact' streamed = in memory, bit for bit


def test_chunked_reader_and_info(tmp_path, hilly_road):
    road = hilly_road
    path = simulate("bmw_i3", road, seed=2, duration=100.0, out=tmp_path / "c.parquet", chunk_seconds=30.0)
    info = Trip.read_info(path)
    assert info["n_measured"] == 10_000 and info["precision"] == "compact" and "vehicle_speed" in info["channels"]
    whole = Trip.load(path, channels=["vehicle_speed"], truth_channels=["speed"])
    assert whole.channels == ["vehicle_speed"] and list(whole.truth.columns) == ["t", "speed"]
    parts = list(Trip.iter_chunks(path, channels=["vehicle_speed"], truth_channels=[], rows=3000))
    assert [len(p) for p in parts] == [3000, 3000, 3000, 1000] and all(p.truth is None for p in parts)
    np.testing.assert_array_equal(np.concatenate([p.channel("vehicle_speed") for p in parts]),
                                  whole.channel("vehicle_speed"))


def test_streamed_simulator_refuses_whole_log_queries_and_failed_runs_leave_nothing(tmp_path, hilly_road):
    road = hilly_road
    sim = Simulator("bmw_i3", road, seed=0, log_capacity=500)
    with sim.trip_writer(tmp_path / "x.parquet") as w:
        sim.run(duration=60.0, chunk_seconds=10.0, writer=w)
        w.close(sim.trip_meta())
    assert sim._log.shape[1] < 2_500 and sim._log_base > 0   # the log held a chunk, not the 6000 substeps
    with pytest.raises(SimulationError, match="streamed"):
        sim.to_trip()
    with pytest.raises(TripError, match="precision"):
        simulate("bmw_i3", road, seed=0, duration=5.0, out=tmp_path / "p.parquet", precision="half")
    with pytest.raises(RuntimeError):
        with TripWriter(tmp_path / "y.parquet", {"t": "s"}, None) as w:
            w.write(Trip.load(tmp_path / "x.parquet", channels=[], truth_channels=[]).measured)
            raise RuntimeError("boom")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["x.parquet"]
