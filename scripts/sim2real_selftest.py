"""Sim-to-real selftest: withheld catalog effects must be identified blind; an effect outside the catalog must come
out unexplained and localised. Prints the confusion matrix, top-1 accuracy and gap shrinkage; writes JSON.

    python scripts/sim2real_selftest.py [--vehicle bmw_i3] [--duration 900] [--workers 2] [--out out/sim2real_selftest]
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import pandas as pd

from roadload.fileio import write_json
from roadload.experiments.sim2real_selftest import run_selftest


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--vehicle", default="bmw_i3")
    ap.add_argument("--duration", type=float, default=900.0, help="seconds per 'real' trip (3 roads)")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--out", default="out/sim2real_selftest")
    args = ap.parse_args()
    t0 = time.perf_counter()
    res = run_selftest(args.vehicle, duration=args.duration, workers=args.workers)
    pd.set_option("display.width", 200)
    rows = res.cases + ([res.outside] if res.outside else []) + ([res.none] if res.none else [])
    print(pd.DataFrame([{"withheld": c.label, "identified": c.identified, "correct": c.correct,
                         "rmse_before_N": round(c.rmse_before, 1), "rmse_after_N": round(c.rmse_after, 1),
                         "shrinkage": round(c.shrinkage, 3), "shrinkage_resim": round(c.shrinkage_simulator, 3),
                         "excess_shrinkage": round(res.excess_shrinkage(c), 3),
                         "unexplained_at": c.unexplained_where} for c in rows]).to_string(index=False))
    print("\nconfusion matrix (rows withheld, columns identified):")
    print(res.confusion().to_string())
    print(f"\ntop-1 identification: {res.top1:.1%} of {len(res.cases)} catalog effects")
    print(f"median gap shrinkage (held-out force RMSE): fitted {res.median_shrinkage:.1%}, "
          f"re-simulated {res.median_shrinkage_simulator:.1%}")
    print(f"noise floor (nothing withheld): held-out RMSE {res.noise_rmse:.1f} N, identified "
          f"{res.none.identified if res.none else '?'}; median shrinkage of the gap above it "
          f"{res.median_excess_shrinkage:.1%}")
    print(f"outside-catalog effect unexplained and localised: {res.outside_ok}"
          + (f" ({res.outside.unexplained_where})" if res.outside else ""))
    print(f"wall time {time.perf_counter() - t0:.0f} s")
    out = Path(args.out)
    write_json(out / "selftest.json", res.to_dict(), default=float)
    print(f"wrote {out / 'selftest.json'}")


if __name__ == "__main__":
    main()
