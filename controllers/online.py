"""The ``online`` force model: a recursive estimator running on the vehicle's CAN data during the drive.

Every ``update_period`` seconds it takes the CAN samples since its last update (plus ``margin`` seconds for the
smoothers to settle) from its ``can_source``, runs them through the chapter-5 pipeline
(:func:`roadload.estimators.pipeline.run_pipeline`: PKS smoothing, 10 Hz states, eq. 5.2 gradient, eq. 5.3
curvature, drive-train rim torque, the trigger of section 5.3) and feeds the new triggered rows of the chosen
model structure (M4 by default; any registered structure whose parameters the MPC can use: M3, M4, M0) to the
chosen catalog estimator (RRLM by default, section 5.5 settings), one row at a time.

``parameters()`` maps the current estimate X̂ onto the MPC's resistance polynomial: m_V f_r0 -> c0 = g X̂_0,
m_V -> mass (grade and acceleration), rho_a/2 A_V c_x -> c2, m_V^2/c_yW -> k_corner (M0's a_V, b_V, c_V map to
c0, c1, c2). Estimates outside a plausible range around the nominal values are clipped (counted in
``clipped``) so one bad update cannot make the NLP ill-posed.
"""

from __future__ import annotations

from typing import Any, Callable

import numpy as np

from roadload.road_load import RoadLoadParameters
from roadload.trip import Trip
from roadload.units import G

from .force_model import ForceModelError
from roadload.estimators import chapter5_settings, make_estimator
from roadload.estimators.change import ChangeDetection, CusumDetector, reset_covariance
from roadload.estimators.models import get_model
from roadload.estimators.pipeline import PipelineError, PipelineSettings, model_data, run_pipeline

# estimator parameter name -> (RoadLoadParameters field, factor)
_MAPPING = {"m_V f_r0": ("c0", G), "m_V": ("mass", 1.0), "rho_a/2 A_V c_x": ("c2", 1.0),
            "m_V^2/c_yW": ("k_corner", 1.0), "a_V": ("c0", 1.0), "b_V": ("c1", 1.0), "c_V": ("c2", 1.0)}


