"""Vehicle tractive-force model structures of chapter 5 and a registry for new ones.

A model structure is a list of terms; each term is one column of the measured inputs A (a regressor built from
the preprocessed vehicle states of :mod:`roadload.estimators.pipeline`) and one parameter of X. The measured
output is always the vehicle tractive force B = F_xV (eq. 5.5c). Built in:

- ``M0``: the abc white-box model (eq. 5.4), A = [cos θ, v cos θ, v², g sin θ + v̇], X = [a_V, b_V, c_V, m_V]
  fixed from a coast-down (no estimator);
- ``M3``: eq. 5.5, A = [g cos θ, g sin θ + v̇, v²], X = [m_V f_r0, m_V, ρ_a/2 A_V c_x];
- ``M4``: eq. 5.6, M3 plus the cornering resistance v⁴/(4 r²) with parameter m_V²/c_yW.

A user adds a structure with extra regressors through :func:`register_model` (e.g.
``register_model(get_model("M3").extend("M3w", Term(...)))``); the pipeline and the evaluation only ever call
:meth:`ModelStructure.regressors`, so nothing else needs to change.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Callable, Mapping

import numpy as np

from roadload.envs.coast_down import neutral_road_load
from roadload.registry import Registry
from roadload.road_load import RoadLoadParameters
from roadload.units import G, STANDARD_AIR_DENSITY

# Names of the preprocessed vehicle states the built-in regressors read (columns of the pipeline's "states" stage).
SPEED = "speed"                    # v_V [m/s]
ACCELERATION = "acceleration"      # dv_V/dt [m/s^2]
GRADIENT_ANGLE = "gradient_angle"  # θ [rad]
PATH_CURVATURE = "path_curvature"  # 1/r [1/m]
TRACTIVE_FORCE = "tractive_force"  # F_xV [N], eq. 5.5c

class ModelError(ValueError):
    """Unknown model name, duplicate registration, or states that lack what a model needs."""


@dataclass(frozen=True)
class NominalParameters:
    """What the estimating side knows about the vehicle before driving: the spec sheet's road load
    (:class:`roadload.road_load.RoadLoadParameters` at the air density ρ_a [kg/m^3] it assumes) and, when one was
    measured, the coast-down (a_V [N], b_V [N s/m], c_V [N s²/m²]) of eq. 5.4 (M0 is unavailable without it).

    Views: mass m_V [kg]; rolling_resistance_coefficient f_r0 [1]; drag_area c_x A_V [m^2]; cornering_stiffness
    c_yW [N/rad] as it enters eq. 2.15 (F_Wc = m_V² v⁴ / (4 r² c_yW)); drag_coefficient ρ_a/2 c_x A_V [kg/m].
    """

    road_load: RoadLoadParameters
    air_density: float = STANDARD_AIR_DENSITY
    coast_down: tuple[float, float, float] | None = None

    def __post_init__(self) -> None:
        if not np.isfinite(self.air_density) or self.air_density <= 0:
            raise ModelError(f"NominalParameters.air_density must be a positive finite number [kg/m^3], "
                             f"got {self.air_density!r}")
        for name, value, unit in (("rolling resistance a_V", self.road_load.c0, "N"),
                                  ("drag c_V", self.road_load.c2, "kg/m"),
                                  ("cornering k = m_V^2/c_yW", self.road_load.k_corner, "kg^2/N")):
            if value <= 0:
                raise ModelError(f"NominalParameters.road_load: {name} must be > 0 {unit}, got {value!r}")
        if self.coast_down is not None:
            if len(self.coast_down) != 3 or not all(np.isfinite(c) for c in self.coast_down):
                raise ModelError(f"NominalParameters.coast_down must be three finite numbers (a_V, b_V, c_V), "
                                 f"got {self.coast_down!r}")

    @classmethod
    def from_physical(cls, mass: float, rolling_resistance_coefficient: float, drag_area: float,
                      cornering_stiffness: float, air_density: float = STANDARD_AIR_DENSITY,
                      coast_down: tuple[float, float, float] | None = None) -> "NominalParameters":
        """From m_V [kg], f_r0 [1], c_x A_V [m^2], c_yW [N/rad] and ρ_a [kg/m^3]."""
        for name, value in (("mass", mass), ("rolling_resistance_coefficient", rolling_resistance_coefficient),
                            ("drag_area", drag_area), ("cornering_stiffness", cornering_stiffness),
                            ("air_density", air_density)):
            if not np.isfinite(value) or value <= 0:
                raise ModelError(f"NominalParameters.{name} must be a positive finite number, got {value!r}")
        road = RoadLoadParameters.from_physical(mass, rolling_resistance_coefficient, drag_area=drag_area,
                                                air_density=air_density, cornering_stiffness=cornering_stiffness)
        return cls(road, float(air_density), coast_down)

    @property
    def mass(self) -> float:
        return self.road_load.mass

    @property
    def rolling_resistance_coefficient(self) -> float:
        return self.road_load.rolling_resistance_f0()

    @property
    def drag_area(self) -> float:
        return self.road_load.drag_area(self.air_density)

    @property
    def cornering_stiffness(self) -> float:
        return self.road_load.mass ** 2 / self.road_load.k_corner

    @property
    def drag_coefficient(self) -> float:
        """ρ_a/2 A_V c_x [kg/m] — the third parameter of M3/M4."""
        return self.road_load.c2


@dataclass(frozen=True)
class Term:
    """One regressor column of A and its parameter in X.

    regressor: the column's formula (text); parameter: the parameter's symbol; unit: the parameter's SI unit;
    build: states -> column (1-D array); requires: state names build reads; nominal: NominalParameters ->
    initial value of the parameter (X̂_{t-1} of section 5.5); random_walk_variance: the diagonal entry of P_d
    for the random-walk estimators (section 5.5.3).
    """

    regressor: str
    parameter: str
    unit: str
    build: Callable[[Mapping[str, np.ndarray]], np.ndarray]
    requires: tuple[str, ...]
    nominal: Callable[[NominalParameters], float]
    random_walk_variance: float = 1e-6


@dataclass(frozen=True)
class ModelStructure:
    """A linear-in-parameters tractive-force model A X ≈ B with B = F_xV (eq. 5.5c).

    white_box: True when X is fixed from the nominal parameters (M0) and no estimator runs.
    """

    name: str
    terms: tuple[Term, ...]
    description: str = ""
    white_box: bool = False
    requires_output: tuple[str, ...] = field(default=(TRACTIVE_FORCE,))

    def __post_init__(self) -> None:
        if not self.name or not isinstance(self.name, str):
            raise ModelError("a model structure needs a non-empty name")
        if not self.terms:
            raise ModelError(f"model {self.name!r} has no terms")
        params = [t.parameter for t in self.terms]
        if len(set(params)) != len(params):
            raise ModelError(f"model {self.name!r} has duplicate parameters {params}")

    @property
    def n_params(self) -> int:
        return len(self.terms)

    @property
    def parameter_names(self) -> list[str]:
        return [t.parameter for t in self.terms]

    @property
    def parameter_units(self) -> list[str]:
        return [t.unit for t in self.terms]

    @property
    def requires(self) -> tuple[str, ...]:
        """Every state the regressors read (without the output)."""
        seen: list[str] = []
        for t in self.terms:
            seen += [r for r in t.requires if r not in seen]
        return tuple(seen)

    def missing(self, states: Mapping[str, np.ndarray]) -> list[str]:
        """States the model needs that are absent or entirely NaN."""
        out = []
        for name in self.requires + self.requires_output:
            if name not in states:
                out.append(name)
                continue
            col = np.asarray(states[name], dtype=float)
            if col.size and not np.any(np.isfinite(col)):
                out.append(name)
        return out

    def check(self, states: Mapping[str, np.ndarray]) -> None:
        miss = self.missing(states)
        if miss:
            absent = [m for m in miss if m not in states]
            empty = [m for m in miss if m in states]
            parts = ([f"lacks the states {absent}"] if absent else []) + \
                    ([f"has no valid sample of {empty} (all NaN, e.g. no steering signal for the path curvature)"]
                     if empty else [])
            raise ModelError(f"model {self.name!r} cannot be built: the trip " + " and ".join(parts))

    def regressors(self, states: Mapping[str, np.ndarray]) -> np.ndarray:
        """The measured inputs A [T x n] from the states."""
        self.check(states)
        cols = [np.asarray(t.build(states), dtype=float) for t in self.terms]
        return np.column_stack(cols)

    def output(self, states: Mapping[str, np.ndarray]) -> np.ndarray:
        """The measured output B = F_xV [N] (eq. 5.5c)."""
        self.check(states)
        return np.asarray(states[TRACTIVE_FORCE], dtype=float)

    def nominal_parameters(self, nominal: NominalParameters) -> np.ndarray:
        """X̂ from the vehicle spec (initial value of the estimators; the fixed parameters of a white box)."""
        return np.array([float(t.nominal(nominal)) for t in self.terms])

    def random_walk_variances(self) -> np.ndarray:
        """diag(P_d) of section 5.5.3 for this structure."""
        return np.array([t.random_walk_variance for t in self.terms])

    def predict(self, states: Mapping[str, np.ndarray], parameters: np.ndarray) -> np.ndarray:
        """B̂ = A X [N]."""
        return self.regressors(states) @ np.asarray(parameters, dtype=float)

    def extend(self, name: str, *terms: Term, description: str = "") -> "ModelStructure":
        """A new (gray-box) structure with this one's terms plus `terms`."""
        return replace(self, name=name, terms=self.terms + tuple(terms),
                       description=description or f"{self.name} + " + ", ".join(t.regressor for t in terms),
                       white_box=False)


