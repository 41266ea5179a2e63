"""The smoke stage of .ci/run, two jobs at a time: every ``scripts/*.py --quick``, the README's shell commands and
the docs stage (.ci/docs: site build, the guides' commands with their stored outputs, the examples), whose parts
(the site, the home page, each guide, each example) are jobs of their own.

The jobs are independent (each script writes into its own temporary folders; the numba kernels come from the cache
the test stage filled, which several processes may read and write at once), so two of them share the 2 cores
instead of waiting for each other. Each job's output goes to its own log; the line per job says its wall time and
its CPU time (user + system, children included). A failed job prints the end of its log; the jobs already running
finish, no new one starts, and the stage fails.

The script jobs start from one process that imported the heavy libraries once (torch, stable-baselines3, CasADi,
highway-env, pandas, matplotlib and roadload's packages: 5-10 s of CPU per interpreter, most of a quick run's cost):
each ``scripts/*.py --quick`` and each ``examples/*.py --quick`` of the docs stage is a ``fork()`` of it that runs
the file as ``python FILE --quick`` would (its own process, argv, working folder, ``__main__``, log and exit status).
The guides, the home page, the site build and the README commands start their own interpreters, as a user would.

Nothing runs twice: a ``python scripts/NAME.py --quick`` line of a shell block in the pages the docs stage runs
(docs/index.md, docs/guides/*.md: docs/tools/build_docs.sh) is its smoke run, and a README shell block that is
also a block of those pages runs there only.

    python .ci/smoke.py [--jobs 2] [--workdir DIR]
"""

from __future__ import annotations

import argparse
import ast
import atexit
import importlib
import io
import os
import re
import runpy
import subprocess
import sys
import tempfile
import threading
import time
import traceback
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
#: imported once by the smoke process before the script jobs are forked from it: the libraries whose import is most
#: of a quick script's CPU (each interpreter would pay them again)
PRELOAD = ("numpy", "scipy.optimize", "scipy.signal", "scipy.stats", "pandas", "pyarrow.parquet", "matplotlib.pyplot",
           "numba", "casadi", "torch", "gymnasium", "stable_baselines3", "highway_env", "roadload.envs",
           "roadload.estimators", "roadload.controllers", "roadload.gym.vector", "roadload.gym.traffic",
           "roadload.gym.highway", "roadload.gym.sb3", "roadload.sim2real", "roadload.experiments.rl",
           "roadload.experiments.cli")
#: scripts that measure the memory of their own process or of the processes they start (a fork of the preloaded
#: process starts at its size): each runs in a fresh interpreter
FRESH_INTERPRETER = {"bench_cli_startup.py", "bench_simulator.py", "bench_trip_storage.py"}


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
    script: Path | None = None  # a ``python SCRIPT --quick`` job: forked from the preloaded smoke process


def preload() -> None:
    """Import :data:`PRELOAD` in this process (the script jobs fork from it). OMP_WAIT_POLICY is set first, as the
    scripts that set it do before torch / numba load libgomp; a module that fails to import is left to the job."""
    os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")
    os.environ.setdefault("MPLBACKEND", "Agg")
    for name in PRELOAD:
        try:
            importlib.import_module(name)
        except Exception as exc:  # the job that needs it fails with its own traceback
            print(f"preload: {name} not imported ({type(exc).__name__}: {exc})", flush=True)


def run_script_in_child(job: Job) -> None:
    """In a forked child: run ``job.script --quick`` as ``python`` would run it (``__main__``, argv, sys.path[0],
    working folder, stdout and stderr to the job's log, non-daemon threads joined and exit handlers run at the end),
    then leave the process with the script's exit status. Never returns."""
    code = 1
    try:
        fd = os.open(job.log, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644)
        os.dup2(fd, 1)
        os.dup2(fd, 2)
        os.close(fd)
        # new stream objects on the new descriptors: the inherited ones may buffer (or be a capturing wrapper)
        sys.stdout = sys.__stdout__ = io.TextIOWrapper(io.FileIO(1, "w", closefd=False), write_through=True)
        sys.stderr = sys.__stderr__ = io.TextIOWrapper(io.FileIO(2, "w", closefd=False), write_through=True)
        os.chdir(job.cwd)
        assert job.script is not None
        sys.argv = [str(job.script), *job.argv[2:]]
        sys.path[:] = [str(job.script.parent), *(p for p in sys.path[1:] if p != str(ROOT / ".ci"))]
        try:
            runpy.run_path(str(job.script), run_name="__main__")
            code = 0
        except SystemExit as exc:
            if exc.code is None or isinstance(exc.code, int):
                code = exc.code or 0
            else:
                print(exc.code, file=sys.stderr)
                code = 1
        for thread in threading.enumerate():
            if thread is not threading.main_thread() and not thread.daemon:
                thread.join()
        atexit._run_exitfuncs()
    except BaseException:
        traceback.print_exc()
        code = 1
    finally:
        for stream in (sys.stdout, sys.stderr):
            try:
                stream.flush()
            except Exception:
                pass
        os._exit(code)


