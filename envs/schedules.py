"""Time- or distance-scheduled effects (wind onset, parameter ramps), applied between substeps of the jitted core.

A schedule moves a quantity linearly from its start value to its final value:
    q(x) = q_0 + (q_1 - q_0) clip((x - onset) / ramp, 0, 1)     (ramp = 0: a step at x = onset),
with x the time t [s] or the distance s [m] driven (``onset_unit``). The simulator writes q into the parameter
vector before every 10-ms substep while a ramp is under way (and runs whole chunks while every schedule is
constant), so the truth channels (wind_speed, wind_angle, mass, drag_area, rolling_resistance_f0/f1/f4, ...) and
the tractive force follow the schedule exactly as if the core computed it. The core itself is unchanged.

Effects (``roadload.envs.effects.EFFECTS``): ``wind_ramp`` (mean wind speed and direction; with ``wind`` on, its
gusts and direction wander ride on top, its mean_speed and direction are replaced), ``mass_ramp`` (payload m_V
+ magnitude [kg]), ``drag_area_ramp`` (c_x A_V x (1 + magnitude)), ``rolling_resistance_ramp``
(f_r0, f_r1, f_r4 x (1 + magnitude)).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .effects import EffectsConfig
from .layout import (
    P_CW, P_FR0, P_FR1, P_FR4, P_MASS0, P_WIND_DIR, P_WIND_DIR_STD, P_WIND_GUST_STD, P_WIND_MEAN, P_WIND_ON, S_MASS,
    S_POS, S_T,
)

SCHEDULE_EFFECTS = ("wind_ramp", "mass_ramp", "drag_area_ramp", "rolling_resistance_ramp")


@dataclass(frozen=True)
class Ramp:
    """Linear ramp of one quantity from ``start`` to ``final`` over [onset, onset + ramp] in time or distance."""

    onset: float
    ramp: float
    by_distance: bool
    start: float
    final: float

    def fraction(self, t: float, s: float) -> float:
        x = s if self.by_distance else t
        if self.ramp <= 0.0:
            return 1.0 if x >= self.onset else 0.0
        return min(1.0, max(0.0, (x - self.onset) / self.ramp))

    def value(self, t: float, s: float) -> float:
        return self.start + (self.final - self.start) * self.fraction(t, s)

    def settled(self, t: float, s: float) -> bool:
        """True once the ramp has ended (t and s never decrease, so it stays constant from now on)."""
        return (s if self.by_distance else t) >= self.onset + max(self.ramp, 0.0)

    def started(self, t: float, s: float) -> bool:
        """True from (just before) the onset on: the simulator then applies the schedule every substep."""
        return (s if self.by_distance else t) >= self.onset - 1e-6


def _ramp(p: dict, start: float, final: float) -> Ramp:
    return Ramp(float(p["onset"]), float(p["ramp"]), p["onset_unit"] == "m", start, final)


class Schedules:
    """The scheduled effects of one simulator; ``apply`` writes their values at (t, s) into P (and the mass into
    X). ``base`` holds the unscheduled parameter values, restored by ``restore`` (on reset)."""

    def __init__(self, effects: EffectsConfig, P: np.ndarray) -> None:
        self.base = {i: float(P[i]) for i in (P_CW, P_FR0, P_FR1, P_FR4, P_MASS0, P_WIND_ON, P_WIND_MEAN,
                                                P_WIND_DIR, P_WIND_GUST_STD, P_WIND_DIR_STD)}
        self.wind_speed = self.wind_direction = self.mass = self.drag = self.rolling = None
        if effects.enabled("wind_ramp"):
            p = effects.params("wind_ramp")
            self.wind_speed = _ramp(p, float(p["start_speed"]), float(p["final_speed"]))
            self.wind_direction = _ramp(p, float(p["start_direction"]), float(p["final_direction"]))
        if effects.enabled("mass_ramp"):
            p = effects.params("mass_ramp")
            self.mass = _ramp(p, 0.0, float(p["magnitude"]))
        if effects.enabled("drag_area_ramp"):
            p = effects.params("drag_area_ramp")
            self.drag = _ramp(p, 0.0, float(p["magnitude"]))
        if effects.enabled("rolling_resistance_ramp"):
            p = effects.params("rolling_resistance_ramp")
            self.rolling = _ramp(p, 0.0, float(p["magnitude"]))
        self.wind_alone = self.wind_speed is not None and self.base[P_WIND_ON] < 0.5
        self.mass_applied = 0.0

    @property
    def ramps(self) -> list[Ramp]:
        return [r for r in (self.wind_speed, self.mass, self.drag, self.rolling) if r is not None]

    @property
    def active(self) -> bool:
        return bool(self.ramps)

    def restore(self, P: np.ndarray) -> None:
        if not self.active:  # nothing scheduled: P is left exactly as packed
            return
        for i, v in self.base.items():
            P[i] = v
        self.mass_applied = 0.0
        if self.wind_alone:  # the wind process without gusts or wander: exactly the scheduled wind
            P[P_WIND_ON], P[P_WIND_GUST_STD], P[P_WIND_DIR_STD] = 1.0, 0.0, 0.0

    def apply(self, X: np.ndarray, P: np.ndarray) -> None:
        t, s = float(X[S_T]), float(X[S_POS])
        if self.wind_speed is not None and self.wind_direction is not None:  # set together by 'wind_ramp'
            P[P_WIND_MEAN] = self.wind_speed.value(t, s)
            P[P_WIND_DIR] = self.wind_direction.value(t, s)
        if self.mass is not None:
            d = self.mass.value(t, s)
            X[S_MASS] += d - self.mass_applied
            P[P_MASS0] = self.base[P_MASS0] + d  # payload changes at stops stay relative to the ramped mass
            self.mass_applied = d
        if self.drag is not None:
            P[P_CW] = self.base[P_CW] * (1.0 + self.drag.value(t, s))
        if self.rolling is not None:
            k = 1.0 + self.rolling.value(t, s)
            P[P_FR0], P[P_FR1], P[P_FR4] = self.base[P_FR0] * k, self.base[P_FR1] * k, self.base[P_FR4] * k

    def limits(self, X: np.ndarray) -> tuple[float, float] | None:
        """(t_limit, s_limit) up to which every schedule stays constant from now (inf: for ever), or None while a
        ramp is under way (then the simulator applies the schedule before every substep)."""
        t, s = float(X[S_T]), float(X[S_POS])
        t_lim = s_lim = math.inf
        for r in self.ramps:
            if r.settled(t, s):
                continue
            if r.started(t, s):
                return None
            if r.by_distance:
                s_lim = min(s_lim, r.onset)
            else:
                t_lim = min(t_lim, r.onset)
        return t_lim, s_lim
