"""Aggregation, breakdown tables, rankings, decision-tree checks, breakdown curves (PNG) and the Markdown report."""

from __future__ import annotations

from typing import Any, Sequence

import numpy as np

from roadload.fileio import save_figure, write_text
from roadload.tables import format_number, markdown_table
from .faults import RobustnessError
from .metrics import breakdown_point, spread
from .scenarios import ERRORS_IN_VARIABLES, INPUT_TARGETS, ROBUST, SweepSpec, WINDUP_STABLE
from .sweeps import DEFAULT_BOUND, sweep_specs


# ====================================================================================== aggregation and report
METRICS = ("rel_error", "excess_error", "sevn", "medse", "recovery_time", "prediction_recovery_time",
           "trace_P_max", "cond_P_max", "trace_P_growth", "longest_stretch")
_KEYS = ["backend", "sweep", "variant", "model", "estimator"]


def aggregate(results):
    """Median and IQR over seeds of every metric per (backend, sweep, variant, level, model, estimator),
    plus fault counters (samples skipped, estimates rolled back, runs with P blow-up, runs with non-finite X̂)."""
    import pandas as pd

    if results.empty:
        raise RobustnessError("no results to aggregate")
    results = with_excess_error(results)
    out = []
    for key, g in results.groupby(_KEYS[:3] + ["level"] + _KEYS[3:], sort=True):
        row = dict(zip(_KEYS[:3] + ["level"] + _KEYS[3:], key))
        row["n_seeds"] = int(g["seed"].nunique())
        for m in METRICS:
            if m in g and g[m].notna().any():
                s = spread(g[m].to_numpy(dtype=float))
                row[m] = s["median"]
                row[f"{m}_q25"] = s["q25"]
                row[f"{m}_q75"] = s["q75"]
        row["n_skipped"] = int(g["n_skipped"].sum())
        row["n_pipeline_dropped"] = int(g["n_pipeline_dropped"].sum()) if "n_pipeline_dropped" in g else 0
        row["n_rolled_back"] = int(g["n_rolled_back"].sum())
        row["runs_p_blowup"] = int(g["p_blowup"].sum())
        row["runs_nonfinite"] = int((~g["finite"].astype(bool)).sum())
        out.append(row)
    return pd.DataFrame(out)


def with_excess_error(results):
    """A copy with 'excess_error': rel_error minus the fault-free rel_error of the same seed (level 0 of the
    same backend, sweep, variant, model, estimator; NaN when level 0 was not swept)."""
    out = results.copy()
    base = out[out["level"] == 0].set_index(_KEYS + ["seed"])["rel_error"]
    base = base[~base.index.duplicated()]
    idx = out.set_index(_KEYS + ["seed"]).index
    out["excess_error"] = out["rel_error"].to_numpy(dtype=float) - base.reindex(idx).to_numpy(dtype=float)
    return out


def breakdown_table(results, bound: float = DEFAULT_BOUND, metric: str = "rel_error"):
    """Per (backend, sweep, variant, model, estimator): the breakdown point of every seed and its median / IQR
    over seeds. A seed breaks down at the smallest level whose ``metric`` exceeds its own fault-free value
    (level 0 of the same seed, when swept) by more than ``bound``; inf = not up to the largest level.

    Measuring the excess over the fault-free error follows the definition (the estimate moves away from the
    solution it gives without outliers, section 3.4) and keeps the bias of the model structure on vehicle
    data (f_r1, f_r4, drive-train model, section 5.4) from counting as breakdown."""
    import pandas as pd

    out = []
    for key, g in results.groupby(_KEYS, sort=True):
        per_seed = []
        for _, gs in g.groupby("seed"):
            gs = gs.sort_values("level")
            lv, err = gs["level"].to_numpy(), gs[metric].to_numpy(dtype=float)
            base = float(err[0]) if lv[0] == 0 and np.isfinite(err[0]) else 0.0
            per_seed.append(breakdown_point(lv, err, bound, base))
        s = spread(per_seed)
        out.append({**dict(zip(_KEYS, key)), "breakdown": s["median"], "breakdown_q25": s["q25"],
                    "breakdown_q75": s["q75"], "n_seeds": s["n"], "bound": bound, "metric": metric})
    return pd.DataFrame(out)


