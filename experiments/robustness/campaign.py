"""Run the estimator robustness sweeps with >= 20 seeds and print the figures (``scripts/robustness_sweeps.py``;
``roadload benchmark robustness`` runs the same sweeps without the printed figures).

    python scripts/robustness_sweeps.py --backend synthetic --out /tmp/robustness_synthetic
    python scripts/robustness_sweeps.py --backend vehicle --out /tmp/robustness_vehicle

Prints the breakdown points (median [IQR] over seeds), the ranking per failure mode, the check against the
decision tree (figure 3.17) and the wall time; the tables, PNG curves and summary.md go to --out.
"""

from __future__ import annotations

import argparse
import time
from typing import Any

import numpy as np
import pandas as pd

from roadload.experiments.robustness import (
    DEFAULT_BOUND, breakdown_table, scenarios, sweep_specs, write_report, run_sweep_results,
)

DURATION = {"synthetic": 10_000.0, "vehicle": 1200.0}


def _f(x: float) -> str:
    return "∞" if np.isinf(x) else f"{x:.3g}"


def _scenario_tasks(args: argparse.Namespace, specs: dict[str, Any], names: list[str], duration: float) -> list:
    """The scenarios of the named sweeps; --variants keeps the listed variants of the sweeps that have them."""
    def chosen(name: str) -> list[str] | None:
        own = [v for v in args.variants or () if v in specs[name].variants]
        return own or None
    return [sc for name in names for sc in scenarios(args.backend, name, args.seeds, duration, variants=chosen(name))]


def _run_or_rebuild(args: argparse.Namespace, specs: dict[str, Any]
                    ) -> tuple[pd.DataFrame, list[tuple[Any, str]], list[str], dict[str, Any]]:
    """Run the sweeps (or read an earlier run's results.csv with --from-results) and write the report; returns
    (results, failed scenarios, sweep names, report)."""
    if args.from_results:
        results = pd.read_csv(args.from_results)
        failed: list[tuple[Any, str]] = []
        names = [n for n in (args.sweeps or list(specs)) if n in set(results["sweep"])]
        args.seeds = int(results["seed"].nunique())
        report = write_report(results, args.out, args.bound, failed)
        print(f"report rebuilt from {args.from_results}: {len(results)} estimator runs")
        return results, failed, names, report
    names = args.sweeps or list(specs)
    duration = args.duration or DURATION[args.backend]
    tasks = _scenario_tasks(args, specs, names, duration)
    t0 = time.perf_counter()
    results, failed = run_sweep_results(tasks, args.estimators, scheduler=args.scheduler, workers=args.workers)
    wall = time.perf_counter() - t0
    report = write_report(results, args.out, args.bound, failed)
    print(f"{len(tasks)} scenarios ({args.seeds} seeds, {duration:g} s records), {len(results)} estimator "
          f"runs, {len(failed)} failed scenarios, wall time {wall:.1f} s")
    return results, failed, names, report


def _print_breakdown(name: str, spec: Any, res: pd.DataFrame, args: argparse.Namespace) -> None:
    """Breakdown points of one sweep: median [q25, q75] over seeds per model and variant, best first."""
    bd = breakdown_table(res, args.bound)
    print(f"\n## breakdown points — {name} ({spec.parameter} [{spec.unit}], "
          f"error > fault-free + {args.bound:g}, "
          f"relative parameter error): median [q25, q75] over {args.seeds} seeds")
    for (model, variant), g in bd.groupby(["model", "variant"]):
        g = g.sort_values(["breakdown"], ascending=False)
        print(f"  {variant} ({model}): " + ", ".join(
            f"{r.estimator} {_f(r.breakdown)} [{_f(r.breakdown_q25)}, {_f(r.breakdown_q75)}]"
            for r in g.itertuples()))


def _print_sweep(name: str, spec: Any, res: pd.DataFrame, report: dict[str, Any], args: argparse.Namespace) -> None:
    """One sweep's figures: breakdown points (where the sweep has them), the ranking, non-finite counts."""
    if res.empty:
        return
    if spec.breakdown:
        _print_breakdown(name, spec, res, args)
    ranking = report["rankings"][(args.backend, name)]
    score = [c for c in ranking.columns if c.endswith("_at_max") or c == "breakdown"][0]
    print(f"\n## ranking — {name} by {score}")
    for (model, variant), g in ranking.groupby(["model", "variant"]):
        print(f"  {variant} ({model}): " + ", ".join(f"{r.estimator} {_f(getattr(r, score))}"
                                                     for r in g.itertuples()))
    n_nonfinite = int((~res["finite"].astype(bool)).sum())
    print(f"  non-finite estimates: {n_nonfinite} of {len(res)} runs; P blow-up reported in "
          f"{int(res['p_blowup'].sum())} runs; {int(res['n_skipped'].sum())} non-finite samples skipped")


def _print_checks(report: dict[str, Any]) -> None:
    """The check of every sweep against the text's decision tree (figure 3.17)."""
    print("\n## check against the decision tree (figure 3.17)")
    for c in report["checks"]:
        verdict = "tie" if c["agrees"] is None else ("agrees" if c["agrees"] else "DISAGREES")
        print(f"  {c['sweep']} / {c['variant']} ({c['model']}): {verdict} — "
              f"{c['expected']}: {c['metric']} {_f(c['group_median'])} vs {_f(c['others_median'])}"
              + (f" [{c['note']}]" if c["note"] else ""))


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--backend", default="synthetic", choices=("synthetic", "vehicle"))
    ap.add_argument("--sweeps", nargs="*", default=None, help="sweep names (default: all of the backend)")
    ap.add_argument("--variants", nargs="*", default=None,
                    help="only these variants (of the sweeps that have them; other sweeps run all variants)")
    ap.add_argument("--estimators", nargs="*", default=None, help="estimators (default: every catalog estimator)")
    ap.add_argument("--seeds", type=int, default=20)
    ap.add_argument("--duration", type=float, default=None)
    ap.add_argument("--bound", type=float, default=DEFAULT_BOUND)
    ap.add_argument("--workers", type=int, default=None)
    ap.add_argument("--scheduler", default=None)
    ap.add_argument("--out", default=None, help="report folder (required unless --quick)")
    ap.add_argument("--from-results", default=None,
                    help="rebuild the report from a results.csv of an earlier run instead of sweeping")
    ap.add_argument("--quick", action="store_true",
                    help="tiny run for CI: the first sweep, 2 seeds, 2 estimators, short records, output in "
                         "out/robustness_quick unless --out is given")
    args = ap.parse_args(argv)
    specs = sweep_specs(args.backend)
    if args.quick:
        args.sweeps = args.sweeps or list(specs)[:1]
        args.seeds, args.estimators, args.workers = 2, args.estimators or ["RLS", "RRLM"], 1
        args.duration = args.duration or DURATION[args.backend] / 10
        args.out = args.out or "out/robustness_quick"
    if args.out is None:
        ap.error("--out is required (or --quick)")
    results, failed, names, report = _run_or_rebuild(args, specs)
    for name in names:
        _print_sweep(name, specs[name], results[results["sweep"] == name], report, args)
    _print_checks(report)
    for task, err in failed[:20]:
        print(f"  failed: {task}: {err}")
    print(f"\nreport (tables, PNG curves, summary.md) in {args.out}")
