"""Is the diagnosis unchanged? A fixed set of diagnoses on the selftest worlds (roadload's simulator, the
independent model, FASTSim), written as one JSON document and compared value by value with a reference written
before a change. Covers the matched sims, a shipped preset with the base calibrated first (joint refit), the energy
side, the re-simulation and the replay through the simulator.

    python scripts/sim2real_identity.py --write out/identity_ref.json     # before the change
    python scripts/sim2real_identity.py --check out/identity_ref.json     # after: exit 1 on any difference
"""

from __future__ import annotations

import json
import tempfile
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from roadload.experiments.worlds import generate_case
from roadload.sim2real.diagnose import DiagnosisSettings, diagnose, sim_trips
from roadload.sim2real.simconfig import SimConfig

ROADS: tuple[tuple[str, int], ...] = (("hilly", 11), ("city", 12), ("motorway", 13))


@dataclass(frozen=True)
class IdentityCase:
    """One diagnosis of the check: ``world`` (roadload | independent | fastsim), the withheld effect (a world
    effect name; for roadload a simulator switch with its parameters), the sim (None: matched to the world) and
    whether the base is calibrated first."""

    world: str
    withheld: str
    preset: str | None = None
    base_first: bool = False
    resimulate: bool = False
    switch: str = ""
    params: tuple[tuple[str, float], ...] = ()

    @property
    def label(self) -> str:
        sim = self.preset or "matched"
        return f"{self.world}/{self.withheld}/{sim}{'/base-first' if self.base_first else ''}"


CASES: tuple[IdentityCase, ...] = (
    IdentityCase("roadload", "payload", resimulate=True, switch="payload",
                 params=(("initial_payload", 200.0), ("change_std", 0.0))),
    IdentityCase("roadload", "auxiliary_load", switch="auxiliary_load", params=(("power", 1500.0),)),
    IdentityCase("independent", "wind"),
    IdentityCase("independent", "none", preset="bmw_i3", base_first=True),
    IdentityCase("fastsim", "payload"),
    IdentityCase("fastsim", "torque_latency", preset="bmw_i3", base_first=True),
)


def settings_for(case: IdentityCase, duration: float) -> DiagnosisSettings:
    """Small but complete settings: re-simulation and replay where the case asks for them."""
    return DiagnosisSettings(floor_duration=duration, n_boot=60, n_null=99, base_first=case.base_first,
                             resimulate=case.resimulate, replay=case.resimulate)


def _trips_and_sim(case: IdentityCase, duration: float, work: Path) -> tuple[list, SimConfig]:
    if case.world == "roadload":
        sim = SimConfig.load(case.preset or "bmw_i3")
        real_sim = sim.with_effect(case.switch, dict(case.params)) if case.switch else sim
        return sim_trips(real_sim, ROADS, duration), sim
    gen = generate_case(case.world, case.withheld, 0, n_trips=3, duration_s=duration, out_dir=work / case.world)
    return gen.import_trips(), SimConfig.load(case.preset or gen.sim_path)


def diagnoses(duration: float = 300.0, cases: tuple[IdentityCase, ...] = CASES,
              say: Callable[[str], None] | None = None) -> dict[str, Any]:
    """{case label: diagnosis JSON document (``Diagnosis.to_dict``)} of every case."""
    out: dict[str, Any] = {}
    with tempfile.TemporaryDirectory(prefix="s2r-identity-") as tmp:
        for case in cases:
            trips, sim = _trips_and_sim(case, duration, Path(tmp))
            diag = diagnose(trips, sim, settings_for(case, duration))
            out[case.label] = json.loads(json.dumps(diag.to_dict()))
            if say:
                say(f"{case.label}: identified {diag.identified}")
    return out


ADDED = "only in the current document"


def differences(reference: Any, current: Any, path: str = "") -> Iterator[str]:
    """Every place where two JSON documents differ (exact comparison: the refactoring must not move a bit); a
    key the current document adds is reported as ``<path>: only in the current document`` (:data:`ADDED`)."""
    if isinstance(reference, dict) and isinstance(current, dict):
        for key in sorted(set(reference) | set(current)):
            if key not in reference:
                yield f"{path}/{key}: {ADDED}"
            elif key not in current:
                yield f"{path}/{key}: only in the reference document"
            else:
                yield from differences(reference[key], current[key], f"{path}/{key}")
    elif isinstance(reference, list) and isinstance(current, list):
        if len(reference) != len(current):
            yield f"{path}: {len(reference)} entries in the reference, {len(current)} now"
        for i, (a, b) in enumerate(zip(reference, current)):
            yield from differences(a, b, f"{path}[{i}]")
    elif reference != current:
        yield f"{path}: {reference!r} in the reference, {current!r} now"
