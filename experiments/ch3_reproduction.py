"""Reproduce the experiments of chapter 3 (Rhode 2018) over many seeds; print tables, write figures.

Experiments 3.1/3.2 (straight lines with an outlier / leverage point), 3.3 (RLS, RLM, LM-RRLM, Tikhonov-RRLM),
3.4 (RRLM vs RRIVM under input noise, plus the k = 1000 validation MSE), 3.6 (RRIVM vs RIVMKF on a random-walk
X̄_3) and 3.7 (PKS vs 41-tap moving average vs Savitzky-Golay). Each runs over --seeds seeds (default 20) and
reports the median and the interquartile range, and how many seeds follow the text's ranking.

Settings the text does not give are fixed here before looking at any result and printed with the tables:
X̂_0 = 0, P_0 = 100 I (section 5.5 convention), σ̂_0 = 1, Q̂_0 = 1, η = 0.01, σ̂² forgetting = λ.

Usage: python scripts/reproduce_ch3.py [--seeds 20] [--out out/ch3] [--only 3.3,3.4]
"""

from __future__ import annotations

import argparse
import time
from typing import Any
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from scipy.signal import savgol_filter  # noqa: E402

import roadload.estimators as E  # noqa: E402
from roadload.estimators.synthetic import linear_miso, straight_line  # noqa: E402
from roadload.fileio import save_figure

ROBUST: dict[str, Any] = dict(robust_scale=True, scale0=1.0, quantile0=1.0, learn_rate=0.01, p0=100.0)
LAMBDA = 0.995


def q(values) -> str:
    """median [25 %, 75 %] of a sample."""
    v = np.asarray(values, dtype=float)
    lo, med, hi = np.nanpercentile(v, [25, 50, 75])
    return f"{med:9.4g} [{lo:.3g}, {hi:.3g}]"


def save(fig, path: Path) -> None:
    """Atomic PNG write."""
    save_figure(fig, path, dpi=110)


# ------------------------------------------------------------------------------------------ 3.1 / 3.2
def exp_3_1(seeds: int, out: Path) -> dict:
    print("\n=== Experiments 3.1/3.2: straight line B = 3 A, 7 points, noise std 1 ===")
    fits = {
        "LS": E.least_squares,
        "M-Huber": lambda A, B: E.m_estimate(A, B, "huber"),
        "M-Myriad": lambda A, B: E.m_estimate(A, B, "myriad"),
        "LMS": E.least_median_of_squares,
        "LTS": E.least_trimmed_squares,
    }
    cases: list[tuple[str, dict[str, float]]] = [("clean", {}), ("outlier", {}), ("good_leverage", {})] + [
        ("bad_leverage", {"bad_leverage_at": p}) for p in (10.0, 15.0, 20.0, 30.0, 50.0)]
    print(f"median |X̂ - 3| [IQR] over {seeds} seeds")
    print(f"{'case':<22s}" + "".join(f"{k:>28s}" for k in fits))
    table = {}
    for case, kw in cases:
        label = case + (f" A4={kw['bad_leverage_at']:g}" if kw else "")
        errs = {k: [abs(f(*straight_line(case, s, **kw)[:2]).X[0] - 3.0) for s in range(seeds)]
                for k, f in fits.items()}
        table[label] = {k: float(np.median(v)) for k, v in errs.items()}
        print(f"{label:<22s}" + "".join(f"{q(v):>28s}" for v in errs.values()))
    fig, axes = plt.subplots(1, 4, figsize=(16, 4))
    for ax, (case, kw) in zip(axes, [("clean", {}), ("outlier", {}), ("bad_leverage", {"bad_leverage_at": 30.0}),
                                     ("good_leverage", {})]):
        A, B, _ = straight_line(case, 0, **kw)
        ax.plot(A[:, 0], B, "o", color="k")
        xs = np.linspace(0, A.max() * 1.05, 10)
        for k, f in fits.items():
            ax.plot(xs, f(A, B).X[0] * xs, label=f"{k}")
        ax.plot(xs, 3 * xs, "k:", label="truth")
        ax.set_title(case + (f" (A4={kw['bad_leverage_at']:g})" if kw else ""))
        ax.set_xlabel("A")
    axes[0].set_ylabel("B")
    axes[0].legend(fontsize=7)
    save(fig, out / "fig_3_4_3_6_straight_lines.png")
    u = np.linspace(-5, 5, 501)
    fig, axes = plt.subplots(1, 3, figsize=(14, 4))
    for name in ("l2", "huber", "myriad", "cauchy", "tukey", "hampel"):
        for ax, fn in zip(axes, (E.rho, E.psi, E.weight)):
            ax.plot(u, fn(u, name), label=name)
    for ax, title in zip(axes, ("ρ(u)", "ψ(u)", "W(u) = ψ(u)/u")):
        ax.set_title(title)
        ax.set_xlabel("u = ΔB/σ̂")
    axes[0].set_ylim(0, 6)
    axes[1].set_ylim(-3, 3)
    axes[0].legend()
    save(fig, out / "fig_3_5_influence_functions.png")
    return table