def _col(states: Mapping[str, np.ndarray], name: str) -> np.ndarray:
    return np.asarray(states[name], dtype=float)


# ---------------------------------------------------------------- M3 / M4 terms (eq. 5.5, 5.6)
ROLLING = Term(
    regressor="g cos(theta)", parameter="m_V f_r0", unit="kg",
    build=lambda s: G * np.cos(_col(s, GRADIENT_ANGLE)), requires=(GRADIENT_ANGLE,),
    nominal=lambda n: n.mass * n.rolling_resistance_coefficient, random_walk_variance=5e-5)
INERTIA = Term(
    regressor="g sin(theta) + dv/dt", parameter="m_V", unit="kg",
    build=lambda s: G * np.sin(_col(s, GRADIENT_ANGLE)) + _col(s, ACCELERATION),
    requires=(GRADIENT_ANGLE, ACCELERATION), nominal=lambda n: n.mass, random_walk_variance=1e-6)
AERO = Term(
    regressor="v^2", parameter="rho_a/2 A_V c_x", unit="kg/m",
    build=lambda s: _col(s, SPEED) ** 2, requires=(SPEED,),
    nominal=lambda n: n.drag_coefficient, random_walk_variance=1e-8)
CORNERING = Term(
    regressor="v^4/(4 r^2)", parameter="m_V^2/c_yW", unit="kg^2 rad/N",
    build=lambda s: _col(s, SPEED) ** 4 * _col(s, PATH_CURVATURE) ** 2 / 4.0,
    requires=(SPEED, PATH_CURVATURE), nominal=lambda n: n.mass ** 2 / n.cornering_stiffness,
    random_walk_variance=1e-6)


