"""Speed of ``roadload/EcoTraffic-v0`` against highway-env in the same run.

Rows, interleaved over ``rounds`` (reference, native with each thread count, reference, ...: every pair sees the
same machine load):

- reference: ``roadload/EcoHighway-v0`` on highway-env with EcoTraffic-v0's scenario and step (the same lanes,
  traffic, frequencies and ego powertrain: roadload.gym.traffic_reference.highway_config), one process, one env;
- highway-env's own ``highway-fast-v0`` (its fast configuration: 5 Hz traffic, 1 s steps), for scale, compared by
  simulated seconds per wall second;
- native: ``gymnasium.make_vec("roadload/EcoTraffic-v0", num_envs=N, vectorization_mode="vector_entry_point",
  threads=k)``.

Every row steps random actions in [-1, 1] and includes its autoresets; rates are env steps per wall second and per
CPU second of this process (the machine is shared: the CPU rate is what the code costs, the wall rate what the
scheduler gave), with the 1-minute load average as the row started. The ratio native / reference is per round
(same load) and its median is reported. Command line: :func:`main` (``scripts/bench_traffic.py``).

    python scripts/bench_traffic.py                       # N = 256, threads 1 and 2, 2 rounds of 5 s per row
    python scripts/bench_traffic.py --vehicles 10 --threads 2 --rounds 3
    python scripts/bench_traffic.py --quick               # CI smoke run (N = 16, 0.5 s per row, one round)
    python scripts/bench_traffic.py --compare main --rounds 4   # native rows of commit main against the working tree
    python scripts/bench_traffic.py --compare main --bursts 60  # the same in 60 paired short bursts (busy machine)

``--compare REF`` runs the native rows alone (``--native-only``) on commit REF (exported, refcompare) and on the
working tree, in alternating child processes, and reports the per-round ratio new / old of env steps per CPU second
(robust to the machine's load) and per wall second. This file runs against an old package tree too: it imports from
roadload only what every commit with EcoTraffic-v0 has.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any, Callable, cast

import gymnasium as gym
import numpy as np
import pandas as pd

from roadload.gym.config import EcoTrafficConfig, make_config
from roadload.gym.traffic import EcoTrafficVectorEnv

from roadload.experiments.rl.benchmark import call_rates, load_average, random_action_stepper

TARGET_STEPS_PER_S = 100_000
"""Native env steps per wall second at N = 256 with 2 threads (10+ traffic vehicles per env)."""
TARGET_RATIO = 1000.0
"""Goal of the native / highway-env ratio."""


def _reference_env(cfg: EcoTrafficConfig):
    from roadload.gym.highway import EcoHighwayEnv
    from roadload.gym.traffic_reference import highway_config

    return EcoHighwayEnv(highway_config(cfg))


def _highway_fast_env():
    import gymnasium as gym
    import highway_env

    gym.register_envs(highway_env)
    return gym.make("highway-fast-v0")


def _native_stepper(cfg: EcoTrafficConfig, n_envs: int, threads: int, seed: int) -> Callable[[], None]:
    venv = EcoTrafficVectorEnv(n_envs, config=cfg, threads=threads)
    venv.reset(seed=seed)
    d = cast(gym.spaces.Box, venv.single_action_space).shape[0]
    acts = np.random.default_rng(seed).uniform(-1, 1, (256, n_envs, d)).astype(np.float32)
    k = [0]

    def step() -> None:
        venv.step(acts[k[0] % 256])
        k[0] += 1
    for _ in range(3):  # warm-up: kernels loaded, first allocations
        step()
    return step


def run_traffic_benchmark(seconds: float = 5.0, n_envs: int = 256, threads: tuple[int, ...] = (1, 2),
                          rounds: int = 2, env_config: dict[str, Any] | None = None, highway_fast: bool = True,
                          progress: Callable[[str], None] | None = None, reference: bool = True,
                          variant: dict[str, Any] | None = None) -> pd.DataFrame:
    """The interleaved rows (module docstring): env, mode, round, threads, steps/s (wall, CPU), simulated
    seconds per wall second, load average (``reference`` False: no EcoHighway-v0 rows; ``variant``: native rows
    of the configuration with these fields too, each right after the default's)."""
    cfg = make_config(EcoTrafficConfig, {"curvature": False, **(env_config or {})})
    step_time = 1.0 / cfg.policy_frequency
    ref = random_action_stepper(_reference_env(cfg)) if reference else None
    natives = {t: _native_stepper(cfg, n_envs, t, 0) for t in threads}
    varied = make_config(EcoTrafficConfig, {**cfg.model_dump(), **variant}) if variant else None
    variants = {t: _native_stepper(varied, n_envs, t, 0) for t in threads} if varied else {}
    fast = random_action_stepper(_highway_fast_env()) if highway_fast else None
    for warm in (ref, fast):  # the first steps compile (the reference's ego kernels on a cold cache): not timed
        if warm is not None:
            for _ in range(3):
                warm()
    rows = []

    def add(env: str, mode: str, rnd: int, t: int, per_call: int, sim_step: float, fn: Callable[[], None]) -> None:
        load = load_average()
        wall, cpu, n = call_rates(fn, seconds)
        rows.append({"env": env, "mode": mode, "round": rnd, "threads": t, "steps_per_s": wall * per_call,
                     "steps_per_cpu_s": cpu * per_call, "simulated_s_per_wall_s": wall * per_call * sim_step,
                     "steps": n * per_call, "load_1min": load})
        if progress:
            progress(f"round {rnd}: {env} {mode}")

    for rnd in range(rounds):
        if ref is not None:
            add("EcoHighway-v0 (highway-env)", "single process", rnd, 1, 1, step_time, ref)
        for t, fn in natives.items():
            add("EcoTraffic-v0 (native)", f"vector x{n_envs}", rnd, t, n_envs, step_time, fn)
            if t in variants:
                add("EcoTraffic-v0 (native, --config)", f"vector x{n_envs}", rnd, t, n_envs, step_time, variants[t])
        if fast is not None:
            add("highway-fast-v0 (highway-env)", "single process", rnd, 1, 1, 1.0, fast)
    return pd.DataFrame(rows)


def traffic_ratios(table: pd.DataFrame) -> pd.DataFrame:
    """Per thread count: the native rate (median over rounds, wall and CPU), the per-round ratio native /
    EcoHighway-v0 (median, min, max; wall and CPU), the ratio to highway-fast-v0 in simulated seconds per wall
    second, and the load."""
    out = []
    ref = table[table.env.str.startswith("EcoHighway")].set_index("round")
    fast = table[table.env.str.startswith("highway-fast")].set_index("round")
    native = table[table.env.str.startswith("EcoTraffic")]
    for t, grp in native.groupby("threads"):
        g = grp.set_index("round")
        wall = g.steps_per_s / ref.steps_per_s.reindex(g.index)
        cpu = g.steps_per_cpu_s / ref.steps_per_cpu_s.reindex(g.index)
        row = {"threads": int(t), "native_steps_per_s": float(g.steps_per_s.median()),
               "native_steps_per_cpu_s": float(g.steps_per_cpu_s.median()),
               "reference_steps_per_s": float(ref.steps_per_s.median()),
               "ratio_wall": float(wall.median()), "ratio_wall_min": float(wall.min()),
               "ratio_wall_max": float(wall.max()), "ratio_cpu": float(cpu.median()),
               "load_1min": float(g.load_1min.median())}
        if len(fast):
            sim = g.simulated_s_per_wall_s / fast.simulated_s_per_wall_s.reindex(g.index)
            row["ratio_highway_fast_simulated_s"] = float(sim.median())
        out.append(row)
    return pd.DataFrame(out)


def variant_ratios(table: pd.DataFrame) -> pd.DataFrame:
    """Per thread count: the per-round ratio of the ``--config`` variant's rate to the default's, each pair
    measured back to back (median, min, max; per CPU second and per wall second)."""
    out = []
    base = table[table.env == "EcoTraffic-v0 (native)"]
    var = table[table.env == "EcoTraffic-v0 (native, --config)"]
    for t, grp in var.groupby("threads"):
        g = grp.set_index("round")
        b = base[base.threads == t].set_index("round").reindex(g.index)
        cpu = g.steps_per_cpu_s / b.steps_per_cpu_s
        wall = g.steps_per_s / b.steps_per_s
        out.append({"threads": int(t), "default_steps_per_s": float(b.steps_per_s.median()),
                    "config_steps_per_s": float(g.steps_per_s.median()), "ratio_cpu": float(cpu.median()),
                    "ratio_cpu_min": float(cpu.min()), "ratio_cpu_max": float(cpu.max()),
                    "ratio_wall": float(wall.median()), "load_1min": float(g.load_1min.median())})
    return pd.DataFrame(out)


def summary_line(ratios: pd.DataFrame, n_envs: int, vehicles: int) -> str:
    best = ratios.loc[ratios.native_steps_per_s.idxmax()]
    met = "met" if best.native_steps_per_s >= TARGET_STEPS_PER_S else "missed"
    goal = "met" if best.ratio_wall >= TARGET_RATIO else "missed"
    two = ratios[ratios.threads == 2]
    two_text = (f"; 2 threads: {float(two.native_steps_per_s.iloc[0]):,.0f} steps/s wall, "
                f"{float(two.native_steps_per_cpu_s.iloc[0]):,.0f} per CPU second" if len(two) else "")
    return (f"best native rate {best.native_steps_per_s:,.0f} env steps/s with {int(best.threads)} thread(s) at "
            f"N = {n_envs}, {vehicles} traffic vehicles per env (target >= {TARGET_STEPS_PER_S:,}: {met}){two_text}; "
            f"native / EcoHighway-v0 (same scenario and step) {best.ratio_wall:,.0f}x wall (per-round range "
            f"{best.ratio_wall_min:,.0f}-{best.ratio_wall_max:,.0f}), {best.ratio_cpu:,.0f}x per CPU second "
            f"(goal >= {TARGET_RATIO:,.0f}x: {goal}); load average {statistics.median(ratios.load_1min):.1f}")


def compare_rounds(old: list[dict], new: list[dict]) -> pd.DataFrame:
    """Per thread count: the native rates of the old and the new tree (median over the runs), the median and range
    of the per-run ratio new / old (runs paired in the order they ran), per CPU second and per wall second, and the
    load average over the runs."""
    def rates(runs: list[dict], t: int, key: str) -> list[float]:
        return [statistics.median(r[key] for r in run["rows"] if r["threads"] == t) for run in runs]
    threads = sorted({int(r["threads"]) for run in new for r in run["rows"]})
    out = []
    for t in threads:
        row: dict[str, Any] = {"threads": t}
        for key, name in (("steps_per_cpu_s", "cpu"), ("steps_per_s", "wall")):
            o, n = rates(old, t, key), rates(new, t, key)
            ratio = [b / a for a, b in zip(o, n)]
            row.update({f"old_per_{name}_s": statistics.median(o), f"new_per_{name}_s": statistics.median(n),
                        f"new_over_old_{name}": statistics.median(ratio),
                        f"range_{name}": f"{min(ratio):.3f}-{max(ratio):.3f}"})
        loads = [r["load_1min"] for run in old + new for r in run["rows"] if r["threads"] == t]
        row["load_1min"] = statistics.median(loads)
        out.append(row)
    return pd.DataFrame(out)


def compare_with(args: argparse.Namespace, repo: Path | None = None) -> pd.DataFrame:
    """--compare: the native rows of commit ``args.compare`` and of the working tree, ``args.rounds`` interleaved
    child runs each (roadload.experiments.benchmarks.refcompare)."""
    # imported here, not at the top: this file also runs against old package trees
    from roadload.experiments.benchmarks.refcompare import REPO, compare

    bench = ["--native-only", "--seconds", str(args.seconds), "--n-envs", str(args.n_envs), "--threads",
             args.threads, "--rounds", "1", "--vehicles", str(args.vehicles)]
    old, new = compare(Path(__file__).resolve(), bench, args.compare, args.rounds, repo or REPO)
    return compare_rounds(old, new)



def burst_worker(n_envs: int, threads: int, vehicles: int) -> None:
    """--burst-worker: a native vector env (as the rows') that steps the number of batch steps each line of stdin
    asks for and answers with a JSON line of env steps per CPU second and per wall second (compare_bursts)."""
    cfg = make_config(EcoTrafficConfig, {"curvature": False, "vehicles_count": vehicles})
    step = _native_stepper(cfg, n_envs, threads, 0)
    print("ready", flush=True)
    for line in sys.stdin:
        n = int(line)
        w0, c0 = time.perf_counter(), time.process_time()
        for _ in range(n):
            step()
        cpu, wall = time.process_time() - c0, time.perf_counter() - w0
        print(json.dumps({"cpu": n * n_envs / max(cpu, 1e-9), "wall": n * n_envs / wall}), flush=True)


def compare_bursts(args: argparse.Namespace, repo: Path | None = None) -> pd.DataFrame:
    """--compare REF --bursts K: per thread count, two persistent child processes (commit REF exported, and the
    working tree) step ``args.burst_steps`` batch steps in turn, K pairs (the first of a pair alternating), so that
    each pair sees the same load within a second; the median and quartiles of the per-pair ratios new / old per
    CPU second and per wall second. Robust to a busy machine, where whole child runs scatter by +-30 %."""
    # imported here, not at the top: this file also runs against old package trees
    from roadload.experiments.benchmarks.refcompare import _RUN_FILE, REPO, export_commit

    out = []
    with tempfile.TemporaryDirectory(prefix="roadload-ref-") as tmp:
        pkg = export_commit(args.compare, Path(tmp), repo or REPO)
        for t in (int(x) for x in args.threads.split(",")):
            children = [_burst_child(str(pkg), t, args, _RUN_FILE), _burst_child(None, t, args, _RUN_FILE)]
            pairs = []
            loads = []
            for k in range(args.bursts):
                order = (0, 1) if k % 2 == 0 else (1, 0)
                got = {i: _burst(children[i], args.burst_steps) for i in order}
                pairs.append((got[0], got[1]))
                loads.append(load_average())
            for child in children:
                cast(Any, child.stdin).close()
                child.wait()
            row: dict[str, Any] = {"threads": t, "pairs": len(pairs)}
            for key in ("cpu", "wall"):
                ratio = sorted(new[key] / old[key] for old, new in pairs)
                q = statistics.quantiles(ratio, n=4) if len(ratio) > 1 else [ratio[0]] * 3
                row.update({f"old_per_{key}_s": statistics.median(o[key] for o, _ in pairs),
                            f"new_per_{key}_s": statistics.median(n[key] for _, n in pairs),
                            f"new_over_old_{key}": q[1], f"quartiles_{key}": f"{q[0]:.3f}-{q[2]:.3f}"})
            row["load_1min"] = statistics.median(loads)
            out.append(row)
    return pd.DataFrame(out)


def _burst_child(pythonpath: str | None, threads: int, args: argparse.Namespace, code: str) -> subprocess.Popen:
    """A burst worker of this file on the package under ``pythonpath`` (None: the installed one), ready."""
    env = dict(os.environ)
    env.pop("PYTHONPATH", None)
    if pythonpath:
        env["PYTHONPATH"] = pythonpath
    cmd = [sys.executable, "-c", code, str(Path(__file__).resolve()), "--burst-worker", "--threads", str(threads),
           "--n-envs", str(args.n_envs), "--vehicles", str(args.vehicles)]
    child = subprocess.Popen(cmd, stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True, env=env,
                             cwd=tempfile.gettempdir())
    if cast(Any, child.stdout).readline().strip() != "ready":
        raise RuntimeError(f"burst worker on {pythonpath or 'the working tree'} did not start")
    return child


def _burst(child: subprocess.Popen, steps: int) -> dict[str, float]:
    cast(Any, child.stdin).write(f"{steps}\n")
    cast(Any, child.stdin).flush()
    return json.loads(cast(Any, child.stdout).readline())


__all__ = ["run_traffic_benchmark", "traffic_ratios", "summary_line", "compare_rounds", "compare_with",
           "compare_bursts", "burst_worker", "main",
           "TARGET_STEPS_PER_S", "TARGET_RATIO"]


def _variant_config(ap: argparse.ArgumentParser, a: argparse.Namespace) -> dict[str, Any] | None:
    """The ``--config`` fields (checked against EcoTrafficConfig), or None."""
    if not a.config:
        return None
    if not a.native_only:
        ap.error("--config: only with --native-only (the variant's rows are native)")
    try:
        variant = json.loads(a.config)
    except json.JSONDecodeError as exc:
        ap.error(f"--config: expected a JSON object, got {a.config!r} ({exc})")
    if not isinstance(variant, dict):
        ap.error(f"--config: expected a JSON object, got {a.config!r}")
    try:
        make_config(EcoTrafficConfig, variant)  # a bad field fails before any row, naming it
    except ValueError as exc:
        ap.error(f"--config: {exc}")
    return variant


def main(argv: list[str] | None = None) -> None:
    """Run the benchmark and print its tables (``scripts/bench_traffic.py``; module docstring)."""
    from rich.console import Console

    from roadload.experiments.rl.command import print_table

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seconds", type=float, default=5.0, help="measurement time per row [s]")
    ap.add_argument("--n-envs", type=int, default=256, help="sub-envs of the native vector env")
    ap.add_argument("--threads", default=None, help="numba thread counts, comma-separated (default 1,2; with "
                                                    "--quick 1)")
    ap.add_argument("--rounds", type=int, default=2, help="interleaved rounds")
    ap.add_argument("--vehicles", type=int, default=20, help="traffic vehicles per env")
    ap.add_argument("--no-highway-fast", action="store_true", help="skip highway-env's highway-fast-v0 rows")
    ap.add_argument("--json", metavar="PATH", help="also write the rows and ratios as JSON")
    ap.add_argument("--native-only", action="store_true", help="only the native rows (no highway-env, no ratios)")
    ap.add_argument("--config", default=None, help="with --native-only: native rows of the config with these "
                                                   "EcoTraffic-v0 fields too (JSON text), paired with the default's "
                                                   "per round, e.g. '{\"kinematics_rows\": 10}'")
    ap.add_argument("--compare", metavar="REF", help="native rows of commit REF (old) against the working tree "
                                                     "(new), --rounds interleaved child runs each")
    ap.add_argument("--bursts", type=int, default=0, metavar="K", help="with --compare: K pairs of short bursts of "
                                                                       "two persistent processes instead of child runs")
    ap.add_argument("--burst-steps", type=int, default=150, help="batch steps per burst (--bursts)")
    ap.add_argument("--burst-worker", action="store_true", help=argparse.SUPPRESS)
    ap.add_argument("--quick", action="store_true", help="tiny run for CI")
    a = ap.parse_args(argv)
    if a.burst_worker:
        burst_worker(a.n_envs, int(a.threads), a.vehicles)
        return
    # --quick (CI) on one thread unless told otherwise: the 2-thread step kernel's first compile (~35 s of CPU) is
    # left to the slow test that checks its traffic against one thread's (tests/gym/test_traffic.py)
    a.threads = a.threads or ("1" if a.quick else "1,2")
    try:
        threads = tuple(int(t) for t in a.threads.split(",") if t.strip())
    except ValueError:
        ap.error(f"--threads: expected comma-separated integers >= 1, got {a.threads!r}")
    if not threads or min(threads) < 1 or a.n_envs < 1 or a.rounds < 1 or a.seconds <= 0:
        ap.error("--threads, --n-envs and --rounds must be >= 1 and --seconds > 0")
    if a.quick:
        a.seconds, a.n_envs, a.rounds = 0.5, 16, 1
    console = Console(width=160)
    console.print(f"load average (1 min) at start: {load_average():.2f} on {os.cpu_count()} cores")
    if a.compare and a.bursts > 0:
        ratios = compare_bursts(a)
        print_table(console, ratios, f"EcoTraffic-v0 native x{a.n_envs}, {a.vehicles} vehicles: {a.compare} (old) "
                                     f"against the working tree (new), {a.bursts} paired bursts of {a.burst_steps} "
                                     f"batch steps", "{:,.3f}")
        return
    if a.compare:
        ratios = compare_with(a)
        print_table(console, ratios, f"EcoTraffic-v0 native x{a.n_envs}, {a.vehicles} vehicles: {a.compare} (old) "
                                     f"against the working tree (new), {a.rounds} interleaved runs", "{:,.3f}")
        return
    variant = _variant_config(ap, a)
    table = run_traffic_benchmark(a.seconds, a.n_envs, threads, a.rounds, {"vehicles_count": a.vehicles},
                                  highway_fast=not (a.no_highway_fast or a.native_only),
                                  progress=lambda m: console.print(m), reference=not a.native_only, variant=variant)
    print_table(console, table, "env steps per second (interleaved rounds)", "{:,.1f}")
    if variant:
        print_table(console, variant_ratios(table), f"--config {a.config} against the default, paired per round",
                    "{:,.3f}")
    if a.native_only:
        if a.json:
            Path(a.json).write_text(json.dumps({"rows": table.to_dict("records"), "ratios": []}, indent=1))
        return
    ratios = traffic_ratios(table)
    print_table(console, ratios, "EcoTraffic-v0 native against EcoHighway-v0 (highway-env), same run", "{:,.1f}")
    console.print(summary_line(ratios, a.n_envs, a.vehicles))
    if a.json:
        Path(a.json).write_text(json.dumps({"rows": table.to_dict("records"), "ratios": ratios.to_dict("records")},
                                           indent=1))


if __name__ == "__main__":
    main()
