"""Train PPO (stable-baselines3) on roadload/EcoTraffic-v0's native vector env (safety layer on), one policy per
seed, and compare them with the IDM follower on held-out episodes, natively and on the highway-env backend
(roadload.experiments.rl.traffic_training).

    OMP_WAIT_POLICY=PASSIVE python scripts/train_traffic.py --seeds 0,1,2 --timesteps 2000000 --out out/rl_traffic
    python scripts/train_traffic.py --evaluate-only --seeds 0,1,2 --out out/rl_traffic     # re-evaluate
    python scripts/train_traffic.py --quick             # CI smoke run (4k steps, 2 + 1 held-out episodes)
"""

import os

os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")  # before torch loads libgomp (roadload.gym.vector)

import argparse  # noqa: E402
import json  # noqa: E402
import tempfile  # noqa: E402
from pathlib import Path  # noqa: E402

from roadload.experiments.rl.traffic_training import run_traffic_experiment  # noqa: E402
from roadload.tables import markdown_table  # noqa: E402


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", default="0,1,2", help="training seeds, comma-separated")
    ap.add_argument("--timesteps", type=int, default=2_000_000, help="env steps per seed (0.1 s of driving each)")
    ap.add_argument("--n-envs", type=int, default=32, help="sub-envs of the native vector env")
    ap.add_argument("--threads", type=int, default=1, help="numba threads of the vector env")
    ap.add_argument("--episodes", type=int, default=50, help="held-out episodes on the native backend")
    ap.add_argument("--transfer-episodes", type=int, default=20, help="held-out episodes on highway-env (0: none)")
    ap.add_argument("--config", default=None, help="EcoTraffic-v0 config as JSON text (default: shield on)")
    ap.add_argument("--out", type=Path, default=Path("out/rl_traffic"))
    ap.add_argument("--evaluate-only", action="store_true", help="load the policies saved in --out")
    ap.add_argument("--quick", action="store_true", help="tiny run for CI")
    a = ap.parse_args()
    try:
        seeds = tuple(int(s) for s in a.seeds.split(",") if s.strip())
    except ValueError:
        ap.error(f"--seeds: expected comma-separated integers, got {a.seeds!r}")
    config = json.loads(a.config) if a.config else {}
    if a.quick:
        seeds, a.timesteps, a.n_envs, a.episodes, a.transfer_episodes = (0,), 4096, 8, 2, 1
        config = {"duration": 5.0, "vehicles_count": 10, **config}
        if a.out == Path("out/rl_traffic"):
            a.out = Path(tempfile.mkdtemp(prefix="roadload-rl-traffic-"))
    if not seeds or a.timesteps < 1 or a.episodes < 1:
        ap.error("--seeds, --timesteps and --episodes must be given and >= 1")
    res = run_traffic_experiment(seeds, a.timesteps, a.out, a.episodes, a.transfer_episodes, a.n_envs, config,
                                 a.threads, a.evaluate_only, progress=lambda m: print(m, flush=True))
    print(markdown_table(res["summary"], floatfmt=".4g"))
    if len(res["intervals"]):
        print(markdown_table(res["intervals"], floatfmt=".4g"))
    print(f"tables and policies in {res['out_dir']}")


if __name__ == "__main__":
    main()
