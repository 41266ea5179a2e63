"""The one mapping layer: a declarative JSON file turns any loader's source signals into Trip channels.

A mapping file::

    {
      "name": "canedge_gnss_obd", "format": "dbc-mf4", "licence": "MIT (CSS Electronics)",
      "sample_rate": 100,                      # Hz of the uniform time base (null: the source's median rate)
      "dbc": [{"file": "gnss.dbc", "bus": 2}], # CAN formats only: DBC files (found next to the log or packaged)
      "clock": {"source": "gnss_time.Epoch", "valid": "gnss_time.TimeValid", "unit": "s"},   # optional
      "csv": {"sep": ";", "encoding": "latin-1", "time": "Time [s]", "time_unit": "s"},       # CSV only
      "vehicle": "bmw_i3",                     # optional roadload.envs preset for derived channels
      "derived": [{"kind": "rim_torque"}, {"kind": "grade", "window": 150}],
      "channels": [
        {"source": "gnss_speed.Speed", "channel": "gnss_speed", "unit": "m/s", "scale": 1, "offset": 0,
         "resample": "linear", "valid": "gnss_speed.SpeedValid", "required": true}
      ]
    }

Per channel: ``source`` (a name or a list of alternative names; matched exactly, then case/space-insensitively),
``channel`` (Trip name, see roadload.channels), ``unit`` (the source unit, converted to SI with
roadload.units), ``scale``/``offset`` (applied before the unit conversion: ``x = raw * scale + offset``),
``resample`` (linear | hold | nearest, see roadload.io.resample), optional ``valid`` (a flag signal; samples
with flag 0 are dropped), ``required``, ``circular`` (angles that wrap), ``values`` (text -> number for
enumerations), ``range`` (plausible SI range; outside is dropped), ``plus`` (signals added to the source
before scaling, matched by nearest time, e.g. a fine steering-angle fraction), ``event`` (sent only on change:
held to the end of the log, long silences are not gaps), ``accuracy`` (``{"source": signal, "max": x}``:
samples whose reported accuracy is worse than x are dropped, e.g. GNSS altitude converging after start-up).

`apply_mapping` checks units against the source's declared units and the channel catalogue, aligns clocks,
validates, resamples and builds the Trip; everything it drops or repairs is counted in the ImportReport.
"""

from __future__ import annotations

import codecs
import difflib
import json
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Literal, TypedDict

import numpy as np
import pandas as pd
from pydantic import Field, ValidationError, field_validator, model_validator

from ..channels import MEASURED, unit_of
from ..registry import did_you_mean
from ..schema import StrictModel, format_errors
from ..trip import Trip
from ..units import si_unit_of, to_si
from .report import ImportReport, LogImportError
from .resample import RULES, resample, uniform_time_base
from .signals import SignalSet, monotonic
from .validate import plausible

MAPPINGS_DIR = Path(__file__).parent / "mappings"

# unit spellings met in DBCs and CSV headers -> roadload.units names
UNIT_ALIASES = {"kph": "km/h", "kmh": "km/h", "km/hr": "km/h", "deg/sec": "deg/s", "°/s": "deg/s", "sec": "s",
                "m/s2": "m/s^2", "m/s²": "m/s^2", "m/sec^2": "m/s^2", "nm": "N*m", "n*m": "N*m", "n.m": "N*m",
                "°c": "degC", "c": "degC", "degc": "degC", "deg c": "degC", "°": "deg", "degree": "deg",
                "degrees": "deg", "": "1", "-": "1", "percent": "%", "rad/sec": "rad/s", "1/min": "rpm",
                "kw": "kW", "v": "V", "a": "A", "w": "W", "kpa": "kPa", "k": "K", "ms": "ms", "m": "m",
                "km": "km", "deg": "deg", "rad": "rad", "rpm": "rpm", "s": "s", "%": "%", "bar": "bar",
                "pa": "Pa", "mph": "mph", "km/h": "km/h", "m/s": "m/s", "m/s^2": "m/s^2", "deg/s": "deg/s",
                "rad/s": "rad/s", "n": "N", "kg": "kg", "g": "g"}

