"""One error path for every ``roadload`` command.

Every command callback is wrapped by :func:`guarded`: bad input (any roadload error class, a pydantic validation
error, a missing/unwritable file, a bad option value) is printed as one plain line ``error: <what>`` on stderr,
without Rich markup interpretation (so ``[km/h]`` in a message stays), and the command exits with code 2. Anything
else is an internal error: one line, exit code 1 (a write that ran out of room,
:class:`roadload.fileio.OutputSpaceError`, too, without the word "internal"). Tracebacks only with the global
``--debug`` (or ``ROADLOAD_DEBUG=1``).

Before a command runs, its arguments get generic checks: seeds (``seed``, ``*_seed``) must be >= 0, float options
must be finite, and ``out`` paths are checked with :func:`roadload.fileio.check_output_path` (a path with a suffix
is a file, one without is a folder). Commands check names and input files with :func:`choose` and
:func:`require_file` (both say "did you mean" for a close match) before they import anything heavy.

This module imports nothing heavy (no pydantic either: a pydantic error can only come from code that imported it).
"""

from __future__ import annotations

import difflib
import functools
import inspect
import math
import os
import sys
from collections.abc import Iterable
from pathlib import Path
from typing import Any, Callable, NoReturn

import typer

from roadload.fileio import OutputSpaceError, check_output_path
from roadload.registry import did_you_mean

#: typer >= 0.2x vendors its own click: its usage errors (typer.BadParameter) derive from this class
_TYPER_CLICK_EXCEPTION: type[Exception] = next(c for c in typer.BadParameter.__mro__ if c.__name__ == "ClickException")
BAD_INPUT_EXIT = 2
INTERNAL_EXIT = 1
_STATE = {"debug": os.environ.get("ROADLOAD_DEBUG", "") not in ("", "0")}


class CliInputError(ValueError):
    """A command-line argument is invalid; the message names the option and the expected value."""


def set_debug(on: bool) -> None:
    _STATE["debug"] = bool(on) or os.environ.get("ROADLOAD_DEBUG", "") not in ("", "0")


def debug() -> bool:
    return _STATE["debug"]


def one_line(text: str) -> str:
    """Collapse a (possibly multi-line) message into one line."""
    return "; ".join(part.strip() for part in str(text).splitlines() if part.strip())


def option_name(param: str) -> str:
    return "--" + param.replace("_", "-")


def _is_validation_error(exc: BaseException) -> bool:
    pydantic = sys.modules.get("pydantic")
    return pydantic is not None and isinstance(exc, pydantic.ValidationError)


def is_bad_input(exc: BaseException) -> bool:
    """True for errors caused by what the user handed in (files, options, specs), False for internal bugs."""
    if isinstance(exc, (FileNotFoundError, IsADirectoryError, NotADirectoryError, PermissionError,
                        FileExistsError, UnicodeDecodeError)) or _is_validation_error(exc):
        return True
    return isinstance(exc, (ValueError, KeyError)) and type(exc).__module__.split(".")[0] == "roadload"


def describe(exc: BaseException) -> str:
    """The user-facing message of an exception (no repr quotes of KeyError, file name of OSError)."""
    if isinstance(exc, KeyError) and exc.args:
        text = str(exc.args[0])
    elif isinstance(exc, OSError) and exc.filename is not None:
        text = f"{exc.filename}: {exc.strerror or exc}"
    elif _is_validation_error(exc):
        error: Any = exc  # a pydantic ValidationError (pydantic is not imported here)
        text = "; ".join(f"{'.'.join(str(p) for p in e['loc']) or error.title}: {e['msg']} (got {e.get('input')!r})"
                         for e in error.errors())
    else:
        text = str(exc) or type(exc).__name__
    return one_line(text)


def fail(message: str, code: int = BAD_INPUT_EXIT) -> NoReturn:
    """Print ``error: message`` as one plain line on stderr and exit (2 = bad input)."""
    typer.echo(f"error: {one_line(message)}", err=True)
    raise typer.Exit(code=code)


