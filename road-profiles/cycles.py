"""Standard speed-vs-time drive cycles and graded real cycles, read from the shared data folder.

The traces are public test procedures (EPA UDDS/FTP-75/HWFET/US06, UNECE GTR 15 WLTC class 3a/3b), staged from
NREL FASTSim (Apache-2.0) in ``<shared data>/drive_cycles/`` (see its SOURCE.md); they are never copied into the
project. ``cycle_position`` / ``speed_at_position`` / ``cycle_to_profile`` give a cycle in the distance domain.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from roadload.data import shared_data_dir

from .profile import DriveCycle, RoadProfile, RoadProfileError

if TYPE_CHECKING:
    import pandas as pd

_FASTSIM = "NREL FASTSim python/fastsim/resources/cycles (snapshot bd9111bb)"
_LICENCE = "Apache-2.0 (NREL FASTSim); the regulatory speed traces are public test procedures"

# name -> (file under drive_cycles/, description, regulation reference)
STANDARD_CYCLES: dict[str, tuple[str, str]] = {
    "wltc3b": ("standard/wltc_3b.csv", "WLTC class 3b (v_max >= 120 km/h), UNECE GTR 15: 1800 s, 23.27 km"),
    "wltc3a": ("standard/wltc_3a.csv", "WLTC class 3a (v_max < 120 km/h), UNECE GTR 15: 1800 s, 23.19 km"),
    "wltc3_low": ("standard/wltc_low_3.csv", "WLTC class 3 low phase: 589 s, 3.09 km"),
    "wltc3a_medium": ("standard/wltc_medium_3a.csv", "WLTC class 3a medium phase: 433 s"),
    "wltc3b_medium": ("standard/wltc_medium_3b.csv", "WLTC class 3b medium phase: 433 s"),
    "wltc3a_high": ("standard/wltc_high_3a.csv", "WLTC class 3a high phase: 455 s"),
    "wltc3b_high": ("standard/wltc_high_3b.csv", "WLTC class 3b high phase: 455 s"),
    "wltc3_extrahigh": ("standard/wltc_extrahigh_3.csv", "WLTC class 3 extra-high phase: 323 s, 8.25 km"),
    "udds": ("standard/udds.csv", "EPA UDDS (FTP-72, LA-4), 40 CFR 86 App. I: 1369 s, 11.99 km"),
    "hwfet": ("standard/hwfet.csv", "EPA Highway Fuel Economy Test, 40 CFR 600 App. I: 765 s, 16.5 km"),
    "us06": ("standard/us06.csv", "EPA US06 supplemental FTP: 600 s, 12.9 km"),
}
CYCLE_ALIASES = {"wltc3": "wltc3b", "wltc": "wltc3b"}
FTP75_COLD_PHASE = 505  # s, UDDS 0..505 s: cold-start transient phase (bag 1), repeated hot (bag 3)
FTP75_SOAK = 600  # s, hot soak between bag 2 and bag 3 (engine off)


def drive_cycles_dir() -> Path:
    """``<shared data>/drive_cycles``; FileNotFoundError naming ROADLOAD_DATA when absent."""
    base = shared_data_dir()
    if base is None or not (base / "drive_cycles").is_dir():
        raise FileNotFoundError("drive cycles need the shared data folder drive_cycles/: set ROADLOAD_DATA to the "
                                "shared data folder (or place it at ../shared/data next to the project)")
    return base / "drive_cycles"


def _read_csv(path: Path, columns: tuple[str, ...]) -> pd.DataFrame:
    import pandas as pd  # here, not at import: a simulate that follows no drive cycle needs no pandas (45 MB)

    if not path.is_file():
        raise FileNotFoundError(f"drive cycle file {path} is missing: check ROADLOAD_DATA / the shared data folder")
    frame = pd.read_csv(path, encoding="utf-8-sig")  # some FASTSim files carry a byte-order mark
    missing = [c for c in columns if c not in frame.columns]
    if missing:
        raise RoadProfileError(f"{path.name}: missing columns {missing}; found {list(frame.columns)}")
    return frame


def _fastsim_cycle(name: str, relpath: str, description: str) -> DriveCycle:
    path = drive_cycles_dir() / relpath
    frame = _read_csv(path, ("cycSecs", "cycMps", "cycGrade"))
    grade = np.arctan(frame["cycGrade"].to_numpy(float))
    return DriveCycle(name=name, time=frame["cycSecs"].to_numpy(float), speed=frame["cycMps"].to_numpy(float),
                      grade=grade if np.any(grade != 0) else None,
                      meta={"source": f"{_FASTSIM}/{Path(relpath).name}", "licence": _LICENCE,
                            "description": description, "units": {"time": "s", "speed": "m/s", "grade": "rad"}})


def load_cycle(name: str) -> DriveCycle:
    """A standard cycle by name: wltc3 (= wltc3b), wltc3a, wltc3b, WLTC phases, udds, ftp75, hwfet, us06."""
    key = CYCLE_ALIASES.get(name.lower(), name.lower())
    if key == "ftp75":
        return ftp75()
    if key not in STANDARD_CYCLES:
        known = sorted([*STANDARD_CYCLES, *CYCLE_ALIASES, "ftp75"])
        raise RoadProfileError(f"unknown drive cycle {name!r}; known: {known}")
    relpath, description = STANDARD_CYCLES[key]
    return _fastsim_cycle(key, relpath, description)


def ftp75(include_soak: bool = False) -> DriveCycle:
    """EPA FTP-75 (40 CFR 86.115/86.130): UDDS 0-1369 s (cold-start bag 1 = 0-505 s, stabilised bag 2 =
    505-1369 s), a 10 min hot soak with the engine off, then UDDS 0-505 s again (hot-start bag 3).

    Without the soak (default) the hot-start phase follows directly: 1874 s, 17.77 km (11.04 mi). With
    ``include_soak`` the 600 s standstill is inserted (2474 s); ``meta["phases"]`` gives the bag boundaries [s].
    """
    udds = load_cycle("udds")
    if not (udds.time[0] == 0 and np.all(np.diff(udds.time) == 1.0)):
        raise RoadProfileError("udds: expected a 1 Hz trace starting at 0 s to compose FTP-75")
    end = udds.time[-1]
    hot = udds.speed[1:FTP75_COLD_PHASE + 1]  # t = 1..505 s; t = 0 coincides with the end of bag 2 (standstill)
    offset = end + (FTP75_SOAK if include_soak else 0.0)
    speed = [udds.speed]
    time = [udds.time]
    if include_soak:
        time.append(np.arange(end + 1, offset + 1))
        speed.append(np.zeros(FTP75_SOAK))
    time.append(offset + np.arange(1, FTP75_COLD_PHASE + 1))
    speed.append(hot)
    meta = dict(udds.meta)
    meta.update(description="EPA FTP-75 composed from UDDS per 40 CFR 86: bag 1 cold 0-505 s, bag 2 505-1369 s, "
                            f"{'600 s hot soak, ' if include_soak else 'hot soak omitted, '}bag 3 hot = UDDS 0-505 s",
                phases={"cold_transient": [0.0, float(FTP75_COLD_PHASE)],
                        "stabilized": [float(FTP75_COLD_PHASE), float(end)],
                        **({"soak": [float(end), float(offset)]} if include_soak else {}),
                        "hot_transient": [float(offset), float(offset + FTP75_COLD_PHASE)]})
    return DriveCycle(name="ftp75", time=np.concatenate(time), speed=np.concatenate(speed), meta=meta)


def tsdc_trip() -> DriveCycle:
    """Real 300 s trip with road grade (NREL TSDC trip 42648 via FASTSim), 1 Hz, grade in rad."""
    path = drive_cycles_dir() / "real_world" / "TSDC_tripno_42648_cycle.csv"
    frame = _read_csv(path, ("time_s", "mps", "grade"))
    return DriveCycle(name="tsdc_300s", time=frame["time_s"].to_numpy(float), speed=frame["mps"].to_numpy(float),
                      grade=np.arctan(frame["grade"].to_numpy(float)),
                      meta={"source": f"{_FASTSIM}/real_world/TSDC_tripno_42648_cycle.csv (NREL TSDC)",
                            "licence": "Apache-2.0 (NREL FASTSim)",
                            "description": "real 300 s trip with road grade (rise/run converted to rad)"})


def long_haul_truck() -> DriveCycle:
    """Heavy-truck long-haul cycle with grade: 83 042 s, 805 km, grade -2.3..+2.9 % (provenance undocumented)."""
    path = drive_cycles_dir() / "real_world" / "longHaulDriveCycle.csv"
    frame = _read_csv(path, ("cycSecs", "cycMps", "cycGrade"))
    return DriveCycle(name="longhaul_truck", time=frame["cycSecs"].to_numpy(float),
                      speed=frame["cycMps"].to_numpy(float), grade=np.arctan(frame["cycGrade"].to_numpy(float)),
                      meta={"source": f"{_FASTSIM}/real_world/longHaulDriveCycle.csv", "licence": _LICENCE,
                            "description": "heavy-truck long-haul cycle with grade; provenance not documented "
                                           "in FASTSim"})


# --------------------------------------------------------------------------------------------- distance domain

def cycle_position(cycle: DriveCycle) -> np.ndarray:
    """Position s(t) [m] along the cycle: trapezoidal integral of the speed, s(t0) = 0."""
    steps = 0.5 * (cycle.speed[1:] + cycle.speed[:-1]) * np.diff(cycle.time)
    return np.concatenate([[0.0], np.cumsum(steps)])


def speed_at_position(cycle: DriveCycle, position) -> np.ndarray:
    """The speed [m/s] the cycle drives at position(s) s [m].

    While the cycle stands, s does not advance, so the trace is indexed by its strictly increasing positions only;
    a standstill position gives the arrival speed 0. Positions beyond the end give the last speed.
    """
    s = cycle_position(cycle)
    moving = np.concatenate([[True], np.diff(s) > 1e-9])
    return np.interp(np.asarray(position, dtype=float), s[moving], cycle.speed[moving])


def cycle_stops(cycle: DriveCycle, min_duration: float = 1.0) -> np.ndarray:
    """Positions [m] where the cycle stands still (speed < 0.1 m/s) for at least ``min_duration`` [s], excluding
    the start; one entry per standstill."""
    s = cycle_position(cycle)
    still = cycle.speed < 0.1
    stops = []
    i = 0
    while i < still.size:
        if still[i]:
            j = i
            while j + 1 < still.size and still[j + 1]:
                j += 1
            if cycle.time[j] - cycle.time[i] >= min_duration - 1e-9 and s[i] > 1.0:
                stops.append(s[i])
            i = j + 1
        else:
            i += 1
    return np.asarray(stops)


def cycle_to_profile(cycle: DriveCycle, step: float = 5.0, min_speed_limit: float = 1.0) -> RoadProfile:
    """The cycle in the distance domain as a RoadProfile on a ``step`` [m] grid.

    grade: the cycle's grade at each position (0 without grade); curvature and bank: 0; speed_limit: the speed
    the cycle drives there (``speed_at_position``), at least ``min_speed_limit`` [m/s] because a limit must be
    positive; stops: ``cycle_stops``. Useful for graded cycles (the 805 km truck cycle) and for a driver that
    follows a cycle by position.
    """
    s = cycle_position(cycle)
    moving = np.concatenate([[True], np.diff(s) > 1e-9])
    n = max(int(round(s[-1] / step)) + 1, 2)
    grid = np.linspace(0.0, s[-1], n)
    grade = np.interp(grid, s[moving], cycle.grade[moving]) if cycle.grade is not None else np.zeros(n)
    limit = np.maximum(speed_at_position(cycle, grid), min_speed_limit)
    meta = {**cycle.meta, "derived_from_cycle": cycle.name,
            "speed_limit_meaning": "speed driven by the cycle at this position (not a posted limit)"}
    return RoadProfile(name=f"{cycle.name}_by_distance", distance=grid, grade=grade, curvature=np.zeros(n),
                       bank=np.zeros(n), speed_limit=limit, stops=cycle_stops(cycle), meta=meta)
