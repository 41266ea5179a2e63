"""Trips out as CAN traffic (project DBC from the sensor quantisation, frames at channel rates) and back in."""

from __future__ import annotations

from types import SimpleNamespace

import cantools
import numpy as np
import pandas as pd
import pytest

from roadload import Trip
from roadload.io.export import export_channels, export_trip
from roadload.io.frames import read_can_log
from roadload.io.importer import import_log
from roadload.io.report import LogImportError

RES = {"vehicle_speed": 0.01, "accel_x": 0.05, "drive_torque": 0.5, "yaw_rate": 0.001, "ambient_temperature": 0.5,
       "gear": 1.0}
UNITS = {"t": "s", "vehicle_speed": "m/s", "accel_x": "m/s^2", "drive_torque": "N*m", "yaw_rate": "rad/s",
         "ambient_temperature": "K", "gear": "1"}


def _sensors(rates=None):
    rates = rates or {}
    return SimpleNamespace(sample_rate=100.0, channels={
        k: SimpleNamespace(resolution=r, enabled=True, rate=rates.get(k)) for k, r in RES.items()})


def _trip(quantised=True, duration=30.0):
    t = np.arange(0, duration, 0.01)
    cols = {"t": t, "vehicle_speed": 10 + 5 * np.sin(t / 5), "accel_x": np.cos(t / 5) - 0.3,
            "drive_torque": 100 * np.sin(t) - 20, "yaw_rate": 0.1 * np.sin(t / 3),
            "ambient_temperature": 290.0 + 0.01 * t, "gear": 1.0 + (t > 10) + (t > 20)}
    if quantised:
        for k, r in RES.items():
            cols[k] = np.round(cols[k] / r) * r
    return Trip(pd.DataFrame(cols), dict(UNITS), {"name": "sim", "t0_unix": 1.7e9})


@pytest.mark.parametrize("fmt,import_fmt", [("candump", "candump"), ("blf", "blf"), ("mf4", "dbc-mf4")])
def test_round_trip_to_quantisation(tmp_path, fmt, import_fmt):
    trip = _trip()
    paths = export_trip(trip, tmp_path / "sim", fmt, sensors=_sensors({"ambient_temperature": 1.0}))
    back = import_log(paths["log"], import_fmt, paths["mapping"])
    assert len(back) == len(trip)
    np.testing.assert_allclose(back.t, trip.t, atol=1e-9)
    for name, res in RES.items():
        # exact up to the frame time stamps: absolute unix seconds in float64 carry ~0.2 us of rounding, which
        # linear interpolation turns into errors far below one quantisation step
        tol = 1e-3 * res
        if name == "ambient_temperature":
            # 1 Hz channel held on the 100 Hz base: equal at every whole second
            np.testing.assert_allclose(back.channel(name)[::100], trip.channel(name)[::100], atol=tol)
        else:
            np.testing.assert_allclose(back.channel(name), trip.channel(name), atol=tol, err_msg=name)
    assert back.meta["import_report"]["n_dropped"] == 0 and back.meta["import_report"]["n_repaired"] == 0
    assert back.meta["t0_unix"] == pytest.approx(1.7e9, abs=1e-4)


def test_unquantised_values_come_back_within_half_a_step(tmp_path):
    trip = _trip(quantised=False)
    paths = export_trip(trip, tmp_path / "sim.log", "candump", sensors=_sensors())
    back = import_log(paths["log"], "candump", paths["mapping"])
    for name, res in RES.items():
        err = np.abs(back.channel(name) - trip.channel(name))
        assert err.max() <= res / 2 + 1e-9, name
        if name not in ("gear",):
            assert err.max() > res / 10, name  # the values really were quantised on the way


def test_dbc_scales_are_the_sensor_resolutions_and_rates_are_kept(tmp_path):
    trip = _trip()
    paths = export_trip(trip, tmp_path / "sim.blf", "blf", sensors=_sensors({"ambient_temperature": 1.0,
                                                                               "gear": 10.0}))
    db = cantools.database.load_file(str(paths["dbc"]))
    scales = {s.name: s.scale for m in db.messages for s in m.signals}
    assert scales == RES
    frames = read_can_log(paths["log"])
    ids, counts = np.unique(frames.arbitration_id, return_counts=True)
    by_id = dict(zip(ids.tolist(), counts.tolist()))
    rate_of = {m.frame_id: {s.name for s in m.signals} for m in db.messages}
    for fid, names in rate_of.items():
        expect = 30 if names == {"ambient_temperature"} else 300 if names == {"gear"} else 3000
        assert by_id[fid] == expect, names


