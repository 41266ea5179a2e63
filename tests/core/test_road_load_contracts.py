"""The road-load constructors and views, value by value: defaults that add nothing, the wind's sign convention,
the rotational mass of the engaged gear, the vector form the MPC uses, and the errors of bad parameters."""

import math

import numpy as np
import pytest

from roadload.presets import get_preset
from roadload.road_load import (RoadLoadError, RoadLoadParameters, road_load, rolling_resistance_coefficient,
                                rolling_resistance_force, tractive_force)
from roadload.units import G, STANDARD_AIR_DENSITY

TRUTH = {"mass": 1500.0, "rolling_resistance_f0": 0.01, "rolling_resistance_f1": 2e-4, "rolling_resistance_f4": 3e-9,
         "drag_area": 0.6, "air_density": 1.1, "cornering_stiffness": 5e4}


def test_omitted_speed_terms_add_nothing():
    assert rolling_resistance_coefficient(20.0, 0.01) == 0.01
    assert rolling_resistance_coefficient(20.0, 0.01, 1e-4) == pytest.approx(0.01 + 2e-3, rel=1e-15)
    assert rolling_resistance_coefficient(10.0, 0.0, 0.0, 1e-8) == pytest.approx(1e-4, rel=1e-15)
    assert rolling_resistance_force(1000.0, 20.0, 0.0, 0.01) == pytest.approx(1000.0 * G * 0.01, rel=1e-15)
    p = RoadLoadParameters(mass=1000.0, c0=100.0)
    assert (p.c1, p.c2, p.c4, p.k_corner, p.headwind, p.rotational_mass) == (0.0,) * 6
    assert road_load(25.0, 0.0, 0.01, p) == 100.0  # only a_V: no speed, drag, cornering or climbing term


@pytest.mark.parametrize("angle,headwind", [(0.0, -5.0), (math.pi, 5.0), (math.pi / 2, 0.0)])
def test_wind_from_truth_is_a_headwind_component(angle, headwind):
    """psi_w = 0 is a tailwind (the wind blows along the direction of travel), psi_w = pi a headwind."""
    p = RoadLoadParameters.from_truth({**TRUTH, "wind_speed": 5.0, "wind_angle": angle})
    assert p.headwind == pytest.approx(headwind, abs=1e-12)
    # the drag term sees the air approach speed v + w
    still = RoadLoadParameters.from_truth(TRUTH)
    assert road_load(20.0, 0.0, 0.0, p) - road_load(20.0, 0.0, 0.0, still) == pytest.approx(
        p.c2 * ((20.0 + headwind) ** 2 - 400.0), rel=1e-12, abs=1e-9)


def test_truth_values_map_one_to_one():
    p = RoadLoadParameters.from_truth(TRUTH)
    assert p.mass == 1500.0 and p.headwind == 0.0 and p.rotational_mass == 0.0
    assert p.c0 == pytest.approx(1500.0 * G * 0.01) and p.c1 == pytest.approx(1500.0 * G * 2e-4)
    assert p.c4 == pytest.approx(1500.0 * G * 3e-9) and p.c2 == pytest.approx(0.5 * 1.1 * 0.6)
    assert p.k_corner == pytest.approx(1500.0 ** 2 / 5e4)
    assert RoadLoadParameters.from_truth({**TRUTH, "cornering_stiffness": 0.0}).k_corner == 0.0
    no_corner = {k: v for k, v in TRUTH.items() if k != "cornering_stiffness"}
    assert RoadLoadParameters.from_truth(no_corner).k_corner == 0.0


def test_rotational_mass_of_the_engaged_gear_from_truth():
    geared = RoadLoadParameters.from_truth({**TRUTH, "effective_mass": 1580.0})
    assert geared.rotational_mass == pytest.approx(80.0) and geared.mass == 1500.0
    assert geared.inertial_mass == pytest.approx(1580.0)
    # an effective mass below m_V (a rounding of the simulator) is no negative rotational mass
    assert RoadLoadParameters.from_truth({**TRUTH, "effective_mass": 1499.0}).rotational_mass == 0.0


def test_physical_and_coast_down_constructors_keep_every_argument():
    p = RoadLoadParameters.from_physical(1200.0, 0.01, drag_area=0.5)
    assert p.c2 == pytest.approx(0.5 * STANDARD_AIR_DENSITY * 0.5) and p.k_corner == 0.0
    assert p.c1 == 0.0 and p.c4 == 0.0 and p.headwind == 0.0 and p.rotational_mass == 0.0
    assert RoadLoadParameters.from_physical(1200.0, 0.01, cornering_stiffness=None).k_corner == 0.0
    assert RoadLoadParameters.from_physical(1200.0, 0.01, cornering_stiffness=6e4).k_corner == pytest.approx(24.0)
    q = RoadLoadParameters.from_coast_down(150.0, 2.0, 0.4, mass=1300.0, rotational_mass=30.0)
    assert (q.mass, q.c0, q.c1, q.c2, q.c4, q.rotational_mass) == (1300.0, 150.0, 2.0, 0.4, 0.0, 30.0)
    assert q.inertial_mass == 1330.0 and q.coast_down == (150.0, 2.0, 0.4)
    assert q.drag_area(1.0) == pytest.approx(0.8) and q.drag_area() == pytest.approx(0.8 / STANDARD_AIR_DENSITY)
    assert q.rolling_resistance_f0() == pytest.approx(150.0 / (1300.0 * G))