def _coast(n: NominalParameters, i: int) -> float:
    if n.coast_down is None:
        raise ModelError("model M0 needs coast-down coefficients (a_V, b_V, c_V); the nominal parameters have none")
    return float(n.coast_down[i])


# ---------------------------------------------------------------- M0 terms (eq. 5.4)
M0 = ModelStructure(
    name="M0",
    description="abc white-box model (eq. 5.4), parameters fixed from a coast-down",
    white_box=True,
    terms=(
        Term("cos(theta)", "a_V", "N", lambda s: np.cos(_col(s, GRADIENT_ANGLE)), (GRADIENT_ANGLE,),
             lambda n: _coast(n, 0)),
        Term("v cos(theta)", "b_V", "N s/m", lambda s: _col(s, SPEED) * np.cos(_col(s, GRADIENT_ANGLE)),
             (SPEED, GRADIENT_ANGLE), lambda n: _coast(n, 1)),
        Term("v^2", "c_V", "N s^2/m^2", lambda s: _col(s, SPEED) ** 2, (SPEED,), lambda n: _coast(n, 2)),
        INERTIA,
    ),
)
M3 = ModelStructure(name="M3", terms=(ROLLING, INERTIA, AERO),
                    description="longitudinal gray-box model (eq. 5.5)")
M4 = M3.extend("M4", CORNERING, description="longitudinal and lateral gray-box model (eq. 5.6)")

_MODELS: Registry[ModelStructure] = Registry("model", ModelStructure, ModelError)


def register_model(model: ModelStructure, replace_existing: bool = False) -> ModelStructure:
    """Add a model structure to the registry (ModelError if the name is taken and replace_existing is False)."""
    if not isinstance(model, ModelStructure):
        raise ModelError(f"register_model expects a ModelStructure, got {type(model).__name__}")
    return _MODELS.register(model.name, model, replace_existing)


def get_model(name: str | ModelStructure) -> ModelStructure:
    """The registered model structure of that name (ModelError listing the known names otherwise)."""
    return _MODELS.get(name)


def model_names() -> list[str]:
    return _MODELS.names()


for _m in (M0, M3, M4):
    register_model(_m)


