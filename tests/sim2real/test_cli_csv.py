"""``roadload diagnose`` on plain CSV logs: --format/--mapping like ``roadload import``, folders yield trips only,
the packaged plain_csv mapping, and a clear error for --mapping without --format."""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest
from typer.testing import CliRunner

from roadload.experiments.cli import _load, app
from roadload.experiments.cli.sim2real import load_trips
from roadload.io.mapping import load_mapping
from roadload.sim2real.diagnose import sim_trips
from roadload.sim2real.errors import DiagnosisError
from roadload.sim2real.simconfig import SimConfig

# plain_csv column -> (Trip channel, factor from SI to the column's unit)
PLAIN = {"speed_kmh": ("vehicle_speed", 3.6), "accel_x_mps2": ("accel_x", 1.0),
         "drive_torque_nm": ("drive_torque", 1.0), "motor_speed_rpm": ("engine_speed", 60 / (2 * np.pi)),
         "brake_pressure_front_bar": ("brake_pressure_front", 1e-5),
         "brake_pressure_rear_bar": ("brake_pressure_rear", 1e-5),
         "steering_wheel_angle_deg": ("steering_wheel_angle", 180 / np.pi)}


def write_plain_csv(trip, path) -> None:
    cols = {"time_s": trip.t}
    for col, (ch, f) in PLAIN.items():
        if trip.has(ch):
            cols[col] = trip.channel(ch) * f
    pd.DataFrame(cols).to_csv(path, index=False)


@pytest.fixture(scope="module")
def csv_folder(tmp_path_factory):
    folder = tmp_path_factory.mktemp("logger")
    sim = SimConfig.load("bmw_i3")
    for trip in sim_trips(sim.with_effect("payload", {"initial_payload": 300.0, "change_std": 0.0}),
                          (("hilly", 41), ("city", 42)), 300.0):
        write_plain_csv(trip, folder / f"{trip.meta['name']}.csv")
    (folder / "vehicle.json").write_text(json.dumps({"note": "not a trip"}))
    (folder / "mapping.json").write_text(open(load_mapping("plain_csv").path).read())
    return folder


def test_packaged_plain_csv_mapping_documents_brake_pressure():
    m = load_mapping("plain_csv")
    assert m.format == "csv"
    chans = {c.channel for c in m.channels}
    assert {"vehicle_speed", "accel_x", "drive_torque", "brake_pressure_front", "brake_pressure_rear"} <= chans
    raw = json.loads(open(m.path).read())
    assert "brake geometry" in raw["description"]


def test_folder_yields_trip_files_only_and_csv_defaults_to_plain_csv(csv_folder):
    trips = load_trips([csv_folder], "csv")
    assert len(trips) == 2                       # the two JSON documents beside the logs are not trips
    t = trips[0]
    assert t.has("brake_pressure_front") and t.has("drive_torque")
    assert np.nanmax(t.channel("vehicle_speed")) < 60.0          # km/h column converted to m/s
    same = load_trips([csv_folder], "csv", str(csv_folder / "mapping.json"))
    assert len(same) == 2


def test_mapping_without_format_is_a_clear_error(csv_folder):
    with pytest.raises(DiagnosisError, match="--mapping needs --format"):
        load_trips([csv_folder], None, "plain_csv")


@pytest.mark.slow
def test_cli_diagnose_takes_format_and_mapping(csv_folder, tmp_path):
    _load()
    out = tmp_path / "diag"
    res = CliRunner().invoke(app, ["diagnose", "--sim", "bmw_i3", "--real", str(csv_folder), "--format", "csv",
                                   "--mapping", "plain_csv", "--out", str(out), "--no-resimulate",
                                   "--floor-duration", "300"])
    assert res.exit_code == 0, res.output
    d = json.loads((out / "diagnosis.json").read_text())
    assert len(d["trips"]) == 2
    assert d["notes"]["resimulation"].startswith("not asked")
    assert "base_calibration" in d["notes"] and d["notes"]["base_calibration"]["parameters"]
    assert d["effects"] and d["effects"][0]["name"] == "mass_offset"


def test_cli_selftest_rejects_an_unknown_world_and_bad_seeds():
    _load()
    res = CliRunner().invoke(app, ["sim2real", "selftest", "--world", "mars"])
    assert res.exit_code == 2 and "unknown world 'mars'" in res.output and "independent" in res.output
    res = CliRunner().invoke(app, ["sim2real", "selftest", "--world", "independent", "--seeds", "one"])
    assert res.exit_code == 2 and "--seeds" in res.output
