"""The fuzz suite feeds at least 300 malformed inputs from its tables alone (hypothesis adds more per run; the
session ledger printed at the end of a run counts both)."""

from __future__ import annotations

import importlib.util
from pathlib import Path

HERE = Path(__file__).parent
MODULES = ["test_fuzz_files", "test_fuzz_runtime", "test_fuzz_import", "test_fuzz_cli"]


def _table_inputs(name: str) -> int:
    spec = importlib.util.spec_from_file_location(f"_fuzz_count_{name}", HERE / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return int(module.TABLE_INPUTS)


def test_at_least_300_table_driven_malformed_inputs():
    counts = {name: _table_inputs(name) for name in MODULES}
    print(f"table-driven malformed inputs: {sum(counts.values())} {counts}")
    assert all(n > 0 for n in counts.values())
    assert sum(counts.values()) >= 300, counts
