"""Train PPO (stable-baselines3) on roadload/EcoHighway-v0 and compare it on held-out episodes with a cruise
speed hold, an IDM follower and random actions (roadload.experiments.rl.highway).

    python scripts/train_rl_highway.py --timesteps 75000 --n-envs 4 --out out/rl_highway
    python scripts/train_rl_highway.py --quick          # tiny run for CI (512 steps, 2 held-out episodes)
"""

import argparse
import json
import tempfile
from pathlib import Path

from roadload.experiments.rl.highway import HIGHWAY_HELD_OUT_SEEDS, train_highway


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--timesteps", type=int, default=75_000, help="environment steps (0.5 s of driving each)")
    ap.add_argument("--n-envs", type=int, default=4, help="environments in the DummyVecEnv")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--episodes", type=int, default=len(HIGHWAY_HELD_OUT_SEEDS), help="held-out episodes")
    ap.add_argument("--config", default=None, help="EcoHighway-v0 config as JSON text")
    ap.add_argument("--out", type=Path, default=Path("out/rl_highway"))
    ap.add_argument("--quick", action="store_true", help="tiny run (512 steps, 2 episodes, 5 traffic vehicles)")
    a = ap.parse_args()
    config = json.loads(a.config) if a.config else {}
    if a.quick:
        a.timesteps, a.episodes, a.n_envs = 512, 2, 2
        config = {"vehicles_count": 5, "duration": 10.0, **config}
        if a.out == Path("out/rl_highway"):
            a.out = Path(tempfile.mkdtemp(prefix="roadload-rl-highway-"))
    res = train_highway(a.timesteps, a.out, n_envs=a.n_envs, seed=a.seed, env_config=config,
                        seeds=HIGHWAY_HELD_OUT_SEEDS[:a.episodes])
    print(f"PPO on EcoHighway-v0: {res['timesteps']} steps in {res['seconds']:.0f} s "
          f"({res['timesteps'] / res['seconds']:.0f} steps/s)")
    print(res["summary"].to_string(index=False, float_format=lambda x: f"{x:.3g}"))
    print(f"tables and learning curve in {res['out_dir']}")


if __name__ == "__main__":
    main()
