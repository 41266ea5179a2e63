"""Environment steps per second (one EcoDrive-v0 step = 0.1 s of driving, 10 physics steps at 100 Hz):
EcoDrive-v0 single process (state and can observations), vectorised on n cores (SB3 DummyVecEnv and
SubprocVecEnv), EcoHighway-v0, and highway-env's highway-fast-v0 measured in the same run; prints the table and the
EcoDrive / highway-fast ratio. Random actions, resets included.

    python scripts/bench_gym.py [--seconds 5] [--n-envs 2]      # = roadload benchmark gym
"""

import argparse
import os

from rich.console import Console

from roadload.experiments.rl import print_table, run_benchmark, speed_ratio

if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=5.0, help="measurement time per row [s]")
    ap.add_argument("--n-envs", type=int, default=2, help="vectorised environments")
    ap.add_argument("--no-highway", action="store_true", help="skip EcoHighway-v0 and highway-fast-v0")
    args = ap.parse_args()
    console = Console(width=150)
    table = run_benchmark(args.seconds, args.n_envs, not args.no_highway)
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    print_table(console, table.drop(columns=["episodes"]),
                f"environment steps per second ({os.cpu_count()} cores, load average {load:.1f})", "{:.1f}")
    console.print(f"EcoDrive-v0 / highway-fast-v0 single-process steps/s: {speed_ratio(table):.0f}x")
