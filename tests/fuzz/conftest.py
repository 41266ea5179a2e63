"""Fuzz ledger: every malformed input a fuzz test feeds in is recorded with its outcome.

Outcomes: ``error`` (a clean project error whose message names the field / option / line) or ``repair`` (accepted,
and the repair is reported, e.g. in the import report). A traceback or a silent acceptance fails the test that
produced it, so a green run has 0 of both. The session prints the totals and writes them to
``$ROADLOAD_FUZZ_SUMMARY`` (default: the pytest cache-free temp dir) as JSON; under xdist the workers' ledgers are
merged by the controller. Run ``pytest tests/fuzz`` to see the ledger: under xdist, a run from the repository root
does not load this conftest in the controller, and then only ``test_fuzz_count.py`` checks the table size.
"""

from __future__ import annotations

import json
import os
import shutil
import tempfile
from collections import Counter
from pathlib import Path

import pytest

_LEDGER: Counter = Counter()
_SURFACES: Counter = Counter()
MIN_INPUTS = 300


def _ledger_dir(config) -> Path:
    base = os.environ.get("ROADLOAD_FUZZ_DIR") or getattr(config, "_fuzz_dir", None)
    if base is None:
        root = getattr(config, "workerinput", {}).get("fuzz_dir") if hasattr(config, "workerinput") else None
        base = root or tempfile.mkdtemp(prefix="roadload-fuzz-")
        config._fuzz_dir = base
    return Path(base)


def pytest_configure(config):
    if not hasattr(config, "workerinput"):
        _ledger_dir(config)


def pytest_configure_node(node):  # xdist controller -> worker: share the ledger folder
    node.workerinput["fuzz_dir"] = str(_ledger_dir(node.config))


class Ledger:
    def record(self, surface: str, outcome: str, n: int = 1) -> None:
        assert outcome in ("error", "repair"), outcome
        _LEDGER[outcome] += n
        _SURFACES[surface] += n


@pytest.fixture
def ledger() -> Ledger:
    return Ledger()


def pytest_sessionfinish(session, exitstatus):
    config = session.config
    if hasattr(config, "workerinput") and "fuzz_dir" not in config.workerinput and not os.environ.get(
        "ROADLOAD_FUZZ_DIR"
    ):
        return  # a worker of a run whose controller did not load this conftest: nobody would read the ledger
    folder = _ledger_dir(config)
    worker = getattr(config, "workerinput", {}).get("workerid", "main") if hasattr(config, "workerinput") else "main"
    if _LEDGER:
        (folder / f"ledger-{worker}.json").write_text(
            json.dumps({"outcomes": dict(_LEDGER), "surfaces": dict(_SURFACES)})
        )


def fuzz_totals(folder: Path) -> tuple[Counter, Counter]:
    outcomes, surfaces = Counter(), Counter()
    for f in folder.glob("ledger-*.json"):
        data = json.loads(f.read_text())
        outcomes.update(data["outcomes"])
        surfaces.update(data["surfaces"])
    return outcomes, surfaces


def pytest_terminal_summary(terminalreporter, exitstatus, config):
    if hasattr(config, "workerinput"):
        return
    outcomes, surfaces = fuzz_totals(_ledger_dir(config))
    if not outcomes:
        return
    failed = len(terminalreporter.stats.get("failed", []))
    total = sum(outcomes.values())
    tr = terminalreporter
    tr.write_sep("-", "roadload fuzz ledger")
    tr.write_line(
        f"malformed inputs: {total} (clean errors {outcomes['error']}, reported repairs "
        f"{outcomes['repair']}); failing fuzz tests (traceback or silent acceptance): {failed}"
    )
    tr.write_line("per surface: " + ", ".join(f"{k} {v}" for k, v in sorted(surfaces.items())))
    out = os.environ.get("ROADLOAD_FUZZ_SUMMARY")
    if out:
        Path(out).write_text(
            json.dumps(
                {
                    "inputs": total,
                    "clean_errors": outcomes["error"],
                    "repairs": outcomes["repair"],
                    "failed_tests": failed,
                    "surfaces": dict(surfaces),
                },
                indent=1,
            )
        )
    if not os.environ.get("ROADLOAD_FUZZ_DIR"):
        shutil.rmtree(_ledger_dir(config), ignore_errors=True)
    if total < MIN_INPUTS and config.getoption("-k", None) in (None, "") and not config.args[1:]:
        tr.write_line(f"WARNING: fewer than {MIN_INPUTS} fuzz inputs ran")
