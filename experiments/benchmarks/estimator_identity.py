"""Are the estimators' outputs bitwise those of another commit? For work on the estimator kernels that must not
change a single bit.

    python scripts/check_estimator_identity.py --ref 8efaaad     # the working tree against commit 8efaaad
    python scripts/check_estimator_identity.py --quick            # CI smoke run: HEAD, short records, no trip

Every catalogue composition (RLS ... SGIVMKF, plus variants that reach the kernel's other branches: iterated
weights, Joseph form, Tikhonov, saturation, user instruments, a transition matrix), RGTLS with a fixed noise
covariance and with the noise covariance estimator, the PKS and its bank, and the batch references run on fixed
seeded data (a clean and a faulty record: NaN, inf and 1e200 samples, a dead stretch without excitation). Then a
simulated trip goes through the chapter-5 pipeline and the section-5.5 estimators run on its M3 and M4 data.

Of each recursive run the whole histories are kept: X̂_t and diag P_t of the record run (``store='full'``, with
the residuals, weights and scale), X̂_t and the full P_t of the sample-by-sample ``update`` path, the final state
and the counters, and the many-trips path. ``--ref`` is exported with ``git archive`` into a temporary package
tree (:mod:`.refcompare`); each side runs this file in its own process and dumps its arrays, which are then
compared bit for bit (NaN equal to NaN, the sign of a zero counted). Exit status 1 when any array differs. This
file runs against an old package tree too: it imports only the public API of ``roadload.estimators`` (and
``simulate``, ``load_profile``, ``knowledge_for_preset``), which every commit has.
"""

from __future__ import annotations

import tempfile
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from functools import partial
from typing import Any, cast

import numpy as np

#: sizes of the full and the quick run: record length, sample-by-sample length, trips of run_many, seconds of the
#: simulated trip (0: none), and whether to run the parts that compile the kernel for other parameter counts (PKS
#: order 4, model M4). The quick run (CI) compiles the kernel for 3 parameters only and simulates no trip: in the
#: exported package tree every compilation starts from scratch (20-40 s of CPU per parameter count, 30 s for the
#: simulator)
FULL = dict(samples=6000, online=1500, trips=4, trip_seconds=600.0, all_sizes=True)
QUICK = dict(samples=800, online=200, trips=2, trip_seconds=0.0, all_sizes=False)


