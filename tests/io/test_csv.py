"""CSV (BMW i3 layout), OpenXC and comma2k19-array loaders on small generated files."""

from __future__ import annotations

import json

import numpy as np
import pytest

from roadload.io.bmw_i3 import extra_payload_kg
from roadload.io.derived import rim_torque_from_motor, vehicle_spec
from roadload.io.frames import read_comma2k19
from roadload.io.importer import import_log
from roadload.io.loaders import split_header
from roadload.io.report import LogImportError

I3_HEADER = ("Time [s];Velocity [km/h];Elevation [m];Throttle [%];Motor Torque [Nm];"
             "Longitudinal Acceleration [m/s^2];Regenerative Braking Signal ;Battery Voltage [V];"
             "Battery Current [A];Battery Temperature [°C];max. SoC [%);SoC [%];Heating Power CAN [kW];"
             "AirCon Power [kW];Ambient Temperature [°C];Cabin Temperature Sensor [°C];Temperature Vent right [°C] ;"
             "Temperature Vent right [°C]")


def _i3_csv(path, n=3000, grade=0.02, drop_column=None):
    """A 10 Hz i3-layout trip: accelerate to 15 m/s, cruise uphill at `grade` (elevation in whole metres)."""
    t = np.arange(n) * 0.1
    v = np.minimum(t * 1.5, 15.0)
    s = np.concatenate([[0.0], np.cumsum(0.5 * (v[1:] + v[:-1]) * 0.1)])
    z = np.floor(500.0 + grade * s)  # 1 m quantisation like the real log
    torque = np.where(t * 1.5 < 15.0, 150.0, 40.0)
    cols = {"Time [s]": t, "Velocity [km/h]": v * 3.6, "Elevation [m]": z, "Throttle [%]": np.full(n, 30.0),
            "Motor Torque [Nm]": torque, "Longitudinal Acceleration [m/s^2]": np.where(t * 1.5 < 15, 1.5, 0.0),
            "Regenerative Braking Signal ": np.zeros(n), "Battery Voltage [V]": np.full(n, 380.0),
            "Battery Current [A]": -torque / 3, "Battery Temperature [°C]": np.full(n, 21.0),
            "max. SoC [%)": np.full(n, 90.0), "SoC [%]": np.linspace(80, 79, n),
            "Heating Power CAN [kW]": np.full(n, 1.5), "AirCon Power [kW]": np.zeros(n),
            "Ambient Temperature [°C]": np.full(n, 5.0), "Cabin Temperature Sensor [°C]": np.full(n, 20.0),
            "Temperature Vent right [°C] ": np.full(n, 30.0), "Temperature Vent right [°C]": np.full(n, 31.0)}
    names = I3_HEADER.split(";")
    keep = [k for k, name in enumerate(names) if name != drop_column]
    rows = [";".join(names[k] for k in keep)]
    values = list(cols.values())
    for i in range(n):
        rows.append(";".join(f"{values[k][i]:.2f}" for k in keep))
    path.write_bytes(("\r\n".join(rows) + "\r\n").encode("latin-1"))
    overview = path.parent / "overview.csv"
    overview.write_text("Trip,Date,Route/Area,Distance [km],Note\n"
                        f"{path.stem},2020-01-01_10-00-00,Test loop,{s[-1] / 1000:.4f},'+70 kg\"\n")
    return t, v, s, z, torque


