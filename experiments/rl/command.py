"""``roadload train``: train, evaluate and report (the command is registered by :mod:`roadload.experiments.cli`)."""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import typer

from roadload.gym.config import EcoDriveConfig, make_config
from roadload.tables import write_csv

from .common import HELD_OUT_SEEDS, RLError, _algo_class
from .rollouts import CONTROLLER_BASELINES, random_policy, sb3_policy
from .training import TrainResult, load_policy, plot_learning_curves, plot_speed_profiles, train_policy
from .evaluation import evaluation_table, summarise
from .benchmark import run_benchmark, speed_ratio


# --------------------------------------------------------------------------------------------- CLI
def _fail(msg: str) -> None:
    typer.secho(f"error: {msg}", fg=typer.colors.RED, err=True)
    raise typer.Exit(code=2)


def _parse_config(text: str | None) -> dict[str, Any]:
    if not text:
        return {}
    p = Path(text)
    try:
        raw = p.read_text() if p.suffix == ".json" and p.is_file() else text
        cfg = json.loads(raw)
    except (OSError, json.JSONDecodeError) as exc:
        raise RLError(f"--config: not a JSON object or JSON file ({exc})") from None
    if not isinstance(cfg, dict):
        raise RLError("--config: must be a JSON object")

    make_config(EcoDriveConfig, cfg)  # validate now: a bad key fails before any training
    return cfg


def print_table(console, table: pd.DataFrame, title: str, floatfmt: str = "{:.3g}") -> None:
    from rich.table import Table

    t = Table(title=title)
    for col in table.columns:
        t.add_column(str(col))
    for _, row in table.iterrows():
        t.add_row(*[floatfmt.format(v) if isinstance(v, (float, np.floating)) else str(v) for v in row])
    console.print(t)


def load_trained(algo: str, out_dir: Path) -> TrainResult:
    """A policy saved by train_policy in ``out_dir`` with its learning curve CSV and metadata."""
    out_dir = Path(out_dir)
    model = load_policy(out_dir / f"{algo}_ecodrive.zip")
    curve_path = out_dir / f"{algo}_learning_curve.csv"
    curve = pd.read_csv(curve_path) if curve_path.is_file() else pd.DataFrame(columns=["timesteps", "kind", "value"])
    meta_path = out_dir / f"{algo}_ecodrive.json"
    meta = json.loads(meta_path.read_text()) if meta_path.is_file() else {}
    return TrainResult(algo, out_dir / f"{algo}_ecodrive.zip", curve, float(meta.get("seconds", float("nan"))),
                       int(meta.get("timesteps", model.num_timesteps)), {"model": model, "meta": meta})


def train_and_evaluate(algos: list[str], timesteps: int, out_dir: Path, n_envs: int, seed: int,
                       env_config: dict[str, Any], vec: str, eval_every: int, road_seeds, console=None,
                       controllers: tuple[str, ...] = ("cruise", "mpc"), evaluate_only: bool = False,
                       skip_evaluation: bool = False, threads: int = 1, checkpoint_every: int = 0
                       ) -> dict[str, Any]:
    """The whole workflow of ``roadload train`` / scripts/train_rl.py: train each algorithm (or, with
    ``evaluate_only``, load what an earlier run saved in ``out_dir``), write the learning curve PNG, evaluate on
    held-out roads with the baselines, write CSV tables; returns paths and tables."""
    from rich.console import Console
    from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn, TimeRemainingColumn

    console = console or Console()
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    results = []
    with Progress(TextColumn("{task.description}"), BarColumn(), TextColumn("{task.completed}/{task.total}"),
                  TimeElapsedColumn(), TimeRemainingColumn(), console=console) as bar:
        for algo in algos:
            if evaluate_only:
                res = load_trained(algo, out_dir)
                env_config = res.extra["meta"].get("env_config", env_config)
            else:
                task = bar.add_task(f"training {algo.upper()}", total=timesteps)
                res = train_policy(algo, timesteps, out_dir, n_envs=n_envs, seed=seed, env_config=env_config,
                                   vec=vec, eval_every=eval_every, threads=threads,
                                   progress=lambda n: bar.update(task, completed=n),
                                   checkpoint_every=checkpoint_every)
                if res.extra["resume"].startswith(("resumed", "checkpoint")):
                    console.print(f"{algo.upper()}: {res.extra['resume']}")
                curve = res.curve
                write_csv(out_dir / f"{algo}_learning_curve.csv", curve)
            results.append(res)
        curve_png = plot_learning_curves(results, out_dir / "learning_curve.png")
        if skip_evaluation:
            return {"results": results, "curve_png": curve_png, "table": None, "summary": None, "notes": [],
                    "table_path": None}
        n_eval = len(road_seeds) * (len(results) + 1 + len(controllers))
        task = bar.add_task("evaluating on held-out roads", total=n_eval)
        policies = {r.algo.upper(): sb3_policy(r.extra["model"]) for r in results}
        import gymnasium as gym

        space = gym.make("roadload/EcoDrive-v0", config=env_config).action_space
        policies["random"] = random_policy(space, seed)
        logs: dict[str, pd.DataFrame] = {}
        table, notes = evaluation_table(policies, env_config, road_seeds, controllers,
                                        progress=lambda _m: bar.advance(task), logs=logs)
        profiles_png = plot_speed_profiles(logs, env_config, road_seeds[0], out_dir / "speed_profiles.png")
    table_path = out_dir / "evaluation.csv"
    summary = summarise(table)
    write_csv(table_path, table)
    write_csv(out_dir / "evaluation_summary.csv", summary)
    return {"results": results, "curve_png": curve_png, "table": table, "summary": summary, "notes": notes,
            "table_path": table_path, "profiles_png": profiles_png}


