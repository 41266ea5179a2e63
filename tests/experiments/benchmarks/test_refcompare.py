"""roadload.experiments.benchmarks.refcompare, the old/new export behind every ``--compare`` / ``--ref`` of the
benchmarks: an unknown commit gets a clean message, a known one becomes an importable package tree with the
commit's files."""

from __future__ import annotations

import subprocess
from pathlib import Path

import pytest

from roadload.experiments.benchmarks import refcompare as rc

REPO = Path(__file__).resolve().parents[3]


def _git_available() -> bool:
    return subprocess.run(["git", "-C", str(REPO), "rev-parse", "HEAD"], capture_output=True).returncode == 0


pytestmark = pytest.mark.skipif(not _git_available(), reason="needs the project's git history (a clone)")


def test_unknown_commit_is_refused_with_its_name(tmp_path):
    with pytest.raises(rc.RefError, match="'no-such-commit' is not a commit"):
        rc.export_commit("no-such-commit", tmp_path, REPO)
    assert not any(tmp_path.iterdir())  # nothing written


def test_head_is_exported_as_the_package_layout(tmp_path):
    pkg = rc.export_commit("HEAD", tmp_path, REPO)
    committed = subprocess.run(["git", "-C", str(REPO), "show", "HEAD:envs/physics.py"],
                               capture_output=True, text=True, check=True).stdout
    assert (pkg / "roadload" / "envs" / "physics.py").read_text() == committed
    assert (pkg / "roadload" / "gym" / "vector.py").is_file()
