"""Env steps per second of roadload/EcoTraffic-v0 (native, compiled, batched) against highway-env in the same run
(roadload.experiments.rl.traffic_bench: interleaved rounds, wall and CPU rates, load average per row).

    python scripts/bench_traffic.py                       # N = 256, threads 1 and 2, 2 rounds of 5 s per row
    python scripts/bench_traffic.py --vehicles 10 --threads 2 --rounds 3
    python scripts/bench_traffic.py --quick               # CI smoke run (N = 16, 0.5 s per row, one round)
"""

import os

# libgomp reads OMP_WAIT_POLICY once, when it is loaded (numba's thread pool, or torch): set before any import
os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")

import argparse  # noqa: E402
import json  # noqa: E402
from pathlib import Path  # noqa: E402

from rich.console import Console  # noqa: E402

from roadload.experiments.rl.command import print_table  # noqa: E402
from roadload.experiments.rl.traffic_bench import (run_traffic_benchmark, summary_line,  # noqa: E402
                                                   traffic_ratios)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=5.0, help="measurement time per row [s]")
    ap.add_argument("--n-envs", type=int, default=256, help="sub-envs of the native vector env")
    ap.add_argument("--threads", default="1,2", help="numba thread counts, comma-separated")
    ap.add_argument("--rounds", type=int, default=2, help="interleaved rounds")
    ap.add_argument("--vehicles", type=int, default=20, help="traffic vehicles per env")
    ap.add_argument("--no-highway-fast", action="store_true", help="skip highway-env's highway-fast-v0 rows")
    ap.add_argument("--json", metavar="PATH", help="also write the rows and ratios as JSON")
    ap.add_argument("--quick", action="store_true", help="tiny run for CI")
    a = ap.parse_args()
    try:
        threads = tuple(int(t) for t in a.threads.split(",") if t.strip())
    except ValueError:
        ap.error(f"--threads: expected comma-separated integers >= 1, got {a.threads!r}")
    if not threads or min(threads) < 1 or a.n_envs < 1 or a.rounds < 1 or a.seconds <= 0:
        ap.error("--threads, --n-envs and --rounds must be >= 1 and --seconds > 0")
    if a.quick:
        a.seconds, a.n_envs, a.rounds = 0.5, 16, 1
    console = Console(width=160)
    console.print(f"load average (1 min) at start: {os.getloadavg()[0]:.2f} on {os.cpu_count()} cores")
    table = run_traffic_benchmark(a.seconds, a.n_envs, threads, a.rounds, {"vehicles_count": a.vehicles},
                                  highway_fast=not a.no_highway_fast, progress=lambda m: console.print(m))
    print_table(console, table, "env steps per second (interleaved rounds)", "{:,.1f}")
    ratios = traffic_ratios(table)
    print_table(console, ratios, "EcoTraffic-v0 native against EcoHighway-v0 (highway-env), same run", "{:,.1f}")
    console.print(summary_line(ratios, a.n_envs, a.vehicles))
    if a.json:
        Path(a.json).write_text(json.dumps({"rows": table.to_dict("records"), "ratios": ratios.to_dict("records")},
                                           indent=1))


if __name__ == "__main__":
    main()
