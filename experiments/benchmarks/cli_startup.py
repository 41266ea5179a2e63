"""How fast the ``roadload`` command answers, against ``python -c "import numpy, pandas"`` measured in the same run.

Every case runs in a fresh process, interleaved with the reference (reference, case 1, case 2, ..., reference, ...)
so that machine load hits them alike; each figure is the median over the repeats of wall time and CPU time (user +
system, from wait4), and its ratio to the reference's median. Peak RSS comes from the same wait4. Cases:

- ``python -c pass`` (the interpreter alone: the last column is each wall time against it);
- ``roadload --help``;
- refused bad input (exit code 2): a mapping file with a typo in a key, an unknown vehicle preset, an unknown import
  format, a missing trip file;
- a 1-hour ``roadload simulate`` on a 150 km motorway (with --quick 20 minutes: the streamed writer holds one
  5-minute row group at a time and the peak RSS is flat from the third one on, measured): peak RSS and wall time,
  after a 10-second run that loads the simulator's kernels (on a fresh install it compiles them with numba, then
  builds the ahead-of-time extension the measured run loads instead of numba and LLVM: ``roadload.compiled``).
  Its peak RSS is that of the whole process tree (the larger of wait4's and the sampled sum of the tree).

Targets (issue: a command line that starts at once): --help within 1.5x and a refused bad input within 2x of the
reference; peak RSS of --help <= 150 MB and of a 1-hour simulate <= 250 MB. The 1-min load average is printed.
The script exits non-zero when the 1-hour simulate's peak RSS exceeds :data:`SIMULATE_RSS_LIMIT_MB` (RSS does not
depend on machine load, unlike the times, which are only printed), with --quick (CI, a fresh install) too: the
20-minute run peaks as high as the hour (see above). The simulate's line is followed by its memory at the sampled peak:
anonymous and file-backed, and of the latter libllvmlite and libarrow.

Why a fresh install measures more: peak RSS counts the clean, shared file pages of the libraries a process maps, and
the kernel maps a whole page-cache folio on a fault. pip writes a library in large folios, so every static
constructor that a library runs at load maps megabytes: 96 MB resident right after ``import llvmlite.binding`` on a
freshly written libllvmlite.so (75 of its 82 MB of code), 40-70 MB once its pages were reclaimed and read back in
smaller ones; likewise libarrow (29 against 11-14 MB). A simulate on the compiled kernels maps no libllvmlite; the
simulate on numba's kernels measured 304 MB right after a fresh install and 219 MB on an older one. To measure the
fresh case (what CI's new venv sees), write the libraries anew in your own venv with a current pip (pip 23 writes
in smaller folios), then run at once:

    pip install --no-deps --force-reinstall llvmlite==X pyarrow==Y   # X, Y: the versions `pip show` lists
    python scripts/bench_cli_startup.py --repeats 1

    python scripts/bench_cli_startup.py                 # 7 repeats + the 1-hour simulate
    python scripts/bench_cli_startup.py --quick         # CI: 1 round + a 20-minute simulate, RSS guard checked
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

#: the most peak RSS a 1-hour ``roadload simulate`` may take [MB] (warm kernel cache)
SIMULATE_RSS_LIMIT_MB = 250.0


def roadload_command() -> list[str]:
    exe = shutil.which("roadload")
    return [exe] if exe else [sys.executable, "-c", "from roadload.experiments.cli import main; main()"]


def run(argv: list[str], cwd: Path) -> tuple[float, float, float, int]:
    """(wall [s], CPU [s], peak RSS [MB], exit code) of one child process."""
    t0 = time.perf_counter()
    proc = subprocess.Popen(argv, cwd=cwd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    _, status, usage = os.wait4(proc.pid, 0)
    wall = time.perf_counter() - t0
    return wall, usage.ru_utime + usage.ru_stime, usage.ru_maxrss / 1024.0, os.waitstatus_to_exitcode(status)


def process_tree(pid: int) -> list[int]:
    """``pid`` and its descendants (/proc/PID/task/*/children), parents first; gone ones are skipped."""
    tree, todo = [], [pid]
    while todo:
        p = todo.pop()
        tree.append(p)
        for task in Path(f"/proc/{p}/task").glob("*/children"):
            try:
                todo += [int(c) for c in task.read_text().split()]
            except OSError:
                continue
    return tree


def memory_breakdown(pid: int) -> dict[str, float] | None:
    """Resident memory of a running process and all its descendants, summed, by kind [MB] (/proc/PID/smaps):
    anonymous (heap, arrays, Python objects) and file-backed, and of the latter the two libraries whose clean pages
    depend on how their files were written (libllvmlite, libarrow); None once the process is gone."""
    out = {"rss": 0.0, "anonymous": 0.0, "libllvmlite": 0.0, "libarrow": 0.0}
    try:
        tree = process_tree(pid)
    except OSError:
        return None
    for member in tree:
        name = ""
        try:
            with open(f"/proc/{member}/smaps") as smaps:
                for line in smaps:
                    key, _, rest = line.partition(" ")
                    if not key.endswith(":"):  # a mapping's header: address range, mode, offset, device, inode, path
                        name = rest.split()[-1] if len(rest.split()) > 4 else ""
                    elif key in ("Rss:", "Anonymous:"):
                        kb = float(rest.split()[0]) / 1024.0
                        out["rss" if key == "Rss:" else "anonymous"] += kb
                        lib = next((k for k in ("libllvmlite", "libarrow.") if k in name and key == "Rss:"), None)
                        if lib:
                            out[lib.rstrip(".")] += kb
        except (FileNotFoundError, ProcessLookupError):
            if member == pid:
                return None
    out["file-backed"] = out["rss"] - out["anonymous"]
    out["processes"] = float(len(tree))
    return out


def run_sampled(argv: list[str], cwd: Path) -> tuple[tuple[float, float, float, int], dict[str, float] | None]:
    """:func:`run` plus the :func:`memory_breakdown` of the process tree at its sampled peak (every 0.1 s). The peak
    RSS returned is the larger of wait4's (the largest single process of the tree) and the sampled peak of the
    tree's sum, so that memory moved into a child process is counted."""
    t0 = time.perf_counter()
    proc = subprocess.Popen(argv, cwd=cwd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    peak: dict[str, float] | None = None
    while True:
        pid, status, usage = os.wait4(proc.pid, os.WNOHANG)
        if pid:
            break
        now = memory_breakdown(proc.pid)
        if now is not None and (peak is None or now["rss"] > peak["rss"]):
            peak = now
        time.sleep(0.1)
    wall = time.perf_counter() - t0
    rss = max(usage.ru_maxrss / 1024.0, peak["rss"] if peak else 0.0)
    return (wall, usage.ru_utime + usage.ru_stime, rss, os.waitstatus_to_exitcode(status)), peak


def cases(work: Path) -> dict[str, tuple[list[str], int]]:
    """name -> (argv, expected exit code)."""
    cli = roadload_command()
    mapping = {"name": "typo", "format": "csv", "csv": {"time": "time_s"},
               "chanels": [{"source": "speed_kmh", "channel": "vehicle_speed", "unit": "km/h"}]}
    (work / "typo.json").write_text(json.dumps(mapping))
    (work / "log.csv").write_text("time_s,speed_kmh\n0,0\n0.01,0.1\n")
    return {
        "python -c pass": ([sys.executable, "-c", "pass"], 0),
        "python -c 'import numpy, pandas'": ([sys.executable, "-c", "import numpy, pandas"], 0),
        "roadload --help": (cli + ["--help"], 0),
        "refused: mapping file with a typo": (cli + ["import", "log.csv", "--format", "csv", "--mapping",
                                                     "typo.json", "--out", "x.parquet"], 2),
        "refused: unknown vehicle preset": (cli + ["simulate", "--vehicle", "gt_rdw", "--road", "hilly", "--out",
                                                   "x.parquet"], 2),
        "refused: unknown import format": (cli + ["import", "log.csv", "--format", "cvs", "--out", "x.parquet"], 2),
        "refused: missing trip file": (cli + ["export", "missing.parquet", "--format", "mf4"], 2),
    }


def simulate_run(work: Path, seconds: float) -> tuple[tuple[float, float, float, int], dict[str, float] | None]:
    """A ``roadload simulate`` of the bmw_i3 for ``seconds`` on a motorway (150 km for an hour; written as a
    profile file first), after a 10-second run that loads the kernels (a first run compiles them and builds the
    ahead-of-time extension)."""
    length = 150_000.0 * max(seconds / 3600.0, 0.1)
    road = work / "motorway.json"
    # written by a child process: this process stays small, since wait4's peak RSS of a child started with vfork
    # (subprocess on Linux) is at least this process's own peak at the start (the kernel carries the shared memory
    # map's high-water mark over the exec); importing the road generator here would load numba (~200 MB)
    subprocess.run([sys.executable, "-c", "import sys; from roadload.road_profiles import load_profile, save_profile; "
                    "save_profile(load_profile('motorway', seed=0, length=float(sys.argv[1])), sys.argv[2])",
                    str(length), str(road)], check=True)
    command = roadload_command() + ["simulate", "--vehicle", "bmw_i3", "--road", str(road), "--duration"]
    warm = run(command + ["10", "--out", "warm.parquet"], work)
    if warm[3] != 0:
        return warm, None
    return run_sampled(command + [f"{seconds:g}", "--out", "run.parquet"], work)


def simulate_check(work: Path, quick: bool) -> list[str]:
    """Run the simulate case (20 minutes with ``quick``, else 1 hour), print it and return what failed."""
    seconds = 1200.0 if quick else 3600.0
    (wall, cpu, rss, code), peak = simulate_run(work, seconds)
    print(f"{f'roadload simulate, {seconds / 60:.0f} min':40s} {wall:9.1f} {'':6s} {cpu:8.1f} {'':6s} {rss:14.0f}  "
          f"{code}")
    if peak is not None:
        print("  at the sampled peak [MB]: " + ", ".join(f"{k} {v:.0f}" for k, v in peak.items()))
    if code != 0:
        return [f"simulate: exit {code}"]
    if rss > SIMULATE_RSS_LIMIT_MB:
        return [f"simulate: peak RSS {rss:.0f} MB above the {SIMULATE_RSS_LIMIT_MB:.0f} MB limit"]
    return []


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=7, help="interleaved rounds (median reported)")
    ap.add_argument("--quick", action="store_true", help="CI run: 1 round, a 20-minute simulate (RSS checked)")
    ap.add_argument("--no-simulate", action="store_true", help="skip the simulate and its RSS check")
    args = ap.parse_args(argv)
    repeats = 1 if args.quick else max(1, args.repeats)
    with tempfile.TemporaryDirectory(prefix="roadload-startup-") as tmp:
        work = Path(tmp)
        table = cases(work)
        samples: dict[str, list[tuple[float, float, float, int]]] = {name: [] for name in table}
        load0 = os.getloadavg()[0]
        for _ in range(repeats):
            for name, (argv, _) in table.items():
                samples[name].append(run(argv, work))
        ref = "python -c 'import numpy, pandas'"
        ref_wall = statistics.median(s[0] for s in samples[ref])
        ref_cpu = statistics.median(s[1] for s in samples[ref])
        bare_wall = statistics.median(s[0] for s in samples["python -c pass"])
        print(f"{repeats} interleaved rounds; 1-min load average {load0:.2f} at start, {os.getloadavg()[0]:.2f} "
              f"at end ({os.cpu_count()} CPUs)")
        print(f"{'case':40s} {'wall [s]':>9s} {'x ref':>6s} {'CPU [s]':>8s} {'x ref':>6s} {'peak RSS [MB]':>14s}  "
              f"exit  {'x pass':>6s}")
        failed = []
        for name, (_, expected) in table.items():
            wall = statistics.median(s[0] for s in samples[name])
            cpu = statistics.median(s[1] for s in samples[name])
            rss = max(s[2] for s in samples[name])
            codes = sorted({s[3] for s in samples[name]})
            print(f"{name:40s} {wall:9.2f} {wall / ref_wall:6.2f} {cpu:8.2f} {cpu / ref_cpu:6.2f} {rss:14.0f}  "
                  f"{','.join(map(str, codes)):4s}  {wall / bare_wall:6.2f}")
            if codes != [expected]:
                failed.append(f"{name}: exit {codes}, expected {expected}")
        if not args.no_simulate:
            failed += simulate_check(work, args.quick)
        print("targets: --help <= 1.5x and refused input <= 2x the reference (wall); --help <= 150 MB, 1-hour "
              "simulate <= 250 MB peak RSS")
    if failed:
        sys.exit("FAILED: " + "; ".join(failed))