_CHANNEL_KEYS = {"source", "channel", "unit", "scale", "offset", "resample", "valid", "required", "circular",
                 "values", "range", "note", "plus", "event", "accuracy", "extra"}
_TOP_KEYS = {"name", "format", "description", "licence", "source_url", "sample_rate", "dbc", "clock", "csv",
             "vehicle", "derived", "channels", "note", "max_gap"}
FORMATS = ("dbc-mf4", "candump", "blf", "asc", "comma2k19", "bmw-i3", "openxc", "csv", "mf4")


# ------------------------------------------------------------------------------------------ schema (pydantic)
Finite = float  # StrictModel refuses NaN/inf


class CsvOptions(StrictModel):
    """``csv`` block: how to read a delimited log."""

    time: str = Field(min_length=1, description="name of the time column, e.g. 'Time [s]'")
    time_unit: Literal["s", "ms"] = Field("s", description="unit of the time column")
    sep: str = Field(",", min_length=1, max_length=4, description="field separator")
    encoding: str = Field("utf-8", min_length=1, description="text encoding, e.g. 'utf-8' or 'latin-1'")
    decimal: str = Field(".", min_length=1, max_length=1, description="decimal mark")
    time_alternatives: list[str] = Field(default_factory=list, description="other names of the time column")

    @field_validator("encoding")
    @classmethod
    def _known_encoding(cls, v: str) -> str:
        try:
            codecs.lookup(v)
        except LookupError:
            raise ValueError(f"unknown text encoding {v!r} (e.g. 'utf-8', 'latin-1')") from None
        return v


class ClockOptions(StrictModel):
    """``clock`` block: a reference time signal (e.g. a GNSS epoch) to align the logger clock to."""

    source: str = Field(min_length=1)
    valid: str | None = None
    unit: Literal["s", "ms"] = "s"


class DbcEntry(StrictModel):
    file: str = Field(min_length=1, description="DBC file name (next to the log, the mapping or packaged)")
    bus: int | None = Field(None, ge=0, le=255, description="CAN bus number")


class DerivedStep(StrictModel):
    kind: Literal["rim_torque", "distance", "grade", "curvature"]
    efficiency: float = Field(0.97, gt=0.0, le=1.0, description="drive-train efficiency [1]")
    window: float = Field(150.0, gt=0.0, le=5000.0, description="smoothing window [m]")
    speed: str = Field("vehicle_speed", min_length=1, description="speed channel")


class AccuracyOptions(StrictModel):
    source: str = Field(min_length=1)
    max: float = Field(ge=0.0, description="worst accepted reported accuracy (in the accuracy signal's unit)")


class ChannelEntry(StrictModel):
    """One ``channels`` entry (see the module docstring)."""

    source: str | list[str]
    channel: str = Field(min_length=1)
    unit: str = Field(min_length=1)
    scale: Finite = Field(1.0, description="raw * scale + offset, before the unit conversion (dimensionless, non-zero)")
    offset: Finite = Field(0.0, description="added after scaling, in the mapping unit")
    resample: str = "linear"
    valid: str | None = None
    required: bool = False
    circular: bool = False
    extra: bool = Field(False, description="a channel outside the roadload.channels catalogue (kept with its unit)")
    values: dict[str, Finite] | None = None
    range: list[Finite] | None = Field(None, min_length=2, max_length=2,
                                        description="plausible [min, max] in the Trip (SI) unit")
    note: str | None = None
    plus: list[str] = Field(default_factory=list)
    event: bool = False
    accuracy: AccuracyOptions | None = None

    @field_validator("source")
    @classmethod
    def _sources(cls, v: str | list[str]) -> str | list[str]:
        if isinstance(v, list) and (not v or not all(x.strip() for x in v)):
            raise ValueError("needs a signal name or a non-empty list of names")
        if isinstance(v, str) and not v.strip():
            raise ValueError("needs a signal name")
        return v

    @field_validator("scale")
    @classmethod
    def _nonzero_scale(cls, v: float) -> float:
        if v == 0:
            raise ValueError("scale 0 would erase the signal; expected a non-zero factor [1]")
        return v

    @model_validator(mode="after")
    def _range_order(self) -> "ChannelEntry":
        if self.range is not None and not self.range[0] < self.range[1]:
            raise ValueError(f"range must be [min, max] with min < max, got {self.range}")
        return self


