"""Resolution study of the headline comparison: the SAME stored closed-loop runs (runs.json of
``roadload benchmark headline``) matched with the old metric (first control step past the road end, raw source
energy) and the new one (crossings interpolated, energy net of the kinetic energy left at arrival), over time
windows of the local fit. Prints the paired difference vs the oracle, its 1-sigma resolution and the fit residual.

Usage: python scripts/headline_resolution.py RUNS.json [RUNS.json ...] [--out table.csv]
       python scripts/headline_resolution.py --quick   (the tiny headline's ./headline_quick/runs.json, run first if
                                                        absent)
"""

import argparse
import json
import sys
from pathlib import Path

import numpy as np
import pandas as pd

from roadload.experiments.controller_comparison import _mean_ci, refit_results
from roadload.experiments.headline_refit import tiny_headline_runs
from roadload.fileio import save_figure, write_text
from roadload.tables import markdown_table


def resolution_table(results: list[dict], windows=(0.06, 0.04, 0.03)) -> pd.DataFrame:
    """Per metric and window: the paired difference vs the oracle as a fleet total, mean difference [J] over the
    mean of ONE common reference energy (the oracle's net-metric energy at T_ref, window 6 %) [%]."""
    ref = {(r["task"]["case"], r["task"]["seed"]): r["energy_at_tref_J"]["oracle"]
           for r in refit_results(results, "net", window=0.06)}
    rows = []
    for metric in ("raw", "net"):
        for w in windows:
            fitted = refit_results(results, metric, window=w)
            for case in dict.fromkeys(r["task"]["case"] for r in fitted):
                rs = [r for r in fitted if r["task"]["case"] == case]
                scale = 100.0 / float(np.nanmean([ref[(case, r["task"]["seed"])] for r in rs]))
                for m in [k for k in rs[0]["energy_at_tref_J"] if k != "oracle"]:
                    d = np.array([scale * (r["energy_at_tref_J"][m] - r["energy_at_tref_J"]["oracle"])
                                  for r in rs])
                    mean, se, lo, hi = _mean_ci(d)
                    rows.append({"vehicle": case, "metric": metric, "window_pct": 100 * w, "force_model": m,
                                 "seeds": int(np.isfinite(d).sum()), "vs_oracle_pct": mean,
                                 "resolution_1sigma_pct": se, "ci95_lo_pct": lo, "ci95_hi_pct": hi,
                                 "fit_residual_pct_median": float(100 * np.nanmedian(
                                     [r["fit_residual_std"] for r in rs]))})
    return pd.DataFrame(rows)


def arrival_figure(results: list[dict], path: Path, model: str = "online") -> Path | None:
    """Per seed: ``model`` vs oracle [% of the common reference energy] with the raw and the net metric, against
    the difference of their arrival speeds at the matched time weight [m/s]."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    raw = {(r["task"]["case"], r["task"]["seed"]): r for r in refit_results(results, "raw")}
    net = {(r["task"]["case"], r["task"]["seed"]): r for r in refit_results(results, "net")}
    pts = []
    for r in results:
        key = (r["task"]["case"], r["task"]["seed"])
        at = [x for x in r["runs"] if x["force_model"] in ("oracle", model)
              and x.get("time_weight") is not None and abs(x["time_weight"] / r["lambda_star"] - 1) < 1e-9]
        by = {x["force_model"]: x for x in at}
        if key not in net or len(by) < 2 or model not in net[key]["energy_at_tref_J"]:
            continue
        ref = net[key]["energy_at_tref_J"]["oracle"]
        d = [100 * (q[key]["energy_at_tref_J"][model] - q[key]["energy_at_tref_J"]["oracle"]) / ref
             for q in (raw, net)]
        pts.append((by[model]["arrival_speed"] - by["oracle"]["arrival_speed"], *d))
    if not pts:
        return None
    a = np.asarray(pts)
    fig, ax = plt.subplots(figsize=(6.5, 4.2))
    ax.scatter(a[:, 0], np.clip(a[:, 1], -5, 5), label="raw: first step past the road end, battery energy",
               marker="x", color="tab:red")
    ax.scatter(a[:, 0], a[:, 2], label="net: interpolated arrival, kinetic energy at arrival booked",
               color="tab:blue")
    ax.axhline(0, color="k", lw=0.8)
    ax.set_xlabel(f"arrival speed {model} MPC - oracle MPC at the matched time weight [m/s]")
    ax.set_ylabel(f"{model} vs oracle at equal time [%] (clipped to +-5)")
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    return save_figure(fig, path, dpi=120)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("runs", nargs="*", type=Path)
    ap.add_argument("--out", type=Path, default=None)
    ap.add_argument("--figure", type=Path, default=None, help="PNG: online vs oracle per seed over the arrival "
                    "speed difference, raw and net metric")
    ap.add_argument("--quick", action="store_true")
    a = ap.parse_args(argv)
    if a.quick:
        a.runs = [tiny_headline_runs()]
    if not a.runs:
        sys.exit("give one or more runs.json files of `roadload benchmark headline` (or --quick)")
    results = [r for p in a.runs for r in json.loads(p.read_text())]
    table = resolution_table(results)
    print(markdown_table(table.round(3)))
    if a.out:
        write_text(a.out, table.to_csv(index=False))
    if a.figure:
        arrival_figure(results, a.figure)
    return 0
