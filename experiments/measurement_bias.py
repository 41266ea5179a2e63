"""Measurement-side honesty: how far the online M4 estimate sits from the least-squares fit of the SAME model to
the simulator's TRUE forces, and which sensor-side effect moves it.

One human-driven trip per seed on a generated hilly road (the same road and driver for every variant); for each
variant the trip is re-simulated with the same seed and run through the chapter-5 pipeline:

- ``truth_ls``: least squares of M4 on the true states (v, dv/dt, theta, 1/r) and the true F_xV, on the rows the
  pipeline triggered (the target the estimator can reach at best; it differs from the spec values because M4
  absorbs f_r1 v and the f_r4 v^4 term);
- ``can`` (the preset's CAN sensors: drive-torque offset and gain error, body pitch in the accelerometer),
  ``no_torque_bias`` (drive-torque offset and gain error set to 0), ``pitch_corrected`` (eq. 5.2 with the pitch
  correction of :class:`roadload.estimators.pipeline.PipelineSettings`), ``both``.
For each measured variant: the RRLM estimate at the end of the trip (section 5.5 settings) and the batch least
squares on the same measured rows (separates the estimator from the measurement).

:func:`main` (``scripts/measurement_bias.py``) prints the table (mean over seeds, difference to the truth LS in %)
and writes measurement_bias.csv/.md/.png and the per-run rows to ``--out``.
"""

from __future__ import annotations

import argparse
import copy
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from roadload.controllers.drive import DriveSettings, drive
from roadload.estimators import chapter5_settings, make_estimator
from roadload.estimators.knowledge import knowledge_for_preset
from roadload.estimators.models import (ACCELERATION, GRADIENT_ANGLE, PATH_CURVATURE, SPEED, TRACTIVE_FORCE,
                                        get_model)
from roadload.estimators.pipeline import PipelineSettings, model_data, run_pipeline
from roadload.presets import get_preset
from roadload.road_profiles import hilly
from roadload.fileio import save_figure, write_text
from roadload.tables import markdown_table

VARIANTS = ("can", "no_torque_bias", "pitch_corrected", "both")
PARAMETERS = ("m_V f_r0", "m_V", "rho_a/2 A_V c_x", "m_V^2/c_yW")


def _trip(preset: str, seed: int, torque_bias: bool, length: float):
    spec = get_preset(preset)
    if not torque_bias:
        spec = copy.deepcopy(spec)
        spec.sensors.drive_torque_offset = 0.0
        spec.sensors.drive_torque_gain_error = 0.0
    _, plant = drive(spec, hilly(seed=seed, length=length), seed=seed, settings=DriveSettings(controller="human"))
    return plant.sim.to_trip()


def measurement_bias(preset: str = "bmw_i3", seed: int = 0, length: float = 20_000.0) -> list[dict[str, Any]]:
    """Rows (variant, parameter values) for one seed (module docstring)."""
    knowledge = knowledge_for_preset(preset)
    model = get_model("M4")
    settings = dict(chapter5_settings("M4")["RRLM"])
    x0 = model.nominal_parameters(knowledge.nominal)
    rows = []
    trips = {True: _trip(preset, seed, True, length), False: _trip(preset, seed, False, length)}
    for variant in VARIANTS:
        trip = trips[variant not in ("no_torque_bias", "both")]
        pipe = PipelineSettings(pitch_correction=variant in ("pitch_corrected", "both"))
        states = run_pipeline(trip, knowledge, pipe).states
        t, a, b = model_data(states, model)
        est = make_estimator("RRLM", x0=x0, **{**settings, "n_params": model.n_params})
        for ai, bi in zip(a, b):
            est.update(ai, bi)
        ls, *_ = np.linalg.lstsq(a, b, rcond=None)
        rows.append({"seed": seed, "variant": variant, "method": "RRLM", "rows": len(t),
                     **dict(zip(PARAMETERS, map(float, est.x)))})
        rows.append({"seed": seed, "variant": variant, "method": "batch LS", "rows": len(t),
                     **dict(zip(PARAMETERS, map(float, ls)))})
        if variant == "can":
            truth = trip.truth
            tt = truth["t"].to_numpy(float)
            named = {SPEED: np.interp(t, tt, truth["speed"].to_numpy(float)),
                     ACCELERATION: np.interp(t, tt, truth["acceleration"].to_numpy(float)),
                     GRADIENT_ANGLE: np.interp(t, tt, truth["grade"].to_numpy(float)),
                     PATH_CURVATURE: np.interp(t, tt, truth["path_curvature"].to_numpy(float))}
            b_true = np.interp(t, tt, truth["tractive_force"].to_numpy(float))
            named[TRACTIVE_FORCE] = b_true
            a_true = model.regressors(named)
            ok = np.all(np.isfinite(a_true), axis=1) & np.isfinite(b_true)
            x_true, *_ = np.linalg.lstsq(a_true[ok], b_true[ok], rcond=None)
            rows.append({"seed": seed, "variant": "truth", "method": "LS on true forces", "rows": int(ok.sum()),
                         **dict(zip(PARAMETERS, map(float, x_true)))})
    nominal = dict(zip(PARAMETERS, map(float, x0)))
    rows.append({"seed": seed, "variant": "spec", "method": "spec values (nominal X0)", "rows": 0, **nominal})
    return rows


