"""Fidelity of roadload/EcoTraffic-v0 (native) against roadload/EcoHighway-v0 (highway-env) on the same scenario,
both egos driven by the IDM follower (roadload.experiments.rl.traffic_fidelity): headway, speed and lane-change
figures of the traffic, the IDM egos' collision rate and energy per km, each with its relative difference and 95 %
bootstrap interval.

    python scripts/traffic_fidelity.py --episodes 100 --out docs/results/traffic     # ~25 min (highway-env side)
    python scripts/traffic_fidelity.py --quick                                       # CI smoke run (2 episodes)
"""

import argparse
import json
import tempfile
from pathlib import Path

from roadload.experiments.rl.traffic_fidelity import run_fidelity
from roadload.tables import markdown_table, write_csv


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--episodes", type=int, default=100, help="IDM episodes on highway-env")
    ap.add_argument("--native-episodes", type=int, default=None, help="IDM episodes on the native backend "
                                                                       "(default: as many)")
    ap.add_argument("--config", default=None, help="EcoTraffic-v0 config as JSON text (curvature is set False)")
    ap.add_argument("--out", type=Path, default=None, help="folder for fidelity.csv / fidelity.md / fidelity.json")
    ap.add_argument("--quick", action="store_true", help="2 short episodes per backend")
    a = ap.parse_args()
    config = json.loads(a.config) if a.config else {}
    if a.quick:
        a.episodes, a.native_episodes = 2, 2
        config = {"duration": 5.0, "vehicles_count": 10, **config}
        a.out = a.out or Path(tempfile.mkdtemp(prefix="roadload-fidelity-"))
    if a.episodes < 1:
        ap.error("--episodes must be >= 1")
    res = run_fidelity(a.episodes, a.native_episodes, config,
                       progress=lambda m: print(m, flush=True) if m.endswith("0/" + str(a.episodes)) else None)
    table = res["table"]
    print(markdown_table(table, floatfmt=".4g"))
    print(f"episodes: {res['episodes']}; wall seconds: "
          f"{ {k: round(v, 1) for k, v in res['seconds'].items()} }")
    if a.out:
        a.out.mkdir(parents=True, exist_ok=True)
        write_csv(a.out / "fidelity.csv", table)
        (a.out / "fidelity.md").write_text(markdown_table(table, floatfmt=".4g") + "\n")
        (a.out / "fidelity.json").write_text(json.dumps(
            {"episodes": res["episodes"], "seconds": res["seconds"], "config": res["config"].model_dump()},
            indent=1, default=str))
        print(f"written to {a.out}")


if __name__ == "__main__":
    main()
