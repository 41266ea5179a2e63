"""Build real road profiles (grade + curvature over distance) from the real logs of ../shared/data.

- CANedge drives (logs 00000164 and 00000165): grade from GNSS altitude (accuracy-filtered, smoothed over 150 m),
  curvature from the IMU yaw rate (gyro bias at standstill removed, smoothed over 40 m); the pitch- and
  course-based variants are compared and the agreement stored in the profile metadata.
- BMW i3 trips (--bmw TripA01 ...): grade from the map elevation (1 m quantised, smoothed over 150 m); the i3
  logs carry no yaw rate or heading, so curvature is 0 (stated in the metadata).

The files are generated, not committed: they land in road-profiles/real/ (or --out) in the road-profiles
JSON format, with source and licence in their metadata. Load one with
``roadload profiles show road-profiles/real/canedge_164.json``.

    python scripts/make_real_profiles.py [--out DIR] [--bmw TripA01 TripA06]
"""

from __future__ import annotations

import argparse
import tempfile
import sys
from pathlib import Path

import numpy as np

from roadload.data import shared_data_dir
from roadload.io.importer import import_log
from roadload.io.mapping import load_mapping
from roadload.io.profiles import profile_from_trip, save_trip_profile

REPO = Path(__file__).resolve().parents[1]
"""The source tree of an editable install; the script passes its own repository instead."""
CANEDGE_SOURCE = ("CSS-Electronics/api-examples examples/other/matlab-basics/LOG_datastore/3BA199E2 "
                  "(snapshot f7932bac), session {session}, via ../shared/data/css_canedge_gnss_obd")


def _licence(mapping: str) -> str:
    """The data licence of a shipped mapping: every profile made from real logs carries it in its metadata."""
    licence = load_mapping(mapping).licence
    if not licence:
        raise ValueError(f"mapping {mapping!r} names no licence; a profile made from its logs must carry one")
    return licence


def canedge_profiles(base: Path, out: Path, limit: int | None = None) -> list[Path]:
    licence = _licence("canedge_gnss_obd")
    written = []
    for folder in sorted((base / "css_canedge_gnss_obd" / "raw_mf4").iterdir())[:limit]:
        session = folder.name.split("_")[-1].lstrip("0")
        trip = import_log(folder, "dbc-mf4")
        source = CANEDGE_SOURCE.format(session=folder.name)
        prof = profile_from_trip(trip, name=f"canedge_{session}", source=source, licence=licence)
        alt = profile_from_trip(trip, name="cmp", source=source, licence=licence, grade_source="pitch",
                                curvature_source="heading")
        prof.meta["cross_check"] = {
            "grade_corr_altitude_vs_pitch": float(np.corrcoef(prof.grade, alt.grade)[0, 1]),
            "grade_rms_diff_altitude_vs_pitch_pct": float(np.sqrt(np.mean((np.tan(prof.grade)
                                                                           - np.tan(alt.grade)) ** 2)) * 100),
            "curvature_corr_yaw_rate_vs_course": float(np.corrcoef(prof.curvature, alt.curvature)[0, 1])}
        prof.meta["clock"] = trip.meta.get("clock")
        written.append(save_trip_profile(prof, out))
        _describe(prof, written[-1])
    return written


def bmw_profiles(base: Path, out: Path, trips: list[str]) -> list[Path]:
    licence = _licence("bmw_i3")
    written = []
    for name in trips:
        trip = import_log(base / "bmw_i3_tum" / "data" / f"{name}.csv", "bmw-i3")
        if "grade" not in trip.channels:
            print(f"{name}: skipped ({'; '.join(n for n in trip.meta['import_report']['notes'] if 'grade' in n)})")
            continue
        prof = profile_from_trip(trip, name=f"bmw_i3_{name}", licence=licence, curvature_source=None,
                                 source=f"TUM BMW i3 data set, {name} (DOI 10.21227/6jr9-5235), "
                                        f"via ../shared/data/bmw_i3_tum")
        prof.meta["curvature_meaning"] = "not in the log (no yaw rate / heading): 0"
        written.append(save_trip_profile(prof, out))
        _describe(prof, written[-1])
    return written


def _describe(prof, path: Path) -> None:
    g = np.tan(prof.grade) * 100
    kappa = np.abs(prof.curvature)
    print(f"{path.name}: {prof.length / 1000:.2f} km, grade {g.min():+.1f} .. {g.max():+.1f} % (std {g.std():.2f} %),"
          f" elevation range {np.ptp(prof.elevation()):.0f} m, min radius "
          f"{(1 / kappa.max()) if kappa.max() > 0 else float('inf'):.0f} m, repairs {prof.meta.get('repairs')}")
    if "cross_check" in prof.meta:
        print(f"    cross-check: {prof.meta['cross_check']}")


def main(argv: list[str] | None = None, repo: Path = REPO) -> int:
    """The command line (``scripts/make_real_profiles.py``); the profiles go to ``repo``/road-profiles/real unless
    ``--out`` or ``--quick`` says otherwise. Returns the exit status."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=repo / "road-profiles" / "real")
    ap.add_argument("--bmw", nargs="*", default=["TripA01", "TripA06"], help="BMW i3 trips to convert")
    ap.add_argument("--quick", action="store_true",
                    help="tiny run for CI: one BMW trip, written to a temporary folder (not the package's real/)")
    args = ap.parse_args(argv)
    if args.quick:
        args.out, args.bmw = Path(tempfile.mkdtemp(prefix="roadload-profiles-")), args.bmw[:1]
    base = shared_data_dir()
    if base is None:
        print("needs the shared data folder (../shared/data or $ROADLOAD_DATA)"
              + ("; skipped" if args.quick else ""), file=sys.stderr)
        return 0 if args.quick else 1
    files = canedge_profiles(base, args.out, 1 if args.quick else None) + bmw_profiles(base, args.out, args.bmw)
    print(f"wrote {len(files)} profiles to {args.out}")
    return 0
