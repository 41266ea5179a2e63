"""Fuzzed contract of the log importers: corrupt lines in CSV / candump / ASC logs are left out and reported with
their line numbers (``--strict`` refuses them); a time unit that cannot be right is refused with a hint."""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from roadload import Trip
from roadload.io.export import export_trip
from roadload.io.importer import import_log
from roadload.io.report import LogImportError

FUZZ = settings(max_examples=15, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
MAPPING = {
    "name": "fuzz_csv",
    "format": "csv",
    "csv": {"sep": ";", "time": "Time [s]", "time_unit": "s"},
    "channels": [
        {"source": "Velocity [km/h]", "channel": "vehicle_speed", "unit": "km/h", "required": True},
        {"source": "Elevation [m]", "channel": "elevation", "unit": "m"},
    ],
}


def _csv_lines(n=600, dt=0.1, scale=1.0):
    lines = ["Time [s];Velocity [km/h];Elevation [m]"]
    lines += [f"{i * dt * scale:.6g};{50 + 10 * np.sin(i / 50):.3f};{500 + 0.01 * i:.2f}" for i in range(n)]
    return lines


def _write(tmp_path, lines, mapping=None, name="log.csv"):
    (tmp_path / "m.json").write_text(json.dumps(mapping or MAPPING))
    p = tmp_path / name
    p.write_text("\n".join(lines) + "\n")
    return p, tmp_path / "m.json"


def _dropped_lines(trip):
    return [
        d
        for d in trip.meta["import_report"]["dropped"]
        if d["what"].endswith(" lines") or d["reason"] == "non-numeric cell"
    ]


CORRUPTIONS = {
    "extra_field": "1;2;3;4;5",
    "missing_fields_ok": None,
    "text_time": "abc;50;500",
    "empty_time": ";50;500",
    "nan_value": None,
}


@pytest.mark.parametrize("bad", ["1;2;3;4;5", "x;y;z;w", ";;;;", "1.0;2.0;3.0;4.0"])
def test_csv_wrong_field_count_reported(tmp_path, bad, ledger):
    lines = _csv_lines()
    lines.insert(100, bad)  # file line 101
    src, mp = _write(tmp_path, lines)
    trip = import_log(src, "csv", mp)
    (row,) = _dropped_lines(trip)
    assert row["detail"] == "line 101" and row["count"] == 1
    ledger.record("import_csv", "repair")


@pytest.mark.parametrize("bad", ["abc;50;500", "NaN;50;500", ";50;500", "--;50;500"])
def test_csv_bad_time_reported(tmp_path, bad, ledger):
    lines = _csv_lines()
    lines.insert(200, bad)  # file line 201
    src, mp = _write(tmp_path, lines)
    trip = import_log(src, "csv", mp)
    (row,) = _dropped_lines(trip)
    assert "time column 'Time [s]'" in row["reason"] and row["detail"] == "line 201"
    ledger.record("import_csv", "repair")


def test_csv_bad_value_reported_with_line(tmp_path, ledger):
    lines = _csv_lines()
    lines[50] = lines[50].split(";")[0] + ";fast;500"  # file line 51
    src, mp = _write(tmp_path, lines)
    trip = import_log(src, "csv", mp)
    rows = _dropped_lines(trip)
    assert any(r["detail"] == "line 51" for r in rows)
    ledger.record("import_csv", "repair")


@FUZZ
@given(positions=st.lists(st.integers(min_value=2, max_value=590), min_size=1, max_size=6, unique=True))
def test_csv_corrupt_lines_fuzz(tmp_path_factory, positions, ledger):
    tmp_path = tmp_path_factory.mktemp("csv")
    lines = _csv_lines()
    for pos in sorted(positions):
        lines.insert(pos, "junk;1;2;3;4")
    src, mp = _write(tmp_path, lines)
    trip = import_log(src, "csv", mp)
    (row,) = _dropped_lines(trip)
    want = sorted(p + 1 for p in positions)
    assert row["count"] == len(positions)
    assert row["detail"].split(" ", 1)[1].split(" ...")[0] == ", ".join(map(str, want[:10]))
    with pytest.raises(LogImportError, match="strict import refused"):
        import_log(src, "csv", mp, strict=True)
    ledger.record("import_csv", "repair")
    ledger.record("import_csv", "error")


TIME_BASE_CASES = [
    (0.1, 1000.0, "s", "looks like ms"),  # ms declared as s: 60 s -> 60,000 s
    (0.01, 1000.0, "s", "looks like ms"),
    (0.02, 1.0, "ms", "looks like s"),  # s declared as ms: 20 us steps
    (0.01, 1.0, "ms", "looks like s"),
    (10.0, 1.0, "s", "interval"),
    (200.0, 1.0, "s", "1 day"),
]


@pytest.mark.parametrize("dt,scale,unit,needle", TIME_BASE_CASES)
def test_csv_time_unit_implausible(tmp_path, dt, scale, unit, needle, ledger):
    mapping = json.loads(json.dumps(MAPPING))
    mapping["csv"]["time_unit"] = unit
    src, mp = _write(tmp_path, _csv_lines(n=600, dt=dt, scale=scale), mapping)
    with pytest.raises(LogImportError) as err:
        import_log(src, "csv", mp)
    assert needle in str(err.value) and "Time [s]" in str(err.value), str(err.value)
    ledger.record("import_csv", "error")


@pytest.mark.parametrize(
    "lines,needle",
    [
        ([], "unreadable CSV"),
        (["Time [s];Velocity [km/h];Elevation [m]"], "no numbers"),
        (["t;v"] + ["1;2"] * 3, "time column 'Time [s]' missing"),
        (["Time [s];Velocity [km/h];Elevation [m]", "a;b;c", "d;e;f"], "no numbers"),
    ],
)
def test_csv_unusable(tmp_path, lines, needle, ledger):
    src, mp = _write(tmp_path, lines)
    with pytest.raises(LogImportError) as err:
        import_log(src, "csv", mp)
    assert needle in str(err.value), str(err.value)
    ledger.record("import_csv", "error")


# ----------------------------------------------------------------------------------------------- CAN logs
UNITS = {"t": "s", "vehicle_speed": "m/s", "drive_torque": "N*m"}


@pytest.fixture(scope="module")
def can_logs(tmp_path_factory):
    folder = tmp_path_factory.mktemp("can")
    t = np.arange(0, 10, 0.01)
    trip = Trip(
        pd.DataFrame(
            {
                "t": t,
                "vehicle_speed": np.round((10 + np.sin(t)) / 0.01) * 0.01,
                "drive_torque": np.round(50 * np.cos(t) / 0.5) * 0.5,
            }
        ),
        dict(UNITS),
        {"name": "sim", "t0_unix": 1.7e9},
    )
    out = {}
    for fmt in ("candump", "asc"):
        out[fmt] = export_trip(trip, folder / f"sim_{fmt}", fmt)
    return out


GARBAGE = {
    "candump": [
        "garbage line",
        "(1700000000.5) can0 12G#0102",
        "(1700000000.5) can0 123#01020",
        "(abc) can0 123#0102",
        "can0 123#0102",
        "(1700000000.5) can0 123#0102 extra words",
    ],
    "asc": [
        " 0.015000 1  1Z3             Rx   d 8 00 01 02 03 04 05 06 07",
        " 0.015000 1  123             Rx   d 8 00 01 0",
        " 0.0x5 1  123             Rx   d 8 00 01 02 03 04 05 06 07",
        " 0.015000 1  123             Rx   d 8 00 01 02 03 04 05 06 ZZ",
        "garbage $$ line",
        "Rx d 8 00 01",
    ],
}


def _inject(paths, tmp_path, fmt, positions, garbage):
    text = paths["log"].read_text().splitlines()
    positions = sorted({min(p, len(text) - 1) for p in positions})
    for pos, g in zip(positions, garbage):
        text.insert(pos, g)
    bad = tmp_path / paths["log"].name
    bad.write_text("\n".join(text) + "\n")
    return bad, sorted(p + 1 for p in positions)


@pytest.mark.parametrize("fmt,garbage", [(f, g) for f, gs in GARBAGE.items() for g in gs])
def test_can_log_corrupt_line_reported(can_logs, tmp_path, fmt, garbage, ledger):
    paths = can_logs[fmt]
    bad, want = _inject(paths, tmp_path, fmt, [20], [garbage])
    trip = import_log(bad, fmt, paths["mapping"])
    (row,) = [d for d in trip.meta["import_report"]["dropped"] if d["what"].endswith(" lines")]
    assert row["count"] == 1 and row["detail"] == f"line {want[0]}"
    assert len(trip) > 900
    with pytest.raises(LogImportError, match=f"strict import refused.*line {want[0]}"):
        import_log(bad, fmt, paths["mapping"], strict=True)
    ledger.record(f"import_{fmt}", "repair")
    ledger.record(f"import_{fmt}", "error")


@FUZZ
@given(
    positions=st.lists(st.integers(min_value=10, max_value=1500), min_size=1, max_size=4, unique=True),
    junk=st.lists(st.text(alphabet="abcxyz#()0123456789 .", min_size=1, max_size=30), min_size=4, max_size=4),
)
def test_candump_random_garbage_fuzz(can_logs, tmp_path_factory, positions, junk, ledger):
    junk = [j for j in junk if j.strip()] or ["x"]
    junk = (junk * 4)[: len(positions)]
    from roadload.io.frames import _CANDUMP_LINE  # the grammar: a random line that parses is not garbage

    if any(_CANDUMP_LINE.match(j) for j in junk):
        return
    paths = can_logs["candump"]
    bad, want = _inject(paths, tmp_path_factory.mktemp("cd"), "candump", positions, junk)
    trip = import_log(bad, "candump", paths["mapping"])
    (row,) = [d for d in trip.meta["import_report"]["dropped"] if d["what"].endswith(" lines")]
    assert row["count"] == len(want) and row["detail"].endswith(", ".join(map(str, want)))
    ledger.record("import_candump", "repair")


TABLE_INPUTS = 4 + 4 + 1 + len(TIME_BASE_CASES) + 4 + 2 * sum(len(g) for g in GARBAGE.values())
