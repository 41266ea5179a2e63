"""The Trip's access methods, slicing, copies, equality and its contract errors, value by value; and convert_trip_file
on every file layout it reads (shared or union time base, with or without truth, each precision)."""

import json

import numpy as np
import pandas as pd
import pyarrow.parquet as pq
import pytest

from roadload import Trip, TripError
from roadload.trip import TripWriter, convert_trip_file


def _trip(n=50, truth=True, name="x"):
    t = np.arange(n) / 100.0
    measured = pd.DataFrame({"t": t, "vehicle_speed": np.linspace(0, 10, n), "gear": np.arange(n) % 7})
    units = {"t": "s", "vehicle_speed": "m/s", "gear": "1"}
    tr = pd.DataFrame({"t": t, "mass": 1900.0 + np.arange(n)}) if truth else None
    return Trip(measured, units, {"name": name, "seed": 3, "effects": ["wind"]}, tr,
                {"t": "s", "mass": "kg"} if truth else {})


# ------------------------------------------------------------------------------------------ access
def test_access_methods_return_the_channels_and_name_what_is_missing():
    trip = _trip()
    assert trip.has("vehicle_speed") and trip.has("t", "gear") and not trip.has("gear", "accel_x")
    assert trip.has()
    np.testing.assert_array_equal(trip.channel("vehicle_speed"), np.linspace(0, 10, 50))
    assert trip.channel("gear").dtype == float and trip.channel("gear")[8] == 1.0
    np.testing.assert_array_equal(trip.true("mass"), 1900.0 + np.arange(50))
    assert trip.true("mass").dtype == float
    trip.require("vehicle_speed", "gear")  # present: no error
    with pytest.raises(TripError, match=r"trip 'x' lacks required channels \['accel_x', 'vehicle_sped'\] \(did "
                                        r"you mean 'vehicle_speed'\?\); it has \['vehicle_speed', 'gear'\]"):
        trip.require("vehicle_speed", "accel_x", "vehicle_sped")
    with pytest.raises(TripError, match=r"trip 'x' lacks required channels \['yaw_rate'\]"):
        trip.channel("yaw_rate")
    with pytest.raises(TripError, match=r"ground truth has no channel 'mas' \(did you mean 'mass'\?\); it has "
                                        r"\['t', 'mass'\]"):
        trip.true("mas")
    with pytest.raises(TripError, match=r"trip 'x' has no ground truth \(not simulated\)"):
        _trip(truth=False).true("mass")
    nameless = Trip(trip.measured, trip.units)
    with pytest.raises(TripError, match=r"trip '\?' lacks required channels"):
        nameless.require("accel_x")
    with pytest.raises(TripError, match=r"trip '\?' has no ground truth"):
        nameless.true("mass")


def test_to_pandas_joins_truth_row_by_row_on_request_only():
    trip = _trip()
    plain = trip.to_pandas()
    assert list(plain.columns) == ["t", "vehicle_speed", "gear"]
    plain.loc[0, "vehicle_speed"] = 99.0  # a copy
    assert trip.channel("vehicle_speed")[0] == 0.0
    joined = trip.to_pandas(include_truth=True)
    assert list(joined.columns) == ["t", "vehicle_speed", "gear", "truth/mass"]
    np.testing.assert_array_equal(joined["truth/mass"], 1900.0 + np.arange(50))
    assert list(_trip(truth=False).to_pandas(include_truth=True).columns) == ["t", "vehicle_speed", "gear"]
    short = Trip(trip.measured, trip.units, {}, trip.truth.iloc[:20], trip.truth_units)
    with pytest.raises(TripError, match="truth and measured frames differ in length; cannot join them row by row"):
        short.to_pandas(include_truth=True)
    assert len(short.to_pandas()) == 50


