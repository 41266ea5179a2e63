"""numba's on-disk cache, made safe against damaged cache files, for every cached kernel of roadload.

numba raises the unpickling error of a truncated or damaged index or data file (a full disk, a bad copy of a
cache folder) at the first call of the function, which fails the whole run. :func:`cached_njit` is
``numba.njit(cache=True, ...)`` whose cache is a :class:`CheckedCache`: such a file is reported (RuntimeWarning),
removed with the function's other cache files, and the function compiled and cached again.

Processes may start on an empty cache at the same time (Dask workers, SubprocVecEnv, pytest-xdist): numba writes
every index and data file through a temporary file and a rename, so a reader sees a whole file or none, and a
kernel two processes compile at once is compiled twice, not corrupted. ``NUMBA_CACHE_DIR`` puts the cache of
every kernel in one folder (a read-only install, or one cache for the workers of a cluster).
"""

from __future__ import annotations

import warnings
from pathlib import Path
from typing import Any, Callable

import numba
from numba.core import config
from numba.core.caching import FunctionCache
from numba.core.runtime import rtsys


class CheckedCache(FunctionCache):
    """numba's per-function disk cache; an index or data file that cannot be read back is not trusted (module
    docstring)."""

    #: False: a cache hit loads the machine code with only the runtime (NRT) it links against. numba's own load
    #: first installs every lowering registry of the target (its whole library of numpy and builtin implementations:
    #: 1.4 s and ~25 MB of a simulate's peak RSS) that only compiling needs (a cache miss installs them itself).
    #: True for a ufunc (cached_vectorize): numba builds its loop wrapper with the target's lowerings after the load.
    full_context = False

    def load_overload(self, sig: Any, target_context: Any) -> Any:
        try:
            if self.full_context:
                return super().load_overload(sig, target_context)
            rtsys.initialize(target_context)
            with self._guard_against_spurious_io_errors():
                return self._load_overload(sig, target_context)
        except Exception as exc:  # whatever a damaged pickle raises: UnpicklingError, EOFError, ValueError, ...
            warnings.warn(f"numba cache of {self._name} in {self._cache_path} is corrupt ({type(exc).__name__}: "
                          f"{exc}); compiling it again", RuntimeWarning, stacklevel=2)
            self.discard()
            return None

    def discard(self) -> None:
        """Remove this function's index and data files (the next save writes them afresh)."""
        index = Path(self._cache_file._index_path)
        for path in [index, *index.parent.glob(index.name[:-len(".nbi")] + ".*.nbc")]:
            try:
                path.unlink()
            except OSError:  # gone already (another process rebuilt it), or not ours to remove
                pass


def cached_njit(fn: Callable[..., Any] | None = None, *, cache_dir: str | None = None, **options: Any) -> Any:
    """``numba.njit(cache=True, **options)`` with a :class:`CheckedCache`, in ``cache_dir`` when given (else numba's
    own locations: ``NUMBA_CACHE_DIR`` or ``__pycache__`` next to the source). As a decorator: ``@cached_njit`` or
    ``@cached_njit(inline="always")``."""
    if fn is None:
        return lambda f: cached_njit(f, cache_dir=cache_dir, **options)
    # numba.core.config creates its settings (CACHE_DIR, ...) at runtime from the environment: getattr/setattr
    old = getattr(config, "CACHE_DIR")
    if cache_dir is not None:
        setattr(config, "CACHE_DIR", cache_dir)
    try:
        dispatcher = numba.njit(cache=True, **options)(fn)
        dispatcher._cache = CheckedCache(dispatcher.py_func)  # the dispatcher's cache slot (enable_caching sets it)
        return dispatcher
    finally:
        setattr(config, "CACHE_DIR", old)


def cached_vectorize(signatures: list[str], **options: Any) -> Callable[[Callable[..., Any]], Any]:
    """``numba.vectorize(signatures, cache=True, **options)`` (CPU target) with a :class:`CheckedCache`: the
    signatures are compiled (or loaded) at decoration time, as numba's own decorator does."""
    from numba.np.ufunc.dufunc import DUFunc

    def wrap(fn: Callable[..., Any]) -> Any:
        ufunc: Any = DUFunc(fn, cache=True, **options)
        ufunc._dispatcher.cache = CheckedCache(ufunc._dispatcher.py_func)  # before any signature is loaded
        ufunc._dispatcher.cache.full_context = True
        for signature in signatures:
            ufunc.add(signature)
        ufunc.disable_compile()
        return ufunc
    return wrap
