"""Switchable, parameterised, seeded effects: drifting vehicle parameters, disturbances and sensor faults.

Every effect has a name, a short description with its equation, and named parameters with defaults, units and
valid ranges (``EFFECTS``). An :class:`EffectsConfig` says which effects are on and with which parameters; it is
built from a list of strings (``["wind", "payload:change_std=120", "sensor_dropouts:mode=missing"]``), a dict
(``{"wind": {"mean_speed": 5.0}}``) or the CLI (``--effects wind,tire_warmup``). Unknown effect or parameter
names raise :class:`EffectsError` listing the known ones. The ground truth of every drifting quantity is
recorded in the Trip's truth frame (channel names in ``roadload.channels``).

Ambient conditions (temperature T_a [K], pressure p_a [Pa], section 2.4.3) are part of the config, not effects.
"""

from __future__ import annotations

import copy
import math
from dataclasses import dataclass, field
from typing import Any

from roadload.units import STANDARD_PRESSURE, STANDARD_TEMPERATURE


class EffectsError(ValueError):
    """Unknown effect / parameter or a parameter outside its range; the message names it."""


@dataclass(frozen=True)
class EffectParam:
    default: float | str
    unit: str
    doc: str
    lo: float = -math.inf
    hi: float = math.inf
    choices: tuple[str, ...] = ()


@dataclass(frozen=True)
class EffectDef:
    name: str
    description: str
    params: dict[str, EffectParam] = field(default_factory=dict)


