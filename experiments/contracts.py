"""Property-based contract check: inputs generated from the schemas themselves, each classified by outcome.

Every user-facing schema -- the pydantic models (trip-file metadata, gym configs), the settings dataclasses (MPC,
closed loop, cruise, drive), the effect registry, the channel catalogue (Trip constructor), road profiles, route
files and file exports -- is read for its fields (type, bounds, choices, unit). Hypothesis draws inputs from those
fields: mostly valid values within the declared bounds, and in about half of the inputs one to three fields broken
(NaN, inf, out of its bounds, the wrong type, a near-miss choice, an unknown key, a missing unit, time running
backwards, channels of unequal length, near-duplicate names ...).

Each input ends in one of four outcomes:

- ``clean error``: a ``ValueError`` (the project's error types derive from it) whose message names the field
  (or channel) that is wrong;
- ``valid result``: accepted, every output finite and every declared constraint met (bounds of each field; a trip
  saved, loaded back and equal within its resolution; an export that reads back with the trip's values);
- ``traceback``: any other exception, or an error that does not name what is wrong;
- ``silent acceptance``: a broken input accepted, or an accepted input whose result is not finite or breaks a
  constraint.

A contract holds when the last two counts are 0. ``python scripts/contracts.py`` runs 2,000+ inputs seeded and
prints the counts per surface; ``--quick`` runs a small number (CI). Examples of the failing outcomes are printed.
"""

from __future__ import annotations

import dataclasses
import json
import math
import tempfile
import typing
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable

import numpy as np
from hypothesis import HealthCheck, given, seed, settings
from hypothesis import strategies as st

__all__ = ["OUTCOMES", "FieldSpec", "Case", "SURFACES", "run", "main"]

OUTCOMES = ("clean error", "valid result", "traceback", "silent acceptance")
NOT_A_NUMBER = ("abc", None, [1.0], {"x": 1})


# --------------------------------------------------------------------------------------------- schema fields
@dataclass(frozen=True)
class FieldSpec:
    """One field of a schema: dotted name, kind ('float', 'int', 'str', 'bool'), bounds, choices, default."""

    name: str
    kind: str
    default: Any = None
    lo: float | None = None
    hi: float | None = None
    lo_open: bool = False
    hi_open: bool = False
    choices: tuple[str, ...] = ()
    optional: bool = False
    nan_ok: bool = False  # NaN is a documented value (e.g. "NaN = ambient")

    def within(self, value: Any) -> bool:
        """True when `value` meets the field's type and declared bounds."""
        if (self.optional or self.nan_ok) and value is None:  # nan_ok: the JSON form writes NaN as None
            return True
        if self.kind in ("float", "int"):
            if isinstance(value, bool) or not isinstance(value, (int, float, np.floating, np.integer)):
                return False
            x = float(value)
            if self.nan_ok and math.isnan(x):
                return True
            if not math.isfinite(x):
                return False
            if self.lo is not None and (x < self.lo or (self.lo_open and x == self.lo)):
                return False
            return not (self.hi is not None and (x > self.hi or (self.hi_open and x == self.hi)))
        if self.choices:
            return value in self.choices
        return True


_SCALAR = {float: "float", int: "int", str: "str", bool: "bool"}


def _scalar_kind(tp: Any) -> tuple[str | None, bool, tuple[str, ...]]:
    """(kind, optional, choices) of an annotation, or (None, ...) for a non-scalar field."""
    args = typing.get_args(tp)
    if typing.get_origin(tp) is typing.Literal:
        return "str", False, tuple(str(a) for a in args)
    if args and type(None) in args:
        rest = [a for a in args if a is not type(None)]
        if len(rest) == 1:
            kind, _, choices = _scalar_kind(rest[0])
            return kind, True, choices
        return None, True, ()
    return _SCALAR.get(tp), False, ()


def pydantic_fields(model: type, prefix: str = "") -> list[FieldSpec]:
    """Scalar fields of a pydantic model (nested models flattened with dotted names), bounds from their metadata."""
    from pydantic import BaseModel

    out: list[FieldSpec] = []
    for name, info in model.model_fields.items():  # type: ignore[attr-defined]
        tp = info.annotation
        if isinstance(tp, type) and issubclass(tp, BaseModel):
            out += pydantic_fields(tp, f"{prefix}{name}.")
            continue
        kind, optional, choices = _scalar_kind(tp)
        if kind is None:
            continue
        bounds: dict[str, Any] = {}
        for m in info.metadata:
            for attr, key in (("ge", "lo"), ("gt", "lo"), ("le", "hi"), ("lt", "hi")):
                if getattr(m, attr, None) is not None:
                    bounds[key] = float(getattr(m, attr))
                    bounds[f"{key}_open"] = attr in ("gt", "lt")
        default = None if info.is_required() else info.get_default(call_default_factory=True)
        out.append(FieldSpec(f"{prefix}{name}", kind, default, choices=choices, optional=optional, **bounds))
    return out