def summarise_bias(rows: list[dict[str, Any]]) -> pd.DataFrame:
    """Mean and standard error over seeds per (variant, method), and the difference to the truth LS [%]."""
    df = pd.DataFrame(rows)
    out = []
    truth = df[df.variant == "truth"].set_index("seed")
    for (variant, method), g in df.groupby(["variant", "method"], sort=False):
        row = {"variant": variant, "method": method, "seeds": len(g)}
        for p in PARAMETERS:
            v = g[p].to_numpy(float)
            row[p] = float(v.mean())
            row[f"{p} se"] = float(v.std(ddof=1) / np.sqrt(v.size)) if v.size > 1 else float("nan")
            ref = truth.loc[g.seed, p].to_numpy(float)
            row[f"{p} vs truth LS [%]"] = float(np.mean(100 * (v / ref - 1)))
        out.append(row)
    return pd.DataFrame(out)


def bias_figure(summary: pd.DataFrame, path) -> None:
    """Grouped bars: each parameter relative to the truth LS [%] per variant and method."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    s = summary[summary.variant != "truth"].reset_index(drop=True)
    labels = [f"{v}\n{m}" for v, m in zip(s.variant, s.method)]
    fig, axes = plt.subplots(1, 3, figsize=(15, 4.5), sharey=True)
    for ax, p in zip(axes, PARAMETERS[:3]):
        vals = s[f"{p} vs truth LS [%]"].to_numpy(float)
        ax.barh(range(len(s)), vals, color=["tab:blue" if m == "RRLM" else "tab:gray" if m == "batch LS"
                                             else "tab:green" for m in s.method])
        ax.axvline(0.0, color="k", lw=0.8)
        ax.set_title(f"{p}: vs LS on the true forces [%]")
        ax.set_yticks(range(len(s)), labels, fontsize=7)
    axes[0].invert_yaxis()
    fig.tight_layout()
    save_figure(fig, path, dpi=120)


def main(argv: list[str] | None = None) -> None:
    """The experiment's command line: ``[--out DIR] [--seeds 3] [--length 20000] [--preset bmw_i3] [--quick]``."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=Path("measurement_bias"), help="output folder")
    ap.add_argument("--seeds", type=int, default=3)
    ap.add_argument("--length", type=float, default=20_000.0, help="hilly road length [m] per trip")
    ap.add_argument("--preset", default="bmw_i3")
    ap.add_argument("--quick", action="store_true", help="1 seed, 4 km")
    args = ap.parse_args(argv)
    seeds, length = (1, 4000.0) if args.quick else (args.seeds, args.length)
    if seeds < 1 or length < 1000:
        ap.error("--seeds must be >= 1 and --length >= 1000 m")
    rows = [r for seed in range(seeds) for r in measurement_bias(args.preset, seed, length)]
    summary = summarise_bias(rows)
    args.out.mkdir(parents=True, exist_ok=True)
    write_text(args.out / "measurement_bias_runs.csv", pd.DataFrame(rows).to_csv(index=False))
    write_text(args.out / "measurement_bias.csv", summary.to_csv(index=False))
    cols = ["variant", "method", "seeds", *PARAMETERS, *[f"{p} vs truth LS [%]" for p in PARAMETERS[:3]]]
    md = markdown_table(summary[cols].round(3))
    write_text(args.out / "measurement_bias.md", md + "\n")
    bias_figure(summary, args.out / "measurement_bias.png")
    print(md)
    print(f"wrote {args.out}/measurement_bias.md/.csv/.png")