def test_slice_keeps_start_drops_end_and_cuts_truth_on_its_own_time_base():
    trip = _trip()
    trip = Trip(trip.measured, trip.units, {"name": "x", "nested": {"a": [1]}},
                pd.DataFrame({"t": np.arange(25) / 50.0, "mass": np.arange(25.0)}), trip.truth_units)
    part = trip.slice(0.1, 0.2)
    np.testing.assert_array_equal(part.t, np.arange(10, 20) / 100.0)  # 0.1 <= t < 0.2
    np.testing.assert_array_equal(part.channel("vehicle_speed"), trip.channel("vehicle_speed")[10:20])
    np.testing.assert_array_equal(part.true("t"), [0.1, 0.12, 0.14, 0.16, 0.18])
    np.testing.assert_array_equal(part.true("mass"), [5.0, 6.0, 7.0, 8.0, 9.0])
    assert part.units == trip.units and part.truth_units == trip.truth_units and part.meta == trip.meta
    assert list(part.measured.index) == list(range(10))  # a fresh index
    part.meta["nested"]["a"].append(2)  # the metadata is a deep copy
    part.units["gear"] = "-"
    part.measured.loc[0, "vehicle_speed"] = -1.0
    assert trip.meta["nested"]["a"] == [1] and trip.units["gear"] == "1" and trip.channel("vehicle_speed")[10] > 0
    real = _trip(truth=False).slice(0.0, 0.05)
    assert len(real) == 5 and real.truth is None and real.truth_units == {}
    assert len(trip.slice(0.0, 10.0)) == 50


def test_copy_is_equal_and_independent():
    trip = _trip()
    trip.meta["nested"] = {"a": [1]}
    dup = trip.copy()
    assert dup.equals(trip) and dup is not trip
    dup.meta["nested"]["a"].append(2)
    dup.units["gear"] = "-"
    dup.truth_units["mass"] = "g"
    dup.measured.loc[0, "gear"] = 5
    dup.truth.loc[0, "mass"] = 0.0
    assert trip.meta["nested"]["a"] == [1] and trip.units["gear"] == "1" and trip.truth_units["mass"] == "kg"
    assert trip.channel("gear")[0] == 0.0 and trip.true("mass")[0] == 1900.0
    real = _trip(truth=False).copy()
    assert real.truth is None and real.equals(_trip(truth=False))


def test_equals_tells_every_difference():
    trip = _trip()
    assert trip.equals(_trip()) and not trip.equals("trip")
    assert not trip.equals(_trip(name="y"))                                    # meta
    renamed = trip.measured.rename(columns={"gear": "my_gear"})
    assert not Trip(renamed, {"t": "s", "vehicle_speed": "m/s", "my_gear": "1"}, trip.meta, trip.truth,
                    trip.truth_units).equals(Trip(renamed, {"t": "s", "vehicle_speed": "m/s", "my_gear": "rad"},
                                                  trip.meta, trip.truth, trip.truth_units))  # units
    other = trip.measured.assign(vehicle_speed=trip.measured["vehicle_speed"] + 1e-12)
    assert not trip.equals(Trip(other, trip.units, trip.meta, trip.truth, trip.truth_units))  # measured values
    assert not trip.equals(Trip(trip.measured, trip.units, trip.meta))         # truth missing
    assert not Trip(trip.measured, trip.units, trip.meta).equals(trip)
    assert not trip.equals(Trip(trip.measured, trip.units, trip.meta, trip.truth.assign(mass=0.0),
                                trip.truth_units))                             # truth values
    assert not trip.equals(Trip(trip.measured, trip.units, trip.meta, trip.truth.rename(columns={"mass": "m"}),
                                {"t": "s", "m": "kg"}))                        # truth units
    assert _trip(truth=False).equals(_trip(truth=False))
    dropped = trip.copy()
    dropped.truth = None  # truth removed after construction, truth units left as they were
    assert not dropped.equals(trip) and not trip.equals(dropped)


