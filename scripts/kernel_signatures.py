"""Parameter count of every numba kernel in the simulator and gym sources, and the largest one.

    python scripts/kernel_signatures.py [--folders envs gym-envs] [--limit 12] [--quick]

Reads the sources (no compilation; experiments/kernel_signatures.py). Prints one line per kernel, largest first,
then ``largest kernel signature: N parameters (file:line name)``; exits 1 when N exceeds ``--limit``.
``--quick`` (CI smoke run) prints only the ten largest.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from roadload.experiments.kernel_signatures import kernel_signatures

ROOT = Path(__file__).resolve().parents[1]


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--folders", nargs="+", default=["envs", "gym-envs"], help="source folders under the repository")
    ap.add_argument("--limit", type=int, default=12, help="largest parameter count allowed (exit 1 above it)")
    ap.add_argument("--quick", action="store_true", help="print only the ten largest (CI smoke run)")
    args = ap.parse_args()
    kernels = kernel_signatures([ROOT / f for f in args.folders], ROOT)
    if not kernels:
        print(f"no numba kernels under {args.folders}")
        return 0
    for k in kernels[:10] if args.quick else kernels:
        print(f"{k.parameters:3d}  {k.path}:{k.line}  {k.name}")
    top = kernels[0]
    print(f"{len(kernels)} kernels; largest kernel signature: {top.parameters} parameters ({top.path}:{top.line} "
          f"{top.name}); limit {args.limit}")
    return 1 if top.parameters > args.limit else 0


if __name__ == "__main__":
    sys.exit(main())
