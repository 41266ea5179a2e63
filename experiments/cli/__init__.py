"""The ``roadload`` command line. Each subpackage contributes its commands through a module with a
``register(app)`` function listed in ``_COMMAND_MODULES``; the core only assembles them.

Every command goes through one error path (:mod:`.errors`): bad input is one plain line and exit code 2,
internal errors one line and exit code 1; tracebacks only with the global ``--debug``."""

from __future__ import annotations

import importlib
import os

import typer

from .errors import guard_app, set_debug

app = typer.Typer(help="roadload: vehicle simulator, tractive-force estimators, eco-driving MPC, sim-to-real.",
                  no_args_is_help=True, pretty_exceptions_enable=False, rich_markup_mode=None)
benchmark_app = typer.Typer(help="Benchmarks and sweeps that print tables and write figures.", no_args_is_help=True,
                            rich_markup_mode=None)
app.add_typer(benchmark_app, name="benchmark")


@app.callback()
def _global_options(debug: bool = typer.Option(False, "--debug",
                                               help="show the Python traceback of an error (also ROADLOAD_DEBUG=1)")
                    ) -> None:
    set_debug(debug)


# modules that define register(app, benchmark_app); a missing module is a packaging bug, so no try/except
_COMMAND_MODULES: list[str] = [
    "roadload.experiments.cli.simulate",
    "roadload.experiments.cli.profiles",
    "roadload.experiments.cli.io",
    "roadload.experiments.cli.robustness",
    "roadload.experiments.cli.estimate",
    "roadload.experiments.cli.sim2real",
    "roadload.experiments.rl",
    "roadload.experiments.cli.controllers",
]
_LOADED: list[bool] = []


def _load() -> None:
    if not _LOADED:
        for name in _COMMAND_MODULES:
            importlib.import_module(name).register(app, benchmark_app)
        _LOADED.append(True)
    guard_app(app)


def main() -> None:
    # libgomp reads OMP_WAIT_POLICY once, when it is loaded, and loading the commands loads it (torch, via
    # stable-baselines3): set the native vector env's default here, first, or `roadload train --threads 2` spins
    # idle OpenMP threads (32k instead of 160k steps/s at load 4.6, docs/results/scale.md)
    os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")
    _load()
    app()