class MappingFile(StrictModel):
    """The whole mapping JSON (see the module docstring)."""

    name: str = Field(min_length=1)
    format: str
    description: str = ""
    licence: str | None = None
    source_url: str | None = None
    note: str | None = None
    sample_rate: float | None = Field(None, gt=0.0, le=10000.0, description="uniform time base rate [Hz]")
    dbc: list[DbcEntry] = Field(default_factory=list)
    clock: ClockOptions | None = None
    csv: CsvOptions | None = None
    vehicle: str | None = None
    derived: list[DerivedStep] = Field(default_factory=list)
    channels: list[ChannelEntry] = Field(min_length=1)
    max_gap: float = Field(2.0, gt=0.0, le=3600.0, description="longest source gap bridged silently [s]")


def normalise_unit(unit: str | None) -> str | None:
    """A declared unit in roadload.units spelling, or None when undeclared or unknown."""
    if unit is None:
        return None
    u = str(unit).strip()
    if u in UNIT_ALIASES.values():
        return u
    return UNIT_ALIASES.get(u.lower())


def normalise_name(name: str) -> str:
    """Lenient signal/column name: lower case, brackets unified, runs of space/punctuation collapsed."""
    s = str(name).strip().lower().replace("(", "[").replace(")", "]")
    s = re.sub(r"[\s_]+", " ", s)
    return s


@dataclass
class ChannelMap:
    """One mapping entry: source signal -> Trip channel."""

    sources: list[str]
    channel: str
    unit: str
    scale: float = 1.0
    offset: float = 0.0
    resample: str = "linear"
    valid: str | None = None
    required: bool = False
    circular: bool = False
    values: dict[str, float] | None = None
    range: tuple[float, float] | None = None
    plus: list[str] = field(default_factory=list)
    event: bool = False
    accuracy: dict[str, Any] | None = None

    @property
    def si_unit(self) -> str:
        """The Trip unit: the catalogue's unit of the channel (e.g. 'deg' for latitude), else the SI unit."""
        return unit_of(self.channel) or si_unit_of(self.unit)

    def convert(self, raw: np.ndarray) -> np.ndarray:
        """raw * scale + offset, converted from the mapping unit to the Trip unit."""
        x = np.asarray(raw, dtype=float) * self.scale + self.offset
        return x if self.unit == self.si_unit else to_si(x, self.unit)[0]


@dataclass
class Mapping:
    """A parsed mapping file (see the module docstring for the schema)."""

    name: str
    format: str
    channels: list[ChannelMap]
    sample_rate: float | None = None
    dbc: list[dict[str, Any]] = field(default_factory=list)
    clock: dict[str, Any] | None = None
    csv: dict[str, Any] = field(default_factory=dict)
    vehicle: str | None = None
    derived: list[dict[str, Any]] = field(default_factory=list)
    licence: str | None = None
    description: str = ""
    max_gap: float = 2.0
    path: str | None = None

    @classmethod
    def from_dict(cls, raw: dict[str, Any], where: str = "mapping") -> "Mapping":
        _check_mapping_keys(raw, where)
        try:
            MappingFile.model_validate(raw)
        except ValidationError as exc:
            raise LogImportError(f"{where}: {format_errors(exc, MappingFile)}") from None
        chans = []
        for i, entry in enumerate(raw["channels"]):
            chans.append(_parse_channel(entry, f"{where}: channels[{i}]"))
        names = [c.channel for c in chans]
        dupes = sorted({n for n in names if names.count(n) > 1})
        if dupes:
            raise LogImportError(f"{where}: duplicate channel names {dupes} (each Trip channel is mapped once)")
        rate = raw.get("sample_rate")
        if rate is not None and not (isinstance(rate, (int, float)) and rate > 0):
            raise LogImportError(f"{where}: sample_rate must be a positive number of Hz or null, got {rate!r}")
        return cls(name=str(raw["name"]), format=raw["format"], channels=chans,
                   sample_rate=None if rate is None else float(rate), dbc=list(raw.get("dbc", [])),
                   clock=raw.get("clock"), csv=dict(raw.get("csv") or {}), vehicle=raw.get("vehicle"),
                   derived=list(raw.get("derived", [])), licence=raw.get("licence"),
                   description=raw.get("description", ""), max_gap=float(raw.get("max_gap", 2.0)))

    @property
    def auxiliary_sources(self) -> list[str]:
        """Source signals a mapping reads besides the channels' own: validity flags, added ('plus') signals,
        accuracy signals, the clock reference and its validity flag."""
        out = [c.valid for c in self.channels if c.valid] + [p for c in self.channels for p in c.plus]
        out += [c.accuracy["source"] for c in self.channels if c.accuracy]
        if self.clock:
            out += [self.clock["source"]] + ([self.clock["valid"]] if self.clock.get("valid") else [])
        return out

    @property
    def source_names(self) -> set[str]:
        return {s for c in self.channels for s in c.sources} | set(self.auxiliary_sources)


