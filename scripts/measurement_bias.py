"""Measurement-side honesty (issue 14): the online M4-RRLM estimate against the least-squares fit of M4 to the
simulator's TRUE forces, with the CAN drive-torque bias and the body pitch in eq. 5.2 switched off one by one.

Prints the table (mean over seeds, difference to the truth LS in %) and writes measurement_bias.csv/.md/.png to
--out. Usage: python scripts/measurement_bias.py [--out DIR] [--seeds 3] [--length 20000] [--quick]
"""

from __future__ import annotations

import argparse
from pathlib import Path

import pandas as pd

from roadload.tables import markdown_table
from roadload.experiments.measurement_bias import PARAMETERS, bias_figure, measurement_bias, summarise_bias
from roadload.fileio import write_text


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=Path("measurement_bias"), help="output folder")
    ap.add_argument("--seeds", type=int, default=3)
    ap.add_argument("--length", type=float, default=20_000.0, help="hilly road length [m] per trip")
    ap.add_argument("--preset", default="bmw_i3")
    ap.add_argument("--quick", action="store_true", help="1 seed, 4 km")
    args = ap.parse_args()
    seeds, length = (1, 4000.0) if args.quick else (args.seeds, args.length)
    if seeds < 1 or length < 1000:
        ap.error("--seeds must be >= 1 and --length >= 1000 m")
    rows = [r for seed in range(seeds) for r in measurement_bias(args.preset, seed, length)]
    summary = summarise_bias(rows)
    args.out.mkdir(parents=True, exist_ok=True)
    write_text(args.out / "measurement_bias_runs.csv", pd.DataFrame(rows).to_csv(index=False))
    write_text(args.out / "measurement_bias.csv", summary.to_csv(index=False))
    cols = ["variant", "method", "seeds", *PARAMETERS, *[f"{p} vs truth LS [%]" for p in PARAMETERS[:3]]]
    md = markdown_table(summary[cols].round(3))
    write_text(args.out / "measurement_bias.md", md + "\n")
    bias_figure(summary, args.out / "measurement_bias.png")
    print(md)
    print(f"wrote {args.out}/measurement_bias.md/.csv/.png")


if __name__ == "__main__":
    main()