def _faulty(A: np.ndarray, B: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The record with the faults the safety nets handle: NaN and inf samples, absurd (1e200, 1e15) values and a
    stretch without excitation."""
    A, B = A.copy(), B.copy()
    T = B.shape[0]
    k = T // 20
    A[k:k + 10] = np.nan
    B[2 * k] = np.inf
    A[3 * k, 1] = -np.inf
    B[4 * k] = 1e200
    A[5 * k, 2] = 1e200
    B[6 * k:6 * k + 5] = 1e15
    A[8 * k:12 * k] = 0.0
    return A, B


#: settings of the catalogue runs on the synthetic records (3 parameters, output noise variance 0.02): fixed
#: here, so that this check sees changes of the estimators alone
_FORGETTING = dict(forgetting=0.995, scale0=float(np.sqrt(0.02)), quantile0=0.02)
_KALMAN = dict(output_noise=0.02, scale0=float(np.sqrt(0.02)), quantile0=0.02)
_Q = dict(process_noise=[1e-6, 1e-8, 1e-5])
_PD = dict(desired_covariance=0.02 * 0.005 / 0.25)
_DELAY = dict(instrument_delay=2)
_KAPPA = dict(kappa=0.1)
CATALOGUE_RUNS: dict[str, tuple[str, dict]] = {
    "RLS": ("RLS", _FORGETTING), "RLM": ("RLM", _FORGETTING), "RRLM": ("RRLM", {**_FORGETTING, **_KAPPA}),
    "KF": ("KF", {**_KALMAN, **_Q}), "MKF": ("MKF", {**_KALMAN, **_Q}), "RMKF": ("RMKF", {**_KALMAN, **_Q, **_KAPPA}),
    "SGMKF": ("SGMKF", {**_KALMAN, **_PD}), "RIV": ("RIV", {**_FORGETTING, **_DELAY}),
    "RIVM": ("RIVM", {**_FORGETTING, **_DELAY}), "RRIVM": ("RRIVM", {**_FORGETTING, **_DELAY, **_KAPPA}),
    "IVKF": ("IVKF", {**_KALMAN, **_DELAY, **_Q}), "IVMKF": ("IVMKF", {**_KALMAN, **_DELAY, **_Q}),
    "RIVMKF": ("RIVMKF", {**_KALMAN, **_DELAY, **_Q, **_KAPPA}),
    "SGIVMKF": ("SGIVMKF", {**_KALMAN, **_DELAY, **_PD}),
    # variants reaching the kernel's other parts
    "RLM/iterated-hampel": ("RLM", {**_FORGETTING, "scale_iterations": 3, "psi": "hampel"}),
    "RLM/tukey": ("RLM", {**_FORGETTING, "psi": "tukey"}),
    "RLM/myriad": ("RLM", {**_FORGETTING, "psi": "myriad", "psi_params": 2.0}),
    "MKF/joseph": ("MKF", {**_KALMAN, **_Q, "joseph": True}),
    "RRLM/tikhonov": ("RRLM", {**_FORGETTING, "regularisation": "tikhonov", "kappa": 1e-3}),
    "RLS/saturated": ("RLS", {**_FORGETTING, "x_min": [0.0, 0.5, 0.0], "x_max": [1.2, 2.5, 2.9]}),
    "RLS/unsymmetrised": ("RLS", {**_FORGETTING, "symmetrize": False, "p0": [10.0, 100.0, 1000.0]}),
    "RIV/user": ("RIV", {**_FORGETTING, "instruments": "user", "instrument_delay": None}),
    "KF/transition": ("KF", {**_KALMAN, **_Q, "transition": np.diag([1.0, 0.999, 1.0])}),
    "RLS/tight-bound": ("RLS", {**_FORGETTING, "covariance_bound_ratio": 1.5, "forgetting": 0.95}),
}


def _recursive(arrays: dict, key: str, make: Callable[[], Any], A: np.ndarray, B: np.ndarray,
               Z: np.ndarray | None, online: int) -> None:
    """Record run (every store mode), then the sample-by-sample path with the full P_t after every sample."""
    est = make()
    res = est.run(A, B, instruments=Z, store="full")
    for field in ("X", "P_diag", "residual_prior", "residual_post", "weights", "scale", "skipped"):
        arrays[f"{key}/run/{field}"] = np.asarray(getattr(res, field))
    arrays[f"{key}/run/counters"] = np.array([res.n_skipped, res.n_rolled_back, res.p_blowup_at,
                                              getattr(res, "n_p_resets", 0)], dtype=float)
    arrays[f"{key}/run/p_diag_max"] = np.array([res.p_diag_max])
    _state(arrays, f"{key}/run/state", res.state)
    for store in ("x", "final"):
        other = make()
        r = other.run(A, B, instruments=Z, store=store)
        arrays[f"{key}/run-{store}/x_final"] = other.x
        arrays[f"{key}/run-{store}/p_final"] = other.p
        if store == "x":
            arrays[f"{key}/run-x/X"] = r.X
    est = make()
    xs, ps = np.empty((online, A.shape[1])), []
    for t in range(online):
        xs[t] = est.update(A[t], B[t], None if Z is None else Z[t])
        ps.append(est.p)
    arrays[f"{key}/online/X"] = xs
    arrays[f"{key}/online/P"] = np.asarray(ps)


def _state(arrays: dict, key: str, state) -> None:
    for field in ("x", "p", "ring"):
        arrays[f"{key}/{field}"] = np.asarray(getattr(state, field))
    arrays[f"{key}/scalars"] = np.array([state.scale, state.quantile, state.t, state.n_skipped, state.n_rolled_back,
                                         state.blowup_at, state.p_diag_max, state.ring_pos, state.ring_fill,
                                         getattr(state, "n_p_resets", 0)], dtype=float)


def catalogue_runs(arrays: dict, size: dict) -> None:
    """Every composition on a clean and a faulty seeded record, and the many-trips path."""
    from roadload.estimators import make_config, make_estimator, run_many
    from roadload.estimators.synthetic import linear_miso

    T = size["samples"]
    d = linear_miso(seed=7, m=T, input_noise_var=(0.0, 0.005, 0.01), output_noise_var=0.02)
    records = {"clean": (d.A, d.B), "faulty": _faulty(d.A, d.B)}
    Z = np.vstack([np.zeros((3, 3)), d.A[:-3]])  # user instruments: A three samples earlier
    for label, (name, settings) in CATALOGUE_RUNS.items():
        s = dict(settings, n_params=3)
        user = s.get("instruments") == "user"
        for rec, (A, B) in records.items():
            _recursive(arrays, f"{label}/{rec}", partial(make_estimator, name, **s), A, B,
                       Z if user else None, size["online"])
        if user:
            continue
        K = size["trips"]
        AK = np.stack([linear_miso(seed=20 + k, m=T).A for k in range(K)])
        BK = np.stack([linear_miso(seed=20 + k, m=T).B for k in range(K)])
        many = run_many(make_config(name, **s), AK, BK, store="full", n_threads=2)
        for field in ("X", "P_diag", "residual_prior", "weights", "scale", "n_skipped", "p_blowup_at"):
            arrays[f"{label}/many/{field}"] = np.asarray(getattr(many, field))


def rgtls_and_pks_runs(arrays: dict, size: dict) -> None:
    """RGTLS with a fixed P̌ and with the noise covariance estimator; the PKS and the PKS bank."""
    from roadload.estimators import PolynomialKalmanSmoother, RecursiveGTLS, pks_bank
    from roadload.estimators.synthetic import linear_miso

    T = size["samples"]
    d = linear_miso(seed=4, m=T, input_noise_var=(0.0, 0.005, 0.01), output_noise_var=0.02, outlier_fraction=0.0)
    settings: dict[str, dict[str, Any]] = {
        "RGTLS/fixed": dict(n_params=3, forgetting=0.999, noise_covariance=[1e-4, 0.005, 0.01, 0.02]),
        "RGTLS/rtls": dict(n_params=3),
        "RGTLS/nce-pks": dict(n_params=3, forgetting=0.999, nce=True, nce_forgetting=0.99,
                              pks=dict(n_params=3, window_left=10, window_right=5, forgetting=0.95)),
    }
    if size["all_sizes"]:
        settings["RGTLS/nce"] = dict(n_params=3, forgetting=0.995, nce=True)   # the default PKS: order 4
    for key, s in settings.items():
        for rec, (A, B) in {"clean": (d.A, d.B), "faulty": _faulty(d.A, d.B)}.items():
            _recursive(arrays, f"{key}/{rec}", partial(RecursiveGTLS, **s), A, B, None, size["online"])
            est = RecursiveGTLS(**s)
            est.run(A, B)
            arrays[f"{key}/{rec}/noise_covariance"] = est.noise_covariance_estimate
    rng = np.random.default_rng(11)
    t = np.arange(T) * 0.01
    signal = np.sin(2.0 * t) + 0.1 * t ** 2 + rng.normal(0.0, 0.05, T)
    signal[T // 3:T // 3 + 4] = np.nan
    designs: dict[str, dict[str, Any]] = {
        "PKS/order2": dict(n_params=3, window_left=10, window_right=30, forgetting=0.98, p0=1e3)}
    if size["all_sizes"]:
        designs["PKS/default"] = {}
    for key, kw in designs.items():
        pks = PolynomialKalmanSmoother(**kw)
        arrays[f"{key}/update"] = np.array([pks.update(b) for b in signal[:size["online"]]])
        arrays[f"{key}/x"] = pks.x
        run = PolynomialKalmanSmoother(**kw).run(signal)
        arrays[f"{key}/run/X"] = run.X
        smooth = PolynomialKalmanSmoother(**kw).smooth(signal, dt=0.01, derivatives=2)
        arrays[f"{key}/smooth/value"] = smooth.value["signal"]
        arrays[f"{key}/smooth/derivatives"] = smooth.derivatives["signal"]
    bank = pks_bank({"a": signal, "b": np.cos(t)}, dt=0.01, derivatives=1, window=15, order=2, forgetting=0.95)
    assert bank.derivative is not None
    for name in ("a", "b"):
        arrays[f"PKS/bank/{name}/value"] = bank.value[name]
        arrays[f"PKS/bank/{name}/derivative"] = bank.derivative[name]
        arrays[f"PKS/bank/{name}/aligned"] = bank.aligned(name)


def batch_runs(arrays: dict, size: dict) -> None:
    """The batch references of chapter 3 on seeded data."""
    from roadload import estimators as E
    from roadload.estimators.synthetic import linear_miso

    d = linear_miso(seed=5, m=min(size["samples"], 2000), input_noise_var=(0.0, 0.005, 0.01))
    A, B = d.A, d.B
    runs = {
        "LS": lambda: E.least_squares(A, B),
        "WLS": lambda: E.weighted_least_squares(A, B, np.linspace(0.5, 1.5, B.shape[0])),
        "M/huber": lambda: E.m_estimate(A, B, "huber"),
        "M/tukey": lambda: E.m_estimate(A, B, "tukey"),
        "TLS": lambda: E.total_least_squares(A, B),
        "GTLS": lambda: E.generalized_total_least_squares(A, B, [1e-4, 0.005, 0.01, 0.1],
                                                          0.999 ** np.arange(B.shape[0])[::-1]),
        "LMS": lambda: E.least_median_of_squares(A[:200], B[:200], max_subsets=300, seed=1),
        "LTS": lambda: E.least_trimmed_squares(A[:200], B[:200], max_subsets=50, seed=1),
    }
    for key, fn in runs.items():
        res = fn()
        for field in ("X", "cov", "residual", "weights", "scale", "iterations"):
            value = getattr(res, field)
            if value is not None:
                arrays[f"batch/{key}/{field}"] = np.asarray(value, dtype=float)
    arrays["batch/mad_scale"] = np.array([E.mad_scale(B - A @ np.array([1.0, 2.0, 3.0]))])


def pipeline_runs(arrays: dict, size: dict) -> None:
    """A simulated trip through the chapter-5 pipeline; the section-5.5 estimators on its M3 and M4 data."""
    from roadload.envs import simulate
    from roadload.estimators import chapter5_settings, get_model, make_estimator, model_data, run_pipeline
    from roadload.estimators.knowledge import knowledge_for_preset
    from roadload.road_profiles import load_profile

    trip = simulate("gt_rwd", load_profile("hilly", seed=3), effects=["payload:initial_payload=200"], seed=3,
                    duration=size["trip_seconds"])
    for name in trip.measured.columns:
        arrays[f"trip/measured/{name}"] = trip.measured[name].to_numpy()
    knowledge = knowledge_for_preset("gt_rwd")
    result = run_pipeline(trip, knowledge)
    for stage in ("smoothed", "decimated", "states"):
        frame = result.stages[stage]
        for name in frame.columns:
            arrays[f"pipeline/{stage}/{name}"] = frame[name].to_numpy()
    for model in ("M3", "M4") if size["all_sizes"] else ("M3",):
        t, A, B = model_data(result.states, model)
        arrays[f"pipeline/{model}/A"] = A
        arrays[f"pipeline/{model}/B"] = B
        x0 = get_model(model).nominal_parameters(knowledge.nominal)
        for name, s in chapter5_settings(model).items():
            _recursive(arrays, f"pipeline/{model}/{name}", partial(make_estimator, name, x0=x0, **s),
                       A, B, None, min(size["online"], B.shape[0]))


def dump(out: Path, quick: bool) -> None:
    """Run everything in this process (whichever roadload PYTHONPATH selects) and save the arrays."""
    size = QUICK if quick else FULL
    arrays: dict[str, np.ndarray] = {}
    catalogue_runs(arrays, size)
    rgtls_and_pks_runs(arrays, size)
    batch_runs(arrays, size)
    if size["trip_seconds"] > 0:
        pipeline_runs(arrays, size)
    np.savez(out, **cast(dict[str, Any], arrays))


@dataclass
class Comparison:
    """Arrays and values compared between two dumps, and the keys that differ (or exist on one side only)."""

    arrays: int
    values: int
    differ: list[str]


def compare_dumps(old: Path, new: Path) -> Comparison:
    a, b = np.load(old), np.load(new)
    differ = []
    for key in sorted(set(a.files) | set(b.files)):
        if key not in a.files or key not in b.files:
            differ.append(f"{key} (only in the {'new' if key in b.files else 'old'} dump)")
            continue
        x, y = a[key], b[key]
        same = x.shape == y.shape and x.dtype == y.dtype and np.array_equal(x, y, equal_nan=x.dtype.kind == "f")
        if same and x.dtype.kind == "f":   # -0.0 == 0.0: the signs must agree too (NaN's sign is no result)
            finite = ~np.isnan(x)
            same = np.array_equal(np.signbit(x[finite]), np.signbit(y[finite]))
        if not same:
            differ.append(key)
    return Comparison(len(a.files), int(sum(a[k].size for k in a.files)), differ)


def compare(ref: str, quick: bool, repo: Path | None = None) -> int:
    """Dump the arrays of commit ``ref`` (of the git repository ``repo``, default: the source tree of this file) and
    of the working tree, each in its own process, compare them and print the counts; returns the exit status."""
    # imported here, not at the top: this file also runs against old package trees that lack the module
    from roadload.experiments.benchmarks.refcompare import REPO, dump_pair

    repo = repo or REPO
    with tempfile.TemporaryDirectory(prefix="roadload-estimator-identity-") as tmp:
        result = compare_dumps(*dump_pair(Path(__file__).resolve(), ref, quick, Path(tmp), repo))
    print(f"estimators, {ref} vs working tree ({repo}): {result.arrays} arrays ({result.values:,} values) compared, "
          f"{len(result.differ)} differ")
    for key in result.differ:
        print(f"  differs: {key}")
    return 1 if result.differ else 0


def main(argv: list[str] | None = None, repo: Path | None = None) -> int:
    """The check's command line (``scripts/check_estimator_identity.py``); returns the exit status."""
    # imported here, not at the top: this file also runs against old package trees that lack the module
    from roadload.experiments.benchmarks.refcompare import identity_command

    return identity_command(__doc__ or "", "short records, no simulated trip (CI smoke run)", compare, argv, repo)


if __name__ == "__main__":
    raise SystemExit(main())
