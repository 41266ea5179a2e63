"""Energy at the source for the MPC objective: smooth fits of the powertrain maps.

Both powertrains use one smooth loss polynomial in shaft speed omega [rad/s] and torque T [N m]
(copper losses ~ T^2, friction / iron losses ~ omega, omega^2, battery resistance ~ (T omega)^2):

    P_loss(omega, T) = l0 + l1 omega + l2 omega^2 + l3 T^2 + l4 (T omega)^2                 [W]

- EV: battery power P_bat = F v + P_loss(omega_M, T_M) + P_aux, where F = F_trac - F_regen is the net wheel
  force of the motor, omega_M = v i / r_W, T_M = F r_W / i (motor/inverter map fitted by least squares).
- ICE: fuel power P_fuel = (F_trac v + P_loss(omega_E, T_E)) / eta_i + P_idle (Willans line: indicated
  efficiency eta_i plus speed-dependent friction), omega_E = v i_G(G) i_D / r_W; braking through the engine's
  drag (engine brake / retarder, fuel cut) is the ICE's ``regen`` force: limited, and free of fuel. The gear G is
  NOT optimised: it comes from a shift rule on speed (:meth:`SourceEnergyModel.gear_for_speed`), applied by
  the MPC as a smooth function of the planned speed (:meth:`SourceEnergyModel.smooth_ratio`).
- ICE with the plant's fuel map (:class:`PlantFuelModel`, ``MpcSettings.fuel_model = "plant_map"``): the fuel
  power of the gear of least fuel in the plant's own quasi-static map, over (speed, net wheel force), 0 in overrun
  (fuel cut; the brakes take a force beyond the engine's drag), smoothed for the NLP
  (:meth:`PlantFuelModel.smooth_table`); the gear is then chosen per move, not by a shift rule.

The polynomial is convex in the forces and smooth in v > 0, which keeps the NLP (and the QP path) well-behaved.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from roadload.units import G


class EnergyModelError(ValueError):
    """Invalid powertrain-energy settings or map data."""


@dataclass(frozen=True)
class SourceEnergyModel:
    """Smooth source-energy model of one powertrain. kind: "ev" (battery energy) or "ice" (fuel energy)."""

    kind: str
    wheel_radius: float  # r_W [m]
    gear_ratios: tuple[float, ...]  # overall ratios wheel->shaft per gear (EV: one entry, incl. final drive)
    loss: tuple[float, ...]  # l0 [W], l1 [W s/rad], l2 [W s^2/rad^2], l3 [W/(N m)^2], l4 [1/W]
    max_power: float  # P_max [W] at the wheel (traction)
    max_torque: float  # T_max [N m] at the shaft (motor / engine)
    max_regen_power: float = 0.0  # [W] (EV only)
    max_regen_torque: float = 0.0  # [N m]
    indicated_efficiency: float = 1.0  # eta_i (ICE); 1 for EV
    auxiliary_power: float = 0.0  # P_aux (EV) / idle fuel power (ICE) [W]
    max_brake_deceleration: float = 8.0  # friction brake capability [m/s^2] times mass gives its force limit
    shift_speeds: tuple[float, ...] = field(default=())  # ICE: upshift speeds [m/s], len(gear_ratios) - 1
    name: str = ""
    # ICE: the largest wheel force [N] of full load in each gear: (speeds [m/s], (force of gear 1 per speed), ...);
    # 0 where the engine speed is out of range; empty: unknown (gear_for_force keeps the shift rule's gear)
    traction_table: tuple[tuple[float, ...], ...] = field(default=())
    # ICE: wheel power at full load over the shaft speed, P = p0 + p1 omega + p2 omega^2 [W] (a fit over every
    # gear's full load); empty: max_power at every speed
    full_load_power: tuple[float, ...] = field(default=())
    # ICE: engine speed range (idle, maximum) [rad/s] of the gear choice (best_gear_fuel_power); empty: unknown
    engine_speed_range: tuple[float, ...] = field(default=())
    # ICE: the plant's own fuel map per gear (PlantFuelModel); None: not attached (MpcSettings.fuel_model "willans")
    plant_fuel: PlantFuelModel | None = None

    def __post_init__(self) -> None:
        if self.kind not in ("ev", "ice"):
            raise EnergyModelError(f"powertrain kind must be 'ev' or 'ice', got {self.kind!r}")
        if self.wheel_radius <= 0 or not self.gear_ratios or min(self.gear_ratios) <= 0:
            raise EnergyModelError("wheel_radius and gear_ratios must be positive")
        if self.kind == "ice" and len(self.shift_speeds) != len(self.gear_ratios) - 1:
            raise EnergyModelError(f"ICE needs {len(self.gear_ratios) - 1} shift speeds for {len(self.gear_ratios)} "
                                   f"gears, got {len(self.shift_speeds)}")
        if self.kind == "ev" and len(self.gear_ratios) != 1:
            raise EnergyModelError("an EV model has exactly one (fixed) ratio")
        if len(self.loss) != 5 or not all(np.isfinite(self.loss)):
            raise EnergyModelError(f"loss must hold 5 finite coefficients (l0..l4), got {self.loss}")
        if not 0 < self.indicated_efficiency <= 1:
            raise EnergyModelError(f"indicated_efficiency must be in (0, 1], got {self.indicated_efficiency}")
        if self.max_power <= 0 or self.max_torque <= 0:
            raise EnergyModelError("max_power and max_torque must be positive")

    # ------------------------------------------------------------------ gears
    @property
    def regenerates(self) -> bool:
        """True when the drive can brake without the friction brakes: EV regeneration, or an ICE's engine brake /
        retarder in fuel cut (zero fuel, the ``regen`` force of an ICE costs nothing in :meth:`source_power`)."""
        return self.max_regen_power > 0 and self.max_regen_torque > 0

    def gear_with_hysteresis(self, v: float, previous: int | None, band: float) -> int:
        """Gear index (0-based) of the speed-based shift rule held within +-``band`` [m/s] of each shift speed:
        the previous gear is kept while v stays between the gears of v - band and v + band (no shift hunting when
        the speed hovers at a shift speed); the rule's own gear without a previous one. 0 for an EV."""
        if self.kind == "ev":
            return 0
        if previous is None:
            return int(self.gear_for_speed(v))
        low, high = int(self.gear_for_speed(v - band)), int(self.gear_for_speed(v + band))
        return min(max(previous, low), high)

    def gear_for_force(self, v: float, force: float, preferred: int) -> int:
        """Gear index (0-based) for a traction force [N] at speed v [m/s]: ``preferred`` (the shift rule's) while its
        full load delivers the force, else the highest lower gear that does (a kick-down), else the one with the
        most force (:attr:`traction_table`; without one, ``preferred``)."""
        if self.kind == "ev" or not self.traction_table:
            return preferred
        capacity = [self.full_load_force(v, g) for g in range(len(self.gear_ratios))]
        if capacity[preferred] >= force:
            return preferred
        for g in range(preferred - 1, -1, -1):
            if capacity[g] >= force:
                return g
        return int(np.argmax(capacity))

    def full_load_force(self, v: float, gear: int) -> float:
        """The wheel force [N] of full load in ``gear`` (0-based) at speed v [m/s], from :attr:`traction_table` (0
        where the engine speed is out of range); inf without a table (no limit known)."""
        if not self.traction_table:
            return math.inf
        return float(np.interp(v, self.traction_table[0], self.traction_table[gear + 1]))

    def gear_for_speed(self, v) -> np.ndarray:
        """Gear index (0-based) from the speed-based shift rule; always 0 for an EV."""
        v = np.asarray(v, dtype=float)
        if self.kind == "ev":
            return np.zeros(v.shape, dtype=int)
        return np.searchsorted(np.asarray(self.shift_speeds), v, side="right").astype(int)

    def ratio_for_speed(self, v) -> np.ndarray:
        """Overall ratio shaft/wheel [-] at speed v from the shift rule."""
        return np.asarray(self.gear_ratios, dtype=float)[self.gear_for_speed(v)]

    def smooth_ratio(self, v, width: float = 1.0):
        """The shift rule as a smooth function of speed (numpy or CasADi): i_1 + sum_g (i_{g+1} - i_g)
        (1 + tanh((v - v_shift,g)/width))/2 [-]; used inside the NLP so the engine speed follows the planned
        speed (a ratio fixed from a previous plan would penalise speeding up in a low gear)."""
        if self.kind == "ev":
            return self.gear_ratios[0] + 0.0 * v
        try:
            import casadi as ca
            tanh = ca.tanh if isinstance(v, (ca.SX, ca.MX, ca.DM)) else np.tanh
        except ImportError:  # pragma: no cover
            tanh = np.tanh
        r = self.gear_ratios
        out = r[0] + 0.0 * v
        for g, vs in enumerate(self.shift_speeds):
            out = out + (r[g + 1] - r[g]) * 0.5 * (1.0 + tanh((v - vs) / width))
        return out

    def best_gear_fuel_power(self, wheel_force, v) -> tuple[np.ndarray, np.ndarray]:
        """ICE, numpy: the lowest fuel power [W] over every gear for a wheel force [N] (net: < 0 brakes) at speed v
        [m/s], and that gear (0-based; -1 where none can). A gear can when its engine speed is in
        :attr:`engine_speed_range` and, for a traction force, its full load (:attr:`traction_table`) gives it. Fuel
        per gear: the Willans line of :meth:`source_power`, with fuel cut while braking,
        P = max(0, (F v + P_loss(omega, 0)) / eta_i) for F < 0 (the engine's drag takes F v down to -P_loss, the
        brakes the rest, no fuel). inf where no gear can. An ICE without the tables: the shift rule's gear."""
        f, v = np.broadcast_arrays(np.asarray(wheel_force, float), np.asarray(v, float))
        if self.kind != "ice":
            raise EnergyModelError("best_gear_fuel_power: an ICE model only (an EV has one ratio)")
        tables = bool(self.traction_table) and len(self.engine_speed_range) == 2
        gears = range(len(self.gear_ratios)) if tables else [None]
        idle, top = self.engine_speed_range if tables else (0.0, np.inf)
        traction = np.maximum(f, 0.0)
        best, gear = np.full(f.shape, np.inf), np.full(f.shape, -1)
        for g in gears:
            ratio = self.smooth_ratio(v) if g is None else self.gear_ratios[g]
            omega = v * ratio / self.wheel_radius
            ok = (omega >= idle) & (omega <= top)
            if g is not None:
                ok &= traction <= np.interp(v, self.traction_table[0], self.traction_table[g + 1])
            willans = (f * v + self.loss_power(omega, traction * self.wheel_radius / ratio)) / self.indicated_efficiency
            power = np.where(ok, np.maximum(willans, 0.0) + self.auxiliary_power, np.inf)
            better = power < best
            best, gear = np.where(better, power, best), np.where(better, -1 if g is None else g, gear)
        return best, gear

    # ------------------------------------------------------------------ limits (numpy or casadi)
    def max_traction_force(self, v, ratio):
        """Wheel-force limit of the drive [N] from shaft torque (ignores the power limit; see max_power)."""
        return self.max_torque * ratio / self.wheel_radius

    def max_regen_force(self, ratio):
        return self.max_regen_torque * ratio / self.wheel_radius if self.regenerates else 0.0

    def traction_power_limit(self, v):
        """Traction power [W] the drive gives at the wheels at speed v [m/s] (numpy or CasADi): ICE with a
        full-load fit, that fit at the shift rule's (smooth) shaft speed, at most max_power; otherwise max_power."""
        if self.kind == "ev" or not self.full_load_power:
            return self.max_power + 0.0 * v
        omega = v * self.smooth_ratio(v) / self.wheel_radius
        p0, p1, p2 = self.full_load_power
        power = p0 + p1 * omega + p2 * omega * omega
        try:
            import casadi as ca
            if isinstance(v, (ca.SX, ca.MX, ca.DM)):
                return ca.fmin(power, self.max_power)
        except ImportError:  # pragma: no cover
            pass
        return np.minimum(power, self.max_power)

    # ------------------------------------------------------------------ power
    def source_power(self, traction_force, regen_force, v, ratio):
        """Power drawn at the source [W]: battery (EV) or fuel (ICE); numpy or CasADi expressions.

        traction_force, regen_force >= 0 [N] at the wheels; v [m/s]; ratio = overall shaft/wheel ratio.
        """
        omega = v * ratio / self.wheel_radius
        if self.kind == "ev":
            net = traction_force - regen_force
            return net * v + self.loss_power(omega, net * self.wheel_radius / ratio) + self.auxiliary_power
        torque = traction_force * self.wheel_radius / ratio
        return (traction_force * v + self.loss_power(omega, torque)) / self.indicated_efficiency + self.auxiliary_power

    def loss_power(self, shaft_speed, shaft_torque):
        """P_loss(omega, T) [W] of the fitted polynomial."""
        l0, l1, l2, l3, l4 = self.loss
        p_mech = shaft_torque * shaft_speed
        return (l0 + l1 * shaft_speed + l2 * shaft_speed * shaft_speed + l3 * shaft_torque * shaft_torque
                + l4 * p_mech * p_mech)

    def brake_force_limit(self, mass: float) -> float:
        return self.max_brake_deceleration * mass


