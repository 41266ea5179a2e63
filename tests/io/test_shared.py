"""Importers on the real logs of ../shared/data (skipped with a reason when the folder is absent)."""

from __future__ import annotations

import shutil

import numpy as np
import pytest

from roadload.io.dbc import DbcSource, decode_frames, load_dbc
from roadload.io.frames import read_comma2k19, read_mf4
from roadload.io.importer import import_log
from roadload.io.mapping import load_mapping
from roadload.io.profiles import profile_from_trip
from roadload.io.report import ImportReport, LogImportError

pytestmark = pytest.mark.shared_data


@pytest.fixture(scope="module")
def canedge():
    from roadload.data import shared_data_dir

    base = shared_data_dir()
    if base is None or not (base / "css_canedge_gnss_obd").is_dir():
        pytest.skip("needs ../shared/data/css_canedge_gnss_obd (or $ROADLOAD_DATA); not present")
    folder = base / "css_canedge_gnss_obd" / "raw_mf4"
    return {s: import_log(folder / f"3BA199E2_00000{s}", "dbc-mf4") for s in ("164", "165")}


def test_canedge_session_164_is_a_40_km_trip(canedge):
    trip = canedge["164"]
    gnss_odo = np.nanmax(trip.channel("gnss_distance"))
    integrated = np.trapezoid(trip.channel("gnss_speed"), trip.t)
    assert gnss_odo == pytest.approx(40_500, rel=0.02)  # SOURCE.md: 40.5 km
    assert integrated == pytest.approx(gnss_odo, rel=0.01)
    assert trip.duration == pytest.approx(37.6 * 60, abs=60)  # 04:41-05:20 UTC minus the GNSS start-up
    assert trip.meta["sample_rate"] == 100 and trip.sample_rate == pytest.approx(100)
    # OBD-II speed (whole km/h, 2 Hz) agrees with GNSS speed
    v_obd, v_gnss = trip.channel("vehicle_speed"), trip.channel("gnss_speed")
    assert np.corrcoef(v_obd, v_gnss)[0, 1] > 0.99
    assert np.nanmedian(v_obd[v_gnss > 5] / v_gnss[v_gnss > 5]) == pytest.approx(1.0, abs=0.03)


def test_canedge_clock_offset_and_invalid_gnss(canedge):
    # SOURCE.md: the logger clock differs from the GNSS epoch by ~4.4 s (164) and ~5.6 s (165)
    assert abs(canedge["164"].meta["clock"]["offset_s"]) == pytest.approx(4.4, abs=0.2)
    assert abs(canedge["165"].meta["clock"]["offset_s"]) == pytest.approx(5.6, abs=0.2)
    for trip in canedge.values():
        assert trip.meta["clock"]["residual_rms_s"] < 0.1
        rep = trip.meta["import_report"]
        dropped = {(d["what"], d["reason"]): d["count"] for d in rep["dropped"]}
        assert dropped[("elevation", "validity flag gnss_altitude.AltitudeValid = 0")] > 10  # the -5400 m
        z = trip.channel("elevation")
        assert np.nanmin(z) > 0 and np.nanmax(z) < 200  # Denmark, no -5400 m and no start-up transient
        # the IMU axes: forward acceleration follows dv/dt of the GNSS speed, yaw rate follows the course
        v = np.convolve(trip.channel("gnss_speed"), np.ones(200) / 200, "same")
        ax = np.convolve(trip.channel("accel_x"), np.ones(200) / 200, "same")
        assert np.corrcoef(np.gradient(v, trip.t)[300:-300], ax[300:-300])[0, 1] > 0.75


