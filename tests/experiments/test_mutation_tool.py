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
    STRATA,
    ModuleScore,
    _plan,
    _line,
    _live_of,
    _staged_path,
    _tests_tree_of,
    collect,
    modules_at,
    mutants_of,
    sample_names,
    stage,
    wilson_interval,
)

# the checkout these tests live in: CI installs roadload non-editable, so the module's own folder has no sources
REPO = Path(__file__).resolve().parents[2]


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
    folder = stage(module, ("tests/core/test_trip_schema.py",), tmp_path / "m", repo=REPO)
    meta = folder / "mutants" / f"{_staged_path(module, REPO)}.meta"
    meta.parent.mkdir(parents=True, exist_ok=True)
    meta.write_text(json.dumps({"exit_code_by_key": {"roadload.trip_schema.x_f__mutmut_1": 1}}))
    staged_test = folder / "tests" / "core" / "test_trip_schema.py"
    staged_test.write_text("stale")
    stage(module, ("tests/core/test_trip_schema.py",), folder, repo=REPO, keep=True)
    assert json.loads(meta.read_text())["exit_code_by_key"] == {"roadload.trip_schema.x_f__mutmut_1": 1}
    assert staged_test.read_text() == (REPO / "tests" / "core" / "test_trip_schema.py").read_text()
    assert "[tool.mutmut]" in (folder / "pyproject.toml").read_text()
    stage(module, ("tests/core/test_trip_schema.py",), folder, repo=REPO)  # a fresh run starts from nothing
    assert not meta.exists()


def _meta(folder: Path, module: str, verdicts: dict) -> Path:
    meta = folder / "mutants" / f"{_staged_path(module, REPO)}.meta"
    meta.parent.mkdir(parents=True, exist_ok=True)
    meta.write_text(json.dumps({"exit_code_by_key": verdicts}))
    return meta


def test_collect_counts_only_tested_mutants(tmp_path):
    module = "core/trip_schema.py"
    verdicts = {f"roadload.trip_schema.x_f__mutmut_{i}": 1 for i in range(1, 9)}
    verdicts.update({"roadload.trip_schema.x_f__mutmut_9": -24, "roadload.trip_schema.x_f__mutmut_10": None,
                     "roadload.trip_schema.x_f__mutmut_11": None})
    _meta(tmp_path, module, verdicts)
    score = collect(module, tmp_path, 1.0, repo=REPO)
    assert (score.total, score.killed, score.timeout, score.untested, score.pool) == (9, 8, 1, 2, 0)
    assert score.score == 1.0 and score.interval == wilson_interval(9, 9)
    assert "(2 of 11 mutants not tested)" in _line(score)
    assert "tested" not in _line(ModuleScore(module, total=3, killed=3))


def test_a_sampled_score_is_the_stratified_estimate_with_wilsons_interval(tmp_path, monkeypatch):
    """A census of 18 killed mutants and a sample of 10 of a pool of 100 (5 killed, 1 timed out, 1 equivalent,
    3 live): the pool holds an estimated 90 live mutants of which 6 / 9 are killed."""
    module = "core/trip_schema.py"
    name = "roadload.trip_schema.x_f__mutmut_{}".format
    verdicts = {name(i): 1 for i in range(1, 19)}
    sample = [name(i) for i in range(100, 110)]
    verdicts.update({s: code for s, code in zip(sample, [1, 1, 1, 1, 1, -24, 0, 0, 0, 0])})
    verdicts.update({name(i): None for i in range(200, 290)})
    _meta(tmp_path, module, verdicts)
    (tmp_path / STRATA).write_text(json.dumps({"pool": 100, "sample": sample}))
    import mutmut.mutation.diff_apply as diff_apply  # the survivors' diffs: no mutated file is staged here

    def diff(mutant, path):  # the last one is an equivalent mutant listed for every module
        return ('-    a = float("nan")\n+    a = float("NAN")\n' if mutant == sample[-1]
                else "-    a = 1\n+    a = 2\n")

    monkeypatch.setattr(diff_apply, "get_diff_for_mutant", diff)
    score = collect(module, tmp_path, 1.0, repo=REPO)
    assert (score.sampled, score.sampled_killed, score.sampled_equivalent, score.untested) == (10, 6, 1, 90)
    assert (score.survived, score.equivalent) == (3, 1)
    assert score.score == pytest.approx((18 + 90 * 6 / 9) / (18 + 90))
    low, high = wilson_interval(6, 9)
    assert score.interval == (pytest.approx((18 + 90 * low) / 108), pytest.approx((18 + 90 * high) / 108))
    assert "all 18 others and a sample of 10 of 100 tested" in _line(score)
    plain = ModuleScore(module, total=10, killed=6, sampled=10, sampled_killed=6, pool=50)
    assert plain.score == pytest.approx(0.6) and plain.interval == pytest.approx(wilson_interval(6, 10))


