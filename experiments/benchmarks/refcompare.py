"""Same-session old/new comparison for the benchmark scripts: export a git commit of roadload into a temporary
package tree and run a benchmark script against it and against the working tree, interleaved.

The export follows ``[tool.setuptools.package-dir]`` of the commit's pyproject.toml (``roadload`` = ``core/``,
``roadload.envs`` = ``envs/``, ...), so ``PYTHONPATH=<tree>`` imports the old package ahead of the editable
install. Each run writes its figures as JSON; the caller divides them.
"""

from __future__ import annotations

import io
import json
import os
import shutil
import subprocess
import sys
import tarfile
import tempfile
import tomllib
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]


class RefError(SystemExit):
    """A commit to compare with that git does not know (the scripts exit with this message, no traceback)."""


def export_commit(ref: str, dest: Path) -> Path:
    """``git archive ref`` laid out as an importable package tree under ``dest``; returns the PYTHONPATH entry.
    Raises RefError when ref names no commit of the repository."""
    known = subprocess.run(["git", "-C", str(REPO), "rev-parse", "--verify", "--quiet", f"{ref}^{{commit}}"],
                           capture_output=True)
    if known.returncode != 0:
        raise RefError(f"commit to compare with: {ref!r} is not a commit of {REPO} (expected a hash, branch or tag "
                       "that `git rev-parse` resolves)")
    blob = subprocess.run(["git", "-C", str(REPO), "archive", ref], check=True, capture_output=True).stdout
    src = dest / "src"
    with tarfile.open(fileobj=io.BytesIO(blob)) as tar:
        tar.extractall(src, filter="data")
    mapping = tomllib.loads((src / "pyproject.toml").read_text())["tool"]["setuptools"]["package-dir"]
    pkg = dest / "pkg"
    # parents first: "roadload" before "roadload.envs"
    for name, folder in sorted(mapping.items(), key=lambda kv: kv[0].count(".")):
        target = pkg.joinpath(*name.split("."))
        if target.exists():
            shutil.rmtree(target)
        shutil.copytree(src / folder, target)
    return pkg


def run_json(script: Path, args: list[str], pythonpath: str | None) -> dict:
    """Run ``script args --json <tmp>`` (with PYTHONPATH when given) and return its JSON figures."""
    with tempfile.NamedTemporaryFile(suffix=".json", delete=False) as f:
        out = Path(f.name)
    env = dict(os.environ)
    if pythonpath:
        env["PYTHONPATH"] = pythonpath
    else:
        env.pop("PYTHONPATH", None)
    try:
        subprocess.run([sys.executable, str(script), *args, "--json", str(out)], check=True, env=env,
                       cwd=tempfile.gettempdir(), stdout=subprocess.DEVNULL)
        return json.loads(out.read_text())
    finally:
        out.unlink(missing_ok=True)


def compare(script: Path, args: list[str], ref: str, rounds: int = 3) -> tuple[list[dict], list[dict]]:
    """Figures of ``script`` on commit ``ref`` and on the working tree, ``rounds`` times each, interleaved
    (old, new, old, new, ...), so both see the same machine load. Returns (old runs, new runs)."""
    with tempfile.TemporaryDirectory(prefix="roadload-ref-") as tmp:
        pkg = export_commit(ref, Path(tmp))
        old, new = [], []
        for _ in range(rounds):
            old.append(run_json(script, args, str(pkg)))
            new.append(run_json(script, args, None))
    return old, new
