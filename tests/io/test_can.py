"""CAN log import: vectorised DBC decoding vs cantools, log readers/writers, MF4 + DBC + mapping end to end."""

from __future__ import annotations

import json

import cantools
import numpy as np
import pytest

from roadload.io.dbc import DbcSource, decode_frames, load_dbc
from roadload.io.frames import CanFrames, read_can_log, read_mf4, write_can_log
from roadload.io.importer import import_log
from roadload.io.report import ImportReport, LogImportError

TEST_DBC = """VERSION ""

NS_ :
\tSG_MUL_VAL_

BS_:

BU_: ECU

BO_ 256 MOTION: 8 ECU
 SG_ speed : 0|16@1+ (0.01,0) [0|655.35] "km/h" ECU
 SG_ accel : 16|12@1- (0.01,0) [-20.48|20.47] "m/s^2" ECU
 SG_ speed_valid : 28|1@1+ (1,0) [0|1] "" ECU
 SG_ torque : 39|16@0- (0.1,-100) [-3376.8|3176.7] "Nm" ECU
 SG_ gear : 55|4@0+ (1,0) [0|15] "" ECU

BO_ 512 TIME: 6 ECU
 SG_ epoch : 0|40@1+ (0.001,1500000000) [1500000000|2599511627] "sec" ECU
 SG_ epoch_valid : 40|1@1+ (1,0) [0|1] "" ECU

BO_ 2566844416 EXT: 8 ECU
 SG_ temperature : 7|8@0+ (1,-40) [-40|215] "degC" ECU
 SG_ mode M : 15|8@0+ (1,0) [0|255] "" ECU
 SG_ sub m1M : 23|8@0+ (1,0) [0|255] "" ECU
 SG_ voltage m2 : 31|16@0+ (0.001,0) [0|65] "V" ECU
 SG_ current m3 : 24|16@1- (0.1,0) [-3000|3000] "A" ECU

SG_MUL_VAL_ 2566844416 sub mode 1-1;
SG_MUL_VAL_ 2566844416 voltage sub 2-2;
SG_MUL_VAL_ 2566844416 current sub 3-3;
"""


@pytest.fixture
def dbc_file(tmp_path):
    p = tmp_path / "test.dbc"
    p.write_text(TEST_DBC)
    return p


def _random_frames(db, rng, n_per=300):
    """Random valid frames of every message, encoded by cantools; returns frames and the cantools-decoded truth."""
    rows, truth = [], []
    t = 0.0
    for k in range(n_per):
        for msg in db.messages:
            data = {}
            for s in msg.signals:
                lo = s.minimum if s.minimum is not None else 0
                hi = s.maximum if s.maximum is not None else 1
                data[s.name] = s.scale * round((rng.uniform(lo, hi) - s.offset) / s.scale) + s.offset
            if msg.name == "EXT":
                data["mode"] = 1
                data["sub"] = int(rng.choice([2, 3]))
                data.pop("voltage" if data["sub"] == 3 else "current")
            payload = msg.encode(data, strict=False)
            t += 0.001
            rows.append((t, msg.frame_id, msg.is_extended_frame, payload))
            truth.append((msg, payload))
    n = len(rows)
    arr = np.zeros((n, 8), dtype=np.uint8)
    for i, r in enumerate(rows):
        arr[i, : len(r[3])] = np.frombuffer(r[3], dtype=np.uint8)
    frames = CanFrames([r[0] for r in rows], np.ones(n), [r[1] for r in rows], [r[2] for r in rows],
                       [len(r[3]) for r in rows], arr, 1.6e9)
    return frames, truth


def test_vectorised_decoding_equals_cantools(dbc_file):
    """Intel/Motorola, signed/unsigned, 40-bit, extended id and two-level multiplexing decode bit-exactly."""
    db_ct = cantools.database.load_file(str(dbc_file))
    frames, truth = _random_frames(db_ct, np.random.default_rng(1))
    report = ImportReport()
    sigs = decode_frames(frames, load_dbc([DbcSource(dbc_file)]), report)
    expect: dict[str, list[float]] = {}
    for msg, payload in truth:
        for name, value in msg.decode(payload, decode_choices=False).items():
            expect.setdefault(f"{msg.name}.{name}", []).append(float(value))
    assert set(expect) == set(sigs)
    for key, values in expect.items():
        np.testing.assert_allclose(sigs[key].values, values, rtol=0, atol=1e-6, err_msg=key)
    # the multiplexed signals appear only in their frames: voltage + current = all EXT frames
    assert len(sigs["EXT.voltage"]) + len(sigs["EXT.current"]) == len(sigs["EXT.temperature"])
    assert report.count() == 0


def test_unknown_ids_and_short_frames_are_counted(dbc_file):
    db = load_dbc([DbcSource(dbc_file)])
    data = np.zeros((4, 8), dtype=np.uint8)
    frames = CanFrames([0, 1, 2, 3], [1, 1, 1, 1], [256, 256, 0x7FF, 256], [False] * 4, [8, 3, 8, 8], data)
    report = ImportReport()
    sigs = decode_frames(frames, db, report)
    assert len(sigs["MOTION.speed"]) == 2
    dropped = {d["what"]: d["count"] for d in report.dropped}
    assert dropped == {"MOTION": 1, "CAN frames": 1}


