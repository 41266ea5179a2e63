"""The base gap of a test world: with nothing withheld, how far the matched roadload vehicle's force
balance plus the sim's floor (what the diagnosis compares against) stays from the world's logged tractive force,
per speed bin. Variants: ``before`` (the sim at roadload's default 20 °C ambient, floor fitted by plain least
squares, rcond 1e-8: the state the 20-30 N gap was measured in), ``ambient`` (the matched sim config at the
world's nominal ambient, old floor fit), ``after`` (matched sim config, the floor's truncated-SVD fit
:data:`roadload.sim2real.floor.RCOND`). Printed by ``scripts/worlds_base_gap.py`` (:func:`main`).

    python scripts/worlds_base_gap.py --world independent,fastsim [--duration 900] [--seed 0]
    python scripts/worlds_base_gap.py --quick          # CI smoke run: independent, 240 s trips
"""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path

import numpy as np
import pandas as pd

from roadload.sim2real.diagnose import FLOOR_ROADS, sim_trips
from roadload.sim2real.floor import RCOND, SimFloor, reduce_channels
from roadload.sim2real.simconfig import SimConfig
from roadload.sim2real.table import build_table
from roadload.tables import markdown_table

from .cases import generate_case

SPEED_BINS_KMH = (0, 20, 40, 60, 80, 100, 120, 160)
OLD_RCOND = 1e-8


def base_gap(world: str, seed: int = 0, duration: float = 900.0, out_dir: Path | None = None) -> pd.DataFrame:
    """Rows: (variant, speed bin) with n, median raw / floor / residual [N] and the residual's RMS [N]."""
    with tempfile.TemporaryDirectory(prefix=f"gap-{world}-") as tmp:
        case = generate_case(world, "none", seed, n_trips=3, duration_s=duration, out_dir=out_dir or Path(tmp))
        trips = case.import_trips()
        matched = SimConfig.load(case.sim_path)
        default = SimConfig(matched.vehicle)
    channels = set(trips[0].channels)
    rows = []
    for variant, sim, rcond in (("before", default, OLD_RCOND), ("ambient", matched, OLD_RCOND),
                                ("after", matched, RCOND)):
        own = build_table([reduce_channels(t, channels) for t in sim_trips(sim, FLOOR_ROADS, duration)], sim).frame
        floor = SimFloor.fit(own, own["sim_balance"].to_numpy(), own["residual"].to_numpy(),
                             own["valid"].to_numpy(bool), model=None, rcond=rcond)
        f = build_table(trips, sim, floor=floor).frame
        f = f[f["valid"]]
        raw = f["tractive_force"] - f["sim_balance"]
        fl = f["sim_force"] - f["sim_balance"]
        res = f["residual"]
        bins = pd.cut(f["speed"] * 3.6, list(SPEED_BINS_KMH))
        for b, idx in res.groupby(bins, observed=True).groups.items():
            rows.append({"world": world, "variant": variant, "speed [km/h]": str(b), "n": len(idx),
                         "raw median [N]": float(raw[idx].median()), "floor median [N]": float(fl[idx].median()),
                         "residual median [N]": float(res[idx].median()),
                         "residual RMS [N]": float(np.sqrt(np.mean(res[idx] ** 2)))})
        rows.append({"world": world, "variant": variant, "speed [km/h]": "all", "n": len(res),
                     "raw median [N]": float(raw.median()), "floor median [N]": float(fl.median()),
                     "residual median [N]": float(res.median()), "residual RMS [N]": float(np.sqrt(np.mean(res ** 2)))})
    return pd.DataFrame(rows)


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
