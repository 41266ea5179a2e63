"""Samples per second of the recursive estimators (4 parameters) on this machine; prints a table.

Measured in one run, on the same data (records of 20 000 samples by default — short runs, best of many
interleaved repeats, so that a shared machine disturbs the figures least — three sine
inputs and a constant as regressors, output noise and 5 % outliers):

- a hand-written compiled 4-parameter RLS loop (numba, fixed n = 4, storing X̂_t) — the reference;
- the batch path ``RecursiveEstimator.run`` with store='x' (X̂_t only), 'full' (X̂, diag P, residuals,
  weights, scale) and 'final' (state only) for RLS, RRLM with robust scale, SGMKF and SGIVMKF;
- the online API (``update`` per sample);
- the many-trips path ``run_many`` (trips x samples/s, store='x') with 1 and 2 worker threads;
- RGTLS (Algorithm 3.8, fixed P̌ and with the noise covariance estimator, store='full') and a PKS bank smoothing
  four channels (the chapter-5 pipeline's smoother: order 2, w = 50, λ = 0.98).

Usage: python scripts/bench_estimators.py [--samples 20000] [--repeats 30] [--trips 8] [--quick]
       python scripts/bench_estimators.py --compare main [--rounds 3]   # old commit vs working tree

``--compare REF`` exports commit REF (``git archive``, :mod:`.refcompare`) into a temporary package tree, runs
this module on it and on the working tree interleaved ``--rounds`` times, and prints new/old ratios of each
figure relative to the hand-written loop of its own run (> 1: the working tree is faster). This file runs
against an old package tree too: it imports from roadload only what every commit has.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import time
from collections.abc import Callable
from typing import Any
from pathlib import Path

import numba
import numpy as np
from numba import njit
from roadload.estimators import make_config, make_estimator, run_many


@njit(cache=True)
def hand_rls4(A, B, lam, X, P, out):
    """Reference: plain RLS (Algorithm 3.1) for exactly 4 parameters, P kept symmetric, X̂_t stored."""
    T = B.shape[0]
    Pa = np.empty(4)
    L = np.empty(4)
    il = 1.0 / lam
    for t in range(T):
        a0 = A[t, 0]
        a1 = A[t, 1]
        a2 = A[t, 2]
        a3 = A[t, 3]
        for i in range(4):
            Pa[i] = P[i, 0] * a0 + P[i, 1] * a1 + P[i, 2] * a2 + P[i, 3] * a3
        s = a0 * Pa[0] + a1 * Pa[1] + a2 * Pa[2] + a3 * Pa[3]
        g = 1.0 / (lam + s)
        r = B[t] - (a0 * X[0] + a1 * X[1] + a2 * X[2] + a3 * X[3])
        for i in range(4):
            L[i] = g * Pa[i]
            X[i] += L[i] * r
        for i in range(4):
            for j in range(i, 4):
                v = (P[i, j] - L[i] * Pa[j]) * il
                P[i, j] = v
                P[j, i] = v
        for i in range(4):
            out[t, i] = X[i]


def make_data(T: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    t = np.arange(1, T + 1, dtype=float)
    A = np.column_stack([np.sin(2 * np.pi * t * f) * np.sin(2 * np.pi * t * f / 3.3) for f in (0.006, 0.012, 0.014)]
                        + [np.ones(T)])
    B = A @ np.array([1.0, 2.0, 3.0, 0.5]) + rng.normal(0.0, np.sqrt(0.1), T)
    out = rng.random(T) < 0.05
    B[out] = rng.uniform(-4, 4, out.sum())
    return A, B


def best_rates(cases: dict, repeats: int) -> tuple[dict, dict]:
    """Samples per second of each case (name -> (fn, samples)), best of ``repeats``, by the wall clock and by the
    process CPU clock. The cases are interleaved so that each sees the same share of quiet moments; the CPU
    clock does not count time the process waits for a core on a busy machine (for several threads it adds
    their CPU times, so it gives the rate per core)."""
    for fn, _ in cases.values():
        fn()  # warm-up: compilation (cached) and memory pages
    wall = {k: 0.0 for k in cases}
    cpu = {k: 0.0 for k in cases}
    for _ in range(repeats):
        for k, (fn, samples) in cases.items():
            c0, t0 = time.process_time(), time.perf_counter()
            fn()
            t1, c1 = time.perf_counter(), time.process_time()
            wall[k] = max(wall[k], samples / (t1 - t0))
            cpu[k] = max(cpu[k], samples / max(c1 - c0, 1e-9))
    return wall, cpu


ESTIMATORS: dict[str, dict[str, Any]] = {
    "RLS": {"forgetting": 0.999},
    "RRLM": {"forgetting": 0.999, "kappa": 1e-5, "scale0": 0.5, "quantile0": 0.1},
    "SGMKF": {"output_noise": 0.1, "desired_covariance": [1e-5, 1e-6, 1e-6, 1e-6], "scale0": 0.5, "quantile0": 0.1},
    "SGIVMKF": {"output_noise": 0.1, "desired_covariance": [1e-5, 1e-6, 1e-6, 1e-6], "instrument_delay": 4,
                    "scale0": 0.5, "quantile0": 0.1},
}


OTHERS = ("RGTLS/full", "RGTLS-NCE/full", "PKS-bank/4 channels")


def other_cases(A: np.ndarray, B: np.ndarray) -> dict[str, tuple[Callable[[], Any], int]]:
    """RGTLS (fixed P̌; with the noise covariance estimator) over the record, each run continuing from the last,
    and a PKS bank over four channels of it: name -> (run, samples per run)."""
    from roadload.estimators import RecursiveGTLS, pks_bank

    T = B.shape[0]
    fixed = RecursiveGTLS(4, noise_covariance=[1e-4, 1e-2, 1e-2, 1e-2, 0.1])
    nce = RecursiveGTLS(4, nce=True, noise_covariance=[1e-4, 1e-2, 1e-2, 1e-2, 0.1])
    channels = {f"c{i}": A[:, i] + 0.01 * B for i in range(4)}

    def rgtls(est: Any = fixed) -> None:   # continues from the last run's state (a reset builds q smoothers)
        est.run(A, B, store="full")
    return {"RGTLS/full": (rgtls, T), "RGTLS-NCE/full": (lambda: rgtls(nce), T),
            "PKS-bank/4 channels": (lambda: pks_bank(channels, dt=0.01, window=50, order=2, forgetting=0.98), 4 * T)}


def print_comparison(old: list[dict], new: list[dict], ref: str) -> None:
    """new/old of every figure relative to the hand-written loop of its own run (CPU clock), median of rounds."""
    print(f"old = commit {ref}, new = working tree; {len(old)} interleaved rounds; each figure divided by the "
          "hand-written RLS loop of its own run (CPU clock); new/old of the medians (> 1: new is faster)")
    print(f"{'estimator':<9s} " + " ".join(f"{k:>10s}" for k in ("x", "full", "final", "online", "many1", "many2")))
    for name in ESTIMATORS:
        cells = []
        for store in ("x", "full", "final", "online", "many1", "many2"):
            key = f"{name}/{store}"
            ref_key = "hand_long" if store.startswith("many") else "hand"
            o = statistics.median(r["cpu"][key] / r["cpu"][ref_key] for r in old)
            n = statistics.median(r["cpu"][key] / r["cpu"][ref_key] for r in new)
            cells.append(f"{n / o:10.3f}")
        print(f"{name:<9s} " + " ".join(cells))
    for key in (k for k in new[0]["cpu"] if k in OTHERS and k in old[0]["cpu"]):
        o = statistics.median(r["cpu"][key] / r["cpu"]["hand"] for r in old)
        n = statistics.median(r["cpu"][key] / r["cpu"]["hand"] for r in new)
        print(f"{key:<20s} {n / o:10.3f}")
    o = statistics.median(r["cpu"]["hand"] for r in old) / 1e6
    n = statistics.median(r["cpu"]["hand"] for r in new) / 1e6
    print(f"hand-written loop: {o:.2f} (old runs) / {n:.2f} (new runs) M samples per CPU-second")


def main(argv: list[str] | None = None, repo: Path | None = None) -> None:
    """The benchmark's command line (``scripts/bench_estimators.py``); ``repo``: the git repository of
    ``--compare`` (default: the source tree of this file)."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--samples", type=int, default=20_000)
    ap.add_argument("--repeats", type=int, default=30)
    ap.add_argument("--trips", type=int, default=8)
    ap.add_argument("--online-samples", type=int, default=2_000)
    ap.add_argument("--quick", action="store_true", help="tiny sizes for a smoke run (< 60 s)")
    ap.add_argument("--json", type=Path, help="also write the figures as JSON here")
    ap.add_argument("--compare", metavar="REF", help="git commit to compare against (in this run, interleaved)")
    ap.add_argument("--rounds", type=int, default=3, help="interleaved rounds of --compare")
    args = ap.parse_args(argv)
    if args.quick:
        args.samples, args.repeats, args.trips, args.online_samples = 2_000, 3, 2, 200
    if args.compare:
        # imported here, not at the top: this file also runs against old package trees that lack the module
        from roadload.experiments.benchmarks.refcompare import REPO, compare

        sub = ["--samples", str(args.samples), "--repeats", str(args.repeats), "--trips", str(args.trips),
               "--online-samples", str(args.online_samples)]
        old, new = compare(Path(__file__).resolve(), sub, args.compare, args.rounds, repo or REPO)
        print_comparison(old, new, args.compare)
        return
    T = args.samples
    A, B = make_data(T, 0)
    print(f"machine: {os.cpu_count()} cores, numba {numba.__version__}, record of {T} samples, "
          f"best of {args.repeats} runs (other work on the machine only slows runs down)")

    def hand():
        X = np.zeros(4)
        P = 100.0 * np.eye(4)
        out = np.empty((T, 4))
        hand_rls4(A, B, 0.999, X, P, out)
    # name (or (estimator, store)) -> (run, samples per run)
    cases: dict[Any, tuple[Callable[[], Any], int]] = {"hand": (hand, T)}
    m = args.online_samples
    K = args.trips
    AK = np.ascontiguousarray(np.broadcast_to(A, (K, T, 4)))
    BK = np.repeat(B[None], K, axis=0)
    A_long, B_long = AK.reshape(K * T, 4), BK.reshape(K * T)

    def hand_long():
        """The reference loop over all trips' samples as one record (same memory footprint as run_many)."""
        X = np.zeros(4)
        P = 100.0 * np.eye(4)
        out = np.empty((K * T, 4))
        hand_rls4(A_long, B_long, 0.999, X, P, out)
    cases["hand_long"] = (hand_long, K * T)
    for name, kw in ESTIMATORS.items():
        est = make_estimator(name, n_params=4, **kw)
        cfg = make_config(name, n_params=4, **kw)
        for store in ("x", "full", "final"):
            def go(est=est, store=store):
                est.reset()
                est.run(A, B, store=store)
            cases[(name, store)] = (go, T)

        def online(est=est):
            est.reset()
            for i in range(m):
                est.update(A[i], B[i])
        cases[(name, "online")] = (online, m)
        for threads in (1, 2):
            def many(cfg=cfg, threads=threads):
                run_many(cfg, AK, BK, store="x", n_threads=threads)
            cases[(name, f"many{threads}")] = (many, K * T)
    cases.update(other_cases(A, B))
    load0 = os.getloadavg()[0]
    wall, cpu = best_rates(cases, args.repeats)
    load1 = os.getloadavg()[0]
    print(f"load average during the run: {load0:.1f} -> {load1:.1f} (runnable processes on {os.cpu_count()} cores)")
    for title, res in (("CPU clock (samples per CPU-second: per core, not counting waits for a core)", cpu),
                       ("wall clock (best run)", wall)):
        ref = res["hand"]
        print(f"\n--- {title}")
        print(f"{'hand-written 4-parameter RLS loop (numba)':<52s} {ref / 1e6:8.2f} M samples/s")
        print(f"{'the same loop over all trips as one record':<52s} {res['hand_long'] / 1e6:8.2f} M samples/s "
              f"({K} x {T} samples: the memory footprint of the many-trips runs)")
        print(f"{'estimator':<9s} {'batch x':>9s} {'batch full':>11s} {'state only':>11s} {'online':>9s} "
              f"{'many 1 thr':>11s} {'many 2 thr':>11s} {'x / hand':>9s}   [M samples/s]")
        for name in ESTIMATORS:
            r = {k[1]: v for k, v in res.items() if isinstance(k, tuple) and k[0] == name}
            print(f"{name:<9s} {r['x'] / 1e6:9.2f} {r['full'] / 1e6:11.2f} {r['final'] / 1e6:11.2f} "
                  f"{r['online'] / 1e6:9.3f} {r['many1'] / 1e6:11.2f} {r['many2'] / 1e6:11.2f} {r['x'] / ref:9.2f}")
        for key in OTHERS:
            print(f"{key:<20s} {res[key] / 1e6:9.2f}")
    if args.json:
        def keyed(res: dict) -> dict:
            return {k if isinstance(k, str) else f"{k[0]}/{k[1]}": v for k, v in res.items()}
        args.json.write_text(json.dumps({"cpu": keyed(cpu), "wall": keyed(wall)}))


if __name__ == "__main__":
    main()
