"""The safety envelope against its analytic form v_env(s) = min over caps ahead of sqrt(v_cap^2 + 2 b (s_cap - s))."""

import numpy as np
import pytest

from roadload.controllers.safety import SpeedEnvelope, braking_envelope
from roadload.road_profiles import RoadProfile


def test_braking_envelope_is_the_constant_deceleration_parabola():
    s = np.linspace(0.0, 200.0, 401)
    cap = np.where(s >= 150.0, 5.0, 30.0)
    b = 2.0
    v = braking_envelope(s, cap, b)
    expected = np.minimum(cap, np.sqrt(5.0 ** 2 + 2.0 * b * np.maximum(150.0 - s, 0.0)))
    np.testing.assert_allclose(v, expected, rtol=1e-12, atol=1e-12)
    # braking along the envelope at b exactly meets the cap: v dv/ds = -b between the knee and the cap
    knee = np.sqrt(30.0 ** 2 - 5.0 ** 2) ** 2 / (2 * b)  # metres before 150 m where the parabola meets 30 m/s
    ramp = (s > 150.0 - knee + 1.0) & (s < 149.0)
    decel = -np.gradient(0.5 * v ** 2, s)[ramp]
    np.testing.assert_allclose(decel, b, rtol=1e-3)


def test_speed_envelope_stops_at_an_unserved_stop_and_forgets_a_served_one():
    s = np.arange(0.0, 1001.0, 5.0)
    z = np.zeros_like(s)
    road = RoadProfile("flat", s, z, z, z, np.full_like(s, 25.0), stops=np.array([600.0]))
    env = SpeedEnvelope(road, lateral_accel_max=2.0, decel=2.5)
    assert float(env(600.0)) == pytest.approx(0.0, abs=1e-9)
    for d in (10.0, 50.0, 100.0):
        assert float(env(600.0 - d)) == pytest.approx(np.sqrt(2 * 2.5 * d), rel=1e-3)
    assert float(env(200.0)) == pytest.approx(25.0)
    env.serve(0)
    assert float(env(600.0)) == pytest.approx(25.0)