def _check_mapping_keys(raw: Any, where: str) -> None:
    """The top level of a mapping file: an object with the known keys, name, format and channels, a known format;
    each channel entry with known keys and a known resample rule (checked before the schema, whose messages for
    these cases would be less direct)."""
    if not isinstance(raw, dict):
        raise LogImportError(f"{where}: a mapping is a JSON object, got {type(raw).__name__}")
    unknown = set(raw) - _TOP_KEYS
    if unknown:
        hints = "".join(did_you_mean(k, _TOP_KEYS) for k in sorted(unknown))
        raise LogImportError(f"{where}: unknown mapping keys {sorted(unknown)}{hints}; allowed "
                             f"{sorted(_TOP_KEYS)}")
    for key in ("name", "format", "channels"):
        if key not in raw:
            raise LogImportError(f"{where}: mapping lacks {key!r}")
    if raw["format"] not in FORMATS:
        raise LogImportError(f"{where}: unknown format {raw['format']!r}; choose one of {list(FORMATS)}")
    if not isinstance(raw["channels"], list):
        return
    for i, entry in enumerate(raw["channels"]):
        if isinstance(entry, dict):
            _check_channel_keys(entry, f"{where}: channels[{i}]")


def _check_channel_keys(entry: dict[str, Any], where: str) -> None:
    """A channel entry's keys are known and its resample rule is one of RULES."""
    unknown = set(entry) - _CHANNEL_KEYS
    if unknown:
        hints = "".join(did_you_mean(k, _CHANNEL_KEYS) for k in sorted(unknown))
        raise LogImportError(f"{where}: unknown keys {sorted(unknown)}{hints}; allowed {sorted(_CHANNEL_KEYS)}")
    rule = entry.get("resample", "linear")
    if isinstance(rule, str) and rule not in RULES:
        raise LogImportError(f"{where} ({entry.get('channel')}): unknown resample rule {rule!r}; choose {list(RULES)}")


def _parse_channel(entry: Any, where: str) -> ChannelMap:
    if not isinstance(entry, dict):
        raise LogImportError(f"{where}: expected an object, got {entry!r}")
    _check_channel_keys(entry, where)
    for key in ("source", "channel", "unit"):
        if key not in entry:
            raise LogImportError(f"{where}: lacks {key!r}")
    sources = entry["source"] if isinstance(entry["source"], list) else [entry["source"]]
    unit = normalise_unit(entry["unit"])
    if unit is None:
        raise LogImportError(f"{where} ({entry['channel']}): unknown unit {entry['unit']!r}")
    rule = entry.get("resample", "linear")
    if rule not in RULES:
        raise LogImportError(f"{where} ({entry['channel']}): unknown resample rule {rule!r}; choose {list(RULES)}")
    cm = ChannelMap(sources=[str(s) for s in sources], channel=str(entry["channel"]), unit=unit,
                    scale=float(entry.get("scale", 1.0)), offset=float(entry.get("offset", 0.0)), resample=rule,
                    valid=entry.get("valid"), required=bool(entry.get("required", False)),
                    circular=bool(entry.get("circular", False)), values=entry.get("values"),
                    range=tuple(entry["range"]) if entry.get("range") is not None else None,
                    plus=[str(p) for p in entry.get("plus", [])], event=bool(entry.get("event", False)),
                    accuracy=entry.get("accuracy"))
    _check_channel_map(cm, entry, where)
    return cm


