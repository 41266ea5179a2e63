"""Import CSV logs through a mapping file and diagnose where the simulator disagrees with them.

    python examples/import_and_diagnose.py --quick                   # demo logs, small settings (< 1 min)
    python examples/import_and_diagnose.py                           # demo logs, roadload's default settings
    python examples/import_and_diagnose.py --csv a.csv b.csv --mapping my_logger.json --sim bmw_i3

Without ``--csv`` the script first writes demo logs: the ``bmw_i3`` preset driven with a payload the sim does not
know (``--payload`` [kg]), exported as a data logger would (km/h, bar, °C, its own column names), plus the
mapping file that reads them. The logs are imported with ``roadload.io.import_log`` (what ``roadload import
--format csv --mapping FILE`` does), diagnosed with ``roadload.sim2real.diagnose`` and the report is written to
OUT (report.md, diagnosis.json, PNG figures). Prints the gap before/after and the candidate ranking.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import pandas as pd

from roadload.envs import simulate
from roadload.fileio import write_text
from roadload.io import import_log
from roadload.road_profiles import load_profile
from roadload.sim2real import DiagnosisSettings, SimConfig, diagnose, write_report
from roadload.tables import markdown_table

DEMO_MAPPING = {
    "name": "demo_logger", "format": "csv", "sample_rate": 100,
    "csv": {"time": "Time [s]", "time_unit": "s"},
    "channels": [
        {"source": "Speed [km/h]", "channel": "vehicle_speed", "unit": "km/h", "resample": "linear", "required": True},
        {"source": "AccelX", "channel": "accel_x", "unit": "m/s^2", "resample": "linear", "required": True},
        {"source": "MotorTorque", "channel": "drive_torque", "unit": "N*m", "resample": "linear", "required": True},
        {"source": "Gear", "channel": "gear", "unit": "1", "resample": "hold"},
        {"source": "BrakeF", "channel": "brake_pressure_front", "unit": "bar", "resample": "linear"},
        {"source": "BrakeR", "channel": "brake_pressure_rear", "unit": "bar", "resample": "linear"},
        {"source": "Tamb", "channel": "ambient_temperature", "unit": "degC", "resample": "linear"},
    ],
}


def write_demo_logs(folder: Path, roads: list[str], duration: float, payload: float) -> tuple[list[Path], Path]:
    """Simulated 'real' logs in a logger's own columns and units, and the mapping that reads them."""
    folder.mkdir(parents=True, exist_ok=True)
    paths = []
    for i, road in enumerate(roads):
        trip = simulate("bmw_i3", load_profile(road, seed=30 + i), seed=30 + i, duration=duration,
                        effects=[f"payload:initial_payload={payload:g},change_std=0"])
        log = trip.measured[["t", "vehicle_speed", "accel_x", "drive_torque", "gear", "brake_pressure_front",
                             "brake_pressure_rear", "ambient_temperature"]].copy()
        log["vehicle_speed"] *= 3.6
        log[["brake_pressure_front", "brake_pressure_rear"]] /= 1e5
        log["ambient_temperature"] -= 273.15
        log.columns = ["Time [s]"] + [c["source"] for c in DEMO_MAPPING["channels"]]
        path = folder / f"drive{i}_{road}.csv"
        write_text(path, log.to_csv(index=False))
        paths.append(path)
    mapping = folder / "demo_logger.json"
    write_text(mapping, json.dumps(DEMO_MAPPING, indent=1) + "\n")
    return paths, mapping


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="2 x 400 s demo logs and small diagnosis settings")
    parser.add_argument("--csv", type=Path, nargs="*", help="your CSV logs (default: write demo logs)")
    parser.add_argument("--mapping", type=Path, help="mapping JSON for --csv (see roadload.io.mapping)")
    parser.add_argument("--sim", default="bmw_i3", help="sim: preset name or sim config JSON")
    parser.add_argument("--payload", type=float, default=200.0, help="payload of the demo logs [kg]")
    parser.add_argument("--out", type=Path, default=Path("out/examples/diagnosis"))
    args = parser.parse_args()
    if args.csv:
        if args.mapping is None:
            parser.error("--csv needs --mapping (a JSON file: source column -> channel, unit, resample)")
        paths, mapping = list(args.csv), args.mapping
    else:
        roads = ["hilly", "city"] if args.quick else ["hilly", "city", "motorway"]
        paths, mapping = write_demo_logs(args.out / "logs", roads, 400.0 if args.quick else 900.0, args.payload)
    trips = [import_log(p, "csv", mapping=mapping) for p in paths]
    for p, trip in zip(paths, trips):
        report = trip.meta["import_report"]
        print(f"imported {p.name}: {len(trip)} samples, {len(trip.channels)} channels, "
              f"{report['n_repaired']} repaired, {report['n_dropped']} dropped")
    settings = (DiagnosisSettings(floor_roads=(("hilly", 9101),), floor_duration=300.0, n_boot=100,
                                  resimulate=False, replay=False) if args.quick else DiagnosisSettings())
    diagnosis = diagnose(trips, SimConfig.load(args.sim), settings)
    before, after = diagnosis.gap_before.force_residual, diagnosis.gap_after.force_residual
    print(f"held-out force residual: median {before.median:+.0f} N, RMSE {before.rmse:.0f} N -> "
          f"{after.rmse:.0f} N; identified {diagnosis.identified or 'nothing'}")
    ranking = pd.DataFrame([{"candidate": r.name, "held-out gain": r.improvement, "significant": r.significant,
                             "fit": ", ".join(f"{k} = {v:.4g}" for k, v in r.parameters.items())}
                            for r in diagnosis.ranking[:6]])
    print(markdown_table(ranking, floatfmt=".3f"))
    for step in diagnosis.selection:
        print(f"forward selection step {step.step}: {step.effect} -> {step.reason}")
    written = write_report(diagnosis, args.out)
    print("report:", ", ".join(str(p) for p in written.values()))


if __name__ == "__main__":
    main()
