"""Typed, validated configuration of the gymnasium environments (EcoDrive-v0, EcoHighway-v0).

Unlike highway-env's untyped dicts, an unknown key or an out-of-range value raises :class:`GymConfigError`
(a ``ValueError``) naming the field, at construction and not mid-episode. Units are SI; the field
descriptions carry them.
"""

from __future__ import annotations

from typing import Any, Literal

from pydantic import BaseModel, ConfigDict, Field, ValidationError, field_validator, model_validator
from roadload.presets import PRESETS
from roadload.road_profiles import known_profiles
from roadload.envs.effects import EffectsConfig

PHYSICS_RATE = 100.0
"""Rate of the simulator's physics [Hz]; control periods must be whole multiples of its step."""


class GymConfigError(ValueError):
    """A gym environment configuration is invalid; the message names the field and what is wrong."""


class _Strict(BaseModel):
    # allow_inf_nan=False: every float option (tuples and the reward weights included) must be finite; NaN passes
    # no range check and inf passes every lower bound
    model_config = ConfigDict(extra="forbid", frozen=True, validate_default=True, allow_inf_nan=False)


def _check_vehicle(name: str) -> str:

    if name not in PRESETS:
        raise ValueError(f"unknown vehicle preset {name!r}; presets: {sorted(PRESETS)}")
    return name


def _check_road(name: str | None) -> str | None:
    if name is None:
        return None
    from pathlib import Path


    if name.lower() in known_profiles("road"):
        return name
    if name.lower() in known_profiles("cycle"):
        raise ValueError(f"{name!r} is a drive cycle (speed over time), not a road profile")
    if Path(name).is_file():
        return name
    raise ValueError(f"unknown road profile {name!r}; road profiles: {', '.join(known_profiles('road'))}")


def _check_effects(effects: Any) -> Any:

    EffectsConfig.parse(effects)  # raises EffectsError (a ValueError) naming the effect / parameter
    return effects


class EcoDriveReward(_Strict):
    """Weights of the EcoDrive reward r = -scale * (energy + time * dt + speeding * (v - v_lim)+ * dt
    + lateral * (|a_y| - a_y,max)+ * dt + stop * [stop passed too fast] + jerk * jerk^2 * dt - progress * ds).

    Every weight converts its term into joule-equivalents, so the raw terms reported in ``info`` can be
    re-weighted by the user. The progress term is potential-based shaping with potential -progress * (remaining
    distance): over an arrived episode it adds the constant progress * route length (so it does not change which
    arrival is best), and a truncated episode pays progress * (distance left); without it a policy that stands
    still until the time limit out-scores careless driving early in training.
    """

    energy: float = Field(1.0, ge=0, description="weight of the source energy [1 per J] (battery or fuel)")
    time: float = Field(3000.0, ge=0, description="value of time [J/s] (the MPC's default time weight)")
    speeding: float = Field(2000.0, ge=0, description="penalty per m/s above the speed limit per second [J s/m / s]")
    lateral: float = Field(2000.0, ge=0, description="penalty per m/s^2 above the lateral-acceleration limit per s")
    stop: float = Field(2.0e5, ge=0, description="penalty for passing a stop line faster than stop_speed [J]")
    jerk: float = Field(1.0, ge=0, description="penalty per (m/s^3)^2 per second [J s^5/m^2 / s]")
    progress: float = Field(3000.0, ge=0, description="credit per metre driven along the route [J/m] "
                                                      "(potential-based shaping, see above); above the energy per "
                                                      "metre of a steep climb (~1.2 kJ/m for 1.4 t at 6 %)")
    scale: float = Field(1e-4, gt=0, description="reward units per joule-equivalent [1/J]")