def _check_channel_map(cm: ChannelMap, entry: dict[str, Any], where: str) -> None:
    """A channel map is consistent: accuracy as {source, max}, event channels held, circular channels angles, the
    channel in the catalogue (or marked extra) and its unit convertible to the catalogue's."""
    if cm.accuracy is not None and (not isinstance(cm.accuracy, dict) or set(cm.accuracy) != {"source", "max"}):
        raise LogImportError(f"{where} ({cm.channel}): accuracy must be {{\"source\": signal, \"max\": number}}")
    if cm.event and cm.resample != "hold":
        raise LogImportError(f"{where} ({cm.channel}): event channels (sent on change) must use resample 'hold'")
    if cm.circular and si_unit_of(cm.unit) != "rad":
        raise LogImportError(f"{where} ({cm.channel}): circular channels must be angles (rad/deg), got {cm.unit!r}")
    if cm.channel not in MEASURED and not entry.get("extra", False):
        close = difflib.get_close_matches(cm.channel, list(MEASURED), n=3, cutoff=0.6)
        raise LogImportError(f"{where}: channel {cm.channel!r} is not in the roadload.channels catalogue"
                             + (f" (did you mean {close}?)" if close else "")
                             + "; for a signal outside the catalogue set \"extra\": true")
    expected = unit_of(cm.channel)
    if expected is not None and cm.unit != expected and si_unit_of(cm.unit) != expected:
        raise LogImportError(f"{where}: unit mismatch for channel {cm.channel!r}: the mapping gives {entry['unit']!r} "
                             f"(SI {si_unit_of(cm.unit)!r}) but the channel is in {expected!r}")


def load_mapping(path_or_name: str | Path) -> Mapping:
    """A mapping from a JSON file, or a packaged one by name (e.g. ``"bmw_i3"``, see roadload/io/mappings/)."""
    p = Path(path_or_name)
    if not p.is_file():
        packaged = MAPPINGS_DIR / f"{path_or_name}.json"
        if packaged.is_file():
            p = packaged
        else:
            known = sorted(x.stem for x in MAPPINGS_DIR.glob("*.json"))
            raise LogImportError(f"mapping {str(path_or_name)!r}{did_you_mean(p.name, known)} is neither a file "
                                 f"nor a packaged mapping {known}")
    try:
        raw = json.loads(p.read_text(encoding="utf-8"))
    except json.JSONDecodeError as exc:
        raise LogImportError(f"{p}: not valid JSON ({exc})") from None
    m = Mapping.from_dict(raw, str(p))
    m.path = str(p)
    return m


# ------------------------------------------------------------------------------------------ applying
def find_source(signals: SignalSet, candidates: list[str]) -> str | None:
    """The first candidate present in the signal set: exact name first, then the lenient name."""
    for c in candidates:
        if c in signals:
            return c
    lenient: dict[str, list[str]] = {}
    for k in signals:
        lenient.setdefault(normalise_name(k), []).append(k)
    for c in candidates:
        hits = lenient.get(normalise_name(c), [])
        if len(hits) > 1:
            raise LogImportError(f"source name {c!r} matches several signals {hits}; make the mapping exact")
        if hits:
            return hits[0]
    return None


def _to_numeric(name: str, values: np.ndarray, table: dict[str, float] | None) -> np.ndarray:
    if values.dtype.kind in "fiu":
        return values.astype(float)
    if values.dtype.kind == "b":
        return values.astype(float)
    out = np.empty(values.size, dtype=float)
    for i, v in enumerate(values):
        if isinstance(v, (bool, np.bool_)):
            out[i] = float(v)
        elif isinstance(v, (int, float, np.number)):
            out[i] = float(v)
        elif table is not None and str(v) in table:
            out[i] = float(table[str(v)])
        else:
            try:
                out[i] = float(v)
            except (TypeError, ValueError):
                known = sorted(table) if table else []
                raise LogImportError(f"{name}: value {v!r} is not numeric and not in the mapping's 'values' "
                                     f"table {known}") from None
    return out


