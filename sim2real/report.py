"""Writing a diagnosis: ``diagnosis.json`` (schema below), ``report.md`` and PNG figures, each file atomically.

diagnosis.json (schema_version 1; SI units, forces in N, NaN written as null):

- ``sim``: {vehicle, effects (EffectsConfig dict), name}; ``trips``: trip names; ``settings``: DiagnosisSettings;
- ``split``: {n_valid, n_train, n_test, n_folds, n_segments, n_test_segments} — the held-out part is ``test``;
- ``floor``: {basis, coefficients, residual_rms, n}: the sim's own floor (sim trips vs the sim's balance);
- ``gap``: {before, after, after_simulator, shrinkage, shrinkage_simulator, per_regime} on the held-out part;
  before/after = {force_residual: {n, mean, median, mad, medse, rmse}, replay_simulator: {rms, median_end,
  windows} [m/s] (recorded forces and road fed into the simulator; null for the fitted after),
  replay_speed_error: {rms, median_end, windows} [m/s] (linearised), energy_per_distance: {measured, sim,
  relative_error, unit}}; shrinkage = 1 - after/before for
  rmse, medse, |median|; per_regime: [{regime, bin, n, rmse_before, rmse_after, median_before, median_after,
  remaining}];
- ``regimes``: {regime: [{bin, n, n_blocks, share, median, mad, mean, medse, ci_low, ci_high, p_value,
  notch_low, notch_high, departs}]} of the residual before (all valid samples);
- ``residual_analysis``: {signal: {correlation [per lag], max_abs, lag, bound}} (eq. 3.4a; 'residual': 3.4b);
- ``ranking``: candidates alone, best first: {name, description, parameters, std_errors, units, shape,
  cv_mse, baseline_cv_mse, heldout_improvement, heldout_gain [mean, low, high], significant, aic, bic,
  delta_aic, delta_bic, explained_fraction, sim_effect, sim_parameters}; ``skipped_candidates``: {name: reason};
- ``forward_selection``: steps {step, effect, shape, robust_loss_before, robust_loss_after (shares of the sim's
  original robust loss, :mod:`.robust`), relative_gain, gain_of_original, null_p, null_quantile, gain,
  reference_robust_loss, explained_fraction, size_rms, implausible, accepted, reason};
- ``effects``: the accepted effects {name, description, shape, shape_name, shape_unit, parameters, std_errors,
  units, heldout_gain, null_p, explained_fraction, sim_switch, sim_parameters};
- ``energy_side`` (battery-electric only, else null): {power_residual_before/after (robust summaries, W),
  base_calibration (the energy base block, as below), electric_energy_per_distance {measured, sim_before,
  sim_after}, ranking, skipped_candidates, forward_selection, effects (as above)} of the battery-power residual
  (:mod:`.energy`);
- ``unexplained``: {present, departing_bins [regime bins as above], reference_gain {relative, interval,
  significant}, reference_importance [{column, std, strongest_bin, strongest_effect}], rms_after};
- ``notes``: pipeline notes per trip, baseline robust loss/AIC/BIC with the null's settings, strongest departures
  before, ``base_calibration`` {parameters [{name, candidate, parameter, unit, value, std_error, size_rms,
  significant, physical {sim, calibrated, unit}}], used_for_effects}, ``implausible`` [{effect, reason}] (fits
  outside the simulator's physical range: reported, never accepted), ``resimulation`` (done / skipped / why).
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np
import pandas as pd

from roadload import fileio
from roadload.fileio import atomic_path, save_figure

from .errors import DiagnosisError
from .records import jsonable
from .results import Diagnosis


def _atomic_write(path: Path, write) -> None:
    with atomic_path(path) as tmp:
        write(tmp)


def write_json(diag: Diagnosis, path: Path) -> Path:
    def w(tmp):
        with open(tmp, "w") as fh:
            json.dump(diag.to_dict(), fh, indent=1)
    _atomic_write(path, w)
    return path


# ------------------------------------------------------------------------------------------------ figures
def _save(fig, path: Path) -> None:
    save_figure(fig, path, dpi=110, format="png")


def _held_out(diag: Diagnosis) -> tuple[pd.DataFrame, np.ndarray, np.ndarray]:
    """(table frame, held-out row mask, residual after [N]) of a diagnosis run in this process."""
    if diag.table is None or diag.test_rows is None or diag.residual_after is None:
        raise DiagnosisError("the figures need the diagnosis table, held-out rows and residuals after the fit; a "
                             "Diagnosis read back from JSON carries none - run diagnose() again")
    return diag.table.frame, diag.test_rows, diag.residual_after


def figure_residual_map(diag: Diagnosis, path: Path) -> Path:
    """Median residual over speed × acceleration, before and after (held-out part)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    f, test, residual_after = _held_out(diag)
    v = f["speed"].to_numpy() * 3.6
    a = f["acceleration"].to_numpy()
    ve = np.arange(0, max(140, np.nanmax(v[test]) + 10), 10)
    ae = np.array([-3, -1.5, -1, -0.5, -0.2, 0.2, 0.5, 1, 1.5, 3])
    before = f["residual"].to_numpy()
    fig, axes = plt.subplots(1, 2, figsize=(11, 4.2), sharey=True)
    maps = []
    for r in (before, residual_after):
        m = np.full((ae.size - 1, ve.size - 1), np.nan)
        iv = np.searchsorted(ve, v, side="right") - 1
        ia = np.searchsorted(ae, a, side="right") - 1
        for i in range(ae.size - 1):
            for j in range(ve.size - 1):
                sel = test & (ia == i) & (iv == j)
                if sel.sum() >= 20:
                    m[i, j] = np.median(r[sel])
        maps.append(m)
    lim = np.nanmax(np.abs(maps[0])) if np.isfinite(maps[0]).any() else 1.0
    for ax, m, title in zip(axes, maps, ("before", "after (identified effects)")):
        im = ax.pcolormesh(ve, np.arange(ae.size), m, cmap="RdBu_r", vmin=-lim, vmax=lim)
        ax.set_title(f"median force residual, {title}")
        ax.set_xlabel("speed [km/h]")
        ax.set_yticks(np.arange(ae.size))
        ax.set_yticklabels([f"{x:g}" for x in ae])
    axes[0].set_ylabel("acceleration [m/s²]")
    fig.colorbar(im, ax=axes, label="N")
    _save(fig, path)
    return path


