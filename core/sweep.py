"""A small generic sweep runner: local processes by default, a Dask distributed cluster with ``scheduler``.

``run_sweep(fn, tasks)`` calls ``fn(task)`` for every task and returns one :class:`TaskOutcome` per task, in task
order. A task that raises does not sink the sweep: its outcome carries the error text and traceback instead of
a value. ``fn`` and the tasks must be picklable (a module-level function, plain data).

Resume (``checkpoint=<folder>``): every finished task is written at once, atomically, as one JSON unit file
``<name>-<key>.json`` holding the task, its value and a SHA-256 of the value; ``key`` hashes the function (with a
``functools.partial``'s arguments) and the task, so a unit is only ever reused by the same computation. A run
killed at any moment (SIGKILL, power loss) leaves finished units whole and nothing half-written; the next run
with the same folder takes every valid unit as it is and computes only the rest. A unit file that does not parse,
belongs to another task or whose value does not match its checksum is reported and computed again, never
trusted. With a checkpoint every value goes through the same JSON round trip, fresh or resumed, so a resumed
sweep returns exactly what an uninterrupted one does (values must be JSON data: numbers, strings, lists, dicts;
numpy scalars and arrays are converted).
"""

from __future__ import annotations

import dataclasses
import functools
import hashlib
import json
import os
import sys
import traceback
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Iterable

from .fileio import write_text

UNIT_FORMAT = "roadload.sweep_unit"
UNIT_VERSION = 1


@dataclass
class TaskOutcome:
    """Result of one task: ``value`` when ``ok``, else ``error`` (``"Type: message"``) and ``traceback``."""

    index: int
    task: Any
    value: Any = None
    error: str | None = None
    traceback: str | None = None
    source: str = "computed"  # "computed", "resumed" (a valid unit file) or "rebuilt" (its unit file was corrupt)

    @property
    def ok(self) -> bool:
        return self.error is None


def _call(fn: Callable[[Any], Any], index: int, task: Any) -> TaskOutcome:
    try:
        return TaskOutcome(index, task, value=fn(task))
    except Exception as exc:  # a failed task is reported, not raised
        return TaskOutcome(index, task, error=f"{type(exc).__name__}: {exc}", traceback=traceback.format_exc())


def _progress_bar(total: int, description: str, enabled: bool):
    if not enabled:
        return None, None
    from rich.console import Console
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

    # on stderr, gone when done: stdout is for the results a command prints
    bar = Progress(TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn(), TimeElapsedColumn(),
                   console=Console(stderr=True), transient=True)
    bar.start()
    return bar, bar.add_task(description, total=total)


# ------------------------------------------------------------------------------------------------ unit files
def _canonical(x: Any) -> Any:
    """Plain JSON data describing ``x`` (dataclasses by their fields, functions by their qualified name)."""
    if dataclasses.is_dataclass(x) and not isinstance(x, type):
        return {"type": type(x).__qualname__, **{f.name: _canonical(getattr(x, f.name)) for f in dataclasses.fields(x)}}
    if isinstance(x, functools.partial):
        return {"partial": _canonical(x.func), "args": _canonical(x.args), "keywords": _canonical(x.keywords)}
    if callable(x) and hasattr(x, "__qualname__"):
        return f"{getattr(x, '__module__', '')}.{x.__qualname__}"
    return _jsonable(x)


