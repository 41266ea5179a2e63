"""Atomic file output: every file roadload writes appears whole or not at all.

A writer gets a temporary path in the target's folder; only when it returns without error is the file moved into
place (``os.replace`` is atomic on one file system), with the permissions a plain ``open()`` would have given.
On any error the temporary file is removed and an existing target is left untouched.
"""

from __future__ import annotations

import json
import os
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any


def _default_mode() -> int:
    umask = os.umask(0)
    os.umask(umask)
    return 0o666 & ~umask


@contextmanager
def atomic_path(path: str | os.PathLike, suffix: str | None = None) -> Iterator[Path]:
    """Yield a temporary path next to ``path``; move it onto ``path`` when the block succeeds.

    ``suffix`` (default: the target's own) matters for writers that pick the format from the file name
    (matplotlib, python-can)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.stem}.", suffix=path.suffix if suffix is None else suffix,
                               dir=path.parent)
    os.close(fd)
    try:
        yield Path(tmp)
        os.chmod(tmp, _default_mode())  # mkstemp creates 0600
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise


def write_text(path: str | os.PathLike, text: str, newline: str | None = None) -> Path:
    """Write a UTF-8 text file atomically."""
    with atomic_path(path) as tmp:
        with open(tmp, "w", encoding="utf-8", newline=newline) as fh:
            fh.write(text)
    return Path(path)


def write_json(path: str | os.PathLike, data: Any, indent: int | None = 1, **dumps_kw) -> Path:
    """Serialise to JSON first (a TypeError leaves nothing behind), then write atomically."""
    return write_text(path, json.dumps(data, indent=indent, **dumps_kw))


def save_figure(fig, path: str | os.PathLike, dpi: int = 110, close: bool = True, **savefig_kw) -> Path:
    """Write a matplotlib figure (PNG unless the name says otherwise) atomically and close it."""
    try:
        with atomic_path(path) as tmp:
            fig.savefig(tmp, dpi=dpi, **savefig_kw)
    finally:
        if close:
            import matplotlib.pyplot as plt

            plt.close(fig)
    return Path(path)
