"""The diagnosis table: recorded trips -> one row per 10 Hz sample of the chapter-5 pipeline's states, with the
measured force F_xV,measured, the sim's force balance F_xV,sim and the regime columns.

Per trip the chapter-5 pipeline (:func:`roadload.estimators.pipeline.run_pipeline`, with the estimating-side
knowledge of the sim's vehicle) gives v_V, v̇_V, θ, 1/r, gear and F_xV from the drive torque (eq. 5.5c). Added:

=====================  ==============================================================================
trip, t                trip name, time [s]
time_since_start       t - t_0 [s]; distance [m] integrated speed
air_density            ρ_a [kg/m³] from the trip's ambient temperature (else the sim's ambient)
brake_force            F_B = Σ 2 p_B A_B r_B X_B / r_W [N] from the brake pressures with the sim's brakes;
                       the pressures pass the pipeline's smoother bank first (:func:`smoothed_pressure`), so
                       F_B carries the same smoothing and delay as dv/dt and the drive force
drive_force            F_xV from the drive torque (pipeline) [N]
tractive_force         F_xV,measured = drive_force - brake_force [N]
sim_balance            F_xV,sim of :class:`.forcemodel.SimForceModel` for the measured motion [N]
sim_force              sim_balance + the sim's floor (:mod:`.floor`) [N]
residual               tractive_force - sim_force [N]
rotational_mass        (I_red(G) + I_W) / r_W² [kg]: the rotating parts' inertia the pipeline takes out of
                       the drive torque (eq. 2.16b/2.17; I_W alone for a logged rim torque)
sim_drive_force(_rate) the force the drive torque delivers at the wheels in the sim's balance, sim_force +
                       brake_force + rotational_mass dv/dt [N] (what T i η / r_W must be), and its time derivative
                       [N/s]: a torque-signal gain g changes the measured force by g times this, not by g F_xV
lateral_acceleration   v² / r [m/s²]; heading: integrated yaw rate [rad] (NaN without yaw rate)
mode                   'traction' / 'coast' / 'regen' / 'braking'; time_since_brake [s] (0 while braking)
ambient_temperature, heating_power, payload [kg] (metadata), season
electric_power, sim_electric_power, power_residual, aux_power_logged: the energy side [W] (:mod:`.energy`)
valid                  moving (v > 1 m/s), smoothers settled, drive-train engaged, finite; on trips without
                       brake pressure also not braking and not at the regenerative torque floor (unknown
                       friction-brake force)
=====================  ==============================================================================
"""

from __future__ import annotations

import dataclasses

import re
from dataclasses import dataclass, field
from typing import Sequence

import numpy as np
import pandas as pd

from roadload.estimators.pipeline import PipelineError, PipelineSettings, knowledge_from_spec, run_pipeline
from roadload.estimators.pks import pks_bank
from roadload.trip import Trip
from roadload.units import KELVIN, air_density

from .energy import power_columns
from .errors import DiagnosisError
from .forcemodel import SimForceModel
from .records import Record
from .simconfig import SimConfig

MIN_SPEED = 1.0               # m/s, slower samples are not diagnosed (standstill, creeping)
BRAKE_PRESSURE_ON = 2.0e4     # Pa, brake pressure counted as braking (pipeline's threshold)
REQUIRED_CHANNELS = ("vehicle_speed", "accel_x")


def trip_name(trip: Trip, i: int) -> str:
    return str(trip.meta.get("name") or trip.meta.get("trip") or f"trip{i}")


def trip_vehicle(trip: Trip) -> str | None:
    v = trip.meta.get("vehicle")
    if isinstance(v, dict):
        return v.get("name")
    return v if isinstance(v, str) else None


