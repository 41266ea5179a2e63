"""The "sim" of a diagnosis: a vehicle (preset name or spec file) plus the simulator effects it models.

A sim config file is JSON (a vehicle spec JSON is taken as that vehicle with no effects)::

    {"vehicle": "bmw_i3",                      # preset name, or a path to a vehicle spec JSON
     "effects": {"effects": {"wind": {"mean_speed": 2.0}}, "ambient_temperature": 293.15},   # EffectsConfig
     "name": "i3 as shipped",
     "held_at_bound": {"motor_loss_scale": -0.3}}  # written by `roadload calibrate` (roadload.sim2real.held)

:meth:`SimConfig.with_effect` gives the sim with one more effect switched on (the "after" of a diagnosis).
"""

from __future__ import annotations

import copy
import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from pydantic import Field, ValidationError

from roadload.envs.effects import EffectsConfig, EffectsError
from roadload.schema import StrictModel, format_errors
from roadload.vehicle import VehicleSpec, VehicleSpecError, load_vehicle

from .errors import DiagnosisError
from roadload.presets import PRESETS, get_preset

_KEYS = {"vehicle", "effects", "name", "held_at_bound"}
VEHICLE_SPEC_KEYS = {"name", "body", "aero", "tires", "drivetrain"}     # an object with these is a vehicle spec


class SimConfigFile(StrictModel):
    """Schema of a sim config JSON (see the module docstring)."""

    vehicle: str | dict[str, Any] = Field(description="preset name, vehicle spec file or an inline spec object")
    effects: str | dict[str, Any] | None = Field(None, description="EffectsConfig: 'wind,payload' or its dict form")
    name: str = Field("", description="label used in reports")
    held_at_bound: dict[str, float] = Field(
        default_factory=dict, description="calibrated changes held at a bound of their physical range -> what the "
                                          "bound held back (the fitted change beyond it, in the change's unit)")


@dataclass
class SimConfig:
    """vehicle: a VehicleSpec; effects: the EffectsConfig the sim runs with; name: for reports; held_at_bound: the
    calibration's changes held at a bound of their range (:mod:`.held`; empty for a sim that is no calibration)."""

    vehicle: VehicleSpec
    effects: EffectsConfig = field(default_factory=EffectsConfig)
    name: str = ""
    held_at_bound: dict[str, float] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if not self.name:
            self.name = self.vehicle.name

    @classmethod
    def from_dict(cls, data: dict[str, Any], base: Path | None = None) -> "SimConfig":
        """From a sim config object, or a vehicle spec object (the sim is that vehicle with no effects: what
        ``roadload calibrate`` writes)."""
        if not isinstance(data, dict):
            raise DiagnosisError(f"sim config: expected a JSON object, got {type(data).__name__}")
        if VEHICLE_SPEC_KEYS <= set(data):
            return cls(load_sim_vehicle(data, base))
        unknown = set(data) - _KEYS
        if unknown:
            raise DiagnosisError(f"sim config: unknown keys {sorted(unknown)}; allowed: {sorted(_KEYS)}")
        if "vehicle" not in data:
            raise DiagnosisError("sim config: missing 'vehicle' (a preset name such as 'bmw_i3' or a spec file)")
        try:
            SimConfigFile.model_validate(data)
        except ValidationError as exc:
            raise DiagnosisError(f"sim config: {format_errors(exc, SimConfigFile)}") from None
        if isinstance(data["vehicle"], str) and not data["vehicle"].strip():
            raise DiagnosisError("sim config: vehicle: empty; expected a preset name such as 'bmw_i3' or a spec file")
        vehicle = load_sim_vehicle(data["vehicle"], base)
        try:
            effects = EffectsConfig.parse(data.get("effects"))
        except EffectsError as exc:
            raise DiagnosisError(f"sim config 'effects': {exc}") from None
        return cls(vehicle, effects, str(data.get("name", "")),
                   {str(k): float(v) for k, v in (data.get("held_at_bound") or {}).items()})

    @classmethod
    def load(cls, source: str | Path) -> "SimConfig":
        """From a JSON file, or a bare preset name ('bmw_i3')."""
        path = Path(source)
        if path.suffix.lower() != ".json":
            return cls(load_sim_vehicle(str(source), None))
        if not path.is_file():
            raise DiagnosisError(f"sim config file {path} does not exist")
        try:
            data = json.loads(path.read_text())
        except json.JSONDecodeError as exc:
            raise DiagnosisError(f"sim config {path}: not valid JSON ({exc})") from None
        return cls.from_dict(data, path.parent)

    def to_dict(self) -> dict[str, Any]:
        out = {"vehicle": self.vehicle.name, "effects": self.effects.to_dict(), "name": self.name}
        return {**out, "held_at_bound": dict(self.held_at_bound)} if self.held_at_bound else out

    def with_effect(self, effect: str, params: dict[str, Any]) -> "SimConfig":
        """A copy with ``effect`` switched on (or re-parameterised) with ``params``; ``spec:<dotted.path>``
        switches change that field of the vehicle spec instead (``{"delta": x}`` added, ``{"factor": f}``
        multiplied); ``params["spec_changes"]`` = {path: change} changes further spec fields along with it."""
        params = dict(params)
        vehicle = self.vehicle
        for path, change in (params.pop("spec_changes", None) or {}).items():
            vehicle = with_spec_change(vehicle, path, change)
        if effect.startswith("spec:"):
            return SimConfig(with_spec_change(vehicle, effect[5:], params),
                             EffectsConfig.parse(self.effects), f"{self.name} + {effect}", dict(self.held_at_bound))
        eff = EffectsConfig.parse(self.effects)
        try:
            eff.enable(effect, **params)
        except EffectsError as exc:
            raise DiagnosisError(f"cannot switch on {effect!r} in the sim: {exc}") from None
        return SimConfig(vehicle, eff, f"{self.name} + {effect}", dict(self.held_at_bound))


