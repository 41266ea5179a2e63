"""The smoke stage of .ci/run, two jobs at a time: every ``scripts/*.py --quick``, the README's shell commands and
the docs stage (.ci/docs: site build, the guides' commands with their stored outputs, the examples), whose parts
(the site, the home page, each guide, each example) are jobs of their own.

The jobs are independent (each script writes into its own temporary folders; the numba kernels come from the cache
the test stage filled, which several processes may read and write at once), so two of them share the 2 cores
instead of waiting for each other. Each job's output goes to its own log; the line per job says its wall time and
its CPU time (user + system, children included). A failed job prints the end of its log; the jobs already running
finish, no new one starts, and the stage fails.

Nothing runs twice: a ``python scripts/NAME.py --quick`` line of a shell block in the pages the docs stage runs
(docs/index.md, docs/guides/*.md: docs/tools/build_docs.sh) is its smoke run, and a README shell block that is
also a block of those pages runs there only.

    python .ci/smoke.py [--jobs 2] [--workdir DIR]
"""

from __future__ import annotations

import argparse
import ast
import os
import re
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / ".ci"))
from doc_commands import shell_blocks  # noqa: E402  (the page reader of .ci/doc_commands.py, beside this file)

#: the pages whose shell blocks the docs stage runs (docs/tools/build_docs.sh)
DOCS_PAGES = [ROOT / "docs" / "index.md", *sorted((ROOT / "docs" / "guides").glob("*.md"))]
SCRIPT_QUICK = re.compile(r"^python scripts/([\w.-]+\.py) --quick$")
#: scripts whose ``--quick`` run is this ``roadload`` command with the options of the script's ``QUICK`` list (and an
#: ``--out``): a docs page line that runs the same command with those options and another ``--out`` runs the same
#: code at the same size, so the script is not run again. A changed page line or a changed ``QUICK`` list no longer
#: matches: the script runs again.
QUICK_COMMANDS = {"train_rl.py": "roadload train"}


def quick_command(script: str) -> str | None:
    """The ``roadload`` command line (without ``--out``) that ``scripts/<script> --quick`` runs, or None."""
    if script not in QUICK_COMMANDS:
        return None
    for node in ast.parse((ROOT / "scripts" / script).read_text()).body:
        if isinstance(node, ast.Assign) and any(isinstance(t, ast.Name) and t.id == "QUICK" for t in node.targets):
            return " ".join([QUICK_COMMANDS[script], *ast.literal_eval(node.value)])
    return None


@dataclass
class Job:
    label: str
    argv: list[str]
    cwd: Path
    log: Path


def scripts_run_by_docs() -> dict[str, str]:
    """``{script file name: page:line}`` of the ``python scripts/NAME.py --quick`` lines the docs stage runs, and of
    the :data:`QUICK_COMMANDS` lines that run a script's quick command."""
    found: dict[str, str] = {}
    for code, where in shell_blocks(DOCS_PAGES).items():
        for line in code.splitlines():
            m = SCRIPT_QUICK.match(line.strip())
            if m:
                found.setdefault(m.group(1), where)
            for script in QUICK_COMMANDS:
                command = quick_command(script)
                if command and re.fullmatch(re.escape(command) + r" --out \S+", line.strip()):
                    found.setdefault(script, where)
    return found


def docs_parts() -> list[str]:
    """The parts of the docs stage (docs/tools/build_docs.sh --only=PART), the longest first: the guides (the
    longest jobs of the smoke stage), the site build, the home page, the examples."""
    guides = sorted((ROOT / "docs" / "guides").glob("*.md"), key=lambda p: -p.stat().st_size)
    examples = sorted((ROOT / "examples").glob("*.py"))
    return [*(str(p.relative_to(ROOT)) for p in guides), "site", "home", *(str(p.relative_to(ROOT)) for p in examples)]


def jobs(smoke: Path) -> list[Job]:
    """The docs stage's parts first (the guides are the longest jobs: started first, the scripts fill the other slot
    meanwhile and no long job starts last), the README's commands, then every entry point (a leading _ would mark a
    file that is not one) that the docs stage does not run already."""
    out = []
    docs = ROOT / ".ci" / "docs"
    by_docs: dict[str, str] = {}
    readme = [sys.executable, str(ROOT / ".ci" / "doc_commands.py"), str(ROOT / "README.md"), "--workdir", str(smoke)]
    if docs.is_file() and os.access(docs, os.X_OK):
        for part in docs_parts():
            out.append(Job(f"docs: {part}", [str(docs), f"--only={part}"], ROOT,
                           smoke / f"docs-{part.replace('/', '-')}.log"))
        by_docs = scripts_run_by_docs()
        readme += ["--covered-by", *map(str, DOCS_PAGES)]
    out.append(Job("README commands", readme, smoke, smoke / "readme.log"))
    for script in sorted((ROOT / "scripts").glob("[!_]*.py")):
        if script.name in by_docs:
            print(f"scripts/{script.name} --quick: run by the docs stage ({by_docs[script.name]})")
            continue
        out.append(Job(f"scripts/{script.name} --quick", [sys.executable, str(script), "--quick"], smoke,
                       smoke / f"{script.name}.log"))
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--jobs", type=int, default=2, help="jobs at a time (2: the CI machine's cores)")
    ap.add_argument("--workdir", type=Path, default=None, help="folder the scripts run in (default: a new temporary "
                                                               "folder)")
    args = ap.parse_args(argv)
    smoke = args.workdir or Path(tempfile.mkdtemp(prefix="roadload-smoke."))
    smoke.mkdir(parents=True, exist_ok=True)
    pending = jobs(smoke)
    running: dict[int, tuple[Job, subprocess.Popen, float]] = {}
    failed: list[Job] = []
    t_stage, cpu_total = time.perf_counter(), 0.0
    while pending or running:
        while pending and not failed and len(running) < max(1, args.jobs):
            job = pending.pop(0)
            with job.log.open("wb") as log:
                proc = subprocess.Popen(job.argv, cwd=job.cwd, stdout=log, stderr=subprocess.STDOUT)
            running[proc.pid] = (job, proc, time.perf_counter())
        if not running:
            break
        pid, status, usage = os.wait4(-1, 0)
        if pid not in running:
            continue
        job, proc, start = running.pop(pid)
        proc.returncode = os.waitstatus_to_exitcode(status)
        cpu = usage.ru_utime + usage.ru_stime
        cpu_total += cpu
        wall = time.perf_counter() - start
        if proc.returncode == 0:
            print(f"ok: {job.label} ({wall:.0f} s, {cpu:.0f} s CPU)", flush=True)
            continue
        failed.append(job)
        print(f"FAILED: {job.label} (exit {proc.returncode}, {wall:.0f} s); the end of {job.log}:", flush=True)
        print("\n".join(job.log.read_text(errors="replace").splitlines()[-40:]), flush=True)
    print(f"smoke stage: {time.perf_counter() - t_stage:.0f} s wall, {cpu_total:.0f} s CPU "
          f"({len(failed)} failed, {len(pending)} not started)")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
