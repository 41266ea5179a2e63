"""Fuzzed contract of the files a user hands in: mapping JSON, vehicle JSON, trip metadata, sim config.

Every malformed input must end in the surface's own error class with a message naming the field (never a
traceback from deep inside, never a silent acceptance)."""

from __future__ import annotations

import copy
import json

import numpy as np
import pandas as pd
import pyarrow.parquet as pq
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from roadload.io.mapping import Mapping, load_mapping
from roadload.io.report import LogImportError
from roadload.presets import get_preset
from roadload.sim2real.errors import DiagnosisError
from roadload.sim2real.simconfig import SimConfig
from roadload.trip import Trip, TripError
from roadload.trip_schema import TripMetadataError, parse_trip_payload
from roadload.vehicle import VehicleSpec, VehicleSpecError, load_vehicle, vehicle_json_schema

FUZZ = settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])

# ----------------------------------------------------------------------------------------------- mapping JSON
BASE_MAPPING = {
    "name": "m",
    "format": "csv",
    "sample_rate": 10,
    "max_gap": 2.0,
    "csv": {"time": "Time [s]", "time_unit": "s", "sep": ";"},
    "derived": [{"kind": "distance"}],
    "channels": [
        {
            "source": "Velocity [km/h]",
            "channel": "vehicle_speed",
            "unit": "km/h",
            "required": True,
            "scale": 1.0,
            "offset": 0.0,
            "range": [0, 70],
        }
    ],
}

