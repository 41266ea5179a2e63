"""The ``roadload`` command line, assembled lazily so that it answers at once.

``roadload --help`` imports no command module: it prints the one-line help of every command from the tables below.
A command's module is imported only when that command (or its ``--help``) runs; every command goes through one
error path (:mod:`.errors`): bad input is one plain line and exit code 2, internal errors one line and exit code 1;
tracebacks only with the global ``--debug``. Unknown commands get "did you mean".

How to add a command (the pattern every command module follows)
---------------------------------------------------------------
1. Write it in a module of this package with ``register(app, benchmark_app)`` that adds the command(s) with
   typer (top-level commands on ``app``, ``roadload benchmark ...`` commands on ``benchmark_app``, a command group
   as a ``typer.Typer`` added to ``app``).
2. At the top of the module import only what the argument checks need: typer, ``pathlib``, ``.errors``
   (:func:`.errors.choose` and :func:`.errors.require_file` say "did you mean"), and light roadload modules
   (``roadload.presets``, ``roadload.channels``, ``roadload.io.mapping``). Not at the top: ``roadload.envs``,
   ``roadload.estimators``, ``roadload.controllers``, ``roadload.sim2real``, ``roadload.road_profiles``,
   ``roadload.experiments.rl`` (numba kernels, CasADi, torch, scipy), matplotlib, dask, highway-env: import those
   inside the command function, after its arguments and input files have been checked::

       @app.command("calibrate")
       def calibrate_cmd(trip: Path = typer.Argument(...), out: Path = typer.Option(...)) -> None:
           \"\"\"Calibrate the sim's base parameters on recorded trips.\"\"\"
           require_file(trip, "TRIP")                       # checks first: fast refusals
           from roadload.sim2real.calibrate import calibrate  # then the heavy import
           ...

3. List the command below in :data:`COMMANDS` (or :data:`BENCHMARKS`) with its module and the first line of its
   docstring. tests/experiments/cli/test_startup.py checks that every listed line matches the command's own help
   and that ``roadload --help`` imports none of the heavy dependencies.
"""

from __future__ import annotations

import difflib
import importlib
import os
from typing import Any

import typer
from typer.core import TyperGroup

from .errors import guard_app, set_debug

_PKG = "roadload.experiments.cli"

#: top-level command -> (module that registers it, one-line help as its docstring starts)
COMMANDS: dict[str, tuple[str, str]] = {
    "simulate": (f"{_PKG}.simulate", "Simulate a trip (100 Hz CAN-like channels + ground truth) and write it as "
                                     "Parquet."),
    "plot": (f"{_PKG}.simulate", "Plot a trip over distance (speed, forces, grade and elevation, energy) to a PNG."),
    "effects": (f"{_PKG}.simulate", "List the simulator's effects with their equations and parameters."),
    "import": (f"{_PKG}.io", "Import a real log into a Trip (SI channels on a uniform time base, import report in "
                             "the metadata)."),
    "export": (f"{_PKG}.io", "Export a Trip for other tools: ASAM MDF4 (asammdf, units per channel), CSV with a "
                             "units row, or MATLAB .mat."),
    "export-can": (f"{_PKG}.io", "Write a Trip as CAN traffic: log + project DBC (scales = sensor quantisation) + "
                                 "import mapping."),
    "convert": (f"{_PKG}.io", "Rewrite a trip file of an older format (or another precision) as the current open "
                              "Parquet format."),
    "estimate": (f"{_PKG}.estimate", "Run the chapter-5 pipeline and one model-estimator combination over a trip."),
    "diagnose": (f"{_PKG}.sim2real", "Diagnose where a sim departs from recorded trips, which effect explains it, "
                                     "how far the gap shrinks."),
    "calibrate": (f"{_PKG}.sim2real", "Calibrate the sim's base vehicle to reference trips and write it as a "
                                      "vehicle spec."),
    "train": (f"{_PKG}.rl", "Train PPO / SAC on EcoDrive-v0, save the policies, and compare them on held-out roads "
                            "with cruise control and the MPC (energy, time, violations)."),
    "drive": (f"{_PKG}.controllers", "Drive a road once in closed loop on the simulator and print energy, time, "
                                     "violations, jerk, solver time and fallbacks."),
    "benchmark": ("", "Benchmarks and sweeps that print tables and write figures."),
    "profiles": (f"{_PKG}.profiles", "Road profiles and drive cycles: list, show, export."),
    "sim2real": (f"{_PKG}.sim2real", "Sim-to-real gap diagnosis."),
}

