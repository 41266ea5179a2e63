"""Wind-aware tractive-force model structures: M3 / M4 (eq. 5.5, 5.6) with the wind vector as parameters.

The air approach speed of eq. 2.8 is u_x = v - v_w cos(psi_w - psi): a wind of speed v_w blowing towards psi_w
seen by a vehicle heading psi. Written with the wind vector in the road's frame, w = (w_x, w_y) =
v_w (cos psi_w, sin psi_w), the headwind is h = -(w_x cos psi + w_y sin psi) and the drag

    rho_a/2 c_x A_V (v + h)^2 = c_V v^2 + c_V w_x (-2 v cos psi) + c_V w_y (-2 v sin psi) + c_V h^2

is linear in (c_V, c_V w_x, c_V w_y): two regressors, -2 v cos psi and -2 v sin psi, added to M3 / M4 give the
structures ``M3w`` / ``M4w``, estimated by any catalogue estimator like the others. The wind follows as
w = (c_V w_x, c_V w_y) / c_V (:func:`wind_vector`). The square c_V h^2, and with a crosswind u_y the extra drag
c_V u_y^2 (1/2 + k) of the yaw-dependent c_x (k the yaw drag factor; eq. 2.7), change with the heading only by a
term c_V v_w^2 (1/2 - k) cos 2(psi_w - psi) / 2 (1.5 N for the i3 at 6 m/s): their mean,
c_V v_w^2 (3/2 + k) / 2, is a constant force that the rolling term m_V f_r0 g cos(theta) absorbs
(:func:`wind_constant_force`).

The regressors need the heading psi [rad] in the road's frame as the state column ``heading``; where it comes from
(the road geometry the vehicle follows, the integrated yaw rate, a GNSS course) is the caller's choice
(:mod:`roadload.controllers.wind`).
"""

from __future__ import annotations

from typing import Mapping

import numpy as np

from .models import M3, M4, SPEED, ModelError, ModelStructure, Term, get_model, model_names, register_model

HEADING = "heading"  # psi [rad], the vehicle's heading in the road's frame (0 = the road's initial heading)
WIND_X = "rho_a/2 A_V c_x w_x"
WIND_Y = "rho_a/2 A_V c_x w_y"


def _col(states: Mapping[str, np.ndarray], name: str) -> np.ndarray:
    return np.asarray(states[name], dtype=float)


WIND_ALONG = Term(
    regressor="-2 v cos(psi)", parameter=WIND_X, unit="kg/s",
    build=lambda s: -2.0 * _col(s, SPEED) * np.cos(_col(s, HEADING)), requires=(SPEED, HEADING),
    nominal=lambda n: 0.0, random_walk_variance=1e-6)
WIND_ACROSS = Term(
    regressor="-2 v sin(psi)", parameter=WIND_Y, unit="kg/s",
    build=lambda s: -2.0 * _col(s, SPEED) * np.sin(_col(s, HEADING)), requires=(SPEED, HEADING),
    nominal=lambda n: 0.0, random_walk_variance=1e-6)

M3W = M3.extend("M3w", WIND_ALONG, WIND_ACROSS, description="M3 with the wind vector (eq. 5.5, 2.8)")
M4W = M4.extend("M4w", WIND_ALONG, WIND_ACROSS, description="M4 with the wind vector (eq. 5.6, 2.8)")
for _m in (M3W, M4W):
    if _m.name not in model_names():
        register_model(_m)


def wind_structure(name: str) -> ModelStructure:
    """The registered wind-aware structure (``M3w`` / ``M4w``); ModelError for a structure without wind terms."""
    m = get_model(name)
    if WIND_X not in m.parameter_names or WIND_Y not in m.parameter_names:
        raise ModelError(f"model {m.name!r} has no wind parameters ({WIND_X!r}, {WIND_Y!r}); use M3w or M4w")
    return m


def wind_vector(structure: ModelStructure, x: np.ndarray) -> tuple[float, float]:
    """(w_x, w_y) [m/s] from an estimate X̂ of a wind-aware structure: (c_V w_x, c_V w_y) / c_V; (0, 0) while the
    drag estimate c_V is not positive."""
    names = structure.parameter_names
    c_v = float(x[names.index("rho_a/2 A_V c_x")])
    if not c_v > 0:
        return 0.0, 0.0
    return float(x[names.index(WIND_X)]) / c_v, float(x[names.index(WIND_Y)]) / c_v


def wind_constant_force(drag_coefficient: float, wind_speed: float, yaw_drag_factor: float) -> float:
    """c_V v_w^2 (3/2 + k) / 2 [N]: the heading-mean of the wind's square terms (module docstring), which a
    wind-aware structure's rolling term m_V f_r0 g absorbs. drag_coefficient c_V [kg/m], wind_speed [m/s]."""
    return 0.5 * drag_coefficient * wind_speed ** 2 * (1.5 + yaw_drag_factor)