# (path into the mapping, bad value, text the message must contain)
MAPPING_CASES = [
    (("channels", 0, "scale"), "abc", "scale"),
    (("channels", 0, "scale"), None, "scale"),
    (("channels", 0, "scale"), [1], "scale"),
    (("channels", 0, "scale"), 0, "scale"),
    (("channels", 0, "scale"), float("nan"), "scale"),
    (("channels", 0, "scale"), float("inf"), "scale"),
    (("channels", 0, "scale"), True, "scale"),
    (("channels", 0, "offset"), "1", "offset"),
    (("channels", 0, "offset"), float("-inf"), "offset"),
    (("channels", 0, "offset"), {}, "offset"),
    (("channels", 0, "range"), 5, "range"),
    (("channels", 0, "range"), [5], "range"),
    (("channels", 0, "range"), [5, 1], "range"),
    (("channels", 0, "range"), [0, "x"], "range"),
    (("channels", 0, "range"), [0, 1, 2], "range"),
    (("channels", 0, "range"), "0..70", "range"),
    (("channels", 0, "range"), [float("nan"), 1], "range"),
    (("channels", 0, "range"), [3, 3], "range"),
    (("channels", 0, "channel"), "warp_factor", "warp_factor"),
    (("channels", 0, "channel"), "vehicle_sped", "vehicle_speed"),
    (("channels", 0, "channel"), 5, "channel"),
    (("channels", 0, "channel"), "", "channel"),
    (("channels", 0, "channel"), None, "channel"),
    (("channels", 0, "unit"), "furlong", "furlong"),
    (("channels", 0, "unit"), 3, "unit"),
    (("channels", 0, "unit"), "deg", "unit mismatch"),
    (("channels", 0, "unit"), None, "unit"),
    (("channels", 0, "source"), 5, "source"),
    (("channels", 0, "source"), [], "source"),
    (("channels", 0, "source"), "", "source"),
    (("channels", 0, "source"), [1, 2], "source"),
    (("channels", 0, "source"), None, "source"),
    (("channels", 0, "required"), "yes", "required"),
    (("channels", 0, "required"), 1, "required"),
    (("channels", 0, "resample"), "cubic", "resample"),
    (("channels", 0, "resample"), 3, "resample"),
    (("channels", 0, "values"), [1, 2], "values"),
    (("channels", 0, "values"), {"on": "one"}, "values"),
    (("channels", 0, "accuracy"), 5, "accuracy"),
    (("channels", 0, "accuracy"), {"source": "a"}, "accuracy"),
    (("channels", 0, "accuracy"), {"source": "a", "max": -1}, "accuracy"),
    (("channels", 0, "plus"), "x", "plus"),
    (("channels", 0, "event"), "true", "event"),
    (("channels", 0, "circular"), 1, "circular"),
    (("channels", 0, "valid"), 5, "valid"),
    (("channels", 0, "resmaple"), "linear", "resmaple"),
    (("channels", 0, "warp"), 9, "warp"),
    (("channels",), 5, "channels"),
    (("channels",), [], "channels"),
    (("channels",), {"a": 1}, "channels"),
    (("channels",), "vehicle_speed", "channels"),
    (("channels",), [5], "channels"),
    (("channels",), [None], "channels"),
    (("channels",), [[]], "channels"),
    (("max_gap",), "long", "max_gap"),
    (("max_gap",), -1, "max_gap"),
    (("max_gap",), 0, "max_gap"),
    (("max_gap",), float("nan"), "max_gap"),
    (("max_gap",), [2], "max_gap"),
    (("sample_rate",), -5, "sample_rate"),
    (("sample_rate",), 0, "sample_rate"),
    (("sample_rate",), "10", "sample_rate"),
    (("sample_rate",), 1e9, "sample_rate"),
    (("sample_rate",), float("inf"), "sample_rate"),
    (("csv",), "t [s]", "csv"),
    (("csv",), 5, "csv"),
    (("csv",), [], "csv"),
    (("csv", "time"), 5, "time"),
    (("csv", "time"), "", "time"),
    (("csv", "time_unit"), "min", "time_unit"),
    (("csv", "time_unit"), "sec", "time_unit"),
    (("csv", "sep"), "", "sep"),
    (("csv", "sep"), 1, "sep"),
    (("csv", "encoding"), "klingon", "encoding"),
    (("csv", "decimal"), ",,", "decimal"),
    (("csv", "header"), 0, "header"),
    (("csv", "time_alternatives"), "t", "time_alternatives"),
    (("derived",), {"kind": "distance"}, "derived"),
    (("derived",), [{"kind": "teleport"}], "kind"),
    (("derived",), [{"kind": "grade", "window": -3}], "window"),
    (("derived",), [{"kind": "grade", "window": "x"}], "window"),
    (("derived",), [{"kind": "rim_torque", "efficiency": 1.5}], "efficiency"),
    (("derived",), [{}], "kind"),
    (("derived",), [{"kind": "grade", "smooth": 1}], "smooth"),
    (("dbc",), "a.dbc", "dbc"),
    (("dbc",), [{"file": "a.dbc", "bus": -1}], "bus"),
    (("dbc",), [{"bus": 1}], "file"),
    (("clock",), "gps", "clock"),
    (("clock",), {"valid": "x"}, "source"),
    (("clock",), {"source": "x", "unit": "h"}, "unit"),
    (("name",), 5, "name"),
    (("name",), "", "name"),
    (("format",), "pcap", "pcap"),
    (("format",), 3, "format"),
    (("vehicle",), 3, "vehicle"),
    (("licence",), [], "licence"),
    (("description",), 5, "description"),
    (("colour",), "red", "colour"),
]


def _set(d, path, value):
    node = d
    for p in path[:-1]:
        node = node[p]
    node[path[-1]] = value
    return d


@pytest.mark.parametrize(
    "path,value,needle", MAPPING_CASES, ids=[f"{'.'.join(map(str, p))}={v!r}"[:60] for p, v, _ in MAPPING_CASES]
)
def test_mapping_field(path, value, needle, ledger):
    raw = _set(copy.deepcopy(BASE_MAPPING), path, value)
    with pytest.raises(LogImportError) as err:
        Mapping.from_dict(raw)
    assert needle in str(err.value), str(err.value)
    ledger.record("mapping", "error")


def test_mapping_base_is_valid():
    assert Mapping.from_dict(copy.deepcopy(BASE_MAPPING)).channels[0].channel == "vehicle_speed"


