"""The channel catalogue: one place that names every Trip channel, its SI unit and meaning.

Measured channels are what a vehicle's CAN bus (or a logger) delivers; truth channels exist only
for simulated trips and are stored apart so no estimator reads them by accident.
Importers and the simulator must use these names; unknown names are allowed (extra signals) but
must carry a unit. The catalogue itself is the table ``channels.csv`` next to this module (an open
format: columns kind = measured or truth, name, SI unit, description). Measured rows from ``grade`` on are
derived or logger channels of real logs (roadload.io); truth rows from ``rolling_resistance_f0`` on are simulator
truth beyond the lumped parameters (roadload.envs).
"""

from __future__ import annotations

import csv
import io
from dataclasses import dataclass
from importlib import resources


@dataclass(frozen=True)
class Channel:
    name: str
    unit: str
    description: str


def _read_catalogue() -> dict[str, list[Channel]]:
    """The channels of ``channels.csv`` (columns kind, name, unit, description), by kind, in file order."""
    text = resources.files("roadload").joinpath("channels.csv").read_text(encoding="utf-8")
    out: dict[str, list[Channel]] = {"measured": [], "truth": []}
    for row in csv.DictReader(io.StringIO(text)):
        out[row["kind"]].append(Channel(row["name"], row["unit"], row["description"]))
    return out


_CATALOGUE = _read_catalogue()
_MEASURED = _CATALOGUE["measured"]
_TRUTH = _CATALOGUE["truth"]

MEASURED: dict[str, Channel] = {c.name: c for c in _MEASURED}
TRUTH: dict[str, Channel] = {c.name: c for c in _TRUTH}


def unit_of(name: str, truth: bool = False) -> str | None:
    """SI unit of a catalogued channel, or None for a channel the catalogue does not know."""
    table = TRUTH if truth else MEASURED
    return table[name].unit if name in table else None