_INF = math.inf
_RAMP_TIMING = {
    "onset": EffectParam(600.0, "s or m", "start of the ramp (time or distance, see onset_unit)", 0.0, 1e7),
    "ramp": EffectParam(60.0, "s or m", "ramp length in the unit of onset (0 = a step)", 0.0, 1e7),
    "onset_unit": EffectParam("s", "", "'s': onset/ramp in seconds of trip time; 'm': metres driven",
                              choices=("s", "m")),
}
EFFECTS: dict[str, EffectDef] = {e.name: e for e in [
    EffectDef("wind", "Wind with gusts (eq. 2.7-2.8a): v_w = max(0, mean + g(t)), g an Ornstein-Uhlenbeck process "
              "(std gust_std, time constant gust_time_constant); direction psi_w0 + d(t) in the road frame at s=0 "
              "(direction the wind blows towards; the vehicle sees psi_w = psi_w0 + d - heading, 0 = tailwind).",
              {"mean_speed": EffectParam(3.0, "m/s", "mean wind speed", 0.0, 40.0),
               "direction": EffectParam(math.pi, "rad", "wind direction (blowing towards) relative to the road's "
                                        "initial heading; pi = headwind at the start", -10.0, 10.0),
               "gust_std": EffectParam(1.0, "m/s", "gust standard deviation", 0.0, 20.0),
               "gust_time_constant": EffectParam(5.0, "s", "gust correlation time", 0.1, 3600.0),
               "direction_std": EffectParam(0.2, "rad", "direction wander standard deviation", 0.0, 3.2)}),
    EffectDef("payload", "Payload changes at stops: at each road stop (v = 0 within 30 m) the payload changes by "
              "N(0, change_std^2), reflected into [min_payload, max_payload]; m_V = m_nominal + payload (eq. 2.5/2.6).",
              {"change_std": EffectParam(80.0, "kg", "std of the payload change per stop", 0.0, 2000.0),
               "min_payload": EffectParam(0.0, "kg", "lowest payload", -500.0, 5000.0),
               "max_payload": EffectParam(400.0, "kg", "highest payload", -500.0, 5000.0),
               "initial_payload": EffectParam(0.0, "kg", "payload at the start", -500.0, 5000.0)}),
    EffectDef("tire_warmup", "Tire warm-up: f_r0, f_r1, f_r4 scaled by 1 + (cold_factor - 1) exp(-s / "
              "distance_constant) (eq. 2.10; f_r falls as the tires warm).",
              {"cold_factor": EffectParam(1.25, "1", "f_r multiplier of cold tires", 1.0, 3.0),
               "distance_constant": EffectParam(8000.0, "m", "warm-up distance constant", 10.0, 1e6)}),
    EffectDef("winter_tires", "Winter tires: f_r coefficients x rolling_factor (eq. 2.10), axle cornering "
              "stiffnesses x cornering_factor (eq. 2.12).",
              {"rolling_factor": EffectParam(1.15, "1", "f_r multiplier", 0.5, 3.0),
               "cornering_factor": EffectParam(0.85, "1", "cornering stiffness multiplier", 0.2, 2.0)}),
    EffectDef("drag_area", "Drag-area changes (eq. 2.7): c_x A_V x (1 + roof_box + windows o_w(t) + sunroof "
              "o_s(t)), o_w, o_s in {0, 1} toggled at random (Poisson, toggle_rate per hour each).",
              {"roof_box": EffectParam(0.0, "1", "relative drag-area increase of a roof box (e.g. 0.25)", 0.0, 2.0),
               "windows": EffectParam(0.05, "1", "relative increase with windows open", 0.0, 1.0),
               "sunroof": EffectParam(0.02, "1", "relative increase with the sunroof open", 0.0, 1.0),
               "toggle_rate": EffectParam(2.0, "1/h", "opening/closing events per hour (each)", 0.0, 3600.0)}),
    EffectDef("road_bank", "Road bank angle phi_r (section 2.1): scale x the profile's bank plus superelevation "
              "clip(superelevation_gain x curvature, +-max_bank); enters the lateral force balance, the wheel "
              "load and the lateral accelerometer. Off: the road is flat across.",
              {"scale": EffectParam(1.0, "1", "multiplier of the profile's bank angle", 0.0, 10.0),
               "superelevation_gain": EffectParam(15.0, "m", "bank per unit curvature (rad m)", 0.0, 1000.0),
               "max_bank": EffectParam(0.06, "rad", "largest superelevation", 0.0, 0.3)}),
    EffectDef("wet_road", "Wet road: f_r x rolling_factor + water_f1 v (water displacement, eq. 2.10).",
              {"rolling_factor": EffectParam(1.1, "1", "f_r multiplier", 0.5, 3.0),
               "water_f1": EffectParam(1.0e-4, "s/m", "added speed-proportional f_r1", 0.0, 1e-2)}),
    EffectDef("oil_temperature", "Drive-train losses depend on oil temperature (section 5.2.1): T_oil warms "
              "towards T_warm with the drive-train's time constant from start_temperature (NaN = ambient); the loss "
              "maps of eq. 2.17 are scaled by phi(T_oil). Off: oil always warm (phi = 1).",
              {"start_temperature": EffectParam(math.nan, "K", "oil temperature at the start (NaN = ambient)",
                                                200.0, 450.0)}),
    EffectDef("brake_pad_drift", "Brake pad friction drift (T_B = p_B A_B r_B X_B, section 2.7): X_B = X_B0 (1 + "
              "temperature_coefficient (T_disc - reference_temperature)) + w(t), T_disc from a lumped disc "
              "heat balance, w a random walk (random_walk_std per sqrt(s)), |w| <= 0.25 X_B0. The brake "
              "controller maps force to pressure with the nominal X_B0.",
              {"temperature_coefficient": EffectParam(-6e-4, "1/K", "relative change per K of disc temperature",
                                                      -0.01, 0.01),
               "reference_temperature": EffectParam(323.15, "K", "disc temperature of nominal friction", 200, 900),
               "random_walk_std": EffectParam(5e-4, "1/sqrt(s)", "random walk intensity of X_B", 0.0, 0.1)}),
    EffectDef("barometric", "Air pressure falls with elevation: p_a = p_a0 exp(-h / scale_height), "
              "rho_a = p_a / (R_a T_a) (section 2.4.3).",
              {"scale_height": EffectParam(8434.5, "m", "barometric scale height", 1000.0, 20000.0)}),
    EffectDef("auxiliary_load", "Auxiliary load (heating, air conditioning): BEV battery power + power; ICE fuel "
              "power + power / 0.3.",
              {"power": EffectParam(1500.0, "W", "extra auxiliary power", 0.0, 20000.0)}),
    EffectDef("torque_model_error", "Error of the CAN drive torque (engine / motor model, section 5.2.1): "
              "T_CAN = T_E (1 + gain_error) + offset (replaces the sensor spec's values).",
              {"gain_error": EffectParam(0.05, "1", "relative gain error", -0.5, 0.5),
               "offset": EffectParam(10.0, "N*m", "torque offset", -500.0, 500.0)}),
    EffectDef("sensor_outliers", "Outliers: each sample of the selected channels is hit with probability rate; "
              "x += +-magnitude outlier_scale (1 + |N(0,1)|) (outlier_scale per channel in the sensor spec). "
              "inputs = speeds, accelerations, yaw rate, steering; outputs = drive torque, brake pressures. "
              "burst_length > 1: rate is the probability per sample that a burst STARTS; a burst hits "
              "burst_length consecutive samples with one sign (drawn independently per channel; bursts may "
              "overlap and then add). channel: one channel name or several joined by '+' (overrides channels).",
              {"rate": EffectParam(1e-3, "1", "probability per sample", 0.0, 0.5),
               "magnitude": EffectParam(1.0, "1", "multiplier of the channel's outlier_scale", 0.0, 1000.0),
               "channels": EffectParam("all", "", "which channels", choices=("all", "inputs", "outputs")),
               "burst_length": EffectParam(1.0, "samples", "samples per outlier burst (1 = isolated outliers; "
                                           "seconds = burst_length / sample_rate)", 1.0, 4096.0),
               "channel": EffectParam("", "", "channel name(s) joined by '+' ('' = use channels)")}),
    EffectDef("sensor_dropouts", "Dropouts: Poisson events (rate per hour) of exponential length (mean_duration); "
              "mode 'nan' sets the selected channels to NaN, 'missing' removes the samples (rows) entirely.",
              {"rate": EffectParam(30.0, "1/h", "dropout events per hour", 0.0, 36000.0),
               "mean_duration": EffectParam(0.5, "s", "mean dropout length", 0.01, 60.0),
               "mode": EffectParam("nan", "", "'nan' runs or 'missing' samples", choices=("nan", "missing")),
               "channels": EffectParam("all", "", "which channels (mode nan)", choices=("all", "inputs", "outputs")),
               "channel": EffectParam("", "", "channel name(s) joined by '+' (mode nan; overrides channels; "
                                      "'' = use channels)")}),
    EffectDef("sensor_bias", "Random constant sensor biases: bias ~ N(0, (scale b_ref)^2) per channel, b_ref from "
              "sensors.BIAS_REFERENCE (e.g. 0.05 m/s^2 for accelerometers).",
              {"scale": EffectParam(1.0, "1", "multiplier of the reference bias", 0.0, 100.0)}),
    EffectDef("sensor_latency", "Extra latency on every channel.",
              {"extra": EffectParam(0.05, "s", "added latency", 0.0, 5.0)}),
    EffectDef("wind_ramp", "Wind onset (envs/schedules.py): the mean wind speed and direction go linearly from "
              "start to final over [onset, onset + ramp] (time or distance, onset_unit; ramp = 0: a step). Direction "
              "as for 'wind' (pi = headwind at the start). With 'wind' on, its gusts and wander ride on top and its "
              "mean_speed/direction are replaced; without it the wind is exactly the schedule.",
              {**_RAMP_TIMING,
               "start_speed": EffectParam(0.0, "m/s", "mean wind speed before the onset", 0.0, 40.0),
               "final_speed": EffectParam(8.0, "m/s", "mean wind speed after the ramp", 0.0, 40.0),
               "start_direction": EffectParam(math.pi, "rad", "direction before the onset", -10.0, 10.0),
               "final_direction": EffectParam(math.pi, "rad", "direction after the ramp", -10.0, 10.0)}),
    EffectDef("mass_ramp", "Mass (payload) ramp/step (envs/schedules.py): m_V + magnitude clip((x - onset) / ramp, "
              "0, 1), x = t or s (onset_unit); payload changes at stops stay on top.",
              {**_RAMP_TIMING, "magnitude": EffectParam(200.0, "kg", "mass added by the end of the ramp",
                                                        -1000.0, 5000.0)}),
    EffectDef("drag_area_ramp", "Drag-area ramp/step (envs/schedules.py): c_x A_V x (1 + magnitude clip((x - "
              "onset) / ramp, 0, 1)) (eq. 2.7), on top of the 'drag_area' toggles.",
              {**_RAMP_TIMING, "magnitude": EffectParam(0.2, "1", "relative drag-area change", -0.9, 5.0)}),
    EffectDef("rolling_resistance_ramp", "Rolling-resistance ramp/step (envs/schedules.py): f_r0, f_r1, f_r4 x (1 + "
              "magnitude clip((x - onset) / ramp, 0, 1)) (eq. 2.10), on top of the other f_r effects.",
              {**_RAMP_TIMING, "magnitude": EffectParam(0.2, "1", "relative f_r change", -0.9, 5.0)}),
    EffectDef("poor_excitation", "Poor excitation (section 5.1): stretches of stretch_length covering fraction of "
              "the road where the driver cruises at constant speed (no speed variation). hold_speed 'yes': in "
              "each stretch the driver holds ONE speed, the lowest planned speed of the stretch (limits and "
              "curves), regardless of speed-limit changes, and skips the stops inside it; a stretch then lasts "
              "stretch_length / that speed (e.g. 15 km at 25 m/s = 600 s). 'no': the speed follows the plan.",
              {"fraction": EffectParam(0.5, "1", "share of the road in cruise stretches", 0.0, 1.0),
               "stretch_length": EffectParam(3000.0, "m", "length of one cruise stretch", 50.0, 1e6),
               "hold_speed": EffectParam("no", "", "hold one speed over each whole stretch", choices=("no", "yes"))}),
]}