NUMERIC_FIELDS = [("channels", 0, "scale"), ("channels", 0, "offset"), ("max_gap",), ("sample_rate",)]
TEXT_FIELDS = [("channels", 0, "unit"), ("channels", 0, "channel"), ("name",), ("csv", "time")]
NOT_A_NUMBER = st.one_of(
    st.text(max_size=8),
    st.lists(st.integers(), max_size=3),
    st.booleans(),
    st.dictionaries(st.text(max_size=3), st.integers(), max_size=2),
    st.sampled_from([float("nan"), float("inf"), -float("inf")]),
)
NOT_A_TEXT = st.one_of(
    st.integers(), st.floats(allow_nan=False), st.lists(st.text(max_size=3), max_size=3), st.booleans(), st.none()
)


@FUZZ
@given(field=st.sampled_from(NUMERIC_FIELDS), value=NOT_A_NUMBER)
def test_mapping_numeric_fields_refuse_non_numbers(field, value, ledger):
    raw = _set(copy.deepcopy(BASE_MAPPING), field, value)
    with pytest.raises(LogImportError) as err:
        Mapping.from_dict(raw)
    assert field[-1] in str(err.value)
    ledger.record("mapping", "error")


@FUZZ
@given(field=st.sampled_from(TEXT_FIELDS), value=NOT_A_TEXT)
def test_mapping_text_fields_refuse_non_text(field, value, ledger):
    raw = _set(copy.deepcopy(BASE_MAPPING), field, value)
    with pytest.raises(LogImportError) as err:
        Mapping.from_dict(raw)
    assert field[-1] in str(err.value)
    ledger.record("mapping", "error")


@pytest.mark.parametrize(
    "text,needle",
    [
        ("", "not valid JSON"),
        ("{", "not valid JSON"),
        ("[1, 2]", "JSON object"),
        ('"m"', "JSON object"),
        ("null", "JSON object"),
        ('{"name": "m"}', "format"),
        ("\x00\x01", "not valid JSON"),
        ('{"name": "m", "format": "csv", "channels": [], "x": 1}', "x"),
    ],
)
def test_mapping_file(tmp_path, text, needle, ledger):
    p = tmp_path / "m.json"
    p.write_text(text)
    with pytest.raises(LogImportError) as err:
        load_mapping(p)
    assert needle in str(err.value) and ("m.json" in str(err.value) or "mapping" in str(err.value))
    ledger.record("mapping", "error")


# ----------------------------------------------------------------------------------------------- vehicle JSON
VEHICLE_CASES = [
    ("body.mass", 0.001, "body.mass"),
    ("body.mass", 1e7, "body.mass"),
    ("body.mass", 0, "body.mass"),
    ("body.mass", -1500, "body.mass"),
    ("body.mass", float("nan"), "body.mass"),
    ("body.mass", "heavy", "body.mass"),
    ("body.mass", None, "body.mass"),
    ("body.mass", [1500], "body.mass"),
    ("body.mass", True, "body.mass"),
    ("body.wheelbase", 0.1, "wheelbase"),
    ("body.wheelbase", 50.0, "wheelbase"),
    ("body.cg_to_front_axle", 5.0, "cg_to_front_axle"),
    ("body.cg_height", -1, "cg_height"),
    ("body.track_front", 10.0, "track_front"),
    ("body.yaw_inertia", 0, "yaw_inertia"),
    ("aero.drag_coefficient", 5.0, "drag_coefficient"),
    ("aero.drag_coefficient", 0, "drag_coefficient"),
    ("aero.frontal_area", 100.0, "frontal_area"),
    ("aero.frontal_area", 0.01, "frontal_area"),
    ("aero.frontal_area", float("inf"), "frontal_area"),
    ("tires.dynamic_radius", 3.0, "dynamic_radius"),
    ("tires.dynamic_radius", "0.3", "dynamic_radius"),
    ("tires.rolling_resistance_f0", 1.0, "rolling_resistance_f0"),
    ("drivetrain.gear_ratios", [1000, 800, 600, 400, 300, 200, 100], "gear_ratios"),
    ("drivetrain.gear_ratios", [1e-3, 9e-4, 8e-4, 7e-4, 6e-4, 5e-4, 4e-4], "gear_ratios"),
    ("drivetrain.gear_ratios", [0.68, 0.84, 1.0, 1.42, 2.08, 3.31, 5.97], "gear_ratios"),
    ("drivetrain.gear_ratios", [5.97, 3.31, 3.31, 1.42, 1.0, 0.84, 0.68], "gear_ratios"),
    ("drivetrain.gear_ratios", [20, 18, 16, 14, 12, 11, 10], "gear_ratios"),
    ("drivetrain.gear_ratios", [], "gear_ratios"),
    ("drivetrain.gear_ratios", 3.0, "gear_ratios"),
    ("drivetrain.gear_ratios", ["a"] * 7, "gear_ratios"),
    ("drivetrain.final_drive", 100.0, "final_drive"),
    ("drivetrain.final_drive", 0.01, "final_drive"),
    ("drivetrain.final_drive", -3, "final_drive"),
    ("drivetrain.kind", "steam", "kind"),
    ("drivetrain.driven_axle", "middle", "driven_axle"),
    ("drivetrain.engine.max_speed", 50.0, "max_speed"),
    ("drivetrain.engine.idle_speed", 1000.0, "idle_speed"),
    ("drivetrain.oil_warm_temperature", 20.0, "oil_warm_temperature"),
    ("brakes.pad_friction", 3.0, "pad_friction"),
    ("brakes.front_share", 1.5, "front_share"),
    ("sensors.sample_rate", 0.1, "sample_rate"),
    ("sensors.channels", {"warp": {}}, "warp"),
    ("sensors.speed_scale_error", 0.9, "speed_scale_error"),
    ("name", "", "name"),
    ("name", 5, "name"),
    ("steering.wheel_angle", [0.0, 0.1], "wheel_angle"),
    ("aero.yaw_drag_factor", -1.0, "yaw_drag_factor"),
    ("body.drag", 1.0, "drag"),
]


