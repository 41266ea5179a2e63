"""Trip files are open Parquet: pandas, polars and DuckDB read a simulated and a real imported trip without roadload,
with 't' in seconds and every channel in SI within its resolution of ``Trip.load``; units are Arrow field metadata,
the metadata one JSON key-value entry; older formats stay readable and ``convert_trip_file`` rewrites them."""

import json

import duckdb
import numpy as np
import pandas as pd
import polars as pl
import pyarrow.parquet as pq
import pytest

from roadload import Trip, TripError
from roadload.envs.simulator import simulate
from roadload.io import import_log
from roadload.trip import convert_trip_file
from roadload.trip_storage import TRUTH_SIGNIFICANT_BITS, round_significant


def _readers(path):
    """The file as pandas, polars and DuckDB read it, each as a pandas frame of float64 columns."""
    frames = {"pandas": pd.read_parquet(path), "polars": pl.read_parquet(path).to_pandas()}
    frames["duckdb"] = duckdb.sql(f"SELECT * FROM read_parquet('{path}')").df()
    return frames


def _within_resolution(frame: pd.DataFrame, trip: Trip, path) -> None:
    """Every measured channel (rows of the measured time base) within half its resolution -- or float32's
    relative precision where it has none -- of Trip.load; truth columns equal to Trip.load's truth."""
    fields = {f.name: f.metadata or {} for f in pq.read_schema(path)}
    rows = frame["measured_row"].to_numpy(bool) if "measured_row" in frame else np.ones(len(frame), bool)
    m = frame[rows].reset_index(drop=True)
    np.testing.assert_array_equal(m["t"].to_numpy(float), trip.t)          # t in seconds, exactly
    assert fields["t"][b"unit"] == b"s"
    for c in trip.channels:
        assert fields[c][b"unit"].decode() == trip.units[c]
        x, y = m[c].to_numpy(float), trip.channel(c)
        step = float(fields[c].get(b"resolution", b"0"))
        tol = np.maximum(step / 2, np.abs(y) * 2.0 ** -23)
        ok = np.isnan(x) == np.isnan(y)
        assert ok.all(), c
        assert np.all(np.abs(x - y)[~np.isnan(y)] <= tol[~np.isnan(y)]), c
    if trip.truth is not None:
        trows = frame["truth_row"].to_numpy(bool) if "truth_row" in frame else np.ones(len(frame), bool)
        tr = frame[trows].reset_index(drop=True)
        np.testing.assert_array_equal(tr["t"].to_numpy(float), trip.truth["t"].to_numpy())
        for c in trip.truth.columns[1:]:
            np.testing.assert_array_equal(tr[f"truth/{c}"].to_numpy(float), trip.true(c))


@pytest.fixture(scope="module")
def simulated(tmp_path_factory, hilly_road):
    path = tmp_path_factory.mktemp("open") / "sim.parquet"
    simulate("bmw_i3", hilly_road, effects=["sensor_dropouts:rate=400"], seed=3, duration=60.0, out=path,
             chunk_seconds=17.0)
    return path


def test_pandas_polars_duckdb_read_a_simulated_trip(simulated):
    trip = Trip.load(simulated)
    frames = _readers(simulated)
    for name, frame in frames.items():
        assert len(frame) == len(trip) == 6000, name
        _within_resolution(frame, trip, simulated)
    # the measured quantised channels come back on the sensor grid exactly (0.01 m/s steps)
    speed = trip.channel("vehicle_speed")
    finite = speed[np.isfinite(speed)]
    np.testing.assert_array_equal(finite, np.round(finite / 0.01) * 0.01)
    assert np.isnan(speed).sum() > 0                          # dropouts stay NaN, not null padding
    # the metadata is one JSON entry; units live in the field metadata
    md = pq.ParquetFile(simulated).metadata.metadata
    payload = json.loads(md[b"roadload"])
    assert payload["version"] == 4 and payload["precision"] == "compact" and payload["meta"]["source"] == "sim"
    schema = pq.read_schema(simulated)
    assert schema.field("truth/tractive_force").metadata[b"unit"] == b"N"
    assert schema.field("vehicle_speed").metadata[b"resolution"] == b"0.01"
    types = {f.name: str(f.type) for f in schema}
    assert types["t"] == "double" and types["truth/position"] == "double" and types["vehicle_speed"] == "float"
    assert types["truth/tractive_force"] == "float"