def test_spec_constructor_with_a_payload_and_a_rotational_mass():
    spec = get_preset("bmw_i3")
    base = RoadLoadParameters.from_spec(spec)
    loaded = RoadLoadParameters.from_spec(spec, mass=spec.body.mass + 300.0, air_density=1.0, rotational_mass=50.0)
    assert loaded.mass == spec.body.mass + 300.0 and loaded.rotational_mass == 50.0
    assert loaded.c0 / base.c0 == pytest.approx(loaded.mass / base.mass)
    assert loaded.c2 == pytest.approx(0.5 * 1.0 * spec.aero.drag_area)
    assert base.c1 == pytest.approx(spec.body.mass * G * spec.tires.rolling_resistance_f1)
    assert base.c4 == pytest.approx(spec.body.mass * G * spec.tires.rolling_resistance_f4)
    assert base.k_corner == pytest.approx(spec.body.mass ** 2 / spec.equivalent_cornering_stiffness())


def test_vector_form_round_trips_and_drives_the_same_force():
    p = RoadLoadParameters(mass=1400.0, c0=140.0, c1=2.0, c2=0.35, c4=1e-5, k_corner=30.0, headwind=3.0,
                           rotational_mass=45.0)
    x = p.as_vector()
    assert x.tolist() == [1400.0, 140.0, 2.0, 0.35, 1e-5, 30.0, 3.0, 45.0]
    assert RoadLoadParameters.from_vector(x) == p and RoadLoadParameters.from_vector(x.reshape(2, 4)) == p
    assert p.to_dict() == dict(zip(RoadLoadParameters.FIELDS, x.tolist()))
    assert p.with_(c0=1.0).c0 == 1.0 and p.with_(c0=1.0).c1 == 2.0 and p.c0 == 140.0
    args = (np.array([5.0, 20.0]), np.array([0.02, -0.01]), np.array([0.0, 0.01]))
    np.testing.assert_allclose(road_load(*args, x), road_load(*args, p), rtol=1e-15)
    # the acceleration term uses m_V + m_rot in both forms
    np.testing.assert_allclose(tractive_force(args[0], 0.7, args[1], args[2], x),
                               road_load(*args, p) + 1445.0 * 0.7, rtol=1e-15)
    np.testing.assert_allclose(tractive_force(args[0], 0.7, args[1], args[2], p),
                               road_load(*args, p) + 1445.0 * 0.7, rtol=1e-15)
    with pytest.raises(RoadLoadError, match=r"expected 8 road-load parameters .*got 7"):
        RoadLoadParameters.from_vector(x[:7])


@pytest.mark.parametrize("name", RoadLoadParameters.FIELDS)
def test_every_non_finite_parameter_is_named(name):
    values = {"mass": 1.0, "c0": 1.0, name: float("nan")}
    with pytest.raises(RoadLoadError, match=rf"road-load parameter {name} is not finite \(nan\)"):
        RoadLoadParameters(**values)


def test_boundaries_of_mass_and_rotational_mass():
    with pytest.raises(RoadLoadError, match=r"mass must be > 0 kg, got -1.0 kg"):
        RoadLoadParameters(mass=-1.0, c0=1.0)
    assert RoadLoadParameters(mass=1e-3, c0=0.0, rotational_mass=0.0).mass == 1e-3


def test_parameter_vector_is_float_whatever_the_inputs():
    """The MPC's parameter vector is float64 even when the parameters were given as integers."""
    x = RoadLoadParameters(mass=1000, c0=100, c1=0, c2=0, c4=0, k_corner=0, headwind=0, rotational_mass=0).as_vector()
    assert x.dtype == np.float64 and x.tolist() == [1000.0, 100.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0]


@pytest.mark.parametrize("stiffness,k_corner", [(0.5, 1500.0 ** 2 / 0.5), (-5.0, 0.0)])
def test_any_positive_truth_stiffness_counts_and_a_negative_one_means_none(stiffness, k_corner):
    p = RoadLoadParameters.from_truth({**TRUTH, "cornering_stiffness": stiffness})
    assert p.k_corner == pytest.approx(k_corner)


def test_defaults_of_the_constructors_add_nothing():
    assert RoadLoadParameters.from_coast_down(150.0, 2.0, 0.4, mass=1300.0).rotational_mass == 0.0
    assert RoadLoadParameters.from_spec(get_preset("bmw_i3")).rotational_mass == 0.0
    bare = RoadLoadParameters.from_physical(1200.0, 0.01)
    assert (bare.c1, bare.c2, bare.c4, bare.k_corner, bare.headwind, bare.rotational_mass) == (0.0,) * 6
    # a wind speed without an angle is a tailwind (psi_w = 0)
    assert RoadLoadParameters.from_truth({**TRUTH, "wind_speed": 5.0}).headwind == pytest.approx(-5.0)
