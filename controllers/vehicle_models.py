"""The controller's view of a simulator vehicle: source-energy fit, abc (M0) parameters, oracle parameters.

- :func:`energy_model_from_spec` samples the vehicle's own maps through the simulator's drive-train functions
  (exact inverse of the loss maps, motor loss map / fuel map, battery resistance) on a grid of speed and wheel
  force (and gear for the ICE) and fits the smooth loss polynomial of :mod:`.energy` by least squares.
- :func:`abc_parameters`: M0 (eq. 5.4) with the coast-down coefficients of the nominal vehicle
  (:func:`roadload.estimators.models.coast_down_coefficients`, a simulated coast-down) and the nominal mass.
- :func:`oracle_parameters`: the simulator's current true parameters (``Simulator.true_parameters()``) as
  :class:`~roadload.road_load.RoadLoadParameters` (wind: its component along the current heading).
"""

from __future__ import annotations

import json
from functools import lru_cache

import numpy as np

from roadload.road_load import RoadLoadParameters
from roadload.units import G
from roadload.vehicle import VehicleSpec

from .energy import SourceEnergyModel, fit_loss_polynomial

from roadload.envs.powertrain import Powertrain
from roadload.envs import get_preset
from roadload.estimators.models import coast_down_coefficients


def _spec(vehicle: VehicleSpec | str) -> VehicleSpec:
    if isinstance(vehicle, str):

        return get_preset(vehicle)
    return vehicle