def dataclass_fields(cls: type) -> list[FieldSpec]:
    """Scalar fields of a settings dataclass (nested ones are left at their defaults)."""
    hints = typing.get_type_hints(cls)
    out = []
    for f in dataclasses.fields(cls):
        kind, optional, choices = _scalar_kind(hints[f.name])
        if kind is None or f.default is dataclasses.MISSING:
            continue
        out.append(FieldSpec(f.name, kind, f.default, choices=choices, optional=optional))
    return out


# --------------------------------------------------------------------------------------------- value strategies
def _valid_value(spec: FieldSpec) -> st.SearchStrategy:
    if spec.kind == "bool":
        return st.booleans()
    if spec.kind == "str":
        return st.sampled_from(spec.choices) if spec.choices else st.just(spec.default)
    lo = spec.lo if spec.lo is not None else -1e4
    hi = spec.hi if spec.hi is not None else 1e4
    if spec.default is not None and isinstance(spec.default, (int, float)) and not isinstance(spec.default, bool):
        near = st.floats(0.0, 3.0).map(lambda k: spec.default * k)
        near = near.filter(spec.within)
    else:
        near = st.nothing()
    if spec.kind == "int":
        return st.one_of(st.just(spec.default) if spec.default is not None else st.nothing(),
                         st.integers(int(math.ceil(max(lo, -1e4))), int(math.floor(min(hi, 1e4))))
                         .filter(spec.within))
    plain = st.floats(max(lo, -1e6), min(hi, 1e6), exclude_min=spec.lo_open, exclude_max=spec.hi_open)
    return st.one_of(near, plain, st.sampled_from([x for x in (lo, hi) if spec.within(x)] or [spec.default]))


def _broken_value(spec: FieldSpec) -> st.SearchStrategy:
    """Values the field must refuse (given its declared type and bounds)."""
    options: list[Any] = []
    if spec.kind in ("float", "int"):
        options += [math.nan, math.inf, -math.inf, "abc", [1.0]]
        if not spec.optional:
            options.append(None)
        if spec.kind == "int":
            options.append(2.5)
        if spec.lo is not None:
            options += [spec.lo - 1.0 - abs(spec.lo), spec.lo - 1e-3] + ([spec.lo] if spec.lo_open else [])
        if spec.hi is not None:
            options += [spec.hi + 1.0 + abs(spec.hi)] + ([spec.hi] if spec.hi_open else [])
    elif spec.kind == "str":
        options += [3.5, [spec.default]]
        if spec.choices:
            options += [spec.choices[0].upper() + "x", spec.choices[0] + " "]
    elif spec.kind == "bool":
        options += ["yes", [True]]
    return st.sampled_from([v for v in options if not spec.within(v)] or [math.nan])


def _nested(data: dict[str, Any], dotted: str, value: Any) -> None:
    head, _, rest = dotted.partition(".")
    if rest:
        _nested(data.setdefault(head, {}), rest, value)
    else:
        data[head] = value


@dataclass
class Case:
    """One generated input: the call's keyword data and the fields deliberately broken (empty: a valid input)."""

    data: dict[str, Any]
    broken: list[str] = field(default_factory=list)
    note: str = ""


@st.composite
def schema_case(draw, specs: list[FieldSpec], unknown_key: bool = True) -> Case:
    """A dict of field values drawn from `specs`: 0-4 valid changes, and in half the cases 1-3 broken fields or
    an unknown key."""
    data: dict[str, Any] = {}
    case = Case(data)
    for spec in draw(st.lists(st.sampled_from(specs), max_size=4, unique_by=lambda s: s.name)):
        _nested(data, spec.name, draw(_valid_value(spec)))
    if draw(st.booleans()):
        n = draw(st.integers(1, 3))
        for spec in draw(st.lists(st.sampled_from(specs), min_size=1, max_size=n, unique_by=lambda s: s.name)):
            value = draw(_broken_value(spec))
            _nested(data, spec.name, value)
            case.broken.append(spec.name)
            case.note += f"{spec.name}={value!r} "
        if unknown_key and draw(st.integers(0, 4)) == 0:
            key = specs[0].name.split(".")[-1] + "_typo"
            data[key] = 1.0
            case.broken.append(key)
            case.note += f"{key} (unknown key) "
    return case


