"""The ``roadload`` command line. Each subpackage contributes its commands through a module with a
``register(app)`` function listed in ``_COMMAND_MODULES``; the core only assembles them."""

from __future__ import annotations

import importlib

import typer

app = typer.Typer(help="roadload: vehicle simulator, tractive-force estimators, eco-driving MPC, sim-to-real.",
                  no_args_is_help=True, pretty_exceptions_enable=False)
benchmark_app = typer.Typer(help="Benchmarks and sweeps that print tables and write figures.", no_args_is_help=True)
app.add_typer(benchmark_app, name="benchmark")

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


def _load() -> None:
    for name in _COMMAND_MODULES:
        importlib.import_module(name).register(app, benchmark_app)


def main() -> None:
    _load()
    app()