def test_nan_channel_is_an_error_and_nothing_is_written(tmp_path):
    trip = _trip()
    trip.measured.loc[500, "drive_torque"] = np.nan
    with pytest.raises(LogImportError, match="channel drive_torque: 1 NaN/inf values cannot be sent"):
        export_trip(trip, tmp_path / "x.log", "candump", sensors=_sensors())
    assert list(tmp_path.iterdir()) == []


def test_too_fine_resolution_is_refused():
    trip = _trip()
    sensors = _sensors()
    sensors.channels["drive_torque"].resolution = 1e-9
    with pytest.raises(LogImportError, match="drive_torque: range .* needs .* bits"):
        export_channels(trip, sensors)


def test_unknown_format():
    with pytest.raises(LogImportError, match="unknown CAN export format 'pcap'"):
        export_trip(_trip(), "x.pcap", "pcap")


def test_cli_export_then_import(tmp_path):
    from typer.testing import CliRunner

    from roadload.experiments.cli import app

    trip = _trip(duration=5.0)
    trip.save(tmp_path / "sim.parquet")
    runner = CliRunner()
    res = runner.invoke(app, ["export-can", str(tmp_path / "sim.parquet"), "--format", "candump"])
    assert res.exit_code == 0, res.output
    assert (tmp_path / "sim.log").is_file() and (tmp_path / "sim.dbc").is_file()
    res = runner.invoke(app, ["import", str(tmp_path / "sim.log"), "--format", "candump", "--mapping",
                              str(tmp_path / "sim.mapping.json"), "--out", str(tmp_path / "back.parquet")])
    assert res.exit_code == 0, res.output
    back = Trip.load(tmp_path / "back.parquet")
    np.testing.assert_allclose(back.channel("drive_torque"), trip.channel("drive_torque"), atol=1e-3 * 0.5)
    res = runner.invoke(app, ["import", str(tmp_path / "missing.log"), "--format", "candump", "--mapping",
                              str(tmp_path / "sim.mapping.json"), "--out", str(tmp_path / "x.parquet")])
    assert res.exit_code == 2 and not (tmp_path / "x.parquet").exists()


def test_packaged_project_dbcs_match_the_presets_sensor_quantisation(tmp_path):
    from roadload.presets import PRESETS, get_preset
    from roadload.io.export import PROJECT_DBC_DIR, write_project_dbc

    for preset in PRESETS:
        fresh = write_project_dbc(preset, tmp_path)
        packaged = PROJECT_DBC_DIR / fresh.name
        assert packaged.read_text() == fresh.read_text(), \
            f"{packaged.name} is stale: regenerate with roadload.io.export.write_project_dbc({preset!r})"
        sensors = get_preset(preset).sensors
        db = cantools.database.load_file(str(packaged))
        scales = {s.name: s.scale for m in db.messages for s in m.signals}
        for name, ch in sensors.channels.items():
            if ch.enabled and ch.resolution > 0:
                assert scales[name] == ch.resolution, name


def test_simulated_trip_round_trip_through_mf4(tmp_path, hilly_road):
    """The simulator's trip (sensor spec in its metadata) -> MF4 + project DBC -> import: every channel back to
    quantisation; the only differences are the importer's counted repairs (negative wheel speeds at standstill
    clipped to 0)."""
    from roadload.envs.simulator import simulate
    from roadload.io.export import sensors_from_meta

    trip = simulate("bmw_i3", hilly_road, seed=3, duration=30.0)
    sensors = sensors_from_meta(trip.meta)
    paths = export_trip(trip, tmp_path / "sim", "mf4")
    db = cantools.database.load_file(str(paths["dbc"]))
    scales = {s.name: s.scale for m in db.messages for s in m.signals}
    for name, spec in sensors.channels.items():
        if spec.enabled and spec.resolution > 0 and name in trip.channels:
            assert scales[name] == spec.resolution, name
    back = import_log(paths["log"], "dbc-mf4", paths["mapping"])
    assert back.channels == trip.channels and len(back) == len(trip)
    clipped = 0
    for name in trip.channels:
        a, b = back.channel(name), trip.channel(name)
        differs = np.abs(a - b) > 1e-9
        np.testing.assert_array_equal(a[differs], 0.0, err_msg=name)  # only clipped samples differ ...
        assert np.all(b[differs] < 0), name  # ... and those were negative speeds
        clipped += int(differs.sum())
    report = back.meta["import_report"]
    assert report["n_repaired"] == clipped and report["n_dropped"] == 0