# --------------------------------------------------------------------------------------------- classification
def _names_field(message: str, names: list[str]) -> bool:
    text = message.lower()
    return any(n.split(".")[-1].lower() in text for n in names)


def _finite_fields(obj: Any, specs: list[FieldSpec]) -> str | None:
    """The first field of a built object that is not finite or breaks its bounds, or None."""
    for spec in specs:
        value: Any = obj
        for part in spec.name.split("."):
            value = value.get(part) if isinstance(value, dict) else getattr(value, part, None)
        if spec.kind in ("float", "int") and value is not None and not spec.within(value):
            return f"{spec.name}={value!r} accepted"
    return None


class Outcome(Exception):
    """Raised by a check to classify the case as silent acceptance (message: what was accepted)."""


def classify(call: Callable[[], Any], check: Callable[[Any], None], broken: list[str],
             all_names: list[str]) -> tuple[str, str]:
    """(outcome, detail) of one call: see the module docstring."""
    try:
        result = call()
    except Outcome as exc:
        return "silent acceptance", str(exc)
    except (ValueError, TypeError) as exc:  # the project's errors derive from ValueError, as pydantic's do
        message = str(exc)
        if isinstance(exc, TypeError) and "unexpected keyword argument" not in message:
            return "traceback", f"TypeError: {message[:200]}"
        if _names_field(message, broken or all_names):
            return "clean error", message.splitlines()[0][:160]
        return "traceback", f"{type(exc).__name__} not naming {broken or 'a field'}: {message[:200]}"
    except Exception as exc:  # noqa: BLE001 -- any other exception is the outcome being counted
        return "traceback", f"{type(exc).__name__}: {str(exc)[:200]}"
    if broken:
        return "silent acceptance", f"accepted with {broken} broken"
    try:
        check(result)
    except Outcome as exc:
        return "silent acceptance", str(exc)
    return "valid result", ""


# --------------------------------------------------------------------------------------------- surfaces
@dataclass
class Surface:
    """A contract surface: a strategy of inputs and how one input is run and classified."""

    name: str
    strategy: Callable[[], st.SearchStrategy]
    run_case: Callable[[Any, Path], tuple[str, str]]
    weight: float = 1.0


def _config_surface(name: str, specs: Callable[[], list[FieldSpec]], build: Callable[[dict], Any],
                    weight: float = 1.0, names: tuple[str, ...] = ()) -> Surface:
    """A surface for a schema object built from keyword data: valid results are checked field by field."""
    cache: dict[str, list[FieldSpec]] = {}

    def fields() -> list[FieldSpec]:
        if "f" not in cache:
            cache["f"] = specs()
        return cache["f"]

    def run_case(case: Case, _tmp: Path) -> tuple[str, str]:
        def check(obj: Any) -> None:
            problem = _finite_fields(obj, fields())
            if problem:
                raise Outcome(problem)
        return classify(lambda: build(case.data), check, case.broken, [s.name for s in fields()] + list(names))

    return Surface(name, lambda: schema_case(fields()), run_case, weight)


def _gym_surfaces() -> list[Surface]:
    def build(cls_name: str) -> Callable[[dict], Any]:
        def make(data: dict) -> Any:
            from roadload.gym import config as gym_config

            return gym_config.make_config(getattr(gym_config, cls_name), None, **data)
        return make

    def specs(cls_name: str) -> Callable[[], list[FieldSpec]]:
        def read() -> list[FieldSpec]:
            from roadload.gym import config as gym_config

            # road / vehicle / effects are names checked against their registries: their own surfaces cover them
            return [s for s in pydantic_fields(getattr(gym_config, cls_name)) if s.kind != "str" or s.choices]
        return read

    return [_config_surface(f"gym {c}", specs(c), build(c)) for c in ("EcoDriveConfig", "EcoHighwayConfig")]


def _settings_surfaces() -> list[Surface]:
    def dc(module: str, cls_name: str) -> tuple[Callable[[], list[FieldSpec]], Callable[[dict], Any]]:
        def cls() -> type:
            import importlib

            return getattr(importlib.import_module(module), cls_name)
        return (lambda: dataclass_fields(cls())), (lambda data: cls()(**data))

    out = []
    for module, cls_name in (("roadload.controllers.mpc", "MpcSettings"),
                             ("roadload.controllers.mpc_controller", "MpcControllerSettings"),
                             ("roadload.controllers.cruise", "CruiseSettings"),
                             ("roadload.controllers.drive", "DriveSettings")):
        specs, build = dc(module, cls_name)
        out.append(_config_surface(cls_name, specs, build))
    return out


