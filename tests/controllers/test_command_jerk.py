"""The command jerk limit |dF/dt| <= m j_max of the MPC and of cruise control: a disturbance that asks for a force
step is ramped at exactly m j_max per second, never faster, then reaches its target."""

import numpy as np
import pytest

from roadload.controllers.base import DriveContext, Observation
from roadload.controllers.cruise import CruiseController
from roadload.controllers.energy import generic_ev
from roadload.controllers.force_model import FixedForceModel
from roadload.controllers.mpc import MpcSettings
from roadload.controllers.mpc_controller import MpcController, MpcControllerSettings
from roadload.road_load import RoadLoadParameters
from roadload.road_profiles import RoadProfile

PARAMS = RoadLoadParameters.from_physical(1420.0, 0.009, 0.0, 0.0, 0.7, 1.2, 60000.0)


def flat_road():
    s = np.arange(0.0, 3001.0, 5.0)
    z = np.zeros_like(s)
    return RoadProfile("flat", s, z, z, z, np.full_like(s, 25.0))


@pytest.mark.parametrize("make", [lambda: MpcController(MpcControllerSettings(mpc=MpcSettings(time_weight=8000.0))),
                                  CruiseController], ids=["mpc", "cruise"])
def test_a_speed_drop_is_answered_by_a_ramp_at_the_jerk_limit(make):
    ctl = make()
    ctx = DriveContext(flat_road(), generic_ev(), FixedForceModel(PARAMS), dt=0.1)
    ctl.reset(ctx)
    m, j_max = PARAMS.inertial_mass, 2.0  # both controllers' default jerk_max [m/s^3]
    step = m * j_max * ctx.dt  # 286 N per 0.1 s
    v, s, forces = 20.0, 0.0, []
    for k in range(30):
        if k == 5:
            v -= 4.0  # a gust: 4 m/s slower than the plan / reference from one step to the next
        forces.append(ctl.wheel_force(Observation(t=k * ctx.dt, s=s, v=v, a=0.0)))
        s += v * ctx.dt
    dF = np.diff(forces)
    assert np.max(np.abs(dF)) <= step * (1 + 1e-9), (np.max(np.abs(dF)), step)
    # the disturbance asks for far more than one step: the command climbs at exactly the limit for a while ...
    at_limit = np.isclose(dF[4:], step, rtol=1e-9)
    assert at_limit[:3].all(), dF[4:10]
    # ... to a force well above the one before the drop (the comfort bound, not the jerk limit, ends the ramp)
    assert forces[-1] - forces[4] > 4 * step