def _time_profile(f: pd.DataFrame, r: np.ndarray, valid: np.ndarray, sel: np.ndarray):
    """Per 1-min bin of time since start: median over trips of each trip's median residual, and the IQR."""
    minute = np.floor(f["time_since_start"].to_numpy() / 60.0)
    g = pd.DataFrame({"trip": f["trip"].to_numpy(), "m": minute, "r": r})[valid & sel]
    per_trip = g.groupby(["m", "trip"])["r"].median().reset_index()
    q = per_trip.groupby("m")["r"].quantile([0.25, 0.5, 0.75]).unstack()
    n = per_trip.groupby("m")["trip"].nunique()
    q = q[n >= 3]
    return q.index.to_numpy() + 0.5, q[0.25].to_numpy(), q[0.5].to_numpy(), q[0.75].to_numpy()


def _finish_time_axes(fig, axes, path: Path, title: str, **legend) -> Path:
    axes[0].set_title(title)
    axes[1].set_title("after the identified effects")
    for ax in axes:
        ax.axhline(0, color="k", lw=0.6)
        ax.set_ylabel("N")
    axes[1].set_xlabel("time since start [min]")
    axes[0].legend(**legend)
    _save(fig, path)
    return path


def figure_residual_time(diag: Diagnosis, path: Path) -> Path:
    """Residual over time since start: per trip (30 s rolling median) for up to 8 trips; for more, the median
    over trips of the per-minute residual with its IQR, per season."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    f, _, residual_after = _held_out(diag)
    valid = f["valid"].to_numpy(bool)
    fig, axes = plt.subplots(2, 1, figsize=(10, 5.5), sharex=True)
    trips = list(pd.unique(f["trip"]))
    if len(trips) > 8:
        seasons = f["season"].to_numpy() if "season" in f.columns else np.full(len(f), "all")
        for season in pd.unique(seasons):
            sel = seasons == season
            for ax, r in zip(axes, (f["residual"].to_numpy(), residual_after)):
                x, lo, med, hi = _time_profile(f, r, valid, sel)
                n_trips = f["trip"][sel].nunique()
                line, = ax.plot(x, med, lw=1.5, label=f"{season} ({n_trips} trips)")
                ax.fill_between(x, lo, hi, color=line.get_color(), alpha=0.2)
        return _finish_time_axes(fig, axes, path, "force residual: median over trips per minute since start "
                                 "(band: IQR), before", fontsize=8)
    for k in trips:
        sel = valid & (f["trip"] == k).to_numpy()
        if sel.sum() < 50:
            continue
        t = f["time_since_start"].to_numpy()[sel] / 60
        for ax, r in zip(axes, (f["residual"].to_numpy()[sel], residual_after[sel])):
            ax.plot(t, pd.Series(r).rolling(300, min_periods=30, center=True).median(), lw=1, label=str(k))
    return _finish_time_axes(fig, axes, path, "force residual (30 s rolling median), before", fontsize=7, ncol=4)


def figure_regimes(diag: Diagnosis, path: Path) -> Path:
    """Per regime bin: held-out RMSE before and after."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = pd.DataFrame([p.to_dict() for p in diag.per_regime])
    if rows.empty:
        fig = plt.figure(figsize=(4, 2))
        _save(fig, path)
        return path
    regs = list(pd.unique(rows["regime"]))
    fig, axes = plt.subplots(len(regs), 1, figsize=(10, 1.9 * len(regs)))
    axes = np.atleast_1d(axes)
    for ax, reg in zip(axes, regs):
        sub = rows[rows["regime"] == reg]
        x = np.arange(len(sub))
        ax.bar(x - 0.2, sub["rmse_before"], 0.4, label="before")
        ax.bar(x + 0.2, sub["rmse_after"], 0.4, label="after")
        ax.set_xticks(x)
        ax.set_xticklabels(sub["bin"], fontsize=7)
        ax.set_ylabel(f"{reg}\nRMSE [N]", fontsize=8)
    axes[0].legend(fontsize=8)
    fig.tight_layout()
    _save(fig, path)
    return path


