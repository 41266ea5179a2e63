"""``roadload train`` and ``roadload benchmark gym``.

Light at import (see the package docstring): stable-baselines3, torch, the gym envs and matplotlib load inside the
commands (roadload.experiments.rl), after the arguments are checked."""

from __future__ import annotations

import json
import math
from pathlib import Path

import typer

from .errors import CliInputError, choose, fail

#: algorithms and table baselines the command accepts (roadload.experiments.rl: _algo_class, CONTROLLER_BASELINES
#: plus the random policy), here so that a typo is refused before torch loads; tests/experiments/cli/test_startup.py
#: checks they agree
ALGORITHMS = ("ppo", "sac")
BASELINES = ("cruise", "mpc", "mpc_online", "random")
VEC_MODES = ("native", "subproc", "dummy")


def _config_text(text: str | None) -> str | None:
    """The --config JSON: a .json file's text or the option's text, checked to be a JSON object."""
    if not text:
        return None
    path = Path(text)
    if path.suffix == ".json":
        if not path.is_file():
            raise CliInputError(f"--config: no file {path}")
        text = path.read_text()
    try:
        cfg = json.loads(text)
    except json.JSONDecodeError as exc:
        raise CliInputError(f"--config: not a JSON object or JSON file ({exc})") from None
    if not isinstance(cfg, dict):
        raise CliInputError(f"--config: must be a JSON object, got {type(cfg).__name__}")
    return text


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
        held_out: int = typer.Option(None, help="number of held-out roads in the final table (default: all 5, "
                                                "road seeds 50000-50004)"),
        out: Path = typer.Option(Path("out/rl"), help="output folder (policies, learning_curve.png, CSV)"),
        baselines: str = typer.Option("cruise,mpc", help="baselines in the table: cruise (PI, abc model), mpc "
                                      "(oracle force model), mpc_online (online RRLM force model), random (a "
                                      "uniformly random policy)"),
        evaluate_only: bool = typer.Option(False, help="no training: evaluate the policies saved in --out"),
        skip_evaluation: bool = typer.Option(False, help="train and plot only, no held-out evaluation"),
        checkpoint_every: int = typer.Option(50_000, min=0, help="save the training state every this many steps "
                                             "[steps] in --out; the same command after a crash continues from "
                                             "the last one (0 = off)"),
    ) -> None:
        """Train PPO / SAC on EcoDrive-v0, save the policies, and compare them on held-out roads with cruise
        control and the MPC (energy, time, violations)."""
        algos = [a.strip().lower() for a in algo.split(",") if a.strip()]
        if not algos:
            raise CliInputError(f"--algo: no algorithm named in {algo!r}; choose from {', '.join(ALGORITHMS)}")
        for a in algos:
            choose(a, ALGORITHMS, "--algo", "algorithm")
        choose(vec, VEC_MODES, "--vec", "vectorisation")
        if threads < 1:
            raise CliInputError(f"--threads: at least 1 numba thread, got {threads}")
        if held_out is not None and held_out < 1:
            raise CliInputError(f"--held-out: at least 1 road, got {held_out}")
        if timesteps < 1 and not evaluate_only:
            raise CliInputError(f"--timesteps: at least 1 step, got {timesteps}")
        ctl = tuple(b.strip() for b in baselines.split(",") if b.strip())
        for b in ctl:
            choose(b, BASELINES, "--baselines", "baseline")
        config_text = _config_text(config)

        from rich.console import Console

        from roadload.experiments.rl import HELD_OUT_SEEDS, RLError
        from roadload.experiments.rl.command import _parse_config, print_table, train_and_evaluate

        console = Console(soft_wrap=True)  # long lines whole, at any terminal width
        try:
            env_config = _parse_config(config_text)
            n_roads = len(HELD_OUT_SEEDS) if held_out is None else held_out
            seeds = tuple(HELD_OUT_SEEDS[0] + i for i in range(n_roads))
            res = train_and_evaluate(algos, timesteps, out, n_envs, seed, env_config, vec, eval_every, seeds,
                                     console, controllers=ctl, evaluate_only=evaluate_only,
                                     skip_evaluation=skip_evaluation, threads=threads,
                                     checkpoint_every=checkpoint_every)
        except RLError as exc:
            fail(str(exc))
        for r in res["results"]:
            console.print(f"{r.algo.upper()}: {r.timesteps} steps in {r.seconds:.0f} s "
                          f"({r.timesteps / r.seconds:.0f} steps/s) -> {r.model_path}")
        if res["summary"] is not None:
            print_table(console, res["summary"], "held-out roads, mean per controller")
        for n in res["notes"]:
            console.print(f"[yellow]{n}")
        console.print(f"learning curve: {res['curve_png']}" if res["curve_png"] is not None else
                      "learning curve: none (no finished training episode or validation in this run; "
                      "--eval-every > 0 adds validation points)")
        if res["table_path"] is not None:
            console.print(f"per-road table: {res['table_path']}")
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
        if not seconds > 0:
            raise CliInputError(f"--seconds: must be > 0 [s], got {seconds:g}")
        from rich.console import Console

        from roadload.experiments.rl import print_table, run_benchmark, speed_ratio

        console = Console()
        with console.status("measuring") as status:
            table = run_benchmark(seconds, n_envs, highway, progress=lambda m: status.update(f"done: {m}"))
        print_table(console, table.drop(columns=["episodes"]), "environment steps per second", "{:.1f}")
        ratio = speed_ratio(table)
        if math.isfinite(ratio):
            console.print(f"EcoDrive-v0 / highway-fast-v0 steps/s ratio: {ratio:.0f}x")
