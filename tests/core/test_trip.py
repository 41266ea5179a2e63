import numpy as np
import pandas as pd
import pytest

from roadload import Trip, TripError


def _trip(n=50, truth=True):
    t = np.arange(n) / 100.0
    measured = pd.DataFrame({"t": t, "vehicle_speed": np.linspace(0, 10, n), "gear": np.arange(n) % 7})
    units = {"t": "s", "vehicle_speed": "m/s", "gear": "1"}
    tr = pd.DataFrame({"t": t, "mass": np.full(n, 1900.0)}) if truth else None
    return Trip(measured, units, {"name": "x", "seed": 3, "effects": ["wind"]}, tr,
                {"t": "s", "mass": "kg"} if truth else {})


def test_parquet_roundtrip_is_exact(tmp_path):
    trip = _trip()
    back = Trip.load(trip.save(tmp_path / "a.parquet"))
    assert back.equals(trip)
    assert back.measured["gear"].dtype == trip.measured["gear"].dtype
    assert "truth/mass" not in back.measured.columns and back.true("mass")[0] == 1900.0
    assert list(trip.to_pandas(include_truth=True).columns) == ["t", "vehicle_speed", "gear", "truth/mass"]


def test_roundtrip_with_unequal_time_bases(tmp_path):
    trip = _trip()
    trip = Trip(trip.measured, trip.units, trip.meta, trip.truth.iloc[:20], trip.truth_units)
    back = Trip.load(trip.save(tmp_path / "b.parquet"))
    assert back.equals(trip) and len(back.truth) == 20 and len(back) == 50


@pytest.mark.parametrize("mutate, message", [
    (lambda m, u: m.assign(t=m["t"][::-1].to_numpy()), "strictly increasing"),
    (lambda m, u: m.drop(columns="t"), "missing the time channel"),
    (lambda m, u: m.assign(extra=1.0), "no unit"),
])
def test_contract_violations_name_the_problem(mutate, message):
    base = _trip(truth=False)
    with pytest.raises(TripError, match=message):
        Trip(mutate(base.measured, base.units), base.units)


def test_wrong_unit_for_catalogued_channel():
    base = _trip(truth=False)
    with pytest.raises(TripError, match="vehicle_speed.*km/h"):
        Trip(base.measured, {**base.units, "vehicle_speed": "km/h"})


def test_failed_save_leaves_no_file(tmp_path):
    trip = _trip()
    trip.meta["bad"] = object.__new__(object)  # not JSON-serialisable after construction
    with pytest.raises(TypeError):
        trip.save(tmp_path / "c.parquet")
    assert list(tmp_path.iterdir()) == []


def test_load_rejects_foreign_parquet(tmp_path):
    pd.DataFrame({"a": [1.0]}).to_parquet(tmp_path / "f.parquet")
    with pytest.raises(TripError, match="not a Trip"):
        Trip.load(tmp_path / "f.parquet")


def test_packed_differenced_columns_roundtrip_across_chunks_gaps_and_wraps(tmp_path):
    """Precision 'packed' (format 3, the private codec, opt-in): 'delta' columns (first differences of the integer
    code, continued over chunks): smooth float32 truth,
    a fixed-step truth channel and a quantised measured channel with NaN gaps, a float32 bit pattern that
    crosses zero (int32 differences wrap); load and chunked reads with rows not aligned to the chunks give the
    compact values exactly."""
    import json

    import pyarrow.parquet as pq

    from roadload.trip import TripWriter

    n = 3000
    t = np.arange(n) / 100.0
    speed = np.round((20.0 + 5.0 * np.sin(t / 3.0)) / 0.01) * 0.01  # k x step, as the sensor quantiser forms it
    speed[[5, 6, 1000, 1999, 2000]] = np.nan  # dropouts, one at a chunk boundary
    measured = pd.DataFrame({"t": t, "vehicle_speed": speed})
    truth = pd.DataFrame({"t": t, "acceleration": 1e-3 * np.sin(t) - 2e-4,  # crosses zero: sign bit flips
                          "position": np.cumsum(np.full(n, 0.25)), "speed": 20.0 + np.cos(t / 3.0)})
    path = tmp_path / "d.parquet"
    with TripWriter(path, {"t": "s", "vehicle_speed": "m/s"}, {"t": "s", "acceleration": "m/s^2",
                    "position": "m", "speed": "m/s"}, "packed", {"vehicle_speed": 0.01}) as w:
        for a in range(0, n, 1000):
            w.write(measured.iloc[a:a + 1000], truth.iloc[a:a + 1000])
        w.close({"name": "delta"})
    enc = json.loads(pq.ParquetFile(path).metadata.metadata[b"roadload"])["encoding"]
    assert all(enc[c].get("delta") for c in ("truth/speed", "truth/position", "truth/acceleration", "vehicle_speed"))
    back = Trip.load(path)
    np.testing.assert_array_equal(back.channel("vehicle_speed"), speed)  # lossless, NaN where NaN
    for name in ("acceleration", "speed"):
        np.testing.assert_array_equal(back.true(name), truth[name].to_numpy().astype(np.float32).astype(float))
    np.testing.assert_allclose(back.true("position"), truth["position"], rtol=0, atol=0.5e-4)
    parts = list(Trip.iter_chunks(path, rows=700))
    joined = np.concatenate([p.true("speed") for p in parts])
    np.testing.assert_array_equal(joined, back.true("speed"))
    np.testing.assert_array_equal(np.concatenate([p.channel("vehicle_speed") for p in parts]), speed)


