"""Diagnose the bmw_i3 preset against the real BMW i3 trips (TUM, ../shared/data/bmw_i3_tum): where the gap lies,
which effects explain it, how far it shrinks. Writes report.md, diagnosis.json and figures.

    python scripts/sim2real_i3.py [--trips TripA01,TripB01,...] [--out out/sim2real_i3]
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np
import pandas as pd

from roadload.data import require_shared_data
from roadload.io import import_log
from roadload.sim2real.diagnose import DiagnosisSettings, diagnose
from roadload.sim2real.report import write_report
from roadload.sim2real.simconfig import SimConfig


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--trips", default="", help="comma-separated trip names (default: all)")
    ap.add_argument("--out", default="out/sim2real_i3")
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args()
    folder = require_shared_data("bmw_i3_tum") / "data"
    files = sorted(folder.glob("Trip*.csv"))
    if args.trips:
        want = {t.strip() for t in args.trips.split(",")}
        files = [f for f in files if f.stem in want]
    t0 = time.perf_counter()
    trips, skipped = [], []
    for f in files:
        try:
            trips.append(import_log(f, "bmw-i3"))
        except ValueError as exc:
            skipped.append(f"{f.stem}: {exc}")
    print(f"loaded {len(trips)} trips in {time.perf_counter() - t0:.0f} s; skipped {skipped or 'none'}")
    sim = SimConfig.load("bmw_i3")
    diag = diagnose(trips, sim, DiagnosisSettings(seed=args.seed),
                    progress=lambda what, frac: print(f"  [{time.perf_counter() - t0:5.0f} s] {what}"))
    paths = write_report(diag, Path(args.out))
    fb, fa = diag.gap_before["force_residual"], diag.gap_after["force_residual"]
    print(f"held-out force residual: median {fb['median']:.0f} -> {fa['median']:.0f} N, RMSE {fb['rmse']:.0f} -> "
          f"{fa['rmse']:.0f} N (shrinkage {100 * diag.shrinkage('rmse'):.1f} %)")
    if diag.gap_after_sim:
        print(f"re-simulated: RMSE {diag.gap_after_sim['force_residual']['rmse']:.0f} N "
              f"(shrinkage {100 * diag.shrinkage('rmse', True):.1f} %)")
    print("ranking:")
    for r in diag.ranking[:8]:
        print(f"  {r['name']:20s} held-out {100 * r['heldout_improvement']:6.1f} %  dAIC {r['delta_aic']:9.0f}  "
              + ", ".join(f"{k}={v:.4g}±{r['std_errors'][k]:.2g}" for k, v in r["parameters"].items()))
    print("forward selection:", [(s["effect"], s["reason"]) for s in diag.selection])
    print("strongest departures before:")
    for b in diag.notes["strongest_departures_before"]:
        print(f"  {b['regime']:22s} {b['bin']:14s} median {b['median']:7.1f} N [{b['ci_low']:.0f}, {b['ci_high']:.0f}]"
              f" share {100 * b['share']:.0f} %")
    print("season:", [(r["bin"], round(r["median"], 1), r["n"]) for r in diag.regimes_before.get("season", [])])
    print("unexplained:", [(b["regime"], b["bin"], round(b["median"], 1)) for b in diag.unexplained["departing_bins"]])
    print(f"wrote {paths['report']} ({time.perf_counter() - t0:.0f} s)")


if __name__ == "__main__":
    main()