def check_trip(trip: Trip, sim: SimConfig, i: int) -> None:
    """DiagnosisError naming what a trip lacks or where it contradicts the sim's vehicle."""
    name = trip_name(trip, i)
    missing = [c for c in REQUIRED_CHANNELS if not trip.has(c)]
    if not (trip.has("drive_torque") or trip.has("rim_torque")):
        missing.append("drive_torque (or rim_torque)")
    if missing:
        raise DiagnosisError(f"trip {name!r} lacks the channels {missing} that the force residual needs; "
                             f"it has {trip.channels}")
    veh = trip_vehicle(trip)
    if veh is not None and veh != sim.vehicle.name:
        raise DiagnosisError(f"trip {name!r} was recorded with vehicle {veh!r}, but the sim config models "
                             f"{sim.vehicle.name!r}; pass a sim config of that vehicle")
    if trip.has("gear"):
        g = trip.channel("gear")
        g = g[np.isfinite(g)]
        n = sim.vehicle.drivetrain.n_gears
        if g.size and g.max() > n + 0.5:
            raise DiagnosisError(f"trip {name!r} engages gear {int(g.max())}, but the sim's vehicle "
                                 f"{sim.vehicle.name!r} has {n} gear(s): the sim config does not match the vehicle")


def _season(trip: Trip, ambient: np.ndarray) -> str:
    ov = trip.meta.get("overview") or {}
    date = str(ov.get("Date") or trip.meta.get("date") or "")
    m = re.match(r"\s*\d{4}[-_/](\d{2})", date)
    month = int(m.group(1)) if m else None
    if month is None:
        a = ambient[np.isfinite(ambient)]
        if not a.size:
            return "unknown"
        c = float(np.median(a)) - KELVIN
        return "winter" if c < 8 else "summer" if c > 18 else "spring"
    return {12: "winter", 1: "winter", 2: "winter", 3: "spring", 4: "spring", 5: "spring", 6: "summer",
            7: "summer", 8: "summer"}.get(month, "autumn")


def _sample(trip: Trip, name: str, t: np.ndarray) -> np.ndarray:
    if not trip.has(name):
        return np.full(t.shape, np.nan)
    x = trip.channel(name)
    tt = trip.t
    ok = np.isfinite(x)
    if ok.sum() < 2:
        return np.full(t.shape, np.nan)
    return np.interp(t, tt[ok], x[ok])