def test_duration_sample_rate_and_channels():
    trip = _trip(n=51)
    assert trip.duration == pytest.approx(0.5) and trip.sample_rate == pytest.approx(100.0)
    assert trip.channels == ["vehicle_speed", "gear"] and trip.is_simulated and len(trip) == 51
    one = Trip({"t": [3.0], "vehicle_speed": [1.0]}, {"t": "s", "vehicle_speed": "m/s"})
    assert one.duration == 0.0 and np.isnan(one.sample_rate) and not one.is_simulated


# ------------------------------------------------------------------------------------------ contract errors
def test_frames_of_the_wrong_kind_and_index_are_handled():
    with pytest.raises(TripError, match=r"measured: expected a pandas DataFrame or a mapping of channel name to "
                                        r"1-D array, got ndarray"):
        Trip(np.zeros((3, 2)), {"t": "s"})
    with pytest.raises(TripError, match=r"truth: expected a pandas DataFrame .* got list"):
        Trip({"t": [0.0, 1.0]}, {"t": "s"}, {}, [[0.0]], {"t": "s"})
    # a DataFrame keeps its values but gets a fresh 0..n-1 index
    frame = pd.DataFrame({"t": [0.0, 0.1, 0.2], "vehicle_speed": [1.0, 2.0, 3.0]}, index=[7, 8, 9])
    trip = Trip(frame, {"t": "s", "vehicle_speed": "m/s"})
    assert list(trip.measured.index) == [0, 1, 2] and trip.channel("vehicle_speed")[0] == 1.0
    # unequal lengths without a 't' name the first channel as reference
    with pytest.raises(TripError, match=r"measured: channels of unequal length: 'a' has 3 samples, 'b' has 2 "
                                        r"\(every channel needs one value per sample of 't'"):
        Trip({"a": np.zeros(3), "b": np.zeros(2)}, {"a": "1", "b": "1"})
    with pytest.raises(TripError, match=r"channel 't' must be a 1-D array, got shape \(\)"):
        Trip({"t": 0.0}, {"t": "s"})


def test_time_channel_errors_give_the_index_and_values():
    base = {"t": "s", "vehicle_speed": "m/s"}
    with pytest.raises(TripError, match=r"measured: time channel 't' contains NaN/inf at index 2"):
        Trip({"t": [0.0, 0.1, np.nan, 0.3], "vehicle_speed": np.ones(4)}, base)
    with pytest.raises(TripError, match=r"measured: time channel 't' contains NaN/inf at index 0"):
        Trip({"t": [np.inf, 0.1], "vehicle_speed": np.ones(2)}, base)
    with pytest.raises(TripError, match=r"measured: time channel 't' is not strictly increasing at index 3 "
                                        r"\(t=0.2 then 0.2\)"):
        Trip({"t": [0.0, 0.1, 0.2, 0.2, 0.4], "vehicle_speed": np.ones(5)}, base)
    with pytest.raises(TripError, match=r"at index 1 \(t=0.5 then 0.1\)"):
        Trip({"t": [0.5, 0.1], "vehicle_speed": np.ones(2)}, base)
    with pytest.raises(TripError, match=r"truth: time channel 't' is not strictly increasing at index 1"):
        Trip({"t": [0.0, 0.1]}, {"t": "s"}, {}, {"t": [0.1, 0.0]}, {"t": "s"})
    with pytest.raises(TripError, match=r"truth: missing the time channel 't' \[s\]"):
        Trip({"t": [0.0, 0.1]}, {"t": "s"}, {}, {"mass": [1.0, 1.0]}, {"mass": "kg"})
    # one sample, or none, is a valid time base
    assert len(Trip({"t": [0.0], "vehicle_speed": [1.0]}, base)) == 1
    assert len(Trip({"t": np.zeros(0), "vehicle_speed": np.zeros(0)}, base)) == 0


