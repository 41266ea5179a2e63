"""The composition of one recursive estimator: which part is used for each step of the kernel, and its settings.

:class:`EstimatorConfig` is validated on construction (unknown choices, out-of-range values and wrong shapes
raise :class:`EstimatorConfigError` naming the setting) and translates itself into the integer/float codes of
:mod:`roadload.estimators.kernel`.
"""

from __future__ import annotations

import dataclasses
import types
import typing
from dataclasses import field
from typing import Annotated, Any, Literal, overload

import annotated_types as at
import numpy as np
from pydantic import ConfigDict, Field, Strict, ValidationError, field_validator, model_validator
from pydantic.fields import FieldInfo
from roadload.schema import spec_dataclass

from . import kernel as K
from .influence import MAD_CONSISTENCY, InfluenceError, check_psi_params, psi_code, psi_defaults


class EstimatorConfigError(ValueError):
    """An estimator composition or setting is invalid; the message names the setting and the allowed range."""


COVARIANCE_KINDS = {"forgetting": K.COV_FORGETTING, "kalman": K.COV_KALMAN,
                    "stenlund_gustafsson": K.COV_SG}
_COV_ALIASES = {"rls": "forgetting", "lambda": "forgetting", "kf": "kalman", "sg": "stenlund_gustafsson",
                "stenlund-gustafsson": "stenlund_gustafsson", "desired": "stenlund_gustafsson"}
REGULARISATION_KINDS = {"none": K.REG_NONE, "levenberg_marquardt": K.REG_LM, "tikhonov": K.REG_TIKHONOV}
_REG_ALIASES = {"lm": "levenberg_marquardt", "levenberg-marquardt": "levenberg_marquardt",
                "levenbergmarquardt": "levenberg_marquardt", None: "none", "off": "none"}
INSTRUMENT_KINDS = {"none": K.IV_NONE, "delayed": K.IV_DELAY, "user": K.IV_USER}


def _setting(doc: str, unit: str = "1", *, gt: float | None = None, ge: float | None = None,
             lt: float | None = None, le: float | None = None) -> Any:
    """A declared numeric setting (pydantic Field): its bounds ``gt``/``ge``/``lt``/``le``, meaning and unit; pydantic
    checks them on construction (a setting left at None is one the composition does not use)."""
    return Field(description=f"{doc} [{unit}]", json_schema_extra={"unit": unit}, gt=gt, ge=ge, lt=lt, le=le)


#: a finite number: int or float, never a string or a bool (pydantic strict; NaN/inf refused by the config)
Real = Annotated[float, Strict()]
Count = Annotated[int, Strict()]

# ---- the defaults of the estimators: each written here once (section 5.5 where the text gives them)
#: λ of the forgetting family and of RGTLS (section 5.5)
FORGETTING = 0.999
#: R¹, the output noise of the Kalman family (section 5.5)
OUTPUT_NOISE = 0.8
#: k of the delayed instruments 𝔄_t = A_{t-k} (section 5.5)
INSTRUMENT_DELAY = 4
#: P_0 = 100 I (section 5.5)
INITIAL_COVARIANCE = 100.0
#: a max diag P above this × max diag P_0 is reported as blow-up
BLOWUP_RATIO = 1e6

# ---- settings several estimators share: declared (bounds, meaning, unit) once, checked by pydantic
ParameterCount = Annotated[Count, Field(ge=1, description="number of parameters n [1]")]
Forgetting = Annotated[Real, _setting("forgetting factor lambda", gt=0.0, le=1.0)]
BlowupRatio = Annotated[Real, _setting("blow-up report level, x max diag P0", gt=1.0)]


def _field_name(cls: type, loc: tuple) -> str:
    """The setting an error location points at (a positional argument's index becomes its name)."""
    names = [f.name for f in dataclasses.fields(cls) if f.init]
    if loc and isinstance(loc[0], int) and loc[0] < len(names):
        return names[loc[0]]
    return str(loc[0]) if loc else ""