# ---------------------------------------------------------------- coast-down fit (for M0)
def fit_coast_down(t: np.ndarray, speed: np.ndarray, effective_mass: float,
                   grade: np.ndarray | None = None) -> tuple[float, float, float]:
    """Coast-down coefficients (a_V [N], b_V [N s/m], c_V [N s²/m²]) from a coast-down record.

    Fits -m_eff dv/dt - m_eff g sin θ = a_V + b_V v + c_V v² by least squares, where m_eff [kg] includes the
    rotating parts that decelerate with the vehicle (as a manufacturer's evaluation of a coast-down does).
    t [s], speed [m/s], grade θ [rad] (flat when None).
    """
    t = np.asarray(t, dtype=float)
    v = np.asarray(speed, dtype=float)
    if t.shape != v.shape or t.size < 10:
        raise ModelError(f"coast-down: need >= 10 samples of equal-length t and speed, got {t.size} and {v.size}")
    if not (np.all(np.isfinite(t)) and np.all(np.isfinite(v))):
        raise ModelError("coast-down: t or speed contains NaN/inf")
    if not np.all(np.diff(t) > 0):
        raise ModelError("coast-down: t is not strictly increasing")
    if not np.isfinite(effective_mass) or effective_mass <= 0:
        raise ModelError(f"coast-down: effective mass must be positive, got {effective_mass!r}")
    dv = np.gradient(v, t)
    force = -effective_mass * dv
    if grade is not None:
        force = force - effective_mass * G * np.sin(np.asarray(grade, dtype=float))
    A = np.column_stack([np.ones_like(v), v, v ** 2])
    coef, *_ = np.linalg.lstsq(A, force, rcond=None)
    return float(coef[0]), float(coef[1]), float(coef[2])


def simulate_coast_down(spec, v_start: float = 130 / 3.6, v_end: float = 15 / 3.6, dt: float = 0.1
                        ) -> tuple[np.ndarray, np.ndarray, float]:
    """A coast-down of the nominal vehicle (no effects, flat road, no wind, neutral) as a manufacturer runs it.

    Integrates m_eff dv/dt = -F_road(v) with the simulator's road load of the spec (rolling resistance, drag and
    the drive-train's spin losses in neutral; :func:`roadload.envs.coast_down.neutral_road_load`) by RK4 from
    v_start to v_end [m/s]; returns (t [s], v [m/s], m_eff [kg]) sampled every dt [s]."""
    m_eff = float(spec.effective_mass(0))
    if not (v_start > v_end > 0 and dt > 0):
        raise ModelError(f"coast-down needs v_start > v_end > 0 and dt > 0, got {v_start}, {v_end}, {dt}")

    v_grid = np.linspace(0.9 * v_end, 1.05 * v_start, 300)
    force = np.asarray(neutral_road_load(spec, v_grid), dtype=float)   # the simulator's road load, evaluated once
    if force.shape != v_grid.shape or not np.all(np.isfinite(force)):
        raise ModelError(f"the road load of vehicle {getattr(spec, 'name', '?')!r} is not finite on "
                         f"[{v_grid[0]:.3g}, {v_grid[-1]:.3g}] m/s")

    def accel(v: float) -> float:
        return -float(np.interp(v, v_grid, force)) / m_eff

    t, v = [0.0], [float(v_start)]
    while v[-1] > v_end:
        x = v[-1]
        k1 = accel(x)
        k2 = accel(x + 0.5 * dt * k1)
        k3 = accel(x + 0.5 * dt * k2)
        k4 = accel(x + dt * k3)
        v.append(x + dt / 6.0 * (k1 + 2 * k2 + 2 * k3 + k4))
        t.append(t[-1] + dt)
        if len(t) > 200_000:
            raise ModelError("coast-down did not reach v_end (road load too small?)")
    return np.array(t), np.array(v), m_eff


def coast_down_coefficients(spec) -> tuple[float, float, float]:
    """(a_V [N], b_V [N s/m], c_V [N s²/m²]) of M0 (eq. 5.4) from a simulated coast-down of the nominal spec."""
    t, v, m_eff = simulate_coast_down(spec)
    return fit_coast_down(t, v, m_eff)


def published_coast_down(spec, air_density: float = STANDARD_AIR_DENSITY) -> tuple[float, float, float]:
    """(a_V, b_V, c_V) of eq. 5.4 from spec-sheet values alone: a_V = m_V g f_r0, b_V = m_V g f_r1,
    c_V = ρ_a/2 c_x A_V (section 5.4.1) — for vehicles whose coast-down is not measured (real logs)."""
    return RoadLoadParameters.from_spec(spec, air_density=air_density).coast_down
