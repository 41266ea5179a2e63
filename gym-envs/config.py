"""Typed, validated configuration of the gymnasium environments (EcoDrive-v0, EcoHighway-v0, EcoTraffic-v0).

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


def _check_seed_range(v: tuple[int, int]) -> tuple[int, int]:
    if v[0] < 0 or v[1] <= v[0]:
        raise ValueError(f"needs 0 <= low < high, got {v}")
    return v


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

    _seed_range = field_validator("road_seed_range")(classmethod(lambda cls, v: _check_seed_range(v)))

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


class _TrafficScenario(_Strict):
    """The multi-lane traffic scenario EcoHighway-v0 and EcoTraffic-v0 share: an ego vehicle preset on a road
    profile among IDM/MOBIL traffic, with highway-env's lanes, spawn density, rates and EcoHighway-v0's reward."""

    vehicle: str = Field("bmw_i3", description="ego vehicle preset name")
    road: str | None = Field("motorway", description="road profile under the ego (its grade; EcoTraffic-v0 also "
                                                     "its curvature); None = flat")
    road_seed: int | None = Field(None, ge=0, description="road generator seed; None draws one per episode")
    effects: dict[str, dict[str, Any]] | list[str] = Field(default_factory=dict, description="simulator effects "
                                                                                            "of the ego vehicle")
    lanes_count: int = Field(3, ge=1, le=6)
    vehicles_count: int = Field(20, ge=0, le=100, description="number of IDM/MOBIL traffic vehicles")
    vehicles_density: float = Field(1.0, gt=0, le=5.0, description="spawn density (spacing = 1 / density x "
                                                                   "highway-env's default spacing)")
    duration: float = Field(40.0, gt=0, le=3600, description="episode time limit [s]")
    policy_frequency: float = Field(2.0, gt=0, le=10.0, description="decisions per second [Hz]")
    simulation_frequency: float = Field(10.0, gt=0, le=100.0, description="traffic simulation rate [Hz]")
    initial_speed: float = Field(25.0, ge=0, le=40.0, description="ego speed at reset [m/s]")
    speed_limit: float = Field(30.0, gt=0, le=60.0, description="lane speed limit [m/s]")
    min_time_headway: float = Field(1.0, ge=0, le=5.0, description="time headway below which a penalty applies [s]")
    reward: EcoHighwayReward = Field(default_factory=EcoHighwayReward)

    _vehicle = field_validator("vehicle")(classmethod(lambda cls, v: _check_vehicle(v)))
    _road = field_validator("road")(classmethod(lambda cls, v: _check_road(v)))
    _effects = field_validator("effects")(classmethod(lambda cls, v: _check_effects(v)))

    @model_validator(mode="after")
    def _rates(self) -> "_TrafficScenario":
        ratio = self.simulation_frequency / self.policy_frequency
        if not ratio <= 1e6 or abs(ratio - round(ratio)) > 1e-9 or round(ratio) < 1:  # not <=: inf (a tiny rate)
            raise ValueError(f"simulation_frequency ({self.simulation_frequency} Hz) must be a whole multiple of "
                             f"policy_frequency ({self.policy_frequency} Hz)")
        sub = PHYSICS_RATE / self.simulation_frequency
        if abs(sub - round(sub)) > 1e-9:
            raise ValueError(f"simulation_frequency ({self.simulation_frequency} Hz) must divide the physics rate "
                             f"{PHYSICS_RATE} Hz")
        return self

    @property
    def frames_per_action(self) -> int:
        """Traffic frames per env step."""
        return int(round(self.simulation_frequency / self.policy_frequency))

    @property
    def n_substeps(self) -> int:
        """Physics steps per traffic-simulation frame."""
        return int(round(PHYSICS_RATE / self.simulation_frequency))


class EcoHighwayConfig(_TrafficScenario):
    """Configuration of ``roadload/EcoHighway-v0``: highway-env traffic (IDM/MOBIL) around an ego vehicle whose
    longitudinal dynamics and energy come from roadload's simulator."""

    lane_changes: Literal["off", "dict", "box"] = Field(
        "off", description="'off': 1-D force; 'dict': Dict(force Box, lane_change Discrete(3)); 'box': 2-D Box, "
                           "second entry < -1/3 = left, > 1/3 = right")
    observed_vehicles: int = Field(5, ge=1, le=20, description="nearest traffic vehicles in the observation")
    screen_width: int = Field(600, ge=64, le=4096)
    screen_height: int = Field(150, ge=64, le=4096)


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


