"""The named inline stages of the simulator's compiled substep against their equations, called directly (an
``inline="always"`` numba function is also an ordinary compiled function). The estimator kernel's stages are
tested in tests/estimators/test_kernel_stages.py."""

from __future__ import annotations

import math
from pathlib import Path

import pytest
from roadload.units import G
from roadload.envs import physics as ph


def test_aero_drag_is_eq_2_7_with_the_approach_velocity_of_eq_2_8():
    rho, cxa, v, k = 1.2, 0.62, 30.0, 0.4
    assert ph.aero_drag(rho, cxa, v, 0.0, 0.0, k) == pytest.approx(0.5 * rho * cxa * v * v, rel=1e-14)
    # 5 m/s wind from 90° (pure crosswind): u_x = v, u_y = -5, v_a = |u|, factor 1 + k sin² psi_a
    u_x, u_y = v - 5.0 * math.cos(math.pi / 2), -5.0
    v_a = math.hypot(u_x, u_y)
    expect = 0.5 * rho * cxa * u_x * v_a * (1.0 + k * u_y * u_y / (v_a * v_a))
    assert ph.aero_drag(rho, cxa, v, 5.0, math.pi / 2, k) == pytest.approx(expect, rel=1e-14)
    # tailwind faster than the car pushes: negative drag
    assert ph.aero_drag(rho, cxa, 3.0, 10.0, 0.0, k) < 0.0


def test_rolling_resistance_and_climbing_force_are_eq_2_9_2_10_and_2_5():
    fr, f_roll = ph.rolling_resistance(0.009, 1e-4, 1e-9, 20.0, 1500.0, math.cos(0.02), 0.03)
    assert fr == pytest.approx(0.009 + 1e-4 * 20.0 + 1e-9 * 20.0 ** 4, rel=1e-14)
    assert f_roll == pytest.approx(fr * 1500.0 * G * math.cos(0.02) * math.cos(0.03) * math.tanh(200.0))
    assert ph.rolling_resistance(0.009, 0.0, 0.0, 0.0, 1500.0, 1.0, 0.0)[1] == 0.0  # smoothed to 0 at standstill
    assert ph.climbing_force(1500.0, math.sin(0.05)) == pytest.approx(1500.0 * 9.80665 * math.sin(0.05))


def test_integrate_speed_holds_the_vehicle_and_books_the_hold_force():
    # braking 50 kN at 0.1 m/s would reverse the car within dt: it stops (a = -v/dt), the rest is hold force
    v_new, a, f_hold, v_avg = ph.integrate_speed(0.1, 0.0, 50000.0, 100.0, 1500.0, 0.01)
    assert v_new == 0.0 and a == pytest.approx(-10.0) and v_avg == pytest.approx(0.05)
    assert f_hold == pytest.approx(0.0 - 50000.0 - 100.0 + 1500.0 * 10.0)  # F_W - F_B - F_nb - M a
    v_new, a, f_hold, _ = ph.integrate_speed(20.0, 3000.0, 0.0, 500.0, 1500.0, 0.01)  # M a = F_W - F_B - F_nb
    assert a == pytest.approx(2500.0 / 1500.0) and v_new == pytest.approx(20.0 + 0.01 * a)
    assert f_hold == pytest.approx(0.0, abs=1e-6)  # only round-off: nothing held while moving


def test_envs_has_no_star_imports():
    envs = Path(ph.__file__).parent
    assert not [p.name for p in envs.glob("*.py") if "import *" in p.read_text()]
