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


def test_compact_differenced_columns_roundtrip_across_chunks_gaps_and_wraps(tmp_path):
    """'delta' columns (first differences of the integer code, continued over chunks): smooth float32 truth,
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
                    "position": "m", "speed": "m/s"}, "compact", {"vehicle_speed": 0.01}) as w:
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