def test_dbc_bound_to_bus_ignores_other_buses(dbc_file):
    db = load_dbc([DbcSource(dbc_file, bus=2)])
    frames = CanFrames([0, 1], [1, 2], [256, 256], [False, False], [8, 8], np.zeros((2, 8), dtype=np.uint8))
    sigs = decode_frames(frames, db, ImportReport())
    np.testing.assert_array_equal(sigs["MOTION.speed"].t, [1.0])


@pytest.mark.parametrize("fmt,suffix", [("candump", ".log"), ("blf", ".blf"), ("asc", ".asc"), ("mf4", ".mf4")])
def test_log_writers_round_trip(tmp_path, fmt, suffix):
    rng = np.random.default_rng(3)
    n = 50
    lengths = rng.integers(1, 9, n)
    data = rng.integers(0, 256, (n, 8)).astype(np.uint8)
    data[np.arange(8)[None, :] >= lengths[:, None]] = 0
    frames = CanFrames(np.arange(n) * 0.01, rng.integers(1, 3, n), rng.integers(1, 0x7FF, n),
                       np.zeros(n, dtype=bool), lengths, data, 1.7e9)
    path = write_can_log(frames, tmp_path / f"x{suffix}", fmt)
    back = read_can_log(path)
    assert len(back) == n
    np.testing.assert_array_equal(back.arbitration_id, frames.arbitration_id)
    np.testing.assert_array_equal(back.bus, frames.bus)
    np.testing.assert_array_equal(back.length, frames.length)
    np.testing.assert_array_equal(back.data[:, :8], frames.data)
    if fmt != "asc":  # ASC stores times relative to its own start
        np.testing.assert_allclose(back.start_time + back.t, frames.start_time + frames.t, atol=1e-5)


def test_writer_rejects_wrong_suffix_and_leaves_nothing(tmp_path):
    frames = CanFrames([0.0], [1], [1], [False], [1], np.zeros((1, 8), dtype=np.uint8))
    with pytest.raises(LogImportError, match="must end in .blf"):
        write_can_log(frames, tmp_path / "x.log", "blf")
    assert list(tmp_path.iterdir()) == []


# --------------------------------------------------------------------------------------------- MF4 end to end
LAG = 5.0  # s: the logger clock runs this much ahead of the reference epoch