def _payload_surface() -> Surface:
    def specs() -> list[FieldSpec]:
        from roadload.trip_schema import TripPayload

        return pydantic_fields(TripPayload)

    def build(data: dict) -> Any:
        from roadload.trip_schema import parse_trip_payload

        payload = {"version": 4, "n_measured": 10, **data}
        return parse_trip_payload(json.dumps(payload, allow_nan=True), "trip.parquet", n_rows=10)

    return _config_surface("trip metadata", specs, build, names=("units", "meta", "dtypes", "truth_units"))


# ------------------------------------------------------------------ effect registry
@st.composite
def effect_case(draw) -> Case:
    from roadload.envs.effects import EFFECTS

    name = draw(st.sampled_from(sorted(EFFECTS)))
    specs = []
    for k, p in EFFECTS[name].params.items():
        if isinstance(p.default, str):  # a choice, or free text (a channel name) checked where it is used
            specs.append(FieldSpec(k, "str", p.default, choices=p.choices))
        else:
            specs.append(FieldSpec(k, "float", p.default, None if p.lo == -math.inf else p.lo,
                                   None if p.hi == math.inf else p.hi, nan_ok=math.isnan(p.default)))
    if not specs:
        return Case({"effects": {name: {}}})
    inner = draw(schema_case(specs))
    case = Case({"effects": {name: inner.data}}, [f"{name}.{b}" for b in inner.broken], inner.note)
    if draw(st.integers(0, 9)) == 0:
        case.data["effects"] = {name + "x": {}}
        case.broken.append(name + "x")
    return case


def _run_effect(case: Case, _tmp: Path) -> tuple[str, str]:
    from roadload.envs.effects import EFFECTS, EffectsConfig

    def check(cfg: Any) -> None:
        for name in cfg.names:
            for k, v in cfg.params(name).items():
                p = EFFECTS[name].params[k]
                if isinstance(p.default, str):
                    if not isinstance(v, str) or (p.choices and v not in p.choices):
                        raise Outcome(f"effect {name}.{k}={v!r} accepted (expected {p.choices or 'text'})")
                elif not (isinstance(v, float) and ((math.isnan(v) and math.isnan(p.default)) or p.lo <= v <= p.hi)):
                    raise Outcome(f"effect {name}.{k}={v!r} outside [{p.lo}, {p.hi}] accepted")

    names = [f"{n}.{k}" for n, e in EFFECTS.items() for k in e.params] + list(EFFECTS)
    return classify(lambda: EffectsConfig.parse(case.data), check, case.broken, names)


# ------------------------------------------------------------------ Trip constructor, from the channel catalogue
SI_EXTRA = ("m", "N", "W", "kg/s", "rad/s^2", "J", "m/s^3")
NON_SI = ("km/h", "rpm", "%", "degC", "bar", "kmh", "g")
TRIP_BREAKS = ("unit of wrong type", "units not a dict", "unequal length", "near-duplicate name", "non-SI unit",
               "catalogue unit mismatch", "t NaN", "t backwards", "missing unit", "unit for absent channel",
               "non-numeric channel", "2-D channel", "truth unequal length", "reserved name", "empty name",
               "missing t")


@st.composite
def trip_case(draw) -> Case:
    """Trip(measured, units, truth=...) arguments drawn from the channel catalogue, optionally broken once."""
    from roadload.channels import MEASURED, TRUTH

    n = draw(st.integers(2, 40))
    dt = draw(st.sampled_from([0.01, 0.02, 0.1, 1.0]))
    t0 = draw(st.floats(0.0, 1e5))
    t = t0 + dt * np.arange(n)
    names = draw(st.lists(st.sampled_from(sorted(set(MEASURED) - {"t"})), min_size=1, max_size=5, unique=True))
    rng = np.random.default_rng(draw(st.integers(0, 2 ** 31)))
    measured: dict[str, Any] = {"t": t}
    units = {"t": "s"}
    for name in names:
        measured[name] = np.round(rng.normal(10.0, 5.0, n), 3)
        units[name] = MEASURED[name].unit
    if draw(st.booleans()):
        measured["custom_signal"] = rng.normal(0.0, 1.0, n)
        units["custom_signal"] = draw(st.sampled_from(SI_EXTRA))
    if draw(st.integers(0, 3)) == 0:
        measured[names[0]][draw(st.integers(0, n - 1))] = np.nan  # NaN marks a missing sample: valid
    truth: dict[str, Any] | None = None
    truth_units: dict[str, str] | None = None
    if draw(st.booleans()):
        tnames = draw(st.lists(st.sampled_from(sorted(set(TRUTH) - {"t"})), min_size=1, max_size=4, unique=True))
        truth = {"t": t.copy(), **{k: rng.normal(1.0, 0.5, n) for k in tnames}}
        truth_units = {"t": "s", **{k: TRUTH[k].unit for k in tnames}}
    case = Case({"measured": measured, "units": units, "truth": truth, "truth_units": truth_units})
    if draw(st.booleans()):
        kind = draw(st.sampled_from(TRIP_BREAKS))
        _break_trip(case, kind, names[0], draw)
    return case