def test_column_and_unit_errors_name_the_channel():
    with pytest.raises(TripError, match=r"measured: channel 'label' is not numeric \(dtype "):
        Trip(pd.DataFrame({"t": [0.0, 0.1], "label": ["a", "b"]}), {"t": "s", "label": "1"})
    with pytest.raises(TripError, match=r"measured: units given for channels that do not exist: \['accel_x'\]"):
        Trip({"t": [0.0, 0.1]}, {"t": "s", "accel_x": "m/s^2"})
    with pytest.raises(TripError, match=r"measured: no unit given for channels \['vehicle_speed'\]"):
        Trip({"t": [0.0, 0.1], "vehicle_speed": [1.0, 2.0]}, {"t": "s"})
    with pytest.raises(TripError, match=r"measured channel 't' has unit 'ms', the catalogue says 's' \(convert to "
                                        r"SI before building a Trip\)"):
        Trip({"t": [0.0, 0.1]}, {"t": "ms"})
    with pytest.raises(TripError, match=r"truth_units given without a truth frame"):
        Trip({"t": [0.0, 0.1]}, {"t": "s"}, {}, None, {"t": "s"})
    with pytest.raises(TripError, match=r"measured: channel name 'a\\tb' is empty or has surrounding whitespace or "
                                        r"control characters"):
        Trip({"t": [0.0], "a\tb": [1.0]}, {"t": "s", "a\tb": "1"})
    with pytest.raises(TripError, match=r"measured: duplicate channel names \['gear'\]"):
        Trip(pd.DataFrame([[0.0, 1.0, 2.0]], columns=["t", "gear", "gear"]), {"t": "s", "gear": "1"})
    with pytest.raises(TripError, match=r"channel name 'truth/mass' is reserved by the trip file layout \(no "
                                        r"'truth/' prefix, not \['measured_row', 'truth_row'\]\)"):
        Trip({"t": [0.0], "truth/mass": [1.0]}, {"t": "s", "truth/mass": "kg"})
    with pytest.raises(TripError, match=r"meta must be JSON-serialisable: .*set"):
        Trip({"t": [0.0]}, {"t": "s"}, {"tags": {1, 2}})
    with pytest.raises(TripError, match=r"meta must be JSON-serialisable"):
        Trip({"t": [0.0]}, {"t": "s"}, {"x": float("nan"), "y": object()})
    # names that differ by inner whitespace only are still a clash; different names are fine
    with pytest.raises(TripError, match=r"'my signal' and 'mysignal' differ only in case or whitespace"):
        Trip({"t": [0.0], "my signal": [1.0], "mysignal": [2.0]}, {"t": "s", "my signal": "1", "mysignal": "1"})
    assert Trip({"t": [0.0], "sig_a": [1.0], "sig_b": [2.0]}, {"t": "s", "sig_a": "1", "sig_b": "1"}).channels == [
        "sig_a", "sig_b"]


def test_units_and_meta_are_copied_into_the_trip():
    units = {"t": "s", "vehicle_speed": "m/s"}
    truth_units = {"t": "s", "mass": "kg"}
    trip = Trip({"t": [0.0, 0.1], "vehicle_speed": [1.0, 2.0]}, units, {}, {"t": [0.0], "mass": [1.0]}, truth_units)
    units["vehicle_speed"] = "km/h"
    truth_units["mass"] = "g"
    assert trip.units == {"t": "s", "vehicle_speed": "m/s"} and trip.truth_units == {"t": "s", "mass": "kg"}
    assert type(trip.units) is dict and isinstance(trip.truth, pd.DataFrame)


