"""`roadload benchmark optimum`: the seed list and the breakdown's variants are checked before anything runs."""

from typer.testing import CliRunner

from roadload.experiments.cli import _load, app

_load()
runner = CliRunner()


def _run(tmp_path, *args):
    return runner.invoke(app, ["benchmark", "optimum", "--vehicles", "truck_40t", "--truck-roads", "long_grades",
                               "--out", str(tmp_path / "out"), *args])


def test_a_bad_seed_list_or_breakdown_option_fails_with_its_reason_and_writes_nothing(tmp_path):
    res = _run(tmp_path, "--seed-list", "8,x")
    assert res.exit_code != 0 and "--seed-list: comma-separated integers" in res.output
    res = _run(tmp_path, "--seed-list", "8,8")
    assert res.exit_code != 0 and "distinct seeds >= 0" in res.output
    res = _run(tmp_path, "--variants", "no comfort term")
    assert res.exit_code != 0 and "only with --breakdown" in res.output
    res = _run(tmp_path, "--breakdown", "--controllers", "mpc:oracle:plant_map,cruise")
    assert res.exit_code != 0 and "names one oracle MPC" in res.output
    res = _run(tmp_path, "--breakdown", "--controllers", "mpc:oracle:plant_map", "--variants", "horizon 9 km",
               "--seed-list", "8")
    assert res.exit_code != 0 and "unknown ['|horizon 9 km']" in res.output
    assert not (tmp_path / "out").exists()
