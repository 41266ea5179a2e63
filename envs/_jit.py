"""``jit``: numba ``njit(cache=True)`` with a cache that is invalidated when ANY simulator-core source changes.

numba's on-disk cache is keyed by the time stamp of the file that holds a function, but the core's functions
inline each other and the record types of ``layout.py`` across files; a change in one file would leave stale
machine code in the others. The cache directory therefore carries a hash of all core sources (with the batch-step
API of ``batch.py``, whose functions other kernels inline).
:func:`dependent_jit` does the same for a kernel outside the core that calls into it (the native vector env):
its cache carries the hash of the core and of the kernel's own sources.
"""

from __future__ import annotations

import hashlib
import os
import shutil
import tempfile
from collections.abc import Callable
from pathlib import Path
from typing import Any

from roadload.compiled import kernel

_HERE = Path(__file__).resolve().parent
_SOURCES = ("_jit.py", "layout.py", "numerics.py", "drivetrain.py", "driver.py", "physics.py", "batch.py")
STAMP = hashlib.sha1(b"".join((_HERE / f).read_bytes() for f in _SOURCES)).hexdigest()[:12]


def _cache_bases(home: Path) -> tuple[Path, ...]:
    """Where the hashed cache folders go: under ``$NUMBA_CACHE_DIR/roadload`` when the variable is set (one cache
    for a read-only install, or shared by the workers of a cluster), else ``home/__pycache__``, else the temp
    folder."""
    shared = os.environ.get("NUMBA_CACHE_DIR", "")
    if shared:
        return (Path(shared) / "roadload",)
    return (home / "__pycache__", Path(tempfile.gettempdir()) / "roadload-numba")


def _cache_dir(home: Path = _HERE, prefix: str = "numba-", stamp: str = STAMP) -> str:
    """``<base>/<prefix><stamp>`` for the first writable base of :func:`_cache_bases`; the folders of earlier
    stamps with the same prefix are removed. Processes may start on an empty cache at the same time (Dask workers,
    SubprocVecEnv): numba writes every index and data file through a temporary file and a rename, so a reader sees
    a whole file or none, and a kernel two processes compile at once is compiled twice, not corrupted."""
    for base in _cache_bases(home):
        d = base / f"{prefix}{stamp}"
        try:
            d.mkdir(parents=True, exist_ok=True)
            probe = d / f".probe-{os.getpid()}"
            probe.write_bytes(b"")
            probe.unlink()
            if not os.environ.get("NUMBA_CACHE_DIR"):  # a shared cache may serve other versions: left alone
                for old in base.glob(f"{prefix}*"):  # caches of earlier sources are dead weight
                    if old.name != d.name and len(old.name) == len(d.name):
                        shutil.rmtree(old, ignore_errors=True)
            return str(d)
        except OSError:
            continue
    return ""  # numba falls back to its default locators


CACHE_DIR = _cache_dir()


def jit(fn=None, *, refcount: bool = True, inline: bool = False):
    """njit(cache=True) with the core's hashed cache directory.

    ``refcount=False`` compiles without numba's reference counting (``_nrt=False``) — for a kernel that allocates
    nothing and passes its arrays to inline stages: every array handed to an inlined stage would otherwise cost an
    atomic increment / decrement pair per call.

    ``error_model="numpy"``: a float division by zero gives inf / NaN instead of raising, so numba emits no zero
    check and branch per division (about 30 per substep; 7 % of the batched physics). The kernels' divisors are
    validated positive where the spec is built (mass, radii, gear ratios, strictly increasing table axes); results
    are bitwise those of the checked build wherever that one did not raise.

    ``inline=True`` (numba's ``forceinline``): LLVM inlines the function into every compiled caller. numba passes an
    array to a called function as seven machine words plus an exception status, so a call of a table look-up cost
    more than the look-up; inlining the look-up and drive-train helpers and the steering law made the batched
    physics 1.38x faster with bitwise-identical results and the same compile time. ``stage`` inlines in numba's IR
    instead, which compiled the same helpers 6x slower."""
    if fn is None:
        return lambda f: jit(f, refcount=refcount, inline=inline)
    options: dict[str, Any] = {"forceinline": True} if inline else {}
    if not refcount:
        options["_nrt"] = False  # numba's private switch for reference counting; its njit overloads do not list it
    return _njit_cached(fn, CACHE_DIR, **options)


def _njit_cached(fn: Any, cache_dir: str, **options: Any) -> Any:
    """``njit(cache=True, error_model="numpy", **options)`` caching into cache_dir (a damaged cache file is rebuilt,
    :mod:`roadload.jitcache`), or the ahead-of-time compiled kernel when this process uses those
    (:mod:`roadload.compiled`: numba is then not imported)."""
    def make() -> Any:
        from roadload.jitcache import cached_njit  # numba: only when the kernel is numba's

        return cached_njit(fn, cache_dir=cache_dir, error_model="numpy", **options)
    return kernel(fn, make)


def stage(fn):
    """``njit(inline="always")``: one named stage of a kernel, inlined into its caller in numba's IR, so a kernel
    written as a short sequence of stage calls compiles to the same single loop body as one long function."""
    def make() -> Any:
        import numba  # only when the kernel is numba's (roadload.compiled)

        return numba.njit(inline="always")(fn)
    return kernel(fn, make)


def dependent_jit(*sources: str | Path, core_stamp: str | None = None) -> Callable[..., Any]:
    """A decorator factory for kernels outside the core that call it: ``@kernel(parallel=True)`` or ``@kernel()``
    is ``njit(cache=True, error_model="numpy", ...)`` with the cache in a folder keyed by the hash of the core
    sources and of ``sources`` (the kernel's module and every module whose jitted functions it calls). numba would
    otherwise keep serving machine code with the old core inlined after an edit of the core (editable installs).
    ``core_stamp``: the hash of the core sources (default: this installation's, ``STAMP``). ``refcount=False``: as
    :func:`jit`'s, for kernels that allocate nothing (numba's reference counts are atomic operations on the shared
    arrays' counters, which two threads stepping the same arrays contend for)."""
    paths = [Path(f).resolve() for f in sources]
    core = STAMP if core_stamp is None else core_stamp
    stamp = hashlib.sha1(core.encode() + b"".join(p.read_bytes() for p in paths)).hexdigest()[:12]
    cache_dir = _cache_dir(paths[0].parent, f"numba-{paths[0].stem}-", stamp)

    def kernel(refcount: bool = True, **options: Any) -> Callable[[Any], Any]:
        if not refcount:
            options["_nrt"] = False
        return lambda fn: _njit_cached(fn, cache_dir, **options)
    kernel.cache_dir = cache_dir  # type: ignore[attr-defined]
    return kernel