def _check_declared_unit(cm: ChannelMap, key: str, declared: str | None, report: ImportReport) -> None:
    if declared is None or str(declared).strip() == "":
        return
    norm = normalise_unit(declared)
    if norm is None:
        report.note(f"{key}: source unit {declared!r} unknown to roadload.units; trusting the mapping ({cm.unit})")
        return
    if norm != cm.unit:
        raise LogImportError(f"unit mismatch for {key} -> {cm.channel}: the source declares {declared!r} "
                             f"but the mapping says {cm.unit!r}")


def _missing_error(mapping: Mapping, missing: list[tuple[str, list[str]]], signals: SignalSet) -> LogImportError:
    parts = []
    for channel, cands in missing:
        close = difflib.get_close_matches(cands[0], list(signals), n=3, cutoff=0.5)
        parts.append(f"{channel} (source {cands if len(cands) > 1 else cands[0]!r}"
                     + (f"; did you mean {close}?" if close else "") + ")")
    return LogImportError(f"mapping {mapping.name!r}: required channels missing in the source: " + "; ".join(parts))


class ClockFit(TypedDict):
    """Reference time = fit_a + fit_b * (logger time - fit_t0) [s]; median offset [s], drift [ppm], residual [s]."""

    offset_s: float
    drift_ppm: float
    fit_a: float
    fit_b: float
    fit_t0: float
    residual_rms_s: float
    reference: str
    n: int


def clock_offset(signals: SignalSet, clock: dict[str, Any], start_time: float,
                 report: ImportReport) -> ClockFit:
    """Fit reference time (e.g. a GNSS epoch signal) = a + b * logger time; returns offset/drift/residual."""
    key = find_source(signals, [clock["source"]])
    if key is None:
        raise LogImportError(f"clock reference signal {clock['source']!r} not in the source")
    sig = signals[key]
    ref = np.asarray(sig.values, dtype=float)
    unit = normalise_unit(clock.get("unit", "s")) or "s"
    ref = to_si(ref, unit)[0]
    ok = np.isfinite(ref)
    if clock.get("valid"):
        vkey = find_source(signals, [clock["valid"]])
        if vkey is None:
            raise LogImportError(f"clock validity signal {clock['valid']!r} not in the source")
        flag = resample(signals[vkey].t, signals[vkey].values.astype(float), sig.t, "nearest")
        ok &= flag > 0.5
        report.drop(key, "clock reference invalid (validity flag 0)", int((flag <= 0.5).sum()))
    if ok.sum() < 2:
        raise LogImportError(f"clock reference {key!r} has fewer than 2 valid samples")
    t_rel = sig.t[ok]  # logger time since start_time: small numbers keep float64 precision (~1e-15 s)
    diff = ref[ok] - start_time - t_rel
    b, a = np.polyfit(t_rel - t_rel[0], diff, 1)
    resid = diff - (a + b * (t_rel - t_rel[0]))
    return {"offset_s": float(np.median(diff)), "drift_ppm": float(b * 1e6), "fit_a": float(a),
            "fit_b": float(b), "fit_t0": float(t_rel[0]), "residual_rms_s": float(np.sqrt(np.mean(resid ** 2))),
            "reference": key, "n": int(ok.sum())}


