"""Builds the ahead-of-time extension of :mod:`roadload.compiled`: the simulator's entry kernels, compiled by
``numba.pycc`` from the same numba functions as the JIT path, for the host CPU.

Each exported kernel is a one-line entry ``entry(a0, ...) -> kernel(a0, ...)`` around the kernel's own numba
dispatcher, so the kernel (and every kernel it calls or inlines) compiles with its own options (``error_model``,
reference counting, forced inlining) exactly as in a JIT run; pycc links that code into one shared object with numba's
small C runtime. The exported set is what a whole-trip run calls from Python (``Simulator`` set-up, reset, ``run``,
``step``, the driver's speed plan, the road generator); a kernel outside it switches the process back to numba when
called (``roadload.compiled``).
"""

from __future__ import annotations

import json
import os
import sys
import time
import warnings
from pathlib import Path
from typing import Any, Callable

import numpy as np

from roadload import compiled
from roadload.road_profiles import generate

from . import driver, drivetrain, numerics, physics
from .layout import VEHICLE


def _exports() -> list[tuple[Any, tuple[Any, ...]]]:
    """(numba dispatcher, sample arguments with the types Python passes) of every exported kernel."""
    vehicle = np.zeros(1, VEHICLE)
    params = vehicle[0]["params"]
    f1, f2, i2 = np.zeros(1), np.zeros((1, 1)), np.zeros((1, 1), np.int64)
    route = (f1, i2, f2, f1, f2, f2)  # tables (values, descriptors), road, stops, cycle, truth log
    return [
        (physics.run_one, (vehicle, *route, 1)), (physics.advance_one, (vehicle, *route, 1)),
        (physics.done_one, (vehicle,)), (physics.set_initial_mass, (vehicle, 1.0)),
        (physics.start_schedules, (vehicle,)), (numerics.road_value_at, (f2, 1, 1.0)),
        (driver._backward_pass, (f1, f1, 1.0)), (drivetrain.source_side_inertia, (params, 1)),
        (drivetrain.wheel_side_mass, (params, 1.0)), (drivetrain.speed_ratio, (params, 1)),
        (generate._symmetric_correlate, (f1, f1, 1, 1)), (generate._cell_means, (f1, 1.0, f1, f1, f1)),
    ]


def _descr(dtype: np.dtype) -> Any:
    """A dtype as JSON (``roadload.compiled`` rebuilds it); checked to round-trip."""
    descr = dtype.descr if dtype.names else dtype.str
    if compiled._dtype(json.loads(json.dumps(descr))) != dtype:
        raise ValueError(f"compiled kernels: dtype {dtype} does not round-trip through its description")
    return descr


def _argument_spec(sample: Any) -> list[Any]:
    """The manifest's description of one argument (``roadload.compiled._argument_check`` reads it)."""
    if isinstance(sample, np.ndarray):
        return ["array", _descr(sample.dtype), sample.ndim, bool(sample.flags.aligned)]
    if isinstance(sample, np.void):
        return ["record", _descr(sample.dtype)]
    return ["int"] if isinstance(sample, int) else ["float"]


def _entry(dispatcher: Any, n_args: int) -> Callable[..., Any]:
    """``entry(a0, ..., a{n-1})`` calling ``dispatcher`` with them (pycc compiles the entry with its own options; the
    dispatcher's code keeps the kernel's)."""
    names = ", ".join(f"a{i}" for i in range(n_args))
    space: dict[str, Any] = {"kernel": dispatcher}
    exec(f"def entry({names}):\n    return kernel({names})\n", space)
    return space["entry"]


def _sources() -> dict[str, str]:
    """SHA-1 of every roadload source loaded here but the command line's (constants and record layouts are frozen
    into the machine code, so an edit anywhere below the experiments means a rebuild)."""
    out = {}
    for name, module in sorted(sys.modules.items()):
        path = getattr(module, "__file__", None)
        if (name == "roadload" or name.startswith("roadload.")) and not name.startswith("roadload.experiments") \
                and path and path.endswith(".py"):
            out[str(Path(path).resolve())] = compiled.file_digest(path)
    return out


def build() -> Path | None:
    """Compile the extension into :func:`roadload.compiled.folder` and write its manifest (the library first, under
    a new name, then the manifest through a rename: a process loading at the same time sees the old pair or the
    new one). Returns the library's path, or None when no folder can be written. Takes 20-60 s (numba's cache of
    the kernels is filled on the way)."""
    if compiled.active():
        raise RuntimeError("build: this process runs the compiled kernels; build from a process that uses numba")
    folder = compiled.folder()
    if folder is None:
        return None
    import numba
    from numba.core.errors import NumbaPendingDeprecationWarning

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", NumbaPendingDeprecationWarning)
        from numba.pycc import CC

    cc = CC(compiled.MODULE_NAME)
    cc.output_dir = str(folder)
    cc.output_file = f"{compiled.MODULE_NAME}-{os.getpid()}-{time.time_ns()}.so"
    cc.target_cpu = "host"  # as numba's JIT compiles: the same instructions, so the same results bit for bit
    exports = {}
    for dispatcher, samples in _exports():
        argtypes = tuple(numba.typeof(a) for a in samples)
        dispatcher.compile(argtypes)
        restype = dispatcher.overloads[argtypes].signature.return_type
        name = compiled.export_name(dispatcher.py_func)
        cc.export(name, restype(*argtypes))(_entry(dispatcher, len(samples)))
        exports[name] = [_argument_spec(a) for a in samples]
    cc.compile()
    manifest = {"key": compiled.build_key(), "library": cc.output_file, "exports": exports, "sources": _sources()}
    tmp_manifest = folder / f"manifest.json.{os.getpid()}.tmp"
    tmp_manifest.write_text(json.dumps(manifest))
    os.replace(tmp_manifest, folder / "manifest.json")
    for old in folder.glob(f"{compiled.MODULE_NAME}-*.so"):  # earlier builds (a process that loaded one keeps it)
        if old.name != cc.output_file:
            old.unlink(missing_ok=True)
    return folder / cc.output_file
