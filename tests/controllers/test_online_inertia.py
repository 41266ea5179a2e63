"""The online force model's inertial mass: the pipeline takes the rotating parts out of F_xV, so the estimate's
m_V is the body mass and the MPC must add (I_red + I_W)/r_W^2 back."""

import pytest

from roadload.controllers.online import OnlineForceModel
from roadload.controllers.vehicle_models import abc_parameters
from roadload.envs import get_preset
from roadload.estimators.knowledge import knowledge_for_preset


@pytest.mark.parametrize("preset, gear", [("bmw_i3", 1), ("gt_rwd", 4)])
def test_online_inertial_mass_includes_the_rotating_parts(preset, gear):
    spec = get_preset(preset)
    online = OnlineForceModel(knowledge_for_preset(preset))
    p = online.parameters()  # at the nominal start estimate: m_V = the nominal body mass
    assert p.mass == pytest.approx(spec.body.mass, rel=1e-9)
    rotating = spec.effective_mass(gear) - spec.body.mass
    assert rotating > 30.0  # the i3: ~60 kg, i.e. 4 % of its mass
    assert p.rotational_mass == pytest.approx(rotating, rel=0.02)
    assert p.inertial_mass == pytest.approx(abc_parameters(preset).inertial_mass, rel=2e-3)