def _break_trip(case: Case, kind: str, name: str, draw) -> None:
    """Break the Trip arguments of `case` in one way; `broken` holds the names the error must mention."""
    case.note = kind
    breaker = _break_units if kind in _UNIT_BREAKS else _break_samples
    case.broken.append(breaker(case, kind, name, draw))
    if kind not in _UNIT_BREAKS + _SAMPLE_BREAKS:
        raise AssertionError(f"no way to break a Trip as {kind!r}")


_UNIT_BREAKS = ("unit of wrong type", "units not a dict", "near-duplicate name", "non-SI unit",
                "catalogue unit mismatch", "missing unit", "unit for absent channel", "reserved name", "empty name")


_SAMPLE_BREAKS = ("unequal length", "t NaN", "t backwards", "non-numeric channel", "2-D channel",
                  "truth unequal length", "missing t")


def _break_units(case: Case, kind: str, name: str, draw) -> str:
    """Units and channel names broken; returns the name the error must mention."""
    m, u = case.data["measured"], case.data["units"]
    if kind == "unit of wrong type":
        u[name] = draw(st.sampled_from([3.6, None, ["m/s"], b"m/s"]))
    elif kind == "units not a dict":
        case.data["units"] = draw(st.sampled_from([list(u.values()), "SI", None, 1.0]))
        name = "units"
    elif kind == "near-duplicate name":
        twin = draw(st.sampled_from([name + " ", name.upper(), " " + name, name.replace("_", " _")]))
        if twin == name:
            twin = name + " "
        m[twin], u[twin] = m[name].copy(), u[name]
    elif kind == "non-SI unit":
        m["custom_signal"] = np.ones(len(m["t"]))
        u["custom_signal"] = draw(st.sampled_from(NON_SI))
        name = "custom_signal"
    elif kind == "catalogue unit mismatch":
        u[name] = draw(st.sampled_from(NON_SI))
    elif kind == "missing unit":
        del u[name]
    elif kind == "unit for absent channel":
        u["absent_channel"] = "m"
        name = "absent_channel"
    elif kind == "reserved name":
        name = draw(st.sampled_from(["truth/speed", "measured_row"]))
        m[name], u[name] = np.ones(len(m["t"])), "m"
    elif kind == "empty name":
        m[""], u[""] = np.ones(len(m["t"])), "m"
        name = "''"
    return name


def _break_samples(case: Case, kind: str, name: str, draw) -> str:
    """Time, lengths, shapes and types of the samples broken; returns the name the error must mention."""
    m, u = case.data["measured"], case.data["units"]
    if kind == "t NaN":
        m["t"] = m["t"].copy()
        m["t"][draw(st.integers(0, len(m["t"]) - 1))] = draw(st.sampled_from([np.nan, np.inf]))
        name = "t"
    elif kind == "t backwards":
        i = draw(st.integers(1, len(m["t"]) - 1))
        m["t"] = m["t"].copy()
        m["t"][i] = m["t"][i - 1] - draw(st.sampled_from([0.0, 0.005, 1.0]))
        name = "t"
    elif kind == "unequal length":
        m[name] = m[name][:-1]
    elif kind == "non-numeric channel":
        m[name] = np.array(["x"] * len(m["t"]), dtype=object)
    elif kind == "2-D channel":
        m[name] = np.ones((len(m["t"]), 2))
    elif kind == "truth unequal length":
        if case.data["truth"] is None:
            case.data["truth"], case.data["truth_units"] = {"t": m["t"].copy(), "speed": np.ones(1)}, {
                "t": "s", "speed": "m/s"}
            name = "speed"
        else:
            name = next(k for k in case.data["truth"] if k != "t")
            case.data["truth"][name] = case.data["truth"][name][:-1]
    elif kind == "missing t":
        del m["t"], u["t"]
        name = "'t'"
    return name


