"""The chapter-5 preprocessing pipeline: CAN channels of a Trip -> vehicle states -> trigger -> (A, B).

Stages (each a DataFrame, inspectable and plottable, see :func:`run_pipeline` and
:func:`roadload.estimators.figures.plot_stage`):

``measured``  the Trip's measured channels as recorded (e.g. 100 Hz);
``smoothed``  every continuous channel through a bank of polynomial Kalman smoothers with one configuration
              (section 5.3), so all smoothed channels carry the same, known delay; the smoothers also give the
              derivatives dv_V/dt and the wheel angular acceleration (of the mean wheel speed 'wheel_speed').
              Rows are aligned to the time the smoothed value belongs to (t - delay); discrete channels (gear,
              clutch, brake pressure) are taken at that time;
``decimated`` every k-th row, k = sample rate / estimation rate (100 Hz -> 10 Hz);
``states``    v_V, dv_V/dt, gradient angle θ (eq. 5.2), path curvature 1/r (eq. 5.3 through the steering-ratio
              table), rim torque T_R from the estimating side's drive-train model (eq. 2.17), tractive force
              F_xV (eq. 5.5c), the five trigger conditions of section 5.3 and the trigger.

:func:`model_data` then gives the measured inputs A and output B of a model structure on the triggered samples.

The estimating side knows the vehicle only through :class:`VehicleKnowledge` (nominal parameters, its own
drive-train model with its own loss tables, the steering-ratio table); it never reads a Trip's truth.
"""

from __future__ import annotations

import dataclasses
import os
import warnings
from dataclasses import dataclass, field
from typing import Annotated, Literal, Sequence

import numpy as np
import pandas as pd

from roadload.trip import Trip
from roadload.units import G

from .models import (ACCELERATION, GRADIENT_ANGLE, PATH_CURVATURE, SPEED, TRACTIVE_FORCE, ModelStructure,
                     NominalParameters, get_model)
from roadload.road_load import RoadLoadParameters
from roadload.units import STANDARD_AIR_DENSITY
from pydantic import Field, Strict, model_validator

from .config import EstimatorConfigError, Real, _setting, settings_dataclass
from .pks import PKSDesign, pks_bank

STAGES = ("measured", "smoothed", "decimated", "states")

# continuous channels that pass the smoother bank (when present)
SMOOTHED_CHANNELS = ("vehicle_speed", "accel_x", "drive_torque", "engine_speed", "steering_wheel_angle",
                     "wheel_speed_fl", "wheel_speed_fr", "wheel_speed_rl", "wheel_speed_rr", "rim_torque", "grade")
# channels taken as they are (discrete or thresholded), aligned to the smoothed time base
DISCRETE_CHANNELS = ("gear", "clutch", "brake_pressure_front", "brake_pressure_rear")
WHEEL_SPEEDS = ("wheel_speed_fl", "wheel_speed_fr", "wheel_speed_rl", "wheel_speed_rr")
TRIGGER_CONDITIONS = ("no_brake", "moving", "no_slip", "torque", "rim_torque_available")
PIPELINE_CHANNELS = tuple(dict.fromkeys(SMOOTHED_CHANNELS + DISCRETE_CHANNELS))
"""Every measured channel the pipeline reads (when present)."""
GradientSource = Literal["accelerometer", "grade_channel", "auto"]
"""Where the gradient angle comes from (:class:`PipelineSettings`.gradient)."""


class PipelineError(ValueError):
    """A trip cannot be preprocessed (missing channels, bad settings, unknown stage); the message names what."""


