"""The simulator core's speed-ups change no bit: each shortcut equals the full expression it skips, a call of n
substeps equals n calls of one, the preview search from a cached segment equals a binary search, regen is still
allocated only for braking, and kernels outside the core recompile when a source they inline changes.
(scripts/check_core_identity.py compares whole trajectories against an older commit.)"""

from __future__ import annotations

import math

import numpy as np
import pytest
from numba import njit
from roadload.envs import Simulator
from roadload.envs import batch
from roadload.envs import physics as ph
from roadload.envs import numerics
from roadload.envs.numerics import SMALL_ANGLE, road_value_at, road_value_near
from roadload.units import G


@njit
def _libm(x):
    return math.tanh(x), math.cos(x), math.sin(x)


def test_skipped_libm_calls_are_exact_in_double_precision():
    # rolling resistance skips tanh(v / 0.1) for v >= 2.5 m/s and cos(bank) for bank == 0; the lateral model and
    # the aero drag skip sin/cos of 0: each skip is only valid if the compiled libm call returns exactly that
    for x in np.concatenate([np.linspace(25.0, 30.0, 501), [1e3, 1e6, 1e300]]):
        assert _libm(x)[0] == 1.0
    assert _libm(0.0)[1:] == (1.0, 0.0)


@pytest.mark.parametrize("name", ["sin", "cos", "tan", "asin", "atan"])
def test_small_angle_branches_equal_libm_bit_for_bit(name):
    """sin_small & co. skip libm below SMALL_ANGLE (the single-track model on a straight road; the steering law and
    the bicycle step of the quarter of the traffic that keeps a ~1e-16 heading after a lane change): the value they
    return there must be libm's to the last bit, down to subnormals and signed zeros, and above the threshold they
    are libm's call."""
    rng = np.random.default_rng(11)
    below = np.exp(rng.uniform(math.log(5e-324), math.log(SMALL_ANGLE), 4000))
    above = SMALL_ANGLE * np.exp(rng.uniform(0.0, math.log(1.0 / SMALL_ANGLE), 1000))
    edges = [0.0, 5e-324, SMALL_ANGLE, np.nextafter(SMALL_ANGLE, 0.0), 2.0 ** -27, 0.3]
    fast = getattr(numerics, f"{name}_small")
    exact = getattr(math, name)
    n_below = 0
    for x in np.concatenate([below, above, edges]):
        for signed in (float(x), -float(x)):
            got, want = fast(signed), exact(signed)
            assert np.float64(got).tobytes() == np.float64(want).tobytes(), (name, signed, got, want)
            n_below += abs(signed) < SMALL_ANGLE
    assert n_below >= 8000  # the branch itself was exercised


@pytest.mark.parametrize("bank", [0.0, 0.03])
def test_rolling_resistance_shortcut_equals_the_full_expression(bank):
    fr0, fr1, fr4, mass, cth = 0.009, 1e-4, 1e-9, 1500.0, math.cos(0.02)
    for v in np.concatenate([np.linspace(0.0, 3.0, 301), np.linspace(3.0, 60.0, 58)]):
        fr = fr0 + fr1 * v + fr4 * v * v * v * v
        full = fr * mass * G * cth * math.cos(bank) * math.tanh(v / 0.1)
        assert ph.rolling_resistance(fr0, fr1, fr4, v, mass, cth, bank) == (fr, full)


def test_aero_drag_in_still_air_equals_the_wind_formula():
    rho, cxa, k = 1.2, 0.62, 0.4
    for v in (0.0, 0.3, 13.7, 41.0):
        for angle in (0.0, 1.0, -2.5, math.pi):
            u_x, u_y = v - 0.0 * math.cos(angle), -0.0 * math.sin(angle)
            v_a = math.sqrt(u_x * u_x + u_y * u_y)
            sin2 = (u_y * u_y) / (v_a * v_a) if v_a > 1e-9 else 0.0
            assert ph.aero_drag(rho, cxa, v, 0.0, angle, k) == 0.5 * rho * cxa * u_x * v_a * (1.0 + k * sin2)


