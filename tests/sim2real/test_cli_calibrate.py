"""``roadload calibrate``, ``roadload sim2real inject`` and the diagnose command's messages: the files a calibration
writes, clear errors for bad input with nothing written, an error naming a file once, and a diagnosis that
accepts nothing saying why."""

from __future__ import annotations

import json

import pytest
from typer.testing import CliRunner

from roadload.experiments.cli import _load, app
from roadload.sim2real.diagnose import sim_trips
from roadload.sim2real.simconfig import SimConfig
from roadload.trip import Trip


@pytest.fixture(scope="module")
def trip_files(tmp_path_factory):
    folder = tmp_path_factory.mktemp("trips")
    for trip in sim_trips(SimConfig.load("bmw_i3"), (("hilly", 71), ("city", 72)), 420.0):
        trip.save(folder / f"{trip.meta['name']}.parquet")
    return folder


def _run(*args: str):
    _load()
    return CliRunner().invoke(app, list(args))


def test_cli_calibrate_writes_the_spec_its_sim_config_report_and_figure(trip_files, tmp_path):
    out = tmp_path / "cal" / "calibrated.json"
    res = _run("calibrate", "--sim", "bmw_i3", "--real", str(trip_files), "--out", str(out), "--floor-duration",
               "120")
    assert res.exit_code == 0, res.output
    assert "held-out force RMSE" in res.output and "calibrated.json" in res.output
    for name in ("calibrated.json", "calibrated_sim.json", "calibrated_calibration.json",
                 "calibrated_calibration.md", "calibrated_residual.png"):
        assert (out.parent / name).is_file(), name
    record = json.loads((out.parent / "calibrated_calibration.json").read_text())
    mass = next(p for p in record["parameters"] if p["name"] == "mass")
    assert mass["value_unit"] == "kg" and mass["low"] <= mass["calibrated"] <= mass["high"]
    assert mass["calibrated"] == pytest.approx(1400.0, abs=3 * mass["calibrated_std"] + 30.0)   # the sim's own car


def test_cli_calibrate_refuses_an_output_that_is_no_json_and_writes_nothing(trip_files, tmp_path):
    res = _run("calibrate", "--sim", "bmw_i3", "--real", str(trip_files), "--out", str(tmp_path / "cal.txt"))
    assert res.exit_code == 2 and "ends in .json" in res.output
    assert not list(tmp_path.iterdir())


def test_cli_inject_writes_copies_and_refuses_bad_sizes(trip_files, tmp_path):
    out = tmp_path / "injected"
    res = _run("sim2real", "inject", "--real", str(trip_files), "--effect", "accel_bias", "--size", "0.1",
               "--out", str(out))
    assert res.exit_code == 0, res.output
    files = sorted(out.glob("*.parquet"))
    assert len(files) == 2 and files[0].name.endswith("+accel_bias.parquet")
    original = Trip.load(sorted(trip_files.glob("*.parquet"))[0])
    copy = Trip.load(files[0])
    assert (copy.channel("accel_x") - original.channel("accel_x")).mean() == pytest.approx(0.1, abs=1e-3)
    assert copy.meta["injected"]["size"] == 0.1
    bad = _run("sim2real", "inject", "--real", str(trip_files), "--effect", "latency", "--size", "30",
               "--out", str(tmp_path / "bad"))
    assert bad.exit_code == 2 and "must lie in [0, 5] [s]" in bad.output
    assert not (tmp_path / "bad").exists()
    unknown = _run("sim2real", "inject", "--real", str(trip_files), "--effect", "payload", "--size", "1",
                   "--out", str(tmp_path / "bad"))
    assert unknown.exit_code == 2 and "unknown injected effect 'payload'" in unknown.output


def test_cli_diagnose_names_a_broken_log_once(tmp_path):
    log = tmp_path / "broken.csv"
    log.write_text("time_s,speed_kmh\n0,1\n")
    res = _run("diagnose", "--sim", "bmw_i3", "--real", str(log), "--format", "csv", "--out", str(tmp_path / "o"))
    assert res.exit_code == 2
    assert res.output.count("broken.csv") == 1, res.output


def test_cli_diagnose_says_why_nothing_was_identified(trip_files, tmp_path):
    res = _run("diagnose", "--sim", "bmw_i3", "--real", str(trip_files), "--out", str(tmp_path / "d"),
               "--no-resimulate", "--floor-duration", "120")
    assert res.exit_code == 0, res.output
    assert "identified: none" in res.output
    assert "force side: " in res.output and ("not accepted" in res.output or "significant alone" in res.output)
