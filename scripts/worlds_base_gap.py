"""The base gap of a test world: with nothing withheld, how far the matched roadload vehicle's force balance plus
the sim's floor (what the diagnosis compares against) stays from the world's logged tractive force, per speed bin.

Per world (nothing withheld, seed 0, 3 trips): F_xV,measured - F_xV,sim [N] by speed bin, split into the analytic
balance's part (``raw``: measured - balance), the sim floor's (``floor``) and what is left (``residual``), for

- ``before``: the sim at roadload's default 20 °C ambient, floor fitted by plain least squares (rcond 1e-8) —
  the state the issue-13 gap of 20-30 N was measured in;
- ``ambient``: the matched sim config (the world's nominal ambient), the old floor fit;
- ``after``: the matched sim config and the floor's truncated-SVD fit (:data:`roadload.sim2real.floor.RCOND`).

    python scripts/worlds_base_gap.py --world independent,fastsim [--duration 900] [--seed 0]
    python scripts/worlds_base_gap.py --quick          # CI smoke run: independent, 240 s trips
"""

from __future__ import annotations

import argparse

from roadload.experiments.worlds.base_gap import base_gap
from roadload.tables import markdown_table


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--world", default="independent,fastsim", help="comma-separated worlds")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--duration", type=float, default=900.0, help="seconds per trip (3 trips)")
    ap.add_argument("--quick", action="store_true", help="tiny run: independent, 240 s trips")
    args = ap.parse_args(argv)
    worlds = [w.strip() for w in args.world.split(",") if w.strip()]
    duration = args.duration
    if args.quick:
        worlds, duration = ["independent"], 240.0
    for world in worlds:
        tab = base_gap(world, args.seed, duration)
        wide = tab.pivot_table(index="speed [km/h]", columns="variant",
                               values=["residual median [N]", "residual RMS [N]"], sort=False)
        wide.columns = [f"{v}: {m}" for m, v in wide.columns]
        cols = [f"{v}: {m}" for v in ("before", "ambient", "after")
                for m in ("residual median [N]", "residual RMS [N]")]
        wide = wide[cols].round(1)
        print(f"\n== {world}, nothing withheld, seed {args.seed}, 3 x {duration:.0f} s")
        print(markdown_table(wide.reset_index()))
        print(tab.round(1).to_string(index=False))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