def apply_mapping(signals: SignalSet, mapping: Mapping, report: ImportReport, *, start_time: float = 0.0,
                  meta: dict[str, Any] | None = None, name: str | None = None) -> Trip:
    """Source signals -> Trip: match, check units, convert to SI, validate, align clock, resample.

    start_time: unix time [s] of the source clock's zero (logger start), used for clock alignment.
    """
    meta = dict(meta or {})
    # 1. match sources, check declared units, collect per-channel source samples in SI
    per_channel = _mapped_samples(signals, mapping, report)
    # 2. clock alignment: source time -> reference time (e.g. GNSS epoch)
    clock_info = clock_offset(signals, mapping.clock, start_time, report) if mapping.clock else None

    def align(t_src: np.ndarray) -> np.ndarray:
        if clock_info is None:
            return t_src
        return t_src + clock_info["fit_a"] + clock_info["fit_b"] * (t_src - clock_info["fit_t0"])

    # 3. the uniform time base over the span all required channels cover
    grid, rate = _time_base(per_channel, mapping, align)
    # 4. resample every channel by its rule, report bridged gaps and samples outside a channel's span
    cols = {"t": np.arange(grid.size) / rate}
    units = {"t": "s"}
    rules = {}
    for ch, (t, values, cm, key) in per_channel.items():
        cols[ch] = _resampled(ch, align(t), values, cm, grid, mapping.max_gap, report)
        units[ch] = cm.si_unit
        rules[ch] = {"source": key, "resample": cm.resample}
    unmapped = sorted(set(signals) - {v[3] for v in per_channel.values()} - mapping.source_names)
    if unmapped:
        report.note(f"{len(unmapped)} source signals not mapped")
    meta.update({
        "name": name or meta.get("name", mapping.name),
        "mapping": mapping.name,
        "mapping_file": mapping.path,
        "licence": mapping.licence,
        "sample_rate": rate,
        "t0_unix": float(start_time + grid[0]),
        "channels": rules,
        "unmapped_signals": unmapped[:200],
    })
    if clock_info is not None:
        meta["clock"] = {"reference": clock_info["reference"], "offset_s": clock_info["offset_s"],
                         "drift_ppm": clock_info["drift_ppm"], "residual_rms_s": clock_info["residual_rms_s"],
                         "n": clock_info["n"]}
    meta["import_report"] = report.to_dict()
    return Trip(pd.DataFrame(cols), units, meta)


ChannelSamples = tuple[np.ndarray, np.ndarray, ChannelMap, str]
"""(source time [s], values in SI, the channel's map, the source key) of one mapped channel."""


def _mapped_samples(signals: SignalSet, mapping: Mapping, report: ImportReport) -> dict[str, ChannelSamples]:
    """Every mapped channel found in the source as SI samples on its own time; a missing required channel or no
    channel at all is an error (naming the sources and close matches)."""
    per_channel: dict[str, ChannelSamples] = {}
    missing: list[tuple[str, list[str]]] = []
    for cm in mapping.channels:
        key = find_source(signals, cm.sources)
        if key is None:
            if cm.required:
                missing.append((cm.channel, cm.sources))
            else:
                report.note(f"optional channel {cm.channel} absent (source {cm.sources[0]!r})")
            continue
        t, values = _channel_samples(signals, cm, key, report)
        if t.size == 0:
            if cm.required:
                raise LogImportError(f"channel {cm.channel} (source {key!r}): no valid samples left")
            report.note(f"optional channel {cm.channel}: no valid samples left, omitted")
            continue
        per_channel[cm.channel] = (t, values, cm, key)
    if missing:
        raise _missing_error(mapping, missing, signals)
    if not per_channel:
        raise LogImportError(f"mapping {mapping.name!r}: no mapped channel found in the source")
    return per_channel