def test_truth_is_rounded_to_its_significant_bits_and_kept_apart(simulated, hilly_road):
    mem = simulate("bmw_i3", hilly_road, effects=["sensor_dropouts:rate=400"], seed=3, duration=60.0)
    back = Trip.load(simulated)
    assert back.measured.equals(mem.measured)                     # measured: bit for bit on the sensor grid
    assert not any(c.startswith("truth/") for c in back.measured.columns)
    force = mem.true("tractive_force").astype(np.float32)
    expect = round_significant(force, TRUTH_SIGNIFICANT_BITS).astype(float)
    np.testing.assert_array_equal(back.true("tractive_force"), expect)
    rel = np.abs(back.true("tractive_force") - mem.true("tractive_force")) / np.abs(mem.true("tractive_force"))
    assert np.nanmax(rel) <= 2.0 ** -TRUTH_SIGNIFICANT_BITS + 2.0 ** -24    # 3.1e-5 relative at most
    assert back.true("position")[-1] == pytest.approx(mem.true("position")[-1], abs=1e-6)   # float64


def test_union_time_base_when_sensors_are_decimated(tmp_path, hilly_road):
    """Measured at 50 Hz, truth at 100 Hz: one row per instant, measured channels null on truth-only rows, and the
    two bool columns say which rows belong to which; every reader sees the same."""
    from dataclasses import replace

    from roadload.presets import get_preset
    sensors = replace(get_preset("bmw_i3").sensors, sample_rate=50.0)
    path = simulate("bmw_i3", hilly_road, sensors=sensors, seed=1, duration=20.0, out=tmp_path / "d.parquet",
                    chunk_seconds=7.0)
    trip = Trip.load(path)
    assert len(trip) == 1000 and len(trip.truth) == 2000
    for name, frame in _readers(path).items():
        assert len(frame) == 2000 and int(frame["measured_row"].sum()) == 1000, name
        assert frame.loc[~frame["measured_row"].astype(bool), "vehicle_speed"].isna().all()
        _within_resolution(frame, trip, path)
    chunks = list(Trip.iter_chunks(path, rows=333))
    assert sum(len(c) for c in chunks) == 1000 and sum(len(c.truth) for c in chunks) == 2000


@pytest.mark.shared_data
def test_pandas_polars_duckdb_read_a_real_imported_trip(tmp_path, shared_data):
    trip = import_log(shared_data / "openxc_ford_trace" / "raw" / "drivingnew.openxc.txt", "openxc")
    for precision in ("exact", "compact"):
        path = trip.save(tmp_path / f"real_{precision}.parquet", precision=precision)
        back = Trip.load(path)
        assert back.units == trip.units and back.meta == trip.meta
        for name, frame in _readers(path).items():
            assert len(frame) == len(trip), name
            _within_resolution(frame, back, path)
        for c in trip.channels:   # and Trip.load within float32 of the imported values
            np.testing.assert_allclose(back.channel(c), trip.channel(c), rtol=2.0 ** -23, atol=0, equal_nan=True)


def test_exact_precision_is_bit_for_bit_and_keeps_dtypes(tmp_path):
    t = np.arange(500) / 100.0
    measured = pd.DataFrame({"t": t, "vehicle_speed": np.sin(t) + 10.0, "gear": (np.arange(500) // 100).astype(
        np.int64), "regen_braking": np.arange(500) % 2 == 0})
    trip = Trip(measured, {"t": "s", "vehicle_speed": "m/s", "gear": "1", "regen_braking": "1"}, {"name": "x"})
    back = Trip.load(trip.save(tmp_path / "e.parquet"))
    assert back.equals(trip) and back.measured["gear"].dtype == np.int64
    assert back.measured["regen_braking"].dtype == bool
    frame = pd.read_parquet(tmp_path / "e.parquet")
    assert frame["gear"].tolist() == measured["gear"].tolist()


def test_packed_opt_in_is_smaller_but_not_open_and_convert_rewrites_it(tmp_path, simulated):
    trip = Trip.load(simulated)
    packed = trip.save(tmp_path / "p.parquet", precision="packed")
    assert Trip.read_info(packed)["precision"] == "packed" and Trip.read_info(packed)["version"] == 3
    raw = pd.read_parquet(packed)
    speed = trip.channel("vehicle_speed")
    ok = np.isfinite(speed) & np.isfinite(raw["vehicle_speed"].to_numpy(float))
    assert not np.allclose(raw["vehicle_speed"].to_numpy(float)[ok], speed[ok])   # integer codes, not m/s
    assert Trip.load(packed).measured.equals(trip.measured)    # roadload decodes them
    out = convert_trip_file(packed, tmp_path / "c.parquet")
    info = Trip.read_info(out)
    assert info["version"] == 4 and info["precision"] == "compact"
    conv = Trip.load(out)
    assert conv.measured.equals(trip.measured) and conv.meta == trip.meta
    np.testing.assert_allclose(conv.true("speed"), trip.true("speed"), rtol=2.0 ** -15)
    with pytest.raises(TripError, match="other than the source"):
        convert_trip_file(out, out)


