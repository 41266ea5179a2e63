"""Kernels compiled ahead of time: the simulator's numba kernels as one C extension that loads without numba or LLVM.

A process that only runs whole trips (``roadload simulate``) calls a handful of compiled kernels from Python. With
numba, each process imports numba and llvmlite and maps libllvmlite (40-100 MB of resident library pages, more on a
freshly written install) only to load machine code from numba's cache. :func:`use_compiled_kernels` (called before
the simulator is imported) loads instead an extension module that ``numba.pycc`` built from the same kernels
(``roadload.envs.compiled`` builds it, with numba, into a cache folder; the first run that asks builds it).

Every numba kernel of the simulator and the road generator is made through :func:`kernel`: with no extension
loaded it returns numba's dispatcher (exactly as before); with one loaded it returns, without importing numba,

* the extension's function for a kernel the extension exports (the entry points Python calls), behind a check of
  the argument types it was compiled for;
* otherwise a placeholder (a kernel that only other kernels call, or one this process was not expected to call).

Calling a placeholder, or an exported kernel with other argument types, switches the process back to numba
(:func:`use_numba`): every kernel made so far gets its numba dispatcher, in every ``roadload`` module that holds it,
and the call goes on there. A missing, stale or unloadable extension leaves numba in charge.

The extension is keyed (:func:`build_key`) by the Python, numpy, numba and llvmlite versions and the CPU (it is
compiled for the host CPU, as numba's JIT compiles), and it is used only while every roadload source file it was
built from is unchanged (its manifest lists them with their SHA-1).
"""

from __future__ import annotations

import hashlib
import importlib.util
import json
import os
import platform
import sys
import tempfile
from importlib import metadata
from pathlib import Path
from types import ModuleType
from typing import Any, Callable

import numpy as np

#: the extension module's name (its init function is PyInit_<name>)
MODULE_NAME = "roadload_kernels"
#: environment switch: "0" keeps every process on numba (no extension is loaded or built)
ENV_SWITCH = "ROADLOAD_COMPILED_KERNELS"

_module: ModuleType | None = None
#: (what :func:`kernel` returned, the factory of its numba dispatcher) while the extension is in use
_made: list[tuple[Any, Callable[[], Any]]] = []
#: numba dispatchers made by :func:`kernel` since the process started (0: the extension may still be loaded)
_numba_kernels = 0
#: whether :func:`use_compiled_kernels` found no valid extension (the caller may build one for the next runs)
build_wanted = False


def export_name(fn: Callable[..., Any]) -> str:
    """The extension's name for kernel ``fn``: its module and qualified name with '.' as '__'."""
    return f"{fn.__module__}.{fn.__qualname__}".replace(".", "__")


def kernel(fn: Callable[..., Any], make: Callable[[], Any]) -> Any:
    """The kernel of Python function ``fn``: ``make()`` (its numba dispatcher) unless the extension is in use (module
    docstring)."""
    global _numba_kernels
    if _module is None:
        _numba_kernels += 1
        return make()
    compiled = getattr(_module, export_name(fn), None)
    spec = _manifest_exports.get(export_name(fn))
    made: Any = _Checked(fn, compiled, spec) if compiled is not None and spec is not None else _Placeholder(fn)
    _made.append((made, make))
    return made


def cached_kernel(fn: Callable[..., Any]) -> Any:
    """``roadload.jitcache.cached_njit`` as a decorator through :func:`kernel` (numba is imported only when the
    kernel is numba's)."""
    def make() -> Any:
        from roadload.jitcache import cached_njit  # numba: only when the kernel is numba's

        return cached_njit(fn)
    return kernel(fn, make)


class _Placeholder:
    """A kernel the extension does not export: calling it from Python switches the process to numba."""

    def __init__(self, fn: Callable[..., Any]) -> None:
        self.py_func = fn
        self.__name__, self.__qualname__, self.__doc__ = fn.__name__, fn.__qualname__, fn.__doc__

    def __call__(self, *args: Any) -> Any:
        return use_numba()[id(self)](*args)


class _Checked(_Placeholder):
    """An exported kernel: the extension's function when every argument has the type it was compiled for (an array's
    dtype, dimensions, C order, writeability and alignment; a record's dtype; an integer; a float), else numba."""

    def __init__(self, fn: Callable[..., Any], compiled: Callable[..., Any], spec: list[Any]) -> None:
        super().__init__(fn)
        self.compiled = compiled
        self.checks = [_argument_check(s) for s in spec]

    def __call__(self, *args: Any) -> Any:
        if len(args) == len(self.checks) and all(check(a) for check, a in zip(self.checks, args)):
            return self.compiled(*args)
        return use_numba()[id(self)](*args)


def _dtype(descr: Any) -> np.dtype:
    """A dtype from its JSON-stored ``descr`` (lists back to the tuples numpy expects)."""
    def fields(d: Any) -> Any:  # [name, type (a string or nested fields), optional shape]
        return [(f[0], fields(f[1]) if isinstance(f[1], list) else f[1], *[tuple(x) for x in f[2:]]) for f in d]
    return np.dtype(fields(descr) if isinstance(descr, list) else descr)