# ------------------------------------------------------------------------------------------ files
def test_save_and_load_subsets_and_chunks(tmp_path):
    trip = _trip(n=300)
    path = trip.save(tmp_path / "a.parquet")
    assert path == tmp_path / "a.parquet"
    info = Trip.read_info(path)
    assert info["n_measured"] == 300 and info["channels"] == ["vehicle_speed", "gear"]
    assert info["truth_channels"] == ["mass"] and info["meta"] == trip.meta
    sub = Trip.load(path, channels=["gear"], truth_channels=[])
    assert sub.channels == ["gear"] and sub.truth is None and sub.units == {"t": "s", "gear": "1"}
    only_truth = Trip.load(path, channels=[], truth_channels=["mass"])
    assert only_truth.channels == [] and only_truth.true("mass")[299] == 2199.0
    parts = list(Trip.iter_chunks(path, channels=["vehicle_speed"], truth_channels=["mass"], rows=128))
    assert [len(p) for p in parts] == [128, 128, 44]
    assert all(p.channels == ["vehicle_speed"] and p.meta == trip.meta for p in parts)
    assert list(parts[1].measured.index) == list(range(128)) and list(parts[1].truth.index) == list(range(128))
    np.testing.assert_array_equal(np.concatenate([p.true("mass") for p in parts]), trip.true("mass"))
    assert len(list(Trip.iter_chunks(path))) == 1
    real = _trip(truth=False)
    back = Trip.load(real.save(tmp_path / "r.parquet"))
    assert back.truth is None and back.truth_units == {} and back.equals(real)


def test_save_writes_sensor_resolutions_and_precision(tmp_path):
    trip = _trip(n=100)
    trip.meta["sensors"] = {"channels": {"vehicle_speed": {"resolution": 0.5}}}
    path = trip.save(tmp_path / "c.parquet", precision="compact")
    field = pq.read_schema(path).field("vehicle_speed")
    assert field.metadata[b"resolution"] == b"0.5"
    assert Trip.read_info(path)["precision"] == "compact"
    np.testing.assert_array_equal(Trip.load(path).channel("vehicle_speed"),
                                  np.round(trip.channel("vehicle_speed") / 0.5) * 0.5)
    assert Trip.read_info(trip.save(tmp_path / "e.parquet"))["precision"] == "exact"


def _payload(path):
    return json.loads(pq.ParquetFile(path).metadata.metadata[b"roadload"])


def test_convert_keeps_precision_resolutions_and_time_base(tmp_path):
    n = 400
    t = np.arange(n) / 100.0
    speed = np.round((5.0 + np.sin(t)) / 0.02) * 0.02
    units, truth_units = {"t": "s", "vehicle_speed": "m/s"}, {"t": "s", "speed": "m/s"}
    meta = {"name": "conv"}  # no sensors in the metadata: the resolution lives in the file only
    shared = tmp_path / "shared.parquet"
    with TripWriter(shared, units, truth_units, "compact", {"vehicle_speed": 0.02}) as w:
        for a in range(0, n, 150):
            w.write(pd.DataFrame({"t": t[a:a + 150], "vehicle_speed": speed[a:a + 150]}),
                    pd.DataFrame({"t": t[a:a + 150], "speed": 5.0 + np.sin(t[a:a + 150])}))
        w.close(meta)
    before = Trip.load(shared)
    out = convert_trip_file(shared, tmp_path / "out.parquet")
    assert out == tmp_path / "out.parquet" and _payload(out)["precision"] == "compact"
    assert _payload(out)["time_base"] == "shared" and _payload(out)["meta"] == meta
    assert pq.read_schema(out).field("vehicle_speed").metadata[b"resolution"] == b"0.02"
    assert Trip.load(out).equals(before)
    exact = convert_trip_file(shared, tmp_path / "exact.parquet", precision="exact")
    assert _payload(exact)["precision"] == "exact" and Trip.load(exact).equals(before)
    packed = convert_trip_file(shared, tmp_path / "packed.parquet", precision="packed")
    assert Trip.read_info(packed)["precision"] == "packed"
    assert Trip.load(convert_trip_file(packed, tmp_path / "back.parquet")).equals(before)  # packed -> compact
    assert _payload(tmp_path / "back.parquet")["precision"] == "compact"
    with pytest.raises(TripError, match=r"precision: expected one of \('compact', 'exact', 'packed'\), got 'lossy'"):
        convert_trip_file(shared, tmp_path / "bad.parquet", precision="lossy")
    assert not (tmp_path / "bad.parquet").exists()
    with pytest.raises(TripError, match=r"shared.parquet: convert writes a new file; give an output path other "
                                        r"than the source"):
        convert_trip_file(shared, tmp_path / "." / "shared.parquet")
    # a union time base (truth on its own, shorter time base) is read whole and written the same
    union = _trip(n=60)
    union = Trip(union.measured, union.units, union.meta, union.truth.iloc[::3].reset_index(drop=True),
                 union.truth_units)
    src = union.save(tmp_path / "union.parquet")
    conv = convert_trip_file(src, tmp_path / "union4.parquet")
    assert _payload(conv)["time_base"] == "union" and Trip.load(conv).equals(union)
    # a trip without truth
    real = _trip(truth=False)
    conv = convert_trip_file(real.save(tmp_path / "real.parquet"), tmp_path / "real4.parquet")
    assert Trip.load(conv).equals(real) and _payload(conv)["has_truth"] is False