def figure_ranking(diag: Diagnosis, path: Path) -> Path:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rk = diag.ranking
    fig, ax = plt.subplots(figsize=(8, 0.35 * max(len(rk), 3) + 1))
    names = [r.name for r in rk][::-1]
    imp = [100 * r.improvement for r in rk][::-1]
    colors = ["tab:green" if r.significant else "tab:gray" for r in rk][::-1]
    ax.barh(names, imp, color=colors)
    ax.axvline(0, color="k", lw=0.6)
    ax.set_xlabel("held-out MSE reduction alone [%] (green: significant)")
    fig.tight_layout()
    _save(fig, path)
    return path


# ------------------------------------------------------------------------------------------------ report.md
def _fmt(x, nd=1):
    if x is None or (isinstance(x, float) and not np.isfinite(x)):
        return "–"
    return f"{x:.{nd}f}"


def _param_text(params: dict, se: dict, units: dict) -> str:
    return "; ".join(f"{k} = {v:.4g} ± {se.get(k, float('nan')):.2g} {units.get(k, '')}" for k, v in params.items())


def _gap_table(d: Diagnosis) -> list[str]:
    fb, fa, fs = d.gap_before, d.gap_after, d.gap_after_sim
    L = [f"# Sim-to-real diagnosis: {d.sim.name}", ""]
    L += [f"Sim: vehicle `{d.sim.vehicle.name}`, effects {sorted(d.sim.effects.to_dict()['effects']) or 'none'}. "
          f"Trips: {len(d.trips)} ({', '.join(map(str, d.trips[:8]))}{' …' if len(d.trips) > 8 else ''}). "
          f"Held-out part: {d.split.n_test} of {d.split.n_valid} valid samples "
          f"({d.split.n_test_segments} segments of {d.settings.segment_length:g} s); training in "
          f"{d.split.n_folds} CV folds. Sim floor RMS (the sim against its own balance): "
          f"{_fmt(d.floor.scale)} N.", ""]
    L += ["## Gap (held-out)", "", "| measure | before | after (fitted) | after (sim re-run) |", "|---|---|---|---|"]

    def row(name, get, nd=1):
        return f"| {name} | {_fmt(get(fb), nd)} | {_fmt(get(fa), nd)} | {_fmt(get(fs), nd) if fs else '–'} |"
    L += [row("force residual median [N]", lambda g: g.force_residual.median),
          row("force residual MAD [N]", lambda g: g.force_residual.mad),
          row("force residual RMSE [N]", lambda g: g.force_residual.rmse),
          row("force residual MEDSE [N²]", lambda g: g.force_residual.medse, 0),
          row("replay through the simulator, speed RMS [m/s]",
              lambda g: g.replay_simulator.rms if g.replay_simulator else float("nan"), 3),
          row("replay speed error RMS, linearised [m/s]", lambda g: g.replay_speed_error.rms, 3),
          row("traction energy sim vs measured [%]", lambda g: 100 * g.energy_per_distance.relative_error, 2)]
    L += ["", f"Measured traction energy {_fmt(fb.energy_per_distance.measured, 2)} kWh/100 km. "
          f"Shrinkage of the held-out RMSE: {100 * d.shrinkage('rmse'):.0f} % (fitted)"
          + (f", {100 * d.shrinkage('rmse', True):.0f} % (sim re-run with the effects on)" if fs else "") + ".", ""]
    return L