class TrafficBehaviour(_Strict):
    """The traffic vehicles' driver models, with highway-env 1.x's ``IDMVehicle`` constants as defaults.

    Longitudinal, IDM (Treiber, Hennecke & Helbing 2000): a = a_c (1 - (v / v_0)^delta - (d* / d)^2) with
    d* = d_0 + v T + v dv / (2 sqrt(a_c b)), d the centre-to-centre distance to the leader (as highway-env, whose
    d_0 = 5 m + one vehicle length), clipped to [-a_max, a_max]. Lateral, MOBIL (Kesting, Treiber & Helbing 2007):
    change when the own acceleration gain plus politeness x the followers' gains exceeds the threshold and the new
    follower brakes less than the safe limit; decided at most once per ``lane_change_delay``."""

    max_acceleration: float = Field(6.0, gt=0, le=20.0, description="a_max: clip of the IDM acceleration [m/s^2]")
    comfort_acceleration: float = Field(3.0, gt=0, le=10.0, description="a_c: IDM maximum acceleration [m/s^2]")
    comfort_deceleration: float = Field(5.0, gt=0, le=10.0, description="b: IDM comfortable deceleration [m/s^2]")
    jam_distance: float = Field(10.0, gt=0, le=50.0, description="d_0: desired centre-to-centre distance at "
                                                                   "standstill [m] (5 m gap + 5 m vehicle length)")
    time_gap: float = Field(1.5, gt=0, le=5.0, description="T: desired time gap [s]")
    delta_range: tuple[float, float] = Field((3.5, 4.5), description="[low, high] of each vehicle's IDM speed "
                                                                     "exponent delta, drawn at spawn [1]")
    politeness: float = Field(0.0, ge=0, le=1.0, description="MOBIL politeness factor p [1]")
    lane_change_min_gain: float = Field(0.2, ge=0, le=5.0, description="MOBIL threshold of the acceleration gain "
                                                                        "[m/s^2]")
    lane_change_max_braking: float = Field(2.0, gt=0, le=10.0, description="MOBIL safe limit of the braking "
                                                                            "imposed on the new follower [m/s^2]")
    lane_change_delay: float = Field(1.0, gt=0, le=10.0, description="time between two lane-change decisions [s]")

    @field_validator("delta_range")
    @classmethod
    def _delta(cls, v: tuple[float, float]) -> tuple[float, float]:
        if not 0 < v[0] <= v[1] <= 20:
            raise ValueError(f"needs 0 < low <= high <= 20, got {v}")
        return v


class TrafficShield(_Strict):
    """The safety layer of ``roadload/EcoTraffic-v0`` (``shield=...``): the command u is capped at
    SHIELD_GAIN (v_safe - v), v_safe the highest speed from which the ego, reacting after ``reaction_time`` and
    braking at ``deceleration``, stops behind its leader braking at ``leader_deceleration`` with ``margin`` to
    spare: v T + v^2 / (2 b) <= gap - margin + v_l^2 / (2 b_l)."""

    enabled: bool = Field(False, description="cap the command by the braking envelope behind the leader")
    reaction_time: float = Field(0.3, ge=0, le=3.0, description="T: delay before the ego brakes [s]")
    deceleration: float = Field(3.5, gt=0, le=9.0, description="b: the ego's braking deceleration [m/s^2] (u = -1 "
                                                                "asks for 0.5 g)")
    leader_deceleration: float = Field(6.0, gt=0, le=15.0, description="b_l: the leader's worst braking [m/s^2] "
                                                                        "(highway-env's IDM clips at 6)")
    margin: float = Field(2.0, ge=0, le=50.0, description="bumper-to-bumper distance left at the stop [m]")


