"""The one road-load owner: analytic terms, constructors agree with each other and with the simulator's truth."""

import casadi as ca
import numpy as np
import pytest

from roadload.envs import Simulator
from roadload.presets import get_preset
from roadload.road_load import (RoadLoadError, RoadLoadParameters, aerodynamic_drag_force, climbing_force,
                                cornering_resistance_force, road_load, rolling_resistance_force, tractive_force)
from roadload.units import G, STANDARD_AIR_DENSITY


def test_terms_match_chapter_2_by_hand():
    m, v, theta, kappa = 1500.0, 20.0, 0.03, 0.01
    assert rolling_resistance_force(m, v, theta, 0.01, 1e-4, 1e-9) == pytest.approx(
        m * G * np.cos(theta) * (0.01 + 1e-4 * v + 1e-9 * v ** 4))
    assert aerodynamic_drag_force(1.2, 0.6, v + 5.0) == pytest.approx(0.5 * 1.2 * 0.6 * 25.0 ** 2)
    assert climbing_force(m, theta) == pytest.approx(m * G * np.sin(theta))
    assert cornering_resistance_force(m, v, kappa, 8e4) == pytest.approx(m ** 2 * v ** 4 * kappa ** 2 / (4 * 8e4))
    p = RoadLoadParameters.from_physical(m, 0.01, 1e-4, 1e-9, 0.6, 1.2, 8e4, headwind=5.0, rotational_mass=40.0)
    total = (rolling_resistance_force(m, v, theta, 0.01, 1e-4, 1e-9) + aerodynamic_drag_force(1.2, 0.6, v + 5.0)
             + climbing_force(m, theta) + cornering_resistance_force(m, v, kappa, 8e4))
    assert road_load(v, theta, kappa, p) == pytest.approx(total, rel=1e-12)
    assert tractive_force(v, 0.5, theta, kappa, p) == pytest.approx(total + 1540.0 * 0.5, rel=1e-12)


def test_numpy_and_casadi_give_the_same_force():
    p = RoadLoadParameters.from_physical(1800.0, 0.012, 2e-4, 2e-9, 0.7, 1.18, 6e4, headwind=-2.0)
    v, th, k = ca.SX.sym("v"), ca.SX.sym("th"), ca.SX.sym("k")
    f = ca.Function("f", [v, th, k], [road_load(v, th, k, p.as_vector(), xp=ca)])
    for args in ((3.0, -0.05, 0.0), (30.0, 0.06, 0.002), (12.0, 0.0, 0.02)):
        assert float(f(*args)) == pytest.approx(road_load(*args, p), rel=1e-12)


def test_constructors_agree(hilly_road):
    spec = get_preset("bmw_i3")
    p = RoadLoadParameters.from_spec(spec)
    a, b, c = p.coast_down
    assert a == pytest.approx(spec.body.mass * G * spec.tires.rolling_resistance_f0)
    assert c == pytest.approx(0.5 * STANDARD_AIR_DENSITY * spec.aero.drag_area)
    assert p.drag_area() == pytest.approx(spec.aero.drag_area)
    assert p.rolling_resistance_f0() == pytest.approx(spec.tires.rolling_resistance_f0)
    q = RoadLoadParameters.from_coast_down(a, b, c, mass=spec.body.mass)
    v = np.linspace(1.0, 35.0, 8)
    # without f_r4 and cornering, the coast-down form reproduces the flat-road load
    assert np.allclose(road_load(v, 0.0, 0.0, q), road_load(v, 0.0, 0.0, p.with_(c4=0.0)), rtol=1e-12)
    # the simulator's truth at reset is the nominal spec
    sim = Simulator(spec, hilly_road)
    sim.reset()
    truth = RoadLoadParameters.from_truth(sim.true_parameters())
    assert truth.mass == pytest.approx(spec.body.mass)
    for name in ("c0", "c1", "c4", "k_corner"):
        assert getattr(truth, name) == pytest.approx(getattr(p, name), rel=1e-9)
    assert truth.c2 == pytest.approx(0.5 * sim.true_parameters()["air_density"] * spec.aero.drag_area)


def test_bad_parameters_are_refused_with_the_unit():
    with pytest.raises(RoadLoadError, match="mass must be > 0 kg"):
        RoadLoadParameters(mass=0.0, c0=1.0)
    with pytest.raises(RoadLoadError, match="c1 is not finite"):
        RoadLoadParameters(mass=1.0, c0=1.0, c1=float("inf"))
    with pytest.raises(RoadLoadError, match="rotational_mass must be >= 0 kg"):
        RoadLoadParameters(mass=1.0, c0=1.0, rotational_mass=-1.0)