class PlantFuelModel:
    """An ICE plant's own quasi-static fuel map per gear, as the MPC uses it (``MpcSettings.fuel_model =
    "plant_map"``), read from a :class:`~.dynamic_programming.PlantFuelMap` (the one the plant-fuel bound uses:
    fuel[g, i, j] [W] at speed v_i [m/s] and net wheel force F_j [N], each gear's full load max_force[g, i] [N], its
    overrun drag, its speed ratio k_g [rad/s per m/s] and the engine speed range [rad/s]).

    - :meth:`gear_fuel_power`: P_g(v, F) [W] per gear, bilinear in the map, inf where gear g cannot (k_g v outside
      the engine speed range, or F above its full load); 0 at or below the gear's drag (fuel cut, brakes free).
    - :meth:`least_fuel_gear`: the gear the controller requests, argmin_g P_g(v, F) with hysteresis.
    - :meth:`smooth_table`: phi(v, F) = min_g P_g(v, F) on the map's grid, continued linearly in F above the
      largest full load, smoothed by a Gaussian of (sigma_v, sigma_F); the NLP's fuel power (a cubic B-spline
      through it, :class:`~.mpc.OcpSolver`), with the traction limit F <= F_max(v) = max_g max_force[g](v)
      (:meth:`full_load_envelope`).

    Compared by ``key`` (the vehicle spec it was built from), so an energy model carrying it stays hashable."""

    def __init__(self, fuel_map: Any, key: str) -> None:
        for name in ("speeds", "forces", "fuel", "max_force", "speed_ratio", "engine_speed_range", "gear_power"):
            if not hasattr(fuel_map, name):
                raise EnergyModelError(f"PlantFuelModel: the fuel map has no {name!r} (expected a PlantFuelMap)")
        self.map = fuel_map
        self.key = key

    def __eq__(self, other: object) -> bool:
        return isinstance(other, PlantFuelModel) and other.key == self.key

    def __hash__(self) -> int:
        return hash(("PlantFuelModel", self.key))

    def __repr__(self) -> str:
        return f"PlantFuelModel({self.key!r})"

    @property
    def gears(self) -> int:
        return int(np.asarray(self.map.fuel).shape[0])

    def full_load(self, v: float) -> np.ndarray:
        """Each gear's full-load wheel force [N] at speed v [m/s] (linear in the map's speeds); 0 where the gear's
        engine speed is out of range."""
        sp = np.asarray(self.map.speeds)
        vc = min(max(v, sp[0]), sp[-1])
        i = int(np.clip(np.searchsorted(sp, vc) - 1, 0, sp.size - 2))
        wv = (vc - sp[i]) / (sp[i + 1] - sp[i])
        mf = np.asarray(self.map.max_force)
        lo, hi = self.map.engine_speed_range
        omega = np.asarray(self.map.speed_ratio) * v
        return np.where((omega >= lo) & (omega <= hi), (1 - wv) * mf[:, i] + wv * mf[:, i + 1], 0.0)

    def gear_fuel_power(self, v: float, force: float, load_margin: float = 1.0) -> np.ndarray:
        """P_g(v, F) [W] of every gear at speed v [m/s] and net wheel force F [N] (class docstring), inf where the
        gear cannot give F / load_margin [N] (load_margin <= 1 keeps a reserve below full load) or its engine speed
        is out of range: the map's own per-gear look-up (:meth:`~.dynamic_programming.PlantFuelMap.gear_power`) with
        the speed clamped to the map's edge (a gear is named at any measured speed; the bound refuses such a
        speed instead)."""
        value = np.asarray(self.map.gear_power(v, force, clamp_speed=True), float)
        return np.where(force <= load_margin * self.full_load(v), value, np.inf)

    def least_fuel_gear(self, v: float, force: float, current: int | None = None, hysteresis: float = 0.005,
                        load_margin: float = 0.98) -> int:
        """The gear (0-based) of least fuel at speed v [m/s] and net wheel force F [N] among those whose full load
        gives F / load_margin (a reserve for a gear to shift into); ``current`` is kept while its full load gives F
        and its fuel is within (1 + hysteresis) of the least (no hunting between gears of nearly equal fuel, e.g.
        in overrun where every gear burns 0). No gear can: ``current`` if it can, else the one with the largest
        full load."""
        fuel = self.gear_fuel_power(v, force, load_margin)
        stay = (float(self.gear_fuel_power(v, force)[current]) if current is not None and 0 <= current < self.gears
                else np.inf)
        keep = current is not None and bool(np.isfinite(stay))
        if not np.isfinite(fuel).any():
            return int(current) if keep and current is not None else int(np.argmax(self.full_load(v)))
        best = int(np.argmin(fuel))
        if keep and current is not None and stay <= (1.0 + hysteresis) * fuel[best] + 1e-9:
            return int(current)
        return best

    def full_load_envelope(self) -> tuple[np.ndarray, np.ndarray]:
        """(speeds [m/s], the largest full-load wheel force over the gears in range [N]) on the map's speeds."""
        sp = np.asarray(self.map.speeds, float)
        return sp, np.array([self.full_load(float(v)).max() for v in sp])

    def smooth_table(self, sigma_speed: float = 0.5, sigma_force: float = 500.0, fuel_cut: bool = True,
                     rule_gear: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(speeds [m/s], forces [N], phi [W] (speeds x forces)): the least fuel over the gears (class docstring),
        continued linearly in F above the largest full load (the slope of its last 2 kN; the NLP's traction limit
        keeps the plan below it), then smoothed by a Gaussian of sigma_speed [m/s] x sigma_force [N] so that a cubic
        spline through it does not ring at the fuel cut and the gear changes.

        Model variants that separate what the map buys: ``fuel_cut`` False charges a braking force the fuel of
        F = 0 (the engine's friction fuelled, as the Willans line does); ``rule_gear`` (0-based gear per map speed,
        a shift rule's) prices each speed in that gear, or where its full load cannot give F the highest lower
        gear that can (a kick-down), instead of the least over the gears."""
        from scipy.ndimage import gaussian_filter

        sp, fo = np.asarray(self.map.speeds, float), np.asarray(self.map.forces, float)
        lo, hi = self.map.engine_speed_range
        omega = np.asarray(self.map.speed_ratio, float)[:, None] * sp[None, :]  # (gears, speeds)
        able = (((omega >= lo) & (omega <= hi))[:, :, None]
                & (fo[None, None, :] <= np.asarray(self.map.max_force, float)[:, :, None]))
        per_gear = np.where(able, np.asarray(self.map.fuel, float), np.inf)
        if rule_gear is None:
            table = per_gear.min(axis=0)  # gear_fuel_power's least
        else:
            table = np.full(per_gear.shape[1:], np.inf)
            for g in range(per_gear.shape[0] - 1, -1, -1):  # from the top: the rule's gear, else lower ones
                take = (np.asarray(rule_gear)[:, None] >= g) & ~np.isfinite(table)
                table = np.where(take, per_gear[g], table)
        if not fuel_cut:
            table = np.where(fo[None, :] < 0.0, table[:, [int(np.argmin(np.abs(fo)))]], table)
        for row in table:
            ok = np.flatnonzero(np.isfinite(row))
            last = ok[-1]
            tail = ok[fo[ok] >= fo[last] - 2000.0]
            slope = np.polyfit(fo[tail], row[tail], 1)[0] if tail.size > 1 else 0.0
            row[last + 1:] = row[last] + slope * (fo[last + 1:] - fo[last])
            row[:ok[0]] = 0.0  # below every gear's table: brakes (fuel cut)
        sigma = (sigma_speed / (sp[1] - sp[0]), sigma_force / (fo[1] - fo[0]))
        return sp, fo, gaussian_filter(table, sigma, mode="nearest")


def with_loss_error(model: SourceEnergyModel, error: float) -> SourceEnergyModel:
    """The energy model with every loss coefficient scaled by (1 + error) (sensitivity map: a wrong drive-train /
    engine loss model in the MPC)."""
    if not np.isfinite(error) or error <= -1.0:
        raise EnergyModelError(f"loss error must be finite and > -1, got {error}")
    return replace(model, loss=tuple(float(c) * (1.0 + error) for c in model.loss))


def fit_loss_polynomial(shaft_speed, shaft_torque, loss_power) -> tuple[float, float, float, float, float]:
    """Non-negative least-squares fit of P_loss = l0 + l1 omega + l2 omega^2 + l3 T^2 + l4 (T omega)^2 to samples
    (omega [rad/s], T [N m], loss [W]); NaN samples (outside the map) are dropped. Non-negative coefficients
    keep the losses physical and the objective convex in the forces. Returns (l0, l1, l2, l3, l4)."""
    from scipy.optimize import nnls

    w, t, p = (np.asarray(a, dtype=float).ravel() for a in np.broadcast_arrays(shaft_speed, shaft_torque, loss_power))
    ok = np.isfinite(w) & np.isfinite(t) & np.isfinite(p)
    if ok.sum() < 5:
        raise EnergyModelError(f"need at least 5 finite map samples to fit the loss polynomial, got {int(ok.sum())}")
    a = np.column_stack([np.ones(ok.sum()), w[ok], w[ok] ** 2, t[ok] ** 2, (t[ok] * w[ok]) ** 2])
    scale = np.abs(a).max(axis=0)
    scale[scale == 0] = 1.0
    coef, _ = nnls(a / scale, p[ok])
    l0, l1, l2, l3, l4 = (float(c) for c in coef / scale)
    return l0, l1, l2, l3, l4


def generic_ev(mass: float = 1420.0) -> SourceEnergyModel:
    """An i3-like EV (125 kW, 250 N m, single ratio 9.665, r_W 0.35 m), loss coefficients chosen for
    ~90-93 % motor+inverter efficiency at part load. Used when no simulator spec is at hand (tests, benches)."""
    return SourceEnergyModel(kind="ev", wheel_radius=0.35, gear_ratios=(9.665,),
                             loss=(300.0, 0.5, 2.0e-3, 0.06, 1.5e-7),
                             max_power=125e3, max_torque=250.0, max_regen_power=50e3, max_regen_torque=150.0,
                             auxiliary_power=300.0, max_brake_deceleration=0.8 * G, name="generic_ev")
