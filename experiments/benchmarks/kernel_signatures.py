"""How many parameters the compiled kernels take: every numba function of the given source folders, found by
reading the sources (no import, no compilation).

A kernel is a function decorated with numba's ``njit`` / ``jit`` / ``vectorize`` / ``cfunc``, one of roadload's
wrappers of it (``jit``, ``stage``, ``cached_njit`` / ``cached_vectorize``) or a module-level name bound to such a call
(``kernel = dependent_jit(__file__)``, ``_inline = njit(inline="always")``), with or without a call. Counted: the
positional and keyword parameters of its ``def``. The simulator's kernels take a few packed records (state,
parameters, command, tables, route) instead of dozens of arrays and scalars; ``scripts/kernel_signatures.py`` prints
the table and the largest count and fails above a limit.

    python scripts/kernel_signatures.py [--folders envs gym-envs] [--limit 12] [--quick]   # default: all
    python scripts/kernel_signatures.py                        # every package folder (PACKAGE_FOLDERS)
"""

from __future__ import annotations

import argparse
import ast
from dataclasses import dataclass
from pathlib import Path

KERNEL_DECORATORS = frozenset({"njit", "jit", "cached_njit", "stage", "kernel", "generated_jit", "vectorize",
                               "cached_vectorize", "guvectorize", "cfunc"})
"""Decorator names (bare or called, plain or as an attribute such as ``numba.njit``) that make a kernel."""
KERNEL_FACTORIES = KERNEL_DECORATORS | {"dependent_jit"}
"""Calls whose result, bound to a module-level name, is a kernel decorator too."""


@dataclass(frozen=True)
class KernelSignature:
    """One compiled kernel: source file (relative to the repository), line, name and number of parameters."""

    path: str
    line: int
    name: str
    parameters: int


PACKAGE_FOLDERS = ("core", "road-profiles", "envs", "estimators", "controllers", "gym-envs", "sim2real", "experiments")
"""The source folders of the package (pyproject's package-dir), what ``--folders all`` reads."""


def _decorator_name(node: ast.expr) -> str:
    target = node.func if isinstance(node, ast.Call) else node
    if isinstance(target, ast.Attribute):
        return target.attr
    return target.id if isinstance(target, ast.Name) else ""


def _parameter_count(fn: ast.FunctionDef) -> int:
    a = fn.args
    return len(a.posonlyargs) + len(a.args) + len(a.kwonlyargs) + (a.vararg is not None) + (a.kwarg is not None)


def _decorator_aliases(tree: ast.Module) -> set[str]:
    """Module-level names bound to a kernel decorator call (``kernel = dependent_jit(__file__)``)."""
    return {t.id for node in tree.body if isinstance(node, ast.Assign) and isinstance(node.value, ast.Call)
            and _decorator_name(node.value) in KERNEL_FACTORIES for t in node.targets if isinstance(t, ast.Name)}


def file_kernels(path: Path, root: Path) -> list[KernelSignature]:
    """The kernels defined in one Python source file."""
    tree = ast.parse(path.read_text(), filename=str(path))
    decorators = KERNEL_DECORATORS | _decorator_aliases(tree)
    return [KernelSignature(str(path.relative_to(root)), node.lineno, node.name, _parameter_count(node))
            for node in ast.walk(tree) if isinstance(node, ast.FunctionDef)
            and any(_decorator_name(d) in decorators for d in node.decorator_list)]


def kernel_signatures(folders: list[Path], root: Path) -> list[KernelSignature]:
    """Every kernel under the folders (recursively), largest parameter count first, then by file and line."""
    missing = [str(f) for f in folders if not f.is_dir()]
    if missing:
        raise FileNotFoundError(f"source folders not found: {missing} (expected folders under {root})")
    found = [k for folder in folders for path in sorted(folder.rglob("*.py")) for k in file_kernels(path, root)]
    return sorted(found, key=lambda k: (-k.parameters, k.path, k.line))


def main(argv: list[str] | None = None, repo: Path | None = None) -> int:
    """The check's command line (``scripts/kernel_signatures.py``): one line per kernel, largest first (the ten
    largest with ``--quick``), then the largest count; returns 1 when it exceeds ``--limit``. ``repo``: the source
    tree (default: the one of this file)."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--folders", nargs="+", default=["all"],
                    help="source folders under the repository ('all': every package folder)")
    ap.add_argument("--limit", type=int, default=12, help="largest parameter count allowed (exit 1 above it)")
    ap.add_argument("--quick", action="store_true", help="print only the ten largest (CI smoke run)")
    args = ap.parse_args(argv)
    root = repo or Path(__file__).resolve().parents[2]
    folders = list(PACKAGE_FOLDERS) if args.folders == ["all"] else args.folders
    kernels = kernel_signatures([root / f for f in folders], root)
    if not kernels:
        print(f"no numba kernels under {folders}")
        return 0
    for k in kernels[:10] if args.quick else kernels:
        print(f"{k.parameters:3d}  {k.path}:{k.line}  {k.name}")
    top = kernels[0]
    print(f"{len(kernels)} kernels; largest kernel signature: {top.parameters} parameters ({top.path}:{top.line} "
          f"{top.name}); limit {args.limit}")
    return 1 if top.parameters > args.limit else 0
