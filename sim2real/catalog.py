"""The catalog of candidate effects: each one both a regressor for the force model and a switch of the simulator.

A :class:`CandidateEffect` maps an unmodelled effect to

- ``terms(model, shape)``: extra regressor column(s) (:class:`roadload.estimators.models.Term`) whose fitted
  parameters explain the residual F_xV,measured - F_xV,sim; :meth:`CandidateEffect.structure` registers
  ``sim:<vehicle>+<effect>`` in the chapter-5 model registry (the sim's white box extended by the terms);
- ``shape_grid``: values of one non-linear shape parameter (e.g. a warm-up time constant τ [s]) profiled on a
  grid, or () when the effect is linear in its parameters;
- ``needs``: diagnosis-table columns (channels) it cannot do without;
- ``sim_effect`` and ``to_sim(params, shape, model)``: the simulator switch and its parameters from the fitted
  values, so the identified effect can be switched on in the simulator. A switch is an effect name of
  :data:`roadload.envs.effects.EFFECTS`, or ``spec:<dotted path>`` for a vehicle-spec field (e.g.
  ``spec:sensors.channels.drive_torque.latency``), whose parameter ``{"delta": x}`` is added to the field
  (``{"factor": f}``: multiplied).

``side`` is "force" (explains the force residual) or "power" (explains the battery-power residual of
:mod:`.energy`, e.g. auxiliary loads). A signal error shows on both sides: ``signal_gain`` says which drive-torque
signal gain a force-side effect implies on the battery power, ``force_twin`` names the force-side candidate that
carries a power-side effect's force signature (its one parameter the same), so each side's fit is checked against
the other's evidence (:func:`roadload.sim2real.diagnose.energy_consistency`, :func:`~roadload.sim2real.diagnose.
force_consistency`). Users add their own with :func:`register_candidate`. Parameters are in
SI; signs follow "measured minus sim".
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

from roadload.estimators.models import ACCELERATION, GRADIENT_ANGLE, PATH_CURVATURE, SPEED, ModelStructure, \
    Term, register_model
from roadload.registry import Registry
from roadload.units import STANDARD_TEMPERATURE, G

from .energy import LOSS_SPEED_SLOPE, LOSS_TORQUE_SLOPE, MOTOR_SPEED, SPEED_DERIVED
from .errors import DiagnosisError
from .forcemodel import AIR_DENSITY, SimForceModel

# further diagnosis-table columns candidates read (see .table)
TIME_SINCE_START = "time_since_start"
DISTANCE = "distance"
# the force the drive torque delivers in the sim's balance (F_xV,sim + F_brake + m_rot dv/dt: the pipeline takes the
# rotating parts' inertia out of the torque) and its rate: candidates that scale with the drive torque read this
# one, not the measured drive force, whose noise is also in the residual
DRIVE_FORCE = "sim_drive_force"
DRIVE_FORCE_RATE = "sim_drive_force_rate"
BRAKE_FORCE = "brake_force"
GEAR = "gear"
HEADING = "heading"
TIME_SINCE_BRAKE = "time_since_brake"
POWER_RESIDUAL = "power_residual"
AUX_LOGGED = "aux_power_logged"
ROTATIONAL_MASS = "rotational_mass"

TermFactory = Callable[[SimForceModel, "float | None"], tuple[Term, ...]]
SimMapping = Callable[[dict[str, float], "float | None", SimForceModel], dict[str, float]]


@dataclass(frozen=True)
class CandidateEffect:
    """One unmodelled effect (see module doc). ``description`` says what it is; ``regime_hint`` names the
    regime where it shows most (for reports)."""

    name: str
    description: str
    terms: TermFactory
    needs: tuple[str, ...]
    sim_effect: str | None = None
    to_sim: SimMapping | None = None
    shape_grid: tuple[float, ...] = ()
    shape_name: str = ""
    shape_unit: str = ""
    regime_hint: str = ""
    sim_aliases: tuple[str, ...] = ()
    side: str = "force"
    signal_gain: Callable[[dict, float | None, bool], float] | None = None
    force_twin: str | None = None

    def torque_signal_gain(self, params: dict, shape: float | None, speed_derived: bool) -> float:
        """The drive-torque signal gain g the fitted effect implies on the battery power (P_el,sim is computed from
        the logged torque and the motor speed: a signal reading (1 + g) T over-predicts it by g T ω): 0 for a
        physical effect (a heavier car needs a truly larger torque); ``speed_derived``: the motor speed comes
        from the vehicle speed (no motor-speed channel), so a speed-signal scale acts like a torque gain."""
        return self.signal_gain(params, shape, speed_derived) if self.signal_gain is not None else 0.0

    @property
    def is_brake(self) -> bool:
        """About the friction brake: the only candidates that braking rows fit and judge (:mod:`.robust`)."""
        return BRAKE_FORCE in self.needs or TIME_SINCE_BRAKE in self.needs

    @property
    def explains(self) -> tuple[str, ...]:
        """Simulator switches this candidate stands for (its own plus aliases), e.g. for the selftest."""
        return ((self.sim_effect,) if self.sim_effect else ()) + self.sim_aliases

    def missing(self, columns) -> list[str]:
        """Needed columns absent from ``columns`` (a table or mapping) or without one finite value."""
        out = []
        for c in self.needs:
            if c not in columns:
                out.append(c)
                continue
            col = np.asarray(columns[c], dtype=float)
            usable = np.isfinite(col)
            if c in (BRAKE_FORCE, HEADING, PATH_CURVATURE, SPEED_DERIVED):   # all-zero: no information
                usable &= col != 0
            if not usable.any():
                out.append(c)
        return out

    def shapes(self) -> tuple[float | None, ...]:
        return self.shape_grid if self.shape_grid else (None,)

    def structure(self, model: SimForceModel, shape: float | None = None) -> ModelStructure:
        """``sim:<vehicle>+<name>`` in the model registry: the sim's white box extended by this effect's terms."""
        name = f"{model.structure().name}+{self.name}" + ("" if shape is None else f"@{shape:g}")
        return register_model(model.structure().extend(name, *self.terms(model, shape),
                                                       description=f"sim + {self.description}"),
                              replace_existing=True)

    def sim_parameters(self, params: dict[str, float], shape: float | None, model: SimForceModel
                       ) -> dict[str, float] | None:
        """Simulator effect parameters for the fitted values (None when the effect has no simulator switch)."""
        if self.to_sim is None:
            return None
        return self.to_sim(params, shape, model)


def _c(s, name):
    return np.asarray(s[name], dtype=float)


# ---------------------------------------------------------------------------------------------- built-in effects
def _drag_area(model, shape):
    return (Term("rho_a/2 v^2", "delta c_x A_V", "m^2", lambda s: 0.5 * _c(s, AIR_DENSITY) * _c(s, SPEED) ** 2,
                 (AIR_DENSITY, SPEED), lambda n: 0.0),)


def _wind(model, shape):
    # F_a = rho/2 c_x A_V (v + w)^2 -> d/dw at w = 0: rho c_x A_V v (w > 0: headwind along the vehicle's course)
    return (Term("rho_a c_x A_V v", "headwind w", "m/s",
                 lambda s: _c(s, AIR_DENSITY) * model.drag_area * _c(s, SPEED), (AIR_DENSITY, SPEED),
                 lambda n: 0.0),)


def _wind_heading(model, shape):
    # wind fixed in the world frame, blowing towards heading psi_w: headwind component -w cos(heading - psi_w)
    # = w_x cos(h) + w_y sin(h) with (w_x, w_y) the wind's velocity *from* which it comes
    return (Term("rho_a c_x A_V v cos(heading)", "wind w_x", "m/s",
                 lambda s: _c(s, AIR_DENSITY) * model.drag_area * _c(s, SPEED) * np.cos(_c(s, HEADING)),
                 (AIR_DENSITY, SPEED, HEADING), lambda n: 0.0),
            Term("rho_a c_x A_V v sin(heading)", "wind w_y", "m/s",
                 lambda s: _c(s, AIR_DENSITY) * model.drag_area * _c(s, SPEED) * np.sin(_c(s, HEADING)),
                 (AIR_DENSITY, SPEED, HEADING), lambda n: 0.0))


def _rolling_scale(model, shape):
    return (Term("m_V g cos(theta) f_r(v)", "rolling factor - 1", "1",
                 lambda s: model.mass * G * np.cos(_c(s, GRADIENT_ANGLE))
                 * model.rolling_resistance_coefficient(_c(s, SPEED)), (GRADIENT_ANGLE, SPEED), lambda n: 0.0),)


def _rolling_speed(model, shape):
    return (Term("m_V g cos(theta) v", "delta f_r1", "s/m",
                 lambda s: model.mass * G * np.cos(_c(s, GRADIENT_ANGLE)) * _c(s, SPEED), (GRADIENT_ANGLE, SPEED),
                 lambda n: 0.0),
            Term("m_V g cos(theta) v^4", "delta f_r4", "s^4/m^4",
                 lambda s: model.mass * G * np.cos(_c(s, GRADIENT_ANGLE)) * _c(s, SPEED) ** 4,
                 (GRADIENT_ANGLE, SPEED), lambda n: 0.0))


def _mass_offset(model, shape):
    def build(s):
        th = _c(s, GRADIENT_ANGLE)
        f_r = model.rolling_resistance_coefficient(_c(s, SPEED))
        return G * np.sin(th) + _c(s, ACCELERATION) + G * np.cos(th) * f_r
    return (Term("g sin(theta) + dv/dt + g cos(theta) f_r(v)", "delta m_V", "kg", build,
                 (GRADIENT_ANGLE, ACCELERATION, SPEED), lambda n: 0.0),)


def _accel_bias(model, shape):
    # a bias b of accel_x shifts the gradient angle of eq. 5.2 by ~ b/g: the sim's climbing force is off by m_V b
    return (Term("-m_V", "accelerometer bias b", "m/s^2", lambda s: -model.mass * np.ones_like(_c(s, SPEED)),
                 (SPEED, GRADIENT_ANGLE), lambda n: 0.0),)


def _cornering(model, shape):
    return (Term("v^4/(4 r^2)", "delta m_V^2/c_yW", "kg^2 rad/N",
                 lambda s: _c(s, SPEED) ** 4 * np.nan_to_num(_c(s, PATH_CURVATURE)) ** 2 / 4.0,
                 (SPEED, PATH_CURVATURE), lambda n: 0.0),)


def _drivetrain_oil(model, shape):
    tau = float(shape)
    return (Term(f"|F_drive| exp(-t/{tau:g} s)", "cold loss fraction", "1",
                 lambda s: np.abs(_c(s, DRIVE_FORCE)) * np.exp(-_c(s, TIME_SINCE_START) / tau),
                 (DRIVE_FORCE, TIME_SINCE_START), lambda n: 0.0),)


def _tire_warmup(model, shape):
    d = float(shape)
    return (Term(f"m_V g cos(theta) f_r(v) exp(-s/{d:g} m)", "cold tire factor - 1", "1",
                 lambda s: model.mass * G * np.cos(_c(s, GRADIENT_ANGLE))
                 * model.rolling_resistance_coefficient(_c(s, SPEED)) * np.exp(-_c(s, DISTANCE) / d),
                 (GRADIENT_ANGLE, SPEED, DISTANCE), lambda n: 0.0),)


def _friction_brake(model, shape):
    # the measured side subtracts the nominal brake force F_B; with the pad friction X_B = (1 + k) X_B0 the wheels
    # brake with (1 + k) F_B, so the motion needs k F_B less drive force than measured: residual = +k F_B
    return (Term("F_brake", "pad friction error k", "1", lambda s: np.nan_to_num(_c(s, BRAKE_FORCE)),
                 (BRAKE_FORCE,), lambda n: 0.0),)


def _brake_drag(model, shape):
    # pads that keep rubbing after the brake is released: a drag F_d fading with tau after each brake application
    tau = float(shape)
    return (Term(f"exp(-t_since_brake/{tau:g} s)", "residual brake drag F_d", "N",
                 lambda s: np.nan_to_num(np.exp(-np.asarray(s[TIME_SINCE_BRAKE], dtype=float) / tau)),
                 (TIME_SINCE_BRAKE,), lambda n: 0.0),)


def _rotational_inertia(model, shape):
    def per_gear(g):
        return Term(f"dv/dt [gear {g}]", f"delta I_red/r_W^2 (gear {g})", "kg",
                    lambda s, g=g: _c(s, ACCELERATION) * (np.rint(np.nan_to_num(_c(s, GEAR))) == g),
                    (ACCELERATION, GEAR), lambda n: 0.0)
    return tuple(per_gear(g) for g in range(1, model.n_gears + 1))


def _torque_scale(model, shape):
    return (Term("F_drive", "torque scale error epsilon", "1", lambda s: _c(s, DRIVE_FORCE), (DRIVE_FORCE,),
                 lambda n: 0.0),)


def _drive_efficiency(model, shape):
    # efficiency off differently when motoring and when regenerating: F_meas = (1 + e_m) F in traction,
    # (1 + e_r) F in regen
    return (Term("max(F_drive, 0)", "traction scale error e_m", "1",
                 lambda s: np.clip(_c(s, DRIVE_FORCE), 0.0, None), (DRIVE_FORCE,), lambda n: 0.0),
            Term("min(F_drive, 0)", "regen scale error e_r", "1",
                 lambda s: np.clip(_c(s, DRIVE_FORCE), None, 0.0), (DRIVE_FORCE,), lambda n: 0.0))


def _latency(model, shape):
    # a torque signal late by tau: F_meas(t) = F(t - tau) ~ F(t) - tau dF/dt
    return (Term("-dF_drive/dt", "latency tau", "s", lambda s: -_c(s, DRIVE_FORCE_RATE), (DRIVE_FORCE_RATE,),
                 lambda n: 0.0),)


def _speed_scale(model, shape):
    # the speed signal reads (1 + s) v: the balance is evaluated at (1 + s) v and (1 + s) dv/dt, and eq. 5.2 turns
    # the scaled dv/dt into a grade g sin(theta) - s dv/dt, so the vehicle's inertial terms cancel and, to first
    # order, the sim's force is too high by s (m_V g cos(theta) (f_r1 v + 4 f_r4 v^4) + 2 rho_a/2 c_x A_V v^2
    # + 4 F_corner); the measured side takes the rotating parts' inertia m_rot (1 + s) dv/dt out of the drive
    # torque (eq. 2.17), which makes it lower by s m_rot dv/dt
    def build(s):
        v = _c(s, SPEED)
        corner = v ** 4 * np.nan_to_num(_c(s, PATH_CURVATURE)) ** 2 / 4.0 * model.mass ** 2 / model.cornering_stiffness
        m_rot = np.nan_to_num(_c(s, ROTATIONAL_MASS)) if ROTATIONAL_MASS in s else 0.0
        return -(model.mass * G * np.cos(_c(s, GRADIENT_ANGLE)) * (model.rolling_resistance_f1 * v
                                                                  + 4.0 * model.rolling_resistance_f4 * v ** 4)
                 + _c(s, AIR_DENSITY) * model.drag_area * v ** 2 + 4.0 * corner
                 + m_rot * np.nan_to_num(_c(s, ACCELERATION)))
    return (Term("-(v dF_road/dv + m_rot dv/dt)", "speed scale error s", "1", build,
                 (SPEED, GRADIENT_ANGLE, AIR_DENSITY, PATH_CURVATURE), lambda n: 0.0),)


def _aux_constant(model, shape):
    return (Term("1", "delta P_aux", "W", lambda s: np.ones_like(_c(s, SPEED)), (SPEED,), lambda n: 0.0),)


def _aux_logged(model, shape):
    return (Term("P_heater + P_aircon (logged)", "logged auxiliary power gain", "1",
                 lambda s: np.nan_to_num(_c(s, AUX_LOGGED)), (AUX_LOGGED,), lambda n: 0.0),)


def _torque_signal(model, shape):
    # P_el,sim from a torque signal reading (1 + g) T: over-predicted by g (T_E ω_E + T_E dP_loss/dT_E)
    return (Term("-(T_E omega_E + T_E dP_loss/dT_E)", "drive-torque signal gain error g", "1",
                 lambda s: -(_c(s, "drive_torque") * _c(s, MOTOR_SPEED) + _c(s, LOSS_TORQUE_SLOPE)),
                 (MOTOR_SPEED, LOSS_TORQUE_SLOPE), lambda n: 0.0),)


def _speed_signal(model, shape):
    # the motor speed derived from a speed signal reading (1 + s) v: P_el,sim over-predicted by
    # s (T_E ω_E + ω_E dP_loss/dω_E); nothing where the motor speed is logged
    return (Term("-(T_E omega_E + omega_E dP_loss/domega_E) [motor speed from v]", "speed scale error s", "1",
                 lambda s: -(_c(s, "drive_torque") * _c(s, MOTOR_SPEED) + _c(s, LOSS_SPEED_SLOPE))
                 * np.nan_to_num(_c(s, SPEED_DERIVED)),
                 (MOTOR_SPEED, LOSS_SPEED_SLOPE, SPEED_DERIVED), lambda n: 0.0),)


def _p(params, key):
    return float(params[key])


_CATALOG: Registry[CandidateEffect] = Registry("candidate effect", CandidateEffect, DiagnosisError)


def register_candidate(candidate: CandidateEffect, replace_existing: bool = False) -> CandidateEffect:
    """Add a candidate effect (DiagnosisError if the name is taken and replace_existing is False)."""
    if not isinstance(candidate, CandidateEffect):
        raise DiagnosisError(f"register_candidate expects a CandidateEffect, got {type(candidate).__name__}")
    return _CATALOG.register(candidate.name, candidate, replace_existing)


def get_candidate(name: str | CandidateEffect) -> CandidateEffect:
    return _CATALOG.get(name)


def candidate_names() -> list[str]:
    return _CATALOG.names()


_TAU_GRID = (150.0, 300.0, 600.0, 1200.0, 2400.0, 4800.0)
_DIST_GRID = (1000.0, 2500.0, 5000.0, 10000.0, 20000.0)


def _tire_to_sim(p, shape: float | None, model) -> dict[str, float]:
    """Fitted cold-tire factor - 1 and distance constant d [m] -> the sim's tire_warmup effect parameters."""
    if shape is None:
        raise DiagnosisError("tire_warmup: needs the fitted distance constant d [m] (the effect's shape), got None")
    return {"cold_factor": float(np.clip(1.0 + _p(p, "cold tire factor - 1"), 1.0, 3.0)),
            "distance_constant": float(shape)}


