"""Profile files (JSON/CSV round trip, malformed files) and the name registry."""

import json

import numpy as np
import pytest

from roadload.road_profiles import (DriveCycle, ProfileFileError, RoadProfile, RoadProfileError,
                                    UnknownProfileError, city, known_profiles, load_profile, register_profile,
                                    register_profile_folder, save_profile)
from roadload.road_profiles import registry

FIELDS = ("distance", "grade", "curvature", "bank", "speed_limit", "stops")


@pytest.fixture
def clean_registry():
    saved = registry._REGISTRY.snapshot()
    yield
    registry._REGISTRY.restore(saved)


@pytest.mark.parametrize("suffix", [".json", ".csv"])
def test_road_profile_round_trip_is_exact(tmp_path, suffix):
    p = city(5, length=3000.0)
    path = save_profile(p, tmp_path / f"c{suffix}")
    q = load_profile(path)
    assert isinstance(q, RoadProfile) and q.name == p.name and q.meta == p.meta
    for f in FIELDS:
        np.testing.assert_array_equal(getattr(q, f), getattr(p, f))
    assert [x.name for x in tmp_path.iterdir()] == [path.name]  # no temporary file left behind


@pytest.mark.parametrize("suffix", [".json", ".csv"])
@pytest.mark.parametrize("grade", [None, [0.0, 0.01, -0.02]])
def test_drive_cycle_round_trip(tmp_path, suffix, grade):
    c = DriveCycle("mini", time=[0.0, 1.0, 2.0], speed=[0.0, 1.5, 0.25], grade=grade,
                   meta={"source": "test", "licence": "MIT"})
    d = load_profile(save_profile(c, tmp_path / f"m{suffix}"))
    assert isinstance(d, DriveCycle) and d.meta == c.meta
    np.testing.assert_array_equal(d.speed, c.speed)
    assert (d.grade is None) == (grade is None)


def test_save_rejects_unknown_suffix_without_writing(tmp_path):
    with pytest.raises(ProfileFileError, match="unsupported extension '.txt'"):
        save_profile(city(0, length=1000.0), tmp_path / "x.txt")
    assert list(tmp_path.iterdir()) == []


def test_nan_in_profile_file_names_field_and_index(tmp_path):
    p = city(1, length=1000.0)
    path = save_profile(p, tmp_path / "c.json")
    doc = json.loads(path.read_text())
    doc["grade"][17] = None
    path.write_text(json.dumps(doc))
    with pytest.raises(ProfileFileError, match="grade: 1 NaN/inf values, first at index 17"):
        load_profile(path)
    csv = save_profile(p, tmp_path / "c.csv")
    lines = csv.read_text().splitlines()
    cells = lines[2 + 9].split(",")
    cells[4] = ""  # speed_limit of row 9 missing
    lines[2 + 9] = ",".join(cells)
    csv.write_text("\n".join(lines) + "\n")
    with pytest.raises(ProfileFileError, match="speed_limit: 1 NaN/inf values, first at index 9"):
        load_profile(csv)


def test_malformed_profile_files(tmp_path):
    p = city(2, length=1000.0)
    broken = tmp_path / "broken.json"
    broken.write_text("{not json")
    with pytest.raises(ProfileFileError, match="broken.json: not valid JSON"):
        load_profile(broken)
    other = tmp_path / "other.json"
    other.write_text(json.dumps({"hello": 1}))
    with pytest.raises(ProfileFileError, match="not a roadload profile"):
        load_profile(other)
    doc = json.loads(save_profile(p, tmp_path / "v.json").read_text())
    missing = dict(doc)
    del missing["curvature"]
    (tmp_path / "missing.json").write_text(json.dumps(missing))
    with pytest.raises(ProfileFileError, match=r"without the fields \['curvature'\]"):
        load_profile(tmp_path / "missing.json")
    (tmp_path / "v2.json").write_text(json.dumps({**doc, "version": 2}))
    with pytest.raises(ProfileFileError, match="unsupported version 2"):
        load_profile(tmp_path / "v2.json")
    short = dict(doc, bank=doc["bank"][:-1])
    (tmp_path / "short.json").write_text(json.dumps(short))
    with pytest.raises(ProfileFileError, match="bank: length"):
        load_profile(tmp_path / "short.json")
    csv = save_profile(p, tmp_path / "t.csv")
    lines = csv.read_text().splitlines()
    lines[5] = lines[5].replace(lines[5].split(",")[1], "steep", 1)
    csv.write_text("\n".join(lines) + "\n")
    with pytest.raises(ProfileFileError, match="column 'grade' has a non-numeric value at row 3"):
        load_profile(csv)
    with pytest.raises(FileNotFoundError, match="does not exist"):
        load_profile(tmp_path / "absent.json")


