"""Baseline of the existing sim-to-real diagnosis on the independent test worlds: confusion tables per world (and
per seed), top-1 over the catalog effects, the out-of-catalog and nothing-withheld cases.

    python scripts/sim2real_worlds.py --world fastsim --seeds 3
    python scripts/sim2real_worlds.py --world all --seeds 3 --json results.json
    python scripts/sim2real_worlds.py --world independent --quick      # CI smoke run (< 60 s)
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

from roadload.experiments.worlds import (
    WORLDS,
    default_settings,
    run_world_selftest,
    supported_effects,
)
from roadload.experiments.worlds.selftest import (
    WorldResult,
    WorldSelftest,
    markdown_table,
    plot_confusion,
)
from roadload.fileio import write_text

QUICK_EFFECTS = ("payload", "none")


def report(world: str, res: WorldSelftest, seeds: list[int], png: Path | None, seconds: float | None = None,
           markdown: bool = False) -> dict:
    """Print the confusion table and summary of one world (and write its heat map to ``png``)."""
    took = f", {seconds:.0f} s" if seconds is not None else ""
    print(f"\n== world {world}: confusion (withheld x first identified), {len(seeds)} seed(s){took}")
    print(markdown_table(res.confusion(world)) if markdown else res.confusion(world).to_string())
    s = res.summary(world)
    print(f"top-1 {s['catalog_correct']}/{s['catalog_cases']} = {100 * s['top1']:.1f} %; out-of-catalog "
          f"unexplained and localised {s['outside_ok']}; nothing withheld -> nothing identified "
          f"{s['none_clean']}; median held-out RMSE shrinkage {100 * s['median_shrinkage']:.1f} %; withheld "
          f"effect among all identified (force + energy side) {s['found_anywhere']}/{s['catalog_cases']}")
    if len(seeds) > 1:
        for seed in seeds:
            print(f"  seed {seed}: top-1 {100 * res.top1(world, seed):.1f} %")
    if png:
        path = plot_confusion(res.confusion(world), png / f"confusion_{world}.png",
                              f"{world}: top-1 {s['catalog_correct']}/{s['catalog_cases']} catalog effects")
        print(f"wrote {path}")
    return s


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--world", default="all", choices=sorted(WORLDS) + ["all"])
    ap.add_argument("--seeds", type=int, default=1, help="number of seeds (first-seed .. first-seed + N - 1)")
    ap.add_argument("--first-seed", type=int, default=0, help="first seed")
    ap.add_argument("--effects", default=None, help="comma-separated withheld effects (default: all the world "
                                                    "supports)")
    ap.add_argument("--duration", type=float, default=900.0, help="seconds per trip (3 trips per case)")
    ap.add_argument("--quick", action="store_true", help="tiny run: 1 seed, 240 s trips, payload + none")
    ap.add_argument("--out", type=Path, default=None, help="keep the generated logs here")
    ap.add_argument("--json", type=Path, default=None, help="write all results as JSON")
    ap.add_argument("--png", type=Path, default=None, help="folder for the confusion heat maps (PNG per world)")
    ap.add_argument("--from-json", type=Path, default=None, help="print (and plot) the tables of a saved --json "
                                                                  "run instead of running")
    ap.add_argument("--markdown", action="store_true", help="print the confusion tables as markdown")
    args = ap.parse_args(argv)
    if args.from_json:
        dump = json.loads(args.from_json.read_text())
        for world, d in dump.items():
            res = WorldSelftest([WorldResult(**r) for r in d["results"]])
            report(world, res, sorted({r.seed for r in res.results}), args.png, markdown=args.markdown)
        return 0
    worlds = sorted(WORLDS) if args.world == "all" else [args.world]
    seeds = range(args.first_seed, args.first_seed + (1 if args.quick else args.seeds))
    duration = 240.0 if args.quick else args.duration
    settings = default_settings(quick=args.quick)
    dump = {}
    for world in worlds:
        if args.effects:
            effects = [e.strip() for e in args.effects.split(",") if e.strip()]
        elif args.quick:
            effects = list(QUICK_EFFECTS)
        else:
            effects = list(supported_effects(world))
        t0 = time.perf_counter()
        res = run_world_selftest(world, seeds, effects, duration_s=duration, settings=settings,
                                 out_dir=args.out / world if args.out else None,
                                 progress=lambda msg: print(msg, flush=True))
        s = report(world, res, list(seeds), args.png, time.perf_counter() - t0, args.markdown)
        dump[world] = {"summary": s, "results": [r.to_dict() for r in res.results],
                       "confusion": res.confusion(world).to_dict()}
    if args.json:
        write_text(args.json, json.dumps(dump, indent=1, default=float))
    return 0


if __name__ == "__main__":
    sys.exit(main())