def test_a_resumed_plan_keeps_killed_verdicts_of_unchanged_functions_only(tmp_path):
    module = "core/tables.py"  # small, with three functions
    folder = stage(module, (), tmp_path / "m", repo=REPO)
    names, hashes = mutants_of(module, folder, repo=REPO)
    assert len(names) == len(set(names)) > 10 and all(n.startswith("roadload.tables.") for n in names)
    assert {n.rpartition(".")[2].partition("__mutmut_")[0] for n in names} <= set(hashes)
    a, b, c = names[0], names[-1], names[1]
    fa, fb = (n.rpartition(".")[2].partition("__mutmut_")[0] for n in (a, b))
    assert fa != fb
    previous = {"exit_code_by_key": {a: 1, b: 1, c: 0},
                "hash_by_function_name": {**hashes, fb: "changed"}}
    kept, todo = _plan(module, folder, previous, None, 0, repo=REPO)
    assert kept == {a: 1}  # b: its function changed; c: survived, so tested again
    assert a not in todo and b in todo and c in todo and len(todo) == len(names) - 1
    assert not (folder / STRATA).exists()
    kept, chosen = _plan(module, folder, previous, 5, 7, repo=REPO)
    assert set(kept) == {a} and len(chosen) == 5 and a not in chosen
    strata = json.loads((folder / STRATA).read_text())
    assert strata["pool"] == len(names) - 1 and strata["sample"] == chosen


def test_a_rerun_tests_again_only_the_tested_mutants_not_killed():
    kept, again = _live_of({"exit_code_by_key": {"a": 1, "b": 0, "c": None, "d": 33, "e": -24, "f": 3}})
    assert kept == {"a": 1, "e": -24, "f": 3} and again == ["b", "d"]  # c: outside the sample, stays untested


def test_a_resumed_sample_is_continued_and_grown_not_drawn_again(tmp_path):
    module = "core/tables.py"
    folder = stage(module, (), tmp_path / "m", repo=REPO)
    names, hashes = mutants_of(module, folder, repo=REPO)
    kept, first = _plan(module, folder, {}, 6, 3, repo=REPO)
    strata = json.loads((folder / STRATA).read_text())
    assert kept == {} and len(first) == 6 and strata == {"pool": len(names), "sample": first, "seed": 3, "size": 6}
    # stopped after three verdicts (one survivor): those stand, the other three members are tested, nothing new
    done = {first[0]: 1, first[1]: 0, first[2]: 33}
    previous = {"exit_code_by_key": {**dict.fromkeys(names), **done}, "hash_by_function_name": hashes}
    kept, todo = _plan(module, folder, previous, 6, 3, repo=REPO, strata=strata)
    assert kept == done and todo == first[3:]
    assert json.loads((folder / STRATA).read_text())["sample"] == first
    # grown to 10: the 6 stay, 4 more from the mutants not in it; a member whose function changed is tested again
    function = first[0].rpartition(".")[2].partition("__mutmut_")[0]
    changed = {**hashes, function: "changed"}
    kept, todo = _plan(module, folder, {**previous, "hash_by_function_name": changed}, 10, 3, repo=REPO,
                       strata=strata)
    grown = json.loads((folder / STRATA).read_text())
    assert set(first) < set(grown["sample"]) and len(grown["sample"]) == 10 and grown["pool"] == len(names)
    assert grown["grown_from"] == 6 and first[0] in todo
    assert set(kept) == {n for n in done if n.rpartition(".")[2].partition("__mutmut_")[0] != function}
    assert sorted(todo + list(kept)) == grown["sample"]
    # another seed is a new sample; a sample drawn after a census cannot grow
    _, other = _plan(module, folder, previous, 6, 4, repo=REPO, strata=strata)
    assert other != first
    with pytest.raises(SystemExit, match="cannot grow"):
        _plan(module, folder, previous, 10, 3, repo=REPO, strata={**strata, "pool": len(names) - 1})
