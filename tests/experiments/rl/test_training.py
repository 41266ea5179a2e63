"""A short PPO run trains (beats a random policy on fixed held-out roads), saves and reloads; bad input errors."""

import numpy as np
import pytest

import roadload  # noqa: F401
from roadload.experiments import rl as rl_cli
from roadload.experiments.rl import command as rl_command

CONFIG = {"road": "motorway", "route_length": 1000.0}


@pytest.fixture(scope="module")
def trained(tmp_path_factory):
    import torch

    torch.set_num_threads(1)
    out = tmp_path_factory.mktemp("rl")
    res = rl_cli.train_policy("ppo", 4096, out, n_envs=2, seed=0, env_config=CONFIG, vec="dummy",
                              hyperparams={"n_steps": 256, "n_epochs": 10, "learning_rate": 1e-3})
    return res


def test_short_ppo_run_beats_random_policy_and_reloads(trained):
    import gymnasium as gym

    seeds = (50_000, 50_001, 50_002)  # roads outside the training range [0, 10000)
    ppo = [rl_cli.run_policy(rl_cli.sb3_policy(trained.extra["model"]), CONFIG, s)[0] for s in seeds]
    space = gym.make("roadload/EcoDrive-v0", config=CONFIG).action_space
    rnd = [rl_cli.run_policy(rl_cli.random_policy(space, 0), CONFIG, s)[0] for s in seeds]
    assert trained.timesteps >= 4096
    assert np.mean([m["episode_return"] for m in ppo]) > np.mean([m["episode_return"] for m in rnd]) + 50.0
    # it learned to drive, not merely to avoid the random policy's jerk: most of the route is covered
    assert np.mean([m["distance"] for m in ppo]) > 0.6 * CONFIG["route_length"]
    # the learning curve recorded finished training episodes
    assert (trained.curve.kind == "train").sum() >= 3
    # the saved policy reloads and acts identically (one test: under xdist a module fixture trains per worker)
    model = rl_cli.load_policy(trained.model_path)
    obs = np.linspace(-1, 1, model.observation_space.shape[0]).astype(np.float32)
    a1 = trained.extra["model"].predict(obs, deterministic=True)[0]
    a2 = model.predict(obs, deterministic=True)[0]
    assert np.array_equal(a1, a2)
    assert (trained.model_path.parent / "ppo_ecodrive.json").is_file()


def test_bad_training_input(tmp_path):
    with pytest.raises(rl_cli.RLError, match="unknown algorithm"):
        rl_cli.train_policy("dqn", 100, tmp_path)
    with pytest.raises(rl_cli.RLError, match="timesteps"):
        rl_cli.train_policy("ppo", 0, tmp_path)
    with pytest.raises(ValueError, match="unknown key"):
        rl_command._parse_config('{"vehicel": "bmw_i3"}')
    with pytest.raises(rl_cli.RLError, match="does not exist"):
        rl_cli.load_policy(tmp_path / "ppo_missing.zip")
    assert not list(tmp_path.iterdir())  # nothing half-written


def test_evaluation_table_uses_the_controllers_metrics_and_baselines():
    cfg = {"road": "motorway", "route_length": 800.0}

    def p_control(obs):  # obs is normalised: v / 30, speed_limit@0m / 30 at index 2 + 2 * 6
        v, limit = 30.0 * obs[0], 30.0 * obs[2 + 2 * 6]
        return np.array([np.clip(0.5 * (0.85 * limit - v), -1.0, 1.0)], dtype=np.float32)

    table, notes = rl_cli.evaluation_table({"p": p_control}, cfg, road_seeds=(50_000,), controllers=("cruise",))
    assert not notes and list(table.controller) == ["p", "cruise"]
    assert list(table.columns) == rl_cli.TABLE_COLUMNS
    row = table.iloc[0]
    assert row.arrived and row.speed_violations == 0 and 20.0 < row.trip_time < 80.0
    m, log = rl_cli.run_policy(p_control, cfg, 50_000)
    assert m["energy_kWh"] == pytest.approx(log.energy.iloc[-1] / 3.6e6)
    cruise = table.iloc[1]
    assert cruise.arrived and np.isfinite(cruise.energy_kWh) and np.isnan(cruise.episode_return)
    summary = rl_cli.summarise(table)
    assert list(summary.controller) == ["p", "cruise"] and (summary.common_roads == 1).all()
    assert summary.energy_kWh.iloc[1] == pytest.approx(cruise.energy_kWh)