class EcoTrafficConfig(_TrafficScenario):
    """Configuration of ``roadload/EcoTraffic-v0``: EcoHighway-v0's scenario (highway-env's defaults) on the native
    backend: compiled IDM/MOBIL traffic around an ego that drives roadload's powertrain on a road with grade and
    curvature, batched (roadload.gym.traffic)."""

    road_seed_range: tuple[int, int] = Field((0, 100), description="[low, high) of drawn road seeds (each road is "
                                             "built once per process, ~5 ms, and cached); evaluate outside it")
    curvature: bool = Field(True, description="the ego drives the road's curvature (cornering resistance); False "
                                              "= straight, as EcoHighway-v0")
    policy_frequency: float = Field(10.0, gt=0, le=100.0, description="decisions per second [Hz] (10 = "
                                                                      "EcoDrive-v0's 0.1 s control period)")
    lane_changes: Literal["off", "box"] = Field(
        "off", description="'off': 1-D force; 'box': 2-D Box, second entry < -1/3 = left, > 1/3 = right")
    kinematics_rows: int = Field(5, ge=2, le=20, description="rows of the Kinematics block, the ego's first "
                                                             "(highway-env's vehicles_count)")
    see_behind: bool = Field(False, description="the Kinematics block also lists vehicles more than 10 m behind")
    neighbour_features: tuple[Literal["ax", "lane_change", "cut_in_time"], ...] = Field(
        (), description="extra features of each observed vehicle (the Kinematics block's rows 1 on, in its order), "
                        "appended after the powertrain block: 'ax' its acceleration command [m/s^2], "
                        "'lane_change' target lane - lane (-1 left, +1 right: MOBIL's decision in progress), "
                        "'cut_in_time' the time until it turns into the ego's lane [s] (0 while it does, the time "
                        "to its next lane decision where MOBIL accepts the ego's lane now, else 2 x the decision "
                        "delay); () = highway-env's Kinematics features only")
    traffic: TrafficBehaviour = Field(default_factory=TrafficBehaviour)
    shield: TrafficShield = Field(default_factory=TrafficShield)
    spawn: Literal["highway-env", "outside-envelope", "stopping-gap"] = Field(
        "highway-env", description="'highway-env': the ego placed as EcoHighway-v0 places it (often 15-20 m behind "
                                   "slower traffic at its initial speed, inside the safety layer's braking "
                                   "envelope); 'outside-envelope': moved back along its lane to the envelope's gap "
                                   "(the shield's parameters) behind the vehicle ahead, for every policy alike; "
                                   "'stopping-gap': moved back to the envelope's gap behind a vehicle at rest "
                                   "(margin + v T + v^2 / (2 b) [m], 98.8 m at 25 m/s), so that the traffic's own "
                                   "braking in its first seconds forces no policy to brake")

    _seed_range = field_validator("road_seed_range")(classmethod(lambda cls, v: _check_seed_range(v)))

    @field_validator("neighbour_features")
    @classmethod
    def _features(cls, v: tuple[str, ...]) -> tuple[str, ...]:
        if len(set(v)) != len(v):
            raise ValueError(f"each feature at most once, got {list(v)}")
        return v

    @property
    def road_length(self) -> float:
        """Length of the ego's road [m]: EcoHighway-v0's, duration x 60 m/s + 500 m, at least 2 km, at most 10 km."""
        return min(10_000.0, max(2000.0, self.duration * 60.0 + 500.0))


SPACE_FIELDS_TRAFFIC = ("lane_changes", "kinematics_rows", "neighbour_features", "lanes_count", "vehicles_count")
"""Fields of EcoTrafficConfig that shape the spaces or the batch arrays; reset options may not change them."""
