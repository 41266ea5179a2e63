"""``roadload benchmark robustness``: sweep the catalog estimators over injected faults to breakdown."""

from __future__ import annotations

import time
from pathlib import Path

import typer
from rich.console import Console
from rich.table import Table

from roadload.experiments.robustness import (
    DEFAULT_BOUND, DEFAULT_SEEDS, SWEEP_FAMILIES, RobustnessError, default_estimators, run_sweep_results,
    scenarios, sweep_specs, write_report,
)

from .errors import describe, fail

#: record length per backend [s]: Experiment 3.3's 10 000 s for the synthetic data; 20 min simulated trips
DEFAULT_DURATION = {"synthetic": 10_000.0, "vehicle": 1200.0}


def _fail(exc: Exception) -> None:
    fail(describe(exc))


def _sweeps_of(backend: str, families: list[str]) -> list[str]:
    specs = sweep_specs(backend)
    if not families:
        return list(specs)
    out = []
    for f in families:
        if f in SWEEP_FAMILIES:
            out += [s for s in SWEEP_FAMILIES[f] if s in specs]
        elif f in specs:
            out.append(f)
        else:
            raise RobustnessError(f"unknown sweep {f!r} for backend {backend!r}; use one of "
                                  f"{sorted(set(SWEEP_FAMILIES) | set(specs))}")
    if not out:
        raise RobustnessError(f"backend {backend!r} has none of the sweeps {families}; it has {sorted(specs)}")
    return list(dict.fromkeys(out))


def register(app: typer.Typer, benchmark_app: typer.Typer) -> None:
    @benchmark_app.command("robustness")
    def robustness_cmd(
        out: Path = typer.Option(..., "--out", "-o",
                                 help="output directory (tables, PNG curves, summary.md; units/ holds every "
                                      "finished scenario, so a stopped run resumes where it was)"),
        estimators: str = typer.Option(None, "--estimators", "-e",
                                       help="comma-separated catalog names (default: all but the PKS)"),
        sweep: list[str] = typer.Option([], "--sweep", "-s",
                                        help="outliers | excitation | drift | bias | input_noise, or a single "
                                             "sweep name (dropouts, latency); repeatable; default all"),
        backend: str = typer.Option("vehicle", "--backend", "-b",
                                    help="vehicle (simulated trips -> chapter-5 pipeline) or synthetic (A/B level)"),
        seeds: int = typer.Option(DEFAULT_SEEDS, "--seeds", "-n", help="seeds per level (>= 20 for the report)"),
        duration: float = typer.Option(None, "--duration", help="record length in s (default 10000 synthetic, "
                                                               "1200 vehicle)"),
        bound: float = typer.Option(DEFAULT_BOUND, "--bound",
                                    help="breakdown: median relative parameter error this much above its "
                                         "fault-free value [1]"),
        scheduler: str = typer.Option(None, "--scheduler", help="Dask scheduler address (default: local processes)"),
        workers: int = typer.Option(None, "--workers", help="local worker processes (default: CPU count)"),
    ) -> None:
        """Sweep outliers, poor excitation, drift and sensor bias to breakdown; rank estimators per failure mode."""
        console = Console()
        try:
            names = [e.strip().upper() for e in estimators.split(",") if e.strip()] if estimators else None
            if seeds < 1:
                raise RobustnessError(f"--seeds must be >= 1, got {seeds}")
            if not bound > 0:
                raise RobustnessError(f"--bound must be > 0, got {bound}")
            dur = duration if duration is not None else DEFAULT_DURATION.get(backend, 0.0)
            tasks = []
            for name in _sweeps_of(backend, list(sweep)):
                tasks += scenarios(backend, name, seeds, dur)
            t0 = time.perf_counter()
            results, failed = run_sweep_results(tasks, names, scheduler=scheduler, workers=workers,
                                                checkpoint=out / "units")
            elapsed = time.perf_counter() - t0
            if results.empty:
                raise RobustnessError(f"every scenario failed; first error: {failed[0][1] if failed else '?'}")
            report = write_report(results, out, bound, failed)
        except (RobustnessError, ValueError) as exc:
            _fail(exc)
        console.print(f"{len(tasks)} scenarios x {len(names or default_estimators())} estimators in "
                      f"{elapsed:.1f} s -> {out}")
        for task, err in failed[:10]:
            console.print(f"[yellow]failed[/yellow] {task}: {err}")
        if failed:
            console.print(f"[yellow]{len(failed)} scenarios failed[/yellow] (listed in the summary)")
        for (bk, sw), ranking in report["rankings"].items():
            score = [c for c in ranking.columns if c.endswith("_at_max") or c == "breakdown"][0]
            table = Table(title=f"{bk} / {sw}: ranked by {score}")
            table.add_column("model / variant")
            table.add_column("best → worst")
            for (model, variant), g in ranking.groupby(["model", "variant"], sort=True):
                table.add_row(f"{model} / {variant}",
                              ", ".join(f"{r.estimator} {getattr(r, score):.3g}" for r in g.itertuples()))
            console.print(table)
        for c in report["checks"]:
            mark = ("tie" if c["agrees"] is None else
                    "[green]agrees[/green]" if c["agrees"] else "[red]DISAGREES[/red]")
            console.print(f"fig. 3.17 {c['sweep']} {c['variant']} ({c['model']}): {mark} — {c['metric']} "
                          f"{c['group_median']:.3g} vs {c['others_median']:.3g}")