def _build_trip(data: dict) -> Any:
    import pandas as pd
    from roadload.trip import Trip

    measured = data["measured"]
    if isinstance(measured, dict) and all(np.ndim(v) == 1 for v in measured.values()) and \
            len({len(v) for v in measured.values()}) == 1 and len(measured) % 2:
        measured = pd.DataFrame(measured)  # both accepted input kinds: a DataFrame and a mapping
    return Trip(measured, data["units"], meta={"name": "contract"}, truth=data["truth"],
                truth_units=data["truth_units"])


def _check_trip(trip: Any, tmp: Path) -> None:
    """Every output finite; the trip saved and loaded back equals it within the resolution of each channel."""
    from roadload.trip import Trip

    t = trip.t
    if not (np.all(np.isfinite(t)) and np.all(np.diff(t) > 0)):
        raise Outcome("t accepted not finite or not increasing")
    path = tmp / "contract_trip.parquet"
    trip.save(path)
    back = Trip.load(path)
    if list(back.measured.columns) != list(trip.measured.columns) or back.units != trip.units:
        raise Outcome(f"saved trip reads back with other channels or units: {back.units} vs {trip.units}")
    for name in trip.measured.columns:
        a = trip.measured[name].to_numpy(float)
        b = back.measured[name].to_numpy(float)
        tolerance = 1e-6 * np.maximum(1.0, np.abs(a)) + 1e-3
        same = (np.isnan(a) & np.isnan(b)) | (np.abs(a - b) <= tolerance)
        if not np.all(same):
            raise Outcome(f"channel {name!r} reads back as {b[~same][:3]} instead of {a[~same][:3]}")


def _run_trip(case: Case, tmp: Path) -> tuple[str, str]:
    from roadload.channels import MEASURED

    return classify(lambda: _build_trip(case.data), lambda trip: _check_trip(trip, tmp), case.broken,
                    list(MEASURED) + ["units", "t"])


# ------------------------------------------------------------------ exports of a valid trip
@st.composite
def export_case(draw) -> Case:
    base = draw(trip_case().filter(lambda c: not c.broken))
    fmt = draw(st.sampled_from(["mf4", "csv", "mat", "mf4", "csv", "mat", "MF4", "xlsx", "cvs"]))
    suffix = {"mf4": ".mf4", "csv": ".csv", "mat": ".mat"}.get(fmt, ".csv")
    if draw(st.integers(0, 5)) == 0:
        suffix = draw(st.sampled_from([".txt", ".parquet", ""]))
    truth = draw(st.booleans())
    empty = draw(st.integers(0, 7)) == 0
    case = Case({**base.data, "fmt": fmt, "suffix": suffix, "truth_flag": truth, "empty": empty})
    if fmt not in ("mf4", "csv", "mat"):
        case.broken.append("format")
    elif suffix != {"mf4": ".mf4", "csv": ".csv", "mat": ".mat"}[fmt]:
        case.broken.append(f"ends in .{fmt}")
    elif empty:
        case.broken.append("nothing to export")
    elif truth and base.data["truth"] is None:
        case.broken.append("no ground truth")
    case.note = f"{fmt}{suffix} truth={truth} empty={empty}"
    return case


def _read_export(path: Path, fmt: str) -> dict[str, np.ndarray]:
    """The exported channels read back without roadload: asammdf, pandas (units row), scipy.io."""
    if fmt == "csv":
        import pandas as pd

        frame = pd.read_csv(path, skiprows=[1])
        return {c: frame[c].to_numpy(float) for c in frame.columns}
    if fmt == "mat":
        from scipy.io import loadmat

        mat = loadmat(path, squeeze_me=True, struct_as_record=False)
        measured = mat["measured"]
        return {k: np.atleast_1d(np.asarray(getattr(measured, k), float)) for k in measured._fieldnames}
    from asammdf import MDF

    with MDF(path) as mdf:
        return {name: np.asarray(mdf.get(name).samples, float)
                for group in mdf.groups for name in [c.name for c in group.channels] if name not in ("time", "t")}


def _run_export(case: Case, tmp: Path) -> tuple[str, str]:
    from roadload.io.export import export_file

    data = case.data
    path = tmp / f"contract_export{data['suffix']}"
    path.unlink(missing_ok=True)

    def call() -> Path:
        trip = _build_trip(data)
        if data["empty"]:
            trip = type(trip)(trip.measured[["t"]], {"t": "s"}, meta=trip.meta)
        return export_file(trip, path, data["fmt"], truth=data["truth_flag"])

    def check(out: Path) -> None:
        values = _read_export(out, data["fmt"])
        measured = data["measured"]
        for name, v in measured.items():
            if name == "t":
                continue
            got = values.get(name)
            if got is None or got.shape != np.shape(v):
                raise Outcome(f"{data['fmt']} export lacks channel {name!r} or has another length")
            ok = (np.isnan(v) & np.isnan(got)) | (np.abs(got - v) <= 1e-6 * np.maximum(1.0, np.abs(v)) + 1e-3)
            if not np.all(ok):
                raise Outcome(f"{data['fmt']} export of {name!r} reads back as {got[~ok][:3]}")

    outcome = classify(call, check, case.broken, ["format", "export"])
    if outcome[0] == "clean error" and path.exists():
        return "silent acceptance", f"refused export left a file: {path.name}"
    return outcome