def _range_text(name: str, value: Any, kind: str, integer: bool, info: FieldInfo) -> str:
    """``<name> must lie in (lo, hi] [unit], got <value>`` (or the integer / number form) of a declared setting."""
    bounds = {type(m): m for m in info.metadata}
    unit = info.json_schema_extra.get("unit", "1") if isinstance(info.json_schema_extra, dict) else "1"
    lo, lo_open = (bounds[at.Gt].gt, True) if at.Gt in bounds else (getattr(bounds.get(at.Ge), "ge", -np.inf), False)
    hi, hi_open = (bounds[at.Lt].lt, True) if at.Lt in bounds else (getattr(bounds.get(at.Le), "le", np.inf), False)
    if integer:
        where = f">= {lo}" if hi == np.inf else f"in [{lo}, {hi}]"
        return f"{name} must be an integer {where}{'' if unit == '1' else f' [{unit}]'}, got {value!r}"
    if kind in ("float_type", "float_parsing"):
        return f"{name} must be a number [{unit}], got {value!r}"
    hi_open = hi_open or hi == np.inf
    return (f"{name} must lie in {'(' if lo_open else '['}{float(lo)}, {float(hi)}{')' if hi_open else ']'} "
            f"[{unit}], got {value!r}")


_TYPE_ERRORS = {"bool_type": "{name} must be true or false, got {value!r}",
                "string_type": "{name} must be a string, got {value!r}",
                "unexpected_keyword_argument": "unknown setting(s) [{name!r}]; valid settings are {valid}",
                "unexpected_positional_argument": "unknown setting(s) [{name!r}]; valid settings are {valid}"}


def _error_text(exc: ValidationError, cls: type) -> str:
    """The first error of a ValidationError of an estimator's settings class as one line naming the setting, its
    range and unit: ``forgetting must lie in (0.0, 1.0] [1], got 0.0``."""
    err = exc.errors(include_url=False)[0]
    ctx = err.get("ctx") or {}
    if err["type"] == "value_error" and isinstance(ctx.get("error"), ValueError):
        return str(ctx["error"])
    name, value = _field_name(cls, tuple(err["loc"])), err.get("input")
    declared = _declared_hints(cls)
    if name in declared:
        return _range_text(name, value, err["type"], *declared[name])
    if err["type"] in _TYPE_ERRORS:
        return _TYPE_ERRORS[err["type"]].format(name=name, value=value, valid=sorted(setting_names(cls)))
    return f"{name}: {err['msg']}, got {value!r}"


def python_scalar(cls: type, value: Any) -> Any:
    """Before-validator of integer and boolean settings: numpy integers and booleans count as Python ones (the strict
    int and bool types refuse them)."""
    if isinstance(value, np.bool_):
        return bool(value)
    return int(value) if isinstance(value, np.integer) else value


_T = typing.TypeVar("_T")


@typing.dataclass_transform(field_specifiers=(dataclasses.field, Field))
def settings_dataclass(frozen: bool = False, error: type[ValueError] = EstimatorConfigError
                       ) -> typing.Callable[[type[_T]], type[_T]]:
    """The decorator of the estimators' settings classes: a pydantic dataclass whose errors are ``error`` lines
    naming the setting, the value and the expected range with its unit."""
    return spec_dataclass(ConfigDict(extra="forbid", allow_inf_nan=False, arbitrary_types_allowed=True),
                          lambda exc, cls: error(_error_text(exc, cls)), frozen=frozen)


def start_vector(x0: Any, n: int) -> np.ndarray:
    """X̂_0: n finite numbers (default 0)."""
    out = np.zeros(n) if x0 is None else np.asarray(x0, dtype=float).reshape(-1)
    if out.shape != (n,) or not np.all(np.isfinite(out)):
        raise EstimatorConfigError(f"x0 must be {n} finite numbers, got {x0!r}")
    return out


@overload
def _matrix(value: Any, n: int, what: str, *, allow_none: Literal[False] = False, psd: bool = False) -> np.ndarray: ...


@overload
def _matrix(value: Any, n: int, what: str, *, allow_none: bool, psd: bool = False) -> np.ndarray | None: ...


