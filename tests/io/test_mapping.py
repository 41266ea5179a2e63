"""The mapping layer: resample rules, unit checks, validation repairs (counted), clear errors."""

from __future__ import annotations

import numpy as np
import pytest

from roadload.io.mapping import Mapping, apply_mapping, load_mapping
from roadload.io.report import ImportReport, LogImportError
from roadload.io.resample import resample, uniform_time_base
from roadload.io.signals import Signal


def _mapping(channels, **kw):
    return Mapping.from_dict({"name": "m", "format": "csv", "channels": channels, **kw})


def test_resample_rules_analytic():
    t = np.array([0.0, 1.0, 2.0, 3.0])
    x = np.array([0.0, 10.0, 20.0, 0.0])
    tn = np.array([0.0, 0.4, 0.6, 1.0, 2.5, 3.0])
    np.testing.assert_allclose(resample(t, x, tn, "linear"), [0, 4, 6, 10, 10, 0])
    np.testing.assert_array_equal(resample(t, x, tn, "hold"), [0, 0, 0, 10, 20, 0])
    np.testing.assert_array_equal(resample(t, x, tn, "nearest"), [0, 0, 10, 10, 20, 0])
    # no extrapolation outside the signal's span; a held value lasts one sample interval past the last sample
    assert np.isnan(resample(t, x, np.array([-0.1, 3.1]), "linear")).all()
    np.testing.assert_array_equal(resample(t, x, np.array([-0.1, 3.9, 4.1]), "hold"), [np.nan, 0.0, np.nan])
    # circular: 350 deg -> 10 deg passes through 0, not through 180
    ang = np.radians([350.0, 10.0])
    mid = resample(np.array([0.0, 1.0]), ang, np.array([0.5]), "linear", circular=True)
    assert mid[0] == pytest.approx(0.0, abs=1e-12) or mid[0] == pytest.approx(2 * np.pi, abs=1e-12)
    with pytest.raises(LogImportError, match="unknown resample rule"):
        resample(t, x, tn, "cubic")


def test_uniform_time_base_has_no_drift():
    grid = uniform_time_base(10.0, 3610.0, 100.0)
    assert grid.size == 360_001
    assert grid[-1] == pytest.approx(3610.0, abs=1e-9)
    np.testing.assert_allclose(np.diff(grid), 0.01, atol=1e-9)


def test_units_converted_and_scaled():
    t = np.arange(0, 10, 0.1)
    sigs = {"v": Signal(t, np.full(t.size, 36.0), "km/h"), "T": Signal(t, np.full(t.size, 20.0), "°C"),
            "I": Signal(t, np.full(t.size, -5.0), "A")}
    m = _mapping([{"source": "v", "channel": "vehicle_speed", "unit": "km/h", "required": True},
                  {"source": "T", "channel": "ambient_temperature", "unit": "degC"},
                  {"source": "I", "channel": "battery_current", "unit": "A", "scale": -1}], sample_rate=10)
    trip = apply_mapping(sigs, m, ImportReport())
    np.testing.assert_allclose(trip.channel("vehicle_speed"), 10.0)
    np.testing.assert_allclose(trip.channel("ambient_temperature"), 293.15)
    np.testing.assert_allclose(trip.channel("battery_current"), 5.0)
    assert trip.units["vehicle_speed"] == "m/s" and trip.meta["sample_rate"] == 10


def test_mapping_unit_must_fit_the_channel():
    with pytest.raises(LogImportError, match="unit mismatch for channel 'vehicle_speed'"):
        _mapping([{"source": "v", "channel": "vehicle_speed", "unit": "deg"}])
    with pytest.raises(LogImportError, match="unknown unit 'furlong'"):
        _mapping([{"source": "v", "channel": "x", "unit": "furlong"}])


def test_declared_source_unit_mismatch_is_an_error():
    t = np.arange(5.0)
    m = _mapping([{"source": "v", "channel": "vehicle_speed", "unit": "m/s", "required": True}])
    with pytest.raises(LogImportError, match="unit mismatch for v -> vehicle_speed.*'km/h'"):
        apply_mapping({"v": Signal(t, t, "km/h")}, m, ImportReport())


def test_duplicate_target_channels_rejected():
    with pytest.raises(LogImportError, match=r"duplicate channel names \['vehicle_speed'\]"):
        _mapping([{"source": "a", "channel": "vehicle_speed", "unit": "m/s"},
                  {"source": "b", "channel": "vehicle_speed", "unit": "m/s"}])


def test_unknown_keys_are_typos_not_ignored():
    with pytest.raises(LogImportError, match="unknown keys \\['resmaple'\\]"):
        _mapping([{"source": "a", "channel": "vehicle_speed", "unit": "m/s", "resmaple": "hold"}])


