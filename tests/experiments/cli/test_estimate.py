"""``roadload estimate``: output file, printed parameters and clear errors."""

import importlib.util
from pathlib import Path

import pandas as pd
import pytest
from typer.testing import CliRunner

import roadload.presets  # noqa: F401  (a broken import must fail, not skip)

from roadload.experiments.cli import _load, app  # noqa: E402

_spec = importlib.util.spec_from_file_location("handmade",
                                               Path(__file__).parents[2] / "estimators" / "test_pipeline_stages.py")
hm = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(hm)

_load()
runner = CliRunner()


@pytest.fixture(scope="module")
def trip_file(tmp_path_factory):
    from roadload.estimators.knowledge import knowledge_for_preset

    # CAN channels made through the gt_rwd preset's estimating-side drive-train (3rd/4th gear)
    trip = hm.handmade_trip(duration=400.0, events=False, knowledge=knowledge_for_preset("gt_rwd"), gears=(3, 4))
    trip.meta["vehicle"] = "gt_rwd"
    return trip.save(tmp_path_factory.mktemp("cli") / "hand.parquet")


def test_estimate_writes_parameter_traces(trip_file, tmp_path):
    out = tmp_path / "params.parquet"
    r = runner.invoke(app, ["estimate", str(trip_file), "--model", "M4", "--estimator", "RRLM", "--out", str(out),
                            "--figures", str(tmp_path / "fig")])
    assert r.exit_code == 0, r.output
    df = pd.read_parquet(out)
    assert {"t", "tractive_force", "prediction", "output_correction", "m_V", "m_V^2/c_yW"} <= set(df.columns)
    assert "m_V =" in r.output and (tmp_path / "fig" / "parameters.png").stat().st_size > 1000
    # the hand-made trip is exactly M4 with m_V = 1850 kg: RRLM gets there from the gt_rwd nominal 1900 kg
    assert df["m_V"].iloc[-1] == pytest.approx(hm.X_TRUE[1], rel=0.02)


@pytest.mark.parametrize("args, message", [
    (["--model", "M9"], "unknown model 'M9'"),
    (["--estimator", "XYZ"], "no chapter-5 settings for estimator 'XYZ'"),
    (["--out", "params.csv"], "must end in .parquet"),
])
def test_estimate_errors_are_clear(trip_file, tmp_path, args, message):
    base = {"--model": "M3", "--estimator": "RLS", "--out": str(tmp_path / "p.parquet")}
    for k, v in zip(args[::2], args[1::2]):
        base[k] = v
    r = runner.invoke(app, ["estimate", str(trip_file)] + [x for kv in base.items() for x in kv])
    assert r.exit_code == 2
    assert message in r.output
    assert not (tmp_path / "p.parquet").exists()


def test_estimate_missing_trip_file(tmp_path):
    r = runner.invoke(app, ["estimate", str(tmp_path / "nope.parquet"), "--out", str(tmp_path / "p.parquet")])
    assert r.exit_code == 2 and f"TRIP: no file {tmp_path / 'nope.parquet'}" in r.output