class OnlineForceModel:
    """Force model from an estimator on the CAN stream (module docstring)."""

    name = "online"
    # parameters of the structure that a subclass maps itself (not onto a RoadLoadParameters field)
    extra_parameters: tuple[str, ...] = ()

    def __init__(self, knowledge, model: str = "M4", estimator: str = "RRLM", update_period: float = 10.0,
                 margin: float = 3.0, estimator_settings: dict[str, Any] | None = None,
                 pipeline_settings: PipelineSettings | None = None,
                 change_detection: ChangeDetection | None = None) -> None:

        self.knowledge = knowledge
        self.structure = get_model(model)
        unknown = [p for p in self.structure.parameter_names if p not in _MAPPING and p not in self.extra_parameters]
        if unknown:
            raise ForceModelError(f"model {self.structure.name!r} has parameters the MPC cannot use: {unknown}; "
                                  f"usable: {sorted(_MAPPING)}")
        if update_period <= 0 or margin < 0:
            raise ForceModelError("update_period must be > 0 s and margin >= 0 s")
        self.model_name, self.estimator_name = self.structure.name, estimator.upper()
        self.x0 = self.structure.nominal_parameters(knowledge.nominal)
        if estimator_settings is None:
            table = chapter5_settings("M4" if self.structure.n_params >= 4 else "M3")
            estimator_settings = dict(table.get(self.estimator_name, {"n_params": self.structure.n_params}))
        estimator_settings = {**estimator_settings, "n_params": self.structure.n_params}
        pd = estimator_settings.get("desired_covariance")
        if pd is not None and len(pd) < self.structure.n_params:  # a structure with more terms than M3 / M4: their
            # random-walk variances (Term.random_walk_variance) for the added parameters
            extra = self.structure.random_walk_variances()[len(pd):]
            estimator_settings["desired_covariance"] = [*pd, *map(float, extra)]
        self.change_detection = change_detection
        self._reset_diagonal = (None if change_detection is None
                                else change_detection.reset_diagonal(self.structure.parameter_names))
        self._make = lambda: make_estimator(self.estimator_name, x0=self.x0, **estimator_settings)
        self.update_period, self.margin = float(update_period), float(margin)
        self.pipeline_settings = pipeline_settings
        self.can_source: Callable[[float], Trip | None] | None = None
        # the pipeline removes (I_red + I_W) dv/dt / r_W from F_xV before the estimator sees it, so the estimated
        # m_V is the body mass alone: the MPC's inertial mass needs the rotating parts added back
        self.rotational_mass = knowledge.drivetrain.rotational_mass()
        self._replay_now = float("inf")  # replay(): the recorded time up to which CAN windows reach [s]
        self.reset()

    def attach(self, can_source: Callable[[float], Trip | None]) -> None:
        """Where the CAN samples come from: can_source(t_from) -> Trip of samples with t >= t_from (or None)."""
        self.can_source = can_source

    def reset(self) -> None:
        self.estimator = self._make()
        self.detector = None if self.change_detection is None else CusumDetector(self.change_detection)
        self._t_done = -np.inf
        self._t_last_update = 0.0
        self.updates = 0
        self.rows = 0
        self.clipped = 0
        self.errors: list[str] = []
        self.history: list[tuple[float, list[float]]] = []  # (t [s], estimate) after every update

    def observe(self, sample: dict[str, float]) -> None:
        t = float(sample.get("t", np.nan))
        if not np.isfinite(t) or t - self._t_last_update < self.update_period:
            return
        self._t_last_update = t
        self.update()

    def update(self) -> int:
        """Feed the triggered rows since the last update; returns how many rows were used."""

        if self.can_source is None:
            raise ForceModelError("online force model: no CAN source attached (call attach())")
        t_from = self._t_done - self.margin if np.isfinite(self._t_done) else 0.0
        window = self.can_source(t_from)
        if window is None:
            return 0
        try:
            states = self.augment(run_pipeline(window, self.knowledge, self.pipeline_settings).states)
            t, A, B = model_data(states, self.structure)
        except PipelineError as exc:  # a too-short or unusable window: skip it, keep the estimate
            self.errors.append(str(exc))
            return 0
        new = t > self._t_done + 1e-9
        for a, b in zip(A[new], B[new]):
            if self.detector is not None and self.detector.update(float(b - a @ self.estimator.x)):
                assert self._reset_diagonal is not None  # set together with the detector from change_detection
                # a change of the road load: learn anew, the covariance raised on the residuals' own scale
                reset_covariance(self.estimator, self._reset_diagonal, self.detector.scale)
            self.estimator.update(a, b)
        if new.any():
            self._t_done = float(t[new].max())
        self.updates += 1
        self.rows += int(new.sum())
        self.history.append((self._t_done, [float(x) for x in self.estimate()]))
        return int(new.sum())

    def replay(self, trip: Trip, rate: float = 10.0) -> "OnlineForceModel":
        """Feed a recorded trip's measured channels as the closed loop would: CAN windows from the trip, and every
        1/rate seconds the latest sample to :meth:`observe` (a real log, or a simulated trip driven by anyone).
        Returns self; the estimate is in :meth:`parameters` / :meth:`estimate`."""
        if not (np.isfinite(rate) and rate > 0):
            raise ForceModelError(f"replay rate: a finite rate > 0 Hz, got {rate!r}")
        frame = trip.to_pandas()
        t = frame["t"].to_numpy(float)

        def window(t_from: float) -> Trip | None:
            sel = (t >= t_from) & (t <= self._replay_now)
            return None if sel.sum() < 10 else trip.slice(float(t[sel][0]), float(t[sel][-1]) + 1e-9)

        self.attach(window)
        self.reset()
        step = max(1, int(round(1.0 / (rate * np.median(np.diff(t))))))
        columns = [c for c in frame.columns]
        values = frame.to_numpy(float)
        for i in range(0, len(t), step):
            self._replay_now = float(t[i])
            self.observe(dict(zip(columns, values[i])))
        self._replay_now = float(t[-1])
        self.update()
        return self

    def augment(self, states):
        """The pipeline's states with any columns a subclass's structure needs besides them (here: as they are)."""
        return states

    def estimate(self) -> np.ndarray:
        """Current X̂ of the model structure (parameter order of ``structure.parameter_names``)."""
        return np.asarray(self.estimator.x, dtype=float).copy()

    def parameters(self) -> RoadLoadParameters:
        x = self.estimate()
        nominal = dict(zip(self.structure.parameter_names, self.x0))
        values: dict[str, float] = {"mass": float(self.knowledge.nominal.mass), "c0": 0.0}
        for name, value in zip(self.structure.parameter_names, x):
            if name in self.extra_parameters:
                continue
            ref = nominal[name]
            lo, hi = (0.5 * ref, 2.0 * ref) if name == "m_V" else (0.0, 4.0 * max(ref, 1e-9))
            if not np.isfinite(value) or not lo <= value <= hi:
                self.clipped += 1
                value = float(np.clip(value, lo, hi)) if np.isfinite(value) else ref
            field, factor = _MAPPING[name]
            values[field] = float(value) * factor
        return RoadLoadParameters(rotational_mass=self.rotational_mass, **values)

    def describe(self) -> dict[str, Any]:
        return {"force_model": self.name, "model": self.model_name, "estimator": self.estimator_name,
                "updates": self.updates, "rows": self.rows, "clipped": self.clipped,
                "change_alarms": 0 if self.detector is None else self.detector.alarms,
                "estimate": dict(zip(self.structure.parameter_names, map(float, self.estimate()))),
                "history": {"parameters": list(self.structure.parameter_names), "t": [h[0] for h in self.history],
                            "x": [h[1] for h in self.history]}}