def test_i3_csv_through_the_mapping(tmp_path):
    t, v, s, z, torque = _i3_csv(tmp_path / "TripZ01.csv")
    trip = import_log(tmp_path / "TripZ01.csv", "bmw-i3")
    assert trip.sample_rate == pytest.approx(10.0) and len(trip) == t.size
    np.testing.assert_allclose(trip.channel("vehicle_speed"), v, atol=0.01 / 3.6)
    np.testing.assert_allclose(trip.channel("ambient_temperature"), 278.15)
    np.testing.assert_allclose(trip.channel("heating_power"), 1500.0)
    np.testing.assert_allclose(trip.channel("battery_current"), torque / 3, atol=0.01)  # discharge positive
    np.testing.assert_allclose(trip.channel("accelerator_pedal"), 0.30)
    # rim torque: motor torque x i (preset gear ratio) x efficiency 0.97 (driving)
    spec = vehicle_spec("bmw_i3")
    ratio = spec.drivetrain.gear_ratios[0] * spec.drivetrain.final_drive
    np.testing.assert_allclose(trip.channel("rim_torque"), torque * ratio * 0.97)
    assert trip.meta["derived"][1]["ratio"] == pytest.approx(ratio)
    # grade from 1 m quantised elevation, smoothed over 150 m: 2 % recovered on the cruise part
    cruise = (trip.channel("distance") > 400) & (trip.channel("distance") < s[-1] - 400)
    assert np.tan(trip.channel("grade")[cruise]).mean() == pytest.approx(0.02, abs=0.002)
    assert np.abs(np.tan(trip.channel("grade")[cruise]) - 0.02).max() < 0.006
    # metadata: overview row, payload note, the duplicate column repaired and counted
    assert trip.meta["overview"]["Route/Area"] == "Test loop"
    assert trip.meta["extra_payload_kg"] == 70.0
    assert trip.meta["import_report"]["repairs"][0]["what"] == "Temperature Vent right [°C]"
    assert trip.meta["mapping"] == "bmw_i3" and "CC BY 4.0" in trip.meta["licence"]


def test_i3_csv_with_a_missing_column(tmp_path):
    _i3_csv(tmp_path / "TripZ02.csv", n=200, drop_column="Velocity [km/h]")
    with pytest.raises(LogImportError, match=r"vehicle_speed \(source 'Velocity \[km/h\]'"):
        import_log(tmp_path / "TripZ02.csv", "bmw-i3")


def test_i3_csv_without_time_column(tmp_path):
    _i3_csv(tmp_path / "TripZ03.csv", n=50, drop_column="Time [s]")
    with pytest.raises(LogImportError, match=r"time column 'Time \[s\]' missing"):
        import_log(tmp_path / "TripZ03.csv", "bmw-i3")


def test_generic_csv_with_column_map(tmp_path):
    path = tmp_path / "log.csv"
    path.write_text("time_ms,speed_mph,temp_C\n0,10,20\n100,20,20\n200,30,21\n300,40,21\n")
    mapping = {"name": "custom", "format": "csv", "sample_rate": 10,
               "csv": {"sep": ",", "time": "time_ms", "time_unit": "ms"},
               "channels": [{"source": "speed_mph", "channel": "vehicle_speed", "unit": "mph", "required": True},
                            {"source": "temp_C", "channel": "ambient_temperature", "unit": "degC",
                             "resample": "hold"}]}
    (tmp_path / "map.json").write_text(json.dumps(mapping))
    trip = import_log(path, "csv", tmp_path / "map.json")
    np.testing.assert_allclose(trip.t, [0, 0.1, 0.2, 0.3])
    np.testing.assert_allclose(trip.channel("vehicle_speed"), np.array([10, 20, 30, 40]) * 0.44704)
    np.testing.assert_allclose(trip.channel("ambient_temperature"), [293.15, 293.15, 294.15, 294.15])


def test_header_units_and_payload_notes():
    assert split_header("Velocity [km/h]") == ("Velocity", "km/h")
    assert split_header("max. SoC [%)") == ("max. SoC", "%")
    assert split_header("Regenerative Braking Signal ") == ("Regenerative Braking Signal", None)
    assert extra_payload_kg("'+70 kg\"") == 70.0
    assert extra_payload_kg("+60 kg ") == 60.0
    assert extra_payload_kg("Rush Hour") is None and extra_payload_kg(None) is None


def test_rim_torque_efficiency_direction():
    np.testing.assert_allclose(rim_torque_from_motor([100.0, -50.0], 10.0, 0.9), [900.0, -500.0 / 0.9])
    with pytest.raises(LogImportError, match="efficiency"):
        rim_torque_from_motor([1.0], 10.0, 1.2)


