"""Resolution study of the headline comparison (issue 14): the SAME stored closed-loop runs (runs.json of
``roadload benchmark headline``) matched with the old metric (first control step past the road end, raw source
energy) and the new one (crossings interpolated, energy net of the kinetic energy left at arrival), over time
windows of the local fit. Prints the paired difference vs the oracle, its 1-sigma resolution and the fit residual.

Usage: python scripts/headline_resolution.py RUNS.json [RUNS.json ...] [--out table.csv]
       python scripts/headline_resolution.py --quick   (runs the tiny headline first, into ./headline_quick)
"""

import argparse
import json
import sys
from pathlib import Path

import pandas as pd

from roadload.experiments.cli import main as cli_main
from roadload.experiments.controller_comparison import paired_summary, refit_results
from roadload.fileio import write_text
from roadload.tables import markdown_table


def resolution_table(results: list[dict], windows=(0.06, 0.04, 0.03)) -> pd.DataFrame:
    rows = []
    for metric in ("raw", "net"):
        for w in windows:
            s = paired_summary(refit_results(results, metric, window=w))
            for _, r in s[s.force_model != "oracle"].iterrows():
                rows.append({"vehicle": r.vehicle, "metric": metric, "window_pct": 100 * w,
                             "force_model": r.force_model, "seeds": r.seeds, "vs_oracle_pct": r.vs_oracle_pct,
                             "resolution_1sigma_pct": r.resolution_1sigma_pct, "ci95_lo_pct": r.ci95_lo_pct,
                             "ci95_hi_pct": r.ci95_hi_pct, "fit_residual_pct_median": r.fit_residual_std_pct})
    return pd.DataFrame(rows)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("runs", nargs="*", type=Path)
    ap.add_argument("--out", type=Path, default=None)
    ap.add_argument("--quick", action="store_true")
    a = ap.parse_args()
    if a.quick:
        sys.argv = ["roadload", "benchmark", "headline", "--quick", "--out", "headline_quick", "--workers", "1"]
        try:
            cli_main()
        except SystemExit as exc:
            if exc.code:
                raise
        a.runs = [Path("headline_quick/runs.json")]
    if not a.runs:
        sys.exit("give one or more runs.json files of `roadload benchmark headline` (or --quick)")
    results = [r for p in a.runs for r in json.loads(p.read_text())]
    table = resolution_table(results)
    print(markdown_table(table.round(3)))
    if a.out:
        write_text(a.out, table.to_csv(index=False))
    return 0


if __name__ == "__main__":
    sys.exit(main())
