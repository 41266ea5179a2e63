"""Curvature from the yaw rate (roadload.io.derived.curvature_from_yaw_rate_track) against analytic tracks:
kappa = r / v for a steady turn, its sign the turn's, independent of the speed, and finite through a standstill."""

import numpy as np
import pytest

from roadload.io.derived import curvature_from_yaw_rate_track
from roadload.io.report import ImportReport

DT = 0.1


def steady_middle(t, first, last):
    return (t > first) & (t < last)


@pytest.mark.parametrize("kappa", [0.01, -0.004], ids=["left", "right"])
def test_constant_turn_gives_r_over_v_with_its_sign(kappa):
    """60 s straight, 60 s on a circle of radius 1/|kappa| at 12 m/s, 60 s straight: kappa = r / v in the turn
    (away from the 40 m smoothing window at its ends), 0 on the straights."""
    t = np.arange(0.0, 180.0, DT)
    v = np.full(t.size, 12.0)
    r = np.where((t >= 60.0) & (t < 120.0), kappa * 12.0, 0.0)
    report = ImportReport()
    out = curvature_from_yaw_rate_track(t, v, r, report, window=40.0)
    assert out.shape == t.shape and np.all(np.isfinite(out))
    turn = steady_middle(t, 70.0, 110.0)
    np.testing.assert_allclose(out[turn], kappa, rtol=0.02)
    straight = steady_middle(t, 10.0, 50.0) | steady_middle(t, 130.0, 170.0)
    assert np.max(np.abs(out[straight])) < 0.02 * abs(kappa)


def test_curvature_does_not_depend_on_the_speed_through_the_turn():
    """The same circle (kappa = 1/150 m) driven at a speed ramping 6 -> 20 m/s: r = kappa v changes, kappa not."""
    t = np.arange(0.0, 120.0, DT)
    v = np.interp(t, [0.0, 120.0], [6.0, 20.0])
    kappa = 1.0 / 150.0
    out = curvature_from_yaw_rate_track(t, v, kappa * v, ImportReport(), window=40.0)
    middle = steady_middle(t, 20.0, 100.0)
    np.testing.assert_allclose(out[middle], kappa, rtol=0.02)


def test_a_standstill_and_yaw_rate_dropouts_stay_finite():
    """Standing 20 s (v = 0, gyro noise), then a left turn; NaN yaw-rate samples count as no rotation."""
    rng = np.random.default_rng(0)
    t = np.arange(0.0, 100.0, DT)
    v = np.where(t < 20.0, 0.0, 10.0)
    kappa = 0.005
    r = np.where(t < 20.0, rng.normal(0.0, 0.01, t.size), kappa * 10.0)
    r[500:505] = np.nan
    out = curvature_from_yaw_rate_track(t, v, r, ImportReport(), window=40.0)
    assert np.all(np.isfinite(out))
    driving = steady_middle(t, 30.0, 45.0) | steady_middle(t, 55.0, 95.0)
    np.testing.assert_allclose(out[driving], kappa, rtol=0.03)