def test_convert_of_a_union_time_base_keeps_the_stored_resolutions(tmp_path):
    """Truth on its own time base is converted whole; the channels' resolutions stored in the file (not declared in
    the metadata) are kept, so a compact file converts to the same values on the same grid."""
    t = np.arange(100) / 100.0
    speed = np.round((5.0 + np.sin(t)) / 0.02) * 0.02
    src = tmp_path / "u.parquet"
    with TripWriter(src, {"t": "s", "vehicle_speed": "m/s"}, {"t": "s", "speed": "m/s"}, "compact",
                    {"vehicle_speed": 0.02}) as w:
        w.write(pd.DataFrame({"t": t, "vehicle_speed": speed}), pd.DataFrame({"t": t[::3], "speed": t[::3]}))
        w.close({"name": "u"})
    assert _payload(src)["time_base"] == "union"
    out = convert_trip_file(src, tmp_path / "u4.parquet")
    assert _payload(out)["precision"] == "compact" and _payload(out)["time_base"] == "union"
    assert pq.read_schema(out).field("vehicle_speed").metadata[b"resolution"] == b"0.02"
    np.testing.assert_array_equal(Trip.load(out).channel("vehicle_speed"), speed)
    assert Trip.load(out).equals(Trip.load(src))


def test_convert_keeps_an_empty_or_one_row_truth(tmp_path):
    empty = Trip({"t": [0.0, 0.1], "vehicle_speed": [1.0, 2.0]}, {"t": "s", "vehicle_speed": "m/s"}, {},
                 {"t": np.zeros(0)}, {"t": "s"})
    back = Trip.load(convert_trip_file(empty.save(tmp_path / "e.parquet"), tmp_path / "e4.parquet"))
    assert back.truth is not None and len(back.truth) == 0 and back.equals(empty)
    one = Trip({"t": [0.0], "vehicle_speed": [1.0]}, {"t": "s", "vehicle_speed": "m/s"}, {},
               {"t": [0.0], "mass": [5.0]}, {"t": "s", "mass": "kg"})
    packed = one.save(tmp_path / "o.parquet", precision="packed")  # format 3 states no has_truth
    back = Trip.load(convert_trip_file(packed, tmp_path / "o4.parquet"))
    assert back.true("mass").tolist() == [5.0] and back.equals(one)


def test_chunks_read_only_the_requested_truth_and_default_to_an_hour_at_100_hz(tmp_path):
    t = np.arange(10) / 100.0
    trip = Trip({"t": t, "vehicle_speed": t}, {"t": "s", "vehicle_speed": "m/s"}, {},
                {"t": t, "mass": t + 1.0, "speed": t}, {"t": "s", "mass": "kg", "speed": "m/s"})
    path = trip.save(tmp_path / "m.parquet")
    parts = list(Trip.iter_chunks(path, truth_channels=["mass"], rows=4))
    assert [len(p) for p in parts] == [4, 4, 2] and all(list(p.truth.columns) == ["t", "mass"] for p in parts)
    assert all(p.truth is None for p in Trip.iter_chunks(path, truth_channels=[]))
    n = 360_001  # one hour at 100 Hz and one sample
    big = Trip({"t": np.arange(n) / 100.0}, {"t": "s"}).save(tmp_path / "h.parquet")
    assert [len(p) for p in Trip.iter_chunks(big)] == [360_000, 1]