# ================================================================================ the estimating side's vehicle
@dataclass(frozen=True)
class DrivetrainModel:
    """The estimating side's drive-train model (eq. 2.17, section 5.2.1) with its own loss tables.

    gear_ratios: i_G(G) for G = 1..n; final_drive: i_D; wheel_radius: r_W [m]; wheel_inertia: I_W of all four
    wheels [kg m^2]; reduced_inertia: I_red(G) at the wheels per gear [kg m^2]; gearbox_efficiency: η_G(G) per
    gear and gearbox_drag: constant drag torque per gear at the gearbox input [N m] (the loss table
    f(T_G, θ̇_G, G) ≈ (1 - η_G) |T_G| i_G + drag i_G); differential_efficiency η_D and differential_drag [N m at
    the differential input] (f(T_D, θ̇_D) ≈ (1 - η_D) |T_D| i_D + drag_D i_D).
    slip_tolerance: relative difference of engine and gear-shaft speed still counted as engaged (condition 3).
    """

    gear_ratios: tuple[float, ...]
    final_drive: float
    wheel_radius: float
    wheel_inertia: float
    reduced_inertia: tuple[float, ...]
    gearbox_efficiency: tuple[float, ...]
    gearbox_drag: tuple[float, ...]
    differential_efficiency: float
    differential_drag: float = 0.0
    slip_tolerance: float = 0.05

    def __post_init__(self) -> None:
        n = len(self.gear_ratios)
        if n < 1:
            raise PipelineError("DrivetrainModel.gear_ratios: needs at least one gear")
        for name in ("reduced_inertia", "gearbox_efficiency", "gearbox_drag"):
            if len(getattr(self, name)) != n:
                raise PipelineError(f"DrivetrainModel.{name}: needs one value per gear ({n}), "
                                    f"got {len(getattr(self, name))}")
        if any(not 0.5 < e <= 1.0 for e in self.gearbox_efficiency) or not 0.5 < self.differential_efficiency <= 1:
            raise PipelineError("DrivetrainModel: efficiencies must lie in (0.5, 1]")
        for name in ("final_drive", "wheel_radius"):
            if not getattr(self, name) > 0:
                raise PipelineError(f"DrivetrainModel.{name}: must be > 0")

    @property
    def n_gears(self) -> int:
        return len(self.gear_ratios)

    def rotational_mass(self, gear: int | None = None) -> float:
        """(I_red(G) + I_W) / r_W^2 [kg]: the equivalent mass of the rotating parts that :meth:`rim_torque` and
        :meth:`tractive_force` take out of F_xV (eq. 2.16b/2.17), so a model fitted to F_xV does NOT contain it.
        gear None: the single gear, the middle gear of a multi-speed box (1-based), the top gear of a truck's box
        of >= 10 gears (where a long-haul truck spends its time)."""
        g = gear if gear is not None else (1 if self.n_gears == 1 else self.n_gears if self.n_gears >= 10
                                           else self.n_gears // 2 + 1)
        if not 1 <= g <= self.n_gears:
            raise PipelineError(f"gear must be in 1..{self.n_gears}, got {g}")
        return float((self.reduced_inertia[g - 1] + self.wheel_inertia) / self.wheel_radius ** 2)

    def _per_gear(self, values: Sequence[float], gear: np.ndarray) -> np.ndarray:
        table = np.concatenate([[np.nan], np.asarray(values, dtype=float)])
        g = np.asarray(gear)
        valid = np.isfinite(g) & (g >= 1) & (g <= self.n_gears)
        idx = np.where(valid, np.rint(np.where(valid, g, 0)), 0).astype(int)
        return table[idx]

    def overall_ratio(self, gear: np.ndarray) -> np.ndarray:
        """i_G(G) i_D; NaN where the gear is 0 (neutral) or unknown."""
        return self._per_gear(self.gear_ratios, gear) * self.final_drive

    def rim_torque(self, drive_torque: np.ndarray, gear: np.ndarray, wheel_acceleration: np.ndarray) -> np.ndarray:
        """Σ T_R [N m] from the engine / motor torque T_E [N m], gear G and wheel angular acceleration θ̈_W
        [rad/s^2] (eq. 2.17 without the brake torque; NaN in neutral). Losses oppose the power flow."""
        t_e = np.asarray(drive_torque, dtype=float)
        i_g = self._per_gear(self.gear_ratios, gear)
        eta_g = self._per_gear(self.gearbox_efficiency, gear)
        drag = self._per_gear(self.gearbox_drag, gear)
        t_g = t_e * i_g
        t_d = np.where(t_g >= 0, t_g * eta_g, t_g / eta_g) - drag * i_g
        t_w = t_d * self.final_drive
        eta_d = self.differential_efficiency
        t_w = np.where(t_w >= 0, t_w * eta_d, t_w / eta_d) - self.differential_drag * self.final_drive
        i_red = self._per_gear(self.reduced_inertia, gear)
        return t_w - i_red * np.asarray(wheel_acceleration, dtype=float)

    def tractive_force(self, rim_torque: np.ndarray, wheel_acceleration: np.ndarray) -> np.ndarray:
        """F_xV = (T_R - I_W θ̈_W) / r_W [N] (eq. 2.16b / 5.5c)."""
        return (np.asarray(rim_torque, dtype=float) - self.wheel_inertia * np.asarray(wheel_acceleration)) \
            / self.wheel_radius


@dataclass(frozen=True)
class SteeringGeometry:
    """Steering-ratio table δ_W12 = f(δ_S) and the geometry of eq. 5.3.

    wheelbase: l = l_12 + l_34 [m]; rear_axle_distance: l_34, CG to rear axle [m]; steering_wheel_angle /
    wheel_angle: the table [rad] (strictly increasing, through 0).
    """

    wheelbase: float
    rear_axle_distance: float
    steering_wheel_angle: tuple[float, ...]
    wheel_angle: tuple[float, ...]

    def __post_init__(self) -> None:
        if not (self.wheelbase > 0 and 0 < self.rear_axle_distance < self.wheelbase):
            raise PipelineError(f"SteeringGeometry: need wheelbase > 0 and 0 < l_34 < wheelbase, got "
                                f"{self.wheelbase}, {self.rear_axle_distance}")
        s = np.asarray(self.steering_wheel_angle, dtype=float)
        w = np.asarray(self.wheel_angle, dtype=float)
        if s.shape != w.shape or s.size < 2 or np.any(np.diff(s) <= 0) or np.any(np.diff(w) <= 0):
            raise PipelineError("SteeringGeometry: the steering table needs >= 2 strictly increasing pairs")

    def wheel_steer_angle(self, steering_wheel_angle: np.ndarray) -> np.ndarray:
        """δ_W12 [rad] from δ_S [rad] through the table."""
        return np.interp(steering_wheel_angle, self.steering_wheel_angle, self.wheel_angle)

    def path_curvature(self, steering_wheel_angle: np.ndarray) -> np.ndarray:
        """1/r [1/m], signed like δ_S, from eq. 5.3: r = sqrt((l / tan δ_W)² + l_34²)."""
        tan_d = np.tan(self.wheel_steer_angle(np.asarray(steering_wheel_angle, dtype=float)))
        return tan_d / np.sqrt(self.wheelbase ** 2 + (self.rear_axle_distance * tan_d) ** 2)


@dataclass(frozen=True)
class VehicleKnowledge:
    """Everything the estimating side knows about a vehicle: name, nominal parameters (initial X̂, M0's
    coast-down), drive-train model, steering geometry (None: no path curvature, M4 unavailable) and
    drive_torque_floor [N m]: below it the drive-train model is not trusted (a BEV near its regenerative torque
    limit, where unlogged friction brakes may add torque)."""

    name: str
    nominal: NominalParameters
    drivetrain: DrivetrainModel
    steering: SteeringGeometry | None = None
    drive_torque_floor: float = -np.inf
    pitch_gradient: float = 0.0  # body pitch per longitudinal acceleration [rad/(m/s^2)] (pitch-corrected eq. 5.2)


def _fit_loss_table(loss_map, ratio: float) -> tuple[float, float]:
    """(η, drag at the input [N m]) of a loss table f(T_in, ω_in) [N m at the output], fitted as
    (1 - η) |T_in| i + drag i over the table's torque axis at the median of its speed axis (the estimating side's
    simplification: no speed dependence of the spin losses, no oil temperature)."""
    torque = np.asarray(loss_map.x, dtype=float)
    speed = float(np.median(np.asarray(loss_map.y, dtype=float)))
    loss = np.asarray(loss_map(torque, np.full_like(torque, speed)), dtype=float)
    A = np.column_stack([np.abs(torque) * ratio, np.full_like(torque, ratio)])
    (one_minus_eta, drag), *_ = np.linalg.lstsq(A, loss, rcond=None)
    return float(np.clip(1.0 - one_minus_eta, 0.51, 1.0)), float(max(drag, 0.0))


def knowledge_from_spec(spec, coast_down: tuple[float, float, float] | None = None,
                        air_density: float | None = None) -> VehicleKnowledge:
    """The estimating side's knowledge of a :class:`roadload.vehicle.VehicleSpec`: nominal mass, f_r0, drag area,
    c_yW (eq. 2.15 equivalent of the axle stiffnesses), geometry, steering table, and a drive-train model whose
    loss tables are simplified from the spec's maps (warm oil, one speed; the same structure for rear- and
    all-wheel drive, as in section 5.9). coast_down: (a_V, b_V, c_V) for M0 (see
    :func:`roadload.estimators.models.simulate_coast_down`)."""

    d = spec.drivetrain
    eff, drag = zip(*[_fit_loss_table(m, r) for m, r in zip(d.gearbox_loss, d.gear_ratios)])
    eta_d, drag_d = _fit_loss_table(d.differential_loss, d.final_drive)
    drivetrain = DrivetrainModel(
        gear_ratios=tuple(float(r) for r in d.gear_ratios), final_drive=float(d.final_drive),
        wheel_radius=float(spec.tires.dynamic_radius), wheel_inertia=4.0 * float(spec.tires.wheel_inertia),
        reduced_inertia=tuple(float(d.reduced_inertia(g)) for g in range(1, d.n_gears + 1)),
        gearbox_efficiency=tuple(eff), gearbox_drag=tuple(drag), differential_efficiency=eta_d,
        differential_drag=drag_d)
    steering = SteeringGeometry(wheelbase=float(spec.body.wheelbase),
                                rear_axle_distance=float(spec.body.cg_to_rear_axle),
                                steering_wheel_angle=tuple(map(float, spec.steering.steering_wheel_angle)),
                                wheel_angle=tuple(map(float, spec.steering.wheel_angle)))
    rho = float(air_density or STANDARD_AIR_DENSITY)
    nominal = NominalParameters(RoadLoadParameters.from_spec(spec, air_density=rho), rho, coast_down)
    floor = -np.inf
    if d.kind == "bev" and d.motor is not None:
        floor = -0.92 * float(d.motor.regen_torque_limit)
    return VehicleKnowledge(spec.name, nominal, drivetrain, steering, floor,
                            pitch_gradient=float(spec.body.pitch_gradient))


# ================================================================================ settings and result
@settings_dataclass(frozen=True, error=PipelineError)
class PipelineSettings:
    """Settings of the preprocessing (section 5.3). Units SI.

    estimation_rate [Hz]: rate of the estimators (10 Hz); smoother: settings of the polynomial Kalman smoother
    bank at smoother_rate (window w_l = w_r [samples], polynomial order, forgetting λ). The text gives no PKS
    setting for chapter 5; the default w = 50, order 2, λ = 0.98 at 100 Hz (0.5 s delay, ~0.5 s memory) has a
    bandwidth comparable to the 1 Hz low-pass of the author's earlier work [134, 135] cited in section 5.3; the
    text's experiment-3.7 setting (w = 20, order 4, λ = 0.9) leaves dv/dt too noisy for eq. 5.2 at 100 Hz.
    Settings are rescaled to the same memory in seconds at other input rates. min_speed [m/s] (condition 2,
    5.5 m/s); min_drive_torque [N m] (condition 4, 10 N m); brake_pressure_threshold [Pa] and brake_hold [s]
    (condition 1: no braking plus 0.5 s);
    brake_deceleration [m/s^2]: when a trip logs no brake pressure, braking is assumed where dv/dt is below
    this (and the trip is flagged); warmup [s]: samples at the start excluded while the smoothers settle;
    smoother_rate [Hz]: the input rate the smoother settings are given for; drive_torque_floor [N m]: samples with
    T_E at or below it are excluded too (e.g. where a BEV's regenerative torque saturates and unlogged friction
    brakes take over; -inf = off; the knowledge's floor applies as well); gradient: 'accelerometer' (eq. 5.2,
    default), 'grade_channel' (a logged / map grade channel named 'grade', e.g. from elevation) or 'auto'
    (eq. 5.2 unless the trip has a grade channel and :func:`accelerometer_gravity_slope` finds that the
    accelerometer does not see g sin θ: slope below 0.25; undecided on flat roads -> eq. 5.2).
    pitch_correction: eq. 5.2 assumes the body-fixed accelerometer is level with the road; under acceleration the
    body pitches by k dv/dt (k = the knowledge's pitch_gradient [rad/(m/s^2)]), so the sensor reads
    dv/dt + g sin(θ + k dv/dt) and eq. 5.2 returns θ + k dv/dt: the force balance then sees m (1 + g k) dv/dt
    (~5 % for the i3). True: θ = arcsin((a_x - dv/dt)/g) - k dv/dt. Default False (the text's eq. 5.2).
    """

    estimation_rate: Annotated[Real, _setting("rate of the estimators", "Hz", gt=0.0)] = 10.0
    smoother: dict = field(default_factory=lambda: {"window": 50, "order": 2, "forgetting": 0.98})
    min_speed: Annotated[Real, _setting("condition 2: least speed", "m/s", ge=0.0)] = 5.5
    min_drive_torque: Annotated[Real, _setting("condition 4: least drive torque", "N m", ge=0.0)] = 10.0
    brake_pressure_threshold: Annotated[Real, _setting("condition 1: brake pressure of braking", "Pa", ge=0.0)] = 1.0e5
    brake_hold: Annotated[Real, _setting("condition 1: time after braking", "s", ge=0.0)] = 0.5
    brake_deceleration: Annotated[Real, _setting("braking without brake pressure: dv/dt below", "m/s^2")] = -1.5
    warmup: Annotated[Real, _setting("samples excluded at the start", "s", ge=0.0)] = 2.0
    smoother_rate: Annotated[Real, _setting("input rate the smoother settings are given for", "Hz", gt=0.0)] = 100.0
    drive_torque_floor: Annotated[Real, _setting("drive torque at or below which samples are excluded", "N m"),
                                  Field(allow_inf_nan=True)] = -np.inf
    gradient: GradientSource = "accelerometer"
    pitch_correction: Annotated[bool, Strict()] = False

    @model_validator(mode="after")
    def _smoother_design(self) -> "PipelineSettings":
        """The smoother settings are those of :meth:`PKSDesign.from_options` (checked here, not at the first trip)."""
        known = ("window", "window_left", "window_right", "order", "n_params", "forgetting", "p0")
        unknown = sorted(set(self.smoother) - set(known))
        if unknown:
            raise PipelineError(f"smoother: unknown setting(s) {unknown}; the smoother takes {list(known)}")
        try:
            PKSDesign.from_options(**self.smoother)
        except EstimatorConfigError as exc:
            raise PipelineError(f"smoother: {exc}") from None
        return self


@dataclass
class PipelineResult:
    """Frames of each stage run so far, the smoother delay [s] and notes (fallbacks taken)."""

    name: str
    stages: dict[str, pd.DataFrame]
    delay: float
    decimation: int
    notes: list[str] = field(default_factory=list)

    @property
    def states(self) -> pd.DataFrame:
        if "states" not in self.stages:
            raise PipelineError(f"trip {self.name!r} was run only to stage {list(self.stages)[-1]!r}")
        return self.stages["states"]

    def triggered(self) -> pd.DataFrame:
        """The states where the trigger is true (the samples the estimators see)."""
        s = self.states
        return s[s["trigger"].to_numpy(dtype=bool)].reset_index(drop=True)


# ================================================================================ stages
def smoother_design(settings: PipelineSettings, rate: float) -> PKSDesign:
    """The PKS design of the pipeline's smoother bank for an input sampled at ``rate`` [Hz].

    The smoother settings are given for settings.smoother_rate (100 Hz); at another input rate the windows are
    scaled with the rate and the forgetting factor λ to the same memory in seconds (λ^(smoother_rate/rate))."""
    design = PKSDesign.from_options(**settings.smoother)
    scale = rate / settings.smoother_rate
    if abs(scale - 1.0) > 1e-6:
        def scaled(window: int) -> int:   # a window of >= 1 sample stays >= 1
            return max(min(window, 1), round(window * scale))
        design = dataclasses.replace(design, window_left=scaled(design.window_left),
                                     window_right=scaled(design.window_right),
                                     forgetting=design.forgetting ** (1.0 / scale))
    return design


def _smoother_bank(values: dict[str, np.ndarray], rate: float, settings: PipelineSettings):
    """Smoothed values, first derivatives [unit/s] and the common delay [samples] of the library's PKS bank
    (:func:`smoother_design`)."""
    return pks_bank(values, dt=1.0 / rate, derivatives=1, design=smoother_design(settings, rate))


def _stage_smoothed(trip: Trip, settings: PipelineSettings, notes: list[str]) -> tuple[pd.DataFrame, float]:
    rate = trip.sample_rate
    cont = {c: trip.channel(c) for c in SMOOTHED_CHANNELS if trip.has(c) and c not in WHEEL_SPEEDS}
    wheels = [trip.channel(c) for c in WHEEL_SPEEDS if trip.has(c)]
    if wheels:   # the smoother is linear in its input: smoothing the mean equals the mean of the smoothed wheels
        with np.errstate(invalid="ignore"), warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            cont["wheel_speed"] = np.nanmean(np.vstack(wheels), axis=0)
    if "vehicle_speed" not in cont:
        raise PipelineError(f"trip {trip.meta.get('name', '?')!r} has no vehicle_speed channel; the pipeline "
                            f"needs at least vehicle_speed, accel_x and drive_torque (or rim_torque)")
    bank = _smoother_bank(cont, rate, settings)
    d = int(bank.delay)
    n = len(trip)
    if n <= d + 1:
        raise PipelineError(f"trip {trip.meta.get('name', '?')!r} is shorter ({n} samples) than the smoother "
                            f"delay ({d} samples)")
    rows = n - d
    frame = {"t": trip.t[:rows]}
    for c in cont:
        frame[c] = bank.value[c][d:]
    frame["vehicle_speed_derivative"] = bank.derivative["vehicle_speed"][d:]
    if "wheel_speed" in cont:
        frame["wheel_acceleration"] = bank.derivative["wheel_speed"][d:]
    for c in DISCRETE_CHANNELS:
        if trip.has(c):
            frame[c] = trip.channel(c)[:rows]
    # a smoothed sample mixes raw samples around it: it is only usable if the gear did not change and the
    # clutch stayed closed over the smoother's window (a torque step across a shift smears into its neighbours)
    unsteady = np.zeros(n, dtype=bool)
    if trip.has("gear"):
        gear = trip.channel("gear")
        unsteady[1:] |= gear[1:] != gear[:-1]
        unsteady |= ~np.isfinite(gear)
    if trip.has("clutch"):
        unsteady |= ~(trip.channel("clutch") >= 0.99)
    width = bank.design.window_left + bank.design.window_right
    if unsteady.any():
        unsteady = np.convolve(unsteady.astype(float), np.ones(2 * width + 1), mode="same") > 0
    frame["drivetrain_steady"] = ~unsteady[:rows]
    return pd.DataFrame(frame), d / rate


def _hold(flag: np.ndarray, t: np.ndarray, hold: float) -> np.ndarray:
    """Extend True stretches of `flag` by `hold` seconds after they end."""
    if hold <= 0 or not flag.any():
        return flag.copy()
    last = np.where(flag, t, -np.inf)
    last = np.maximum.accumulate(last)
    return t - last <= hold


def accelerometer_gravity_slope(frame: pd.DataFrame, min_speed: float = 3.0, average: float = 20.0) -> float:
    """Least-squares slope of (ẍ_CAN - v̇) over g sin θ of the 'grade' channel, both averaged over `average`
    seconds first (the grade of a map or of quantised elevation is only meaningful over distance): ≈ 1 when the
    body-fixed accelerometer measures gravity along the slope (eq. 5.2 applies), ≈ 0 when it does not. NaN when
    the road is too flat to tell (std of the averaged g sin θ below 0.02 m/s², i.e. 0.2 % grade)."""
    t = frame["t"].to_numpy(dtype=float)
    if t.size < 3:
        return float("nan")
    n = max(1, int(round(average / np.median(np.diff(t)))))
    y = frame["accel_x"].to_numpy(dtype=float) - frame["vehicle_speed_derivative"].to_numpy(dtype=float)
    x = G * np.sin(frame["grade"].to_numpy(dtype=float))
    moving = (frame["vehicle_speed"].to_numpy(dtype=float) > min_speed).astype(float)
    ok_in = np.isfinite(x) & np.isfinite(y) & (moving > 0)
    ker = np.ones(n) / n
    xs = np.convolve(np.where(ok_in, x, 0.0), ker, "same")
    ys = np.convolve(np.where(ok_in, y, 0.0), ker, "same")
    ok = np.convolve(ok_in.astype(float), ker, "same") > 0.99
    if ok.sum() < 5 * n or np.std(xs[ok]) < 0.02:
        return float("nan")
    xc = xs[ok] - xs[ok].mean()
    return float(np.sum(xc * (ys[ok] - ys[ok].mean())) / np.sum(xc ** 2))


def _stage_states(dec: pd.DataFrame, knowledge: VehicleKnowledge, settings: PipelineSettings,
                  notes: list[str]) -> pd.DataFrame:
    dt_model = knowledge.drivetrain
    t = dec["t"].to_numpy(dtype=float)
    v = dec["vehicle_speed"].to_numpy(dtype=float)
    dv = dec["vehicle_speed_derivative"].to_numpy(dtype=float)
    out: dict[str, np.ndarray] = {"t": t, SPEED: v, ACCELERATION: dv}
    out[GRADIENT_ANGLE] = _gradient_angle(dec, knowledge, settings, notes)
    out[PATH_CURVATURE] = _path_curvature(dec, knowledge, notes)
    gear = _gear(dec, knowledge)
    out["gear"] = gear
    # wheel angular acceleration θ̈_W: from the wheel-speed smoothers, else from dv/dt
    if "wheel_acceleration" in dec:
        wheel_acc = dec["wheel_acceleration"].to_numpy(dtype=float)
    else:
        wheel_acc = dv / dt_model.wheel_radius
    out["drive_torque"], out["rim_torque"] = _drive_and_rim_torque(dec, dt_model, gear, wheel_acc, notes)
    out[TRACTIVE_FORCE] = dt_model.tractive_force(out["rim_torque"], wheel_acc)
    cond = _trigger_conditions(dec, knowledge, settings, out, notes)
    trigger = np.ones_like(v, dtype=bool)
    for name in TRIGGER_CONDITIONS:
        out[f"trigger_{name}"] = cond[name]
        trigger &= cond[name]
    finite = np.isfinite(out[SPEED]) & np.isfinite(out[ACCELERATION]) & np.isfinite(out[GRADIENT_ANGLE])
    trigger &= finite & (t >= t[0] + settings.warmup if t.size else True)
    out["trigger"] = trigger
    return pd.DataFrame(out)


def _gradient_angle(dec: pd.DataFrame, knowledge: VehicleKnowledge, settings: PipelineSettings,
                    notes: list[str]) -> np.ndarray:
    """θ [rad] by eq. 5.2 (optionally pitch-corrected) or from a grade channel (``settings.gradient``)."""
    dv = dec["vehicle_speed_derivative"].to_numpy(dtype=float)
    gradient = settings.gradient
    if gradient == "auto":
        gradient = "accelerometer"
        if "grade" in dec and "accel_x" in dec:
            slope = accelerometer_gravity_slope(dec)
            if np.isfinite(slope) and slope < 0.25:
                gradient = "grade_channel"
                notes.append(f"the accelerometer does not see g sin(theta) (slope {slope:.2f} against the grade "
                             f"channel)")
    if gradient == "grade_channel":
        if "grade" not in dec:
            raise PipelineError("gradient='grade_channel' but the trip has no 'grade' channel")
        notes.append("gradient angle from the trip's grade channel, not eq. 5.2")
        return dec["grade"].to_numpy(dtype=float)
    if "accel_x" not in dec:
        notes.append("no accel_x: gradient angle unavailable")
        return np.full_like(dv, np.nan)
    ratio = (dec["accel_x"].to_numpy(dtype=float) - dv) / G
    angle = np.arcsin(np.clip(ratio, -1.0, 1.0))
    if settings.pitch_correction:
        angle = angle - knowledge.pitch_gradient * dv
        notes.append(f"eq. 5.2 pitch-corrected (k = {knowledge.pitch_gradient:g} rad/(m/s^2))")
    return angle


def _path_curvature(dec: pd.DataFrame, knowledge: VehicleKnowledge, notes: list[str]) -> np.ndarray:
    """1/r [1/m] by eq. 5.3 through the steering table (NaN without steering angle or table)."""
    if knowledge.steering is not None and "steering_wheel_angle" in dec:
        return knowledge.steering.path_curvature(dec["steering_wheel_angle"].to_numpy(dtype=float))
    notes.append("no steering_wheel_angle or steering table: path curvature unavailable (M4 not possible)")
    return np.full(len(dec), np.nan)


def _gear(dec: pd.DataFrame, knowledge: VehicleKnowledge) -> np.ndarray:
    """The logged gear, or the single gear of a one-speed drive-train."""
    if "gear" in dec:
        return dec["gear"].to_numpy(dtype=float)
    if knowledge.drivetrain.n_gears == 1:
        return np.ones(len(dec))
    raise PipelineError(f"the drive-train model of {knowledge.name!r} has {knowledge.drivetrain.n_gears} gears but "
                        f"the trip logs no gear channel")


def _drive_and_rim_torque(dec: pd.DataFrame, dt_model: DrivetrainModel, gear: np.ndarray, wheel_acc: np.ndarray,
                          notes: list[str]) -> tuple[np.ndarray, np.ndarray]:
    """(T_E, T_R) [N m]: T_R by eq. 2.17 through the own drive-train model; a logged rim torque is used only without
    a drive torque."""
    if "drive_torque" in dec:
        drive_torque = dec["drive_torque"].to_numpy(dtype=float)
        return drive_torque, dt_model.rim_torque(drive_torque, gear, wheel_acc)
    if "rim_torque" in dec:
        rim = dec["rim_torque"].to_numpy(dtype=float)
        notes.append("no drive_torque: the logged rim_torque is used as T_R")
        return rim / dt_model.overall_ratio(gear), rim
    raise PipelineError("the trip has neither drive_torque nor rim_torque; no tractive force possible")


def _trigger_conditions(dec: pd.DataFrame, knowledge: VehicleKnowledge, settings: PipelineSettings,
                        out: dict[str, np.ndarray], notes: list[str]) -> dict[str, np.ndarray]:
    """The five conditions of section 5.3 on the states ``out`` computed so far."""
    t, v, dv, drive_torque = out["t"], out[SPEED], out[ACCELERATION], out["drive_torque"]
    if "brake_pressure_front" in dec or "brake_pressure_rear" in dec:
        p = np.zeros_like(v)
        for c in ("brake_pressure_front", "brake_pressure_rear"):
            if c in dec:
                p = np.maximum(p, np.nan_to_num(dec[c].to_numpy(dtype=float), nan=np.inf))
        braking = p > settings.brake_pressure_threshold
    else:
        braking = dv < settings.brake_deceleration
        notes.append(f"no brake pressure logged: braking assumed where dv/dt < {settings.brake_deceleration} m/s^2")
    return {
        "no_brake": ~_hold(braking, t, settings.brake_hold),
        "moving": v > settings.min_speed,
        "torque": ((np.abs(drive_torque) > settings.min_drive_torque)
                   & (drive_torque > max(settings.drive_torque_floor, knowledge.drive_torque_floor))),
        "rim_torque_available": np.isfinite(out["rim_torque"]) & np.isfinite(out[TRACTIVE_FORCE]),
        "no_slip": _no_slip(dec, knowledge.drivetrain, out["gear"], v, notes),
    }


def _no_slip(dec: pd.DataFrame, dt_model: DrivetrainModel, gear: np.ndarray, v: np.ndarray,
             notes: list[str]) -> np.ndarray:
    """Condition 3: a gear engaged, the drive-train steady over the smoother's window, the clutch closed and the
    engine speed matching the gear shaft speed within the slip tolerance."""
    slip_ok = np.isfinite(dt_model.overall_ratio(gear))
    if "drivetrain_steady" in dec:
        slip_ok &= dec["drivetrain_steady"].to_numpy(dtype=bool)
    if "clutch" in dec:
        slip_ok &= dec["clutch"].to_numpy(dtype=float) >= 0.99
    if "engine_speed" in dec:
        wheel_speed = (dec["wheel_speed"].to_numpy(dtype=float) if "wheel_speed" in dec
                       else v / dt_model.wheel_radius)
        shaft = wheel_speed * dt_model.overall_ratio(gear)   # gear shaft speed θ̇_G seen from the wheels
        eng = dec["engine_speed"].to_numpy(dtype=float)
        with np.errstate(invalid="ignore", divide="ignore"):
            slip_ok &= np.abs(eng - shaft) <= dt_model.slip_tolerance * np.maximum(np.abs(eng), 1.0)
    elif "clutch" not in dec:
        notes.append("no engine_speed or clutch: drive-train slip (condition 3) not checked")
    return slip_ok


def load_for_pipeline(path: str | os.PathLike) -> Trip:
    """A trip file read for :func:`run_pipeline`: only ``PIPELINE_CHANNELS`` and no truth (a column-selective
    Parquet read; a day at 100 Hz then costs ~10 of its channels instead of all of them plus the truth)."""
    return Trip.load(path, channels=list(PIPELINE_CHANNELS), truth_channels=[])


def run_pipeline(trip: Trip, knowledge: VehicleKnowledge, settings: PipelineSettings | None = None,
                 until: str = "states") -> PipelineResult:
    """Run a Trip through the stages up to and including `until` (one of STAGES)."""
    if until not in STAGES:
        raise PipelineError(f"unknown stage {until!r}; stages are {list(STAGES)}")
    name = str(trip.meta.get("name", "trip"))
    settings = settings or PipelineSettings()
    notes: list[str] = []
    stages: dict[str, pd.DataFrame] = {"measured": trip.measured}
    result = PipelineResult(name=name, stages=stages, delay=0.0, decimation=1, notes=notes)
    if until == "measured":
        return result
    if len(trip) < 10:
        raise PipelineError(f"trip {name!r} has only {len(trip)} samples")
    smoothed, delay = _stage_smoothed(trip, settings, notes)
    stages["smoothed"] = smoothed
    result.delay = delay
    if until == "smoothed":
        return result
    rate = trip.sample_rate
    k = max(1, int(round(rate / settings.estimation_rate)))
    if abs(rate / k - settings.estimation_rate) > 0.05 * settings.estimation_rate:
        raise PipelineError(f"trip {name!r} is sampled at {rate:.3g} Hz, which is not an integer multiple of the "
                            f"estimation rate {settings.estimation_rate} Hz; resample it first")
    result.decimation = k
    decimated = smoothed.iloc[::k].reset_index(drop=True)
    stages["decimated"] = decimated
    if until == "decimated":
        return result
    stages["states"] = _stage_states(decimated, knowledge, settings, notes)
    return result


def model_data(states: pd.DataFrame, model: str | ModelStructure, triggered: bool = True
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(t [s], A, B) of a model structure on the (triggered) states; rows with non-finite A or B are dropped."""
    m = get_model(model)
    s = states[states["trigger"].to_numpy(dtype=bool)] if triggered else states
    cols = {c: s[c].to_numpy(dtype=float) for c in s.columns}
    A = m.regressors(cols)
    B = m.output(cols)
    ok = np.all(np.isfinite(A), axis=1) & np.isfinite(B)
    return cols["t"][ok], A[ok], B[ok]
