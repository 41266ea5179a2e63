"""Trip time and energy of the truck's closed-loop MPC over a fine grid of time weights lambda.

Measures whether the closed-loop trip time is continuous and monotone in lambda on one paired-comparison seed
(the headline's road, warm-up and plant), and saves the speed traces so the trajectories of neighbouring lambda
can be compared. ``--variant`` selects the MPC's terminal kinetic-energy value (``source``: m E_N / eta_i, the
default; ``wheel``: m E_N, the earlier value, which undervalues kinetic energy by eta_i on an ICE).

    python scripts/truck_lambda_scan.py --case truck_15t --seed 0 --lams 100000:200000:11 --out scan.json
    python scripts/truck_lambda_scan.py --quick
"""

from __future__ import annotations

import argparse
import json
import time
from typing import Any
from concurrent.futures import ProcessPoolExecutor
from dataclasses import replace
from pathlib import Path

import numpy as np

from roadload.controllers.drive import drive
from roadload.experiments.controller_comparison import VEHICLE_CASES, paired_road
from roadload.fileio import write_text


def run_one(case: str, seed: int, lam: float, warmup: float, variant: str, road: str,
            force_model: str = "oracle", target: float | None = None) -> dict:
    c = VEHICLE_CASES[case]
    prof = paired_road(road, seed, warmup)
    base = replace(c.settings(), measure_from=warmup)
    mpc = replace(base.mpc, terminal_value=variant)
    st = replace(base, controller="mpc", force_model=force_model, time_weight=lam, mpc=mpc)
    if target is not None:  # the schedule knob: lambda by feedback from lam, multi-start every 5 s
        st = replace(st, target_time=target, multistart_period=5.0)
    res, _ = drive(c.vehicle(), prof, seed=seed, settings=st)
    m = res.metrics
    log = res.log
    keep = log["s"].to_numpy() >= 0
    s = log["s"].to_numpy()[keep]
    v = log["v"].to_numpy()[keep]
    grid = np.arange(0.0, prof.length, 50.0)
    return {"lam": lam, "target_time": target, "time_weight_median": m.get("ctl_time_weight_median"),
            "variant": variant, "segment_time": m["segment_time"], "energy_net_J": m["energy_net_J"],
            "segment_energy_J": m["segment_energy_J"], "arrival_speed": m["arrival_speed"],
            "fallbacks": m.get("fallbacks"), "s": grid.tolist(), "v": np.interp(grid, s, v).tolist()}


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--case", default="truck_15t")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--road", default="long_grades")
    ap.add_argument("--warmup", type=float, default=2000.0, help="[m]")
    ap.add_argument("--lams", default="100000:200000:11", help="lo:hi:n (log-spaced) [J/s]")
    ap.add_argument("--variants", default="wheel,source")
    ap.add_argument("--force-model", default="oracle")
    ap.add_argument("--targets", default="", help="segment-time targets [s] (schedule knob, lambda_0 = the first "
                    "of --lams); empty: the fixed-lambda grid")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--out", type=Path, default=None)
    ap.add_argument("--quick", action="store_true", help="3 lambdas, one variant, no warm-up")
    a = ap.parse_args(argv)
    lo, hi, n = a.lams.split(":")
    lams = np.geomspace(float(lo), float(hi), int(n))
    variants = a.variants.split(",")
    if a.quick:
        lams, variants, a.warmup = lams[[0, len(lams) // 2, -1]], variants[-1:], 0.0
    t0 = time.perf_counter()
    targets = [float(x) for x in a.targets.split(",") if x.strip()]
    jobs: list[tuple[Any, ...]]  # the arguments of run_one
    if targets:
        jobs = [(a.case, a.seed, float(lams[0]), a.warmup, var, a.road, a.force_model, tt)
                for var in variants for tt in (targets[:2] if a.quick else targets)]
    else:
        jobs = [(a.case, a.seed, float(lam), a.warmup, var, a.road, a.force_model, None)
                for var in variants for lam in lams]
    with ProcessPoolExecutor(max_workers=a.workers) as ex:
        rows = list(ex.map(run_one, *zip(*jobs)))
    for var in variants:
        print(f"variant {var}: {a.case} seed {a.seed} {a.road} warm-up {a.warmup:.0f} m")
        print("  lambda [J/s]   target [s]   T_segment [s]   E_net [MJ]   v_arrival [m/s]  fallbacks")
        for r in rows:
            if r["variant"] == var:
                lam = r["lam"] if r["target_time"] is None else r["time_weight_median"]
                tgt = "-" if r["target_time"] is None else f"{r['target_time']:.1f}"
                print(f"  {lam:12.0f}   {tgt:>10}   {r['segment_time']:13.2f}   {r['energy_net_J'] / 1e6:10.3f}   "
                      f"{r['arrival_speed']:15.2f}  {r['fallbacks']}")
        t = np.array([r["segment_time"] for r in rows if r["variant"] == var])
        jumps = np.abs(np.diff(t)) / t[:-1]
        print(f"  largest step in T between neighbouring lambdas: {100 * jumps.max():.2f} %;"
              f" monotone: {bool(np.all(np.diff(t) <= 1e-6))}")
    print(f"wall {time.perf_counter() - t0:.1f} s")
    if a.out is not None:
        write_text(a.out, json.dumps({"args": {k: str(v) for k, v in vars(a).items()}, "runs": rows}))