def time_since(flag: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Seconds since ``flag`` was last true (0 while it is, NaN before it ever was)."""
    last = np.where(np.asarray(flag, bool), t, np.nan)
    last = pd.Series(last).ffill().to_numpy()
    return t - last


def smoothed_pressure(trip: Trip, channel: str, t: np.ndarray, settings: PipelineSettings) -> np.ndarray:
    """A brake-pressure channel [Pa] through the same polynomial Kalman smoother configuration as the pipeline's
    continuous channels (window and forgetting scaled to the trip's rate), aligned like them (the smoothed value
    belongs to t - delay) and sampled at ``t``. Without it F_B is a raw step while dv/dt and the drive force are
    smoothed: every brake application then leaves a kN residual transient that no road-load effect explains."""
    x = trip.channel(channel)
    rate = trip.sample_rate
    cfg = dict(settings.smoother)
    scale = rate / settings.smoother_rate
    if abs(scale - 1.0) > 1e-6:
        cfg["window"] = max(1, int(round(cfg.get("window", 20) * scale)))
        cfg["forgetting"] = float(cfg.get("forgetting", 0.9)) ** (1.0 / scale)
    bank = pks_bank({channel: np.nan_to_num(np.asarray(x, dtype=float))}, dt=1.0 / rate, derivatives=1, **cfg)
    d = int(bank.delay)
    if len(x) <= d + 1:
        return np.interp(t, trip.t, np.nan_to_num(x))
    return np.interp(t, trip.t[:len(x) - d], bank.value[channel][d:])


def brake_force_from_pressure(vehicle, p_front: np.ndarray, p_rear: np.ndarray) -> np.ndarray:
    """F_B = 2 (p_f A_f r_f + p_r A_r r_r) X_B / r_W [N] (two wheels per axle, nominal pad friction X_B)."""
    b = vehicle.brakes
    pf = np.clip(np.nan_to_num(p_front), 0, None)
    pr = np.clip(np.nan_to_num(p_rear), 0, None)
    return 2.0 * (pf * b.front_area * b.front_radius + pr * b.rear_area * b.rear_radius) * b.pad_friction \
        / vehicle.wheel_radius


@dataclass
class TripInfo(Record):
    """What a trip's metadata says about it: date, season, median ambient temperature [°C], extra payload [kg],
    the logger's note, and the samples it has in the table."""

    trip: str
    date: str
    season: str
    ambient_c: float
    payload_kg: float | None
    note: str
    samples: int

    @classmethod
    def of(cls, trip: Trip, name: str, frame: pd.DataFrame) -> "TripInfo":
        ov = trip.meta.get("overview") or {}
        amb = frame["ambient_temperature"].to_numpy(dtype=float)
        amb = amb[np.isfinite(amb)]
        payload = trip.meta.get("extra_payload_kg")
        return cls(name, str(ov.get("Date") or trip.meta.get("date") or ""), str(frame["season"].iloc[0]),
                   float(np.median(amb)) - KELVIN if amb.size else float("nan"),
                   float(payload) if payload is not None else None,
                   str(ov.get("Note") or trip.meta.get("note") or "").strip(), len(frame))


@dataclass
class DiagnosisTable:
    """The table (see module doc), the sim's force model, notes (pipeline fallbacks, per trip) and each trip's
    metadata."""

    frame: pd.DataFrame
    model: SimForceModel
    notes: dict[str, list[str]] = field(default_factory=dict)
    trips: list[TripInfo] = field(default_factory=list)

    @property
    def residual(self) -> np.ndarray:
        return self.frame["residual"].to_numpy(dtype=float)


def sim_force_model(sim: SimConfig) -> SimForceModel:
    """The sim's force balance, with the sim's own effects where they are constant (initial payload)."""
    spec = sim.vehicle
    mass = spec.mass
    if sim.effects.enabled("payload"):
        mass += float(sim.effects.params("payload")["initial_payload"])
    know = knowledge_from_spec(spec)
    d = know.drivetrain
    eta = float(np.mean(d.gearbox_efficiency)) * float(d.differential_efficiency)
    base = SimForceModel.from_spec(spec, mass=mass)
    return dataclasses.replace(base, drivetrain_efficiency=eta)


def build_table(trips: Sequence[Trip], sim: SimConfig, settings: PipelineSettings | None = None,
                model: SimForceModel | None = None, floor=None) -> DiagnosisTable:
    """The diagnosis table of ``trips`` against ``sim`` (DiagnosisError naming missing channels or mismatches)."""
    if not trips:
        raise DiagnosisError("no trips given")
    knowledge = knowledge_from_spec(sim.vehicle)
    model = model or sim_force_model(sim)
    frames, notes, infos = [], {}, []
    names = set()
    for i, trip in enumerate(trips):
        check_trip(trip, sim, i)
        name = trip_name(trip, i)
        if name in names:
            name = f"{name}#{i}"
        names.add(name)
        try:
            res = run_pipeline(trip, knowledge, settings)
        except PipelineError as exc:
            raise DiagnosisError(f"trip {name!r}: {exc}") from None
        notes[name] = list(res.notes)
        frames.append(_trip_frame(trip, name, res, sim, knowledge, settings or PipelineSettings(), notes[name]))
        infos.append(TripInfo.of(trip, name, frames[-1]))
    frame = pd.concat(frames, ignore_index=True)
    out = finish_table(frame, model, notes, floor)
    out.trips = infos
    return out


def _trip_frame(trip: Trip, name: str, res, sim: SimConfig, knowledge, st: PipelineSettings,
                notes: list[str]) -> pd.DataFrame:
    """One trip's rows of the table (module doc) from its pipeline result ``res``; notes appended to ``notes``."""
    s = res.states
    t = s["t"].to_numpy(dtype=float)
    v = s["speed"].to_numpy(dtype=float)
    f = pd.DataFrame({"trip": name, "t": t})
    for c in ("speed", "acceleration", "gradient_angle", "path_curvature", "gear", "drive_torque"):
        f[c] = s[c].to_numpy(dtype=float)
    f["time_since_start"] = t - float(trip.t[0])
    f["distance"] = np.concatenate([[0.0], np.cumsum(0.5 * (v[1:] + v[:-1]) * np.diff(t))])
    amb = _sample(trip, "ambient_temperature", t)
    amb_fill = np.where(np.isfinite(amb), amb, sim.effects.ambient_temperature)
    pres = _sample(trip, "ambient_pressure", t)
    pres = np.where(np.isfinite(pres), pres, sim.effects.ambient_pressure)
    f["ambient_temperature"] = amb
    f["elevation"] = _sample(trip, "elevation", t)
    f["air_density"] = air_density(amb_fill, pres)
    has_brakes, braking = _brake_columns(f, trip, res, sim, st)
    f["drive_force"] = s["tractive_force"].to_numpy(dtype=float)
    f["tractive_force"] = f["drive_force"] - f["brake_force"]
    f["time_since_brake"] = time_since(braking, t)
    f["rotational_mass"] = _rotational_mass(knowledge.drivetrain, f["gear"].to_numpy(dtype=float),
                                            trip.has("drive_torque"))
    _path_columns(f, trip, notes)
    torque = f["drive_torque"].to_numpy(dtype=float)
    min_tq = st.min_drive_torque
    f["mode"] = np.where(braking, "braking", np.where(torque > min_tq, "traction",
                                                      np.where(torque < -min_tq, "regen", "coast")))
    f["heating_power"] = _sample(trip, "heating_power", t)
    payload = trip.meta.get("extra_payload_kg")
    f["payload"] = float(payload) if payload is not None else (0.0 if trip.meta.get("overview") else np.nan)
    f["season"] = _season(trip, amb)
    valid = _valid_rows(s, v, t, st, notes)
    if not has_brakes:
        torque_floor = max(st.drive_torque_floor, knowledge.drive_torque_floor)
        valid &= ~braking & (torque > torque_floor)
    for key, col in power_columns(trip, f, sim).items():
        f[key] = col
    f["has_brake_pressure"] = has_brakes
    f["valid_base"] = valid
    return f


def _brake_columns(f: pd.DataFrame, trip: Trip, res, sim: SimConfig, st: PipelineSettings
                   ) -> tuple[bool, np.ndarray]:
    """brake_force [N] into ``f``; (whether the trip logs brake pressure, the braking rows). Without brake
    pressure the braking rows are the pipeline's (its no-brake trigger off)."""
    dec = res.stages["decimated"]
    t = f["t"].to_numpy(dtype=float)
    zero = 0.0 * f["speed"].to_numpy(dtype=float)
    if not any(c in dec for c in ("brake_pressure_front", "brake_pressure_rear")):
        f["brake_force"] = 0.0
        return False, ~res.states["trigger_no_brake"].to_numpy(dtype=bool)
    pf = dec["brake_pressure_front"].to_numpy(dtype=float) if "brake_pressure_front" in dec else zero
    pr = dec["brake_pressure_rear"].to_numpy(dtype=float) if "brake_pressure_rear" in dec else zero
    braking = np.maximum(np.nan_to_num(pf), np.nan_to_num(pr)) > BRAKE_PRESSURE_ON
    pf_s = smoothed_pressure(trip, "brake_pressure_front", t, st) if trip.has("brake_pressure_front") else zero
    pr_s = smoothed_pressure(trip, "brake_pressure_rear", t, st) if trip.has("brake_pressure_rear") else zero
    f["brake_force"] = brake_force_from_pressure(sim.vehicle, pf_s, pr_s)
    braking |= np.maximum(np.nan_to_num(pf_s), np.nan_to_num(pr_s)) > BRAKE_PRESSURE_ON
    return True, braking


def _path_columns(f: pd.DataFrame, trip: Trip, notes: list[str]) -> None:
    """lateral_acceleration [m/s²], path_curvature (0 without a steering signal) and heading [rad] into ``f``."""
    v = f["speed"].to_numpy(dtype=float)
    f["lateral_acceleration"] = v ** 2 * f["path_curvature"].to_numpy(dtype=float)
    if not np.isfinite(f["path_curvature"].to_numpy(dtype=float)).any():
        # no steering signal: the balance goes without cornering resistance (lateral regime stays NaN)
        f["path_curvature"] = 0.0
        notes.append("no path curvature: cornering resistance left out of the sim's balance")
    if trip.has("yaw_rate"):
        yr = np.nan_to_num(trip.channel("yaw_rate"))
        tt = trip.t
        head = np.concatenate([[0.0], np.cumsum(0.5 * (yr[1:] + yr[:-1]) * np.diff(tt))])
        f["heading"] = np.interp(f["t"].to_numpy(dtype=float), tt, head)
    else:
        f["heading"] = np.nan


def _valid_rows(s: pd.DataFrame, v: np.ndarray, t: np.ndarray, st: PipelineSettings, notes: list[str]
                ) -> np.ndarray:
    """Moving, smoothers settled, no wheel slip, rim torque available (before the braking rules)."""
    no_slip = s["trigger_no_slip"].to_numpy(dtype=bool)
    moving = v > MIN_SPEED
    if moving.sum() > 100 and no_slip[moving].mean() < 0.1:
        # "slip" on (nearly) every moving sample: the logged motor speed does not fit the sim vehicle's drive
        # ratio (a preset that is not the car) — the slip check says nothing then and is left out
        no_slip = np.ones_like(no_slip)
        notes.append("wheel-slip check left out: the logged engine/motor speed does not fit the sim "
                     "vehicle's drive ratio on >= 90 % of the moving samples (check the vehicle's gear "
                     "ratios and wheel radius)")
    valid = moving & (t >= t[0] + st.warmup) & no_slip
    return valid & s["trigger_rim_torque_available"].to_numpy(dtype=bool)


def _rotational_mass(drivetrain, gear: np.ndarray, from_drive_torque: bool) -> np.ndarray:
    """Per row the rotating parts' equivalent mass [kg] the pipeline subtracts from the torque's force: (I_red(G) +
    I_W) / r_W² for the engaged gear (the first where unknown), I_W / r_W² when the force comes from a logged rim
    torque (eq. 2.16b)."""
    if not from_drive_torque:
        return np.full(gear.shape, drivetrain.wheel_inertia / drivetrain.wheel_radius ** 2)
    per_gear = np.array([drivetrain.rotational_mass(g) for g in range(1, drivetrain.n_gears + 1)])
    g = np.clip(np.rint(np.nan_to_num(gear, nan=1.0)), 1, drivetrain.n_gears).astype(int)
    return per_gear[g - 1]


def _drive_columns(frame: pd.DataFrame, force: np.ndarray) -> None:
    """sim_drive_force = force + brake_force + rotational_mass dv/dt [N] and its time derivative per trip [N/s], in
    place (a table without rotational_mass: force + brake_force)."""
    sdf = np.asarray(force, dtype=float) + frame["brake_force"].to_numpy(dtype=float)
    if "rotational_mass" in frame.columns:
        sdf = sdf + frame["rotational_mass"].to_numpy(dtype=float) * np.nan_to_num(
            frame["acceleration"].to_numpy(dtype=float))
    frame["sim_drive_force"] = sdf
    rate = np.zeros_like(sdf)
    t = frame["t"].to_numpy(dtype=float)
    for k in pd.unique(frame["trip"]):
        sel = (frame["trip"] == k).to_numpy()
        if sel.sum() > 2:
            rate[sel] = np.gradient(sdf[sel], t[sel])
    frame["sim_drive_force_rate"] = rate


def finish_table(frame: pd.DataFrame, model: SimForceModel, notes: dict | None = None, floor=None,
                 trips: list[TripInfo] | None = None) -> DiagnosisTable:
    """Add sim_balance (the analytic balance), sim_force (balance + the sim's floor, :mod:`.floor`), residual,
    sim_drive_force(_rate) and valid (finite everywhere it matters)."""
    frame = frame.copy()
    balance = model.predict(frame)
    frame["sim_balance"] = balance
    _drive_columns(frame, balance)        # provisional, from the balance alone: what the floor was fitted on
    frame["sim_force"] = balance + (floor.predict(frame, balance) if floor is not None else 0.0)
    frame["residual"] = frame["tractive_force"].to_numpy(dtype=float) - frame["sim_force"].to_numpy(dtype=float)
    _drive_columns(frame, frame["sim_force"].to_numpy(dtype=float))
    if floor is not None and "power_residual" in frame.columns:
        p_floor = floor.predict_power(frame)
        frame["sim_electric_power"] = frame["sim_electric_power"].to_numpy(dtype=float) + p_floor
        frame["power_residual"] = frame["power_residual"].to_numpy(dtype=float) - p_floor
    valid = frame["valid_base"].to_numpy(dtype=bool).copy() if "valid_base" in frame else np.ones(len(frame), bool)
    for c in ("speed", "acceleration", "gradient_angle", "residual", "sim_drive_force_rate"):
        valid &= np.isfinite(frame[c].to_numpy(dtype=float))
    frame["valid"] = valid
    if not valid.any():
        raise DiagnosisError("no valid samples in the trips (moving, drive-train engaged, finite states)")
    return DiagnosisTable(frame, model, notes or {}, list(trips or []))
