"""Reinforcement learning on ``roadload/EcoDrive-v0``: training (PPO / SAC from stable-baselines3 on vectorised
envs), evaluation on held-out roads against cruise control and the MPC (the controllers' metrics), and the
environment speed benchmark. CLI: ``roadload train`` and ``roadload benchmark gym`` (roadload.experiments.cli.rl);
scripts/train_rl.py and scripts/bench_gym.py call the same functions.

Road seeds: training episodes draw roads from ``road_seed_range`` (default [0, 10000)); the learning-curve
evaluation uses VALIDATION_SEEDS and the final table HELD_OUT_SEEDS, both outside the training range.

Modules: ``common`` (ids, seeds, vectorised envs), ``rollouts``, ``training``, ``evaluation``, ``benchmark``
(environment speed), ``command`` (the workflow of ``roadload train``).
"""

from .common import (  # noqa: F401
    ALGO_DEFAULTS,
    ENV_ID,
    HELD_OUT_SEEDS,
    RLError,
    VALIDATION_SEEDS,
    VEC_MODES,
    make_vec_env,
)
from .rollouts import (  # noqa: F401
    CONTROLLER_BASELINES,
    random_policy,
    run_controller,
    run_policy,
    sb3_policy,
)
from .training import (  # noqa: F401
    TrainResult,
    load_policy,
    plot_learning_curves,
    plot_speed_profiles,
    train_policy,
)
from .evaluation import (  # noqa: F401
    TABLE_COLUMNS,
    evaluation_table,
    summarise,
)
from .benchmark import (  # noqa: F401
    bench_native,
    bench_single,
    bench_vectorised,
    load_average,
    native_ratios,
    run_benchmark,
    run_native_benchmark,
    speed_ratio,
)
from .command import (  # noqa: F401
    load_trained,
    print_table,
    train_and_evaluate,
)