def test_openxc_trace(tmp_path):
    lines = []
    t0 = 1.6e9
    for k in range(200):  # 20 s, speed every 0.1 s, torque every 0.25 s, gear on change
        t = t0 + 0.1 * k
        lines.append(f'{t:.6f}: {{"name":"vehicle_speed","value":{36.0 + k * 0.1:.3f}}}')
        if k % 5 == 0:
            lines.append(f'{t + 0.01:.6f}: {{"name":"engine_speed","value":{1500 + k:.1f}}}')
        if k % 3 == 0:
            lines.append(f'{t + 0.02:.6f}: {{"name":"powertrain_torque","value":{80.0:.1f}}}')
    lines.insert(3, f'{t0 + 0.05:.6f}: {{"name":"transmission_gear_position","value":"second"}}')
    lines.append(f'{t0 + 10.05:.6f}: {{"name":"transmission_gear_position","value":"third"}}')
    lines.append(f'{t0 + 12.0:.6f}: {{"name":"brake_pedal_status","value":true}}')
    lines.append("garbage line: {not json")
    path = tmp_path / "trace.openxc.txt"
    path.write_text("\n".join(sorted(lines[:-1]) + lines[-1:]) + "\n")
    trip = import_log(path, "openxc")
    gear = trip.channel("gear")
    tt = trip.t + (trip.meta["t0_unix"] - t0)
    assert np.all(gear[(tt > 0.06) & (tt < 10.04)] == 2) and np.all(gear[tt > 10.06] == 3)  # held to the end
    np.testing.assert_allclose(trip.channel("vehicle_speed"), (36.0 + tt * 1.0) / 3.6, atol=1e-9)
    np.testing.assert_allclose(trip.channel("drive_torque"), 80.0)
    assert {"what": "OpenXC lines", "reason": "malformed JSON record", "count": 1,
            "detail": ""} in trip.meta["import_report"]["dropped"]
    (tmp_path / "bad.txt").write_text('{"name":"vehicle_speed","value":1}\n')
    with pytest.raises(LogImportError, match="without a time stamp"):
        import_log(tmp_path / "bad.txt", "openxc")


def test_comma2k19_arrays(tmp_path):
    folder = tmp_path / "raw_can"
    folder.mkdir()
    t = 1000.0 + np.arange(6) * 0.01
    np.save(folder / "t.npy", t)
    np.save(folder / "address.npy", np.array([180, 37, 180, 0x18FEF100, 37, 180]))
    np.save(folder / "src.npy", np.array([0, 0, 0, 1, 0, 128]))
    np.save(folder / "data.npy", np.array([b"\x01\x02", b"\x00" * 8, b"\xff" * 8, b"\x10", b"\x01", b"\x02\x03"],
                                          dtype="S8"))
    for name in ("t", "address", "src", "data"):
        (folder / f"{name}.npy").rename(folder / name)  # comma2k19 arrays have no extension
    frames = read_comma2k19(folder)
    np.testing.assert_allclose(frames.t, t - t[0])
    assert frames.start_time == 1000.0
    np.testing.assert_array_equal(frames.is_extended, [False, False, False, True, False, False])
    np.testing.assert_array_equal(frames.data[0, :3], [1, 2, 0])  # NUL padding restored
    np.testing.assert_array_equal(frames.data[2], [255] * 8)
    (folder / "src").unlink()
    with pytest.raises(LogImportError, match="raw_can array 'src' missing"):
        read_comma2k19(folder)


def test_elevation_change_at_standstill_is_removed_and_counted():
    from roadload.io.derived import freeze_elevation_at_standstill, grade_from_elevation_track
    from roadload.io.report import ImportReport

    t = np.arange(0, 200, 0.1)
    v = np.where(t < 30, 0.0, 10.0)
    z = np.where(t < 30, 500 + t / 3, 510.0)  # the log ramps 10 m while the car stands, then the road is flat
    report = ImportReport()
    fixed = freeze_elevation_at_standstill(v, z, report)
    np.testing.assert_allclose(fixed, 500.0, atol=0.034)  # only the last 0.1 s step falls on a moving sample
    assert report.repairs[0]["count"] == 299 and "10.0 m in total" in report.repairs[0]["detail"]
    grade = grade_from_elevation_track(t, v, z, ImportReport())
    assert np.abs(np.tan(grade)).max() < 1e-3  # 0.1 %; without the repair: 10 m over ~0 m