# ------------------------------------------------------------------------------------ file exports: MDF4, CSV, MAT
@pytest.fixture(scope="module")
def simulated(tmp_path_factory, hilly_road):
    from roadload.envs.simulator import simulate

    path = tmp_path_factory.mktemp("exports") / "sim.parquet"
    return simulate("bmw_i3", hilly_road, seed=2, duration=60.0, out=path)


def test_mdf4_export_opens_in_asammdf_with_units_and_reimports_within_resolution(tmp_path, simulated):
    from asammdf import MDF

    from roadload.channels import MEASURED
    from roadload.io.export import export_file
    from roadload.trip import resolutions_from_meta

    trip = Trip.load(simulated)
    path = export_file(trip, tmp_path / "sim.mf4", "mf4", truth=True)
    mdf = MDF(path)
    units = {}
    for sig in mdf.iter_channels(skip_master=True):
        units[sig.name] = sig.unit
        if sig.name == "vehicle_speed":
            np.testing.assert_array_equal(sig.timestamps, trip.t)
            np.testing.assert_array_equal(sig.samples, trip.channel("vehicle_speed"))
    mdf.close()
    assert units["vehicle_speed"] == "m/s" and units["accel_x"] == "m/s^2" and units["drive_torque"] == "N*m"
    assert units["brake_pressure_front"] == "Pa" and units["truth/tractive_force"] == "N"
    assert all(units[c] == trip.units[c] for c in trip.channels)

    back = import_log(path, "mf4")                       # the catalogue names map themselves, no mapping file
    assert back.channels == trip.channels and back.units == {**trip.units}
    assert len(back) == len(trip) and back.meta["origin"]["source"] == "sim"
    np.testing.assert_allclose(back.t, trip.t - trip.t[0], atol=1e-9)          # t restarts at 0 on import
    assert back.meta["t0_unix"] == pytest.approx(back.meta["t0_unix"])
    res = resolutions_from_meta(trip.meta)
    repaired = {r["what"]: r["count"] for r in back.meta["import_report"]["repairs"]}
    for c in trip.channels:
        step = res.get(c, 0.0)
        assert MEASURED[c].unit == back.units[c]
        x, y = back.channel(c), trip.channel(c)
        # the importer's one documented repair: small negative speeds (sensor noise at standstill) clipped to 0
        clipped = (y < 0) & (x == 0) if c in ("vehicle_speed", "wheel_speed_fl", "wheel_speed_fr",
                                              "wheel_speed_rl", "wheel_speed_rr") else np.zeros(y.size, bool)
        assert int(clipped.sum()) == repaired.get(c, 0), c
        np.testing.assert_allclose(x[~clipped], y[~clipped], rtol=0, atol=max(step / 2, 1e-9), err_msg=c)
    assert "truth/tractive_force" in back.meta["unmapped_signals"]          # truth listed, not imported
    assert not back.measured.isna().any().any()                            # the last sample survives the time base


def test_the_time_base_keeps_a_last_sample_that_rounding_puts_past_the_span():
    from roadload.io.resample import resample, uniform_time_base

    t = np.cumsum(np.full(6000, 0.01))                 # an accumulated clock, as the simulator's: ends at 59.9999...
    grid = uniform_time_base(t[0], t[-1], 100.0)      # 0.01 + 5999 / 100 = 60.0 > 59.99999999999663
    assert grid.size == t.size and grid[-1] > t[-1]
    for rule in ("linear", "hold", "nearest"):
        out = resample(t, t * 2.0, grid, rule)
        assert not np.isnan(out).any() and out[-1] == pytest.approx(120.0), rule


def test_csv_export_has_a_units_row_and_exact_numbers(tmp_path, simulated):
    from roadload.io.export import export_file

    trip = Trip.load(simulated)
    path = export_file(trip, tmp_path / "sim.csv", "csv", truth=True)
    with open(path, encoding="utf-8") as fh:
        names, units = fh.readline().strip().split(","), fh.readline().strip().split(",")
    assert names[:2] == ["t", "wheel_speed_fl"] and "truth/tractive_force" in names
    assert dict(zip(names, units))["vehicle_speed"] == "m/s" and dict(zip(names, units))["truth/mass"] == "kg"
    frame = pd.read_csv(path, skiprows=[1])
    np.testing.assert_array_equal(frame["vehicle_speed"].to_numpy(), trip.channel("vehicle_speed"))
    np.testing.assert_array_equal(frame["truth/mass"].to_numpy(), trip.true("mass"))