def _jsonable(x: Any) -> Any:
    """JSON data of a value: numpy scalars and arrays as Python numbers and lists, tuples as lists."""
    if isinstance(x, dict):
        return {str(k): _jsonable(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_jsonable(v) for v in x]
    if hasattr(x, "tolist") and hasattr(x, "dtype"):  # numpy scalar or array
        return _jsonable(x.tolist())
    if dataclasses.is_dataclass(x) and not isinstance(x, type):
        return _canonical(x)
    if x is None or isinstance(x, (bool, int, str)):
        return x
    if isinstance(x, float):
        return x
    if isinstance(x, os.PathLike):
        return os.fspath(x)
    raise TypeError(f"a checkpointed sweep stores JSON data; got {type(x).__name__} ({x!r:.80})")


def _dumps(x: Any) -> str:
    """JSON text of a value, its dict keys in their own order (a resumed value iterates like a fresh one)."""
    return json.dumps(x, allow_nan=True)


def task_key(fn: Callable[[Any], Any], task: Any) -> str:
    """SHA-256 (hex) of the function and the task: the identity of a unit file."""
    identity = json.dumps({"fn": _canonical(fn), "task": _canonical(task)}, sort_keys=True, allow_nan=True)
    return hashlib.sha256(identity.encode()).hexdigest()


def _unit_path(folder: Path, key: str, task: Any, name: Callable[[Any], str] | None) -> Path:
    stem = "".join(c if c.isalnum() or c in "-_." else "_" for c in name(task)) + "-" if name is not None else ""
    return folder / f"{stem}{key[:16]}.json"


def read_unit(path: Path, key: str | None = None) -> tuple[Any, str | None]:
    """(value, None) of a valid unit file, or (None, what is wrong with it)."""
    try:
        doc = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        return None, f"unreadable ({exc})"
    if not isinstance(doc, dict) or doc.get("format") != UNIT_FORMAT or doc.get("version") != UNIT_VERSION:
        return None, f"not a {UNIT_FORMAT} version {UNIT_VERSION} file"
    if key is not None and doc.get("key") != key:
        return None, "belongs to another task or function"
    if hashlib.sha256(_dumps(doc.get("value")).encode()).hexdigest() != doc.get("value_sha256"):
        return None, "its value does not match its checksum"
    return doc["value"], None


def _write_unit(path: Path, key: str, fn: Callable[[Any], Any], task: Any, value: Any) -> None:
    doc = {"format": UNIT_FORMAT, "version": UNIT_VERSION, "key": key, "function": _canonical(fn),
           "task": _canonical(task), "value": value, "value_sha256": hashlib.sha256(_dumps(value).encode()).hexdigest()}
    write_text(path, json.dumps(doc, allow_nan=True))


def _round_trip(value: Any) -> Any:
    return json.loads(_dumps(_jsonable(value)))


# ------------------------------------------------------------------------------------------------ the runner
def _resume(fn: Callable[[Any], Any], tasks: list[Any], folder: Path, name: Callable[[Any], str] | None,
            description: str, outcomes: list[TaskOutcome | None]) -> tuple[list[str], list[int], set[int]]:
    """Fill ``outcomes`` from the valid unit files in ``folder``; (keys, indices still to compute, rebuilt ones)."""
    folder.mkdir(parents=True, exist_ok=True)
    keys = [task_key(fn, task) for task in tasks]
    todo: list[int] = []
    rebuilt: set[int] = set()
    for i, task in enumerate(tasks):
        path = _unit_path(folder, keys[i], task, name)
        if not path.exists():
            todo.append(i)
            continue
        value, problem = read_unit(path, keys[i])
        if problem is None:
            outcomes[i] = TaskOutcome(i, task, value=value, source="resumed")
        else:
            print(f"{description}: unit file {path} {problem}: computing it again", file=sys.stderr)
            rebuilt.add(i)
            todo.append(i)
    done = len(tasks) - len(todo)
    if done:
        print(f"{description}: resumed {done} of {len(tasks)} finished tasks from {folder}", file=sys.stderr)
    return keys, todo, rebuilt


def _checkpoint_outcome(outcome: TaskOutcome, fn: Callable[[Any], Any], folder: Path, key: str,
                        name: Callable[[Any], str] | None, rebuilt: set[int]) -> None:
    """Round-trip a finished outcome's value through JSON and write its unit file (an error if it is not JSON)."""
    outcome.source = "rebuilt" if outcome.index in rebuilt else "computed"
    if not outcome.ok:
        return
    try:
        outcome.value = _round_trip(outcome.value)
        _write_unit(_unit_path(folder, key, outcome.task, name), key, fn, outcome.task, outcome.value)
    except TypeError as exc:  # a value that is not JSON data cannot be checkpointed
        outcome.value, outcome.error = None, f"TypeError: {exc}"


def _run_local(fn: Callable[[Any], Any], tasks: list[Any], todo: list[int], workers: int | None,
               record: Callable[[TaskOutcome], None]) -> None:
    """Run the ``todo`` tasks in this process (one worker or one task) or in a process pool."""
    n = workers or os.cpu_count() or 1
    if n <= 1 or len(todo) <= 1:
        for i in todo:
            record(_call(fn, i, tasks[i]))
        return
    with ProcessPoolExecutor(max_workers=min(n, len(todo))) as pool:
        futures = [pool.submit(_call, fn, i, tasks[i]) for i in todo]
        for fut in as_completed(futures):
            record(fut.result())


def _run_dask(fn: Callable[[Any], Any], tasks: list[Any], todo: list[int], scheduler: Any,
              record: Callable[[TaskOutcome], None]) -> None:
    """Run the ``todo`` tasks on a Dask distributed cluster (an address, a ``Client`` or a cluster object)."""
    from distributed import Client
    from distributed import as_completed as dask_completed

    own = isinstance(scheduler, str)
    client = Client(scheduler) if own else (scheduler if isinstance(scheduler, Client) else Client(scheduler))
    try:
        dask_futures = [client.submit(_call, fn, i, tasks[i], pure=False) for i in todo]
        for dask_fut in dask_completed(dask_futures):
            record(dask_fut.result())
    finally:
        if own or not isinstance(scheduler, Client):
            client.close()


def run_sweep(fn: Callable[[Any], Any], tasks: Iterable[Any], scheduler: str | None = None, progress: bool = True,
              workers: int | None = None, description: str = "sweep", checkpoint: str | os.PathLike | None = None,
              name: Callable[[Any], str] | None = None) -> list[TaskOutcome]:
    """Run ``fn`` over ``tasks``; results in task order.

    scheduler: None -> local processes (``workers`` of them, default: CPU count; 1 -> in this process);
    "ADDRESS" (e.g. ``tcp://host:8786``) -> the Dask distributed cluster there; a ``distributed.Client`` or
    ``LocalCluster`` object is accepted too. checkpoint: a folder of unit files to resume from and write each
    finished task to (module docstring); ``name(task)`` gives the unit files a readable prefix.
    """
    tasks = list(tasks)
    outcomes: list[TaskOutcome | None] = [None] * len(tasks)
    folder = Path(checkpoint) if checkpoint is not None else None
    keys: list[str] = []
    todo = list(range(len(tasks)))
    rebuilt: set[int] = set()
    if folder is not None:
        keys, todo, rebuilt = _resume(fn, tasks, folder, name, description, outcomes)
    bar, bar_task = _progress_bar(len(todo), description, progress and len(todo) > 0)

    def record(outcome: TaskOutcome) -> None:
        if folder is not None:
            _checkpoint_outcome(outcome, fn, folder, keys[outcome.index], name, rebuilt)
        outcomes[outcome.index] = outcome
        if bar is not None:
            bar.advance(bar_task)

    try:
        if scheduler is None:
            _run_local(fn, tasks, todo, workers, record)
        else:
            _run_dask(fn, tasks, todo, scheduler, record)
    finally:
        if bar is not None:
            bar.stop()
    return [o for o in outcomes if o is not None]


def failures(outcomes: list[TaskOutcome]) -> list[TaskOutcome]:
    """The outcomes whose task raised."""
    return [o for o in outcomes if not o.ok]
