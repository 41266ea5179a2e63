"""Trips out: files other tools open (:func:`export_file`: ASAM MDF4, CSV with a units row, MATLAB .mat) and
real CAN traffic (:func:`export_trip`: a project DBC, frames at the channel rates, candump / BLF / MDF4 logs).

File exports (``roadload export TRIP --format mf4|csv|mat``) carry the measured channels in SI with their units
(and, with ``truth=True``, the ground truth of a simulated trip as ``truth/<name>``):

- ``mf4``: one channel group for the measured channels on their time base (one for the truth), each channel with
  its unit and catalogue description; the trip metadata as the embedded attachment ``roadload_meta.json``. asammdf,
  CANape, INCA and MATLAB's ``mdfRead`` open it; ``roadload import FILE --format mf4`` reads it back (equal within
  each channel's resolution; the imported trip starts at t = 0, ``meta["t0_unix"]`` keeps the start).
- ``csv``: a header row of channel names, a second row of units, then one row per sample (``t`` first; truth
  columns on the rows of their own time base, empty elsewhere); numbers written to round-trip exactly.
- ``mat``: MATLAB v5 file with structs ``measured`` and ``truth`` (one field per channel), ``units`` and
  ``truth_units`` (one string per channel) and ``meta_json`` (the metadata as JSON text).

CAN traffic:

The DBC is built from the sensor model: every exported channel becomes one signal whose scale equals the
sensor's quantisation step (``ChannelSensorSpec.resolution``; channels without quantisation get
``DEFAULT_RESOLUTION``), whose offset is a multiple of that step (so quantised values are encoded exactly) and
whose bit length covers the channel's physical range. Channels of equal rate are packed (little-endian, in
catalogue order) into 8-byte messages from id 0x100 up, sent every 1/rate seconds.

Next to the log, `export_trip` writes the DBC and a mapping file, so ``roadload import LOG --format candump
--mapping LOG.mapping.json`` reads the Trip channels back (equal to the exported ones within half a
resolution step; exactly, for values on the quantisation grid).
"""

from __future__ import annotations

import json
import math
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

import pandas as pd

from ..channels import MEASURED, TRUTH
from ..fileio import atomic_path, write_text
from ..presets import get_preset
from ..registry import did_you_mean
from ..trip import TRUTH_PREFIX, Trip
from ..vehicle import ChannelSensorSpec, SensorSpec
from .frames import CanFrames, write_can_log
from .report import LogImportError

FIRST_ID = 0x100
# physical ranges [SI] that size the DBC signals; channels not listed use +-DEFAULT_RANGE
RANGES: dict[str, tuple[float, float]] = {
    "vehicle_speed": (-10.0, 100.0), "gnss_speed": (0.0, 100.0),
    "wheel_speed_fl": (-40.0, 400.0), "wheel_speed_fr": (-40.0, 400.0),
    "wheel_speed_rl": (-40.0, 400.0), "wheel_speed_rr": (-40.0, 400.0),
    "accel_x": (-30.0, 30.0), "accel_y": (-30.0, 30.0), "yaw_rate": (-3.0, 3.0),
    "steering_wheel_angle": (-12.0, 12.0), "drive_torque": (-2000.0, 2000.0), "rim_torque": (-20000.0, 20000.0),
    "engine_speed": (-100.0, 1500.0), "gear": (-1.0, 12.0), "clutch": (0.0, 1.0),
    "brake_pressure_front": (0.0, 2.5e7), "brake_pressure_rear": (0.0, 2.5e7),
    "ambient_temperature": (200.0, 350.0), "elevation": (-500.0, 9000.0), "latitude": (-90.0, 90.0),
    "longitude": (-180.0, 180.0), "heading": (0.0, 6.3), "battery_voltage": (0.0, 1000.0),
    "battery_current": (-1000.0, 1000.0), "accelerator_pedal": (0.0, 1.0), "heating_power": (0.0, 20000.0),
    "distance": (0.0, 4.0e6), "grade": (-0.5, 0.5), "curvature": (-1.0, 1.0),
}
DEFAULT_RANGE = 1.0e4
DEFAULT_RESOLUTION: dict[str, float] = {"gear": 1.0, "clutch": 0.01, "latitude": 1e-7, "longitude": 1e-7,
                                        "distance": 0.01, "brake_pressure_front": 1000.0,
                                        "brake_pressure_rear": 1000.0}