def test_missing_required_channel_names_it_and_suggests():
    t = np.arange(5.0)
    m = _mapping([{"source": "Velocity [km/h]", "channel": "vehicle_speed", "unit": "km/h", "required": True},
                  {"source": "Torque [Nm]", "channel": "drive_torque", "unit": "N*m", "required": True}])
    sigs = {"Velocity [km/h]": Signal(t, t, "km/h"), "Torqe [Nm]": Signal(t, t, "Nm")}
    with pytest.raises(LogImportError, match=r"drive_torque \(source 'Torque \[Nm\]'; did you mean \['Torqe \[Nm\]'\]"):
        apply_mapping(sigs, m, ImportReport())


def test_lenient_name_matching():
    t = np.arange(5.0)
    m = _mapping([{"source": "Regenerative Braking Signal", "channel": "regen_braking", "unit": "1",
                   "required": True}])
    trip = apply_mapping({"regenerative  braking signal ": Signal(t, np.ones(5), None)}, m, ImportReport())
    np.testing.assert_array_equal(trip.channel("regen_braking"), 1.0)


def test_non_monotonic_time_sorted_and_counted_or_rejected():
    t = np.arange(200) * 0.1
    t_bad = t.copy()
    t_bad[[50, 51]] = t_bad[[51, 50]]  # one swap
    v = t_bad * 1.0
    m = _mapping([{"source": "v", "channel": "vehicle_speed", "unit": "m/s", "required": True}], sample_rate=10)
    report = ImportReport()
    trip = apply_mapping({"v": Signal(t_bad, v, "m/s")}, m, report)
    np.testing.assert_allclose(trip.channel("vehicle_speed"), t, atol=1e-9)
    assert report.repairs[0]["action"] == "out-of-order samples sorted by time" and report.repairs[0]["count"] == 1
    # repeated time stamps: the last sample kept, counted
    t_dup = np.concatenate([t[:10], t[9:]])
    report = ImportReport()
    apply_mapping({"v": Signal(t_dup, t_dup, "m/s")}, m, report)
    assert report.dropped[0]["count"] == 1
    # time going backwards all the time is a broken log
    with pytest.raises(LogImportError, match="time is not monotonic: it goes backwards 199 times"):
        apply_mapping({"v": Signal(t[::-1].copy(), v, "m/s")}, m, ImportReport())


def test_absurd_values_dropped_or_clipped_and_counted():
    t = np.arange(100) * 0.1
    v = np.full(100, 5.0)
    v[10] = -0.02  # standstill noise -> clipped to 0
    v[20] = -30.0  # impossible -> dropped and interpolated over
    v[30] = np.nan
    z = np.full(100, 500.0)
    z[:5] = -5400.0  # CANedge invalid altitude at start-up
    m = _mapping([{"source": "v", "channel": "vehicle_speed", "unit": "m/s", "required": True},
                  {"source": "z", "channel": "elevation", "unit": "m", "required": True}], sample_rate=10)
    report = ImportReport()
    trip = apply_mapping({"v": Signal(t, v, "m/s"), "z": Signal(t, z, "m")}, m, report)
    assert report.count("vehicle_speed") == 3
    assert {"what": "elevation", "reason": "outside the plausible range [-500, 9000]", "count": 5,
            "detail": "min -5400, max -5400"} in report.dropped
    speed = trip.channel("vehicle_speed")
    assert speed.min() == 0.0 and np.all(np.isfinite(speed))
    assert trip.t[0] == 0.0 and trip.meta["t0_unix"] == pytest.approx(0.5)  # starts where elevation is valid
    assert trip.meta["import_report"]["n_dropped"] == 7


def test_gap_bridging_is_reported():
    t = np.concatenate([np.arange(0, 10, 0.1), np.arange(20, 30, 0.1)])
    m = _mapping([{"source": "v", "channel": "vehicle_speed", "unit": "m/s", "required": True}], sample_rate=10)
    report = ImportReport()
    apply_mapping({"v": Signal(t, np.ones(t.size), "m/s")}, m, report)
    assert report.repairs[0]["what"] == "vehicle_speed" and report.repairs[0]["count"] == 100  # 10.0 .. 19.9 s


def test_enumerations_need_a_table():
    t = np.arange(4.0)
    gears = np.array(["first", "second", "neutral", "reverse"], dtype=object)
    m = _mapping([{"source": "g", "channel": "gear", "unit": "1", "resample": "hold", "required": True,
                   "values": {"neutral": 0, "first": 1, "second": 2, "reverse": -1}}], sample_rate=1)
    trip = apply_mapping({"g": Signal(t, gears)}, m, ImportReport())
    np.testing.assert_array_equal(trip.channel("gear"), [1, 2, 0, -1])
    m2 = _mapping([{"source": "g", "channel": "gear", "unit": "1", "resample": "hold", "required": True,
                    "values": {"first": 1}}], sample_rate=1)
    with pytest.raises(LogImportError, match="value 'second' is not numeric"):
        apply_mapping({"g": Signal(t, gears)}, m2, ImportReport())


def test_packaged_mappings_parse():
    for name in ("canedge_gnss_obd", "comma2k19_rav4", "bmw_i3", "openxc"):
        m = load_mapping(name)
        assert m.channels and any(c.required for c in m.channels)
    with pytest.raises(LogImportError, match="neither a file nor a packaged mapping"):
        load_mapping("no_such_mapping")