def _vehicle_dict(preset="gt_rwd"):
    return get_preset(preset).to_dict()


def _set_dotted(d, key, value):
    parts = key.split(".")
    node = d
    for p in parts[:-1]:
        node = node[p]
    node[parts[-1]] = value
    return d


@pytest.mark.parametrize("key,value,needle", VEHICLE_CASES, ids=[f"{k}={v!r}"[:50] for k, v, _ in VEHICLE_CASES])
def test_vehicle_field(key, value, needle, ledger):
    d = _set_dotted(_vehicle_dict(), key, value)
    with pytest.raises(VehicleSpecError) as err:
        VehicleSpec.from_dict(d)
    msg = str(err.value)
    assert needle in msg and msg.startswith("vehicle."), msg
    ledger.record("vehicle", "error")


def test_vehicle_errors_carry_units():
    with pytest.raises(
        VehicleSpecError, match=r"body\.mass: 0\.001 kg is outside the plausible range \[250, 60000\] kg"
    ):
        VehicleSpec.from_dict(_set_dotted(_vehicle_dict(), "body.mass", 0.001))
    with pytest.raises(VehicleSpecError, match=r"top speed .* m/s .* below 20 m/s \[72 km/h\]"):
        VehicleSpec.from_dict(_set_dotted(_vehicle_dict(), "drivetrain.gear_ratios", [20, 18, 16, 14, 12, 11, 10]))


def test_truck_sized_vehicles_are_admitted():
    """A 40 t truck (12-speed 14.9 ... 1.0 gearbox, 3.4 final drive, 0.5 m wheels, 330 kW) must pass."""
    d = _vehicle_dict("gt_rwd")
    ratios = list(np.geomspace(14.9, 1.0, 12))
    d["body"].update(
        mass=40000.0,
        wheelbase=3.8,
        cg_to_front_axle=1.6,
        yaw_inertia=2.0e5,
        cg_height=1.2,
        track_front=2.0,
        track_rear=1.8,
    )
    d["aero"].update(frontal_area=10.0, drag_coefficient=0.6)
    d["tires"]["dynamic_radius"] = 0.5
    dt = d["drivetrain"]
    dt["gear_ratios"] = ratios
    dt["gearbox_inertia"] = [dt["gearbox_inertia"][0]] * 12
    dt["gearbox_loss"] = [dt["gearbox_loss"][0]] * 12
    dt["final_drive"] = 3.4
    dt["engine"]["full_load"]["y"] = [v * 10 for v in dt["engine"]["full_load"]["y"]]
    dt["engine"]["max_speed"] = 230.0
    dt["engine"]["idle_speed"] = 63.0
    dt["engine"]["full_load"]["x"] = list(np.linspace(63.0, 230.0, len(dt["engine"]["full_load"]["x"])))
    dt["engine"]["drag"]["x"] = list(np.linspace(63.0, 230.0, len(dt["engine"]["drag"]["x"])))
    dt["shift"].update(
        upshift_speed_low=150.0,
        upshift_speed_high=200.0,
        downshift_speed_low=90.0,
        downshift_speed_high=120.0,
        launch_speed=90.0,
    )
    spec = VehicleSpec.from_dict(d)
    assert spec.mass == 40000.0 and spec.drivetrain.n_gears == 12