def load_sim_vehicle(vehicle: str | dict, base: Path | None) -> VehicleSpec:
    """A preset name, a spec file (relative to ``base``) or a spec dict -> VehicleSpec (DiagnosisError otherwise)."""

    try:
        if isinstance(vehicle, dict):
            return VehicleSpec.from_dict(vehicle)
        if vehicle in PRESETS:
            return get_preset(vehicle)
        path = Path(vehicle)
        if base is not None and not path.is_absolute():
            path = base / path
        if path.is_file():
            return load_vehicle(path)
    except VehicleSpecError as exc:
        raise DiagnosisError(f"sim config vehicle: {exc}") from None
    raise DiagnosisError(f"sim config vehicle {vehicle!r} is neither a preset ({list(PRESETS)}) nor a spec file")


def with_spec_change(vehicle: VehicleSpec, path: str, params: dict[str, Any]) -> VehicleSpec:
    """A copy of ``vehicle`` with the field at ``path`` (attributes and dict keys, dotted) changed by
    ``params``: {"delta": x} adds x, {"factor": f} multiplies by f."""
    if set(params) not in ({"delta"}, {"factor"}):
        raise DiagnosisError(f"spec switch {path!r} takes {{'delta': x}} or {{'factor': f}}, got {params}")
    spec = copy.deepcopy(vehicle)
    parts = path.split(".")
    obj: Any = spec  # walks attributes and dict keys
    for part in parts[:-1]:
        obj = obj[part] if isinstance(obj, dict) else getattr(obj, part, None)
        if obj is None:
            raise DiagnosisError(f"vehicle spec has no field {path!r} (stopped at {part!r})")
    last = parts[-1]
    if not hasattr(obj, last):
        raise DiagnosisError(f"vehicle spec has no field {path!r}")
    old = float(getattr(obj, last))
    setattr(obj, last, old + float(params["delta"]) if "delta" in params else old * float(params["factor"]))
    try:
        spec.validate()
    except VehicleSpecError as exc:
        raise DiagnosisError(f"switching {path} by {params}: {exc}") from None
    return spec
