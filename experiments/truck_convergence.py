"""Online M4-RRLM estimate vs distance on the trucks: how long a warm-up the online MPC needs.

Usage: python scripts/truck_convergence.py --out DIR [--seeds 3] [--length 16000] [--workers 2]
       python scripts/truck_convergence.py --quick   (15 t and 40 t, 1 seed, 3 km)
Writes DIR/convergence.csv (median relative error per distance), convergence.png and runs.json.
"""

import argparse
import json
import os
import sys
import time
from pathlib import Path

from roadload.experiments.headline import convergence_figure, convergence_run, convergence_table
from roadload.fileio import write_text
from roadload.sweep import run_sweep
from roadload.tables import markdown_table


def _run(args: tuple[str, int, float]) -> dict:
    return convergence_run(*args)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=Path("truck_convergence"))
    ap.add_argument("--seeds", type=int, default=3)
    ap.add_argument("--length", type=float, default=16000.0, help="road length [m]")
    ap.add_argument("--cases", default="truck_15t,truck_25t,truck_40t")
    ap.add_argument("--workers", type=int, default=None)
    ap.add_argument("--quick", action="store_true")
    a = ap.parse_args(argv)
    if a.quick:
        a.seeds, a.length, a.cases = 1, 3000.0, "truck_15t,truck_40t"
    if a.seeds < 1 or not a.length > 1000.0:
        sys.exit(f"--seeds >= 1 and --length > 1000 m, got {a.seeds} and {a.length} m")
    t0 = time.perf_counter()
    tasks = [(c.strip(), s, a.length) for c in a.cases.split(",") for s in range(a.seeds)]
    outcomes = run_sweep(_run, tasks, workers=a.workers, description="convergence")
    runs = [o.value for o in outcomes if o.ok]
    for o in outcomes:
        if not o.ok:
            print(f"failed {o.task}: {o.error}", file=sys.stderr)
    if not runs:
        return 1
    a.out.mkdir(parents=True, exist_ok=True)
    table = convergence_table(runs)
    write_text(a.out / "runs.json", json.dumps(runs))
    write_text(a.out / "convergence.csv", table.to_csv(index=False))
    convergence_figure(runs, a.out / "convergence.png")
    print(markdown_table(table.round(2)))
    print(f"wall {time.perf_counter() - t0:.0f} s, load average {os.getloadavg()[0]:.2f}; wrote {a.out}")
    return 0
