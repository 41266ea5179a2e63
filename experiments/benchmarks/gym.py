"""Environment steps per second (one EcoDrive-v0 step = 0.1 s of driving, 10 physics steps at 100 Hz).

Table 1 (all in the same run): EcoDrive-v0 single process, SB3 DummyVecEnv, and for each thread count of
``--threads`` the native batched vector env (``gymnasium.make_vec(..., vectorization_mode="vector_entry_point",
threads=k)``) and its bare batched physics with the same k numba threads (the like-for-like reference), as
wall-clock and per-CPU-second rates (the machine is shared: the CPU rate is what the code costs, the wall rate what
the scheduler gave us), with the 1-minute load average as each row started: on 2 cores a load above ~1 means
another process holds a core, and a 2-thread env then waits at every step's barrier. The 2-thread rows run
with OMP_WAIT_POLICY=PASSIVE unless it is set (roadload.gym.vector: spinning OpenMP threads made 2 threads 3x
slower than one on the shared machine); ``OMP_WAIT_POLICY=ACTIVE python scripts/bench_gym.py ...`` measures the
spinning default.
Table 2: per thread count, native / bare and native / DummyVecEnv, and the target check (>= 300,000 wall steps/s).
Table 3 (unless --no-classic): single / can observation / DummyVecEnv / SubprocVecEnv x n, EcoHighway-v0 and
highway-env's highway-fast-v0. Random actions in [-1, 1], resets included.

    python scripts/bench_gym.py --no-classic --threads 1,2       # the native-env figures, ~1 min
    python scripts/bench_gym.py [--seconds 5] [--native 256] [--n-envs 2] [--threads 1,2]     # everything
    python scripts/bench_gym.py --quick                                       # CI smoke run (< 60 s)
    python scripts/bench_gym.py --compare e7237e4 --threads 1,2 [--rounds 2]  # old commit vs working tree

``--compare REF`` exports commit REF (``git archive``, :mod:`.refcompare`) and runs the native-env table on
it and on the working tree, interleaved ``--rounds`` times (old, new, old, new, ...: both see the same machine
load), and prints per thread count the native env's wall and per-CPU-second rates, old and new, their ratio and
native / bare of each (the bare batched physics is the same code in both, so it also shows how the load moved).
This file runs against an old package tree too: it imports from roadload only what every commit has.
"""

import os

# libgomp reads OMP_WAIT_POLICY once, when it is loaded, and roadload.experiments.rl imports torch, which loads it:
# the default has to be set before that import (the env's own default comes too late then: 32k instead of 160k
# env steps/s with 2 threads on the loaded machine)
os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")

import argparse  # noqa: E402
import json  # noqa: E402
import statistics  # noqa: E402
from pathlib import Path  # noqa: E402

import pandas as pd  # noqa: E402
from rich.console import Console  # noqa: E402

from roadload.experiments.rl import (load_average, native_ratios, print_table, run_benchmark,  # noqa: E402
                                     run_native_benchmark, speed_ratio)
from roadload.gym.vector import openmp_wait_policy  # noqa: E402

TARGET_STEPS_PER_S = 300_000
"""Target of the native vector env: steps/s (wall) at N = 256 on the 2-core machine."""


def _thread_counts(text: str) -> tuple[int, ...]:
    try:
        counts = tuple(int(t) for t in text.split(",") if t.strip())
    except ValueError:
        counts = ()
    if not counts or min(counts) < 1:
        raise argparse.ArgumentTypeError(f"expected comma-separated thread counts >= 1 (e.g. 1,2), got "
                                         f"{text!r}")
    return counts


def compare_with(args: argparse.Namespace, repo: Path | None) -> None:
    """--compare: the native-env table of commit args.compare (of the git repository ``repo``, default: the source
    tree of this file) and of the working tree, interleaved."""
    # imported here, not at the top: this file also runs against old package trees that lack the module
    from roadload.experiments.benchmarks.refcompare import REPO, compare

    bench = ["--no-classic", "--seconds", str(args.seconds), "--native", str(args.native), "--dummy",
             str(args.dummy), "--threads", ",".join(str(t) for t in args.threads)]
    old, new = compare(Path(__file__).resolve(), bench, args.compare, args.rounds, repo or REPO)
    console = Console(width=150)
    rows = []
    for t in args.threads:
        def pick(runs: list[dict], key: str) -> float:
            return statistics.median(r[key] for run in runs for r in run["ratios"] if r["threads"] == t)
        o_wall, n_wall = pick(old, "native_steps_per_s"), pick(new, "native_steps_per_s")
        o_cpu, n_cpu = pick(old, "native_steps_per_cpu_s"), pick(new, "native_steps_per_cpu_s")
        rows.append({"threads": t, "old /s": o_wall, "new /s": n_wall, "new/old": n_wall / o_wall,
                     "old /cpu-s": o_cpu, "new /cpu-s": n_cpu, "new/old cpu": n_cpu / o_cpu,
                     "old n/b": pick(old, "native_over_bare_wall"), "new n/b": pick(new, "native_over_bare_wall"),
                     "old n/b cpu": pick(old, "native_over_bare_cpu"),
                     "new n/b cpu": pick(new, "native_over_bare_cpu")})
    loads = [run["load_1min_start"] for run in old + new]
    table = pd.DataFrame(rows)
    print_table(console, table.assign(**{c: table[c].map("{:,.0f}".format) for c in table.columns
                                         if c.endswith(("/s", "/cpu-s"))}),
                f"native vector env x{args.native}: {args.compare} (old) vs working tree (new), median of "
                f"{args.rounds} interleaved rounds; load average at the starts {min(loads):.1f}-{max(loads):.1f}",
                "{:.2f}")
    console.print("/s = env steps per wall second, /cpu-s = per CPU second of the process, n/b = native env / bare "
                  "batched physics with the same threads (wall, cpu)")