def test_chunks_must_follow_each_other_in_time(tmp_path):
    from roadload.trip import TripWriter
    t = np.arange(10) / 10.0
    with pytest.raises(TripError, match="not after the previous chunk"):
        with TripWriter(tmp_path / "w.parquet", {"t": "s", "vehicle_speed": "m/s"}, None) as w:
            w.write(pd.DataFrame({"t": t, "vehicle_speed": t}))
            w.write(pd.DataFrame({"t": t[5:], "vehicle_speed": t[5:]}))
    assert list(tmp_path.iterdir()) == []


def test_a_chunk_as_column_arrays_writes_the_file_a_dataframe_writes(tmp_path, simulated):
    """The streamed simulator hands the writer plain arrays (no pandas): the same bytes as the frame path."""
    from roadload.trip import TripWriter
    trip = Trip.load(simulated)
    units, truth_units = dict(trip.units), dict(trip.truth_units)
    paths = []
    for name, as_arrays in (("frame", False), ("arrays", True)):
        path = tmp_path / f"{name}.parquet"
        with TripWriter(path, units, truth_units, "compact", {"vehicle_speed": 0.01}) as w:
            for lo, hi in ((0, 2500), (2500, len(trip))):
                m, tr = trip.measured.iloc[lo:hi], trip.truth.iloc[lo:hi]
                if as_arrays:
                    m = {c: m[c].to_numpy() for c in m.columns}
                    tr = {c: tr[c].to_numpy() for c in tr.columns}
                w.write(m, tr)
            w.close(trip.meta)
        paths.append(path)
    assert paths[0].read_bytes() == paths[1].read_bytes()
    with pytest.raises(TripError, match="1-D array of one length"):
        with TripWriter(tmp_path / "bad.parquet", {"t": "s", "vehicle_speed": "m/s"}, None) as w:
            w.write({"t": np.arange(5.0), "vehicle_speed": np.arange(4.0)})
    assert not (tmp_path / "bad.parquet").exists()


def test_trip_file_extent_reads_the_first_and_last_rows(tmp_path, hilly_road):
    """roadload simulate's summary (duration, distance) from two columns equals the whole trip's."""
    from roadload.trip_storage import trip_file_extent
    path = simulate("bmw_i3", hilly_road, seed=4, duration=40.0, out=tmp_path / "x.parquet", chunk_seconds=15.0)
    trip = Trip.load(path)
    assert trip_file_extent(path) == (trip.t[0], trip.t[-1], trip.true("position")[-1])
    packed = simulate("bmw_i3", hilly_road, seed=4, duration=40.0, out=tmp_path / "p.parquet", precision="packed")
    t0, t1, x1 = trip_file_extent(packed)  # an older format: read chunk by chunk
    assert (t0, t1) == (trip.t[0], trip.t[-1]) and x1 == pytest.approx(trip.true("position")[-1], abs=1e-3)


def test_round_significant_keeps_the_named_bits():
    x = np.array([1.0, 1.0 + 2.0 ** -20, -3.14159265, 0.0, np.nan, np.inf, 1e-30], dtype=np.float32)
    y = round_significant(x, 15)
    assert y[0] == 1.0 and y[1] == 1.0 and y[3] == 0.0 and np.isnan(y[4]) and np.isinf(y[5])
    assert abs(y[2] + 3.14159265) <= 3.14159265 * 2.0 ** -15
    assert np.all((y[[0, 1, 2, 6]].view(np.uint32) & np.uint32((1 << 9) - 1)) == 0)   # 9 low mantissa bits zero


def test_a_format_1_file_loads_and_converts(tmp_path):
    """Format 1: columns as they are, truth prefixed, the payload in the Arrow schema metadata."""
    import pyarrow as pa

    t = np.arange(20) / 100.0
    table = pa.table({"t": t, "vehicle_speed": np.linspace(0.0, 2.0, 20), "truth/t": t,
                      "truth/mass": np.full(20, 1900.0)})
    payload = {"version": 1, "units": {"t": "s", "vehicle_speed": "m/s"}, "truth_units": {"t": "s", "mass": "kg"},
               "meta": {"name": "old"}, "n_measured": 20, "n_truth": 20}
    table = table.replace_schema_metadata({b"roadload": json.dumps(payload).encode()})
    pq.write_table(table, tmp_path / "v1.parquet")
    trip = Trip.load(tmp_path / "v1.parquet")
    assert trip.meta == {"name": "old"} and trip.true("mass")[0] == 1900.0
    np.testing.assert_array_equal(trip.channel("vehicle_speed"), np.linspace(0.0, 2.0, 20))
    out = convert_trip_file(tmp_path / "v1.parquet", tmp_path / "v4.parquet")
    assert Trip.read_info(out)["version"] == 4 and Trip.read_info(out)["precision"] == "exact"
    assert Trip.load(out).equals(trip)
    assert pq.read_schema(out).field("truth/mass").metadata[b"unit"] == b"kg"
