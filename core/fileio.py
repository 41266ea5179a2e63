"""Atomic file output: every file roadload writes appears whole or not at all.

A writer gets a temporary path in the target's folder; only when it returns without error is the file moved into
place (``os.replace`` is atomic on one file system), with the permissions a plain ``open()`` would have given.
On any error the temporary file is removed and an existing target is left untouched; a write that runs out of room
(disk full, quota, ``ulimit -f``) raises :class:`OutputSpaceError` naming the path and what ran out. A write killed
before it could clean up (SIGKILL, power loss) leaves ``.<name>.roadload-tmp-<pid>-<random><suffix>``; the next
write to the same target removes such leftovers whose process is gone.

:func:`check_output_path` validates an output path before any work starts (a directory where a file is expected,
a parent that is a file, a folder that is not writable), so a long run never fails only at its last step.
"""

from __future__ import annotations

import errno
import json
import os
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any, Literal

TMP_MARK = ".roadload-tmp-"


class OutputPathError(ValueError):
    """An output path cannot be written; the message names the path and what is wrong with it."""


class OutputSpaceError(OSError):
    """A write ran out of room (disk full, disk quota, or the file-size limit ``ulimit -f``); the message names the
    path and says that the previous file, if any, is unchanged."""

    def __str__(self) -> str:
        return str(self.strerror)  # the message names the path and the cause (no "[Errno N]" prefix)


_NO_ROOM = {errno.ENOSPC: "no space left on the device", errno.EFBIG: "the file-size limit (ulimit -f) was reached",
            errno.EDQUOT: "the disk quota is exceeded"}
_NO_ROOM_TEXT = {"No space left on device": errno.ENOSPC, "File too large": errno.EFBIG,
                 "Disk quota exceeded": errno.EDQUOT}


def _out_of_room(exc: BaseException | None) -> int | None:
    """The errno of a write that ran out of room anywhere in the exception chain (libraries such as pyarrow
    re-raise with the system message only), else None."""
    seen = 0
    while exc is not None and seen < 10:
        if isinstance(exc, OSError) and exc.errno in _NO_ROOM:
            return exc.errno
        for text, code in _NO_ROOM_TEXT.items():
            if text in str(exc):
                return code
        exc = exc.__cause__ or exc.__context__
        seen += 1
    return None


def _room_error(path: Path, code: int, existed: bool) -> OutputSpaceError:
    kept = "the previous file is unchanged" if existed else "nothing was written"
    return OutputSpaceError(code, f"{path}: cannot write: {_NO_ROOM[code]}; {kept}")


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
    remove_stale_temporaries(path)
    existed = path.exists()
    try:
        fd, tmp = tempfile.mkstemp(prefix=f".{path.name}{TMP_MARK}{os.getpid()}-",
                                   suffix=path.suffix if suffix is None else suffix, dir=path.parent)
    except OSError as exc:
        code = _out_of_room(exc)
        if code is not None:
            raise _room_error(path, code, existed) from exc
        raise
    os.close(fd)
    try:
        yield Path(tmp)
        os.chmod(tmp, _default_mode())  # mkstemp creates 0600
        os.replace(tmp, path)
    except BaseException as exc:
        if os.path.exists(tmp):
            os.unlink(tmp)
        code = _out_of_room(exc)
        if code is not None and not isinstance(exc, OutputSpaceError):
            raise _room_error(path, code, existed) from exc
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


def _pid_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except (PermissionError, OverflowError):
        return True
    return True


def remove_stale_temporaries(path: str | os.PathLike) -> list[Path]:
    """Remove temporaries of interrupted writes to ``path`` whose writing process no longer runs; returns them."""
    path = Path(path)
    removed: list[Path] = []
    prefix = f".{path.name}{TMP_MARK}"
    try:
        candidates = [p for p in path.parent.iterdir() if p.name.startswith(prefix)]
    except OSError:
        return removed
    for p in candidates:
        pid_text = p.name[len(prefix):].split("-", 1)[0]
        if pid_text.isdigit() and int(pid_text) != os.getpid() and not _pid_alive(int(pid_text)):
            try:
                p.unlink()
                removed.append(p)
            except OSError:
                pass
    return removed


def check_output_path(path: str | os.PathLike, kind: Literal["file", "dir"] = "file",
                      what: str = "--out") -> Path:
    """Refuse an output path before work starts: a file path that is a directory, a folder path that is a file,
    an ancestor that is a file, or an existing folder (or file) without write permission. Returns the path."""
    if str(path).strip() == "":
        raise OutputPathError(f"{what}: empty path; expected a {'file' if kind == 'file' else 'folder'} path")
    path = Path(path)
    if path.exists():
        if kind == "file" and path.is_dir():
            raise OutputPathError(f"{what} {path}: is a directory; expected a file path (e.g. {path / 'out'}"
                                  f"{path.suffix or '.parquet'})")
        if kind == "dir" and not path.is_dir():
            raise OutputPathError(f"{what} {path}: is a file; expected a folder path")
        if not os.access(path, os.W_OK):
            raise OutputPathError(f"{what} {path}: exists and is not writable")
    parent = path if kind == "dir" and path.is_dir() else path.parent
    ancestor = parent
    while not ancestor.exists():
        if ancestor.is_symlink():  # a dangling link
            raise OutputPathError(f"{what} {path}: {ancestor} is a broken symbolic link")
        if ancestor == ancestor.parent:
            break
        ancestor = ancestor.parent
    if ancestor.exists() and not ancestor.is_dir():
        raise OutputPathError(f"{what} {path}: {ancestor} is a file, so it cannot hold "
                              f"{'the output file' if kind == 'file' else 'the output folder'}")
    if ancestor.exists() and not os.access(ancestor, os.W_OK | os.X_OK):
        raise OutputPathError(f"{what} {path}: folder {ancestor} is not writable")
    return path