class EcoDriveConfig(_Strict):
    """Configuration of ``roadload/EcoDrive-v0``: one vehicle preset driving a road profile with preview."""

    vehicle: str = Field("bmw_i3", description="vehicle preset name (roadload.presets)")
    road: str = Field("hilly", description="road profile name (roadload.road_profiles.load_profile)")
    road_seed: int | None = Field(None, ge=0, description="road generator seed; None draws one per episode from "
                                                          "road_seed_range with the env's RNG")
    road_seed_range: tuple[int, int] = Field((0, 10_000), description="[low, high) of drawn road seeds; evaluate "
                                                                       "on seeds outside it (held-out roads)")
    route_length: float | None = Field(2000.0, gt=0, le=1e6, description="drive only the first route_length "
                                                                         "metres of the profile [m]; None = all")
    effects: dict[str, dict[str, Any]] | list[str] = Field(default_factory=dict, description="simulator effects "
                                                           "(roadload.envs.effects), e.g. {'wind': {'mean_speed': 5}}")
    observation: Literal["state", "can", "can+estimates"] = "state"
    estimator: str = Field("RRLM", description="estimator name for observation='can+estimates'")
    preview_distances: tuple[float, ...] = Field((25.0, 50.0, 100.0, 200.0, 400.0),
                                                 description="look-ahead distances of the road preview [m]")
    control_period: float = Field(0.1, gt=0, le=1.0, description="time per env step [s]; physics runs at 100 Hz")
    time_limit: float | None = Field(None, gt=0, description="truncate after this time [s]; None = 2 x the "
                                                             "schedule's time + 30 s")
    schedule_speed_fraction: float = Field(0.9, gt=0, le=1.2, description="schedule speed as a fraction of the "
                                                                          "speed limit (curve speed caps it)")
    lateral_acceleration_limit: float = Field(2.0, gt=0, le=12.0, description="comfort limit of |a_y| [m/s^2] "
                                                                             "(as the controllers' curve cap)")
    stop_speed: float = Field(1.0, gt=0, le=5.0, description="max speed when crossing a stop line [m/s]")
    initial_speed: float = Field(0.0, ge=0, le=60.0, description="speed at reset [m/s]")
    obs_scaling: Literal["normalized", "si"] = Field("normalized", description="'si': raw SI values; "
                                                     "'normalized': SI value / documented scale")
    speed_shield: bool = Field(False, description="cap the command so that the speed stays under the speed-limit "
                                                  "braking envelope (roadload.gym.ecodrive.shield_command)")
    shield_margin: float = Field(0.5, ge=0, le=5.0, description="the shield keeps this far below the limit [m/s]")
    shield_deceleration: float = Field(1.0, gt=0, le=4.0, description="deceleration of the shield's braking "
                                                                      "envelope ahead of a lower limit [m/s^2]")
    reward: EcoDriveReward = Field(default_factory=EcoDriveReward)

    _vehicle = field_validator("vehicle")(classmethod(lambda cls, v: _check_vehicle(v)))
    _road = field_validator("road")(classmethod(lambda cls, v: _check_road(v)))
    _effects = field_validator("effects")(classmethod(lambda cls, v: _check_effects(v)))

    @field_validator("preview_distances")
    @classmethod
    def _preview(cls, v: tuple[float, ...]) -> tuple[float, ...]:
        if not v:
            raise ValueError("needs at least one distance")
        if any(d <= 0 or d > 5000 for d in v):
            raise ValueError("every distance must be in (0, 5000] m")
        if any(b <= a for a, b in zip(v, v[1:])):
            raise ValueError("distances must be strictly increasing")
        return v

    @field_validator("road_seed_range")
    @classmethod
    def _seed_range(cls, v: tuple[int, int]) -> tuple[int, int]:
        if v[0] < 0 or v[1] <= v[0]:
            raise ValueError(f"needs 0 <= low < high, got {v}")
        return v

    @field_validator("control_period")
    @classmethod
    def _period(cls, v: float) -> float:
        n = v * PHYSICS_RATE
        if abs(n - round(n)) > 1e-9 or round(n) < 1:
            raise ValueError(f"{v} s is not a whole multiple of the physics step {1 / PHYSICS_RATE} s")
        return v

    @property
    def n_substeps(self) -> int:
        """Physics steps per env step."""
        return int(round(self.control_period * PHYSICS_RATE))


SPACE_FIELDS_ECODRIVE = ("observation", "preview_distances", "obs_scaling", "estimator")
"""Fields that shape the observation space; reset options may not change them."""