@FUZZ
@given(mass=st.one_of(st.floats(min_value=-1e9, max_value=249.9), st.floats(min_value=60000.1, max_value=1e12)))
def test_vehicle_mass_outside_road_vehicle_range(mass, ledger):
    with pytest.raises(VehicleSpecError, match=r"vehicle\.body\.mass"):
        get_preset("bmw_i3").replace(**{"body.mass": mass})
    ledger.record("vehicle", "error")


@FUZZ
@given(
    ratios=st.lists(st.floats(min_value=0.3, max_value=25.0), min_size=2, max_size=7).filter(
        lambda r: not all(a > b for a, b in zip(r, r[1:]))
    )
)
def test_vehicle_gear_ratios_not_strictly_decreasing(ratios, ledger):
    d = _vehicle_dict()
    dt = d["drivetrain"]
    n = len(ratios)
    dt.update(
        gear_ratios=ratios, gearbox_inertia=dt["gearbox_inertia"][:1] * n, gearbox_loss=dt["gearbox_loss"][:1] * n
    )
    with pytest.raises(VehicleSpecError, match=r"vehicle\.drivetrain\.gear_ratios"):
        VehicleSpec.from_dict(d)
    ledger.record("vehicle", "error")


@pytest.mark.parametrize(
    "text,needle",
    [
        ("", "not valid JSON"),
        ("{", "not valid JSON"),
        ("[]", "expected an object"),
        ('{"name": "x"}', "missing required field"),
        ("5", "expected an object"),
    ],
)
def test_vehicle_file(tmp_path, text, needle, ledger):
    p = tmp_path / "v.json"
    p.write_text(text)
    with pytest.raises(VehicleSpecError) as err:
        load_vehicle(p)
    assert needle in str(err.value) and "v.json" in str(err.value)
    ledger.record("vehicle", "error")


# ----------------------------------------------------------------------------------------------- trip metadata
def _payload():
    return {
        "version": 1,
        "units": {"t": "s", "vehicle_speed": "m/s"},
        "truth_units": {},
        "meta": {"name": "x"},
        "n_measured": 5,
        "n_truth": 0,
        "dtypes": {"t": "float64"},
        "truth_dtypes": {},
    }


TRIP_CASES = [
    ("n_measured", None, "n_measured"),
    ("n_measured", "5", "n_measured"),
    ("n_measured", -1, "n_measured"),
    ("n_measured", 5.5, "n_measured"),
    ("n_measured", 99, "n_measured"),
    ("n_truth", 99, "n_truth"),
    ("n_truth", "0", "n_truth"),
    ("version", 9, "version"),
    ("version", "1", "version"),
    ("version", None, "version"),
    ("units", [1], "units"),
    ("units", {"t": 5}, "units"),
    ("units", None, "units"),
    ("meta", [], "meta"),
    ("meta", "x", "meta"),
    ("truth_units", 3, "truth_units"),
    ("dtypes", [], "dtypes"),
]