def register(app: typer.Typer, benchmark_app: typer.Typer) -> None:
    @app.command("train")
    def train_cmd(
        algo: str = typer.Option("ppo,sac", help="algorithms, comma-separated: ppo, sac"),
        timesteps: int = typer.Option(200_000, help="environment steps per algorithm (0.1 s of driving each)"),
        n_envs: int = typer.Option(2, help="vectorised environments"),
        vec: str = typer.Option("native", help="'native' (batched vector env, observation 'state'), 'subproc' "
                                "(one process per env) or 'dummy' (in-process)"),
        threads: int = typer.Option(1, help="numba threads of the native vector env (--vec native): 2 on 2 idle "
                                    "cores; 1 on a shared machine, where a second thread waits at every step"),
        seed: int = typer.Option(0, help="training seed"),
        config: str = typer.Option(None, help="EcoDrive-v0 config as JSON text or a .json file, e.g. "
                                   "'{\"vehicle\": \"gt_rwd\", \"road\": \"city\"}'"),
        eval_every: int = typer.Option(20_000, help="validation-road evaluation period [steps] (0 = off)"),
        held_out: int = typer.Option(len(HELD_OUT_SEEDS), help="number of held-out roads in the final table"),
        out: Path = typer.Option(Path("out/rl"), help="output folder (policies, learning_curve.png, CSV)"),
        baselines: str = typer.Option("cruise,mpc", help="controller baselines in the table: cruise (PI, abc model), "
                                      "mpc (oracle force model), mpc_online (online RRLM force model)"),
        evaluate_only: bool = typer.Option(False, help="no training: evaluate the policies saved in --out"),
        skip_evaluation: bool = typer.Option(False, help="train and plot only, no held-out evaluation"),
        checkpoint_every: int = typer.Option(50_000, min=0, help="save the training state every this many steps "
                                             "[steps] in --out; the same command after a crash continues from "
                                             "the last one (0 = off)"),
    ) -> None:
        """Train PPO / SAC on EcoDrive-v0, save the policies, and compare them on held-out roads with cruise
        control and the MPC (energy, time, violations)."""
        from rich.console import Console

        console = Console()
        try:
            algos = [a.strip().lower() for a in algo.split(",") if a.strip()]
            for a in algos:
                _algo_class(a)
            if held_out < 1:
                raise RLError("--held-out must be >= 1")
            env_config = _parse_config(config)
            seeds = tuple(HELD_OUT_SEEDS[0] + i for i in range(held_out))
            ctl = tuple(b.strip() for b in baselines.split(",") if b.strip())
            bad = [b for b in ctl if b not in CONTROLLER_BASELINES]
            if bad:
                raise RLError(f"--baselines: unknown {bad}; choose from {sorted(CONTROLLER_BASELINES)}")
            res = train_and_evaluate(algos, timesteps, out, n_envs, seed, env_config, vec, eval_every, seeds,
                                     console, controllers=ctl, evaluate_only=evaluate_only,
                                     skip_evaluation=skip_evaluation, threads=threads,
                                     checkpoint_every=checkpoint_every)
        except ValueError as exc:  # RLError, GymConfigError
            _fail(str(exc))
        for r in res["results"]:
            console.print(f"{r.algo.upper()}: {r.timesteps} steps in {r.seconds:.0f} s "
                          f"({r.timesteps / r.seconds:.0f} steps/s) -> {r.model_path}")
        if res["summary"] is not None:
            print_table(console, res["summary"], "held-out roads, mean per controller")
        for n in res["notes"]:
            console.print(f"[yellow]{n}")
        console.print(f"learning curve: {res['curve_png']}\nper-road table: {res['table_path']}")
        if res.get("profiles_png"):
            console.print(f"speed profiles on the first held-out road: {res['profiles_png']}")

    @benchmark_app.command("gym")
    def bench_cmd(
        seconds: float = typer.Option(5.0, help="measurement time per row [s]"),
        n_envs: int = typer.Option(2, help="vectorised environments"),
        highway: bool = typer.Option(True, help="also measure EcoHighway-v0 and highway-env's highway-fast-v0"),
    ) -> None:
        """Environment steps per second: EcoDrive-v0 single process and vectorised, EcoHighway-v0, and
        highway-env's highway-fast-v0 in the same run."""
        from rich.console import Console

        console = Console(width=max(150, Console().width))
        with console.status("measuring") as status:
            table = run_benchmark(seconds, n_envs, highway, progress=lambda m: status.update(f"done: {m}"))
        print_table(console, table.drop(columns=["episodes"]), "environment steps per second", "{:.1f}")
        ratio = speed_ratio(table)
        if math.isfinite(ratio):
            console.print(f"EcoDrive-v0 / highway-fast-v0 steps/s ratio: {ratio:.0f}x")