def _channel_samples(signals: SignalSet, cm: ChannelMap, key: str,
                     report: ImportReport) -> tuple[np.ndarray, np.ndarray]:
    """(t, values in SI) of one channel from source ``key``: plus signals added, samples whose validity flag is 0 or
    whose accuracy is worse than the mapping's limit dropped, implausible values removed (all counted)."""
    sig = monotonic(key, signals[key], report)
    _check_declared_unit(cm, key, sig.unit, report)
    raw = _to_numeric(key, sig.values, cm.values)
    t = sig.t
    for extra in cm.plus:  # e.g. a fine steering-angle fraction sent next to the coarse angle
        pkey = find_source(signals, [extra])
        if pkey is None:
            raise LogImportError(f"channel {cm.channel}: signal {extra!r} to add ('plus') not in the source")
        psig = monotonic(pkey, signals[pkey], report)
        _check_declared_unit(cm, pkey, psig.unit, report)
        raw = raw + resample(psig.t, _to_numeric(pkey, psig.values, None), t, "nearest")
    if cm.valid:
        flag, vkey = _companion(signals, cm.valid, t, report, f"validity flag {cm.valid!r} of channel {cm.channel}")
        bad = ~(flag > 0.5)
        report.drop(cm.channel, f"validity flag {vkey} = 0", int(bad.sum()))
        t, raw = t[~bad], raw[~bad]
    if cm.accuracy:
        acc, akey = _companion(signals, cm.accuracy["source"], t, report,
                               f"accuracy signal {cm.accuracy['source']!r} of channel {cm.channel}")
        bad = ~(acc <= float(cm.accuracy["max"]))
        report.drop(cm.channel, f"accuracy {akey} worse than {cm.accuracy['max']:g}", int(bad.sum()),
                    f"worst {np.nanmax(acc[bad]):.3g}" if bad.any() else "")
        t, raw = t[~bad], raw[~bad]
    values = cm.convert(raw)
    if cm.circular:
        values = np.mod(values, 2 * np.pi)
    return plausible(cm.channel, t, values, report, cm.range)


def _companion(signals: SignalSet, source: str, t: np.ndarray, report: ImportReport,
               what: str) -> tuple[np.ndarray, str]:
    """A channel's companion signal (validity flag, accuracy) at the channel's sample times ``t`` (nearest sample)
    and its source key; an absent one is an error naming ``what``."""
    key = find_source(signals, [source])
    if key is None:
        raise LogImportError(f"{what} not in the source")
    sig = monotonic(key, signals[key], report)
    return resample(sig.t, sig.values.astype(float), t, "nearest"), key


def _time_base(per_channel: dict[str, ChannelSamples], mapping: Mapping,
               align: Callable[[np.ndarray], np.ndarray]) -> tuple[np.ndarray, float]:
    """(uniform time base [s] over the span all required channels cover, its rate [Hz]: the mapping's, else the
    median rate of the required channels)."""
    spans = {ch: (align(v[0][:1])[0], align(v[0][-1:])[0]) for ch, v in per_channel.items()}
    req = [ch for ch, v in per_channel.items() if v[2].required] or list(per_channel)
    t0 = max(spans[c][0] for c in req)
    t1 = min(spans[c][1] for c in req)
    if not t1 > t0:
        raise LogImportError(f"required channels {req} do not overlap in time")
    rate = mapping.sample_rate
    if rate is None:
        dts = np.concatenate([np.diff(per_channel[c][0]) for c in req])
        rate = float(np.round(1.0 / np.median(dts[dts > 0]), 6))
    return uniform_time_base(t0, t1, rate), rate


def _resampled(ch: str, ta: np.ndarray, values: np.ndarray, cm: ChannelMap, grid: np.ndarray, max_gap: float,
               report: ImportReport) -> np.ndarray:
    """One channel (aligned source times ``ta``) on the time base by its rule; source gaps longer than max(max_gap,
    5 median steps) bridged by the rule are reported, and so are time-base samples outside the channel's span."""
    x = resample(ta, values, grid, cm.resample, circular=cm.circular)
    if cm.event:  # sent on change: the last value stays valid until the end of the log
        x[grid > ta[-1]] = values[-1]
    dt = np.diff(ta)
    if dt.size and not cm.event:
        limit = max(max_gap, 5.0 * float(np.median(dt)))
        gaps = np.flatnonzero(dt > limit)
        if gaps.size:
            inside = np.zeros(grid.size, dtype=bool)
            for g in gaps:
                inside |= (grid > ta[g]) & (grid < ta[g + 1])
            report.repair(ch, f"{gaps.size} source gaps > {limit:.3g} s bridged by '{cm.resample}'",
                          int(inside.sum()), f"longest {dt[gaps].max():.3g} s")
    n_nan = int(np.isnan(x).sum())
    if n_nan:
        report.note(f"{ch}: {n_nan} samples of the time base lie outside the channel's span (NaN)")
    return x
