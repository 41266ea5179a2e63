"""Run the code blocks of Markdown pages in order and check their stored outputs, so that a command the README or a
guide tells users to run -- and what the page says it prints -- cannot rot unnoticed.

Blocks that run: ```bash / ```sh (in a bash with ``-euo pipefail``), and with ``--python`` also ```python (each in a
fresh namespace of one worker process, like separate ``python -c`` runs that share loaded modules). Blocks that
install or run the test suite (``pip install``, ``pytest``) are skipped: .ci/run runs those itself.

Stored outputs: a fenced block with the info string ``output`` right after a block that runs (nothing but blank
lines between) holds what that block prints on stdout::

    ```python
    print(f"energy {energy:.3f} kWh")
    ```

    ```output
    energy 0.128 kWh
    ```

It is compared with the printed text after stripping trailing spaces and leading/trailing blank lines; it must match
exactly, except that ``...`` in the stored text matches any text (wall times, paths of temporary folders, dates,
solver timings -- whatever differs from run to run; deterministic numbers are never elided). A block without an
output block is only run. ``--update`` rewrites every stored output that no longer matches with what was printed
(keep the ``...`` elisions by hand where the new text needs them).

    python .ci/doc_commands.py README.md --workdir SCRATCH                  # the README's shell blocks
    python .ci/doc_commands.py docs/guides/*.md --python --workdir .        # the guides: Python + shell + outputs

``--covered-by PAGE ...``: a shell block whose code is also a shell block of one of these pages is not run again
(.ci/smoke.py passes the pages the docs stage runs, so that the README's command shared with the home page runs
once per CI run).
"""

from __future__ import annotations

import argparse
import json
import os
import re
import resource
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path

SETUP = re.compile(r"^\s*(pip install|pytest)\b", re.M)
#: a fixed terminal width, so that tables rich lays out to the terminal print the same in CI and for a reader
ENV = {**os.environ, "COLUMNS": "120", "MPLBACKEND": "Agg"}
FENCE = re.compile(r"^```([\w-]*)[^\n]*\n(.*?)^```[ \t]*$", re.M | re.S)
RUNS = {"bash": "shell", "sh": "shell", "python": "python"}


@dataclass
class Block:
    """One fenced block that runs, with the stored output that follows it (if any)."""

    kind: str                  # "shell" or "python"
    code: str
    line: int                  # 1-based line of the opening fence
    expected: str | None       # the stored output, or None
    output_span: tuple[int, int] | None = None  # character span of the output block's body in the page


def page_blocks(text: str, python: bool) -> list[Block]:
    """The blocks of a page that run (shell; python too when ``python``), each with its stored output."""
    fences = list(FENCE.finditer(text))
    blocks = []
    for i, m in enumerate(fences):
        kind = RUNS.get(m.group(1))
        if kind is None or (kind == "python" and not python):
            continue
        block = Block(kind, m.group(2), text.count("\n", 0, m.start()) + 1, None)
        nxt = fences[i + 1] if i + 1 < len(fences) else None
        if nxt is not None and nxt.group(1) == "output" and not text[m.end():nxt.start()].strip():
            block.expected, block.output_span = nxt.group(2), (nxt.start(2), nxt.end(2))
        blocks.append(block)
    return blocks


def normalise(text: str) -> str:
    return "\n".join(line.rstrip() for line in text.strip("\n").splitlines()).strip("\n")


def matches(expected: str, actual: str) -> bool:
    """``actual`` equals ``expected``, where ``...`` in ``expected`` stands for any text (across lines too)."""
    pattern = ".*?".join(re.escape(part) for part in normalise(expected).split("..."))
    return re.fullmatch(pattern, normalise(actual), flags=re.S) is not None


def first_difference(expected: str, actual: str) -> str:
    exp, act = normalise(expected).splitlines(), normalise(actual).splitlines()
    for i in range(max(len(exp), len(act))):
        e = exp[i] if i < len(exp) else "<end>"
        a = act[i] if i < len(act) else "<end>"
        if "..." not in e and e != a:
            return f"first difference at output line {i + 1}:\n  stored:  {e}\n  printed: {a}"
    return "the elided (...) lines do not line up"


WORKER = r"""
import contextlib, io, json, os, sys, traceback
os.environ.setdefault("MPLBACKEND", "Agg")
for raw in sys.stdin:
    code = json.loads(raw)
    out, ok = io.StringIO(), True
    try:
        with contextlib.redirect_stdout(out):
            exec(compile(code, "<doc block>", "exec"), {"__name__": "__main__"})
    except BaseException:
        ok = False
        out.write("\n" + traceback.format_exc())
    sys.__stdout__.write("DOC-BLOCK-RESULT " + json.dumps({"ok": ok, "out": out.getvalue()}) + "\n")
    sys.__stdout__.flush()
"""


class PythonWorker:
    """One Python process that runs blocks one after the other, each in a fresh namespace."""

    def __init__(self, workdir: Path) -> None:
        self.proc = subprocess.Popen([sys.executable, "-u", "-c", WORKER], cwd=workdir, stdin=subprocess.PIPE,
                                     stdout=subprocess.PIPE, text=True, env=ENV)

    def run(self, code: str) -> tuple[bool, str]:
        assert self.proc.stdin is not None and self.proc.stdout is not None
        self.proc.stdin.write(json.dumps(code) + "\n")
        self.proc.stdin.flush()
        # what a block wrote to the file descriptor directly (a subprocess, C code): part of its output
        stray: list[str] = []
        for line in self.proc.stdout:
            if line.startswith("DOC-BLOCK-RESULT "):
                result = json.loads(line[len("DOC-BLOCK-RESULT "):])
                return result["ok"], "".join(stray) + result["out"]
            stray.append(line)
        return False, "".join(stray) + "\nthe Python worker died (see its stderr above)"

    def cpu_seconds(self) -> float:
        """CPU seconds (user + system) of the worker so far, with its finished children (/proc/PID/stat)."""
        try:
            fields = Path(f"/proc/{self.proc.pid}/stat").read_text().rsplit(")", 1)[1].split()
        except OSError:
            return 0.0
        return sum(int(f) for f in fields[11:15]) / os.sysconf("SC_CLK_TCK")  # utime stime cutime cstime

    def close(self) -> None:
        if self.proc.stdin is not None:
            self.proc.stdin.close()
        self.proc.wait(timeout=60)