def test_unknown_name_lists_known_names():
    with pytest.raises(UnknownProfileError, match="unknown road profile 'moon'.*hilly.*wltc3"):
        load_profile("moon")
    assert isinstance(UnknownProfileError("x"), ValueError)
    names = known_profiles()
    for n in ("hilly", "motorway", "city", "wltc3", "udds", "ftp75", "hwfet", "us06", "bus_route91"):
        assert n in names
    assert "wltc3" in known_profiles("cycle") and "hilly" not in known_profiles("cycle")


def test_register_named_profiles_and_folder(tmp_path, clean_registry):
    ramp = RoadProfile("ramp", distance=[0.0, 100.0], grade=[0.05, 0.05], curvature=[0.0, 0.0], bank=[0.0, 0.0],
                       speed_limit=[10.0, 10.0])
    register_profile("my_ramp", lambda: ramp, description="test ramp")
    assert load_profile("MY_RAMP", seed=4) is ramp
    with pytest.raises(ValueError, match="already registered"):
        register_profile("my_ramp", lambda: ramp)
    seen = []
    register_profile("seeded_thing", lambda seed, length=1.0: seen.append((seed, length)) or ramp)
    load_profile("seeded_thing", seed=9, length=2.0)
    assert seen == [(9, 2.0)]
    save_profile(ramp, tmp_path / "road_a.json")
    save_profile(DriveCycle("cyc", time=[0.0, 1.0], speed=[0.0, 1.0]), tmp_path / "cyc_b.csv")
    (tmp_path / "notes.txt").write_text("ignored")
    names = register_profile_folder(tmp_path, prefix="real_")
    assert names == ["real_cyc_b", "real_road_a"]
    assert isinstance(load_profile("real_cyc_b"), DriveCycle)
    assert "real_cyc_b" in known_profiles("cycle") and "real_road_a" in known_profiles("road")
    np.testing.assert_array_equal(load_profile("real_road_a").grade, ramp.grade)
    with pytest.raises(ValueError, match="file path"):
        register_profile("x.json", lambda: ramp)


def test_road_profile_rejects_bad_arrays():
    with pytest.raises(RoadProfileError, match="curvature: 1 NaN/inf values, first at index 1"):
        RoadProfile("x", distance=[0.0, 1.0, 2.0], grade=[0, 0, 0], curvature=[0, np.nan, 0], bank=[0, 0, 0],
                    speed_limit=[1, 1, 1])


def test_cli_export_and_show(tmp_path):
    import typer
    from typer.testing import CliRunner

    from roadload.experiments.cli.profiles import register

    app = typer.Typer()
    register(app, typer.Typer())
    runner = CliRunner()
    out = tmp_path / "m.csv"
    result = runner.invoke(app, ["profiles", "export", "motorway", str(out), "--seed", "4"])
    assert result.exit_code == 0, result.output
    np.testing.assert_array_equal(load_profile(out).grade, load_profile("motorway", seed=4).grade)
    shown = runner.invoke(app, ["profiles", "show", str(out)])
    assert shown.exit_code == 0 and "length_km" in shown.output and "50" in shown.output
    bad = runner.invoke(app, ["profiles", "show", "moon"])
    assert bad.exit_code != 0 and "unknown road profile 'moon'" in str(bad.exception)
