"""Add a catalogue estimator variant and sweep it to breakdown against its parent and RLS.

    python examples/estimator_variant_sweep.py --quick                     # 1 seed, 4000 samples (seconds)
    python examples/estimator_variant_sweep.py --seeds 10                  # 10 seeds, 10 000 samples
    python examples/estimator_variant_sweep.py --base SGMKF --psi cauchy   # another variant

The variant is ``make_estimator(base, psi=...)``: the catalogue composition of ``--base`` with other weights ψ
(eq. 3.15-3.17). Data: Experiment-3.3-style synthetic regression (roadload.experiments.robustness); outliers
(uniform in ±4 standard deviations) replace a growing fraction of the samples of B (``--target output``) or of
A and B (``--target both``, bad leverage points). Printed: the median relative parameter error per fraction and
the breakdown point (smallest fraction whose error exceeds the fault-free error by more than 0.1; ∞ = none), as
median over the seeds.
"""

from __future__ import annotations

import argparse

import numpy as np
import pandas as pd

from roadload.estimators import CATALOG, PSI_KINDS, make_estimator
from roadload.experiments.robustness import (breakdown_point, inject_ab_outliers, relative_parameter_error,
                                             synthetic_regression, synthetic_settings)
from roadload.tables import markdown_table

LEVELS = (0.0, 0.02, 0.05, 0.1, 0.15, 0.2, 0.3)


def sweep(label: str, base: str, overrides: dict, seeds: range, duration: float, target: str) -> dict:
    """Median error per outlier fraction and median breakdown point over the seeds."""
    errors = np.empty((len(seeds), len(LEVELS)))
    breakdowns = []
    for i, seed in enumerate(seeds):
        data = synthetic_regression(duration=duration, seed=seed)
        for j, fraction in enumerate(LEVELS):
            d = inject_ab_outliers(data, fraction, target=target, seed=seed)
            result = make_estimator(base, **{**synthetic_settings(base), **overrides}).run(d.A, d.B)
            burn_in = len(d.B) // 5
            errors[i, j] = np.median(relative_parameter_error(result.X[burn_in:], d.X_true[burn_in:]))
        breakdowns.append(breakdown_point(LEVELS[1:], errors[i, 1:], bound=0.1, baseline=errors[i, 0]))
    return {"estimator": label, **{f"{f:g}": e for f, e in zip(LEVELS, np.median(errors, axis=0))},
            "breakdown": float(np.median(breakdowns))}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="one seed, 4000 samples")
    parser.add_argument("--base", default="RRLM", choices=sorted(CATALOG), help="catalogue estimator to vary")
    parser.add_argument("--psi", default="myriad", choices=sorted(PSI_KINDS), help="weights of the variant")
    parser.add_argument("--target", default="output", choices=("output", "both", "input"))
    parser.add_argument("--seeds", type=int, default=10)
    args = parser.parse_args()
    seeds = range(1) if args.quick else range(args.seeds)
    duration = 4000.0 if args.quick else 10_000.0
    rows = [sweep("RLS", "RLS", {}, seeds, duration, args.target),
            sweep(args.base, args.base, {}, seeds, duration, args.target),
            sweep(f"{args.base} with psi={args.psi}", args.base, {"psi": args.psi}, seeds, duration, args.target)]
    print(f"outliers in {args.target}, {len(seeds)} seed(s), {duration:.0f} samples; "
          "median relative parameter error per outlier fraction")
    print(markdown_table(pd.DataFrame(rows), floatfmt=".3f"))


if __name__ == "__main__":
    main()
