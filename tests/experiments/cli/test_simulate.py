"""`roadload simulate` / `roadload plot`: outputs, clear errors, no partial files."""

import json

import numpy as np
from typer.testing import CliRunner

from roadload import Trip
from roadload.experiments.cli import _load, app
from roadload.envs import get_preset
from roadload.road_profiles import RoadProfile, save_profile

if not any(c.name == "simulate" for c in app.registered_commands):
    _load()
runner = CliRunner()


def _road_file(tmp_path, grade_nan=False, name="road.json"):
    s = np.arange(0.0, 1201.0, 10.0)
    grade = 0.03 * np.sin(s / 150.0)
    road = RoadProfile("cli-road", s, grade, np.zeros_like(s), np.zeros_like(s), np.full_like(s, 20.0))
    path = save_profile(road, tmp_path / name)
    if grade_nan:
        data = json.loads(path.read_text())
        data["grade"][5] = float("nan")
        path.write_text(json.dumps(data))
    return path


def test_simulate_writes_trip_and_plot(tmp_path):
    out = tmp_path / "out" / "trip.parquet"
    res = runner.invoke(app, ["simulate", "--vehicle", "bmw_i3", "--road", str(_road_file(tmp_path)), "--seed", "3",
                              "--effects", "wind:mean_speed=4,tire_warmup", "--out", str(out), "--plot"])
    assert res.exit_code == 0, res.output
    trip = Trip.load(out)
    assert trip.meta["seed"] == 3 and trip.meta["vehicle"]["name"] == "bmw_i3"
    assert set(trip.meta["effects"]["effects"]) == {"wind", "tire_warmup"}
    assert trip.truth["position"].iloc[-1] >= 1200.0 - 1e-6
    assert (tmp_path / "out" / "trip.png").stat().st_size > 10_000
    png = tmp_path / "again.png"
    res = runner.invoke(app, ["plot", str(out), "--out", str(png)])
    assert res.exit_code == 0, res.output
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_simulate_duration_and_distance_limits(tmp_path):
    out = tmp_path / "d.parquet"
    res = runner.invoke(app, ["simulate", "--vehicle", "gt_rwd", "--road", str(_road_file(tmp_path)),
                              "--distance", "0.5", "--out", str(out)])
    assert res.exit_code == 0, res.output
    assert abs(Trip.load(out).truth["position"].iloc[-1] - 500.0) < 1.0
    res = runner.invoke(app, ["simulate", "--vehicle", "gt_rwd", "--road", str(_road_file(tmp_path)),
                              "--duration", "20", "--out", str(out)])
    assert res.exit_code == 0, res.output
    assert abs(Trip.load(out).duration - 20.0) < 0.02


def test_bad_inputs_give_clear_errors_and_no_output(tmp_path):
    out = tmp_path / "bad.parquet"
    road = str(_road_file(tmp_path))
    spec = get_preset("gt_rwd").to_dict()
    spec["body"]["mass"] = -100.0
    vfile = tmp_path / "veh.json"
    vfile.write_text(json.dumps(spec))
    cases = [
        (["--vehicle", str(vfile), "--road", road], "vehicle.body.mass: must be > 0"),
        (["--vehicle", "gt_rwd", "--road", str(_road_file(tmp_path, grade_nan=True, name="nan.json"))], "grade"),
        (["--vehicle", "gt_rwd", "--road", road, "--effects", "snowstorm"], "unknown effect 'snowstorm'"),
        (["--vehicle", "gt_rwd", "--road", road, "--effects", "wind:mean_speed=abc"], "mean_speed"),
        (["--vehicle", "lada", "--road", road], "unknown vehicle preset 'lada'"),
        (["--vehicle", "gt_rwd", "--road", road, "--distance", "50"], "distance"),
    ]
    broken = tmp_path / "broken.json"
    broken.write_text('{"name": "x", "body": ')
    cases.append((["--vehicle", str(broken), "--road", road], "not valid JSON"))
    for args, message in cases:
        res = runner.invoke(app, ["simulate", *args, "--out", str(out)])
        assert res.exit_code == 2, (args, res.output)
        assert message in res.output.replace("\n", " "), (args, res.output)
        assert not out.exists()
        assert not list(tmp_path.glob(".bad.parquet*"))  # no temporary leftovers
    res = runner.invoke(app, ["simulate", "--vehicle", "gt_rwd", "--road", road, "--out", str(tmp_path / "x.csv")])
    assert res.exit_code == 2 and ".parquet" in res.output
