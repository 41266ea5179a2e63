"""Environment steps per second (one EcoDrive-v0 step = 0.1 s of driving, 10 physics steps at 100 Hz).

Table 1 (all in the same run): EcoDrive-v0 single process, SB3 DummyVecEnv, the native batched vector env
(``gymnasium.make_vec(..., vectorization_mode="vector_entry_point")``, 1 and 2 numba threads) and its bare batched
physics (the reference it is compared with), as wall-clock and per-CPU-second rates (the machine is shared: the
CPU rate is what the code costs, the wall rate what the scheduler gave us). Table 2 (unless --no-classic):
single / can observation / DummyVecEnv / SubprocVecEnv x n, EcoHighway-v0 and highway-env's highway-fast-v0.
Random actions in [-1, 1], resets included.

    python scripts/bench_gym.py [--seconds 5] [--native 256] [--n-envs 2]     # full
    python scripts/bench_gym.py --quick                                       # CI smoke run (< 60 s)
"""

import argparse
import os

from rich.console import Console

from roadload.experiments.rl import print_table, run_benchmark, run_native_benchmark, speed_ratio

if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=5.0, help="measurement time per row [s]")
    ap.add_argument("--native", type=int, default=256, help="sub-envs of the native vector env")
    ap.add_argument("--dummy", type=int, default=16, help="sub-envs of the DummyVecEnv reference")
    ap.add_argument("--n-envs", type=int, default=2, help="vectorised environments of the classic table")
    ap.add_argument("--no-highway", action="store_true", help="skip EcoHighway-v0 and highway-fast-v0")
    ap.add_argument("--no-classic", action="store_true", help="only the native-vector-env table")
    ap.add_argument("--quick", action="store_true", help="tiny run for CI (0.5 s per row, 32 native envs)")
    args = ap.parse_args()
    if args.quick:
        args.seconds, args.native, args.dummy, args.no_classic = 0.5, 32, 4, True
    console = Console(width=150)
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    native = run_native_benchmark(args.seconds, args.native, args.dummy)
    print_table(console, native, f"native vector env ({os.cpu_count()} cores, load average {load:.1f})", "{:.0f}")
    by = native.set_index("mode")
    env1 = by.filter(like="native vector env", axis=0).iloc[0]
    bare = by.filter(like="bare batched", axis=0).iloc[0]
    dummy = by.filter(like="dummy", axis=0).iloc[0]
    best_wall = by.filter(like="native vector env", axis=0).steps_per_s.max()
    console.print(f"native (1 thread) / bare physics, per CPU second: {env1.steps_per_cpu_s / bare.steps_per_cpu_s:.2f}"
                  f"; native / DummyVecEnv per CPU second: {env1.steps_per_cpu_s / dummy.steps_per_cpu_s:.1f}x; "
                  f"best native wall rate {best_wall:.0f} steps/s")
    if not args.no_classic:
        table = run_benchmark(args.seconds, args.n_envs, not args.no_highway)
        print_table(console, table.drop(columns=["episodes"]),
                    f"environment steps per second ({os.cpu_count()} cores, load average {load:.1f})", "{:.1f}")
        console.print(f"EcoDrive-v0 / highway-fast-v0 single-process steps/s: {speed_ratio(table):.0f}x")