# ------------------------------------------------------------------ road profiles and route files
PROFILE_BREAKS = ("distance backwards", "distance NaN", "grade NaN", "grade too steep", "speed_limit <= 0",
                  "unequal length", "stop outside", "distance not from 0")


@st.composite
def profile_case(draw) -> Case:
    n = draw(st.integers(2, 30))
    step = draw(st.floats(0.5, 50.0))
    rng = np.random.default_rng(draw(st.integers(0, 2 ** 31)))
    distance = step * np.arange(n)
    arrays = {"distance": distance, "grade": rng.uniform(-0.25, 0.25, n), "curvature": rng.uniform(-0.01, 0.01, n),
              "bank": rng.uniform(-0.05, 0.05, n), "speed_limit": rng.uniform(5.0, 40.0, n),
              "stops": np.sort(rng.uniform(0.0, distance[-1], draw(st.integers(0, 2))))}
    as_file = draw(st.booleans())
    case = Case({"arrays": arrays, "as_file": as_file, "cycle": draw(st.integers(0, 3)) == 0})
    if draw(st.booleans()):
        kind = draw(st.sampled_from(PROFILE_BREAKS))
        case.note = kind
        field_name = kind.split()[0]
        i = draw(st.integers(1, n - 1))
        if kind == "distance backwards":
            arrays["distance"] = distance.copy()
            arrays["distance"][i] = distance[i - 1] - draw(st.sampled_from([0.0, 0.1, step]))
        elif kind.endswith("NaN"):
            arrays[field_name] = arrays[field_name].copy()
            arrays[field_name][i] = np.nan
        elif kind == "grade too steep":
            arrays["grade"][i] = draw(st.sampled_from([0.35, -0.5, 1.2]))
        elif kind == "speed_limit <= 0":
            arrays["speed_limit"][i] = draw(st.sampled_from([0.0, -5.0]))
        elif kind == "unequal length":
            field_name = draw(st.sampled_from(["grade", "curvature", "bank", "speed_limit"]))
            arrays[field_name] = arrays[field_name][:-1]
        elif kind == "stop outside":
            arrays["stops"] = np.array([distance[-1] + step])
            field_name = "stops"
        elif kind == "distance not from 0":
            arrays["distance"] = distance + step
        case.broken.append(field_name if not case.data["cycle"] else "time" if field_name == "distance" else "speed")
        if case.data["cycle"] and (field_name not in ("distance", "speed_limit") or kind == "distance not from 0"
                                   or (kind == "speed_limit <= 0" and arrays["speed_limit"][i] == 0.0)):
            case.broken = []  # a drive cycle has no grade-curvature-bank-stops fields to break
            case.note += " (not used by a drive cycle)"
    return case


def _build_profile(data: dict, tmp: Path) -> Any:
    from roadload.road_profiles.files import load_profile_file
    from roadload.road_profiles.profile import DriveCycle, RoadProfile

    a = data["arrays"]
    if data["cycle"]:
        cycle_arrays = {"time": a["distance"], "speed": a["speed_limit"]}
        if not data["as_file"]:
            return DriveCycle("contract", cycle_arrays["time"], cycle_arrays["speed"])
        path = tmp / "contract_cycle.csv"
        _write_roadload_csv(path, "drive_cycle", cycle_arrays, None)
        return load_profile_file(path)
    if not data["as_file"]:
        return RoadProfile("contract", a["distance"], a["grade"], a["curvature"], a["bank"], a["speed_limit"],
                           a["stops"])
    path = tmp / "contract_road.csv"
    _write_roadload_csv(path, "road_profile", {k: v for k, v in a.items() if k != "stops"}, a["stops"])
    return load_profile_file(path)


def _write_roadload_csv(path: Path, kind: str, arrays: dict[str, np.ndarray], stops: np.ndarray | None) -> None:
    """A route file in roadload's CSV layout (header line, one column per array; a short column ends in blanks)."""
    import pandas as pd

    from roadload.road_profiles.files import VERSION

    header = {"version": VERSION, "name": "contract", "stops": None if stops is None else stops.tolist()}
    n = max(len(v) for v in arrays.values())
    frame = pd.DataFrame({k: np.concatenate([v, np.full(n - len(v), np.nan)]) for k, v in arrays.items()})
    path.write_text(f"# roadload.{kind} {json.dumps(header, allow_nan=True)}\n" + frame.to_csv(index=False))


