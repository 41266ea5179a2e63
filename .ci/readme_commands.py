"""Run every ```bash block of the README after the first (the install + test commands, which .ci/run runs itself)
in a scratch folder, so a command the README tells users to run cannot rot unnoticed."""

from __future__ import annotations

import argparse
import re
import subprocess
import sys
import time
from pathlib import Path


def bash_blocks(text: str) -> list[str]:
    return [m.group(1).strip() for m in re.finditer(r"^```(?:bash|sh|console)\n(.*?)^```", text, re.M | re.S)]


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("readme", type=Path)
    ap.add_argument("--workdir", type=Path, required=True)
    args = ap.parse_args()
    blocks = bash_blocks(args.readme.read_text(encoding="utf-8"))
    if not blocks:
        print(f"{args.readme}: no bash blocks", file=sys.stderr)
        return 1
    for i, block in enumerate(blocks[1:], start=2):
        t0 = time.perf_counter()
        run = subprocess.run(["bash", "-euo", "pipefail", "-c", block], cwd=args.workdir, capture_output=True,
                             text=True)
        first = block.splitlines()[0][:100]
        if run.returncode != 0:
            print(f"FAILED: README block {i}: {first}\n{run.stdout[-3000:]}\n{run.stderr[-3000:]}")
            return 1
        print(f"ok: README block {i} ({time.perf_counter() - t0:.0f} s): {first}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