FALLBACK_RESOLUTION = 1e-3  # of the SI unit, for channels without a quantisation step
MAX_BITS = 32


@dataclass(frozen=True)
class ExportChannel:
    """One exported channel: resolution (= DBC scale) [SI unit], rate [Hz], physical range [SI unit]."""

    name: str
    unit: str
    resolution: float
    rate: float
    minimum: float
    maximum: float

    @property
    def offset(self) -> float:
        """DBC offset: the range minimum rounded down onto the quantisation grid (quantised values stay exact)."""
        return math.floor(self.minimum / self.resolution) * self.resolution

    @property
    def bits(self) -> int:
        steps = math.ceil((self.maximum - self.offset) / self.resolution)
        return max(1, int(steps).bit_length())


def sensor_channel(name: str, unit: str, sensors: Any | None, rate: float | None = None,
                   values: np.ndarray | None = None) -> ExportChannel | None:
    """The export layout of one channel from a sensor spec (``roadload.vehicle.SensorSpec``: ``sample_rate``,
    per-channel ``resolution``/``enabled``/optional ``rate``); None when the sensor is disabled. The range is
    RANGES[name], widened to the values when given; the rate is `rate`, else the sensor's, else sample_rate."""
    spec = getattr(sensors, "channels", {}).get(name) if sensors is not None else None
    if spec is not None and not getattr(spec, "enabled", True):
        return None
    res = float(getattr(spec, "resolution", 0.0) or 0.0) if spec is not None else 0.0
    if res <= 0:
        res = DEFAULT_RESOLUTION.get(name, FALLBACK_RESOLUTION)
    rate = rate or (getattr(spec, "rate", None) if spec is not None else None) \
        or (getattr(sensors, "sample_rate", None) if sensors is not None else None)
    if not rate:
        raise LogImportError(f"channel {name}: no rate (no sensor rate and no trip rate given)")
    lo, hi = RANGES.get(name, (-DEFAULT_RANGE, DEFAULT_RANGE))
    if values is not None:
        finite = values[np.isfinite(values)]
        if finite.size:
            lo, hi = min(lo, float(finite.min())), max(hi, float(finite.max()))
    ch = ExportChannel(name, unit, res, float(rate), lo, hi)
    if ch.bits > MAX_BITS:
        raise LogImportError(f"channel {name}: range [{lo:g}, {hi:g}] at resolution {res:g} needs {ch.bits} "
                             f"bits (> {MAX_BITS}); coarsen the resolution")
    return ch


def project_dbc(sensors: Any, vehicle: str = "vehicle") -> str:
    """The project DBC of a sensor configuration alone (its enabled catalogue channels, catalogue units)."""
    chans = [sensor_channel(name, MEASURED[name].unit, sensors) for name in sensors.channels if name in MEASURED]
    return dbc_text([c for c in chans if c is not None], vehicle)


PROJECT_DBC_DIR = Path(__file__).parent / "dbc"


def write_project_dbc(preset: str, folder: str | Path = PROJECT_DBC_DIR) -> Path:
    """Write ``roadload_<preset>.dbc``: the project DBC of a roadload.envs vehicle preset's sensor set (atomic).
    The packaged copies are regenerated with this function (a test checks they are up to date)."""

    spec = get_preset(preset)
    path = Path(folder) / f"roadload_{preset}.dbc"
    path.parent.mkdir(parents=True, exist_ok=True)
    write_text(path, project_dbc(spec.sensors, spec.name))
    return path


def export_channels(trip: Trip, sensors: Any | None = None, channels: list[str] | None = None,
                    rates: dict[str, float] | None = None) -> list[ExportChannel]:
    """Channels of a trip laid out by `sensor_channel`; without a sensor spec they go at the trip's rate."""
    names = channels if channels is not None else trip.channels
    out = []
    for name in names:
        trip.require(name)
        rate = (rates or {}).get(name)
        spec = getattr(sensors, "channels", {}).get(name) if sensors is not None else None
        if rate is None and getattr(spec, "rate", None) is None and not getattr(sensors, "sample_rate", None):
            rate = trip.sample_rate
        ch = sensor_channel(name, trip.units[name], sensors, rate, trip.channel(name))
        if ch is not None:
            out.append(ch)
    if not out:
        raise LogImportError("no channels to export")
    return out