# ------------------------------------------------------------------------------------------ 3.3
def _run_seeds(name: str, datas, **settings) -> E.EstimationResult:
    """One configuration over all seeds at once (many-trips path)."""
    cfg = E.make_config(name, n_params=3, **settings)
    A = np.stack([d.A for d in datas])
    B = np.stack([d.B for d in datas])
    return E.run_many(cfg, A, B)


def exp_3_3(seeds: int, out: Path) -> dict:
    summary = {}
    for literal in (False, True):
        label = ("5 % outliers in every column, also in A2 while unexcited" if literal else
                 "A2 exactly constant (0, no outliers) 1000-6000 s")
        summary[label] = _exp_3_3(seeds, out, literal, label)
    return summary


def _exp_3_3(seeds: int, out: Path, literal: bool, label: str) -> dict:
    print(f"\n=== Experiment 3.3: output noise var 0.1, 5 % outliers in A and B, λ = 0.995, robust scale on;\n"
          f"    data variant: {label} ===")
    datas = [linear_miso(seed=s, outliers_in_unexcited=literal) for s in range(seeds)]
    Xt = np.stack([d.X_true for d in datas])
    tag = "literal" if literal else "constant"
    variants: dict[str, tuple[str, dict[str, Any]]] = {
        "RLS": ("RLS", dict(forgetting=LAMBDA, **ROBUST, scale_forgetting=LAMBDA)),
        "RLM": ("RLM", dict(forgetting=LAMBDA, **ROBUST, scale_forgetting=LAMBDA)),
        "LM-RRLM k=0.1": ("RRLM", dict(forgetting=LAMBDA, kappa=0.1, **ROBUST, scale_forgetting=LAMBDA)),
        "Tik-RRLM k=0.001": ("RRLM", dict(forgetting=LAMBDA, kappa=1e-3, regularisation="tikhonov", **ROBUST,
                                          scale_forgetting=LAMBDA)),
    }
    # full storage: every array of the results is present
    res: dict[str, Any] = {k: _run_seeds(n, datas, **s) for k, (n, s) in variants.items()}
    sev = {k: E.sevn(Xt, r.X) for k, r in res.items()}
    t = datas[0].t
    w_all = t >= 100
    w_wind = (t >= 5000) & (t < 6000)
    w_unex = (t >= 3000) & (t < 6000)
    print(f"per-seed mean SEVN, median [IQR] over {seeds} seeds")
    print(f"{'estimator':<18s} {'SEVN t>=100':>30s} {'SEVN 5000-6000':>30s} {'mean X2 3000-6000':>30s} "
          f"{'max P22 (blow-up seeds)':>26s}")
    summary = {}
    for k, r in res.items():
        s_all = sev[k][:, w_all].mean(axis=1)
        s_w = sev[k][:, w_wind].mean(axis=1)
        x2 = r.X[:, w_unex, 1].mean(axis=1)
        pmax = r.P_diag[:, :, 1].max(axis=1)
        summary[k] = dict(sevn=s_all, wind=s_w, x2=x2, pmax=pmax, blow=r.p_blowup)
        print(f"{k:<18s} {q(s_all):>30s} {q(s_w):>30s} {q(x2):>30s} {np.median(pmax):14.3g} "
              f"({int(r.p_blowup.sum())}/{seeds})")

    def wins(a, b, key="sevn"):
        return int(np.sum(summary[a][key] < summary[b][key]))
    print("rankings (seeds where the first has the lower per-seed mean SEVN):")
    print(f"  RLM < RLS: {wins('RLM', 'RLS')}/{seeds}; LM-RRLM < RLM: {wins('LM-RRLM k=0.1', 'RLM')}/{seeds}; "
          f"LM-RRLM < Tik-RRLM: {wins('LM-RRLM k=0.1', 'Tik-RRLM k=0.001')}/{seeds}; "
          f"Tik-RRLM < RLM: {wins('Tik-RRLM k=0.001', 'RLM')}/{seeds}")
    print(f"  wind-up window 5000-6000 s: LM-RRLM < RLM in {wins('LM-RRLM k=0.1', 'RLM', 'wind')}/{seeds} seeds")
    # figures for seed 0
    fig, axes = plt.subplots(2, 2, figsize=(13, 8), sharex=True)
    for ax, (k, r) in zip(axes.ravel(), res.items()):
        ax.plot(t, r.X[0], lw=0.8)
        ax.plot(t, Xt[0], "k-", lw=0.8)
        ax.set_ylim(-2, 5)
        ax.set_title(f"{k} (seed 0)")
    axes[1, 0].set_xlabel("t [s]")
    save(fig, out / f"fig_3_8_parameters_{tag}.png")
    fig, ax = plt.subplots(figsize=(10, 4))
    for k in res:
        ax.semilogy(t, np.median(sev[k], axis=0), label=k, lw=0.8)
    ax.set_xlabel("t [s]")
    ax.set_ylabel(f"median SEVN over {seeds} seeds")
    ax.legend()
    save(fig, out / f"fig_3_9_sevn_{tag}.png")
    r = res["LM-RRLM k=0.1"]
    fig, axes = plt.subplots(2, 1, figsize=(10, 6), sharex=True)
    axes[0].plot(t, r.scale[0], lw=0.8)
    axes[0].axhline(np.sqrt(0.1), color="k", ls=":", label="noise std")
    axes[0].set_ylabel("σ̂ [-]")
    axes[0].legend()
    axes[1].plot(t, r.weights[0], ".", ms=1)
    axes[1].set_ylabel("W")
    axes[1].set_xlabel("t [s]")
    save(fig, out / f"fig_3_10_scale_weight_{tag}.png")
    return summary