def _where(d: Diagnosis, figures: dict[str, str]) -> list[str]:
    L = ["## Where the gap lies", ""]
    dep = d.notes.strongest_departures_before
    if dep:
        L += ["Regime bins whose median residual departs from 0 (block-bootstrap 95 % interval and notch exclude 0), "
              "largest first:", "", "| regime | bin | share | median [N] | 95 % CI [N] |", "|---|---|---|---|---|"]
        L += [f"| {b.regime} | {b.bin} | {100 * b.share:.0f} % | {_fmt(b.median)} | "
              f"{_fmt(b.ci_low)} … {_fmt(b.ci_high)} |" for b in dep]
    else:
        L += ["No regime bin departs significantly from 0."]
    ra = d.residual_analysis
    strong = sorted(ra.items(), key=lambda kv: -kv[1].max_abs)[:4]
    L += ["", "Residual analysis (eq. 3.4a/3.4b, correlation coefficients, white-noise bound "
          f"±{ra['residual'].bound:.3f}): " + ", ".join(f"{k} {v.max_abs:.2f} at lag {v.lag}"
                                                      for k, v in strong) + ".", ""]
    for key in ("residual_map", "residual_time"):
        if key in figures:
            L += [f"![{key}]({figures[key]})", ""]
    return L


def _physical_text(b) -> tuple[str, str]:
    """(sim value, calibrated value with unit) of a base parameter; the efficiency in traction and regeneration."""
    ph = b.physical
    if ph is None:
        return "–", "–"
    if ph.calibrated_regen is not None:
        text = f"η_t = {ph.calibrated:.3f}, η_r = {ph.calibrated_regen:.3f}"
        return f"η = {ph.sim:.3f}", text + (f" (**{ph.flag}**)" if ph.flag else "")
    return f"{ph.sim:.4g}", f"{ph.calibrated:.4g} {ph.unit}"


