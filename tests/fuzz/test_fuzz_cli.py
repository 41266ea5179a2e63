"""Fuzzed contract of the command line: bad input is one plain ``error:`` line naming the option/field (units in
brackets kept), exit code 2, no traceback, and a file already at the output path is byte-identical afterwards."""

from __future__ import annotations

import json
import os

import numpy as np
import pandas as pd
import pytest
from typer.testing import CliRunner

from roadload.experiments.cli import _load, app
from roadload.trip import Trip

_load()
RUNNER = CliRunner()
SENTINEL = b"precious bytes that must survive\x00\x01"
MAPPING = {
    "name": "fuzz_csv",
    "format": "csv",
    "csv": {"sep": ";", "time": "Time [s]", "time_unit": "s"},
    "channels": [{"source": "Velocity [km/h]", "channel": "vehicle_speed", "unit": "km/h", "required": True}],
}


@pytest.fixture(scope="module")
def world(tmp_path_factory):
    """Input files of every kind, good and bad, in one folder."""
    d = tmp_path_factory.mktemp("cli")
    (d / "adir").mkdir()
    for name in ("dir.parquet", "dir.png", "dir.json"):
        (d / name).mkdir()
    (d / "afile").write_bytes(b"I am a file")
    rows = ["Time [s];Velocity [km/h]"] + [f"{i * 10};{50 + i % 7}" for i in range(600)]  # ms data
    (d / "ms.csv").write_text("\n".join(rows) + "\n")
    rows = ["Time [s];Velocity [km/h]"] + [f"{i * 0.1:.1f};{50 + i % 7}" for i in range(600)]
    (d / "good.csv").write_text("\n".join(rows) + "\n")
    rows.insert(50, "1;2;3;4")
    (d / "badline.csv").write_text("\n".join(rows) + "\n")
    (d / "good.json").write_text(json.dumps(MAPPING))
    bad = json.loads(json.dumps(MAPPING))
    bad["channels"][0]["scale"] = "abc"
    (d / "scale_abc.json").write_text(json.dumps(bad))
    bad = json.loads(json.dumps(MAPPING))
    bad["channels"][0]["channel"] = "warp_factor"
    (d / "warp.json").write_text(json.dumps(bad))
    bad = json.loads(json.dumps(MAPPING))
    bad["channels"][0]["unit"] = "m/s"
    (d / "unit.json").write_text(json.dumps(bad))
    (d / "notjson.json").write_text("{oops")
    from roadload.presets import get_preset

    v = get_preset("gt_rwd").to_dict()
    v["body"]["mass"] = 0.001
    (d / "light.json").write_text(json.dumps(v))
    v = get_preset("gt_rwd").to_dict()
    v["drivetrain"]["gear_ratios"] = [1000, 800, 600, 400, 300, 200, 100]
    (d / "ratios.json").write_text(json.dumps(v))
    trip = Trip(
        pd.DataFrame({"t": np.arange(50) / 10.0, "vehicle_speed": np.ones(50)}),
        {"t": "s", "vehicle_speed": "m/s"},
        {"name": "x"},
    )
    trip.save(d / "trip.parquet")
    import pyarrow.parquet as pq

    table = pq.read_table(d / "trip.parquet")
    md = {k: v for k, v in pq.ParquetFile(d / "trip.parquet").metadata.metadata.items() if k != b"ARROW:schema"}
    payload = json.loads(md[b"roadload"])
    payload.pop("n_measured")
    md[b"roadload"] = json.dumps(payload).encode()
    pq.write_table(table.replace_schema_metadata(md), d / "no_n.parquet")
    md[b"roadload"] = b"not json at all"
    pq.write_table(table.replace_schema_metadata(md), d / "badmeta.parquet")
    pd.DataFrame({"a": [1, 2]}).to_parquet(d / "plain.parquet")
    (d / "garbage.parquet").write_bytes(b"PAR1 nope")
    return d