def main(argv: list[str] | None = None, repo: Path | None = None) -> None:
    """The benchmark's command line (``scripts/bench_gym.py``); ``repo``: the git repository of ``--compare``."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=5.0, help="measurement time per row [s]")
    ap.add_argument("--native", type=int, default=256, help="sub-envs of the native vector env")
    ap.add_argument("--dummy", type=int, default=16, help="sub-envs of the DummyVecEnv reference")
    ap.add_argument("--threads", type=_thread_counts, default=None,
                    help="numba thread counts of the native env and its bare loop, comma-separated (default 1,2; "
                         "with --quick 1)")
    ap.add_argument("--n-envs", type=int, default=2, help="vectorised environments of the classic table")
    ap.add_argument("--no-highway", action="store_true", help="skip EcoHighway-v0 and highway-fast-v0")
    ap.add_argument("--no-classic", action="store_true", help="only the native-vector-env table")
    ap.add_argument("--quick", action="store_true", help="tiny run for CI (0.5 s per row, 32 native envs)")
    ap.add_argument("--json", metavar="PATH", help="also write the native-env ratios table as JSON")
    ap.add_argument("--compare", metavar="REF", help="old (commit REF) against new (working tree), interleaved")
    ap.add_argument("--rounds", type=int, default=2, help="interleaved rounds of --compare")
    args = ap.parse_args(argv)
    if args.quick:
        args.seconds, args.native, args.dummy, args.no_classic = 0.5, 32, 4, True
    # --quick (CI) on one thread unless told otherwise: the 2-thread step kernel's first compile (~35 s of CPU) is
    # left to the slow test that checks its trajectories against one thread's (tests/gym/test_vector.py)
    args.threads = args.threads or ((1,) if args.quick else (1, 2))
    if args.compare:
        compare_with(args, repo)
        return
    console = Console(width=150)
    cores = os.cpu_count()
    load0 = load_average()
    console.print(f"load average (1 min) at start: {load0:.2f} on {cores} cores")
    native = run_native_benchmark(args.seconds, args.native, args.dummy, threads=args.threads)
    print_table(console, native.assign(load_1min=native.load_1min.map("{:.2f}".format)),
                f"native vector env ({cores} cores, load average {load0:.1f} at start)", "{:,.0f}")
    ratios = native_ratios(native)
    rates = ["native_steps_per_s", "native_steps_per_cpu_s"]
    print_table(console, ratios.assign(**{c: ratios[c].map("{:,.0f}".format) for c in rates}),
                "native env against the bare batched physics with the same threads and against DummyVecEnv", "{:.2f}")
    if args.json:
        Path(args.json).write_text(json.dumps({"load_1min_start": load0, "ratios": ratios.to_dict("records"),
                                               "table": native.to_dict("records")}))
    best = ratios.loc[ratios.native_steps_per_s.idxmax()]
    mark = "met" if best.native_steps_per_s >= TARGET_STEPS_PER_S else "missed"
    console.print(f"best native wall rate: {best.native_steps_per_s:,.0f} steps/s with {int(best.threads)} "
                  f"thread(s) at N = {args.native} (target >= {TARGET_STEPS_PER_S:,}: {mark}); native / bare "
                  f"{best.native_over_bare_wall:.2f} (wall), native / DummyVecEnv {best.native_over_dummy_cpu:.1f}x "
                  f"(per CPU second); load average at the end {load_average():.2f}; OMP_WAIT_POLICY "
                  f"{openmp_wait_policy()}")
    if not args.no_classic:
        load = load_average()
        table = run_benchmark(args.seconds, args.n_envs, not args.no_highway)
        print_table(console, table.drop(columns=["episodes"]),
                    f"environment steps per second ({cores} cores, load average {load:.1f})", "{:.1f}")
        console.print(f"EcoDrive-v0 / highway-fast-v0 single-process steps/s: {speed_ratio(table):.0f}x")


if __name__ == "__main__":
    main()