def _matrix(value: Any, n: int, what: str, *, allow_none: bool = False, psd: bool = False) -> np.ndarray | None:
    """A scalar (→ value·I), a length-n vector (→ diag) or an n×n matrix, checked finite."""
    if value is None:
        if allow_none:
            return None
        raise EstimatorConfigError(f"{what} is required")
    arr = np.asarray(value, dtype=float)
    if arr.ndim == 0:
        arr = float(arr) * np.eye(n)
    elif arr.ndim == 1:
        if arr.shape[0] != n:
            raise EstimatorConfigError(f"{what}: expected {n} diagonal entries, got {arr.shape[0]}")
        arr = np.diag(arr)
    elif arr.shape != (n, n):
        raise EstimatorConfigError(f"{what}: expected a scalar, {n} diagonal entries or an {n}x{n} matrix, "
                                   f"got shape {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise EstimatorConfigError(f"{what} contains NaN or inf")
    if psd:
        if not np.allclose(arr, arr.T, rtol=1e-10, atol=1e-300):
            raise EstimatorConfigError(f"{what} must be symmetric")
        if np.min(np.linalg.eigvalsh(arr)) < -1e-12 * max(1.0, np.max(np.abs(arr))):
            raise EstimatorConfigError(f"{what} must be positive semi-definite")
        arr = 0.5 * (arr + arr.T)  # exactly symmetric (the kernel relies on it; a symmetric input is unchanged)
    return np.ascontiguousarray(arr)


@settings_dataclass()
class EstimatorConfig:
    """One recursive estimator as a composition of parts (chapter 3). Units: X in units of B per unit of A.

    Parts and their settings (the text's symbols in brackets):

    - weights: ``psi`` in {'l2','huber','myriad','cauchy','tukey','hampel','l1l2','l1'}, ``psi_params``
      (δ, β, c, or Hampel's a, b, c; defaults in :mod:`.influence`);
    - scale: fixed ``scale0`` (σ̂), or ``robust_scale`` = recursive quantile (Algorithm 3.3) with
      ``quantile0`` (Q̂_0), ``learn_rate`` (η), ``quantile_p`` (p), ``scale_forgetting`` (λ of σ̂²),
      ``scale_factor`` (1.483); ``scale_iterations`` > 1 iterates a time step until X̂_t converges
      (``iteration_tol``, relative) — the "optimal" variant;
    - gain direction: ``instruments`` 'none' (A_t), 'delayed' (𝔄_t = the regressor ``instrument_delay``
      valid samples earlier; the first ones use A_t itself) or 'user' (𝔄_t passed to update/run);
    - covariance evolution: ``covariance`` 'forgetting' (``forgetting`` λ, default 0.999), 'kalman'
      (``process_noise`` Q, ``output_noise`` R¹, default 0.8) or 'stenlund_gustafsson' (``desired_covariance``
      P_d, R¹); ``joseph`` form in the Kalman family without instruments. A setting the chosen parts do not
      use (λ for the Kalman family, R¹ for forgetting, Q without 'kalman', P_d without 'stenlund_gustafsson',
      ``instrument_delay`` without delayed instruments) is rejected, never silently ignored;
    - regularisation: ``regularisation`` 'none', 'levenberg_marquardt' or 'tikhonov' with ``kappa`` (κ),
      always with the P normalisation P(I+κP)⁻¹ (eq. 3.34);
    - constraints: ``x_min`` / ``x_max`` saturation (section 3.10.1);
    - initial state ``x0`` (default 0) and ``p0`` (scalar·I, diagonal or matrix; default 100 I, section 5.5);
    - ``transition`` F (n×n): prediction X' = F X, P' = F P Fᵀ before each update (used by the PKS);
    - numerics: ``symmetrize`` keeps P symmetric (only where it is symmetric in exact arithmetic, i.e.
      without instruments); ``blowup_ratio``: max diag P above this × max diag P0 is reported as blow-up;
      ``covariance_bound_ratio``: the safety net of every composition resets P to P_0 (counted, reported as
      blow-up) when max diag P exceeds this × max diag P0, or when an update leaves P non-finite or not
      positive definite (that update is also rolled back).
    """

    n_params: ParameterCount
    name: str = "custom"
    psi: str = "l2"
    psi_params: tuple[Real, ...] | None = None
    robust_scale: Annotated[bool, Strict()] = False
    scale0: Annotated[Real, _setting("initial / fixed scale sigma_0", "unit of B", gt=0.0)] = 25.0
    quantile0: Annotated[Real, _setting("initial quantile Q_0 of the squared residual", "unit of B^2",
                                        ge=0.0)] = 350.0
    learn_rate: Annotated[Real, _setting("learning rate eta of the recursive quantile (eq. 3.29)", gt=0.0)] = 0.01
    quantile_p: Annotated[Real, _setting("quantile p of the recursive quantile", gt=0.0, lt=1.0)] = 0.5
    scale_forgetting: Annotated[Real, _setting("forgetting lambda of sigma^2 (Algorithm 3.3)", ge=0.0,
                                               le=1.0)] = 0.995
    scale_factor: Annotated[Real, _setting("consistency factor of the robust scale", gt=0.0)] = MAD_CONSISTENCY
    scale_iterations: Annotated[Count, _setting("iterations of one time step (optimal variant)", ge=1)] = 1
    iteration_tol: Annotated[Real, _setting("relative convergence tolerance of the iterations", ge=0.0)] = 1e-10
    min_scale: Annotated[Real, _setting("floor of the scale sigma", "unit of B", gt=0.0)] = 1e-12
    covariance: str = "forgetting"
    forgetting: Forgetting | None = None
    process_noise: Any = None
    output_noise: Annotated[Real, _setting("output noise R (Kalman family)", "unit of B^2", gt=0.0)] | None = None
    desired_covariance: Any = None
    joseph: Annotated[bool, Strict()] = False
    regularisation: str = "none"
    kappa: Annotated[Real, _setting("regularisation kappa (eq. 3.34)", ge=0.0)] = 0.0
    instruments: str = "none"
    instrument_delay: Annotated[Count, _setting("instrument delay in valid samples", ge=1)] | None = None
    x_min: Any = None
    x_max: Any = None
    x0: Any = None
    p0: Any = INITIAL_COVARIANCE
    transition: Any = None
    symmetrize: Annotated[bool, Strict()] = True
    blowup_ratio: BlowupRatio = BLOWUP_RATIO
    covariance_bound_ratio: Annotated[Real, _setting("covariance reset level, x max diag P0", gt=1.0)] = 1e8
    _arrays: dict = field(default_factory=dict, init=False, repr=False, compare=False)  # set by _kernel_arrays

    # ------------------------------------------------------------------ validation (pydantic, in this order:
    # the declared fields, the choices, then the model validators top to bottom)
    _numpy_scalars = field_validator("n_params", "scale_iterations", "instrument_delay", "robust_scale", "joseph",
                                     "symmetrize", mode="before")(python_scalar)

    @field_validator("psi_params", mode="before")
    @classmethod
    def _psi_params_as_tuple(cls, given: Any) -> Any:
        """A scalar or array of tuning constants becomes a tuple (at most 3: delta, beta, c or Hampel's a, b, c)."""
        if given is None or isinstance(given, tuple):
            return given
        return tuple(np.atleast_1d(np.asarray(given)).tolist())

    @field_validator("psi")
    @classmethod
    def _known_psi(cls, psi: str) -> str:
        try:
            psi_code(psi)
        except InfluenceError as exc:
            raise EstimatorConfigError(str(exc)) from None
        return psi.lower().replace("-", "").replace("_", "")

    @field_validator("covariance", mode="before")
    @classmethod
    def _known_covariance(cls, cov: Any) -> str:
        name = _COV_ALIASES.get(str(cov).lower(), str(cov).lower())
        if name not in COVARIANCE_KINDS:
            raise EstimatorConfigError(f"covariance {cov!r} unknown; choose one of {sorted(COVARIANCE_KINDS)}")
        return name

    @field_validator("regularisation", mode="before")
    @classmethod
    def _known_regularisation(cls, reg: Any) -> str:
        name = _REG_ALIASES.get(reg.lower() if isinstance(reg, str) else reg, reg)
        if name not in REGULARISATION_KINDS:
            raise EstimatorConfigError(f"regularisation {reg!r} unknown; choose one of "
                                       f"{sorted(REGULARISATION_KINDS)}")
        return str(name)

    @field_validator("instruments", mode="before")
    @classmethod
    def _known_instruments(cls, iv: Any) -> str:
        if str(iv).lower() not in INSTRUMENT_KINDS:
            raise EstimatorConfigError(f"instruments {iv!r} unknown; choose one of {sorted(INSTRUMENT_KINDS)}")
        return str(iv).lower()

    @model_validator(mode="after")
    def _psi_tuning_constants(self) -> "EstimatorConfig":
        """Fill the influence function's defaults and check its constants (:func:`.influence.check_psi_params`)."""
        params = list(psi_defaults(self.psi))
        if self.psi_params is not None:
            if len(self.psi_params) > 3:
                raise EstimatorConfigError(f"psi_params: at most 3 tuning constants, got {len(self.psi_params)}")
            params[:len(self.psi_params)] = self.psi_params
        c1, c2, c3 = (float(p) for p in params)
        try:
            check_psi_params(self.psi, (c1, c2, c3))
        except InfluenceError as exc:
            raise EstimatorConfigError(str(exc)) from None
        self.psi_params = (c1, c2, c3)
        return self

    @model_validator(mode="after")
    def _check_unused_settings(self) -> "EstimatorConfig":
        """Cross-setting check: reject settings the chosen parts ignore; fill in the defaults of the ones they
        use."""
        where = f"estimator {self.name!r} (covariance {self.covariance!r}, instruments {self.instruments!r})"
        unused = []
        if self.covariance == "forgetting":
            if self.output_noise is not None:
                unused.append(("output_noise", ("R¹ only enters the Kalman family ('kalman', "
                                               "'stenlund_gustafsson')")))
            if self.forgetting is None:
                self.forgetting = FORGETTING
        else:
            if self.forgetting is not None:
                unused.append(("forgetting", ("λ only enters covariance 'forgetting'; the Kalman family forgets "
                                             "through process_noise Q or desired_covariance P_d")))
            if self.output_noise is None:
                self.output_noise = OUTPUT_NOISE
        if self.covariance != "kalman" and self.process_noise is not None:
            unused.append(("process_noise", "Q only enters covariance 'kalman'"))
        if self.covariance != "stenlund_gustafsson" and self.desired_covariance is not None:
            unused.append(("desired_covariance", "P_d only enters covariance 'stenlund_gustafsson'"))
        if self.instruments == "delayed":
            if self.instrument_delay is None:
                self.instrument_delay = INSTRUMENT_DELAY
        elif self.instrument_delay is not None:
            unused.append(("instrument_delay", "the delay only enters instruments 'delayed'"))
        if unused:
            name, why = unused[0]
            raise EstimatorConfigError(f"{name} = {getattr(self, name)!r} is not used by {where}: {why}; "
                                       f"remove it or choose parts that use it")
        return self

    @model_validator(mode="after")
    def _compatible_parts(self) -> "EstimatorConfig":
        """kappa only with a regularisation; the Joseph form only in the Kalman family without instruments."""
        if self.regularisation == "none" and self.kappa != 0.0:
            raise EstimatorConfigError(f"kappa = {self.kappa} given without regularisation; set regularisation "
                                       "to 'levenberg_marquardt' or 'tikhonov'")
        if self.joseph and self.covariance == "forgetting":
            raise EstimatorConfigError("joseph=True applies to the Kalman family (covariance 'kalman' or "
                                       "'stenlund_gustafsson'), not to forgetting")
        if self.joseph and self.instruments != "none":
            raise EstimatorConfigError("joseph=True is defined for regressor gains only, not with instruments")
        return self

    @model_validator(mode="after")
    def _kernel_arrays(self) -> "EstimatorConfig":
        """Matrix-valued settings (Q, P_d, P_0 symmetric PSD; x0, bounds, F by shape) and the kernel's codes."""
        n = self.n_params
        Q, Pd, P0 = self._covariances()
        xmin, xmax, x0 = self._bounds_and_start()
        F = self._transition_matrix()
        constrain = bool(np.any(np.isfinite(xmin)) or np.any(np.isfinite(xmax)))
        codes, values = self._codes(constrain), self._values(float(np.max(np.diag(P0))))
        self._arrays = {"ip": codes, "fp": values, "Q": Q if Q is not None else np.zeros((n, n)),
                        "Pd": Pd if Pd is not None else np.zeros((n, n)), "F": F, "xmin": xmin, "xmax": xmax,
                        "x0": x0, "P0": P0}
        matrices = tuple(self._arrays[k] for k in ("Q", "Pd", "F", "xmin", "xmax", "P0"))
        for store in (K.STORE_FINAL, K.STORE_X, K.STORE_FULL):   # the parts record with each store code
            store_codes = codes.copy()
            store_codes[K.IP_STORE] = store
            self._arrays[("parts", store)] = (store_codes, values) + matrices
        return self

    def _covariances(self) -> tuple[np.ndarray | None, np.ndarray | None, np.ndarray]:
        """Q (required by 'kalman'), P_d (required by 'stenlund_gustafsson') and P_0 (positive diagonal)."""
        n = self.n_params
        shapes = f"a scalar, {n} diagonal entries or an {n}x{n} matrix"
        Q = _matrix(self.process_noise, n, "process_noise (Q)", allow_none=True, psd=True)
        if self.covariance == "kalman" and Q is None:
            raise EstimatorConfigError(f"covariance 'kalman' needs process_noise (Q): {shapes}")
        Pd = _matrix(self.desired_covariance, n, "desired_covariance (P_d)", allow_none=True, psd=True)
        if self.covariance == "stenlund_gustafsson" and Pd is None:
            raise EstimatorConfigError(f"covariance 'stenlund_gustafsson' needs desired_covariance (P_d): {shapes}")
        P0 = _matrix(self.p0, n, "p0", psd=True)
        if np.max(np.diag(P0)) <= 0:
            raise EstimatorConfigError("p0 must have a positive diagonal")
        return Q, Pd, P0

    def _transition_matrix(self) -> np.ndarray:
        """F (n×n, finite; identity when not set)."""
        n = self.n_params
        if self.transition is None:
            return np.eye(n)
        F = np.asarray(self.transition, dtype=float)
        if F.shape != (n, n) or not np.all(np.isfinite(F)):
            raise EstimatorConfigError(f"transition must be a finite {n}x{n} matrix")
        return np.ascontiguousarray(F)

    def _bounds_and_start(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """x_min, x_max (±inf where not set, x_min <= x_max) and X̂_0 (n finite numbers, saturated)."""
        n = self.n_params
        x0 = start_vector(self.x0, n)
        xmin, xmax = (np.full(n, fill) if given is None else np.broadcast_to(np.asarray(given, dtype=float),
                                                                              (n,)).copy()
                      for given, fill in ((self.x_min, -np.inf), (self.x_max, np.inf)))
        if np.any(np.isnan(xmin)) or np.any(np.isnan(xmax)) or np.any(xmin > xmax):
            raise EstimatorConfigError(f"need x_min <= x_max element-wise, got x_min={xmin}, x_max={xmax}")
        return xmin, xmax, np.clip(x0, xmin, xmax)

    def _codes(self, constrain: bool) -> np.ndarray:
        """The integer codes of the parts (``kernel.IP_*``)."""
        codes = np.zeros(K.N_IP, dtype=np.int64)
        codes[K.IP_PSI] = psi_code(self.psi)
        codes[K.IP_COV] = COVARIANCE_KINDS[self.covariance]
        codes[K.IP_REG] = REGULARISATION_KINDS[self.regularisation]
        codes[K.IP_IV] = INSTRUMENT_KINDS[self.instruments]
        codes[K.IP_DELAY] = self.instrument_delay if self.instrument_delay is not None else 1
        codes[K.IP_ROBUST_SCALE] = int(bool(self.robust_scale))
        codes[K.IP_MAX_ITER] = self.scale_iterations
        codes[K.IP_JOSEPH] = int(bool(self.joseph))
        codes[K.IP_SYMMETRIC] = int(bool(self.symmetrize) and self.instruments == "none")
        codes[K.IP_CONSTRAIN] = int(constrain)
        codes[K.IP_TRANSITION] = int(self.transition is not None)
        return codes

    def _values(self, p0_max: float) -> np.ndarray:
        """The float settings (``kernel.FP_*``); ``p0_max`` = max diag P_0 scales the blow-up and reset levels."""
        values = np.zeros(K.N_FP)
        values[K.FP_C1], values[K.FP_C2], values[K.FP_C3] = self.psi_params or psi_defaults(self.psi)  # filled above
        values[K.FP_LAMBDA] = self.forgetting if self.forgetting is not None else 1.0  # 1.0: not used
        values[K.FP_R] = self.output_noise if self.output_noise is not None else 1.0
        values[K.FP_KAPPA] = self.kappa
        values[K.FP_ETA] = self.learn_rate
        values[K.FP_P] = self.quantile_p
        values[K.FP_LAMBDA_SCALE] = self.scale_forgetting
        values[K.FP_SCALE_FACTOR] = self.scale_factor
        values[K.FP_TOL] = self.iteration_tol
        values[K.FP_MIN_SCALE] = self.min_scale
        values[K.FP_BLOWUP_LEVEL] = self.blowup_ratio * p0_max
        values[K.FP_P_BOUND] = self.covariance_bound_ratio * p0_max
        return values

    # ------------------------------------------------------------------ helpers
    @property
    def kernel_arrays(self) -> dict:
        """The code/setting arrays handed to the kernel (read-only by convention)."""
        return self._arrays

    def kernel_parts(self, store: int) -> tuple:
        """The ``parts`` record of :func:`~roadload.estimators.kernel.run_record` (``kernel.PARTS_FIELDS``) with
        the store code ``store`` (``kernel.STORE_*``)."""
        return self._arrays[("parts", store)]

    def replace(self, **changes: Any) -> EstimatorConfig:
        """A validated copy with some settings changed (unknown names raise EstimatorConfigError)."""
        check_setting_names(changes)
        return dataclasses.replace(self, **changes)

    def settings(self) -> dict[str, Any]:
        """All settings as a plain dict (arrays as given)."""
        return {f.name: getattr(self, f.name) for f in dataclasses.fields(self) if f.init}


def _declared_hints(cls: type | None = None) -> dict[str, tuple[bool, FieldInfo]]:
    """name -> (integer, Field info) of the settings of ``cls`` (default EstimatorConfig) declared with bounds
    (cached per class)."""
    cls = EstimatorConfig if cls is None else cls
    if cls not in _DECLARED:
        declared = _DECLARED[cls] = {}
        for name, hint in typing.get_type_hints(cls, include_extras=True).items():
            if typing.get_origin(hint) in (typing.Union, types.UnionType):  # X | None: a setting used by some parts
                hint = next(a for a in typing.get_args(hint) if a is not type(None))
            if typing.get_origin(hint) is not Annotated:
                continue
            info = next((m for m in hint.__metadata__ if isinstance(m, FieldInfo)), None)
            if info is None:
                continue
            base = typing.get_args(hint)[0]
            declared[name] = (base is int or int in typing.get_args(base), info)
    return _DECLARED[cls]


_DECLARED: dict[type, dict[str, tuple[bool, FieldInfo]]] = {}


def setting_names(cls: type | None = None) -> list[str]:
    """Names accepted as settings/overrides of ``cls`` (default EstimatorConfig)."""
    return [f.name for f in dataclasses.fields(EstimatorConfig if cls is None else cls) if f.init]


def check_setting_names(settings: dict[str, Any]) -> None:
    """Raise EstimatorConfigError for any key that is not an EstimatorConfig setting."""
    valid = set(setting_names())
    unknown = sorted(set(settings) - valid)
    if unknown:
        raise EstimatorConfigError(f"unknown setting(s) {unknown}; valid settings are {sorted(valid)}")


def estimator_defaults() -> dict[str, Any]:
    """The default of every EstimatorConfig setting, with the part-dependent ones (λ of the forgetting family, R¹
    of the Kalman family, the instrument delay) at the values the parts that use them get."""
    out = {f.name: f.default for f in dataclasses.fields(EstimatorConfig)
           if f.init and f.default is not dataclasses.MISSING}
    out.update(forgetting=FORGETTING, output_noise=OUTPUT_NOISE, instrument_delay=INSTRUMENT_DELAY)
    return out