def test_summary_compares_energy_on_common_roads_only():
    import pandas as pd

    rows = [("a", 1, True, 1.0, 100.0), ("a", 2, True, 3.0, 100.0), ("b", 1, True, 2.0, 90.0),
            ("b", 2, False, 0.1, float("nan")), ("random", 1, False, 0.5, float("nan")),
            ("random", 2, False, 0.5, float("nan"))]
    table = pd.DataFrame(rows, columns=["controller", "road_seed", "arrived", "energy_kWh", "trip_time"])
    for col in rl_cli.TABLE_COLUMNS:
        if col not in table:
            table[col] = 0.0
    table["cost_kJ"] = table.energy_kWh * 3600 + 3.0 * table.trip_time
    s = rl_cli.summarise(table).set_index("controller")
    # road 2 is not common (b did not finish it): a's energy is its road-1 value, not the mean over both roads
    assert s.loc["a", "energy_kWh"] == 1.0 and s.loc["b", "energy_kWh"] == 2.0
    assert s.loc["b", "arrived"] == 0.5 and np.isnan(s.loc["random", "energy_kWh"])
    assert (s.common_roads == 1).all()


def test_bench_single_counts_steps():
    row = rl_cli.bench_single("roadload/EcoDrive-v0", seconds=0.01, route_length=300.0)
    assert row["steps"] >= 64 and row["steps_per_s"] > 0


def test_threads_reach_the_native_env_of_the_training_path(tmp_path):
    """``roadload train --threads`` -> train_policy -> make_vec_env -> the native vector env's numba threads;
    other vec modes refuse threads (nothing written)."""
    from roadload.experiments.rl.common import make_vec_env
    from roadload.gym.vector import EcoDriveVectorEnv

    venv = make_vec_env(3, 0, {"route_length": 150.0}, vec="native", threads=2)
    assert isinstance(venv.venv, EcoDriveVectorEnv) and venv.venv.threads == 2
    venv.close()
    with pytest.raises(rl_cli.RLError, match="threads"):
        rl_cli.train_policy("ppo", 64, tmp_path, n_envs=2, vec="dummy", threads=2)
    with pytest.raises(ValueError, match="threads"):
        make_vec_env(2, 0, None, vec="native", threads=0)
    assert not list(tmp_path.iterdir())
    from typer.testing import CliRunner

    from roadload.experiments.cli import app

    res = CliRunner().invoke(app, ["train", "--threads", "0", "--algo", "ppo", "--timesteps", "64", "--out",
                                   str(tmp_path), "--eval-every", "0", "--skip-evaluation"])
    assert res.exit_code == 2 and "--threads: at least 1" in res.output, res.output


def test_cli_sets_the_openmp_wait_policy_before_the_runtime_loads():
    """`roadload train --threads 2` runs with OMP_WAIT_POLICY=PASSIVE in effect: the CLI sets it before loading the
    commands (which load libgomp through torch); set later, libgomp ignores it and idle threads spin."""
    import os
    import subprocess
    import sys

    code = ("import os, sys; sys.argv = ['roadload', '--help']\n"
            "from roadload.experiments.cli import main\n"
            "try:\n    main()\nexcept SystemExit:\n    pass\n"
            "from roadload.gym.vector import openmp_wait_policy\n"
            "print('POLICY', openmp_wait_policy())")
    env = {k: v for k, v in os.environ.items() if k != "OMP_WAIT_POLICY"}
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, timeout=300)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip().splitlines()[-1] == "POLICY PASSIVE"
