"""scripts/_refcompare.py, the old/new export behind every ``--compare`` / ``--ref`` of the benchmark scripts: an
unknown commit gets a clean message, a known one becomes an importable package tree with the commit's files."""

from __future__ import annotations

import importlib.util
import subprocess
from pathlib import Path

import pytest

SCRIPTS = Path(__file__).resolve().parents[2] / "scripts"


def _refcompare():
    spec = importlib.util.spec_from_file_location("_refcompare", SCRIPTS / "_refcompare.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _git_available() -> bool:
    return subprocess.run(["git", "-C", str(SCRIPTS), "rev-parse", "HEAD"], capture_output=True).returncode == 0


pytestmark = pytest.mark.skipif(not _git_available(), reason="needs the project's git history (a clone)")


def test_unknown_commit_is_refused_with_its_name(tmp_path):
    rc = _refcompare()
    with pytest.raises(rc.RefError, match="'no-such-commit' is not a commit"):
        rc.export_commit("no-such-commit", tmp_path)
    assert not any(tmp_path.iterdir())  # nothing written


def test_head_is_exported_as_the_package_layout(tmp_path):
    rc = _refcompare()
    pkg = rc.export_commit("HEAD", tmp_path)
    committed = subprocess.run(["git", "-C", str(SCRIPTS.parent), "show", "HEAD:envs/physics.py"],
                               capture_output=True, text=True, check=True).stdout
    assert (pkg / "roadload" / "envs" / "physics.py").read_text() == committed
    assert (pkg / "roadload" / "gym" / "vector.py").is_file()