def _base_block(d: Diagnosis) -> list[str]:
    base = d.base
    if not base.parameters:
        return []
    L = ["## Base calibration (force side)", "",
         "The sim's base road load fitted to the trips (weighted least squares on the robust residual, "
         "cluster-robust standard errors; significant: |value| >= 2.58 SE and RMS >= "
         f"{_fmt(base.min_size)} N). "
         + ("The effects below are selected over this calibrated base." if base.used_for_effects
            else "Effects are selected over the sim as is (calibrate the sim on reference trips with "
                 "`roadload calibrate`, or use --base-first, for a preset that is not the car)."),
         "", "| base parameter | fitted change | SE | sim | calibrated | RMS [N] | significant |",
         "|---|---|---|---|---|---|---|"]
    for b in base.parameters:
        sim, cal = _physical_text(b)
        L.append(f"| {b.name} | {b.value:+.4g} {b.unit} | {b.std_error:.2g} | {sim} | {cal} | {_fmt(b.size_rms)} | "
                 f"{'yes' if b.significant else 'no'} |")
    return L + [""]


def _energy_base(d: Diagnosis) -> list[str]:
    block = d.energy_base
    if block is None or not block.parameters:
        return []
    L = ["", "### Base calibration (energy side)", "",
         "The battery-power residual fitted on the calibration's energy model: a constant (auxiliary power), the "
         "sim's motor loss P_loss (loss scale), -T_E ω_E (drive-torque signal gain g) and -ω_E (signal offset); "
         f"significant: |value| >= 2.58 SE and RMS >= {_fmt(block.min_size)} W.",
         "", "| base parameter | fitted change | SE | RMS [W] | significant |", "|---|---|---|---|---|"]
    L += [f"| {b.name} | {b.value:+.4g} {b.unit} | {b.std_error:.2g} | {_fmt(b.size_rms)} | "
          f"{'yes' if b.significant else 'no'} |" for b in block.parameters]
    return L


def _per_trip(d: Diagnosis, e) -> list[str]:
    """The per-trip sizes of an accepted effect next to the trips' metadata."""
    pt = e.per_trip
    if pt is None:
        return []
    info = {t.trip: t for t in d.trip_info}
    params = list(pt.mean)
    verdict = ("differ more than chance" if pt.differ else "do not differ more than chance")
    mean = ", ".join(f"{k} = {v:.4g} {pt.units.get(k, '')}" for k, v in pt.mean.items())
    L = ["", f"  Per trip (the sizes {verdict}: Wald χ² = {pt.chi2:.1f}, {pt.dof} dof, p = {pt.p_value:.2g}; "
         f"mean {mean}):", "",
         "  | trip | " + " | ".join(params) + " | date | ambient [°C] | payload [kg] | note |",
         "  |---|" + "---|" * (len(params) + 4)]
    for s in pt.sizes:
        t = info.get(s.trip)
        meta = (f"{t.date} | {_fmt(t.ambient_c)} | {_fmt(t.payload_kg, 0)} | {t.note}" if t else " | | | ")
        L.append(f"  | {s.trip} | " + " | ".join(f"{s.values[p]:.4g} ± {s.std_errors[p]:.2g}" for p in params)
                 + f" | {meta} |")
    return L


def _which(d: Diagnosis, figures: dict[str, str]) -> list[str]:
    L = ["## Which effect", "", "Candidates alone (fitted on training, judged out-of-fold on the robust, "
         "regime-normalised loss; null p from the wild block bootstrap):", "",
         "| candidate | held-out gain | null p | significant | ΔAIC | ΔBIC | explained share | parameters |",
         "|---|---|---|---|---|---|---|---|"]
    for r in d.ranking:
        L.append(f"| {r.name} | {100 * r.improvement:.1f} % | {_fmt(r.null_p, 3)} | "
                 f"{'yes' if r.significant else 'no'} | "
                 f"{_fmt(r.delta_aic, 0)} | {_fmt(r.delta_bic, 0)} | {_fmt(r.explained_fraction, 2)} | "
                 f"{_param_text(r.parameters, r.std_errors, r.units)} |")
    if d.skipped:
        L += ["", "Not fitted: " + "; ".join(f"{k} ({v})" for k, v in d.skipped.items()) + "."]
    L += ["", "Greedy forward selection:", ""]
    L += [f"{s.step}. {s.effect}: robust out-of-fold loss {s.robust_loss_before:.3f} → "
          f"{s.robust_loss_after:.3f} of the sim as is ({100 * s.gain_of_original:.1f} % gain; null p = "
          f"{s.null_p:.3f}, null {100 * (1 - d.settings.alpha):.0f} % quantile {100 * s.null_quantile:.1f} %; "
          f"fitted effect RMS {_fmt(s.size_rms)}), {s.reason}" for s in d.selection]
    for imp in d.notes.implausible:
        L += [f"- not accepted, implausible fit: **{imp.effect}**: {imp.reason}"]
    if "ranking" in figures:
        L += ["", f"![ranking]({figures['ranking']})"]
    L += ["", "## Identified effects", ""]
    if d.effects:
        for e in d.effects:
            L += [f"- **{e.name}** ({e.description}): {_param_text(e.parameters, e.std_errors, e.units)}"
                  + (f", {e.shape_name} = {e.shape:g} {e.shape_unit}" if e.shape is not None else "")
                  + f"; simulator switch `{e.sim_switch}` {e.sim_parameters}"]
            L += _per_trip(d, e)
    else:
        L += [f"None on the force side: {why_none(d, 'force')}"]
    return L


