"""Run the shell code blocks (```bash / ```sh) of Markdown pages in order, so a command the README or a guide
tells users to run cannot rot unnoticed. Blocks that install or run the test suite (``pip install``, ``pytest``)
are skipped: .ci/run runs those itself.

    python .ci/doc_commands.py README.md --workdir SCRATCH        # the README's commands in a scratch folder
    python .ci/doc_commands.py docs/guides/*.md --workdir .        # the guides' commands, after their Python blocks
"""

from __future__ import annotations

import argparse
import re
import subprocess
import sys
import time
from pathlib import Path

SETUP = re.compile(r"^\s*(pip install|pytest)\b", re.M)


def shell_blocks(text: str) -> list[str]:
    return [m.group(1).strip() for m in re.finditer(r"^```(?:bash|sh)\n(.*?)^```", text, re.M | re.S)]


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("pages", type=Path, nargs="+")
    ap.add_argument("--workdir", type=Path, required=True)
    args = ap.parse_args()
    ran = 0
    for page in args.pages:
        for i, block in enumerate(shell_blocks(page.read_text(encoding="utf-8")), start=1):
            first = block.splitlines()[0][:100]
            if SETUP.search(block):
                print(f"skip: {page} block {i} (set-up / tests, run by .ci/run): {first}")
                continue
            t0 = time.perf_counter()
            run = subprocess.run(["bash", "-euo", "pipefail", "-c", block], cwd=args.workdir, capture_output=True,
                                 text=True)
            if run.returncode != 0:
                print(f"FAILED: {page} block {i}: {first}\n{run.stdout[-3000:]}\n{run.stderr[-3000:]}")
                return 1
            ran += 1
            print(f"ok: {page} block {i} ({time.perf_counter() - t0:.0f} s): {first}")
    print(f"{ran} shell blocks ran")
    return 0


if __name__ == "__main__":
    sys.exit(main())
