"""Import throughput of the MF4 + DBC path (roadload.io) on the CANedge sessions of ../shared/data.

Prints, per session and stage (read MF4 -> decode with the DBCs -> map/resample to 100 Hz), the wall time,
MB/s of MF4 input, CAN frames/s, decoded signal samples/s and output Trip samples/s (rows x channels).
Best of --repeat runs (the first run also pays imports and file-cache misses; it is shown separately).

    /work/venv/bin/python scripts/bench_import.py [--repeat 5] [--cantools]
"""

from __future__ import annotations

import argparse
import time

from roadload.data import shared_data_dir
from roadload.io.dbc import load_dbc
from roadload.io.frames import read_mf4
from roadload.io.loaders import check_mapping_against_dbc, resolve_dbcs
from roadload.io.mapping import apply_mapping, load_mapping
from roadload.io.report import ImportReport
from roadload.io.dbc import decode_frames


def run_once(folder, mapping):
    t0 = time.perf_counter()
    frames = read_mf4(folder)
    t1 = time.perf_counter()
    report = ImportReport()
    db = load_dbc(resolve_dbcs(mapping, folder), report)
    needed = check_mapping_against_dbc(mapping, db, report)

    signals = decode_frames(frames, db, report, wanted_messages=needed)
    t2 = time.perf_counter()
    trip = apply_mapping(signals, mapping, report, start_time=frames.start_time)
    t3 = time.perf_counter()
    n_samples = sum(len(s) for s in signals.values())
    return {"read": t1 - t0, "decode": t2 - t1, "map": t3 - t2, "total": t3 - t0, "frames": len(frames),
            "signal_samples": n_samples, "out_samples": len(trip) * len(trip.channels), "rows": len(trip),
            "channels": len(trip.channels)}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--cantools", action="store_true", help="also time cantools' per-frame decoding")
    ap.add_argument("--quick", action="store_true", help="tiny run for CI: one session, one repetition")
    args = ap.parse_args(argv)
    if args.quick:
        args.repeat = 1
    base = shared_data_dir()
    if base is None or not (base / "css_canedge_gnss_obd").is_dir():
        print("skipped: needs ../shared/data/css_canedge_gnss_obd (set ROADLOAD_DATA)")
        return 0
    mapping = load_mapping("canedge_gnss_obd")
    sessions = sorted((base / "css_canedge_gnss_obd" / "raw_mf4").iterdir())[: 1 if args.quick else None]
    print(f"MF4 + DBC import, mapping {mapping.name}, best of {args.repeat} (first run in brackets)")
    header = (f"{'session':<20}{'MB':>7}{'frames':>9}{'read s':>8}{'decode s':>9}{'map s':>7}{'total s':>9}"
              f"{'MB/s':>8}{'frames/s':>11}{'sig samp/s':>12}{'out samp/s':>12}")
    print(header)
    tot_mb = tot_t = tot_frames = tot_sig = tot_out = 0.0
    for folder in sessions:
        mb = sum(p.stat().st_size for p in folder.glob("*.MF4")) / 1e6
        runs = [run_once(folder, mapping) for _ in range(max(1, args.repeat))]
        first, best = runs[0], min(runs, key=lambda r: r["total"])
        print(f"{folder.name:<20}{mb:7.1f}{best['frames']:9d}{best['read']:8.3f}{best['decode']:9.3f}"
              f"{best['map']:7.3f}{best['total']:9.3f}{mb / best['total']:8.1f}{best['frames'] / best['total']:11.3g}"
              f"{best['signal_samples'] / best['total']:12.3g}{best['out_samples'] / best['total']:12.3g}"
              f"   [first {first['total']:.3f} s]")
        tot_mb += mb
        tot_t += best["total"]
        tot_frames += best["frames"]
        tot_sig += best["signal_samples"]
        tot_out += best["out_samples"]
    print(f"{'all':<20}{tot_mb:7.1f}{int(tot_frames):9d}{'':>8}{'':>9}{'':>7}{tot_t:9.3f}{tot_mb / tot_t:8.1f}"
          f"{tot_frames / tot_t:11.3g}{tot_sig / tot_t:12.3g}{tot_out / tot_t:12.3g}")
    print(f"output: {best['rows']} rows x {best['channels']} channels at 100 Hz (last session)")
    if args.cantools:
        compare_cantools(sessions[0], mapping)
    return 0


def compare_cantools(folder, mapping) -> None:
    """Reference: decoding the same frames one at a time with cantools' decode_message (no mapping stage)."""

    frames = read_mf4(folder)
    report = ImportReport()
    db = load_dbc(resolve_dbcs(mapping, folder), report)
    t0 = time.perf_counter()
    decode_frames(frames, db, report)
    t_vec = time.perf_counter() - t0
    t0 = time.perf_counter()
    n = 0
    for i in range(len(frames)):
        msg = db.messages.get((int(frames.bus[i]), int(frames.arbitration_id[i]), bool(frames.is_extended[i])))
        if msg is not None:
            msg.decode(frames.data[i, : msg.length].tobytes(), decode_choices=False)
            n += 1
    t_ct = time.perf_counter() - t0
    print(f"decode only, {folder.name}: vectorised {len(frames) / t_vec:.3g} frames/s, cantools per frame "
          f"{n / t_ct:.3g} frames/s ({t_ct / t_vec:.0f}x)")