def test_mat_export_loads_in_scipy_with_units_and_metadata(tmp_path, simulated):
    import json

    from scipy.io import loadmat

    from roadload.io.export import export_file

    trip = Trip.load(simulated)
    path = export_file(trip, tmp_path / "sim.mat", "mat")
    mat = loadmat(path, squeeze_me=True, struct_as_record=False)
    np.testing.assert_array_equal(mat["measured"].vehicle_speed, trip.channel("vehicle_speed"))
    np.testing.assert_array_equal(mat["measured"].t, trip.t)
    assert mat["units"].vehicle_speed == "m/s" and mat["units"].t == "s"
    assert json.loads(mat["meta_json"])["source"] == "sim" and "truth" not in mat


def test_file_exports_refuse_what_they_cannot_write(tmp_path):
    from roadload.io.export import export_file

    trip = _trip(duration=1.0)
    with pytest.raises(LogImportError, match="has no ground truth"):
        export_file(trip, tmp_path / "x.mf4", "mf4", truth=True)
    with pytest.raises(LogImportError, match=r"unknown export format 'mdf' \(did you mean 'mf4'\?\)"):
        export_file(trip, tmp_path / "x.mdf", "mdf")
    only_t = Trip(pd.DataFrame({"t": np.arange(5) / 100}), {"t": "s"})
    with pytest.raises(LogImportError, match="no measured channel besides 't': nothing to export"):
        export_file(only_t, tmp_path / "x.csv", "csv")
    odd = Trip(pd.DataFrame({"t": np.arange(5) / 100, "my-signal": 1.0}), {"t": "s", "my-signal": "1"})
    with pytest.raises(LogImportError, match=r"\['my-signal'\] are not MATLAB field names"):
        export_file(odd, tmp_path / "x.mat", "mat")
    assert list(tmp_path.iterdir()) == []


def test_can_export_with_no_exportable_channel_refuses_and_writes_nothing(tmp_path):
    only_t = Trip(pd.DataFrame({"t": np.arange(50) / 100}), {"t": "s"})
    with pytest.raises(LogImportError, match="no channels to export"):
        export_trip(only_t, tmp_path / "a.log", "candump")
    disabled = SimpleNamespace(sample_rate=100.0, channels={k: SimpleNamespace(resolution=r, enabled=False,
                                                                               rate=None) for k, r in RES.items()})
    with pytest.raises(LogImportError, match="no channels to export"):
        export_trip(_trip(duration=1.0), tmp_path / "b.log", "candump", sensors=disabled)
    with pytest.raises(LogImportError, match="no channels to export"):
        export_trip(_trip(duration=1.0), tmp_path / "c.log", "candump", channels=[])
    assert list(tmp_path.iterdir()) == []


def test_cli_export_convert_and_can_refusals(tmp_path, simulated):
    from typer.testing import CliRunner

    from roadload.experiments.cli import app

    runner = CliRunner()
    res = runner.invoke(app, ["export", str(simulated), "--format", "csv", "--out", str(tmp_path / "s.csv")])
    assert res.exit_code == 0 and "wrote" in res.output and (tmp_path / "s.csv").is_file()
    res = runner.invoke(app, ["export-can", str(simulated), "--channels", " , ", "--out", str(tmp_path / "c")])
    assert res.exit_code == 2 and "--channels: no channel named" in res.output
    res = runner.invoke(app, ["export-can", str(simulated), "--channels", "vehicle_sped", "--out", str(tmp_path / "c")])
    assert res.exit_code == 2 and "(did you mean 'vehicle_speed'?)" in res.output
    packed = Trip.load(simulated).save(tmp_path / "old.parquet", precision="packed")
    res = runner.invoke(app, ["convert", str(packed), "--out", str(tmp_path / "new.parquet")])
    assert res.exit_code == 0 and "format 3 (packed" in res.output and "-> format 4 (compact" in res.output
    assert sorted(p.name for p in tmp_path.iterdir()) == ["new.parquet", "old.parquet", "s.csv"]