def test_road_value_near_equals_a_binary_search_from_any_start_segment():
    rng = np.random.default_rng(4)
    s_axis = np.concatenate([[0.0], np.cumsum(rng.uniform(0.5, 9.0, 300))])  # uneven grid, as a real road
    road = np.vstack([s_axis, rng.normal(size=s_axis.size)])
    for s in np.concatenate([rng.uniform(-20.0, s_axis[-1] + 20.0, 400), s_axis[:50], [s_axis[-1]]]):
        i = int(np.clip(np.searchsorted(s_axis, s, side="right") - 1, 0, s_axis.size - 2))
        w = min(max((s - s_axis[i]) / (s_axis[i + 1] - s_axis[i]), 0.0), 1.0)
        expect = road[1, 0] if s <= s_axis[0] else (road[1, -1] if s >= s_axis[-1] else
                                                     road[1, i] * (1.0 - w) + road[1, i + 1] * w)
        for hint in (-1, 0, max(i - 3, 0), i, min(i + 1, s_axis.size - 2), s_axis.size - 2, s_axis.size + 5):
            assert road_value_near(road, 1, s, hint) == expect
        assert road_value_at(road, 1, s) == expect


def test_one_call_of_n_substeps_equals_n_calls_of_one(hilly_road):
    # the P-only factors (brake lag, gust factors, sin of the toe-in) are computed once per call: a call of 10
    # substeps must equal 10 calls of one, bit for bit, with every effect (wind gusts, pad drift, ...) on
    one, many = (Simulator("truck_40t", hilly_road, effects="all", seed=5) for _ in range(2))
    for k in range(40):
        force = 9000.0 * math.sin(0.3 * k) - 2000.0
        many.step(force, n_substeps=10)
        for _ in range(10):
            one.step(force, n_substeps=1)
    assert one.vehicle_state.log_rows == many.vehicle_state.log_rows == 400
    assert one.vehicle_state == many.vehicle_state
    assert np.array_equal(one.truth_log(), many.truth_log(), equal_nan=True)


def test_regen_is_allocated_for_braking_only(straight_road):
    # the regen capacity is only computed for a braking request: traction draws from the battery without any
    # brake force, a small braking request is all regen (current < 0, no friction), a large one adds friction
    sim = Simulator("bmw_i3", straight_road(), initial_speed=20.0, seed=1)
    rows = {}
    for name, force in (("traction", 800.0), ("regen", -800.0), ("friction", -12000.0)):
        sim.step(force, n_substeps=10)
        rows[name] = sim.to_trip().truth.iloc[-1]
    assert rows["traction"]["battery_current"] > 0.0 and rows["traction"]["brake_force"] == 0.0
    assert rows["regen"]["battery_current"] < 0.0 and rows["regen"]["brake_force"] == pytest.approx(0.0, abs=1.0)
    assert rows["friction"]["brake_force"] > 3000.0


def test_dependent_kernel_cache_follows_every_source(tmp_path):
    module, callee = tmp_path / "kernels.py", tmp_path / "helpers.py"
    module.write_text("x = 1\n")
    callee.write_text("y = 1\n")
    first = batch.dependent_jit(module, callee).cache_dir
    assert batch.dependent_jit(module, callee).cache_dir == first  # unchanged sources: the same cache
    callee.write_text("y = 2\n")  # an edit of a module whose jitted code the kernels inline
    second = batch.dependent_jit(module, callee).cache_dir
    assert second != first and not (tmp_path / "__pycache__" / first.rsplit("/", 1)[-1]).exists()
    assert second.startswith(str(tmp_path / "__pycache__" / "numba-kernels-"))
    # an edit of the simulator core (another hash of its sources)
    assert batch.dependent_jit(module, callee, core_stamp="0" * 12).cache_dir != second