def _how_far(d: Diagnosis, figures: dict[str, str]) -> list[str]:
    L = ["", "## How far it shrinks, per regime (held-out RMSE)", "", "| regime | bin | n | before [N] | after [N] | "
         "remaining |", "|---|---|---|---|---|---|"]
    for p in d.per_regime:
        L.append(f"| {p.regime} | {p.bin} | {p.n} | {_fmt(p.rmse_before)} | {_fmt(p.rmse_after)} | "
                 f"{_fmt(100 * p.remaining, 0)} % |")
    if "regimes" in figures:
        L += ["", f"![regimes]({figures['regimes']})"]
    return L


def _energy(d: Diagnosis) -> list[str]:
    en = d.energy
    if not en:
        return []
    ee = en.electric_energy_per_distance
    before, after = en.power_residual_before, en.power_residual_after
    L = ["", "## Energy side (traction battery)", "",
         f"Battery energy while moving: measured {_fmt(ee.measured, 2)}, sim {_fmt(ee.sim_before, 2)}, "
         f"sim with the identified auxiliary effects {_fmt(ee.sim_after, 2)} kWh/100 km. Power residual "
         f"median {_fmt(before.median, 0)} → {_fmt(after.median, 0)} W, "
         f"RMSE {_fmt(before.rmse, 0)} → {_fmt(after.rmse, 0)} W.", ""]
    L += [f"- {r.name}: held-out gain {100 * r.improvement:.1f} %, "
          f"{_param_text(r.parameters, r.std_errors, r.units)}" for r in en.ranking]
    L += [f"{s.step}. {s.effect}: {100 * s.gain_of_original:.1f} % gain, null p = {s.null_p:.3f}, fitted effect RMS "
          f"{_fmt(s.size_rms, 0)} W: {s.reason}" for s in en.forward_selection]
    L += ["", "Accepted: " + (", ".join(e.name for e in en.effects) or f"none ({why_none(d, 'energy')})") + "."]
    for e in en.effects:
        L += [f"- **{e.name}** ({e.description}): {_param_text(e.parameters, e.std_errors, e.units)}"]
        L += _per_trip(d, e)
    return L + _energy_base(d)


def _unexplained(d: Diagnosis) -> list[str]:
    un = d.unexplained
    L = ["", "## Unexplained residual", ""]
    if not un.present:
        return L + ["None significant."]
    L += [f"Held-out RMS after the identified effects: {_fmt(un.rms_after)} N."]
    if un.departing_bins:
        L += ["Still departing from 0 (not forced onto a candidate):", ""]
        L += [f"- {b.regime} {b.bin}: median {_fmt(b.median)} N (95 % CI {_fmt(b.ci_low)} … "
              f"{_fmt(b.ci_high)}, {100 * b.share:.0f} % of the held-out samples)" for b in un.departing_bins]
    rg = un.reference_gain
    if rg.significant:
        L += ["", f"A regime-only reference model still removes {100 * rg.relative:.1f} % of the original "
              f"held-out MSE; its strongest regime variables: "
              + ", ".join(f"{i.column} (strongest bin {i.strongest_bin}, {i.strongest_effect:.0f} N)"
                          for i in un.reference_importance[:3]) + "."]
    return L