# ------------------------------------------------------------------------------------------ 3.4
def t_all(datas) -> np.ndarray:
    return datas[0].t


def exp_3_4(seeds: int, out: Path) -> dict:
    res = {}
    for frac in (0.05, 0.0):
        res[frac] = _exp_3_4(seeds, out, frac)
    return res


def _exp_3_4(seeds: int, out: Path, frac: float) -> dict:
    print(f"\n=== Experiment 3.4: diag P̃ = [0 0.005 0.01 0.02], {frac:.0%} outliers, λ = 0.995, κ = 0.1, Huber ===")
    kw: dict[str, Any] = dict(input_noise_var=(0.0, 0.005, 0.01), output_noise_var=0.02, outlier_fraction=frac)
    datas = [linear_miso(seed=100 + s, **kw) for s in range(seeds)]
    Xt = np.stack([d.X_true for d in datas])
    base = dict(forgetting=LAMBDA, kappa=0.1, **ROBUST, scale_forgetting=LAMBDA)
    res: dict[str, Any] = {"LM-RRLM": _run_seeds("RRLM", datas, **base),
           "LM-RRIVM A(t-2)": _run_seeds("RRIVM", datas, instrument_delay=2, **base)}
    t = datas[0].t
    late = t >= 7000
    print(f"{'estimator':<16s} {'SEVN t>=100':>30s} {'mean X3 t>=7000 (3)':>30s} {'mean X2 1000-6000 (2)':>30s} "
          f"{'val. MSE k=1000':>30s} {'val. MSE vs true B':>30s}")
    summary = {}
    split = 9000
    for k, r in res.items():
        s_all = E.sevn(Xt, r.X)[:, t >= 100].mean(axis=1)
        x3 = r.X[:, late, 2].mean(axis=1)
        x2 = r.X[:, (t >= 1000) & (t < 6000), 1].mean(axis=1)
        mse_meas, mse_true = [], []
        for d, X in zip(datas, r.X):
            xs = X[split - 1]
            val = (d.t > split) & ~d.any_outlier
            mse_meas.append(E.mse(d.B[val], d.A[val] @ xs))
            mse_true.append(E.mse(d.B_true[val], d.A_true[val] @ xs))
        summary[k] = dict(sevn=s_all, x3=x3, x2=x2, mse=np.array(mse_meas), mse_true=np.array(mse_true))
        print(f"{k:<16s} {q(s_all):>30s} {q(x3):>30s} {q(x2):>30s} {q(mse_meas):>30s} {q(mse_true):>30s}")
    a, b = summary["LM-RRIVM A(t-2)"], summary["LM-RRLM"]
    print(f"RRIVM lower SEVN in {int(np.sum(a['sevn'] < b['sevn']))}/{seeds} seeds; "
          f"|X3 - 3| smaller for RRIVM in {int(np.sum(abs(a['x3'] - 3) < abs(b['x3'] - 3)))}/{seeds}; "
          f"validation MSE (measured A, B) lower for RRLM in {int(np.sum(b['mse'] < a['mse']))}/{seeds}; "
          f"vs true output with true inputs lower for RRIVM in {int(np.sum(a['mse_true'] < b['mse_true']))}/{seeds}")
    # RGTLS (Algorithm 3.8, neither robust nor regularised), with the true P̃ and with the NCE
    rgtls: tuple[tuple[str, dict[str, Any]], ...] = (("RGTLS P̌ = P̃", {}), ("RGTLS + NCE", dict(nce=True)))
    for label, extra in rgtls:
        runs: list[Any] = [E.run("RGTLS", d.A, d.B, forgetting=LAMBDA, noise_covariance=[0.0, 0.005, 0.01, 0.02],
                                  **extra) for d in datas]
        X = np.stack([r.X for r in runs])
        print(f"{label:<16s} SEVN t>=100: {q(E.sevn(Xt, X)[:, t_all(datas) >= 100].mean(axis=1))}")
    _two_estimator_figure(res, t, Xt, out / f"fig_3_14_rrlm_rrivm_{int(frac * 100)}pct.png")
    return summary