def _score(results, spec: SweepSpec, bound: float):
    """(score table, column, ascending) used to rank estimators for one sweep."""
    top = results[results["level"] == results["level"].max()]
    med = top.groupby(_KEYS)["rel_error"].median().rename("rel_error_at_max").reset_index()
    if spec.breakdown:
        bd = breakdown_table(results, bound)
        table = bd.merge(med, on=_KEYS)
        return table, ["breakdown", "rel_error_at_max"], [False, True]
    if spec.name in ("drift", "ramps"):
        rec = top.groupby(_KEYS)["recovery_time"].median().rename("recovery_time_at_max").reset_index()
        return rec.merge(med, on=_KEYS), ["recovery_time_at_max", "rel_error_at_max"], [True, True]
    if spec.name == "wind":
        rec = (top.groupby(_KEYS)["prediction_recovery_time"].median().rename("prediction_recovery_time_at_max")
               .reset_index())
        return rec.merge(med, on=_KEYS), ["prediction_recovery_time_at_max", "rel_error_at_max"], [True, True]
    if spec.name == "excitation":
        tr = top.groupby(_KEYS)["trace_P_growth"].median().rename("trace_P_growth_at_max").reset_index()
        return med.merge(tr, on=_KEYS), ["rel_error_at_max", "trace_P_growth_at_max"], [True, True]
    return med, ["rel_error_at_max"], [True]


def rank(results, spec: SweepSpec, bound: float = DEFAULT_BOUND):
    """Estimators ranked per (model, variant) of one sweep, best first, with the scores used.

    breakdown sweeps: by breakdown point (higher is better), then error at the largest level; drift: by
    recovery time after the largest change; excitation: by parameter error after the longest unexcited stretch
    (trace(P) growth shown); other sweeps: by parameter error at the largest level."""
    table, cols, asc = _score(results, spec, bound)
    table = table.sort_values(["backend", "sweep", "model", "variant"] + cols,
                              ascending=[True, True, True, True] + asc)
    table["rank"] = table.groupby(["backend", "sweep", "model", "variant"]).cumcount() + 1
    return table


def decision_tree_checks(results, spec: SweepSpec, bound: float = DEFAULT_BOUND) -> list[dict[str, Any]]:
    """Check the measured ranking of one sweep against figure 3.17.

    outliers: the robust estimators (yes-branch) have a higher median breakdown point than the non-robust
    ones; poor_excitation: the regularised / Stenlund-Gustafsson estimators keep trace(P) bounded (median
    growth over the longest stretch) where the others wind up; input_noise: the errors-in-variables estimators
    have a lower parameter error at the largest input noise than the output-error ones. One row per model and
    variant: what the tree expects, the two group medians, and whether the measurement agrees (None: a tie, e.g.
    neither group breaks down)."""
    if spec.tree is None:
        return []
    table, _, _ = _score(results, spec, bound)
    if spec.tree == "outliers":
        group, col, better = ROBUST, "breakdown", "higher"
        expect = "robust (M-) estimators break down at a larger outlier fraction"
    elif spec.tree == "poor_excitation":
        group, col, better = WINDUP_STABLE, "trace_P_growth_at_max", "lower"
        expect = "regularised / Stenlund-Gustafsson estimators keep trace(P) bounded in unexcited stretches"
    else:
        group, col, better = ERRORS_IN_VARIABLES, "rel_error_at_max", "lower"
        expect = "errors-in-variables estimators have a smaller parameter bias under input noise"
    checks = []
    for (model, variant), g in table.groupby(["model", "variant"]):
        ins = g[g["estimator"].isin(group)][col].to_numpy(dtype=float)
        outs = g[~g["estimator"].isin(group)][col].to_numpy(dtype=float)
        if ins.size == 0 or outs.size == 0:
            continue
        a, b = spread(ins)["median"], spread(outs)["median"]
        agrees = None if a == b else (bool(a > b) if better == "higher" else bool(a < b))  # None: a tie
        note = ""
        if spec.tree == "outliers" and variant.split("/")[0] in INPUT_TARGETS:
            note = ("outliers in A are bad leverage points, against which M-estimators are not robust "
                    "(section 3.4.2): the text itself expects no advantage here")
        checks.append({"sweep": spec.name, "model": model, "variant": variant, "expected": expect,
                       "metric": col, "group_median": a, "others_median": b, "agrees": agrees, "note": note})
        checks += _pairwise_checks(spec, model, variant, g.set_index("estimator")[col], note)
    return checks


