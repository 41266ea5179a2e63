"""Sim-to-real selftest on three worlds: roadload's own simulator, FASTSim 3 and an independent chapter-2 model
(:mod:`roadload.experiments.worlds`). Per world and seed: every withheld effect diagnosed blind from 3 trips;
prints the confusion table (withheld x first accepted effect) per world and seed, the per-case lines, and the
summary: top-1 over the catalog effects, false acceptances on "nothing withheld" and on the out-of-catalog
torque-map band, median held-out shrinkage; with ``--vehicle PRESET`` the sim is that shipped preset instead of
the vehicle matched to the world (base calibrated first) and "withheld among the accepted" is the figure.

    python scripts/sim2real_selftest.py --world independent --seeds 0,1,2 [--vehicle bmw_i3] [--json out.json]
    python scripts/sim2real_selftest.py --quick          # CI smoke run: one world, 240 s trips, 2 cases
"""

from __future__ import annotations

import os

# the speed target is "one diagnosis on one core": one BLAS thread (set before numpy loads; on a shared machine
# OpenBLAS' spinning worker threads otherwise count several times the work as process CPU time)
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

import argparse  # noqa: E402
import json  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import pandas as pd  # noqa: E402

from roadload.experiments.sim2real_selftest import NONE_WORLD, WORLD_NAMES, WorldRun, run_world
from roadload.fileio import write_json
from roadload.sim2real.diagnose import DiagnosisSettings


def summary_line(s: dict) -> str:
    return (f"found (scoring rule) {s['found']}/{s['catalog_cases']} ({s['found_cases']} with a reference run); "
            f"top-1 {s['top1_correct']}/{s['catalog_cases']}; withheld among the accepted {s['among_accepted']}/"
            f"{s['catalog_cases']}; false acceptances: nothing withheld {s['false_acceptances_none']}/"
            f"{s['none_cases']}, out-of-catalog {s['false_acceptances_outside']}/{s['outside_cases']}; median "
            f"held-out shrinkage (identified cases) {100 * s['median_shrinkage_identified']:.1f} %; cpu per diagnosis "
            f"median {s['median_cpu_seconds']:.1f} s, max {s['max_cpu_seconds']:.1f} s; errors {s['errors']}")


def reprint(paths: list[Path]) -> int:
    """Merge --json outputs per (world, sim) and print the summary line and the Markdown table of each."""
    merged: dict[tuple[str, str], list[dict]] = {}
    for path in paths:
        for world, run in json.loads(Path(path).read_text()).items():
            merged.setdefault((world, run["summary"]["vehicle"]), []).extend(run["results"])
    for (world, vehicle), results in merged.items():
        run = WorldRun.from_dicts(world, vehicle, results)
        print(f"\n### {world} ({vehicle}), seeds {run.summary()['seeds']}\n")
        print(summary_line(run.summary()) + "\n")
        print(run.markdown())
    return 0


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--world", default="all", choices=list(WORLD_NAMES) + ["all"])
    ap.add_argument("--seeds", default="0,1,2", help="comma-separated seeds")
    ap.add_argument("--effects", default=None, help="comma-separated withheld effects (default: all)")
    ap.add_argument("--duration", type=float, default=900.0, help="seconds per trip (3 trips per case)")
    ap.add_argument("--vehicle", default=None, help="a shipped preset as the sim (unmatched), e.g. bmw_i3")
    ap.add_argument("--quick", action="store_true", help="tiny run: independent world, seed 0, 240 s trips, "
                                                        "payload + none")
    ap.add_argument("--json", type=Path, default=None, help="write all results here")
    ap.add_argument("--from-json", type=Path, nargs="+", default=None,
                    help="no run: merge these --json outputs (per world) and print the summaries and Markdown tables")
    args = ap.parse_args(argv)
    if args.from_json:
        return reprint(args.from_json)
    pd.set_option("display.width", 220)
    worlds = list(WORLD_NAMES[:3]) if args.world == "all" else [args.world]
    seeds = [int(s) for s in args.seeds.split(",") if s.strip()]
    effects = [e.strip() for e in args.effects.split(",")] if args.effects else None
    duration = args.duration
    settings = None
    if args.quick:
        worlds, seeds, effects, duration = ["independent"], [0], ["payload", NONE_WORLD], 240.0
        settings = DiagnosisSettings(resimulate=False, replay=False, floor_duration=240.0, n_null=99)
    dump = {}
    for world in worlds:
        t0 = time.perf_counter()
        run = run_world(world, seeds, effects, duration, vehicle=args.vehicle, settings=settings,
                        say=lambda m: print(m, flush=True))
        for seed in seeds:
            print(f"\n== {world}, seed {seed}: confusion (rows withheld, columns first accepted)")
            print(run.confusion(seed).to_string())
        s = run.summary()
        print(f"\n== {world} ({s['vehicle']}), seeds {s['seeds']}, {time.perf_counter() - t0:.0f} s")
        print(f"found (scoring rule: accepted or a significant base departure, beyond the same seed's "
              f"nothing-withheld reference) {s['found']}/{s['catalog_cases']} "
              f"({s['found_cases']} with a reference run)")
        print(f"top-1 {s['top1_correct']}/{s['catalog_cases']}; withheld among the accepted "
              f"{s['among_accepted']}/{s['catalog_cases']} (or a significant base departure standing for it: "
              f"{s['among_accepted_or_base']}/{s['catalog_cases']}); false acceptances: nothing withheld "
              f"{s['false_acceptances_none']}/{s['none_cases']}, out-of-catalog {s['false_acceptances_outside']}/"
              f"{s['outside_cases']}; median held-out shrinkage (identified cases) "
              f"{100 * s['median_shrinkage_identified']:.1f} % (all catalog cases "
              f"{100 * s['median_shrinkage_all']:.1f} %); median diagnosis {s['median_seconds']:.1f} s wall, "
              f"{s['median_cpu_seconds']:.1f} s cpu (max {s['max_cpu_seconds']:.1f} s); "
              f"errors {s['errors']}")
        dump[world] = run.to_dict()
    if args.json:
        write_json(args.json, dump, default=float)
        print(f"wrote {args.json}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
