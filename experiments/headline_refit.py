"""Re-summarise stored headline runs (runs.json of ``roadload benchmark headline``) with the current joint local
fit (no shared energy-time slope is fitted for a model whose runs do not spread in time), plus the matching
statistics of the truck time knob: oracle run at the cruise time within 0.2 %, nearest run per model, fit
residuals.

Usage: python scripts/headline_refit.py RUNS.json [--out DIR]
       python scripts/headline_refit.py --quick   (the tiny headline's ./headline_quick/runs.json, run first if absent)
"""

import argparse
import json
import sys
from pathlib import Path

import numpy as np

from roadload.experiments.cli import main as cli_main
from roadload.experiments.controller_comparison import paired_summary, refit_results
from roadload.experiments.headline import headline_markdown
from roadload.fileio import write_text


QUICK_RUNS = Path("headline_quick") / "runs.json"
"""Where ``scripts/headline.py --quick`` (``roadload benchmark headline --quick --out headline_quick``) leaves its
runs; the --quick re-analyses read them, so CI's smoke loop (which runs headline.py first) runs the tiny headline
once instead of three times."""


def tiny_headline_runs(runs: Path = QUICK_RUNS) -> Path:
    """``runs`` of the tiny headline (``roadload benchmark headline --quick``): the file already there, else the
    tiny headline is run now into its folder."""
    if not runs.is_file():
        sys.argv = ["roadload", "benchmark", "headline", "--quick", "--out", str(runs.parent), "--workers", "1"]
        try:
            cli_main()
        except SystemExit as exc:
            if exc.code:
                raise
    return runs


def matching_stats(results: list[dict]) -> list[str]:
    """Per vehicle: seeds whose oracle run at the cruise time landed within 0.2 %, seeds whose nearest run of each
    model is within 0.2 % of T_ref, and the fit residual (median / max) [%]."""
    lines = []
    for case in dict.fromkeys(r["task"]["case"] for r in results):
        rs = [r for r in results if r["task"]["case"] == case]
        near = {m: sum(1 for r in rs if r["nearest_time_error"].get(m, np.nan) <= 0.002)
                for m in rs[0]["energy_at_tref_J"]}
        res = np.array([100 * r["fit_residual_std"] for r in rs], float)
        lines.append(f"{case}: {len(rs)} seeds; oracle at the cruise time within 0.2 %: "
                     f"{sum(bool(r['oracle_matched']) for r in rs)}; nearest run within 0.2 % of T_ref "
                     + ", ".join(f"{m} {k}" for m, k in near.items())
                     + (f"; fit residual median {np.nanmedian(res):.3f} % max {np.nanmax(res):.3f} %"
                        if np.isfinite(res).any() else "; no fit residual")
                     + f" ({int(np.isnan(res).sum())} seeds without time spread)")
    return lines


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("runs", nargs="?", type=Path)
    ap.add_argument("--out", type=Path, default=None, help="folder for summary.csv and headline.md")
    ap.add_argument("--quick", action="store_true")
    a = ap.parse_args(argv)
    if a.quick:
        a.runs = tiny_headline_runs()
    if a.runs is None:
        ap.error("RUNS.json is required (or --quick)")
    results = refit_results(json.loads(Path(a.runs).read_text()), "net", window=0.06)
    summary = paired_summary(results)
    md = headline_markdown(summary, [])
    print(md)
    for line in matching_stats(results):
        print(line)
    if a.out is not None:
        a.out.mkdir(parents=True, exist_ok=True)
        write_text(a.out / "summary.csv", summary.to_csv(index=False))
        write_text(a.out / "headline.md", md + "\n" + "\n".join(matching_stats(results)) + "\n")