#: the text's pairwise claims: (sweep tree question, estimator that should be better, the one it beats)
PAIRWISE_CLAIMS = {
    "outliers": [("RLM", "RLS"), ("RRLM", "RLS")],                      # section 3.4 / figure 3.8
    "poor_excitation": [("RRLM", "RLM"), ("SGMKF", "RLM")],             # sections 3.3, 3.5.5, 3.7.4
    "input_noise": [("RIV", "RLS"), ("RIVM", "RLM"), ("RRIVM", "RRLM"), ("IVKF", "KF"), ("IVMKF", "MKF"),
                    ("RIVMKF", "RMKF"), ("SGIVMKF", "SGMKF")],          # section 3.6.8 / figure 3.14
}


def _pairwise_checks(spec: SweepSpec, model: str, variant: str, score, note: str) -> list[dict[str, Any]]:
    """One row per pairwise claim of the text whose two estimators were both run.

    outliers: a larger breakdown point; poor_excitation: trace(P) growth at most half of the unregularised
    estimator's growth above 1 (i.e. g - 1 < (g_RLM - 1)/2), so "bounded" means a clear difference; input
    noise: a smaller parameter error at the largest noise level. Ties (e.g. neither breaks down) give None."""
    rows = []
    for better, worse in PAIRWISE_CLAIMS.get(spec.tree or "", []):
        if better not in score.index or worse not in score.index:
            continue
        a, b = float(score[better]), float(score[worse])
        if spec.tree == "outliers":
            agrees = None if a == b else a > b
            text = f"{worse} breaks down at a lower outlier fraction than {better}"
        elif spec.tree == "poor_excitation":
            agrees = (a - 1.0) < 0.5 * (b - 1.0)
            text = f"{better} bounds the wind-up of trace(P) that {worse} shows"
        else:
            agrees = None if a == b else a < b
            text = f"{better} has a smaller parameter bias than {worse} under input noise"
        rows.append({"sweep": spec.name, "model": model, "variant": variant, "expected": text,
                     "metric": f"{better} vs {worse}", "group_median": a, "others_median": b,
                     "agrees": None if agrees is None else bool(agrees), "note": note})
    return rows