@dataclass
class _Layout:
    frame_id: int
    name: str
    rate: float
    signals: list[tuple[ExportChannel, int]]  # (channel, start bit)


def _layout(channels: list[ExportChannel]) -> list[_Layout]:
    order = {n: i for i, n in enumerate(MEASURED)}
    by_rate: dict[float, list[ExportChannel]] = {}
    for ch in sorted(channels, key=lambda c: (order.get(c.name, len(order)), c.name)):
        by_rate.setdefault(ch.rate, []).append(ch)
    msgs: list[_Layout] = []
    fid = FIRST_ID
    for rate in sorted(by_rate, reverse=True):
        current: list[tuple[ExportChannel, int]] = []
        used = 0
        for ch in by_rate[rate]:
            if used + ch.bits > 64:
                msgs.append(_Layout(fid, f"RL_{rate:g}HZ_{fid:X}".replace(".", "_"), rate, current))
                fid += 1
                current, used = [], 0
            current.append((ch, used))
            used += ch.bits
        if current:
            msgs.append(_Layout(fid, f"RL_{rate:g}HZ_{fid:X}".replace(".", "_"), rate, current))
            fid += 1
    return msgs


def dbc_text(channels: list[ExportChannel], vehicle: str = "roadload") -> str:
    """The project DBC for these channels (Vector DBC text)."""
    lines = ['VERSION ""', "", "", "NS_ :", "\tCM_", "", "BS_:", "", "BU_: ROADLOAD", "", ""]
    comments = []
    for msg in _layout(channels):
        lines.append(f"BO_ {msg.frame_id} {msg.name}: 8 ROADLOAD")
        for ch, start in msg.signals:
            top = ch.offset + ((1 << ch.bits) - 1) * ch.resolution
            lines.append(f' SG_ {ch.name} : {start}|{ch.bits}@1+ ({ch.resolution!r},{ch.offset!r}) '
                         f'[{ch.offset:.12g}|{top:.12g}] "{ch.unit}" Vector__XXX')
        lines.append("")
        comments.append(f'CM_ BO_ {msg.frame_id} "roadload simulated sensors, sent every {1 / msg.rate:g} s";')
    comments.insert(0, f'CM_ "roadload project DBC for the simulated {vehicle}: scale = sensor quantisation step, '
                       f'offset on the quantisation grid, little-endian unsigned signals.";')
    return "\n".join(lines + [""] + comments) + "\n"


def encode_trip(trip: Trip, channels: list[ExportChannel]) -> CanFrames:
    """Frames of all messages at their rates over the trip (values sampled at the nearest trip sample)."""
    t = trip.t
    rows_t, rows_id, rows_data = [], [], []
    for msg in _layout(channels):
        n = int(math.floor((t[-1] - t[0]) * msg.rate + 1e-6)) + 1
        tm = t[0] + np.arange(n) / msg.rate
        idx = np.clip(np.searchsorted(t, tm - 0.5 / max(trip.sample_rate, msg.rate)), 0, t.size - 1)
        word = np.zeros(n, dtype=np.uint64)
        for ch, start in msg.signals:
            x = trip.channel(ch.name)[idx]
            bad = ~np.isfinite(x)
            if bad.any():
                raise LogImportError(f"channel {ch.name}: {int(bad.sum())} NaN/inf values cannot be sent on CAN "
                                     f"(first at t = {tm[np.flatnonzero(bad)[0]]:.3f} s)")
            raw = np.round((x - ch.offset) / ch.resolution)
            if raw.min() < 0 or raw.max() >= (1 << ch.bits):
                raise LogImportError(f"channel {ch.name}: value outside the DBC range of the signal")
            word |= raw.astype(np.uint64) << np.uint64(start)
        rows_t.append(tm - t[0])
        rows_id.append(np.full(n, msg.frame_id))
        rows_data.append(word.astype("<u8").view(np.uint8).reshape(n, 8))
    tt = np.concatenate(rows_t)
    order = np.argsort(tt, kind="stable")
    n = tt.size
    return CanFrames(tt[order], np.ones(n, dtype=np.int64), np.concatenate(rows_id)[order], np.zeros(n, dtype=bool),
                     np.full(n, 8), np.concatenate(rows_data)[order], float(trip.meta.get("t0_unix", 0.0) or 0.0))


