"""The workflow of ``roadload train``: train, evaluate and report (the command itself, light at import, is in
:mod:`roadload.experiments.cli.rl`)."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from roadload.gym.config import EcoDriveConfig, make_config
from roadload.tables import markdown_table, write_csv

from .common import RLError
from .rollouts import random_policy, sb3_policy
from .training import TrainResult, load_policy, plot_learning_curves, plot_speed_profiles, train_policy
from .evaluation import evaluation_table, summarise


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
    """``title`` and the table as Markdown, whole at any terminal width (a rich table squeezes its columns into
    80 characters when the output is not a terminal)."""
    fmt = floatfmt[2:-1] if floatfmt.startswith("{:") and floatfmt.endswith("}") else None
    cells = table.copy()
    for col in cells.columns:
        if cells[col].dtype.kind == "f" and fmt is not None:
            cells[col] = cells[col].map(lambda v: format(v, fmt) if np.isfinite(v) else "–")
    console.print(f"{title}\n{markdown_table(cells)}", soft_wrap=True, markup=False, highlight=False)


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
    # the bars on stderr, gone when done (stdout is for the results); redrawn at every update, as a compiled step
    # can hold the GIL past the refresh thread's turn
    with Progress(TextColumn("{task.description}"), BarColumn(), TextColumn("{task.completed}/{task.total}"),
                  TimeElapsedColumn(), TimeRemainingColumn(), console=Console(stderr=True), transient=True) as bar:
        for algo in algos:
            if evaluate_only:
                res = load_trained(algo, out_dir)
                env_config = res.extra["meta"].get("env_config", env_config)
            else:
                task = bar.add_task(f"training {algo.upper()}", total=timesteps)
                res = train_policy(algo, timesteps, out_dir, n_envs=n_envs, seed=seed, env_config=env_config,
                                   vec=vec, eval_every=eval_every, threads=threads,
                                   progress=lambda n: bar.update(task, completed=n, refresh=True),
                                   checkpoint_every=checkpoint_every)
                if res.extra["resume"].startswith(("resumed", "checkpoint")):
                    console.print(f"{algo.upper()}: {res.extra['resume']}")
                curve = res.curve
                write_csv(out_dir / f"{algo}_learning_curve.csv", curve)
            results.append(res)
        curve_png = plot_learning_curves(results, out_dir / "learning_curve.png")  # None: no point to plot
        if skip_evaluation:
            return {"results": results, "curve_png": curve_png, "table": None, "summary": None, "notes": [],
                    "table_path": None}
        with_random = "random" in controllers  # the random policy only when asked for, as a baseline
        controllers = tuple(c for c in controllers if c != "random")
        n_eval = len(road_seeds) * (len(results) + int(with_random) + len(controllers))
        task = bar.add_task("evaluating on held-out roads", total=n_eval)
        policies = {r.algo.upper(): sb3_policy(r.extra["model"]) for r in results}
        import gymnasium as gym

        space = gym.make("roadload/EcoDrive-v0", config=env_config).action_space
        if with_random:
            policies["random"] = random_policy(space, seed)
        logs: dict[str, pd.DataFrame] = {}
        table, notes = evaluation_table(policies, env_config, road_seeds, controllers,
                                        progress=lambda _m: bar.update(task, advance=1, refresh=True), logs=logs)
        profiles_png = plot_speed_profiles(logs, env_config, road_seeds[0], out_dir / "speed_profiles.png")
    table_path = out_dir / "evaluation.csv"
    summary = summarise(table)
    write_csv(table_path, table)
    write_csv(out_dir / "evaluation_summary.csv", summary)
    return {"results": results, "curve_png": curve_png, "table": table, "summary": summary, "notes": notes,
            "table_path": table_path, "profiles_png": profiles_png}