def start(job: Job) -> tuple[int, subprocess.Popen | None]:
    """Start ``job``: a script job forked from this (preloaded) process, any other in its own interpreter; its pid
    and its Popen (None for a fork). The Popen is kept until the job is reaped: a dropped one that is still running
    goes to subprocess's list of unreaped children, which a later Popen polls, and could reap it first."""
    if job.script is not None:
        sys.stdout.flush()
        sys.stderr.flush()
        pid = os.fork()
        if pid == 0:
            run_script_in_child(job)
        return pid, None
    with job.log.open("wb") as log:
        proc = subprocess.Popen(job.argv, cwd=job.cwd, stdout=log, stderr=subprocess.STDOUT)
    return proc.pid, proc


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
            log = smoke / f"docs-{part.replace('/', '-')}.log"
            if part.startswith("examples/"):  # what build_docs.sh --only=PART runs: the example --quick in the root
                out.append(Job(f"docs: {part}", [sys.executable, part, "--quick"], ROOT, log, script=ROOT / part))
            else:
                out.append(Job(f"docs: {part}", [str(docs), f"--only={part}"], ROOT, log))
        by_docs = scripts_run_by_docs()
        readme += ["--covered-by", *map(str, DOCS_PAGES)]
    out.append(Job("README commands", readme, smoke, smoke / "readme.log"))
    for script in sorted((ROOT / "scripts").glob("[!_]*.py")):
        if script.name in by_docs:
            print(f"scripts/{script.name} --quick: run by the docs stage ({by_docs[script.name]})")
            continue
        out.append(Job(f"scripts/{script.name} --quick", [sys.executable, str(script), "--quick"], smoke,
                       smoke / f"{script.name}.log", script=None if script.name in FRESH_INTERPRETER else script))
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--jobs", type=int, default=2, help="jobs at a time (2: the CI machine's cores)")
    ap.add_argument("--workdir", type=Path, default=None, help="folder the scripts run in (default: a new temporary "
                                                               "folder)")
    ap.add_argument("--no-preload", action="store_true", help="every script in its own fresh interpreter")
    args = ap.parse_args(argv)
    # the jobs run two at a time beside the two test processes: an OpenBLAS pool of one spinning thread per core in
    # every job would oversubscribe the cores (the tests' conftest sets the same; set before the preload loads numpy)
    os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
    smoke = args.workdir or Path(tempfile.mkdtemp(prefix="roadload-smoke."))
    smoke.mkdir(parents=True, exist_ok=True)
    pending = jobs(smoke)
    if args.no_preload:
        for job in pending:
            job.script = None
    elif any(job.script for job in pending):
        t0, c0 = time.perf_counter(), time.process_time()
        preload()
        print(f"preloaded for the script jobs ({time.perf_counter() - t0:.0f} s, "
              f"{time.process_time() - c0:.0f} s CPU)", flush=True)
    running: dict[int, tuple[Job, subprocess.Popen | None, float]] = {}
    failed: list[Job] = []
    t_stage, cpu_total = time.perf_counter(), 0.0
    while pending or running:
        while pending and not failed and len(running) < max(1, args.jobs):
            job = pending.pop(0)
            pid, proc = start(job)
            running[pid] = (job, proc, time.perf_counter())
        if not running:
            break
        pid, status, usage = os.wait4(-1, 0)
        if pid not in running:
            continue
        job, proc, started = running.pop(pid)
        returncode = os.waitstatus_to_exitcode(status)
        if proc is not None:
            proc.returncode = returncode  # reaped here: the Popen must not wait for it again
        cpu = usage.ru_utime + usage.ru_stime
        cpu_total += cpu
        wall = time.perf_counter() - started
        if returncode == 0:
            print(f"ok: {job.label} ({wall:.0f} s, {cpu:.0f} s CPU)", flush=True)
            continue
        failed.append(job)
        print(f"FAILED: {job.label} (exit {returncode}, {wall:.0f} s); the end of {job.log}:", flush=True)
        print("\n".join(job.log.read_text(errors="replace").splitlines()[-40:]), flush=True)
    print(f"smoke stage: {time.perf_counter() - t_stage:.0f} s wall, {cpu_total:.0f} s CPU "
          f"({len(failed)} failed, {len(pending)} not started)")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