def _oil_to_sim(p, shape, model):
    """Fitted extra loss fraction k at the start -> the sim's oil start temperature: phi_start - 1 =
    k / (1 - eta) = (phi_cold - 1) x, T_start = T_warm - x (T_warm - 293.15 K), x <= 1.5; the fitted decay time
    tau becomes the drive-train's oil time constant."""
    k = _p(p, "cold loss fraction")
    x = k / max(1.0 - model.drivetrain_efficiency, 1e-3) / max(model.oil_cold_loss_factor - 1.0, 1e-3)
    x = float(np.clip(x, 0.0, 1.5))
    warm = model.oil_warm_temperature
    return {"start_temperature": float(warm - x * (warm - STANDARD_TEMPERATURE)),
            "spec_changes": {"drivetrain.oil_time_constant": {"factor": float(shape) / model.oil_time_constant}}}

for _cand in (
    CandidateEffect("drag_area", "drag-area change c_x A_V (roof box, open windows, body change)", _drag_area,
                    (SPEED, AIR_DENSITY), "drag_area",
                    lambda p, sh, m: {"roof_box": float(np.clip(_p(p, "delta c_x A_V") / m.drag_area, 0.0, 2.0)),
                                      "windows": 0.0, "sunroof": 0.0, "toggle_rate": 0.0}, regime_hint="speed"),
    CandidateEffect("wind", "drag with wind: constant headwind along the course (air approach velocity)", _wind,
                    (SPEED, AIR_DENSITY), "wind",
                    lambda p, sh, m: {"mean_speed": abs(_p(p, "headwind w")),
                                      "direction": float(np.pi if _p(p, "headwind w") >= 0 else 0.0),
                                      "gust_std": 0.0, "direction_std": 0.0},
                    regime_hint="speed"),
    CandidateEffect("wind_world", "drag with a wind fixed in the world frame (needs the course heading)",
                    _wind_heading, (SPEED, AIR_DENSITY, HEADING), "wind",
                    lambda p, sh, m: {"mean_speed": float(np.hypot(_p(p, "wind w_x"), _p(p, "wind w_y"))),
                                      "direction": float(np.arctan2(-_p(p, "wind w_y"), -_p(p, "wind w_x"))),
                                      "gust_std": 0.0, "direction_std": 0.0},
                    regime_hint="speed"),
    CandidateEffect("rolling_scale", "rolling resistance f_r(v) scaled (winter tires, tire pressure, road surface)",
                    _rolling_scale, (GRADIENT_ANGLE, SPEED), "winter_tires",
                    lambda p, sh, m: {"rolling_factor": 1.0 + _p(p, "rolling factor - 1"), "cornering_factor": 1.0},
                    regime_hint="speed", sim_aliases=("wet_road",)),
    CandidateEffect("rolling_speed", "rolling-resistance speed terms f_r1 v + f_r4 v^4 (eq. 2.10; wet road)",
                    _rolling_speed, (GRADIENT_ANGLE, SPEED), "wet_road",
                    lambda p, sh, m: {"rolling_factor": 1.0, "water_f1": max(_p(p, "delta f_r1"), 0.0)},
                    regime_hint="speed"),
    CandidateEffect("mass_offset", "mass offset (payload, passengers)", _mass_offset,
                    (GRADIENT_ANGLE, ACCELERATION, SPEED), "payload",
                    lambda p, sh, m: {"initial_payload": _p(p, "delta m_V"), "change_std": 0.0,
                                      "min_payload": min(0.0, _p(p, "delta m_V")),
                                      "max_payload": max(400.0, _p(p, "delta m_V"))}, regime_hint="acceleration"),
    CandidateEffect("accel_bias", "accelerometer bias / mounting pitch (gradient angle of eq. 5.2 off)",
                    _accel_bias, (SPEED, GRADIENT_ANGLE), "spec:sensors.channels.accel_x.bias",
                    lambda p, sh, m: {"delta": _p(p, "accelerometer bias b")}, regime_hint="grade",
                    sim_aliases=("sensor_bias",)),
    CandidateEffect("cornering", "cornering resistance (eq. 2.15) off", _cornering, (SPEED, PATH_CURVATURE),
                    "winter_tires",
                    lambda p, sh, m: {"rolling_factor": 1.0, "cornering_factor": float(np.clip(
                        1.0 / (1.0 + _p(p, "delta m_V^2/c_yW") * m.cornering_stiffness / m.mass ** 2), 0.2, 2.0))},
                    regime_hint="lateral_acceleration"),
    CandidateEffect("drivetrain_oil", "drive-train losses raised while the oil is cold (decay with tau)",
                    _drivetrain_oil, (DRIVE_FORCE, TIME_SINCE_START), "oil_temperature", _oil_to_sim,
                    shape_grid=_TAU_GRID, shape_name="tau", shape_unit="s", regime_hint="time_since_start"),
    CandidateEffect("tire_warmup", "rolling resistance raised on cold tires (decays over distance d)", _tire_warmup,
                    (GRADIENT_ANGLE, SPEED, DISTANCE), "tire_warmup",
                    _tire_to_sim,
                    shape_grid=_DIST_GRID, shape_name="d", shape_unit="m", regime_hint="time_since_start"),
    CandidateEffect("friction_brake", "friction-brake force off (pad friction drift)", _friction_brake,
                    (BRAKE_FORCE,), "spec:brakes.pad_friction",
                    lambda p, sh, m: {"factor": 1.0 + _p(p, "pad friction error k")}, regime_hint="mode",
                    sim_aliases=("brake_pad_drift",)),
    CandidateEffect("brake_drag", "friction-brake drag: pads still rubbing after release (fades with tau)",
                    _brake_drag, (BRAKE_FORCE, TIME_SINCE_BRAKE), None, None, shape_grid=(5.0, 15.0, 30.0, 60.0),
                    shape_name="tau", shape_unit="s", regime_hint="mode"),
    CandidateEffect("rotational_inertia", "rotational inertia per gear off", _rotational_inertia,
                    (ACCELERATION, GEAR), None, None, regime_hint="gear"),
    CandidateEffect("torque_scale", "drive-torque scale error (efficiency, torque model)", _torque_scale,
                    (DRIVE_FORCE,), "spec:sensors.drive_torque_gain_error",
                    lambda p, sh, m: {"delta": _p(p, "torque scale error epsilon")},
                    regime_hint="mode", sim_aliases=("torque_model_error",),
                    signal_gain=lambda p, sh, fs: _p(p, "torque scale error epsilon")),
    CandidateEffect("drive_efficiency", "drive-train / motor efficiency off, separately in traction and in regen",
                    _drive_efficiency, (DRIVE_FORCE,), None, None, regime_hint="mode",
                    sim_aliases=("spec:sensors.drive_torque_gain_error", "torque_model_error")),
    CandidateEffect("latency", "drive-torque signal latency", _latency, (DRIVE_FORCE_RATE,),
                    "spec:sensors.channels.drive_torque.latency",
                    lambda p, sh, m: {"delta": max(_p(p, "latency tau"), 0.0)}, regime_hint="acceleration"),
    CandidateEffect("speed_scale", "speed-signal scale error (wheel circumference, speed sensor)", _speed_scale,
                    (SPEED, GRADIENT_ANGLE, AIR_DENSITY), "spec:sensors.speed_scale_error",
                    lambda p, sh, m: {"delta": _p(p, "speed scale error s")}, regime_hint="speed",
                    signal_gain=lambda p, sh, fs: _p(p, "speed scale error s") if fs else 0.0),
    CandidateEffect("auxiliary_power", "auxiliary power on the energy side (heater, air conditioning), constant",
                    _aux_constant, (SPEED, POWER_RESIDUAL), "auxiliary_load",
                    lambda p, sh, m: {"power": float(np.clip(_p(p, "delta P_aux"), 0.0, 20000.0))}, side="power",
                    regime_hint="ambient_temperature"),
    CandidateEffect("torque_signal", "drive-torque signal gain seen in the battery power (P_el,sim from the logged "
                    "torque)", _torque_signal, (MOTOR_SPEED, LOSS_TORQUE_SLOPE, POWER_RESIDUAL),
                    "spec:sensors.drive_torque_gain_error",
                    lambda p, sh, m: {"delta": _p(p, "drive-torque signal gain error g")}, side="power",
                    regime_hint="mode", force_twin="torque_scale"),
    CandidateEffect("speed_signal", "speed-signal scale seen in the battery power (motor speed from the vehicle "
                    "speed)", _speed_signal, (MOTOR_SPEED, LOSS_SPEED_SLOPE, SPEED_DERIVED, POWER_RESIDUAL),
                    "spec:sensors.speed_scale_error", lambda p, sh, m: {"delta": _p(p, "speed scale error s")},
                    side="power", regime_hint="speed", force_twin="speed_scale"),
    CandidateEffect("logged_aux_power", "auxiliary power following the logged heater / air-conditioning power",
                    _aux_logged, (AUX_LOGGED, POWER_RESIDUAL), None, None, side="power",
                    regime_hint="ambient_temperature"),
):
    register_candidate(_cand)

DEFAULT_CANDIDATES: tuple[str, ...] = tuple(_CATALOG)
