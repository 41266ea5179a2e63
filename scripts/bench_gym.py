"""Environment steps per second: EcoDrive-v0, SB3 vector envs, the native batched vector env against its bare
batched physics, EcoHighway-v0 and highway-env (roadload.experiments.benchmarks.gym).

    python scripts/bench_gym.py --no-classic --threads 1,2       # the native-env figures, ~1 min
    python scripts/bench_gym.py [--seconds 5] [--native 256] [--n-envs 2] [--threads 1,2]     # everything
    python scripts/bench_gym.py --quick                                       # CI smoke run (< 60 s)
    python scripts/bench_gym.py --compare e7237e4 --threads 1,2 [--rounds 2]  # old commit vs working tree
"""

from pathlib import Path

from roadload.experiments.benchmarks.gym import main

if __name__ == "__main__":
    main(repo=Path(__file__).resolve().parents[1])
