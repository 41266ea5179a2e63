"""The compiled building blocks of the road generators give scipy's / numpy's results bit for bit, so every
generated road (and every seeded experiment on it) is unchanged by them."""

import numpy as np
import pytest
from scipy.ndimage import gaussian_filter1d

from roadload.road_profiles import generate as g


@pytest.mark.parametrize("sigma", [300 / np.sqrt(2) / 5, 600 / np.sqrt(2) / 5, 250 / np.sqrt(2) / 5, 3.3, 10.5,
                                   0.7])
def test_gaussian_interior_equals_scipy_bitwise(sigma):
    pad = int(4 * sigma) + 1
    for seed, n in ((0, 4001), (1, 1234), (2, 11), (3, 10_001)):
        x = np.random.default_rng(seed).standard_normal(n + 2 * pad)
        want = gaussian_filter1d(x, sigma, mode="wrap")[pad:pad + n]
        got = g._gaussian_interior(x, float(sigma), pad, n)
        assert np.array_equal(got, want), f"sigma {sigma}, n {n}: max diff {np.abs(got - want).max()}"


def test_gaussian_interior_refuses_a_too_small_pad():
    with pytest.raises(ValueError, match="pad"):
        g._gaussian_interior(np.zeros(100), 10.0, 20, 50)


def test_restrict_lowers_exactly_the_closed_interval():
    s = g._grid(2000.0, 5.0)
    layout = g._Layout(s, np.full_like(s, 30.0))
    rng = np.random.default_rng(0)
    want = np.full_like(s, 30.0)
    for start, end, limit in [(-50.0, 12.5, 20.0), (100.0, 100.0, 10.0), (995.0, 1500.0, 25.0),
                              (1990.0, 2500.0, 5.0), *zip(rng.uniform(-100, 2100, 20), rng.uniform(-100, 2100, 20),
                                                          rng.uniform(1, 40, 20))]:
        layout.restrict(start, end, limit)
        mask = (s >= start) & (s <= end)
        want[mask] = np.minimum(want[mask], limit)
        assert np.array_equal(layout.limit, want), (start, end, limit)


def test_generated_road_statistics_unchanged():
    """A regression anchor independent of the platform's last bits: the grade process of a seeded hilly road has
    the class's standard deviation (4 %, before the soft cap) within sampling error, zero mean."""
    grades = np.concatenate([np.tan(g.hilly(seed).grade) for seed in range(10)])
    assert abs(grades.mean()) < 0.01
    assert 0.025 < grades.std() < 0.05
