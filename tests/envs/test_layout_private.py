"""The simulator's storage stays private to envs/: no file outside envs/ (package, scripts, experiments, tests,
examples) imports its record layout, packing or numba-cache module, ``pack_vehicle`` or a layout index constant.
import-linter's protected contract checks the package; this test covers every Python file of the repository."""

from __future__ import annotations

import ast
import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
PRIVATE = {"_jit", "layout", "packing"}
LAYOUT_CONSTANT = re.compile(r"^[SPLCRT]_[A-Z0-9_]+$")


def private_imports(path: Path, root: Path = ROOT) -> list[str]:
    """'file:line name' (file relative to root) of every import of the simulator's private storage in one file."""
    found = []
    for node in ast.walk(ast.parse(path.read_text(), filename=str(path))):
        if isinstance(node, ast.Import):
            names = [a.name for a in node.names if a.name.split(".")[:2] == ["roadload", "envs"]
                     and a.name.split(".")[-1] in PRIVATE]
        elif isinstance(node, ast.ImportFrom) and (node.module or "").startswith("roadload.envs"):
            module = node.module or ""
            names = [a.name for a in node.names if module.split(".")[-1] in PRIVATE or a.name in PRIVATE
                     or a.name == "pack_vehicle" or LAYOUT_CONSTANT.match(a.name)]
        else:
            continue
        found += [f"{path.relative_to(root)}:{node.lineno} {name}" for name in names]
    return found


def test_nothing_outside_envs_imports_the_layout_packing_or_jit():
    files = [p for p in ROOT.rglob("*.py") if p.relative_to(ROOT).parts[0] not in ("envs", "build", ".git")]
    assert len(files) > 100
    assert [hit for p in files for hit in private_imports(p)] == []


def test_the_check_finds_a_planted_import(tmp_path):
    planted = tmp_path / "replay.py"
    planted.write_text("from roadload.envs.layout import S_POS\nfrom roadload.envs import packing\n"
                       "import roadload.envs._jit\nfrom roadload.envs.batch import Fleet\n"
                       "from roadload.envs.drivetrain import pack_vehicle\n")
    assert private_imports(planted, tmp_path) == ["replay.py:1 S_POS", "replay.py:2 packing",
                                                  "replay.py:3 roadload.envs._jit", "replay.py:5 pack_vehicle"]
