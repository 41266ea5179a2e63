"""Profiles by name: ``load_profile("hilly", seed=3)``, ``load_profile("wltc3")``, ``load_profile("route.gpx")``.

Built-in names: the seeded generators (hilly, motorway, city), the drive cycles (wltc3 = wltc3b, wltc3a, WLTC
phases, udds, ftp75, hwfet, us06, tsdc_300s, longhaul_truck -> DriveCycle), and -- read from the shared data
folder when present -- GradeIT GPS routes, race tracks and Singapore bus routes. Other code adds names with
``register_profile`` (any factory) or ``register_profile_file`` / ``register_profile_folder`` (saved files).
"""

from __future__ import annotations

import inspect
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

from roadload.registry import Registry, did_you_mean

from . import cycles, generate, real_routes
from .files import load_profile_file
from .profile import DriveCycle, RoadProfile, RoadProfileError

Factory = Callable[..., RoadProfile | DriveCycle]


class UnknownProfileError(RoadProfileError, KeyError):
    """No profile of that name is registered and no such file exists; the message lists the known names."""

    def __str__(self) -> str:  # KeyError would quote the message
        return str(self.args[0])


@dataclass(frozen=True)
class ProfileEntry:
    name: str
    factory: Factory
    description: str
    kind: str  # "road" (RoadProfile) or "cycle" (DriveCycle)
    seeded: bool  # the factory takes ``seed``
    keeps: bool = False  # the factory takes ``keep`` (builds only the start of its road, load_profile_start)


_REGISTRY: Registry[ProfileEntry] = Registry("road profile", ProfileEntry, ValueError, normalise=str.lower)
_SUFFIXES = (".json", ".csv", ".gpx")


def register_profile(name: str, factory: Factory, *, description: str = "", kind: str = "road",
                     overwrite: bool = False) -> None:
    """Register ``factory(**kw)`` under ``name`` (case-insensitive). It is seeded if it accepts ``seed``.

    A second registration of a name raises unless ``overwrite``.
    """
    key = name.lower()
    if not key or any(key.endswith(s) for s in _SUFFIXES) or os.sep in key:
        raise ValueError(f"profile name {name!r}: must be non-empty and not look like a file path")
    if kind not in ("road", "cycle"):
        raise ValueError(f"kind must be 'road' or 'cycle', got {kind!r}")
    parameters = inspect.signature(factory).parameters
    _REGISTRY.register(key, ProfileEntry(key, factory, description, kind, "seed" in parameters, "keep" in parameters),
                       replace_existing=overwrite)