def shell_blocks(pages: list[Path]) -> dict[str, str]:
    """The code of every shell block of ``pages`` (normalised), each with where it is (``page:line``)."""
    found: dict[str, str] = {}
    for page in pages:
        for block in page_blocks(page.read_text(encoding="utf-8"), python=False):
            found.setdefault(normalise(block.code), f"{page}:{block.line}")
    return found


def skip_reason(block: Block, covered: dict[str, str] | None) -> str | None:
    """Why a block is not run here (set-up / tests, or the same shell block runs in a covered page), or None."""
    if block.kind != "shell":
        return None
    if SETUP.search(block.code):
        return "set-up / tests, run by .ci/run"
    if covered and normalise(block.code) in covered:
        return f"the same block runs in {covered[normalise(block.code)]}"
    return None


def cpu_seconds(worker: PythonWorker | None) -> float:
    """CPU seconds of this process's finished children (the shell blocks) plus the page's Python worker so far."""
    children = resource.getrusage(resource.RUSAGE_CHILDREN)
    return children.ru_utime + children.ru_stime + (worker.cpu_seconds() if worker is not None else 0.0)


def run_block(block: Block, workdir: Path, worker: PythonWorker | None) -> tuple[bool, str]:
    """(success, printed text) of one block: a shell block in its own bash, a Python block in the page's worker."""
    if block.kind == "shell":
        run = subprocess.run(["bash", "-euo", "pipefail", "-c", block.code], cwd=workdir,
                             capture_output=True, text=True, env=ENV)
        ok, out = run.returncode == 0, run.stdout
        if not ok:
            out += f"\n(exit code {run.returncode})\n{run.stderr[-3000:]}"
        return ok, out
    assert worker is not None
    return worker.run(block.code)


def run_page(page: Path, workdir: Path, python: bool, update: bool,
             covered: dict[str, str] | None = None) -> tuple[int, int, list[str]]:
    """(blocks run, outputs checked, failures) of one page; with ``update`` the page's stale outputs are rewritten.
    A shell block whose code is a key of ``covered`` (:func:`shell_blocks`) is skipped: it runs there."""
    text = page.read_text(encoding="utf-8")
    blocks = page_blocks(text, python)
    worker = PythonWorker(workdir) if any(b.kind == "python" for b in blocks) else None
    ran = checked = 0
    failures: list[str] = []
    new_outputs: list[tuple[tuple[int, int], str]] = []
    try:
        for block in blocks:
            first = block.code.splitlines()[0][:100] if block.code.strip() else ""
            where = f"{page}:{block.line}"
            reason = skip_reason(block, covered)
            if reason:
                print(f"skip: {where} ({reason}): {first}")
                continue
            t0, c0 = time.perf_counter(), cpu_seconds(worker)
            ok, out = run_block(block, workdir, worker)
            took = f"{time.perf_counter() - t0:.0f} s, {cpu_seconds(worker) - c0:.0f} s CPU"
            ran += 1
            if not ok:
                failures.append(f"{where}: {block.kind} block failed: {first}\n{out[-3000:]}")
                print(f"FAILED: {where} ({took}): {first}")
                break  # later blocks may depend on this one
            status = "ok"
            if block.expected is not None:
                checked += 1
                if not matches(block.expected, out):
                    if update and block.output_span is not None:
                        new_outputs.append((block.output_span, normalise(out) + "\n"))
                        status = "updated"
                    else:
                        failures.append(f"{where}: stored output differs from what the block prints; "
                                        f"{first_difference(block.expected, out)}\n--- printed ---\n{out[-3000:]}")
                        status = "OUTPUT DIFFERS"
            print(f"{status}: {where} ({took}): {first}")
    finally:
        if worker is not None:
            worker.close()
    for (start, end), body in sorted(new_outputs, reverse=True):
        text = text[:start] + body + text[end:]
    if new_outputs:
        page.write_text(text, encoding="utf-8")
        print(f"updated {len(new_outputs)} stored outputs in {page}")
    return ran, checked, failures


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("pages", type=Path, nargs="+")
    ap.add_argument("--workdir", type=Path, required=True)
    ap.add_argument("--python", action="store_true", help="also run the ```python blocks")
    ap.add_argument("--update", action="store_true", help="rewrite stored outputs that no longer match")
    ap.add_argument("--covered-by", type=Path, nargs="+", default=[], metavar="PAGE",
                    help="pages run elsewhere: a shell block that is also one of theirs is not run again")
    args = ap.parse_args()
    covered = shell_blocks(args.covered_by)
    ran = checked = 0
    failures: list[str] = []
    for page in args.pages:
        r, c, f = run_page(page, args.workdir, args.python, args.update, covered)
        ran, checked, failures = ran + r, checked + c, failures + f
    for failure in failures:
        print(f"\nFAILED: {failure}")
    print(f"{ran} blocks ran, {checked} stored outputs checked, {len(failures)} failures")
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
