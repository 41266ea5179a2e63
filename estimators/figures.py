"""Figures of chapter 5: pipeline stages, parameter traces (fig. 5.4), output corrections (5.5), histograms (5.6),
scatter (5.7), single-trip cross-validation (5.8), MEDSE boxplots with notches (5.9), mass NMSE boxplots (5.10).

Every function draws on a new matplotlib figure (Agg backend) and returns it; :func:`save` writes a PNG
atomically.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Mapping, Sequence

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402

from .evaluation import Estimate, mcgill_notch  # noqa: E402
from .pipeline import PipelineError, PipelineResult  # noqa: E402
from roadload.fileio import save_figure

STAGE_DEFAULT_CHANNELS = {
    "measured": ["vehicle_speed", "accel_x", "drive_torque", "steering_wheel_angle"],
    "smoothed": ["vehicle_speed", "vehicle_speed_derivative", "accel_x", "drive_torque"],
    "decimated": ["vehicle_speed", "vehicle_speed_derivative", "accel_x", "drive_torque"],
    "states": ["speed", "acceleration", "gradient_angle", "path_curvature", "tractive_force", "trigger"],
}


def save(fig: plt.Figure, path: str | os.PathLike, dpi: int = 110) -> Path:
    """Write a figure as PNG atomically and close it."""
    return save_figure(fig, path, dpi=dpi, bbox_inches="tight")


def _robust_ylim(ax: plt.Axes, values: np.ndarray, spread: float = 1.0) -> None:
    """Y limits from the 1st-99th percentile widened by `spread` ranges, so a start-up spike of a diverging
    estimator does not flatten every other trace (the spike runs off the axis)."""
    v = values[np.isfinite(values)]
    if v.size < 10:
        return
    lo, hi = np.percentile(v, [1, 99])
    pad = spread * max(hi - lo, 1e-9 * max(abs(lo), abs(hi), 1.0))
    ax.set_ylim(lo - pad, hi + pad)


def plot_stage(result: PipelineResult, stage: str, channels: Sequence[str] | None = None) -> plt.Figure:
    """Time series of a pipeline stage (one panel per channel)."""
    if stage not in result.stages:
        raise PipelineError(f"stage {stage!r} was not run for trip {result.name!r}; run to it first "
                            f"(available: {list(result.stages)})")
    frame = result.stages[stage]
    chans = [c for c in (channels or STAGE_DEFAULT_CHANNELS.get(stage, [])) if c in frame.columns]
    if not chans:
        raise PipelineError(f"none of the channels {list(channels or [])} exist in stage {stage!r}; "
                            f"it has {list(frame.columns)}")
    fig, axes = plt.subplots(len(chans), 1, sharex=True, figsize=(9, 1.8 * len(chans) + 0.6), squeeze=False)
    t = frame["t"].to_numpy(dtype=float)
    for ax, c in zip(axes[:, 0], chans):
        ax.plot(t, frame[c].to_numpy(dtype=float), lw=0.8)
        ax.set_ylabel(c, fontsize=8)
        ax.grid(alpha=0.3)
    axes[-1, 0].set_xlabel("t [s]")
    fig.suptitle(f"{result.name}: stage '{stage}'" + (f" (delay {result.delay:.2f} s)" if stage != "measured" else ""))
    return fig


def plot_parameter_traces(estimates: Mapping[str, Estimate], truth: Mapping[str, float] | None = None
                          ) -> plt.Figure:
    """Estimated parameters over time for several estimators of one model (figure 5.4)."""
    ests = list(estimates.values())
    names = ests[0].parameter_names
    fig, axes = plt.subplots(len(names), 1, sharex=True, figsize=(9, 2.2 * len(names)), squeeze=False)
    for e in ests:
        for j, ax in enumerate(axes[:, 0]):
            ax.plot(e.t, e.X[:, j], lw=0.9, label=e.name)
    for j, ax in enumerate(axes[:, 0]):
        _robust_ylim(ax, np.concatenate([e.X[:, j] for e in ests]))
        ax.set_ylabel(names[j], fontsize=8)
        if truth and names[j] in truth:
            ax.axhline(truth[names[j]], color="k", ls="--", lw=0.8, label="truth")
        ax.grid(alpha=0.3)
    axes[0, 0].legend(fontsize=7, ncol=3)
    axes[-1, 0].set_xlabel("t [s] (triggered samples)")
    return fig


def plot_output_corrections(estimates: Mapping[str, Estimate]) -> plt.Figure:
    """Output corrections ΔB_t over time per estimator (figure 5.5)."""
    ests = [e for e in estimates.values() if e.estimator]
    fig, axes = plt.subplots(len(ests), 1, sharex=True, sharey=True, figsize=(9, 1.8 * len(ests)), squeeze=False)
    _robust_ylim(axes[0, 0], np.concatenate([e.residual for e in ests]), spread=3.0)
    for ax, e in zip(axes[:, 0], ests):
        ax.plot(e.t, e.residual, lw=0.6)
        ax.set_ylabel(f"{e.name}\nΔB [N]", fontsize=8)
        ax.grid(alpha=0.3)
    axes[-1, 0].set_xlabel("t [s]")
    return fig


def plot_correction_histograms(estimates: Mapping[str, Estimate], bins: int = 80) -> plt.Figure:
    """Histograms of the output corrections (figure 5.6), log-count axis to show the heavy tails."""
    ests = [e for e in estimates.values() if e.estimator]
    fig, axes = plt.subplots(1, len(ests), sharey=True, figsize=(3 * len(ests), 3), squeeze=False)
    lim = np.nanpercentile(np.abs(np.concatenate([e.residual for e in ests])), 99.9)
    for ax, e in zip(axes[0], ests):
        r = e.residual[np.isfinite(e.residual)]
        ax.hist(r, bins=bins, range=(-lim, lim))
        ax.set_yscale("log")
        ax.set_title(e.name, fontsize=9)
        ax.set_xlabel("ΔB [N]")
    return fig


def plot_scatter(estimates: Mapping[str, Estimate]) -> plt.Figure:
    """Estimated output A_t X̂_t over measured output B_t (figure 5.7)."""
    ests = list(estimates.values())
    fig, axes = plt.subplots(1, len(ests), sharex=True, sharey=True, figsize=(3 * len(ests), 3.2), squeeze=False)
    for ax, e in zip(axes[0], ests):
        pred = np.einsum("ij,ij->i", e.A, e.X)
        ax.plot(e.B, pred, ".", ms=1.5, alpha=0.4)
        lo, hi = np.nanpercentile(e.B, [0.5, 99.5])
        ax.plot([lo, hi], [lo, hi], "k-", lw=0.6)
        ax.set_title(e.name, fontsize=9)
        ax.set_xlabel("B [N]")
    axes[0, 0].set_ylabel("B̂ [N]")
    return fig


def plot_cv_single_trip(medse: pd.DataFrame, trip: str) -> plt.Figure:
    """MEDSE per combination for each horizon of one trip (figure 5.8)."""
    d = medse[medse["trip"] == trip]
    horizons = sorted(d["horizon"].unique())
    fig, axes = plt.subplots(1, len(horizons), figsize=(3 * len(horizons), 3.4), squeeze=False, sharey=True)
    for ax, k in zip(axes[0], horizons):
        dk = d[d["horizon"] == k]
        ax.bar(range(len(dk)), dk["medse"].to_numpy(dtype=float))
        ax.set_xticks(range(len(dk)), dk["combination"], rotation=90, fontsize=7)
        ax.set_title(f"k = {k}", fontsize=9)
        ax.set_yscale("log")
    axes[0, 0].set_ylabel("MEDSE [N²]")
    fig.suptitle(f"cross-validation, trip {trip}")
    return fig


def plot_notched_boxplot(values: pd.DataFrame, value: str, order: Sequence[str] | None = None,
                         log: bool = True, ylabel: str = "", title: str = "") -> plt.Figure:
    """Boxplot per combination with McGill notches (median ± 1.57 IQR/√m) — figure 5.9 / 5.10 style."""
    order = list(order) if order is not None else list(dict.fromkeys(values["combination"]))
    data = []
    for c in order:
        x = values.loc[values["combination"] == c, value].to_numpy(dtype=float)
        data.append(x[np.isfinite(x)])
    # notches median ± 1.57 IQR/√m computed linearly (as in the text); on a log axis a notch below zero is cut
    # at the smallest positive value shown
    floor = min((x[x > 0].min() for x in data if np.any(x > 0)), default=1.0) * 0.5
    conf: list[tuple[float, float] | None] = []  # notch (low, high) per combination
    for x in data:
        if x.size == 0:
            conf.append(None)
            continue
        _, med, _, half = mcgill_notch(x)
        conf.append((max(med - half, floor) if log else med - half, med + half))
    data, conf, off_scale, where = (_to_log_scale if log else _to_linear_scale)(data, conf)
    if off_scale:
        title = f"{title} ({off_scale} values {where})"
    fig, ax = plt.subplots(figsize=(max(6, 0.8 * len(order) + 2), 4.5))
    ax.boxplot([x if x.size else [np.nan] for x in data], notch=True, whis=1.5, tick_labels=order,
               # matplotlib's stub says ArrayLike; its documented None rows (default notch) do not fit it
               conf_intervals=conf, flierprops={"markersize": 2})  # type: ignore[arg-type]
    if log:
        ax.set_yscale("log")
    ax.set_ylabel(ylabel)
    ax.tick_params(axis="x", rotation=60, labelsize=8)
    ax.set_title(title, fontsize=10)
    ax.grid(alpha=0.3, axis="y")
    return fig


Notches = list[tuple[float, float] | None]


def _to_log_scale(data: list[np.ndarray], conf: Notches) -> tuple[list[np.ndarray], Notches, int, str]:
    """Diverged estimators (MEDSE up to 1e278) would break a log axis: values and notches above 1000 × the largest
    upper quartile are drawn at that ceiling. Returns (values, notches, values moved, where they were moved)."""
    tops = [np.percentile(x, 75) for x in data if x.size]
    ceiling = 1e3 * max(tops) if tops else np.inf
    off_scale = int(sum(np.sum(x > ceiling) for x in data))
    conf = [None if c is None else (min(c[0], ceiling), min(c[1], ceiling)) for c in conf]
    return [np.minimum(x, ceiling) for x in data], conf, off_scale, f"beyond {ceiling:.3g} drawn at that ceiling"


def _to_linear_scale(data: list[np.ndarray], conf: Notches) -> tuple[list[np.ndarray], Notches, int, str]:
    """On a linear axis a diverged estimate (NMSE -1e296) is drawn at a floor / ceiling 3 × the widest IQR beyond
    the quartiles. Returns (values, notches, values moved, where they were moved)."""
    if not any(x.size for x in data):
        return data, conf, 0, ""
    q = np.array([np.percentile(x, [25, 75]) for x in data if x.size])
    span = 3.0 * max(float(np.max(q[:, 1] - q[:, 0])), 1e-12)
    lo, hi = float(q[:, 0].min()) - span, float(q[:, 1].max()) + span
    off_scale = int(sum(np.sum((x < lo) | (x > hi)) for x in data))
    conf = [None if c is None else (float(np.clip(c[0], lo, hi)), float(np.clip(c[1], lo, hi))) for c in conf]
    return [np.clip(x, lo, hi) for x in data], conf, off_scale, f"outside [{lo:.4g}, {hi:.4g}] drawn at its edge"
