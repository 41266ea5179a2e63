"""The mutation-score tool's own parts (``experiments/mutation.py``): the binomial interval of a sampled score, the
seeded sample, the tests tree and selection of an earlier commit (a before score), a resumed staging that keeps
mutmut's verdicts, and the count of a run in which only some mutants were tested."""

from __future__ import annotations

import json
import subprocess
from pathlib import Path

import numpy as np
import pytest

from roadload.experiments.mutation import (
    REPO,
    ModuleScore,
    _line,
    _staged_path,
    _tests_tree_of,
    collect,
    modules_at,
    sample_names,
    stage,
    wilson_interval,
)


def test_wilson_interval_analytic_cases():
    # 0 of n: the upper end is z^2 / (n + z^2); n of n: the lower end is n / (n + z^2)
    z2 = 1.959964 ** 2
    low, high = wilson_interval(0, 10)
    assert low == pytest.approx(0.0, abs=1e-12) and high == pytest.approx(z2 / (10 + z2), rel=1e-9)
    low, high = wilson_interval(10, 10)
    assert low == pytest.approx(10 / (10 + z2), rel=1e-9) and high == pytest.approx(1.0, abs=1e-12)
    # the textbook 8 of 10: 0.490 - 0.943
    low, high = wilson_interval(8, 10)
    assert (round(low, 3), round(high, 3)) == (0.490, 0.943)
    # it narrows as 1/sqrt(n) around the same share
    w100 = float(np.subtract(*wilson_interval(90, 100)[::-1]))
    w400 = float(np.subtract(*wilson_interval(360, 400)[::-1]))
    assert w100 / w400 == pytest.approx(2.0, rel=0.05)
    assert all(np.isnan(wilson_interval(0, 0)))


def test_sample_is_seeded_a_subset_and_capped():
    names = [f"m.x_f__mutmut_{i}" for i in range(1, 301)]
    a = sample_names(names, 150, seed=3)
    assert a == sample_names(list(reversed(names)), 150, seed=3)  # the input order does not matter
    assert len(a) == len(set(a)) == 150 and set(a) <= set(names)
    assert a != sample_names(names, 150, seed=4)
    assert sorted(sample_names(names, 1000, seed=0)) == sorted(names)


def _git(repo: Path, *args: str) -> None:
    subprocess.run(["git", "-C", str(repo), "-c", "user.name=t", "-c", "user.email=t@t", *args], check=True,
                   capture_output=True)


def test_tests_tree_and_selection_of_an_earlier_commit(tmp_path):
    repo = tmp_path / "repo"
    (repo / "tests").mkdir(parents=True)
    (repo / "experiments").mkdir()
    _git(repo, "init", "-q")
    (repo / "tests" / "test_a.py").write_text("OLD = 1\n")
    (repo / "experiments" / "mutation.py").write_text(
        'MODULES: dict[str, tuple[str, ...]] = {\n    "core/a.py": ("tests/test_a.py",),\n}\n')
    _git(repo, "add", ".")
    _git(repo, "commit", "-q", "-m", "one")
    (repo / "tests" / "test_a.py").write_text("NEW = 2\n")
    (repo / "tests" / "test_b.py").write_text("B = 3\n")
    (repo / "experiments" / "mutation.py").write_text('MODULES = {"core/a.py": ("tests/test_b.py",)}\n')
    _git(repo, "commit", "-q", "-am", "two")

    out = tmp_path / "staged" / "tests"
    out.parent.mkdir()
    _tests_tree_of("HEAD~1", out, repo)
    assert (out / "test_a.py").read_text() == "OLD = 1\n"
    assert not (out / "test_b.py").exists()  # only what the commit held
    assert modules_at("HEAD~1", repo) == {"core/a.py": ("tests/test_a.py",)}
    assert modules_at("HEAD", repo) == {"core/a.py": ("tests/test_b.py",)}
    with pytest.raises(SystemExit, match="no-such-rev"):
        modules_at("no-such-rev", repo)
    with pytest.raises(SystemExit, match="git archive failed"):
        _tests_tree_of("no-such-rev", tmp_path / "other" / "tests", repo)


def test_resumed_staging_keeps_mutmut_state_and_refreshes_the_sources(tmp_path):
    module = "core/trip_schema.py"
    folder = stage(module, ("tests/core/test_trip_schema.py",), tmp_path / "m")
    meta = folder / "mutants" / f"{_staged_path(module)}.meta"
    meta.parent.mkdir(parents=True, exist_ok=True)
    meta.write_text(json.dumps({"exit_code_by_key": {"roadload.trip_schema.x_f__mutmut_1": 1}}))
    staged_test = folder / "tests" / "core" / "test_trip_schema.py"
    staged_test.write_text("stale")
    stage(module, ("tests/core/test_trip_schema.py",), folder, keep=True)
    assert json.loads(meta.read_text())["exit_code_by_key"] == {"roadload.trip_schema.x_f__mutmut_1": 1}
    assert staged_test.read_text() == (REPO / "tests" / "core" / "test_trip_schema.py").read_text()
    assert "[tool.mutmut]" in (folder / "pyproject.toml").read_text()
    stage(module, ("tests/core/test_trip_schema.py",), folder)  # a fresh run starts from nothing
    assert not meta.exists()


def test_collect_counts_only_tested_mutants_and_prints_the_interval(tmp_path):
    module = "core/trip_schema.py"
    folder = tmp_path / "m"
    meta = folder / "mutants" / f"{_staged_path(module)}.meta"
    meta.parent.mkdir(parents=True)
    verdicts = {f"roadload.trip_schema.x_f__mutmut_{i}": 1 for i in range(1, 9)}
    verdicts.update({"roadload.trip_schema.x_f__mutmut_9": -24, "roadload.trip_schema.x_f__mutmut_10": None,
                     "roadload.trip_schema.x_f__mutmut_11": None})
    meta.write_text(json.dumps({"exit_code_by_key": verdicts}))
    score = collect(module, folder, 1.0)
    assert (score.total, score.killed, score.timeout, score.untested) == (9, 8, 1, 2)
    assert score.score == 1.0
    assert score.interval == wilson_interval(9, 9)
    line = _line(score)
    assert "sample of 9 of 11 mutants" in line and f"{100 * wilson_interval(9, 9)[0]:.1f}-100.0 %" in line
    assert "sample" not in _line(ModuleScore(module, total=3, killed=3))

