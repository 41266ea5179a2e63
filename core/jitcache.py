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

import hashlib
import os
import pickle
import sys
import warnings
from pathlib import Path
from typing import Any, Callable

import llvmlite
import llvmlite.binding as ll
import numba
from numba.core import config
from numba.core.caching import FunctionCache
from numba.core.compiler_lock import global_compiler_lock
from numba.core.runtime import _nrt_python  # type: ignore[attr-defined]  # a C extension without stubs
from numba.core.runtime import nrtdynmod, rtsys


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
            initialize_runtime(target_context, Path(self._cache_path))
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


#: the numba internals :func:`initialize_runtime` reads (numba 0.68); without any of them numba initialises its runtime
#: itself (compiled in every run, as before the cache)
_RUNTIME_INTERNALS_KNOWN = (hasattr(rtsys, "_init") and hasattr(rtsys, "initialize")
                            and hasattr(_nrt_python, "c_helpers") and hasattr(nrtdynmod, "create_nrt_module"))

#: how this process got numba's runtime module: "cache" (object code loaded), "compiled" (and stored) by
#: :func:`initialize_runtime`, or None (not yet, or by numba itself: a kernel compiled first)
runtime_origin: str | None = None


def initialize_runtime(target_context: Any, cache_dir: Path) -> None:
    """numba's runtime (NRT) made ready for the machine code of cached kernels, as ``rtsys.initialize`` does (numba
    0.68: statistics switched on if configured, its C helpers declared to LLVM, then its small LLVM module of
    reference-counting functions compiled), but with that module's machine code cached too, in ``cache_dir`` (the
    kernels' cache folder): a run on a warm cache then loads object code alone, without running LLVM's optimiser
    and code generator, which map ~10-14 MB more of libllvmlite (/proc/self/smaps) for a module that is the same in
    every run. The file is keyed by the numba and llvmlite versions, the Python version and the codegen's target
    (triple, CPU, features); one that cannot be read is reported (RuntimeWarning) and rewritten."""
    global runtime_origin
    if not _RUNTIME_INTERNALS_KNOWN:  # another numba than the one this was written against: its own initialisation
        rtsys.initialize(target_context)
        return
    if getattr(rtsys, "_init", True):
        return
    with global_compiler_lock:
        if rtsys._init:
            return
        if getattr(config, "NRT_STATS"):  # numba creates its settings at runtime (see cached_njit)
            _nrt_python.memsys_enable_stats()
        for py_name, address in _nrt_python.c_helpers.items():
            ll.add_symbol(py_name if py_name.startswith("_") else "NRT_" + py_name, address)
        codegen = target_context.codegen()
        key = repr((numba.__version__, llvmlite.__version__, sys.version, codegen.magic_tuple()))
        path = cache_dir / f"numba_runtime.{hashlib.sha256(key.encode()).hexdigest()[:16]}.nbc"
        library = _load_runtime_library(codegen, path)
        runtime_origin = "cache"
        if library is None:
            runtime_origin = "compiled"
            ir_module, library = nrtdynmod.create_nrt_module(target_context)
            library.enable_object_caching()  # keep the machine code for serialize_using_object_code
            library.add_ir_module(ir_module)
            library.finalize()
            _save_runtime_library(library, path)
        rtsys._library = library
        rtsys._init = True


def _load_runtime_library(codegen: Any, path: Path) -> Any:
    """The runtime's code library from its cache file (None: no file, or a damaged one, then removed)."""
    try:
        data = path.read_bytes()
    except OSError:
        return None
    try:
        return codegen.unserialize_library(pickle.loads(data))
    except Exception as exc:  # a damaged file: UnpicklingError, EOFError, an LLVM error on the object code, ...
        warnings.warn(f"numba runtime cache {path} is corrupt ({type(exc).__name__}: {exc}); compiling it again",
                      RuntimeWarning, stacklevel=3)
        path.unlink(missing_ok=True)
        return None


def _save_runtime_library(library: Any, path: Path) -> None:
    """Write the runtime's object code through a temporary file and a rename (a reader sees a whole file or none);
    a folder that cannot be written (a read-only install) only costs the compilation in the next run."""
    tmp = path.with_name(f"{path.name}.{os.getpid()}.tmp")
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp.write_bytes(pickle.dumps(library.serialize_using_object_code(), protocol=pickle.HIGHEST_PROTOCOL))
        os.replace(tmp, path)
    except OSError:
        tmp.unlink(missing_ok=True)


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
