"""Diagnose the bmw_i3 preset against the real BMW i3 trips (TUM, ../shared/data/bmw_i3_tum): where the gap lies,
which effects explain it, how far it shrinks. Writes report.md, diagnosis.json and figures.

    python scripts/sim2real_i3.py [--trips TripA01,TripB01,...] [--out out/sim2real_i3] [--base-first]
    python scripts/sim2real_i3.py --quick      # CI smoke run: two trips, short floor, no re-simulation
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

from roadload.data import require_shared_data
from roadload.io import import_log
from roadload.sim2real.diagnose import DiagnosisSettings, diagnose
from roadload.sim2real.report import write_report
from roadload.units import STANDARD_TEMPERATURE
from roadload.sim2real.simconfig import SimConfig
from roadload.estimators.models import Term
from roadload.sim2real.catalog import CandidateEffect, register_candidate
from roadload.units import G
from roadload.sim2real.catalog import DEFAULT_CANDIDATES


def register_cold_rolling() -> str:
    """A user-added candidate (not in the catalog): rolling resistance rising in the cold,
    f_r(v, T_a) = f_r(v) (1 + k max(293.15 K - T_a, 0) / 10 K); regressor m_V g cos(theta) f_r(v) max(...)/10 K,
    parameter k (relative rise per 10 K below 20 degC). The simulator has no such switch (sim_effect None)."""

    def terms(model, shape):
        def build(s):
            th = np.asarray(s["gradient_angle"], dtype=float)
            cold = np.clip(STANDARD_TEMPERATURE - np.asarray(s["ambient_temperature"], dtype=float), 0.0, None) / 10.0
            return model.mass * G * np.cos(th) * model.rolling_resistance_coefficient(
                np.asarray(s["speed"], dtype=float)) * np.nan_to_num(cold)
        return (Term("m_V g cos(theta) f_r(v) max(20 degC - T_a, 0)/10 K", "cold rolling rise k", "1/(10 K)",
                     build, ("gradient_angle", "speed", "ambient_temperature"), lambda n: 0.0),)

    register_candidate(CandidateEffect("cold_rolling", "rolling resistance rising in the cold (user candidate)",
                                       terms, ("gradient_angle", "speed", "ambient_temperature"),
                                       regime_hint="ambient_temperature"), replace_existing=True)
    return "cold_rolling"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--trips", default="", help="comma-separated trip names (default: all)")
    ap.add_argument("--out", default="out/sim2real_i3")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--base-first", action="store_true",
                    help="select effects over the calibrated base (the preset is not the car)")
    ap.add_argument("--quick", action="store_true", help="two trips, 300 s floor trips, no re-simulation")
    ap.add_argument("--user-candidate", action="store_true",
                    help="add the user candidate 'cold_rolling' (temperature-dependent rolling resistance)")
    args = ap.parse_args()
    try:
        folder = require_shared_data("bmw_i3_tum") / "data"
    except FileNotFoundError as exc:
        print(f"{exc}" + ("; skipped" if args.quick else ""), file=sys.stderr)
        sys.exit(0 if args.quick else 1)
    files = sorted(folder.glob("Trip*.csv"))
    if args.trips:
        want = {t.strip() for t in args.trips.split(",")}
        files = [f for f in files if f.stem in want]
    if args.quick:
        files = files[:2]
    t0 = time.perf_counter()
    trips, skipped = [], []
    for f in files:
        try:
            trips.append(import_log(f, "bmw-i3"))
        except ValueError as exc:
            skipped.append(f"{f.stem}: {exc}")
    print(f"loaded {len(trips)} trips in {time.perf_counter() - t0:.0f} s; skipped {skipped or 'none'}")
    sim = SimConfig.load("bmw_i3")
    cands = DEFAULT_CANDIDATES + ((register_cold_rolling(),) if args.user_candidate else ())
    settings = DiagnosisSettings(seed=args.seed, candidates=cands, base_first=args.base_first)
    if args.quick:
        settings = DiagnosisSettings(seed=args.seed, candidates=cands, base_first=args.base_first,
                                     floor_duration=300.0, resimulate=False, replay=False)
    diag = diagnose(trips, sim, settings,
                    progress=lambda what, frac: print(f"  [{time.perf_counter() - t0:5.0f} s] {what}"))
    paths = write_report(diag, Path(args.out))
    fb, fa = diag.gap_before.force_residual, diag.gap_after.force_residual
    print(f"held-out force residual: median {fb.median:.0f} -> {fa.median:.0f} N, RMSE {fb.rmse:.0f} -> "
          f"{fa.rmse:.0f} N (shrinkage {100 * diag.shrinkage('rmse'):.1f} %)")
    if diag.gap_after_sim:
        print(f"re-simulated: RMSE {diag.gap_after_sim.force_residual.rmse:.0f} N "
              f"(shrinkage {100 * diag.shrinkage('rmse', True):.1f} %)")
    print("base calibration (" + ("effects selected over it" if args.base_first else "reported only") + "):")
    for b in diag.base.parameters:
        print(f"  {b.name:40s} {b.value:+.4g} ± {b.std_error:.2g} {b.unit}  RMS {b.size_rms:.0f} N"
              + ("  significant" if b.significant else ""))
    for imp in diag.notes.implausible:
        print(f"  not accepted, implausible: {imp.effect}: {imp.reason}")
    print("ranking:")
    for r in diag.ranking[:8]:
        print(f"  {r.name:20s} held-out {100 * r.improvement:6.1f} %  dAIC {r.delta_aic:9.0f}  "
              + ", ".join(f"{k}={v:.4g}±{r.std_errors[k]:.2g}" for k, v in r.parameters.items()))
    print("forward selection:", [(s.effect, s.reason) for s in diag.selection])
    print("strongest departures before:")
    for b in diag.notes.strongest_departures_before:
        print(f"  {b.regime:22s} {b.bin:14s} median {b.median:7.1f} N [{b.ci_low:.0f}, {b.ci_high:.0f}]"
              f" share {100 * b.share:.0f} %")
    print("season:", [(r.bin, round(r.median, 1), r.n) for r in diag.regimes_before.get("season", [])])
    print("unexplained:", [(b.regime, b.bin, round(b.median, 1)) for b in diag.unexplained.departing_bins])
    if diag.energy:
        en = diag.energy
        ee = en.electric_energy_per_distance
        print(f"energy side: battery energy measured {ee.measured:.2f}, sim {ee.sim_before:.2f} kWh/100 km; "
              f"power residual RMSE {en.power_residual_before.rmse:.0f} W; accepted "
              f"{[e.name for e in en.effects]}; ranking "
              + ", ".join(f"{r.name} {100 * r.improvement:.1f} %" for r in en.ranking))
    print(f"wrote {paths['report']} ({time.perf_counter() - t0:.0f} s)")


if __name__ == "__main__":
    main()