def _run_profile(case: Case, tmp: Path) -> tuple[str, str]:
    def check(profile: Any) -> None:
        for name in ("distance", "grade", "curvature", "bank", "speed_limit", "time", "speed"):
            values = getattr(profile, name, None)
            if values is not None and not np.all(np.isfinite(values)):
                raise Outcome(f"profile {name} accepted with NaN/inf")
        x = getattr(profile, "distance", None)
        x = profile.time if not isinstance(x, np.ndarray) else x
        if not np.all(np.diff(x) > 0):
            raise Outcome("profile accepted with its abscissa not strictly increasing")

    return classify(lambda: _build_profile(case.data, tmp), check, case.broken,
                    ["distance", "grade", "curvature", "bank", "speed_limit", "stops", "time", "speed"])


SURFACES: list[Surface] = [
    Surface("Trip constructor", trip_case, _run_trip, 3.0),
    Surface("trip export", export_case, _run_export, 1.5),
    _payload_surface(),
    Surface("effect registry", effect_case, _run_effect, 1.5),
    *_gym_surfaces(),
    *_settings_surfaces(),
    Surface("road profile / route file", profile_case, _run_profile, 1.5),
]


# --------------------------------------------------------------------------------------------- running
def run_surface(surface: Surface, n: int, seed_value: int, tmp: Path) -> tuple[Counter, list[str]]:
    """Counts by outcome over `n` generated inputs of one surface, and up to 5 examples of failing outcomes."""
    counts: Counter = Counter()
    examples: list[str] = []

    @seed(seed_value)
    @settings(max_examples=n, database=None, deadline=None, derandomize=False, print_blob=False,
              suppress_health_check=list(HealthCheck))
    @given(surface.strategy())
    def body(case: Any) -> None:
        outcome, detail = surface.run_case(case, tmp)
        counts[outcome] += 1
        if outcome in ("traceback", "silent acceptance") and len(examples) < 5:
            examples.append(f"{outcome}: {getattr(case, 'note', '')} -> {detail}")

    body()
    return counts, examples


def run(total: int, seed_value: int = 0, surfaces: list[Surface] | None = None,
        progress: Callable[[str], None] | None = None) -> dict[str, Counter]:
    """Counts by outcome per surface over about `total` generated inputs (split by the surfaces' weights)."""
    surfaces = surfaces or SURFACES
    weight = sum(s.weight for s in surfaces)
    out: dict[str, Counter] = {}
    with tempfile.TemporaryDirectory(prefix="roadload-contracts-") as tmp:
        for i, surface in enumerate(surfaces):
            n = max(5, int(round(total * surface.weight / weight)))
            counts, examples = run_surface(surface, n, seed_value + i, Path(tmp))
            out[surface.name] = counts
            if progress is not None:
                progress(_row(surface.name, counts))
                for line in examples:
                    progress(f"    {line}")
    return out


def _row(name: str, counts: Counter) -> str:
    return f"{name:<28}" + "".join(f"{counts.get(o, 0):>19}" for o in OUTCOMES) + f"{sum(counts.values()):>8}"


def main(argv: list[str] | None = None) -> int:
    """Command line: ``--inputs N`` (default 2,400), ``--seed S``, ``--quick`` (240 inputs); exit 1 on any
    traceback or silent acceptance."""
    import argparse

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--inputs", type=int, default=2400, help="generated inputs in all (default 2400)")
    parser.add_argument("--seed", type=int, default=0, help="hypothesis seed (default 0)")
    parser.add_argument("--quick", action="store_true", help="a small run (240 inputs) for CI")
    args = parser.parse_args(argv)
    if args.inputs < 1:
        parser.error(f"--inputs must be >= 1, got {args.inputs}")
    total = 240 if args.quick else args.inputs
    print(f"{'surface':<28}" + "".join(f"{o:>19}" for o in OUTCOMES) + f"{'inputs':>8}", flush=True)
    results = run(total, args.seed, progress=lambda line: print(line, flush=True))
    counts: Counter = sum(results.values(), Counter())
    print(_row("all", counts))
    bad = counts["traceback"] + counts["silent acceptance"]
    print(f"{sum(counts.values())} generated inputs (seed {args.seed}): " + ", ".join(
        f"{counts.get(o, 0)} {o}" for o in OUTCOMES))
    return 1 if bad else 0