class EcoHighwayReward(_Strict):
    """Weights of the EcoHighway reward r = scale * (progress * dx - energy * E + mechanical_energy * dM
    - collision * [crash] - headway * (h_min - h)+ * dt - jerk * jerk^2 * dt - lane_change * [lane change]),
    dM the change of the ego's mechanical energy (kinetic 0.5 m v^2 + potential m g h) over the step: summed over
    an episode it is the mechanical energy left at the end minus the initial one, so speed and height left at the
    cutoff keep their battery-equivalent value and braking to recover the start's kinetic energy no longer pays."""

    progress: float = Field(1000.0, ge=0, description="reward per metre travelled [J/m equivalent]")
    energy: float = Field(1.0, ge=0, description="weight of the source energy [1 per J]")
    mechanical_energy: float = Field(0.9, ge=0, description="credit per J of change of the ego's mechanical "
                                     "energy (0.5 m v^2 + m g h): its battery-equivalent value [1 per J]; 0.9 = the "
                                     "source energy bmw_i3 regenerates per J of kinetic energy less road losses "
                                     "(measured 0.84-0.91 braking from 25 m/s); 0 = the first reward, which paid "
                                     "for braking down before the cutoff")
    collision: float = Field(1.0e6, ge=0, description="penalty of a collision [J]")
    headway: float = Field(2.0e4, ge=0, description="penalty per second of time headway below the minimum, per s")
    jerk: float = Field(20.0, ge=0, description="penalty per (m/s^3)^2 per second")
    lane_change: float = Field(2000.0, ge=0, description="penalty per commanded lane change [J]")
    scale: float = Field(1e-4, gt=0, description="reward units per joule-equivalent [1/J]")


class EcoHighwayConfig(_Strict):
    """Configuration of ``roadload/EcoHighway-v0``: highway-env traffic (IDM/MOBIL) around an ego vehicle whose
    longitudinal dynamics and energy come from roadload's simulator."""

    vehicle: str = Field("bmw_i3", description="ego vehicle preset name")
    road: str | None = Field("motorway", description="road profile giving the grade along the highway; "
                                                     "None = flat")
    road_seed: int | None = Field(None, ge=0, description="road generator seed; None draws one per episode")
    effects: dict[str, dict[str, Any]] | list[str] = Field(default_factory=dict, description="simulator effects "
                                                                                            "of the ego vehicle")
    lanes_count: int = Field(3, ge=1, le=6)
    vehicles_count: int = Field(20, ge=0, le=100, description="number of IDM/MOBIL traffic vehicles")
    vehicles_density: float = Field(1.0, gt=0, le=5.0)
    duration: float = Field(40.0, gt=0, le=3600, description="episode time limit [s]")
    policy_frequency: float = Field(2.0, gt=0, le=10.0, description="decisions per second [Hz]")
    simulation_frequency: float = Field(10.0, gt=0, le=100.0, description="traffic simulation rate [Hz]")
    initial_speed: float = Field(25.0, ge=0, le=40.0, description="ego speed at reset [m/s]")
    speed_limit: float = Field(30.0, gt=0, le=60.0, description="lane speed limit [m/s]")
    lane_changes: Literal["off", "dict", "box"] = Field(
        "off", description="'off': 1-D force; 'dict': Dict(force Box, lane_change Discrete(3)); 'box': 2-D Box, "
                           "second entry < -1/3 = left, > 1/3 = right")
    observed_vehicles: int = Field(5, ge=1, le=20, description="nearest traffic vehicles in the observation")
    min_time_headway: float = Field(1.0, ge=0, le=5.0, description="time headway below which a penalty applies [s]")
    screen_width: int = Field(600, ge=64, le=4096)
    screen_height: int = Field(150, ge=64, le=4096)
    reward: EcoHighwayReward = Field(default_factory=EcoHighwayReward)

    _vehicle = field_validator("vehicle")(classmethod(lambda cls, v: _check_vehicle(v)))
    _road = field_validator("road")(classmethod(lambda cls, v: _check_road(v)))
    _effects = field_validator("effects")(classmethod(lambda cls, v: _check_effects(v)))

    @model_validator(mode="after")
    def _rates(self) -> EcoHighwayConfig:
        ratio = self.simulation_frequency / self.policy_frequency
        if abs(ratio - round(ratio)) > 1e-9 or round(ratio) < 1:
            raise ValueError(f"simulation_frequency ({self.simulation_frequency} Hz) must be a whole multiple of "
                             f"policy_frequency ({self.policy_frequency} Hz)")
        sub = PHYSICS_RATE / self.simulation_frequency
        if abs(sub - round(sub)) > 1e-9:
            raise ValueError(f"simulation_frequency ({self.simulation_frequency} Hz) must divide the physics rate "
                             f"{PHYSICS_RATE} Hz")
        return self

    @property
    def frames_per_action(self) -> int:
        return int(round(self.simulation_frequency / self.policy_frequency))

    @property
    def n_substeps(self) -> int:
        """Physics steps per traffic-simulation frame."""
        return int(round(PHYSICS_RATE / self.simulation_frequency))