def plot_curves(agg, spec: SweepSpec, path, bound: float = DEFAULT_BOUND) -> None:
    """Breakdown curves: median excess error (relative parameter error above the fault-free one of the same
    seed; IQR band) over the swept level, one line per estimator (solid: robust, dashed: non-robust), one panel
    per (model, variant); the breakdown bound dotted. Clipped to [1e-4, 1e3] for the log axis. Atomic PNG."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    panels = sorted({(m, v) for m, v in zip(agg["model"], agg["variant"])})
    ncol = min(3, len(panels))
    nrow = int(np.ceil(len(panels) / ncol))
    fig, axes = plt.subplots(nrow, ncol, figsize=(5.2 * ncol, 3.8 * nrow), squeeze=False)
    cmap = plt.get_cmap("tab20")
    names = sorted(agg["estimator"].unique())
    for ax, (model, variant) in zip(axes.flat, panels):
        g = agg[(agg["model"] == model) & (agg["variant"] == variant)]
        for i, name in enumerate(names):
            e = g[g["estimator"] == name].sort_values("level")
            if e.empty:
                continue
            e = e[e["level"] > 0]
            if e.empty or "excess_error" not in e:
                continue
            y = np.clip(e["excess_error"].to_numpy(dtype=float), 1e-4, 1e3)
            ax.plot(e["level"], y, marker="os^vD<>ph*"[i % 10], ms=3.5, color=cmap(i % 20), label=name,
                    ls="-" if name in ROBUST else "--", lw=1.2)
            ax.fill_between(e["level"], np.clip(e["excess_error_q25"], 1e-4, 1e3),
                            np.clip(e["excess_error_q75"], 1e-4, 1e3), color=cmap(i % 20), alpha=0.12)
        ax.axhline(bound, color="k", ls=":", lw=1)
        ax.set_yscale("log")
        ax.set_title(f"{spec.name}: {variant} ({model})", fontsize=9)
        ax.set_xlabel(f"{spec.parameter} [{spec.unit}]")
        ax.set_ylabel("rel. parameter error above fault-free [1]")
        ax.grid(alpha=0.3)
    for ax in axes.flat[len(panels):]:
        ax.axis("off")
    axes.flat[0].legend(fontsize=6, ncol=2)
    fig.tight_layout()
    save_figure(fig, path, dpi=110)


def _verdict(agrees: bool | None) -> str:
    return "tie" if agrees is None else ("yes" if agrees else "NO")


def write_report(results, out_dir, bound: float = DEFAULT_BOUND,
                 failed: Sequence[tuple[Any, str]] = ()) -> dict[str, Any]:
    """Tables per sweep (CSV + Markdown), breakdown curves (PNG), rankings and the one-page summary.

    Returns {'rankings': {sweep: DataFrame}, 'checks': [decision-tree check rows], 'files': [paths]}."""
    from pathlib import Path

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    files = []
    write_text(out / "results.csv", results.to_csv(index=False))
    files.append(out / "results.csv")
    rankings, checks = {}, []
    summary = ["# Estimator robustness: summary", "",
               f"Breakdown criterion: the median relative parameter error (RMS over parameters of |X̂-X̄|/|X̄|, "
               f"after burn-in) exceeds its fault-free value (level 0, same seed) by more than {bound:g}. "
               f"Breakdown points are medians [IQR] over seeds; ∞ = no breakdown up to the largest level swept.",
               ""]
    for (backend, sweep), res in results.groupby(["backend", "sweep"], sort=True):
        spec = sweep_specs(backend)[sweep]
        agg = aggregate(res)
        stem = f"{backend}_{sweep}"
        cols = [c for c in ["variant", "model", "level", "estimator", "n_seeds", "rel_error", "rel_error_q25",
                            "rel_error_q75", "excess_error", "sevn", "medse", "recovery_time", "trace_P_max",
                            "cond_P_max",
                            "trace_P_growth", "longest_stretch", "n_skipped", "n_pipeline_dropped", "runs_p_blowup",
                            "runs_nonfinite"] if c in agg]
        write_text(out / f"table_{stem}.csv", agg[cols].to_csv(index=False))
        write_text(out / f"table_{stem}.md", f"# {backend} sweep '{sweep}' ({spec.parameter} "
                           f"[{spec.unit}])\n\n" + markdown_table(agg, cols) + "\n")
        plot_curves(agg, spec, out / f"curves_{stem}.png", bound)
        files += [out / f"table_{stem}.csv", out / f"table_{stem}.md", out / f"curves_{stem}.png"]
        ranking = rank(res, spec, bound)
        rankings[(backend, sweep)] = ranking
        write_text(out / f"ranking_{stem}.csv", ranking.to_csv(index=False))
        files.append(out / f"ranking_{stem}.csv")
        n_seeds = int(res["seed"].nunique())
        summary += [f"## {backend} / {sweep} — {spec.parameter} [{spec.unit}], {n_seeds} seeds", ""]
        score_cols = [c for c in ranking.columns if c.endswith("_at_max") or c.startswith("breakdown")]
        for (model, variant), g in ranking.groupby(["model", "variant"], sort=True):
            best = ", ".join(f"{r.estimator} ({format_number(getattr(r, score_cols[0]))})" for r in g.itertuples())
            summary.append(f"- **{variant}** ({model}), ranked by {score_cols[0]}: {best}")
        c = decision_tree_checks(res, spec, bound)
        checks += [{"backend": backend, **x} for x in c]
        faults = res[~res["finite"].astype(bool)]
        summary.append("")
        dropped = int(res["n_pipeline_dropped"].sum()) if "n_pipeline_dropped" in res else 0
        summary.append(f"Non-finite estimates: {len(faults)} of {len(res)} runs; P blow-up reported in "
                       f"{int(res['p_blowup'].sum())} runs; {int(res['n_skipped'].sum())} non-finite samples "
                       f"skipped by the estimators and {dropped} by the pipeline, all counted.")
        summary.append("")
    summary += ["## Check against the decision tree (figure 3.17)", ""]
    if checks:
        summary.append("| backend | sweep | model | variant | expected | metric | group | others | agrees | note |")
        summary.append("|---|---|---|---|---|---|---|---|---|---|")
        for x in checks:
            summary.append(f"| {x['backend']} | {x['sweep']} | {x['model']} | {x['variant']} | {x['expected']} | "
                           f"{x['metric']} | {format_number(x['group_median'])} | "
                           f"{format_number(x['others_median'])} | "
                           f"{_verdict(x['agrees'])} | {x['note']} |")
    else:
        summary.append("No sweep in this run exercises a question of the decision tree.")
    summary.append("")
    summary.append("Drift, dropouts, bias and latency are not covered by figure 3.17; they are ranked only.")
    if failed:
        summary += ["", f"## Failed scenarios ({len(failed)})", ""]
        summary += [f"- {task}: {err}" for task, err in failed]
    write_text(out / "summary.md", "\n".join(summary) + "\n")
    files.append(out / "summary.md")
    return {"rankings": rankings, "checks": checks, "files": files}