SENSOR_EFFECTS = ("torque_model_error", "sensor_outliers", "sensor_dropouts", "sensor_bias", "sensor_latency")


def _parse_value(effect: str, name: str, raw: Any, p: EffectParam) -> float | str:
    where = f"effect {effect!r} parameter {name!r}"
    if p.choices:
        if raw not in p.choices:
            raise EffectsError(f"{where}: must be one of {list(p.choices)}, got {raw!r}")
        return str(raw)
    if isinstance(p.default, str):  # free text (e.g. channel names), checked where it is used
        if not isinstance(raw, str):
            raise EffectsError(f"{where}: expected text, got {raw!r}")
        return raw.strip()
    try:
        value = float(raw)
    except (TypeError, ValueError):
        raise EffectsError(f"{where}: expected a number [{p.unit}], got {raw!r}") from None
    if math.isnan(value) and isinstance(p.default, float) and math.isnan(p.default):
        return value
    if not math.isfinite(value) or not p.lo <= value <= p.hi:
        raise EffectsError(f"{where}: must lie in [{p.lo}, {p.hi}] {p.unit}, got {raw!r}")
    return value


class EffectsConfig:
    """Which effects are on, with which parameters, plus the ambient conditions."""

    def __init__(self, effects: dict[str, dict[str, Any]] | None = None,
                 ambient_temperature: float = STANDARD_TEMPERATURE,
                 ambient_pressure: float = STANDARD_PRESSURE) -> None:
        if not 200.0 <= float(ambient_temperature) <= 350.0:
            raise EffectsError(f"ambient_temperature: must lie in [200, 350] K, got {ambient_temperature!r}")
        if not 50000.0 <= float(ambient_pressure) <= 110000.0:
            raise EffectsError(f"ambient_pressure: must lie in [50000, 110000] Pa, got {ambient_pressure!r}")
        self.ambient_temperature = float(ambient_temperature)
        self.ambient_pressure = float(ambient_pressure)
        self._on: dict[str, dict[str, float | str]] = {}
        for name, params in (effects or {}).items():
            self.enable(name, **(params or {}))

    # ------------------------------------------------------------------ building
    def enable(self, name: str, **params: Any) -> "EffectsConfig":
        if name not in EFFECTS:
            raise EffectsError(f"unknown effect {name!r}; known effects: {sorted(EFFECTS)}")
        spec = EFFECTS[name]
        values = {k: p.default for k, p in spec.params.items()}
        for k, raw in params.items():
            if k not in spec.params:
                raise EffectsError(f"effect {name!r} has no parameter {k!r}; its parameters: {sorted(spec.params)}")
            values[k] = _parse_value(name, k, raw, spec.params[k])
        if name == "payload" and float(values["min_payload"]) > float(values["max_payload"]):
            raise EffectsError("effect 'payload' parameter 'min_payload': must not exceed max_payload")
        self._on[name] = values
        return self

    def disable(self, name: str) -> "EffectsConfig":
        if name not in EFFECTS:
            raise EffectsError(f"unknown effect {name!r}; known effects: {sorted(EFFECTS)}")
        self._on.pop(name, None)
        return self

    @classmethod
    def parse(cls, spec: "EffectsConfig | list[str] | tuple[str, ...] | str | dict | None") -> "EffectsConfig":
        """From None (no effects), a config, a dict, a list of 'name[:key=value,...]' strings or one string
        ('wind:mean_speed=5,gust_std=2,payload' or with ';' between effects). 'all' enables every effect."""
        if spec is None:
            return cls()
        if isinstance(spec, EffectsConfig):
            return spec.copy()
        if isinstance(spec, dict):
            return cls.from_dict(spec) if "effects" in spec else cls(spec)
        if isinstance(spec, str):
            items: list[str] = []
            for tok in (x.strip() for x in spec.replace(";", ",").split(",")):
                if not tok:
                    continue
                if "=" in tok and ":" not in tok and items:
                    items[-1] += "," + tok  # another key=value of the previous effect
                else:
                    items.append(tok)
            spec = items
        cfg = cls()
        for item in spec:
            if not isinstance(item, str):
                raise EffectsError(f"effects: expected strings like 'wind:mean_speed=5', got {item!r}")
            name, _, rest = item.partition(":")
            name = name.strip()
            if name == "all":
                for n in EFFECTS:
                    cfg.enable(n)
                continue
            params: dict[str, str] = {}
            for kv in filter(None, (x.strip() for x in rest.split(","))):
                k, eq, v = kv.partition("=")
                if not eq:
                    raise EffectsError(f"effect {name!r}: parameter setting {kv!r} is not key=value")
                params[k.strip()] = v.strip()
            cfg.enable(name, **params)
        return cfg

    # ------------------------------------------------------------------ access
    def enabled(self, name: str) -> bool:
        if name not in EFFECTS:
            raise EffectsError(f"unknown effect {name!r}; known effects: {sorted(EFFECTS)}")
        return name in self._on

    def params(self, name: str) -> dict[str, float | str]:
        """Parameters of an effect (defaults if it is off)."""
        if name not in EFFECTS:
            raise EffectsError(f"unknown effect {name!r}; known effects: {sorted(EFFECTS)}")
        return dict(self._on.get(name, {k: p.default for k, p in EFFECTS[name].params.items()}))

    @property
    def names(self) -> list[str]:
        return sorted(self._on)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready: NaN parameters are written as None."""
        eff = {n: {k: (None if isinstance(v, float) and math.isnan(v) else v) for k, v in p.items()}
               for n, p in sorted(self._on.items())}
        return {"effects": eff, "ambient_temperature": self.ambient_temperature,
                "ambient_pressure": self.ambient_pressure}

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> "EffectsConfig":
        unknown = set(data) - {"effects", "ambient_temperature", "ambient_pressure"}
        if unknown:
            raise EffectsError(f"effects config: unknown keys {sorted(unknown)}")
        eff = {n: {k: (math.nan if v is None else v) for k, v in (p or {}).items()}
               for n, p in (data.get("effects") or {}).items()}
        return cls(eff, data.get("ambient_temperature", STANDARD_TEMPERATURE),
                   data.get("ambient_pressure", STANDARD_PRESSURE))

    def copy(self) -> "EffectsConfig":
        return copy.deepcopy(self)

    def __repr__(self) -> str:
        return f"EffectsConfig({self.names}, T_a={self.ambient_temperature} K, p_a={self.ambient_pressure} Pa)"


def describe_effects() -> str:
    """Human-readable table of all effects and their parameters (for --help and docs)."""
    lines = []
    for e in EFFECTS.values():
        lines.append(f"{e.name}: {e.description}")
        for k, p in e.params.items():
            rng = f" one of {list(p.choices)}" if p.choices else f" [{p.unit}]"
            lines.append(f"    {k} = {p.default}{rng}: {p.doc}")
    return "\n".join(lines)