# argv (with {d} for the world folder, {out} for a fresh output path holding SENTINEL), text the error must contain
CASES = [
    ("simulate --vehicle gt_rwd --road hilly --out {d}/dir.parquet", "is a directory"),
    ("simulate --vehicle gt_rwd --road hilly --out {d}/afile/x.parquet", "is a file"),
    ("simulate --vehicle gt_rwd --road hilly --out {d}/afile/deep/x.parquet", "is a file"),
    ("simulate --vehicle gt_rwd --road hilly --out {out} --seed -1", "--seed"),
    ("simulate --vehicle gt_rwd --road hilly --out {out} --road-seed -5", "--road-seed"),
    ("simulate --vehicle gt_rwd --road hilly --out {out} --ambient-temperature -300", "[degC]"),
    ("simulate --vehicle gt_rwd --road hilly --out {out} --ambient-temperature 500", "--ambient-temperature"),
    ("simulate --vehicle gt_rwd --road hilly --out {out} --ambient-temperature nan", "--ambient-temperature"),
    ("simulate --vehicle gt_rwd --road hilly --out {out} --duration 0", "--duration: must be > 0 [s]"),
    ("simulate --vehicle gt_rwd --road hilly --out {out} --duration -5", "[s]"),
    ("simulate --vehicle gt_rwd --road hilly --out {out} --duration inf", "--duration"),
    ("simulate --vehicle gt_rwd --road hilly --out {out} --distance -1", "--distance: must be > 0 [km]"),
    ("simulate --vehicle gt_rwd --road hilly --out {out} --distance nan", "--distance"),
    ("simulate --vehicle atlantis --road hilly --out {out}", "atlantis"),
    ("simulate --vehicle {d}/light.json --road hilly --out {out}", "body.mass"),
    ("simulate --vehicle {d}/ratios.json --road hilly --out {out}", "gear_ratios"),
    ("simulate --vehicle {d}/notjson.json --road hilly --out {out}", "not valid JSON"),
    ("simulate --vehicle gt_rwd --road atlantis --out {out}", "atlantis"),
    ("simulate --vehicle gt_rwd --road hilly --out {out} --effects rain", "rain"),
    ("simulate --vehicle gt_rwd --road hilly --out {out} --effects wind:speed=3", "speed"),
    ("simulate --vehicle gt_rwd --road hilly --out {d}/x.csv", ".parquet"),
    ("simulate --vehicle gt_rwd --road hilly --out {out} --cycle hilly", "--cycle"),
    ("simulate --vehicle gt_rwd --road hilly --out {out} --sensors {d}/notjson.json", "--sensors"),
    ("profiles show atlantis", "atlantis"),
    ("profiles show hilly --seed -1", "--seed"),
    ("profiles export hilly {d}/h.txt", ".txt"),
    ("profiles export hilly {d}/dir.json", "is a directory"),
    ("profiles export atlantis {out_json}", "atlantis"),
    ("profiles export hilly {d}/afile/h.json", "is a file"),
    ("profiles list --kind boat", "boat"),
    ("import {d}/ms.csv -f csv -m {d}/good.json -o {out}", "looks like ms"),
    ("import {d}/badline.csv -f csv -m {d}/good.json -o {out} --strict", "line 51"),
    ("import {d}/ms.csv -f csv -m {d}/scale_abc.json -o {out}", "scale"),
    ("import {d}/ms.csv -f csv -m {d}/warp.json -o {out}", "warp_factor"),
    ("import {d}/good.csv -f csv -m {d}/unit.json -o {out}", "[km/h]"),
    ("import {d}/ms.csv -f csv -m {d}/notjson.json -o {out}", "not valid JSON"),
    ("import {d}/missing.csv -f csv -m {d}/good.json -o {out}", "missing.csv"),
    ("import {d}/ms.csv -f pcap -m {d}/good.json -o {out}", "pcap"),
    ("import {d}/ms.csv -f csv -m nowhere_mapping -o {out}", "nowhere_mapping"),
    ("import {d}/ms.csv -f csv -m {d}/good.json -o {d}/dir.parquet", "is a directory"),
    ("plot {d}/no_n.parquet --out {out_png}", "n_measured"),
    ("plot {d}/badmeta.parquet --out {out_png}", "badmeta.parquet"),
    ("plot {d}/plain.parquet --out {out_png}", "not a Trip"),
    ("plot {d}/garbage.parquet --out {out_png}", "garbage.parquet"),
    ("plot {d}/missing.parquet --out {out_png}", "missing.parquet"),
    ("plot {d}/trip.parquet --out {d}/dir.png", "is a directory"),
    ("estimate {d}/no_n.parquet --out {out}", "n_measured"),
    ("estimate {d}/badmeta.parquet --out {out}", "not valid JSON"),
    ("export-can {d}/no_n.parquet --out {d}/can.log", "n_measured"),
    ("export-can {d}/trip.parquet --format pcap --out {d}/can.pcap", "pcap"),
    ("drive --time-weight nan --out {out}", "--time-weight"),
    ("drive --time-weight inf --out {out}", "--time-weight"),
    ("drive --time-weight -1 --out {out}", "--time-weight"),
    ("drive --controller teleport --out {out}", "teleport"),
    ("drive --force-model crystal_ball --out {out}", "crystal_ball"),
    ("drive --cruise-fraction 1.5 --out {out}", "fraction"),
    ("drive --cruise-fraction nan --out {out}", "--cruise-fraction"),
    ("drive --solver cplex --out {out}", "cplex"),
    ("drive --seed -1 --out {out}", "--seed"),
    ("drive --out {d}/dir.parquet", "is a directory"),
    ("drive --out {d}/x.csv", ".parquet"),
    ("drive --road atlantis --out {out}", "atlantis"),
]