def why_none(d: Diagnosis, side: str = "force") -> str:
    """Why a side accepted nothing, in a sentence: the first selection step's reason, or that no candidate was
    significant alone (the best one's gain and null p), and the significant base departures that say the sim is
    not the car."""
    en = d.energy
    steps = d.selection if side == "force" else (en.forward_selection if en else [])
    ranking = d.ranking if side == "force" else (en.ranking if en else [])
    block = d.base if side == "force" else d.energy_base
    if side == "energy" and en is None:
        return "no battery power on the trips"
    if steps:
        why = f"the best candidate, {steps[0].effect}, was not accepted: {steps[0].reason}"
    elif ranking:
        best = ranking[0]
        why = (f"no candidate was significant alone (best: {best.name}, held-out gain {100 * best.improvement:.1f} %,"
               f" null p = {best.null_p:.3f}, fitted RMS {_fmt(best.size, 0)})")
    else:
        why = "no candidate could be fitted on these trips"
    departing = [p.name for p in (block.parameters if block else []) if p.significant]
    if departing and not (block and block.used_for_effects):
        why += (f"; the base block departs significantly ({', '.join(departing)}): the sim is not the car - "
                "calibrate it on reference trips (roadload calibrate) and diagnose against the calibration")
    return why


def markdown(diag: Diagnosis, figures: dict[str, str]) -> str:
    """report.md: the gap, where it lies, the base block, which effect, how far it shrinks, the energy side and the
    unexplained residual."""
    sections = (_gap_table(diag), _where(diag, figures), _base_block(diag), _which(diag, figures),
                _how_far(diag, figures), _energy(diag), _unexplained(diag))
    return "\n".join(line for section in sections for line in section) + "\n"


