"""Trip metadata errors word for word: the file, the field path under ``metadata``, what is wrong and the value."""

import json

import pytest

from roadload.trip_schema import SUPPORTED_VERSIONS, TripMetadataError, parse_trip_payload

BASE = {"version": 3, "units": {"t": "s"}, "n_measured": 5}


@pytest.mark.parametrize("payload,message", [
    ({**BASE, "n_measured": -1}, "metadata.n_measured: input should be greater than or equal to 0, got -1"),
    ({"version": 3, "units": {"t": "s"}}, "metadata.n_measured: missing required field"),
    ({**BASE, "units": {"t": 5}}, "metadata.units.t: input should be a valid string, got 5"),
    ({**BASE, "version": 9}, f"metadata: version 9 is not supported (this roadload reads {SUPPORTED_VERSIONS}); "
                             f"upgrade roadload"),
    ({**BASE, "n_truth": 9}, "metadata.n_truth: 9 rows declared but the file holds 5"),
    ({**BASE, "n_measured": 6}, "metadata.n_measured: 6 rows declared but the file holds 5"),
])
def test_schema_errors_name_file_and_field_path(payload, message):
    with pytest.raises(TripMetadataError) as err:
        parse_trip_payload(json.dumps(payload), "trip.parquet", n_rows=5)
    assert str(err.value) == f"trip.parquet: {message}"


@pytest.mark.parametrize("raw,kind", [("[1]", "list"), ("null", "NoneType"), ("3", "int"), ('"x"', "str")])
def test_metadata_that_is_not_an_object_names_its_type(raw, kind):
    with pytest.raises(TripMetadataError) as err:
        parse_trip_payload(raw, "trip.parquet")
    assert str(err.value) == f"trip.parquet: trip metadata must be a JSON object, got {kind}"


def test_valid_payload_with_defaults_and_row_bound():
    out = parse_trip_payload(json.dumps({**BASE, "extra": 1}).encode(), "trip.parquet", n_rows=5)
    assert out == {"version": 3, "units": {"t": "s"}, "truth_units": {}, "meta": {}, "n_measured": 5, "n_truth": 0,
                   "dtypes": {}, "truth_dtypes": {}, "extra": 1}  # a newer writer's extra key is kept
    assert parse_trip_payload(json.dumps({**BASE, "n_measured": 10**6}), "t")["n_measured"] == 10**6  # no bound