def choose(value: str, choices: Iterable[str], option: str, what: str, listing: str | None = None) -> str:
    """``value`` if it is one of ``choices``; else :class:`CliInputError` naming the option, the close match and
    the choices (or ``listing``, e.g. where to find a long list)."""
    choices = list(choices)
    if value in choices:
        return value
    listing = f"known: {', '.join(choices)}" if listing is None else listing
    raise CliInputError(f"{option}: unknown {what} {value!r}{did_you_mean(value, choices)}; {listing}")


def require_file(path: Path, option: str, suffixes: tuple[str, ...] = ()) -> Path:
    """``path`` if it is an existing file (with one of ``suffixes`` when given); else :class:`CliInputError` naming
    the option and, for a missing file, a similarly named file in the same folder."""
    path = Path(path)
    if suffixes and path.suffix.lower() not in suffixes:
        raise CliInputError(f"{option}: expected a {' or '.join(suffixes)} file, got {str(path)!r}")
    if path.is_dir():
        raise CliInputError(f"{option}: {path} is a folder, expected a file")
    if not path.is_file():
        folder = path.parent
        siblings = {p.name: p for p in folder.iterdir()} if folder.is_dir() else {}
        close = difflib.get_close_matches(path.name, list(siblings), n=1, cutoff=0.6)
        hint = f" (did you mean {str(siblings[close[0]])!r}?)" if close else ""
        raise CliInputError(f"{option}: no file {path}{hint}")
    return path


def check_arguments(kwargs: dict[str, Any]) -> None:
    """Generic checks of a command's arguments before it runs (see the module docstring)."""
    for name, value in kwargs.items():
        if isinstance(value, bool) or value is None:
            continue
        if (name == "seed" or name.endswith("_seed")) and isinstance(value, int) and value < 0:
            raise CliInputError(f"{option_name(name)}: must be an integer >= 0, got {value}")
        if isinstance(value, float) and not math.isfinite(value):
            raise CliInputError(f"{option_name(name)}: must be a finite number, got {value}")
        if name == "out" and isinstance(value, Path):
            check_output_path(value, "file" if value.suffix else "dir", what=f"{option_name(name)}")


def guarded(fn: Callable[..., Any]) -> Callable[..., Any]:
    """Wrap a command callback with the argument checks and the one error path."""
    if getattr(fn, "__roadload_guarded__", False):
        return fn

    @functools.wraps(fn)
    def wrapper(*args: Any, **kwargs: Any) -> Any:
        try:
            check_arguments(kwargs)
            return fn(*args, **kwargs)
        except (typer.Exit, typer.Abort, KeyboardInterrupt, _TYPER_CLICK_EXCEPTION):
            raise
        except Exception as exc:  # the one place that turns errors into exit codes
            if debug():
                raise
            if is_bad_input(exc):
                fail(describe(exc))
            if isinstance(exc, OutputSpaceError):  # the machine ran out of room: not a bug, say what and where
                fail(describe(exc), code=INTERNAL_EXIT)
            fail(f"internal {type(exc).__name__}: {describe(exc)} (rerun with --debug for the traceback)",
                 code=INTERNAL_EXIT)

    wrapper.__roadload_guarded__ = True  # type: ignore[attr-defined]
    return wrapper


def _uppercase_argument_metavars(fn: Callable[..., Any]) -> None:
    """One style for positional arguments in help texts: ``TRIP``, ``SOURCE`` (as click's default)."""
    for name, param in inspect.signature(fn).parameters.items():
        info = param.default
        if isinstance(info, typer.models.ArgumentInfo) and info.metavar is None:
            info.metavar = name.upper()


def guard_app(app: typer.Typer) -> None:
    """Wrap every command of ``app`` and its sub-apps; show help texts without markup so ``[unit]`` stays."""
    app.rich_markup_mode = None
    for cmd in app.registered_commands:
        if cmd.callback is not None:
            _uppercase_argument_metavars(cmd.callback)
            cmd.callback = guarded(cmd.callback)
    for group in app.registered_groups:
        if group.typer_instance is not None:
            guard_app(group.typer_instance)
