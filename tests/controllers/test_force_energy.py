import casadi as ca
import numpy as np
import pytest

from roadload.road_load import RoadLoadError, RoadLoadParameters
from roadload.controllers.energy import EnergyModelError, SourceEnergyModel, fit_loss_polynomial, generic_ev
from roadload.controllers.force_model import ForceModelError, OracleForceModel, resistance_force, wheel_force
from roadload.units import G


def test_resistance_matches_the_physics_terms():
    p = RoadLoadParameters.from_physical(mass=1500.0, f_r0=0.01, f_r1=2e-4, f_r4=1e-9, drag_area=0.6,
                                      air_density=1.2, cornering_stiffness=80000.0, headwind=3.0)
    v, theta, kappa = 20.0, 0.03, 1 / 200.0
    rolling = 1500 * G * (0.01 + 2e-4 * v + 1e-9 * v ** 4) * np.cos(theta)
    aero = 0.5 * 1.2 * 0.6 * (v + 3.0) ** 2
    climb = 1500 * G * np.sin(theta)
    corner = 1500 ** 2 / 80000.0 * v ** 4 * kappa ** 2 / 4  # eq. 2.15 with r = 1/kappa
    expected = rolling + aero + climb + corner
    assert resistance_force(v, theta, kappa, p) == pytest.approx(expected, rel=1e-12)
    assert wheel_force(v, 0.5, theta, kappa, p) == pytest.approx(expected + 1500 * 0.5, rel=1e-12)


def test_symbolic_and_numeric_resistance_agree():
    p = RoadLoadParameters(mass=1400.0, c0=130.0, c1=2.0, c2=0.38, c4=1e-5, k_corner=30.0, headwind=-2.0)
    v = ca.SX.sym("v")
    f = ca.Function("f", [v], [resistance_force(v, 0.02, 0.004, p.as_vector())])
    for speed in (1.0, 13.0, 33.0):
        assert float(f(speed)) == pytest.approx(resistance_force(speed, 0.02, 0.004, p), rel=1e-12)


def test_force_parameters_reject_bad_values():
    with pytest.raises(RoadLoadError, match="mass must be > 0 kg"):
        RoadLoadParameters(mass=-1.0, c0=100.0)
    with pytest.raises(RoadLoadError, match="c2"):
        RoadLoadParameters(mass=1000.0, c0=100.0, c2=float("nan"))
    with pytest.raises(RoadLoadError, match="expected 8"):
        RoadLoadParameters.from_vector([1, 2, 3])
    p = RoadLoadParameters(mass=1000.0, c0=100.0, c2=0.3)
    assert RoadLoadParameters.from_vector(p.as_vector()) == p
    with pytest.raises(ForceModelError, match="RoadLoadParameters"):
        OracleForceModel(lambda: 3.0).parameters()


def test_loss_polynomial_fit_recovers_coefficients():
    rng = np.random.default_rng(0)
    w = rng.uniform(0, 1000, 400)
    t = rng.uniform(-250, 250, 400)
    truth = (250.0, 0.8, 1.5e-3, 0.05, 2e-7)
    loss = truth[0] + truth[1] * w + truth[2] * w ** 2 + truth[3] * t ** 2 + truth[4] * (t * w) ** 2
    loss[::50] = np.nan  # outside-map samples are dropped
    assert np.allclose(fit_loss_polynomial(w, t, loss), truth, rtol=1e-9)
    with pytest.raises(EnergyModelError, match="at least 5"):
        fit_loss_polynomial([1.0, 2.0], [1.0, 2.0], [1.0, np.nan])


def test_ev_source_power_is_mechanical_power_plus_losses():
    en = generic_ev()
    v, f = 20.0, 800.0
    ratio = en.gear_ratios[0]
    omega, torque = v * ratio / en.wheel_radius, f * en.wheel_radius / ratio
    p_drive = en.source_power(f, 0.0, v, ratio)
    assert p_drive == pytest.approx(f * v + en.loss_power(omega, torque) + en.auxiliary_power)
    # regeneration returns less than the mechanical power; the net force is what matters
    p_regen = en.source_power(0.0, f, v, ratio)
    assert -f * v < p_regen < 0
    assert en.source_power(f, f, v, ratio) == pytest.approx(en.source_power(0.0, 0.0, v, ratio))


def test_ice_shift_rule_and_validation():
    ice = SourceEnergyModel(kind="ice", wheel_radius=0.33, gear_ratios=(14.0, 9.0, 6.5, 5.0, 4.0, 3.3),
                            loss=(2000.0, 5.0, 0.01, 0.0, 0.0), max_power=200e3, max_torque=400.0,
                            indicated_efficiency=0.38, shift_speeds=(4.0, 8.0, 12.0, 17.0, 23.0))
    gears = ice.gear_for_speed(np.array([0.0, 5.0, 10.0, 20.0, 40.0]))
    assert list(gears) == [0, 1, 2, 4, 5]
    assert not ice.regenerates
    # fuel power: indicated efficiency divides the wheel work
    base = ice.source_power(0.0, 0.0, 20.0, 4.0)
    assert ice.source_power(1000.0, 0.0, 20.0, 4.0) - base == pytest.approx(1000.0 * 20.0 / 0.38, rel=1e-9)
    with pytest.raises(EnergyModelError, match="shift speeds"):
        SourceEnergyModel(kind="ice", wheel_radius=0.33, gear_ratios=(14.0, 9.0), loss=(0, 0, 0, 0, 0),
                          max_power=1e5, max_torque=300.0, shift_speeds=())
    with pytest.raises(EnergyModelError, match="kind"):
        SourceEnergyModel(kind="diesel", wheel_radius=0.33, gear_ratios=(1.0,), loss=(0, 0, 0, 0, 0),
                          max_power=1e5, max_torque=300.0)


def test_online_model_maps_estimates_and_selects_model_and_estimator():
    from roadload.controllers.online import OnlineForceModel
    from roadload.estimators.knowledge import knowledge_for_preset

    kn = knowledge_for_preset("bmw_i3")
    nom = kn.nominal
    m3 = OnlineForceModel(kn, model="M3", estimator="SGMKF")
    p = m3.parameters()  # before any data: the nominal X_0 mapped onto the resistance polynomial
    assert p.mass == pytest.approx(nom.mass)
    assert p.c0 == pytest.approx(G * nom.mass * nom.rolling_resistance_coefficient)
    assert p.c2 == pytest.approx(0.5 * nom.air_density * nom.drag_area)
    assert p.k_corner == 0.0 and m3.describe()["estimator"] == "SGMKF"
    m4 = OnlineForceModel(kn)  # default M4-RRLM
    assert m4.parameters().k_corner == pytest.approx(nom.mass ** 2 / nom.cornering_stiffness)
    with pytest.raises(ForceModelError, match="CAN source"):
        m4.update()
    # an implausible estimate (negative mass, NaN drag) is clipped / replaced, not passed to the NLP
    state = m4.estimator.state
    state.x = np.array([state.x[0], -5.0, np.nan, state.x[3]])
    m4.estimator.set_state(state)
    p = m4.parameters()
    assert p.mass == pytest.approx(0.5 * nom.mass) and p.c2 == pytest.approx(0.5 * nom.air_density * nom.drag_area)
    assert m4.clipped == 2
    with pytest.raises(Exception, match="M9"):
        OnlineForceModel(kn, model="M9")