def mapping_for(channels: list[ExportChannel], dbc_name: str, fmt: str, sample_rate: float) -> dict[str, Any]:
    """The mapping that imports an exported log back into the same Trip channels."""
    msg_of = {ch.name: msg.name for msg in _layout(channels) for ch, _ in msg.signals}
    top_rate = max(c.rate for c in channels)
    return {"name": f"roadload_export_{Path(dbc_name).stem}", "format": fmt, "sample_rate": sample_rate,
            "description": "generated by roadload export-can: reads the exported log back into Trip channels",
            "dbc": [{"file": dbc_name, "bus": 1}],
            "channels": [{"source": f"{msg_of[c.name]}.{c.name}", "channel": c.name, "unit": c.unit,
                          "resample": "linear" if c.rate == top_rate else "hold",
                          "required": c.rate == top_rate} for c in channels]}


_SUFFIX = {"candump": ".log", "blf": ".blf", "mf4": ".mf4", "asc": ".asc"}
_IMPORT_FORMAT = {"candump": "candump", "blf": "blf", "asc": "asc", "mf4": "dbc-mf4"}


def export_trip(trip: Trip, path: str | Path, fmt: str, *, sensors: Any | None = None,
                channels: list[str] | None = None, rates: dict[str, float] | None = None) -> dict[str, Path]:
    """Write trip channels as a CAN log (candump | blf | mf4 | asc) plus ``<log>.dbc`` and ``<log>.mapping.json``.

    sensors: a SensorSpec (resolution, rate per channel); by default the spec the simulator stored in the trip's
    metadata (``sensors_from_meta``), else defaults. Returns the written paths.
    """
    if fmt not in _SUFFIX:
        raise LogImportError(f"unknown CAN export format {fmt!r}{did_you_mean(fmt, _SUFFIX)}; choose one of "
                             f"{sorted(_SUFFIX)}")
    path = Path(path)
    if path.suffix.lower() != _SUFFIX[fmt]:
        path = path.with_suffix(_SUFFIX[fmt])
    if sensors is None:
        sensors = sensors_from_meta(trip.meta)
    chans = export_channels(trip, sensors, channels, rates)
    frames = encode_trip(trip, chans)
    path.parent.mkdir(parents=True, exist_ok=True)
    dbc_path = path.with_suffix(".dbc")
    map_path = path.with_name(path.stem + ".mapping.json")
    vehicle = trip.meta.get("vehicle", {}).get("name", "vehicle") if isinstance(trip.meta.get("vehicle"), dict) \
        else str(trip.meta.get("vehicle", "vehicle"))
    write_text(dbc_path, dbc_text(chans, vehicle))
    mapping = mapping_for(chans, dbc_path.name, _IMPORT_FORMAT[fmt], trip.sample_rate)
    write_text(map_path, json.dumps(mapping, indent=1))
    write_can_log(frames, path, fmt)
    return {"log": path, "dbc": dbc_path, "mapping": map_path}


def sensors_from_meta(meta: dict[str, Any]):
    """The SensorSpec a simulated trip was measured with: ``meta["sensors"]`` (the simulator's record), else
    ``meta["vehicle"]["sensors"]``; None for trips without one (real logs)."""

    raw = meta.get("sensors")
    if not isinstance(raw, dict):
        vehicle = meta.get("vehicle")
        raw = vehicle.get("sensors") if isinstance(vehicle, dict) else None
    if not isinstance(raw, dict):
        return None
    try:
        channels = {k: ChannelSensorSpec(**v) for k, v in raw.get("channels", {}).items()}
        return SensorSpec(**{**raw, "channels": channels})
    except TypeError as exc:
        raise LogImportError(f"trip metadata 'sensors' is not a sensor spec: {exc}") from None


# ---------------------------------------------------------------------------------------------- file exports
FILE_FORMATS = {"mf4": ".mf4", "csv": ".csv", "mat": ".mat"}