@pytest.mark.parametrize("key,value,needle", TRIP_CASES, ids=[f"{k}={v!r}" for k, v, _ in TRIP_CASES])
def test_trip_metadata_field(key, value, needle, ledger):
    payload = _payload()
    if value is None:
        payload.pop(key)
    else:
        payload[key] = value
    with pytest.raises(TripMetadataError) as err:
        parse_trip_payload(json.dumps(payload).encode(), "trip.parquet", n_rows=5)
    assert needle in str(err.value) and "trip.parquet" in str(err.value), str(err.value)
    ledger.record("trip", "error")


@pytest.mark.parametrize("raw", [b"", b"{", b"\xff\xfe", b"[1]", b"null", b"NaN"])
def test_trip_metadata_not_json(raw, ledger):
    with pytest.raises(TripMetadataError, match="trip.parquet: trip metadata"):
        parse_trip_payload(raw, "trip.parquet")
    ledger.record("trip", "error")


@pytest.mark.parametrize("mutate", ["drop_n_measured", "not_json", "future_version"])
def test_trip_load_names_file_and_field(tmp_path, mutate, ledger):
    trip = Trip(
        pd.DataFrame({"t": np.arange(5.0), "vehicle_speed": np.ones(5)}),
        {"t": "s", "vehicle_speed": "m/s"},
        {"name": "x"},
    )
    path = trip.save(tmp_path / "t.parquet")
    table = pq.read_table(path)
    # format 2 keeps the payload in the file's key-value metadata (written last, after the streamed row groups)
    md = {k: v for k, v in pq.ParquetFile(path).metadata.metadata.items() if k != b"ARROW:schema"}
    payload = json.loads(md[b"roadload"])
    if mutate == "drop_n_measured":
        payload.pop("n_measured")
        raw, needle = json.dumps(payload).encode(), "n_measured"
    elif mutate == "not_json":
        raw, needle = b"{broken", "not valid JSON"
    else:
        payload["version"] = 7
        raw, needle = json.dumps(payload).encode(), "version 7"
    md[b"roadload"] = raw
    pq.write_table(table.replace_schema_metadata(md), path)
    with pytest.raises(TripError) as err:
        Trip.load(path)
    assert needle in str(err.value) and "t.parquet" in str(err.value)
    ledger.record("trip", "error")


# ----------------------------------------------------------------------------------------------- sim config
SIMCONFIG_CASES = [
    ({"vehicle": 5}, "vehicle"),
    ({"vehicle": ""}, "vehicle"),
    ({"vehicle": None}, "vehicle"),
    ({"vehicle": ["bmw_i3"]}, "vehicle"),
    ({"vehicle": "atlantis"}, "atlantis"),
    ({"vehicle": {"name": "x"}}, "body"),
    ({"vehicle": "bmw_i3", "name": 5}, "name"),
    ({"vehicle": "bmw_i3", "effects": 3}, "effects"),
    ({"vehicle": "bmw_i3", "effects": "rain"}, "rain"),
    ({"vehicle": "bmw_i3", "effects": {"effects": {"wind": {"speed": 1}}}}, "speed"),
    ({"vehicle": "bmw_i3", "colour": "red"}, "colour"),
    ({}, "vehicle"),
    ([], "object"),
    ("bmw_i3", "object"),
    ({"vehicle": "bmw_i3", "effects": [1]}, "effects"),
]


@pytest.mark.parametrize("data,needle", SIMCONFIG_CASES, ids=[repr(d)[:50] for d, _ in SIMCONFIG_CASES])
def test_sim_config(data, needle, ledger):
    with pytest.raises(DiagnosisError) as err:
        SimConfig.from_dict(data)
    assert needle in str(err.value), str(err.value)
    ledger.record("simconfig", "error")


TABLE_INPUTS = len(MAPPING_CASES) + 8 + len(VEHICLE_CASES) + 5 + len(TRIP_CASES) + 6 + 3 + len(SIMCONFIG_CASES)


def test_vehicle_json_schema_carries_units_and_bounds():
    body = vehicle_json_schema()["$defs"]["BodySpec"]["properties"]
    assert body["mass"]["unit"] == "kg" and body["mass"]["plausible"] == [250.0, 60000.0]
    assert body["mass"]["exclusiveMinimum"] == 0.0 and "[m]" in body["wheelbase"]["description"]