@pytest.mark.parametrize("argv,needle", CASES, ids=[c[0][:70] for c in CASES])
def test_cli_bad_input(world, tmp_path, argv, needle, ledger):
    outs = {"out": tmp_path / "out.parquet", "out_png": tmp_path / "out.png", "out_json": tmp_path / "out.json"}
    for p in outs.values():
        p.write_bytes(SENTINEL)
    before = {p: (p.stat().st_size, sorted(os.listdir(p.parent))) for p in [world / "afile"]}
    args = argv.format(d=world, **outs).split()
    res = RUNNER.invoke(app, args)
    text = res.output
    assert res.exit_code == 2, (res.exit_code, text, res.exception)
    assert "Traceback" not in text, text
    assert res.exception is None or isinstance(res.exception, SystemExit), (res.exception, text)
    assert needle in text, text
    error_lines = [ln for ln in text.splitlines() if ln.startswith("error:") or "Error" in ln]
    assert len(error_lines) == 1, text  # one plain line, no traceback, no markup
    for p in outs.values():
        assert p.read_bytes() == SENTINEL  # nothing already at the output path is lost or half-written
    assert not [f for f in os.listdir(tmp_path) if ".roadload-tmp-" in f]
    for p, (size, listing) in before.items():
        assert p.stat().st_size == size and sorted(os.listdir(p.parent)) == listing
    ledger.record("cli", "error")


def test_cli_debug_shows_the_traceback(world):
    res = RUNNER.invoke(app, ["--debug", "profiles", "show", "atlantis"])
    assert res.exit_code != 0 and res.exception is not None and "atlantis" in str(res.exception)


@pytest.mark.parametrize(
    "command,needles",
    [
        ("simulate", ["[km]", "[s]", "[degC]"]),
        ("drive", ["[J/s]"]),
        ("import", ["--strict"]),
    ],
)
def test_help_keeps_units_in_brackets(command, needles):
    res = RUNNER.invoke(app, [command, "--help"], terminal_width=200)
    assert res.exit_code == 0
    for n in needles:
        assert n in res.output, (n, res.output)


def test_import_report_keeps_brackets_and_lists_bad_lines(world, tmp_path, ledger):
    out = tmp_path / "t.parquet"
    res = RUNNER.invoke(
        app, ["import", str(world / "badline.csv"), "-f", "csv", "-m", str(world / "good.json"), "-o", str(out)]
    )
    assert res.exit_code == 0, res.output
    assert "malformed CSV line (wrong number of fields) (line 51)" in res.output
    assert Trip.load(out).meta["import_report"]["n_dropped"] == 1
    ledger.record("cli", "repair")


TABLE_INPUTS = len(CASES) + 1


def test_drive_metrics_are_rounded_with_units():
    from roadload.experiments.cli.controllers import metric_lines

    lines = metric_lines({"arrived": True, "energy_kWh": 1.23456789, "trip_time": 362.3999999998154,
                          "speed_violations": 0, "max_excess_kmh": 0.0, "rms_jerk": 0.41234,
                          "solve_time_median": 0.0123456, "solve_time_p99": float("nan"), "fallbacks": 3,
                          "ctl_relaxed_plans": 2, "ctl_solves": 180, "ctl_fallback_brake": 3,
                          "ctl_comfort_brake_steps": 1, "ctl_emergency_brake_steps": 5,
                          "ctl_worst_violation": "stop at 100 m: 15.6 m/s against a limit of 1 m/s"})
    text = "\n".join(lines)
    assert "trip time: 362.4 [s]" in text and "energy: 1.235 [kWh]" in text
    assert "solve time median: 12.3 [ms]" in text and "solve time p99: -" in text
    assert "362.39999" not in text
    # a relaxed-plan count comes with what it means, the fallback it caused and the worst violation
    assert "relaxed plans: 2 of 180 solves (plans that could not meet a stop, a speed cap" in text, text
    assert "fallback brake: 3 solves (1 control steps at the maximum comfort deceleration, 5 emergency" in text
    assert "worst violation: stop at 100 m" in text
    clean = "\n".join(metric_lines({"ctl_relaxed_plans": 0, "ctl_solves": 50}))
    assert "relaxed plans: 0 of 50 solves (every plan met every stop" in clean and "fallback brake" not in clean
    assert metric_lines({"arrived": True, "fallbacks": 0}) == ["             arrived: True",
                                                               "           fallbacks: 0"]  # cruise: no MPC lines