def export_file(trip: Trip, path: str | Path, fmt: str, *, truth: bool = False) -> Path:
    """Write ``trip`` as an MDF4, CSV or MATLAB file (see the module docstring); atomic, returns the path.
    ``truth``: also the ground truth of a simulated trip (refused for a trip without truth)."""
    if fmt not in FILE_FORMATS:
        raise LogImportError(f"unknown export format {fmt!r}{did_you_mean(fmt, FILE_FORMATS)}; choose one of "
                             f"{list(FILE_FORMATS)}")
    path = Path(path)
    if path.suffix.lower() != FILE_FORMATS[fmt]:
        raise LogImportError(f"{path}: a {fmt} export ends in {FILE_FORMATS[fmt]}")
    if not trip.channels:
        raise LogImportError(f"trip {trip.meta.get('name', '?')!r} has no measured channel besides 't': nothing to "
                             f"export")
    if truth and trip.truth is None:
        raise LogImportError(f"trip {trip.meta.get('name', '?')!r} has no ground truth (not simulated); export it "
                             f"without --truth")
    writer = {"mf4": _write_mf4, "csv": _write_csv, "mat": _write_mat}[fmt]
    with atomic_path(path) as tmp:
        writer(trip, tmp, truth)
    return path


def _description(name: str, truth: bool) -> str:
    table = TRUTH if truth else MEASURED
    return table[name].description if name in table else ""


def _write_mf4(trip: Trip, path: Path, truth: bool) -> None:
    from asammdf import MDF, Signal

    mdf = MDF(version="4.10")
    t = trip.t
    mdf.append([Signal(trip.measured[c].to_numpy(), t, name=c, unit=trip.units[c], comment=_description(c, False))
                for c in trip.channels], comment="measured channels (SI)")
    if truth and trip.truth is not None:
        tt = trip.truth["t"].to_numpy(dtype=float)
        mdf.append([Signal(trip.truth[c].to_numpy(), tt, name=TRUTH_PREFIX + c, unit=trip.truth_units[c],
                           comment=_description(c, True)) for c in trip.truth.columns if c != "t"],
                   comment="ground truth of the simulation (not a measurement)")
    mdf.attach(json.dumps(trip.meta).encode("utf-8"), file_name="roadload_meta.json", embedded=True,
               mime="application/json")
    mdf.save(path, overwrite=True)
    mdf.close()


def _export_frame(trip: Trip, truth: bool) -> tuple[pd.DataFrame, list[str]]:
    """Measured (and truth) channels as one frame on the union of their time bases, with the unit of each column."""
    frame = trip.measured
    units = [trip.units[c] for c in frame.columns]
    if truth and trip.truth is not None:
        tr = trip.truth.rename(columns={c: TRUTH_PREFIX + c for c in trip.truth.columns if c != "t"})
        frame = frame.merge(tr, on="t", how="outer", sort=True)
        units += [trip.truth_units[c] for c in trip.truth.columns if c != "t"]
    return frame, units


def _write_csv(trip: Trip, path: Path, truth: bool) -> None:
    frame, units = _export_frame(trip, truth)
    with open(path, "w", encoding="utf-8", newline="") as fh:
        fh.write(",".join(frame.columns) + "\n")
        fh.write(",".join(units) + "\n")
        frame.to_csv(fh, header=False, index=False, lineterminator="\n")


_MATLAB_NAME = re.compile(r"^[A-Za-z][A-Za-z0-9_]{0,62}$")


def _matlab_struct(frame: pd.DataFrame, what: str) -> dict[str, np.ndarray]:
    bad = [c for c in frame.columns if not _MATLAB_NAME.match(c)]
    if bad:
        raise LogImportError(f"{what} channels {bad} are not MATLAB field names (a letter, then letters, digits or "
                             f"'_', at most 63 characters); rename them before a .mat export")
    return {c: frame[c].to_numpy() for c in frame.columns}


def _write_mat(trip: Trip, path: Path, truth: bool) -> None:
    from scipy.io import savemat

    data: dict[str, object] = {"measured": _matlab_struct(trip.measured, "measured"),
                               "units": {c: trip.units[c] for c in trip.measured.columns},
                               "meta_json": json.dumps(trip.meta)}
    if truth and trip.truth is not None:
        data["truth"] = _matlab_struct(trip.truth, "truth")
        data["truth_units"] = {c: trip.truth_units[c] for c in trip.truth.columns}
    with open(path, "wb") as fh:
        savemat(fh, data, long_field_names=True, do_compression=True, oned_as="column")