def _argument_check(spec: list[Any]) -> Callable[[Any], bool]:
    """A predicate for one argument: ``["array", descr, ndim, aligned]``, ``["record", descr]``, ``["int"]`` or
    ``["float"]`` (what the builder wrote for numba's type of that argument)."""
    kind = spec[0]
    if kind == "array":
        dtype, ndim, aligned = _dtype(spec[1]), spec[2], spec[3]
        return lambda a: (type(a) is np.ndarray and a.dtype == dtype and a.ndim == ndim and a.flags.c_contiguous
                          and a.flags.writeable and a.flags.aligned == aligned)
    if kind == "record":
        dtype = _dtype(spec[1])
        return lambda a: isinstance(a, np.void) and a.dtype == dtype
    if kind == "int":
        return lambda a: isinstance(a, (int, np.integer)) and not isinstance(a, bool)
    if kind == "float":
        return lambda a: isinstance(a, (float, np.floating))
    raise ValueError(f"compiled kernels: unknown argument kind {kind!r} in the manifest")


def use_numba() -> dict[int, Any]:
    """Switch this process to numba: every kernel :func:`kernel` made from the extension gets its numba dispatcher,
    in every ``roadload`` module namespace that holds it (kernels find the kernels they call there); returns
    {id(what kernel() returned): dispatcher}. Kernels made from now on are numba's."""
    global _module
    _module = None
    real = {id(made): make() for made, make in _made}
    for name, module in list(sys.modules.items()):
        if name == "roadload" or name.startswith("roadload."):
            space = vars(module)
            for key, value in list(space.items()):
                if id(value) in real:
                    space[key] = real[id(value)]
    _use_numba_done.update(real)
    _made.clear()
    return _use_numba_done


_use_numba_done: dict[int, Any] = {}
_manifest_exports: dict[str, list[Any]] = {}


def active() -> bool:
    """Whether this process runs the extension's kernels."""
    return _module is not None


def cpu_identity() -> str:
    """The host CPU as the extension was compiled for it: model name and feature flags (Linux), else the machine."""
    try:
        with open("/proc/cpuinfo") as f:
            lines = [line for line in f.read().split("\n\n")[0].splitlines()
                     if line.split(":")[0].strip() in ("vendor_id", "model name", "flags")]
        return "\n".join(lines)
    except OSError:
        return f"{platform.machine()} {platform.processor()}"


def build_key() -> dict[str, str]:
    """What an extension must have been built with to be loaded: Python, numpy, numba, llvmlite, the CPU."""
    versions = {}
    for dist in ("numba", "llvmlite"):
        try:
            versions[dist] = metadata.version(dist)
        except metadata.PackageNotFoundError:
            versions[dist] = "absent"
    return {"python": sys.version, "numpy": np.__version__, **versions,
            "cpu": hashlib.sha256(cpu_identity().encode()).hexdigest()[:16]}


def folder() -> Path | None:
    """The extension's folder: ``$NUMBA_CACHE_DIR/roadload`` when set (one cache for a read-only install or a
    cluster), else ``__pycache__`` of this package, else the temp folder; one sub-folder per build key and install
    location. None when none can be written."""
    shared = os.environ.get("NUMBA_CACHE_DIR", "")
    bases = ([Path(shared) / "roadload"] if shared else
             [Path(__file__).resolve().parent / "__pycache__", Path(tempfile.gettempdir()) / "roadload-numba"])
    key = hashlib.sha256(json.dumps([build_key(), str(Path(__file__).resolve())]).encode()).hexdigest()[:12]
    for base in bases:
        d = base / f"compiled-{key}"
        try:
            d.mkdir(parents=True, exist_ok=True)
            if os.access(d, os.W_OK):
                return d
        except OSError:
            continue
    return None


def file_digest(path: str | Path) -> str:
    return hashlib.sha1(Path(path).read_bytes()).hexdigest()


def read_manifest(d: Path) -> dict[str, Any] | None:
    """The folder's manifest when it is whole, built with this :func:`build_key` and every listed source is unchanged;
    else None."""
    try:
        manifest = json.loads((d / "manifest.json").read_text())
        if manifest["key"] != build_key():
            return None
        if any(file_digest(path) != digest for path, digest in manifest["sources"].items()):
            return None
        return manifest
    except (OSError, ValueError, KeyError, TypeError):
        return None


FAILED = "build-failed.txt"


def record_build_failure(exc: BaseException) -> None:
    """Note a failed build in the folder (keyed like the extension): later runs do not try again."""
    global build_wanted
    build_wanted = False
    d = folder()
    if d is not None:
        (d / FAILED).write_text(f"{type(exc).__name__}: {exc}\n")


def use_compiled_kernels() -> bool:
    """Load the extension for the kernels made from now on (call before ``roadload.envs`` and
    ``roadload.road_profiles`` are imported); False (numba stays in charge) when kernels were already made with
    numba, ``ROADLOAD_COMPILED_KERNELS=0``, or no valid extension exists (then :data:`build_wanted` is set)."""
    global _module, build_wanted
    if _module is not None:
        return True
    if _numba_kernels or os.environ.get(ENV_SWITCH, "1") == "0":
        return False
    d = folder()
    manifest = None if d is None else read_manifest(d)
    if manifest is None:
        build_wanted = d is not None and not (d / FAILED).exists()
        return False
    try:
        spec = importlib.util.spec_from_file_location(MODULE_NAME, d / manifest["library"])
        if spec is None or spec.loader is None:
            return False
        module = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(module)
    except (ImportError, OSError):  # a damaged or foreign file: numba compiles as before; the next build replaces it
        build_wanted = True
        return False
    _manifest_exports.clear()
    _manifest_exports.update(manifest["exports"])
    _module = module
    return True