def _write_synthetic_mf4(db_ct, path, duration=20.0):
    """A 100 Hz MOTION message (speed = 10 + 0.5 t km/h, accel ramp), a 1 Hz TIME message whose epoch is the
    logger time minus LAG, and EXT frames every 0.5 s; the first 2 s of speed are flagged invalid."""
    import can

    start = 1.65e9
    motion, time_msg, ext = (db_ct.get_message_by_name(n) for n in ("MOTION", "TIME", "EXT"))
    writer = can.MF4Writer(str(path))
    n = int(duration * 100)
    for k in range(n):
        t = k * 0.01
        speed = 10 + 0.5 * t
        payload = motion.encode({"speed": speed, "accel": 0.5 / 3.6, "speed_valid": int(t >= 2.0),
                                 "torque": 50 + 10 * np.sin(t), "gear": 1 + int(t // 5)})
        writer.on_message_received(can.Message(timestamp=start + t, arbitration_id=256, data=payload, channel=1,
                                               is_extended_id=False))
        if k % 100 == 0:
            payload = time_msg.encode({"epoch": start + t - LAG, "epoch_valid": 1})
            writer.on_message_received(can.Message(timestamp=start + t + 0.002, arbitration_id=512, data=payload,
                                                   channel=1, is_extended_id=False))
        if k % 50 == 25:
            payload = ext.encode({"temperature": 20 + t, "mode": 1, "sub": 2, "voltage": 12.5}, strict=False)
            writer.on_message_received(can.Message(timestamp=start + t + 0.003, arbitration_id=ext.frame_id,
                                                   data=payload, channel=1, is_extended_id=True))
    writer.stop()
    return start


MAPPING = {
    "name": "synthetic", "format": "dbc-mf4", "sample_rate": 100,
    "dbc": [{"file": "test.dbc"}],
    "clock": {"source": "TIME.epoch", "valid": "TIME.epoch_valid", "unit": "s"},
    "channels": [
        {"source": "MOTION.speed", "channel": "vehicle_speed", "unit": "km/h", "resample": "linear",
         "valid": "MOTION.speed_valid", "required": True},
        {"source": "MOTION.accel", "channel": "accel_x", "unit": "m/s^2", "resample": "linear"},
        {"source": "MOTION.torque", "channel": "drive_torque", "unit": "N*m", "resample": "linear"},
        {"source": "MOTION.gear", "channel": "gear", "unit": "1", "resample": "hold"},
        {"source": "EXT.temperature", "channel": "ambient_temperature", "unit": "degC", "resample": "hold"},
        {"source": "EXT.voltage", "channel": "battery_voltage", "unit": "V", "resample": "nearest"},
    ],
}


@pytest.fixture
def synthetic_mf4(tmp_path, dbc_file):
    db_ct = cantools.database.load_file(str(dbc_file))
    path = tmp_path / "log.mf4"
    start = _write_synthetic_mf4(db_ct, path)
    mapping = tmp_path / "map.json"
    mapping.write_text(json.dumps(MAPPING))
    return path, mapping, start


def test_mf4_import_end_to_end(synthetic_mf4):
    path, mapping, start = synthetic_mf4
    trip = import_log(path, "dbc-mf4", mapping)
    rep = trip.meta["import_report"]
    # clock: reference = logger - LAG, recovered to well below a sample period
    assert trip.meta["clock"]["offset_s"] == pytest.approx(-LAG, abs=0.005)
    assert trip.meta["t0_unix"] == pytest.approx(start + 2.0 - LAG, abs=0.01)
    # the 200 invalid speed samples (t < 2 s) are dropped and counted, the time base starts after them
    assert {"what": "vehicle_speed", "reason": "validity flag MOTION.speed_valid = 0", "count": 200,
            "detail": ""} in rep["dropped"]
    t_logger = trip.t + 2.0
    np.testing.assert_allclose(trip.channel("vehicle_speed"), (10 + 0.5 * t_logger) / 3.6, atol=0.01 / 3.6 + 1e-9)
    assert trip.sample_rate == pytest.approx(100.0)
    # hold: gear steps exactly at multiples of 5 s of logger time
    gear = trip.channel("gear")
    np.testing.assert_array_equal(gear, 1 + np.floor(t_logger / 5 + 1e-9))
    # units converted: degC -> K, hold of a 2 Hz signal
    temp = trip.channel("ambient_temperature")
    assert np.nanmin(temp) > 273.15 + 20 and np.nanmax(temp) < 273.15 + 41
    assert np.nanmax(np.abs(trip.channel("battery_voltage") - 12.5)) < 1e-9
    assert trip.meta["channels"]["gear"]["resample"] == "hold"


def test_truncated_mf4_is_a_clear_error(synthetic_mf4, tmp_path):
    path, mapping, _ = synthetic_mf4
    raw = path.read_bytes()
    cut = tmp_path / "cut.mf4"
    cut.write_bytes(raw[: len(raw) // 2])
    with pytest.raises(LogImportError, match="cut.mf4: MDF4 file truncated"):
        read_mf4(cut)
    junk = tmp_path / "junk.mf4"
    junk.write_bytes(b"not an mdf file at all" * 10)
    with pytest.raises(LogImportError, match="not an MDF file"):
        read_mf4(junk)


def test_dbc_without_the_referenced_message(synthetic_mf4, tmp_path):
    path, _, _ = synthetic_mf4
    bad = dict(MAPPING)
    bad["channels"] = MAPPING["channels"] + [{"source": "BRAKES.pressure", "channel": "brake_pressure_front",
                                              "unit": "bar", "required": True}]
    (tmp_path / "bad.json").write_text(json.dumps(bad))
    with pytest.raises(LogImportError, match=r"brake_pressure_front: message\(s\) \['BRAKES'\] not defined"):
        import_log(path, "dbc-mf4", tmp_path / "bad.json")


def test_missing_dbc_file_is_named(synthetic_mf4, tmp_path):
    path, _, _ = synthetic_mf4
    bad = dict(MAPPING, dbc=[{"file": "nowhere.dbc"}])
    (tmp_path / "bad.json").write_text(json.dumps(bad))
    with pytest.raises(LogImportError, match="nowhere.dbc"):
        import_log(path, "dbc-mf4", tmp_path / "bad.json")


def test_declared_dbc_unit_must_match_mapping(synthetic_mf4, tmp_path):
    path, _, _ = synthetic_mf4
    bad = json.loads(json.dumps(MAPPING))
    bad["channels"][0]["unit"] = "m/s"  # the DBC says km/h
    (tmp_path / "bad.json").write_text(json.dumps(bad))
    with pytest.raises(LogImportError, match="unit mismatch for MOTION.speed"):
        import_log(path, "dbc-mf4", tmp_path / "bad.json")


def test_malformed_dbc_and_mapping_files(tmp_path, synthetic_mf4):
    path, _, _ = synthetic_mf4
    broken = tmp_path / "broken.dbc"
    broken.write_text('BO_ 256 MOTION: 8 ECU\n SG_ speed : 0|16@1+ (0.01,0 [0|655.35] "km/h" ECU\n')
    with pytest.raises(LogImportError, match="broken.dbc: not a valid DBC file"):
        load_dbc([DbcSource(broken)])
    (tmp_path / "m.json").write_text('{"name": "x", "format": "dbc-mf4", "channels": [}')
    with pytest.raises(LogImportError, match="m.json: not valid JSON"):
        import_log(path, "dbc-mf4", tmp_path / "m.json")
    (tmp_path / "m2.json").write_text(json.dumps(dict(MAPPING, format="pcap")))
    with pytest.raises(LogImportError, match="unknown format 'pcap'"):
        import_log(path, "dbc-mf4", tmp_path / "m2.json")