def test_canedge_profiles_from_each_drive(canedge):
    for session, trip in canedge.items():
        prof = profile_from_trip(trip, name=f"canedge_{session}", source="CSS-Electronics/api-examples",
                                 licence="MIT")
        assert prof.length == pytest.approx(np.nanmax(trip.channel("gnss_distance")), rel=0.01)
        assert np.all(np.abs(np.tan(prof.grade)) <= 0.30 + 1e-12)
        assert 0.005 < np.tan(prof.grade).std() < 0.05  # a rolling Danish road, not flat, not a cliff
        assert prof.meta["licence"] == "MIT" and prof.meta["curvature_source"] == "yaw_rate"
        # curvature from the IMU yaw rate and from the GNSS course agree
        other = profile_from_trip(trip, name="x", source="s", licence="MIT", grade_source="pitch",
                                  curvature_source="heading")
        assert np.corrcoef(prof.curvature, other.curvature)[0, 1] > 0.85
        assert np.corrcoef(prof.grade, other.grade)[0, 1] > 0.7  # altitude vs pitch grade


def test_truncated_real_mf4_is_a_clear_error(shared_data, tmp_path):
    src = shared_data / "css_canedge_gnss_obd" / "raw_mf4" / "3BA199E2_00000164" / "00000002-60FE415D.MF4"
    cut = tmp_path / "cut.MF4"
    cut.write_bytes(src.read_bytes()[: src.stat().st_size // 3])
    with pytest.raises(LogImportError, match=r"cut.MF4: MDF4 file truncated: data block ##DT"):
        read_mf4(cut)


def test_canedge_obd_decoding_matches_j1979(shared_data):
    folder = shared_data / "css_canedge_gnss_obd" / "raw_mf4" / "3BA199E2_00000164"
    frames = read_mf4(folder / "00000002-60FE415D.MF4")
    from roadload.io.dbc import find_dbc

    report = ImportReport()
    db = load_dbc([DbcSource(find_dbc("obd2_mode01.dbc", []), 1)], report)
    sigs = decode_frames(frames, db, report)
    sel = (frames.arbitration_id == 0x7E8) & (frames.data[:, 2] == 0x0C)
    rpm = (frames.data[sel, 3].astype(float) * 256 + frames.data[sel, 4]) / 4
    np.testing.assert_array_equal(sigs["OBD2_ECU1.engine_speed"].values, rpm)
    assert set(np.unique(sigs["OBD2_ECU1.service"].values)) == {65.0}


def test_comma2k19_raw_can_matches_the_decoded_arrays(shared_data):
    seg = shared_data / "comma2k19_example_rav4" / "segment"
    can = seg / "processed_log" / "CAN"
    m = load_mapping("comma2k19_rav4")
    frames = read_comma2k19(seg)
    report = ImportReport()
    sigs = decode_frames(frames, load_dbc([DbcSource(find_path(m), 0)], report), report)
    ws = np.load(can / "wheel_speed" / "value")
    for i, corner in enumerate(("FL", "FR", "RL", "RR")):
        np.testing.assert_allclose(sigs[f"WHEEL_SPEEDS.WHEEL_SPEED_{corner}"].values / 3.6, ws[:, i], atol=1e-12)
    steer = sigs["STEER_ANGLE_SENSOR.STEER_ANGLE"].values + sigs["STEER_ANGLE_SENSOR.STEER_FRACTION"].values
    np.testing.assert_allclose(steer, np.load(can / "steering_angle" / "value"), atol=1e-9)
    trip = import_log(seg, "comma2k19")
    assert trip.duration == pytest.approx(60.0, abs=0.5)
    v = trip.channel("vehicle_speed") * 3.6
    assert 25 < v.min() and v.max() < 75  # SOURCE.md: 29-71 km/h (speedometer reads a little high)
    wheel_mean = np.mean([trip.channel(f"wheel_ground_speed_{c}") for c in ("fl", "fr", "rl", "rr")], axis=0)
    assert np.median(trip.channel("vehicle_speed") / wheel_mean) == pytest.approx(1.02, abs=0.02)


def find_path(mapping):
    from roadload.io.dbc import find_dbc

    return find_dbc(mapping.dbc[0]["file"], [])


def test_openxc_trace(shared_data):
    trip = import_log(shared_data / "openxc_ford_trace" / "raw" / "drivingnew.openxc.txt", "openxc")
    assert trip.duration == pytest.approx(205, abs=2)  # SOURCE.md: 205 s
    v, w, gear = trip.channel("vehicle_speed"), trip.channel("engine_speed"), trip.channel("gear")
    ratios = [np.median(w[(gear == g) & (v > 2)] / v[(gear == g) & (v > 2)]) for g in (1, 2, 3, 4, 5)]
    assert np.all(np.diff(ratios) < 0)  # engine speed / road speed falls with every gear: the enum mapping holds
    with pytest.raises(LogImportError, match="without a time stamp"):
        import_log(shared_data / "openxc_ford_trace" / "raw" / "driving.openxc.txt", "openxc")


def test_bmw_i3_trip_a01(shared_data):
    trip = import_log(shared_data / "bmw_i3_tum" / "data" / "TripA01.csv", "bmw-i3")
    assert trip.duration == pytest.approx(1009, abs=1)
    assert trip.channel("vehicle_speed").max() * 3.6 == pytest.approx(53.3, abs=0.1)
    assert trip.meta["sample_rate"] == 10
    assert trip.meta["overview"]["Route/Area"] == "Munich East" and trip.meta["extra_payload_kg"] is None
    assert trip.channel("distance")[-1] == pytest.approx(trip.meta["overview"]["Distance [km]"] * 1000, rel=0.01)
    # positive battery current = discharge: it rises with motor torque
    assert np.corrcoef(trip.channel("battery_current"), trip.channel("drive_torque"))[0, 1] > 0.8
    # torque-derived wheel force against m (dv/dt + g sin(grade)): the rim torque and the grade are consistent
    from roadload.io.derived import vehicle_spec
    from roadload.units import G

    spec = vehicle_spec("bmw_i3")
    force = trip.channel("rim_torque") / spec.wheel_radius
    v = trip.channel("vehicle_speed")
    dvdt = np.gradient(np.convolve(v, np.ones(5) / 5, "same"), trip.t)
    inertial = spec.mass * (dvdt + G * np.sin(trip.channel("grade")))
    assert np.corrcoef(force, inertial)[0, 1] > 0.9


def test_bmw_i3_frozen_elevation_and_payload(shared_data):
    trip = import_log(shared_data / "bmw_i3_tum" / "data" / "TripA04.csv", "bmw-i3")
    assert "grade" not in trip.channels
    assert any("elevation frozen" in n for n in trip.meta["import_report"]["notes"])
    trip = import_log(shared_data / "bmw_i3_tum" / "data" / "TripB22.csv", "bmw-i3")
    assert trip.meta["extra_payload_kg"] == 80.0  # overview note "+80 kg"
    dup = [r for r in trip.meta["import_report"]["repairs"] if r["action"].startswith("duplicate column")]
    assert dup and dup[0]["what"] == "Temperature Vent right [°C]"


def test_missing_column_is_a_clear_error(shared_data, tmp_path):
    src = shared_data / "bmw_i3_tum" / "data" / "TripA13.csv"
    lines = src.read_text(encoding="latin-1").splitlines(keepends=True)
    cols = [c for c in lines[0].rstrip("\r\n").split(";")]
    drop = cols.index("Motor Torque [Nm]")
    bad = tmp_path / "TripA13.csv"
    bad.write_text("".join(";".join(p for k, p in enumerate(line.rstrip("\r\n").split(";")) if k != drop) + "\r\n"
                           for line in lines), encoding="latin-1")
    shutil.copy(shared_data / "bmw_i3_tum" / "overview.csv", tmp_path / "overview.csv")
    with pytest.raises(LogImportError, match=r"required channels missing in the source: drive_torque"):
        import_log(bad, "bmw-i3")