SPACE_FIELDS_HIGHWAY = ("lane_changes", "observed_vehicles")


def _number(x: float) -> str:
    return str(int(x)) if float(x).is_integer() else repr(float(x))


def _expected(cls: type[BaseModel], loc: tuple) -> str:
    """'; expected: <description with unit>, <bounds>' of the field at ``loc`` (nested models followed), or ''."""
    model: Any = cls
    info = None
    for part in loc:
        fields = getattr(model, "model_fields", None)
        if not isinstance(part, str) or fields is None or part not in fields:
            break
        info = fields[part]
        model = info.annotation
    if info is None:
        return ""
    ops = (("gt", ">"), ("ge", ">="), ("lt", "<"), ("le", "<="))
    bounds = [f"{op} {_number(getattr(m, key))}" for m in info.metadata for key, op in ops
              if getattr(m, key, None) is not None]
    text = ", ".join(x for x in [info.description or "", " and ".join(bounds)] if x)
    return f"; expected: {text}" if text else ""


def _format(exc: ValidationError, what: str, cls: type[BaseModel] | None = None) -> str:
    lines = []
    for err in exc.errors():
        loc = ".".join(str(p) for p in err["loc"]) or "(config)"
        if err["type"] == "extra_forbidden":
            lines.append(f"  {loc}: unknown key")
        else:
            got = err.get("input")
            got_s = "" if isinstance(got, dict) else f" (got {got!r})"
            hint = _expected(cls, tuple(err["loc"])) if cls is not None else ""
            lines.append(f"  {loc}: {err['msg']}{got_s}{hint}")
    return f"invalid {what} configuration:\n" + "\n".join(lines)


def make_config(cls: type[_Strict], base: _Strict | dict | None = None, **overrides: Any) -> Any:
    """Build a validated config of type ``cls`` from a config object or dict plus keyword overrides.

    Raises GymConfigError listing every unknown key and out-of-range value.
    """
    if isinstance(base, cls):
        data = base.model_dump()
    elif base is None:
        data = {}
    elif isinstance(base, dict):
        data = dict(base)
    else:
        raise GymConfigError(f"config must be a {cls.__name__} or a dict, got {type(base).__name__}")
    for key, value in overrides.items():
        if key == "reward" and isinstance(value, dict) and isinstance(data.get("reward"), dict):
            data["reward"] = {**data["reward"], **value}
        else:
            data[key] = value
    try:
        return cls.model_validate(data)
    except ValidationError as exc:
        raise GymConfigError(_format(exc, cls.__name__, cls)) from None


def updated_config(config: _Strict, options: dict[str, Any] | None, space_fields: tuple[str, ...]) -> Any:
    """A copy of ``config`` with the reset ``options`` applied; options that would change the spaces are
    refused (an env's spaces are fixed after construction)."""
    if not options:
        return config
    if not isinstance(options, dict):
        raise GymConfigError(f"reset options must be a dict, got {type(options).__name__}")
    frozen = [k for k in options if k in space_fields and options[k] != getattr(config, k, object())]
    if frozen:
        raise GymConfigError(f"reset options {frozen} would change the observation/action space; "
                             f"make a new env instead")
    return make_config(type(config), config, **options)