def register_profile_file(name: str, path: str | os.PathLike, *, description: str = "",
                          overwrite: bool = False) -> None:
    """Register a saved profile file (.json/.csv/.gpx) under ``name``; it is read when loaded."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"profile file {path} does not exist")
    kind = "road"
    if path.suffix.lower() in (".json", ".csv"):
        kind = "cycle" if "roadload.drive_cycle" in path.open(encoding="utf-8-sig").read(200) else "road"
    register_profile(name, lambda **kw: load_profile_file(path, **kw), description=description or f"file {path}",
                     kind=kind, overwrite=overwrite)


def register_profile_folder(folder: str | os.PathLike, *, prefix: str = "", overwrite: bool = False) -> list[str]:
    """Register every .json/.csv/.gpx file in ``folder`` as ``prefix + file stem``; returns the names."""
    folder = Path(folder)
    if not folder.is_dir():
        raise FileNotFoundError(f"profile folder {folder} does not exist")
    names = []
    for path in sorted(folder.iterdir()):
        if path.suffix.lower() in _SUFFIXES and path.is_file():
            register_profile_file(prefix + path.stem, path, overwrite=overwrite)
            names.append((prefix + path.stem).lower())
    return names


def known_profiles(kind: str | None = None) -> dict[str, str]:
    """Registered names -> description (optionally only kind "road" or "cycle")."""
    return {k: e.description for k, e in sorted(_REGISTRY.items()) if kind is None or e.kind == kind}


def load_profile(name_or_path: str | os.PathLike, seed: int = 0, **kw) -> RoadProfile | DriveCycle:
    """A profile by registered name (seeded generators get ``seed``) or from a .json/.csv/.gpx file path.

    Keyword arguments go to the factory (e.g. ``length=`` for generators, ``laps=`` for race tracks) or to the
    file loader (e.g. column names for a track CSV). Unknown name -> UnknownProfileError listing the names.
    """
    text = os.fspath(name_or_path)
    entry = _REGISTRY.find(text)
    if entry is not None:
        return entry.factory(seed=seed, **kw) if entry.seeded else entry.factory(**kw)
    path = Path(text)
    if path.suffix.lower() in _SUFFIXES or path.exists():
        return load_profile_file(path, **kw)
    names = known_profiles()
    raise UnknownProfileError(f"unknown road profile {text!r}{did_you_mean(text, names)}: not a registered name and "
                              f"not a .json/.csv/.gpx file; known names ({len(names)}, with descriptions: roadload "
                              f"profiles list): {', '.join(names)}")


def load_profile_start(name_or_path: str | os.PathLike, length: float | None, seed: int = 0
                       ) -> RoadProfile | DriveCycle:
    """``load_profile(name_or_path, seed=seed)`` when only its first ``length`` [m] will be used (None: all of it):
    a registered generator that takes ``keep`` builds just that part (and one grid step more), bit for bit the
    whole road's; any other profile is loaded whole. Cut it to ``length`` afterwards as needed."""
    entry = _REGISTRY.find(os.fspath(name_or_path))
    if length is not None and entry is not None and entry.keeps:
        return entry.factory(seed=seed, keep=length) if entry.seeded else entry.factory(keep=length)
    return load_profile(name_or_path, seed=seed)


def _register_builtins() -> None:
    for name, gen in generate.GENERATORS.items():
        register_profile(name, gen, description=(gen.__doc__ or "").strip().splitlines()[0])
    for name, (_, description) in cycles.STANDARD_CYCLES.items():
        register_profile(name, lambda _n=name: cycles.load_cycle(_n), description=description, kind="cycle")
    for alias, target in cycles.CYCLE_ALIASES.items():
        register_profile(alias, lambda _n=target: cycles.load_cycle(_n),
                         description=f"= {target}: {cycles.STANDARD_CYCLES[target][1]}", kind="cycle")
    register_profile("ftp75", cycles.ftp75, description="EPA FTP-75 = UDDS + hot-start UDDS 0-505 s: 1874 s, "
                     "17.77 km", kind="cycle")
    register_profile("tsdc_300s", cycles.tsdc_trip, description="real 300 s trip with grade (NREL TSDC)",
                     kind="cycle")
    register_profile("longhaul_truck", cycles.long_haul_truck, description="heavy-truck long-haul cycle with "
                     "grade, 805 km", kind="cycle")
    for name, file in real_routes.GRADEIT_TRIPS.items():
        register_profile(name, lambda _n=name, **kw: real_routes.gradeit_route(_n, **kw),
                         description=f"GradeIT GPS route {file} (curvature, no elevation), BSD-3")
    for track in real_routes.RACETRACKS:
        register_profile(f"racetrack_{track.lower()}", lambda _t=track, **kw: real_routes.racetrack(_t, **kw),
                         description=f"race circuit {track} centre line (curvature), LGPL-3.0")
    for name, route in real_routes.BUS_ROUTES.items():
        register_profile(name, lambda _n=name, **kw: real_routes.bus_route(_n, **kw),
                         description=f"Singapore bus {route}: speed limits, corners, stops, traffic lights, LGPL-3.0")
        register_profile(f"{name}_measured", lambda _n=name: real_routes.bus_route_measured(_n),
                         description=f"measured bus trip on {route} (speed vs time)", kind="cycle")


_register_builtins()
