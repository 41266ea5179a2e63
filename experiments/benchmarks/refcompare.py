"""Old/new comparison in one run for the benchmarks: export a git commit of roadload into a temporary package
tree and run a benchmark module against it and against the working tree, interleaved.

The export follows ``[tool.setuptools.package-dir]`` of the commit's pyproject.toml (``roadload`` = ``core/``,
``roadload.envs`` = ``envs/``, ...), so ``PYTHONPATH=<tree>`` imports the old package ahead of the installed
one. The benchmark module itself runs from the working tree in both children (its file is run as ``__main__``,
so an old commit needs none of it); each child writes its figures as JSON and the caller divides them.
"""

from __future__ import annotations

import argparse
import io
import json
import os
import shutil
import subprocess
import sys
import tarfile
import tempfile
import tomllib
from collections.abc import Callable
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
"""The source tree of an editable install (experiments/benchmarks/ -> the repository root); the scripts pass
their own repository instead, which also works from an installed copy."""

# a child runs a module file as __main__ through runpy: unlike ``python FILE`` this does not put the file's folder
# (experiments/benchmarks/, whose simulator.py, gym.py, ... would shadow top-level modules) first on sys.path
_RUN_FILE = "import runpy, sys; sys.argv = sys.argv[1:]; runpy.run_path(sys.argv[0], run_name='__main__')"
# a child of an identity check loads the module file (not as __main__) and calls its dump(out, quick)
_DUMP_FILE = ("import runpy, sys; from pathlib import Path; "
              "runpy.run_path(sys.argv[1])['dump'](Path(sys.argv[2]), sys.argv[3] == 'quick')")


class RefError(SystemExit):
    """A commit to compare with that git does not know (the scripts exit with this message, no traceback)."""


def export_commit(ref: str, dest: Path, repo: Path = REPO) -> Path:
    """``git archive ref`` of ``repo`` laid out as an importable package tree under ``dest``; returns the
    PYTHONPATH entry. Raises RefError when ref names no commit of the repository."""
    known = subprocess.run(["git", "-C", str(repo), "rev-parse", "--verify", "--quiet", f"{ref}^{{commit}}"],
                           capture_output=True)
    if known.returncode != 0:
        raise RefError(f"commit to compare with: {ref!r} is not a commit of {repo} (expected a hash, branch or tag "
                       "that `git rev-parse` resolves)")
    blob = subprocess.run(["git", "-C", str(repo), "archive", ref], check=True, capture_output=True).stdout
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


def run_file(path: Path, args: list[str], pythonpath: str | None, quiet: bool = True, code: str = _RUN_FILE) -> None:
    """Run the module file ``path`` as ``__main__`` with ``args`` in a child process whose roadload is the one
    under ``pythonpath`` (an exported commit) or, without it, the installed one; raises on a non-zero exit.
    ``code``: what the child runs (``-c``) with ``path`` and ``args`` as its arguments."""
    env = dict(os.environ)
    if pythonpath:
        env["PYTHONPATH"] = pythonpath
    else:
        env.pop("PYTHONPATH", None)
    subprocess.run([sys.executable, "-c", code, str(path), *args], check=True, env=env,
                   cwd=tempfile.gettempdir(), stdout=subprocess.DEVNULL if quiet else None)


def run_json(path: Path, args: list[str], pythonpath: str | None) -> dict:
    """Run the benchmark module file ``path`` with ``args --json <tmp>`` (see :func:`run_file`) and return its
    JSON figures."""
    with tempfile.NamedTemporaryFile(suffix=".json", delete=False) as f:
        out = Path(f.name)
    try:
        run_file(path, [*args, "--json", str(out)], pythonpath)
        return json.loads(out.read_text())
    finally:
        out.unlink(missing_ok=True)


def compare(path: Path, args: list[str], ref: str, rounds: int = 3,
            repo: Path = REPO) -> tuple[list[dict], list[dict]]:
    """Figures of the benchmark module file ``path`` on commit ``ref`` and on the working tree, ``rounds`` times
    each, interleaved (old, new, old, new, ...), so both see the same machine load. Returns (old runs, new runs)."""
    with tempfile.TemporaryDirectory(prefix="roadload-ref-") as tmp:
        pkg = export_commit(ref, Path(tmp), repo)
        old, new = [], []
        for _ in range(rounds):
            old.append(run_json(path, args, str(pkg)))
            new.append(run_json(path, args, None))
    return old, new


def dump_pair(path: Path, ref: str, quick: bool, dest: Path, repo: Path = REPO) -> tuple[Path, Path]:
    """The arrays of commit ``ref`` and of the working tree, each written by ``dump(file, quick)`` of the
    identity-check module file ``path`` in its own process (see :func:`run_file`); returns the (old, new) ``.npz``
    files, written under ``dest``."""
    pkg = export_commit(ref, dest, repo)
    old, new = dest / "old.npz", dest / "new.npz"
    for pythonpath, out in ((str(pkg), old), (None, new)):
        run_file(path, [str(out), "quick" if quick else "full"], pythonpath, quiet=False, code=_DUMP_FILE)
    return old, new


def identity_command(doc: str, quick_help: str, compare: Callable[[str, bool, Path | None], int],
                     argv: list[str] | None = None, repo: Path | None = None) -> int:
    """The command line of an identity check (``--ref REF``, ``--quick``; ``doc``'s first line describes it);
    returns the exit status of ``compare(ref, quick, repo)``."""
    ap = argparse.ArgumentParser(description=doc.splitlines()[0])
    ap.add_argument("--ref", default="HEAD", help="git commit to compare the working tree with (default HEAD)")
    ap.add_argument("--quick", action="store_true", help=quick_help)
    args = ap.parse_args(argv)
    return compare(args.ref, args.quick, repo)