# ------------------------------------------------------------------------------------------ constructor contract
@pytest.mark.parametrize("units, message", [
    (["s", "m/s", "1"], r"units: expected a dict \{channel: SI unit string\}.*got list"),
    ("m/s", r"units: expected a dict.*got str"),
    ({"t": "s", "vehicle_speed": 3.6, "gear": "1"}, r"units\['vehicle_speed'\]: the unit must be a string such as "
                                                    r"'m/s', got float 3.6"),
    ({"t": "s", "vehicle_speed": None, "gear": "1"}, r"units\['vehicle_speed'\].*got NoneType"),
])
def test_units_of_the_wrong_type_give_a_clean_error(units, message):
    base = _trip(truth=False)
    with pytest.raises(TripError, match=message):
        Trip(base.measured, units)
    with pytest.raises(TripError, match=message.replace("units", "truth_units", 1)):
        Trip(base.measured, base.units, {}, pd.DataFrame({"t": base.t, "mass": 1.0}), units)


def test_channels_of_unequal_length_are_refused_not_padded():
    t = np.arange(10) / 100.0
    with pytest.raises(TripError, match=r"measured: channels of unequal length: 't' has 10 samples, "
                                        r"'vehicle_speed' has 7"):
        Trip({"t": t, "vehicle_speed": np.ones(7)}, {"t": "s", "vehicle_speed": "m/s"})
    with pytest.raises(TripError, match=r"truth: channels of unequal length: 't' has 10 samples, 'mass' has 11"):
        Trip({"t": t, "vehicle_speed": np.ones(10)}, {"t": "s", "vehicle_speed": "m/s"}, {},
             {"t": t, "mass": np.ones(11)}, {"t": "s", "mass": "kg"})
    with pytest.raises(TripError, match=r"channel 'vehicle_speed' must be a 1-D array, got shape \(10, 2\)"):
        Trip({"t": t, "vehicle_speed": np.ones((10, 2))}, {"t": "s", "vehicle_speed": "m/s"})
    # equal lengths from a mapping are accepted as a DataFrame
    trip = Trip({"t": t, "vehicle_speed": np.ones(10)}, {"t": "s", "vehicle_speed": "m/s"})
    assert len(trip) == 10 and trip.channel("vehicle_speed").sum() == 10.0


@pytest.mark.parametrize("names, message", [
    (["vehicle_speed", "vehicle_speed "], r"channel name 'vehicle_speed ' is empty or has surrounding whitespace"),
    (["Vehicle_Speed", "vehicle_speed"], r"channel names 'Vehicle_Speed' and 'vehicle_speed' differ only in case"),
    (["my signal", "MY SIGNAL"], r"'my signal' and 'MY SIGNAL' differ only in case or whitespace"),
    (["truth/speed"], r"channel name 'truth/speed' is reserved"),
    (["measured_row"], r"channel name 'measured_row' is reserved"),
    ([""], r"channel name '' is empty"),
])
def test_near_duplicate_and_reserved_channel_names_are_refused(names, message):
    t = np.arange(5) / 100.0
    measured = pd.DataFrame({"t": t, **{n: np.zeros(5) for n in names}})
    units = {"t": "s", **{n: ("m/s" if n.lower().strip() == "vehicle_speed" else "1") for n in names}}
    with pytest.raises(TripError, match=message):
        Trip(measured, units)


def test_channel_names_must_be_strings():
    measured = pd.DataFrame({"t": np.arange(3) / 100.0, 7: np.zeros(3)})
    with pytest.raises(TripError, match=r"channel names must be strings, got 7 \(int\)"):
        Trip(measured, {"t": "s", 7: "1"})


@pytest.mark.parametrize("unit, message", [
    ("km/h", r"channel 'my_speed': unit 'km/h' is not SI: convert to 'm/s' \(x \[m/s\] = x \[km/h\] \* 0.277778"),
    ("degC", r"unit 'degC' is not SI: convert to 'K' \(x \[K\] = x \[degC\] \* 1 \+ 273.15"),
    ("%", r"unit '%' is not SI: convert to '1' \(x \[1\] = x \[%\] \* 0.01"),
    ("furlong/fortnight", r"unit 'furlong/fortnight' is not an SI unit expression"),
    (" m/s", r"unit ' m/s' is not a unit \(empty or with surrounding whitespace\)"),
])
def test_non_si_unit_on_a_channel_outside_the_catalogue_is_refused_with_the_conversion(unit, message):
    measured = pd.DataFrame({"t": np.arange(3) / 100.0, "my_speed": np.ones(3)})
    with pytest.raises(TripError, match=message):
        Trip(measured, {"t": "s", "my_speed": unit})


@pytest.mark.parametrize("unit", ["m/s", "N*m", "kg/m^3", "s^4/m^4", "1/m", "1", "W"])
def test_si_unit_expressions_pass_for_channels_outside_the_catalogue(unit):
    measured = pd.DataFrame({"t": np.arange(3) / 100.0, "my_signal": np.ones(3)})
    assert Trip(measured, {"t": "s", "my_signal": unit}).units["my_signal"] == unit


def test_truth_units_are_checked_against_the_truth_catalogue():
    base = _trip(truth=False)
    with pytest.raises(TripError, match=r"truth channel 'mass' has unit 'g', the catalogue says 'kg'"):
        Trip(base.measured, base.units, {}, pd.DataFrame({"t": base.t, "mass": 1.0}), {"t": "s", "mass": "g"})


def test_meta_must_be_a_dict():
    base = _trip(truth=False)
    with pytest.raises(TripError, match=r"meta: expected a dict of JSON-serialisable metadata, got list"):
        Trip(base.measured, base.units, ["name", "x"])
