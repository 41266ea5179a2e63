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
