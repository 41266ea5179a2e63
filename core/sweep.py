"""A small generic sweep runner: local processes by default, a Dask distributed cluster with ``scheduler``.

``run_sweep(fn, tasks)`` calls ``fn(task)`` for every task and returns one :class:`TaskOutcome` per task, in task
order. A task that raises does not sink the sweep: its outcome carries the error text and traceback instead of
a value. ``fn`` and the tasks must be picklable (a module-level function, plain data).
"""

from __future__ import annotations

import os
import traceback
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import dataclass
from typing import Any, Callable, Iterable


@dataclass
class TaskOutcome:
    """Result of one task: ``value`` when ``ok``, else ``error`` (``"Type: message"``) and ``traceback``."""

    index: int
    task: Any
    value: Any = None
    error: str | None = None
    traceback: str | None = None

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


def run_sweep(fn: Callable[[Any], Any], tasks: Iterable[Any], scheduler: str | None = None, progress: bool = True,
              workers: int | None = None, description: str = "sweep") -> list[TaskOutcome]:
    """Run ``fn`` over ``tasks``; results in task order.

    scheduler: None -> local processes (``workers`` of them, default: CPU count; 1 -> in this process);
    "ADDRESS" (e.g. ``tcp://host:8786``) -> the Dask distributed cluster there; a ``distributed.Client`` or
    ``LocalCluster`` object is accepted too.
    """
    tasks = list(tasks)
    outcomes: list[TaskOutcome | None] = [None] * len(tasks)
    bar, bar_task = _progress_bar(len(tasks), description, progress and len(tasks) > 0)

    def record(outcome: TaskOutcome) -> None:
        outcomes[outcome.index] = outcome
        if bar is not None:
            bar.advance(bar_task)

    try:
        if scheduler is None:
            n = workers or os.cpu_count() or 1
            if n <= 1 or len(tasks) <= 1:
                for i, task in enumerate(tasks):
                    record(_call(fn, i, task))
            else:
                with ProcessPoolExecutor(max_workers=min(n, len(tasks))) as pool:
                    futures = [pool.submit(_call, fn, i, task) for i, task in enumerate(tasks)]
                    for fut in as_completed(futures):
                        record(fut.result())
        else:
            from distributed import Client
            from distributed import as_completed as dask_completed

            own = isinstance(scheduler, str)
            client = Client(scheduler) if own else (scheduler if isinstance(scheduler, Client) else Client(scheduler))
            try:
                dask_futures = [client.submit(_call, fn, i, task, pure=False) for i, task in enumerate(tasks)]
                for dask_fut in dask_completed(dask_futures):
                    record(dask_fut.result())
            finally:
                if own or not isinstance(scheduler, Client):
                    client.close()
    finally:
        if bar is not None:
            bar.stop()
    return [o for o in outcomes if o is not None]


def failures(outcomes: list[TaskOutcome]) -> list[TaskOutcome]:
    """The outcomes whose task raised."""
    return [o for o in outcomes if not o.ok]
