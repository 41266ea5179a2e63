"""Speed and findings of the chapter-5 fleet benchmark.

Generates the simulated fleet into a cache folder when absent (generation is timed separately and may take
longer), then runs the whole benchmark (>= 80 trips x 11 model-estimator combinations x 5 horizons) from the
stored trips and prints the time split (loading, preprocessing, estimation, evaluation; summed over workers),
the wall-clock time, the k = 900 MEDSE table and the findings of the text.

    python scripts/bench_fleet.py [--trips 84] [--workers 2] [--scheduler ADDR] [--cache DIR] [--out DIR]
"""

from __future__ import annotations

import argparse
import tempfile
import os
import time
from pathlib import Path

from roadload.experiments.fleet import (check_findings, generate_fleet, run_benchmark, stored_trips,
                                       write_report)


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--trips", type=int, default=84)
    ap.add_argument("--seed", type=int, default=2012)
    ap.add_argument("--hours", type=float, default=20.0)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--scheduler", default=None)
    ap.add_argument("--cache", type=Path, default=None)
    ap.add_argument("--out", type=Path, default=Path("out/bench_fleet"))
    ap.add_argument("--output-outliers", default=None, metavar="RATE,SIZE",
                    help="sensitivity experiment: outlier events of SIZE N (1 s bursts) starting with probability "
                         "RATE per triggered sample, added to F_xV after preprocessing (not part of the simulator)")
    ap.add_argument("--quick", action="store_true", help="tiny run for CI: 3 trips, 0.3 h, in a temporary cache")
    args = ap.parse_args(argv)
    if args.quick:
        args.trips, args.hours, args.workers = 3, 8.4, 1
        args.cache = args.cache or Path(tempfile.mkdtemp(prefix="roadload-fleet-"))
        args.out = args.cache / "report"
    extra = {}
    if args.output_outliers:
        rate, size = (float(x) for x in args.output_outliers.split(","))
        extra["output_outliers"] = (rate, size)
    base = Path(os.environ.get("ROADLOAD_CACHE", Path.home() / ".cache" / "roadload"))
    folder = args.cache or base / f"fleet-{args.seed}-{args.trips}"
    hours = args.hours * args.trips / 84
    t0 = time.perf_counter()  # stored trips are checked and kept; missing, corrupt or foreign ones simulated
    gen = generate_fleet(folder, args.trips, args.seed, hours, scheduler=args.scheduler, workers=args.workers)
    print(f"fleet generation: {len(gen['trips'])} trips in {time.perf_counter() - t0:.1f} s "
          f"({len(gen['failed'])} failed, {len(gen['rebuilt'])} corrupt or foreign files simulated again)")
    paths = stored_trips(folder, args.trips)
    print(f"load average before the run: {os.getloadavg()[0]:.2f} on {os.cpu_count()} cores")
    res = run_benchmark(paths, scheduler=args.scheduler, workers=args.workers, progress=False,
                        checkpoint=args.out / "units", **extra)
    t = res.timing
    hours_done = res.trips["duration"].sum() / 3600 if not res.trips.empty else 0.0
    n_rows = len(res.medse)
    print(f"benchmark: {len(res.trips)} trips ({hours_done:.1f} h), {res.medse['combination'].nunique()} "
          f"combinations x {res.medse['horizon'].nunique()} horizons = {n_rows} MEDSE values, "
          f"{len(res.failed)} failed trips")
    print(f"wall clock: {t['wall']:.1f} s with {args.workers if args.scheduler is None else 'dask'} workers")
    print("time split (summed over workers) [s]: " + ", ".join(
        f"{k} {t[k]:.1f}" for k in ("loading", "preprocessing", "estimation", "evaluation")))
    report = write_report(res, args.out, title=f"chapter-5 benchmark, fleet seed {args.seed}, {len(paths)} trips")
    print(res.medse_table(900).to_string(index=False, float_format=lambda x: f"{x:.4g}"))
    for f in check_findings(res):
        verdict = {True: "reproduced", False: "NOT reproduced", None: "undecided"}[f["reproduced"]]
        print(f"- {f['finding']}: {verdict}. {f['evidence']}")
    print(f"report: {report}")
