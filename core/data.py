"""Where the shared real-driving data lives: ``$ROADLOAD_DATA`` or ``../shared/data`` from the project root."""

from __future__ import annotations

import os
from pathlib import Path

_PROJECT_ROOT = Path(__file__).resolve().parent.parent


def shared_data_dir() -> Path | None:
    """The shared data folder if it exists, else None (callers skip with a reason)."""
    env = os.environ.get("ROADLOAD_DATA")
    candidates = [Path(env)] if env else []
    candidates += [_PROJECT_ROOT.parent / "shared" / "data", Path.cwd().parent / "shared" / "data"]
    for c in candidates:
        if c.is_dir():
            return c
    return None


def require_shared_data(subfolder: str = "") -> Path:
    """Path to a shared-data subfolder; FileNotFoundError naming where it was looked for."""
    base = shared_data_dir()
    if base is None:
        raise FileNotFoundError("shared driving data not found: set ROADLOAD_DATA or place it at ../shared/data")
    path = base / subfolder
    if not path.exists():
        raise FileNotFoundError(f"shared data folder {path} does not exist")
    return path