def _two_estimator_figure(res, t, Xt, path) -> None:
    """Seed-0 parameter traces of two estimators against the truth, and their median SEVN over seeds."""
    fig, axes = plt.subplots(1, 3, figsize=(16, 4))
    for ax, (k, r) in zip(axes, res.items()):
        ax.plot(t, r.X[0], lw=0.8)
        ax.plot(t, Xt[0], "k-", lw=0.8)
        ax.set_ylim(-2, 5)
        ax.set_title(f"{k} (seed 0)")
    for k, r in res.items():
        axes[2].semilogy(t, np.median(E.sevn(Xt, r.X), axis=0), label=k, lw=0.8)
    axes[2].legend()
    axes[2].set_title("median SEVN")
    save(fig, path)


# ------------------------------------------------------------------------------------------ 3.6
def exp_3_6(seeds: int, out: Path) -> dict:
    print("\n=== Experiment 3.6: X̄_3 random walk (σ = 1e-4), P̃ as in 3.4, instruments A(t-2), R = 0.02 ===")
    kw: dict[str, Any] = dict(input_noise_var=(0.0, 0.005, 0.01), output_noise_var=0.02, random_walk_std=1e-4)
    datas = [linear_miso(seed=200 + s, **kw) for s in range(seeds)]
    Xt = np.stack([d.X_true for d in datas])
    res: dict[str, Any] = {
        "LM-RRIVM": _run_seeds("RRIVM", datas, forgetting=LAMBDA, kappa=0.1, instrument_delay=2, **ROBUST,
                               scale_forgetting=LAMBDA),
        "LM-RIVMKF": _run_seeds("RIVMKF", datas, process_noise=[1e-6, 1e-8, 1e-5], output_noise=0.02, kappa=0.1,
                                instrument_delay=2, **ROBUST, scale_forgetting=LAMBDA),
    }
    t = datas[0].t
    summary = {}
    print(f"{'estimator':<12s} {'SEVN t>=100':>30s} {'SEVN of X3 only':>30s}")
    for k, r in res.items():
        s_all = E.sevn(Xt, r.X)[:, t >= 100].mean(axis=1)
        s3 = ((Xt[:, :, 2] - r.X[:, :, 2]) ** 2)[:, t >= 100].mean(axis=1)
        summary[k] = dict(sevn=s_all, sevn3=s3)
        print(f"{k:<12s} {q(s_all):>30s} {q(s3):>30s}")
    a, b = summary["LM-RIVMKF"], summary["LM-RRIVM"]
    print(f"RIVMKF lower SEVN in {int(np.sum(a['sevn'] < b['sevn']))}/{seeds} seeds, lower X3 error in "
          f"{int(np.sum(a['sevn3'] < b['sevn3']))}/{seeds}")
    ok = (a["sevn"] < 1.0) & (b["sevn"] < 1.0)
    print(f"diverged (per-seed mean SEVN > 1): RIVMKF {int(np.sum(a['sevn'] >= 1))}/{seeds}, RRIVM "
          f"{int(np.sum(b['sevn'] >= 1))}/{seeds}; on the {int(ok.sum())} seeds where neither diverged: "
          f"RIVMKF lower SEVN in {int(np.sum(a['sevn'][ok] < b['sevn'][ok]))}, lower X3 error in "
          f"{int(np.sum(a['sevn3'][ok] < b['sevn3'][ok]))}")
    drift = np.abs(Xt[:, -1, 2] - Xt[:, 0, 2])
    print(f"|X̄3(end) - X̄3(start)| of the random walk: {q(drift)}")
    _two_estimator_figure(res, t, Xt, out / "fig_3_15_rrivm_rivmkf.png")
    return summary