#: ``roadload benchmark`` command -> (module, one-line help)
BENCHMARKS: dict[str, tuple[str, str]] = {
    "simulator": (f"{_PKG}.simulate", "Simulator speed: real-time factor at 100 Hz with all sensors and effects, "
                                      "memory, step throughput."),
    "fleet": (f"{_PKG}.estimate", "Chapter-5 benchmark over the simulated fleet (generated into the cache when "
                                  "absent)."),
    "robustness": (f"{_PKG}.robustness", "Sweep outliers, poor excitation, drift and sensor bias to breakdown; rank "
                                         "estimators per failure mode."),
    "controllers": (f"{_PKG}.controllers", "MPC (each force model) against cruise control, the human-like driver "
                                           "and the full-route optimum, on the car over roads x conditions, paired "
                                           "per seed at equal trip time: every difference with its 95 % CI (the "
                                           "same comparison as `benchmark headline`)."),
    "headline": (f"{_PKG}.controllers", "MPC with the oracle / abc / online force model against cruise control at "
                                        "equal trip time, paired over seeds, with the 1-sigma resolution and 95 % "
                                        "CIs of every difference."),
    "sensitivity": (f"{_PKG}.controllers", "Energy penalty at equal time vs force-model error (mass, rolling "
                                           "resistance, drag area, grade bias, drive-train losses; one at a time and "
                                           "jointly) against the oracle MPC: table and figure per vehicle."),
    "optimum": (f"{_PKG}.optimum", "Every controller (cruise control, the truck's speed-band cruise, the "
                                   "human-like driver, the MPC with each force model, PPO / SAC policies) against "
                                   "the full-route optimum at its own trip time and arrival speed, on the same "
                                   "plant: excess per run and per controller with 95 % CIs over seeds."),
    "gym": (f"{_PKG}.rl", "Environment steps per second: EcoDrive-v0 single process and vectorised, EcoHighway-v0, "
                          "and highway-env's highway-fast-v0 in the same run."),
}

_LOADED: dict[str, tuple[Any, Any]] = {}  # module -> (its click group of top-level commands, of benchmark commands)


def _module_commands(module: str) -> tuple[Any, Any]:
    """The click groups of the commands a module registers (imported and built once)."""
    if module not in _LOADED:
        top, bench = typer.Typer(rich_markup_mode=None), typer.Typer(rich_markup_mode=None)
        for sub in (top, bench):  # a callback keeps each a group even with one command
            sub.callback()(lambda: None)
        importlib.import_module(module).register(top, bench)
        guard_app(top)
        guard_app(bench)
        _LOADED[module] = (typer.main.get_command(top), typer.main.get_command(bench))
    return _LOADED[module]


class _LazyGroup(TyperGroup):
    """A click group whose commands are imported on first use; its help lists them from a table."""

    table: dict[str, tuple[str, str]] = {}
    benchmark = False

    def list_commands(self, ctx: Any) -> list[str]:
        return list(self.table)

    def get_command(self, ctx: Any, name: str) -> Any:
        if name in self.commands:
            return self.commands[name]
        if name not in self.table:
            return None
        module = self.table[name][0]
        group = _module_commands(module)[1 if self.benchmark else 0]
        command = group.commands.get(name)
        if command is None:
            raise RuntimeError(f"{module} does not register the command {name!r} listed in the CLI table")
        self.commands[name] = command
        return command

    def format_commands(self, ctx: Any, formatter: Any) -> None:
        from typer._click.utils import make_default_short_help

        limit = formatter.width - 6 - max(len(name) for name in self.table)
        with formatter.section("Commands"):
            formatter.write_dl([(name, make_default_short_help(text, limit)) for name, (_, text) in self.table.items()])

    def resolve_command(self, ctx: Any, args: list[str]) -> Any:
        if args and args[0] not in self.table and not args[0].startswith("-"):
            close = difflib.get_close_matches(args[0], list(self.table), n=3, cutoff=0.6)
            hint = f" Did you mean {', '.join(repr(c) for c in close)}?" if close else ""
            ctx.fail(f"No such command {args[0]!r}.{hint} Commands: {', '.join(self.table)}.")
        return super().resolve_command(ctx, args)


class _TopGroup(_LazyGroup):
    table = COMMANDS


class _BenchmarkGroup(_LazyGroup):
    table = BENCHMARKS
    benchmark = True


app = typer.Typer(help="roadload: vehicle simulator, tractive-force estimators, eco-driving MPC, sim-to-real.",
                  no_args_is_help=True, pretty_exceptions_enable=False, rich_markup_mode=None, cls=_TopGroup)
benchmark_app = typer.Typer(help=COMMANDS["benchmark"][1], no_args_is_help=True, rich_markup_mode=None,
                            cls=_BenchmarkGroup)
app.add_typer(benchmark_app, name="benchmark")


@app.callback()
def _global_options(debug: bool = typer.Option(False, "--debug",
                                               help="show the Python traceback of an error (also ROADLOAD_DEBUG=1)")
                    ) -> None:
    set_debug(debug)


def load_all() -> None:
    """Import every command module now (the docs reference and tests that walk every command use this)."""
    for module, _ in {**COMMANDS, **BENCHMARKS}.values():
        if module:
            _module_commands(module)


_load = load_all  # the name the tests that walk every command call


#: True in the ``roadload`` command's own process (set by :func:`main`): only there may a command switch the process
#: to the ahead-of-time compiled kernels (roadload.compiled), not when a test or a program invokes ``app`` in-process
runs_as_command = False


def main() -> None:
    global runs_as_command
    runs_as_command = True
    # libgomp reads OMP_WAIT_POLICY once, when it is loaded, and the RL commands load it (torch, via
    # stable-baselines3): set the native vector env's default here, first, or `roadload train --threads 2` spins
    # idle OpenMP threads (32k instead of 160k steps/s at load 4.6, docs/results/scale.md)
    os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")
    app()