def write_report(diag: Diagnosis, out: str | os.PathLike) -> dict[str, Path]:
    """diagnosis.json, report.md and the figures into folder ``out``; returns the paths."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    figs = {"residual_map": figure_residual_map(diag, out / "residual_map.png"),
            "residual_time": figure_residual_time(diag, out / "residual_time.png"),
            "regimes": figure_regimes(diag, out / "regimes.png"),
            "ranking": figure_ranking(diag, out / "ranking.png")}
    paths = {"json": write_json(diag, out / "diagnosis.json"), **figs}
    text = markdown(diag, {k: p.name for k, p in figs.items()})

    def w(tmp):
        Path(tmp).write_text(text)
    _atomic_write(out / "report.md", w)
    paths["report"] = out / "report.md"
    return paths


# ------------------------------------------------------------------------------------------------ calibration
def calibration_paths(out: str | os.PathLike) -> dict[str, Path]:
    """The files :func:`write_calibration` writes for ``--out calibrated.json``: the spec itself, and beside it
    ``calibrated_sim.json`` (a sim config: the spec at the reference trips' ambient temperature),
    ``calibrated_calibration.json`` (the record), ``calibrated_calibration.md`` (the report) and
    ``calibrated_residual.png`` (the figure)."""
    spec = Path(out)
    if spec.suffix.lower() != ".json":
        raise DiagnosisError(f"--out: the calibrated sim is a JSON vehicle spec, so the name ends in .json; "
                             f"got {spec.name!r}")
    stem = spec.with_suffix("")
    return {"spec": spec, "sim": Path(f"{stem}_sim.json"), "json": Path(f"{stem}_calibration.json"),
            "report": Path(f"{stem}_calibration.md"), "figure": Path(f"{stem}_residual.png")}


def figure_calibration_bins(cal, path: Path) -> Path:
    """Median force residual per speed x acceleration bin on the held-out rows, before and after calibration."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    bins = pd.DataFrame([b.to_dict() for b in cal.bins])
    fig, axes = plt.subplots(1, 2, figsize=(11, 4.2), sharey=True)
    if bins.empty:
        _save(fig, path)
        return path
    speeds = list(dict.fromkeys(bins["speed"]))
    accels = list(dict.fromkeys(bins["acceleration"]))
    maps = []
    for col in ("median_before", "median_after"):
        m = np.full((len(accels), len(speeds)), np.nan)
        for _, row in bins.iterrows():
            m[accels.index(row["acceleration"]), speeds.index(row["speed"])] = row[col]
        maps.append(m)
    lim = float(np.nanmax(np.abs(maps[0]))) if np.isfinite(maps[0]).any() else 1.0
    for ax, m, title in zip(axes, maps, (f"sim as is ({cal.sim})", "calibrated sim")):
        im = ax.imshow(m, cmap="RdBu_r", vmin=-lim, vmax=lim, aspect="auto", origin="lower")
        ax.set_title(f"median force residual, {title}", fontsize=9)
        ax.set_xticks(range(len(speeds)), speeds, rotation=30, ha="right", fontsize=7)
        ax.set_xlabel("speed")
    axes[0].set_yticks(range(len(accels)), accels, fontsize=7)
    axes[0].set_ylabel("acceleration")
    fig.colorbar(im, ax=axes, label="N (held-out rows)")
    _save(fig, path)
    return path


def calibration_markdown(cal, figure: str | None = None) -> str:
    """The calibration report: parameters with units, uncertainty and physical range; the held-out gap."""
    h = cal.heldout
    L = [f"# Calibration of {cal.sim} on {len(cal.trips)} reference trips", "",
         f"Trips: {', '.join(cal.trips)}.", "",
         "| parameter | sim | calibrated | ± SE | unit | prior SD (change) | physical range | fitted change | "
         "determined by the trips | flag |", "|---|---|---|---|---|---|---|---|---|---|"]
    for p in cal.parameters:
        L.append(f"| {p.description} | {p.sim:.4g} | {p.calibrated:.4g} | {p.calibrated_std:.2g} | {p.value_unit} | "
                 f"{p.prior_std:.2g} {p.unit} | [{p.low:g}, {p.high:g}] | {p.symbol} = {p.delta:+.4g} "
                 f"± {p.std_error:.2g} {p.unit} | {'yes' if p.determined else 'no (the prior)'} | {p.flag} |")
    L += ["", "Held-out gap (the reference trips' held-out segments re-run against each sim, its own floor):", "",
          "| residual | sim as is | calibrated | shrinkage |", "|---|---|---|---|",
          f"| force RMSE [N] | {_fmt(h.force_before)} | {_fmt(h.force_after)} | {_fmt(100 * h.force_shrinkage, 0)} % |",
          f"| battery power RMSE [W] | {_fmt(h.power_before, 0)} | {_fmt(h.power_after, 0)} | "
          f"{_fmt(100 * h.power_shrinkage, 0)} % |",
          f"| battery power median [W] | {_fmt(h.power_median_before, 0)} | {_fmt(h.power_median_after, 0)} | – |"]
    if cal.notes:
        L += ["", "Notes:", ""] + [f"- {n}" for n in cal.notes]
    if figure:
        L += ["", f"![median force residual per speed and acceleration bin]({figure})"]
    return "\n".join(L) + "\n"


def write_calibration(cal, out: str | os.PathLike) -> dict[str, Path]:
    """The calibrated vehicle spec (``out``, a vehicle JSON every roadload tool reads), the calibration record,
    its report and the residual figure beside it (:func:`calibration_paths`); each file atomically."""
    paths = calibration_paths(out)
    fileio.write_json(paths["spec"], cal.spec.to_dict())
    held = {"held_at_bound": cal.held_at_bound} if cal.held_at_bound else {}
    fileio.write_json(paths["sim"], {"vehicle": paths["spec"].name, "effects": cal.sim_config.effects.to_dict(),
                                     "name": cal.sim_config.name, **held})
    fileio.write_json(paths["json"], {"calibrated_spec": paths["spec"].name, **jsonable(cal.to_dict())})
    figure_calibration_bins(cal, paths["figure"])
    fileio.write_text(paths["report"], calibration_markdown(cal, paths["figure"].name))
    return paths