def test_contract_details_the_messages_depend_on():
    # the reference channel of a length mismatch is 't' wherever it stands, every other length is named
    with pytest.raises(TripError, match=r"channels of unequal length: 't' has 10 samples, 'a' has 7, 'b' has 3 "
                                        r"\(every channel needs one value per sample of 't'; NaN marks a missing "
                                        r"value\)$"):
        Trip({"a": np.zeros(7), "t": np.arange(10.0), "b": np.zeros(3)}, {"t": "s", "a": "1", "b": "1"})
    with pytest.raises(TripError, match=r"^truth_units given without a truth frame$"):
        Trip({"t": [0.0, 0.1]}, {"t": "s"}, {}, None, {"t": "s"})
    short = _trip()
    short = Trip(short.measured, short.units, {}, short.truth.iloc[:20], short.truth_units)
    with pytest.raises(TripError, match=r"^truth and measured frames differ in length; cannot join them row by "
                                        r"row$"):
        short.to_pandas(include_truth=True)
    # an unsigned time channel that runs backwards does not wrap around into "increasing"
    with pytest.raises(TripError, match=r"time channel 't' is not strictly increasing at index 2 \(t=2 then 1\)"):
        Trip({"t": np.array([0, 2, 1], dtype=np.uint32)}, {"t": "s"})
    # a catalogued measured channel is checked against the measured catalogue even with an SI unit
    with pytest.raises(TripError, match=r"measured channel 'vehicle_speed' has unit 'm', the catalogue says 'm/s'"):
        Trip({"t": [0.0], "vehicle_speed": [1.0]}, {"t": "s", "vehicle_speed": "m"})
    # integer truth channels come back as floats
    counted = Trip({"t": [0.0, 0.1]}, {"t": "s"}, {}, {"t": [0.0, 0.1], "gear": np.array([1, 2])},
                   {"t": "s", "gear": "1"})
    assert counted.true("gear").dtype == float and counted.true("gear").tolist() == [1.0, 2.0]


def test_convert_streams_a_shared_time_base_and_reads_a_union_whole(tmp_path):
    """Shared time base (format 4 'shared', format 3 truth on the measured time, or no truth): converted chunk by
    chunk of an hour at 100 Hz, so the output has one row group per chunk; a union time base is read whole."""
    n = 360_001
    t = np.arange(n) / 100.0
    shared = Trip({"t": t}, {"t": "s"}, {}, {"t": t, "mass": np.full(n, 5.0)}, {"t": "s", "mass": "kg"})
    out = convert_trip_file(shared.save(tmp_path / "s.parquet"), tmp_path / "s4.parquet")
    assert pq.ParquetFile(out).num_row_groups == 2 and _payload(out)["time_base"] == "shared"
    packed = shared.save(tmp_path / "p.parquet", precision="packed")
    assert _payload(packed)["truth_time"] == "measured"
    assert pq.ParquetFile(convert_trip_file(packed, tmp_path / "p4.parquet")).num_row_groups == 2
    plain = Trip({"t": t}, {"t": "s"}).save(tmp_path / "r.parquet", precision="packed")  # format 3, no truth
    assert pq.ParquetFile(convert_trip_file(plain, tmp_path / "r4.parquet")).num_row_groups == 2
    union = Trip({"t": t}, {"t": "s"}, {}, {"t": t[::2]}, {"t": "s"}).save(tmp_path / "u.parquet")
    assert pq.ParquetFile(convert_trip_file(union, tmp_path / "u4.parquet")).num_row_groups == 1