def rotational_mass(spec: VehicleSpec, gear: int | None = None) -> float:
    """(I_red(G) + 4 I_W) / r_W^2 [kg]; ICE without a gear: the middle gear (a truck's box of >= 10 gears: the
    top gear, where a long-haul truck spends its time)."""
    d = spec.drivetrain
    g = gear if gear is not None else (1 if d.n_gears == 1 else d.n_gears if d.n_gears >= TRUCK_GEARBOX_GEARS
                                       else max(1, d.n_gears // 2 + 1))
    return float(spec.effective_mass(g) - spec.body.mass)


FIT_QUALITY: dict[str, dict[str, float]] = {}
TRUCK_GEARBOX_GEARS = 10  # a gearbox with at least this many gears is a truck's (rotational mass: top gear)
HEAVY_VEHICLE_MASS = 7500.0  # [kg]: above it the energy fit covers up to 80 % of rated power


def _record_fit(name: str, w, t, loss, coef) -> None:
    w, t, loss = map(np.asarray, (w, t, loss))
    pred = coef[0] + coef[1] * w + coef[2] * w ** 2 + coef[3] * t ** 2 + coef[4] * (t * w) ** 2
    FIT_QUALITY[name] = {"rms_error_W": float(np.sqrt(np.mean((pred - loss) ** 2))),
                         "mean_loss_W": float(np.mean(loss))}


@lru_cache(maxsize=16)
def _energy_model_cached(name: str, spec_json: str) -> SourceEnergyModel:
    import json

    return _fit_energy(VehicleSpec.from_dict(json.loads(spec_json)))


def energy_model_from_spec(vehicle: VehicleSpec | str) -> SourceEnergyModel:
    """Smooth source-energy model fitted to the vehicle's maps (module docstring); cached per spec."""
    import json

    spec = _spec(vehicle)
    return _energy_model_cached(spec.name, json.dumps(spec.to_dict(), sort_keys=True))


def wheel_power_limit(spec: VehicleSpec) -> float:
    """The largest traction power [W] the drive delivers at the wheels: full-load torque through the gearbox and
    differential with their losses (the plant's drive-train functions), over speeds 3-40 m/s and every gear whose
    engine speed is in range. The MPC's power constraint F_t v <= P_max is at the wheels, so the engine's rated
    power would over-state it (truck: 352 kW rated against 334 kW at the wheels)."""
    pt = Powertrain(spec)
    d = spec.drivetrain
    engine = d.require_engine() if d.kind != "bev" else None
    r = float(spec.tires.dynamic_radius)
    best = 0.0
    for v in np.linspace(3.0, 40.0, 75):
        for gear in range(1, d.n_gears + 1):
            omega = pt.speed_ratio(gear) * v
            if engine is not None and not engine.idle_speed <= omega <= engine.max_speed:
                continue
            _, t_max = pt.torque_limits(omega, v)
            wheel_torque = pt.wheel_torque(gear, t_max, omega)
            best = max(best, wheel_torque / r * v)
    return best


def _fit_energy(spec: VehicleSpec) -> SourceEnergyModel:

    pt = Powertrain(spec)
    d = spec.drivetrain
    r = float(spec.tires.dynamic_radius)
    speeds = np.linspace(3.0, 40.0, 38)
    if d.kind == "bev":
        m = d.require_motor()
        battery = d.require_battery()
        ratio = float(d.gear_ratios[0] * d.final_drive)
        aux = float(battery.auxiliary_power)
        voc = float(battery.open_circuit_voltage)
        w_list, t_list, loss = [], [], []
        for v in speeds:
            omega = pt.speed_ratio(1) * v
            t_min, t_max = pt.torque_limits(omega, v)
            # the operating region of eco-driving: |P_mech| <= 60 kW
            f_hi = min(t_max * ratio / r * 0.95, 60e3 / v)
            f_lo = max(t_min * ratio / r * 0.95, -60e3 / v)
            for f in np.linspace(f_lo, f_hi, 25):
                t_m = pt.source_torque(1, f * r, omega)
                if not (t_min <= t_m <= t_max):
                    continue
                p_src = voc * pt.battery_current(pt.motor_electric_power(omega, t_m) + aux)
                w_list.append(omega)
                t_list.append(f * r / ratio)
                loss.append(p_src - f * v - aux)
        coef = fit_loss_polynomial(w_list, t_list, loss)
        _record_fit(spec.name, w_list, t_list, loss, coef)
        return SourceEnergyModel(kind="ev", wheel_radius=r, gear_ratios=(ratio,), loss=coef,
                                 max_power=wheel_power_limit(spec), max_torque=float(m.max_torque),
                                 max_regen_power=float(m.regen_power_limit),
                                 max_regen_torque=float(m.regen_torque_limit),
                                 auxiliary_power=aux, max_brake_deceleration=0.8 * G, name=spec.name)
    e = d.require_engine()
    if e is None or d.shift is None:
        raise ValueError(f"{spec.name}: an ICE drive-train needs an engine and a shift spec")
    ratios = tuple(float(g * d.final_drive) for g in d.gear_ratios)
    # the eco-driving operating region: up to 80 kW for a car, up to 80 % of rated power for a heavy vehicle
    rated = float(np.max(np.asarray(e.full_load.x) * np.asarray(e.full_load.y)))
    power_cap = 80e3 if spec.body.mass < HEAVY_VEHICLE_MASS else 0.8 * rated
    rows, target = [], []
    for gear in range(1, d.n_gears + 1):
        for v in speeds:
            omega = pt.speed_ratio(gear) * v
            if not e.idle_speed <= omega <= e.max_speed:
                continue
            t_drag, t_max = pt.torque_limits(omega, v)
            ratio = ratios[gear - 1]
            for f in np.linspace(50.0, min(0.9 * t_max * ratio / r, power_cap / v), 15):
                t_e = pt.source_torque(gear, f * r, omega)
                if not (t_drag < t_e <= t_max):
                    continue
                torque_w = f * r / ratio
                rows.append([f * v, 1.0, omega, omega ** 2, torque_w ** 2, (f * v) ** 2])
                target.append(pt.fuel_power(omega, t_e))
    from scipy.optimize import nnls

    a = np.asarray(rows)
    scale = np.abs(a).max(axis=0)
    coef, _ = nnls(a / scale, np.asarray(target))  # Willans line with non-negative friction terms
    coef = coef / scale
    eta = 1.0 / coef[0]
    ice_loss = tuple(float(c * eta) for c in coef[1:])
    pred = np.asarray(rows) @ coef
    FIT_QUALITY[spec.name] = {"rms_error_W": float(np.sqrt(np.mean((pred - np.asarray(target)) ** 2))),
                              "mean_fuel_power_W": float(np.mean(target))}
    # speed-only shift rule: upshift where the engine reaches the mean of the zero/full-load upshift speeds
    shift_rule = d.require_shift()
    up = 0.5 * (shift_rule.upshift_speed_low + shift_rule.upshift_speed_high)
    shift = tuple(float(up * r / ratios[g]) for g in range(d.n_gears - 1))
    torque_max = float(np.max(e.full_load.y))
    power_max = wheel_power_limit(spec)
    # engine brake (+ retarder) in fuel cut: the drag torque at the shift rule's cruising speed, and the largest
    # drag power over the speed range, both at 90 % (the plant drops braking beyond its capacity)
    w_drag = np.linspace(float(e.idle_speed), float(e.max_speed), 50)
    drag = -np.interp(w_drag, e.drag.x, e.drag.y)
    brake_torque = 0.9 * float(np.interp(up, e.drag.x, -np.asarray(e.drag.y)))
    brake_power = 0.9 * float(np.max(drag * w_drag))
    table_speeds = np.linspace(1.0, 40.0, 79)
    forces, full_omega, full_power = [], [], []
    for gear in range(1, d.n_gears + 1):
        row = []
        for v in table_speeds:
            omega = pt.speed_ratio(gear) * v
            if not e.idle_speed <= omega <= e.max_speed:
                row.append(0.0)
                continue
            _, t_full = pt.torque_limits(omega, v)
            row.append(pt.wheel_torque(gear, t_full, omega) / r)
            full_omega.append(omega)
            full_power.append(row[-1] * v)
        forces.append(tuple(row))
    # the wheel power at full load over the shaft speed, a quadratic over the upper half of the speed range (where
    # the shift rule keeps the engine): the MPC's traction power limit at the shift rule's speed
    fo, fp = np.asarray(full_omega), np.asarray(full_power)
    upper = fo >= 0.5 * (e.idle_speed + e.max_speed) - 0.25 * (e.max_speed - e.idle_speed)
    full_load = tuple(float(c) for c in np.polyfit(fo[upper], fp[upper], 2)[::-1])
    return SourceEnergyModel(kind="ice", wheel_radius=r, gear_ratios=ratios, loss=ice_loss, max_power=power_max,
                             max_torque=torque_max, max_regen_power=brake_power, max_regen_torque=brake_torque,
                             indicated_efficiency=float(min(max(eta, 0.05), 1.0)),
                             auxiliary_power=0.0, max_brake_deceleration=0.8 * G, shift_speeds=shift, name=spec.name,
                             traction_table=(tuple(map(float, table_speeds)), *forces), full_load_power=full_load,
                             engine_speed_range=(float(e.idle_speed), float(e.max_speed)))


_COAST_DOWN_BY_SPEC: dict[str, tuple[float, float, float]] = {}


@lru_cache(maxsize=16)
def _coast_down(name: str) -> tuple[float, float, float]:

    return coast_down_coefficients(get_preset(name))


def abc_parameters(vehicle: VehicleSpec | str) -> RoadLoadParameters:
    """M0 (eq. 5.4): a_V, b_V, c_V of the nominal vehicle's simulated coast-down, nominal mass m_V and the
    rotational equivalent mass (preset vehicles: cached by name)."""
    spec = _spec(vehicle)
    if isinstance(vehicle, str):
        a, b, c = _coast_down(vehicle)
    else:
        key = json.dumps(spec.to_dict(), sort_keys=True)
        if key not in _COAST_DOWN_BY_SPEC:
            _COAST_DOWN_BY_SPEC[key] = coast_down_coefficients(spec)
        a, b, c = _COAST_DOWN_BY_SPEC[key]
    return RoadLoadParameters.from_coast_down(a, b, c, mass=float(spec.body.mass),
                                              rotational_mass=rotational_mass(spec))


def oracle_parameters(truth: dict[str, float], spec: VehicleSpec) -> RoadLoadParameters:
    """RoadLoadParameters from ``Simulator.true_parameters()`` (:meth:`RoadLoadParameters.from_truth`)."""
    return RoadLoadParameters.from_truth(truth)
