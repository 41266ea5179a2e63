"""The ``online_wind`` force model: the online estimator with the wind vector as two more parameters.

:class:`WindAwareForceModel` is :class:`~.online.OnlineForceModel` on a wind-aware structure (``M4w`` by default,
:mod:`roadload.estimators.wind`): the regressors -2 v cos psi and -2 v sin psi need the vehicle's heading psi per
state sample, which comes from one of

- ``"road"`` (default): the road geometry the vehicle follows, psi(s) = integral of the road's curvature, at the
  distance s from an odometer that integrates the CAN vehicle speed (the road is the one the MPC previews);
- ``"yaw_rate"``: the integral of the CAN yaw rate (its bias drifts the heading: a 0.002 rad/s bias turns it by
  0.4 rad in 200 s);
- ``"gnss"``: a GNSS course channel (``heading``, course over ground, clockwise from north), where the CAN set
  has one: psi = course_0 - course.

The same interface as the other force models: ``parameters()`` gives the lumped road load at the current heading
(its headwind component; the rolling term less the heading-mean of the wind's square terms, which the structure's
rolling term absorbs), and ``wind()`` the estimated wind vector, from which the MPC takes the headwind and
crosswind of every segment ahead.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from roadload.road_load import RoadLoadParameters
from roadload.road_profiles import RoadProfile

from .force_model import ForceModelError, WindEstimate, road_heading
from .online import OnlineForceModel
from roadload.estimators.wind import HEADING, WIND_X, WIND_Y, wind_constant_force, wind_structure, wind_vector

HEADING_SOURCES = ("road", "yaw_rate", "gnss")


def wind_model_name(model: str) -> str:
    """The wind-aware structure of a model name: 'M4' -> 'M4w' (a name that has the wind terms stays)."""
    return model if model.endswith("w") else f"{model}w"


class WindAwareForceModel(OnlineForceModel):
    """Online force model with the wind vector (module docstring). ``road``: the route (heading source 'road');
    ``yaw_drag_factor`` k [1] of the vehicle's c_x(psi_a) (spec sheet)."""

    name = "online_wind"
    extra_parameters = (WIND_X, WIND_Y)

    def __init__(self, knowledge, road: RoadProfile | None = None, model: str = "M4w", estimator: str = "RRLM",
                 heading_source: str = "road", yaw_drag_factor: float = 0.0, **kwargs: Any) -> None:
        if heading_source not in HEADING_SOURCES:
            raise ForceModelError(f"heading_source: choose one of {HEADING_SOURCES}, got {heading_source!r}")
        if heading_source == "road" and road is None:
            raise ForceModelError("heading_source 'road' needs the road the vehicle follows")
        if not (np.isfinite(yaw_drag_factor) and yaw_drag_factor >= 0):
            raise ForceModelError(f"yaw_drag_factor: a finite number >= 0, got {yaw_drag_factor!r}")
        wind_structure(model)  # a structure with the wind parameters, or ModelError
        self.road, self.heading_source, self.yaw_drag_factor = road, heading_source, float(yaw_drag_factor)
        super().__init__(knowledge, model=model, estimator=estimator, **kwargs)

    def reset(self) -> None:
        super().reset()
        self._track_t: list[float] = []
        self._track_psi: list[float] = []
        self._odometer = 0.0
        self._yaw = 0.0
        self._course0: float | None = None
        self._last: tuple[float, float, float] | None = None  # (t, speed, yaw rate) of the previous sample

    # ------------------------------------------------------------------ heading
    def observe(self, sample: dict[str, float]) -> None:
        t = float(sample.get("t", np.nan))
        if np.isfinite(t):
            psi = self._heading_step(t, sample)
            if psi is not None and np.isfinite(psi):
                self._track_t.append(t)
                self._track_psi.append(psi)
        super().observe(sample)

    def _heading_step(self, t: float, sample: dict[str, float]) -> float | None:
        v = float(sample.get("vehicle_speed", np.nan))
        r = float(sample.get("yaw_rate", np.nan))
        if self._last is not None and t > self._last[0]:
            dt = t - self._last[0]
            if np.isfinite(v) and np.isfinite(self._last[1]):
                self._odometer += 0.5 * (v + self._last[1]) * dt
            if np.isfinite(r) and np.isfinite(self._last[2]):
                self._yaw += 0.5 * (r + self._last[2]) * dt
        self._last = (t, v, r)
        if self.heading_source == "road":
            return float(road_heading(self.road, self._odometer))
        if self.heading_source == "yaw_rate":
            return self._yaw
        course = float(sample.get("heading", np.nan))
        if not np.isfinite(course):
            return None
        if self._course0 is None:
            self._course0 = course
        return self._course0 - course

    def heading_at(self, t) -> np.ndarray:
        """The heading psi [rad] at times t [s] (linear between the observed samples, unwrapped)."""
        if not self._track_t:
            return np.full(np.shape(t), np.nan)
        return np.interp(t, self._track_t, np.unwrap(self._track_psi))

    def augment(self, states):
        states = states.copy()
        states[HEADING] = self.heading_at(states["t"].to_numpy(float))
        return states

    # ------------------------------------------------------------------ the force model's outputs
    def wind(self) -> WindEstimate:
        """The estimated wind vector in the road's frame (from the estimate's c_V w_x, c_V w_y and c_V)."""
        wx, wy = wind_vector(self.structure, self.estimate())
        return WindEstimate.from_vector(wx, wy, self.yaw_drag_factor)

    def parameters(self) -> RoadLoadParameters:
        p = super().parameters()
        w = self.wind()
        psi = float(self._track_psi[-1]) if self._track_psi else 0.0
        headwind = float(w.components(psi)[0])
        c0 = p.c0 - wind_constant_force(p.c2, w.speed, self.yaw_drag_factor)
        return p.with_(c0=max(c0, 0.0), headwind=headwind)

    def describe(self) -> dict[str, Any]:
        out = super().describe()
        w = self.wind()
        out.update(heading_source=self.heading_source, wind_speed=w.speed, wind_direction=w.direction)
        return out
