"""Diagnosis JSON before and after a change, compared value by value on the selftest worlds
(:mod:`roadload.experiments.sim2real.identity`).

    python scripts/sim2real_identity.py --write out/identity_ref.json
    python scripts/sim2real_identity.py --check out/identity_ref.json      # exit 1 on a changed or removed value
    python scripts/sim2real_identity.py --quick                             # CI smoke run: one case, 120 s trips
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from roadload.experiments.sim2real.identity import ADDED, CASES, diagnoses, differences
from roadload.fileio import write_json


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--write", type=Path, help="write the diagnoses here (the reference)")
    ap.add_argument("--check", type=Path, help="compare the diagnoses with this reference")
    ap.add_argument("--duration", type=float, default=300.0, help="seconds per trip (3 trips per case)")
    ap.add_argument("--quick", action="store_true", help="one case, 120 s trips, nothing compared")
    args = ap.parse_args(argv)
    if args.quick:
        diagnoses(120.0, CASES[:1], say=print)
        return 0
    if not (args.write or args.check):
        ap.error("give --write REFERENCE or --check REFERENCE")
    current = diagnoses(args.duration, say=print)
    if args.write:
        write_json(args.write, current)
        print(f"wrote {args.write} ({len(current)} diagnoses)")
    if args.check:
        diff = list(differences(json.loads(args.check.read_text()), current))
        changed = [d for d in diff if not d.endswith(ADDED)]
        for line in diff[:60]:
            print(line)
        print(f"{len(current)} diagnoses against {args.check}: {len(changed)} values changed or removed, "
              f"{len(diff) - len(changed)} keys added")
        return 1 if changed else 0
    return 0


if __name__ == "__main__":
    sys.exit(main())
