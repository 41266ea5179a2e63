"""``roadload benchmark robustness`` end to end on the synthetic backend (few seeds, short records)."""

import os

import pandas as pd
from typer.testing import CliRunner

from roadload.experiments.cli import _load, app

_load()
runner = CliRunner()


def test_cli_writes_tables_curves_and_summary(tmp_path):
    out = tmp_path / "rob"
    res = runner.invoke(app, ["benchmark", "robustness", "--backend", "synthetic", "--sweep", "outliers",
                              "--seeds", "2", "--duration", "2000", "-e", "RLS,RLM", "--workers", "1",
                              "--out", str(out)])
    assert res.exit_code == 0, res.output
    assert "ranked by breakdown" in res.output and "fig. 3.17" in res.output
    for name in ("results.csv", "summary.md", "table_synthetic_outliers.csv", "table_synthetic_outliers.md",
                 "curves_synthetic_outliers.png", "ranking_synthetic_outliers.csv"):
        assert (out / name).stat().st_size > 0, name
    results = pd.read_csv(out / "results.csv")
    # 4 variants x 8 levels x 2 seeds x 2 estimators
    assert len(results) == 4 * 8 * 2 * 2
    assert set(results["estimator"]) == {"RLS", "RLM"}
    summary = (out / "summary.md").read_text()
    assert "Check against the decision tree" in summary and "output/isolated" in summary
    ranking = pd.read_csv(out / "ranking_synthetic_outliers.csv")
    first = ranking[(ranking["variant"] == "output/isolated") & (ranking["rank"] == 1)]["estimator"].item()
    assert first == "RLM"
    assert not list(out.glob(".*.tmp"))           # atomic writes leave no temporary files
    umask = os.umask(0)
    os.umask(umask)
    assert (out / "summary.md").stat().st_mode & 0o777 == 0o666 & ~umask   # not mkstemp's 0600
    # every finished scenario is stored: the same command again resumes all 64 and writes the same tables
    assert len(list((out / "units").glob("synthetic_outliers_*.json"))) == 64
    before = {name: (out / name).read_bytes() for name in ("results.csv", "table_synthetic_outliers.csv")}
    again = runner.invoke(app, ["benchmark", "robustness", "--backend", "synthetic", "--sweep", "outliers",
                                "--seeds", "2", "--duration", "2000", "-e", "RLS,RLM", "--workers", "1",
                                "--out", str(out)])
    assert again.exit_code == 0 and "resumed 64 of 64 finished tasks" in again.output, again.output
    assert {name: (out / name).read_bytes() for name in before} == before


def test_cli_rejects_bad_input(tmp_path):
    for args, message in [(["--sweep", "tyres"], "unknown sweep"), (["-e", "RLS,FOO"], "unknown estimators"),
                          (["--seeds", "0"], "--seeds"), (["--backend", "lab"], "unknown backend")]:
        res = runner.invoke(app, ["benchmark", "robustness", "--backend", "synthetic", "--duration", "2000",
                                  "--out", str(tmp_path / "x"), *args])
        assert res.exit_code == 2, (args, res.output)
        assert message in res.output, (args, res.output)
    assert not (tmp_path / "x").exists()