# ------------------------------------------------------------------------------------------ 3.7
def exp_3_7(seeds: int, out: Path) -> dict:
    print("\n=== Experiment 3.7: smoothing B of section 3.5.6 without outliers (noise var 0.1) ===")
    w = 20
    rows: dict[str, list[float]] = {"PKS λ=0.9 w=20 5 par.": [], "moving average 41 taps": [],
                                    "Savitzky-Golay 41/4": []}
    rows_meas: dict[str, list[float]] = {k: [] for k in rows}
    for s in range(seeds):
        d = linear_miso(seed=300 + s, outlier_fraction=0.0)
        pks = E.pks_bank({"B": d.B}, window=w, order=4, forgetting=0.9).aligned("B")
        fir = np.convolve(d.B, np.ones(2 * w + 1) / (2 * w + 1), mode="same")
        sgf = savgol_filter(d.B, 2 * w + 1, 4)
        sl = slice(200, d.B.size - 2 * w)
        for k, est in zip(rows, (pks, fir, sgf)):
            rows[k].append(E.mse(d.B_true[sl], est[sl]))
            rows_meas[k].append(E.mse(d.B[sl], est[sl]))
        if s == 0:
            fig, ax = plt.subplots(figsize=(12, 4))
            tt = slice(3000, 3400)
            ax.plot(d.t[tt], d.B[tt], ".", ms=2, color="0.6", label="B")
            ax.plot(d.t[tt], d.B_true[tt], "k", lw=1, label="B̄")
            for k, est in zip(rows, (pks, fir, sgf)):
                ax.plot(d.t[tt], est[tt], lw=1, label=k)
            ax.legend(fontsize=8)
            ax.set_xlabel("t [s]")
            save(fig, out / "fig_3_16_pks.png")
    print(f"{'filter':<26s} {'MSE vs true B̄':>30s} {'MSE vs measured B':>30s}")
    for k in rows:
        print(f"{k:<26s} {q(rows[k]):>30s} {q(rows_meas[k]):>30s}")
    a = np.array(rows["PKS λ=0.9 w=20 5 par."])
    print(f"PKS < moving average in {int(np.sum(a < np.array(rows['moving average 41 taps'])))}/{seeds} seeds; "
          f"PKS < Savitzky-Golay in {int(np.sum(a < np.array(rows['Savitzky-Golay 41/4'])))}/{seeds}")
    return {k: np.array(v) for k, v in rows.items()}


EXPERIMENTS = {"3.1": exp_3_1, "3.3": exp_3_3, "3.4": exp_3_4, "3.6": exp_3_6, "3.7": exp_3_7}


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=20)
    ap.add_argument("--out", type=Path, default=None, help="output folder (default out/ch3; --quick: out/ch3_quick)")
    ap.add_argument("--only", type=str, default=",".join(EXPERIMENTS))
    ap.add_argument("--quick", action="store_true", help="tiny run for CI: 1 seed, output in out/ch3_quick unless "
                                                         "--out is given")
    args = ap.parse_args(argv)
    if args.quick:
        args.seeds = 1
    if args.out is None:
        args.out = Path("out/ch3_quick" if args.quick else "out/ch3")
    print(f"settings not given by the text: X̂_0 = 0, P_0 = 100 I, σ̂_0 = 1, Q̂_0 = 1, η = 0.01, "
          f"σ̂² forgetting = λ; figures in {args.out}/")
    for key in args.only.split(","):
        t0 = time.perf_counter()
        EXPERIMENTS[key.strip()](args.seeds, args.out)
        print(f"({time.perf_counter() - t0:.1f} s)")
    print(f"figures and tables in {args.out}")
