"""One entry point for both worlds: :func:`generate_case` writes a case's trip CSVs, mapping JSON, matched vehicle
JSON (plus a sim config ``<world>_sim.json`` pointing at it, for ``roadload diagnose --sim``) and truth JSON into
``out_dir`` and returns the :class:`~.common.WorldCase`."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
from roadload.fileio import write_json

from . import fastsim_world, independent
from .common import NONE, ROADS, Column, Withheld, WorldCase, WorldError, write_mapping

WORLDS: dict[str, Any] = {"fastsim": fastsim_world.BEV, "fastsim_conv": fastsim_world.CONV, "independent": independent}


def world_module(world: str):
    if world not in WORLDS:
        raise WorldError(f"unknown world {world!r}; worlds: {sorted(WORLDS)}")
    return WORLDS[world]


def supported_effects(world: str) -> dict[str, Withheld]:
    """The withheld options of a world (name -> :class:`~.common.Withheld`), incl. the out-of-catalog effect
    and "none"."""
    return dict(world_module(world).EFFECTS)


def not_expressible(world: str) -> dict[str, str]:
    """Effects of the user's ten that the world cannot express, with the reason."""
    return dict(world_module(world).NOT_EXPRESSIBLE)


def _mapping_columns(world: str) -> tuple[Column, ...]:
    return world_module(world).COLUMNS


def generate_case(world: str, withheld: str | None, seed: int, n_trips: int = 3, duration_s: float = 900.0,
                  out_dir: Path | str = Path("worlds-out")) -> WorldCase:
    """Trips of ``world`` with ``withheld`` (None or "none": nothing withheld) on roadload's roads
    hilly/city/motorway (road seed 100 seed + i), written as the world's logger writes them."""
    mod = world_module(world)
    withheld = withheld or NONE
    if withheld not in mod.EFFECTS:
        why = mod.NOT_EXPRESSIBLE.get(withheld)
        raise WorldError(f"world {world!r} cannot withhold {withheld!r}"
                         + (f": {why}" if why else f"; it supports {sorted(mod.EFFECTS)}"))
    if not (isinstance(n_trips, int) and n_trips >= 1):
        raise WorldError(f"n_trips must be an integer >= 1, got {n_trips!r}")
    if not duration_s >= 60.0:
        raise WorldError(f"duration_s must be at least 60 s (the diagnosis splits trips into 60 s segments), "
                         f"got {duration_s!r} s")
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    paths = []
    for i in range(n_trips):
        road_name = ROADS[i % len(ROADS)]
        road_seed = 100 * seed + i
        rng = np.random.default_rng([seed, i])
        trip = mod.simulate_trip(road_name, road_seed, rng, duration_s, withheld)
        paths.append(mod.write_trip(out / f"{world}-{withheld}-s{seed}-{road_name}{i}.csv", trip))
    mapping = write_mapping(out / f"{world}_mapping.json", f"{world}_logger", mod.COLUMNS, mod.TIME_HEADER,
                            f"logger of the {world} test world (own column names and units)",
                            extra=getattr(mod, "MAPPING_EXTRA", None))
    vehicle = mod.matched_vehicle()
    vpath = write_json(out / f"{world}_vehicle.json", vehicle.to_dict())
    # `roadload diagnose --sim` takes a sim config (a bare vehicle spec JSON is rejected): one next to it
    # with the world's nominal ambient temperature: the sim's own trips (its floor) then see the world's air density
    write_json(out / f"{world}_sim.json", {"vehicle": vpath.name, "name": f"{world} world, matched vehicle",
                                          "effects": {"effects": {}, "ambient_temperature": mod.NOMINAL_AMBIENT}})
    w = mod.EFFECTS[withheld]
    truth = {"world": world, "withheld": withheld, "accepted": list(w.accepted), "parameters": w.params,
             "description": w.description, "seed": seed, "duration_s": duration_s,
             "roads": [[ROADS[i % len(ROADS)], 100 * seed + i] for i in range(n_trips)]}
    write_json(out / f"{world}-{withheld}-s{seed}-truth.json", truth)
    return WorldCase(world, withheld, seed, paths, mapping, vpath, truth, out)
