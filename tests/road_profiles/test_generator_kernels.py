"""The compiled building blocks of the road generators give scipy's / numpy's results bit for bit, so every
generated road (and every seeded experiment on it) is unchanged by them."""

import numpy as np
import pytest
from scipy.ndimage import gaussian_filter1d

from roadload.road_profiles import RoadProfileError, load_profile_start
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


def _cell_average_numpy(s, knot_s, knot_v):
    """The numpy form the compiled cell average replaced (reference)."""
    knot_s = np.concatenate([[min(knot_s[0], s[0]) - 1.0], knot_s, [max(knot_s[-1], s[-1]) + 1.0]])
    knot_v = np.concatenate([[knot_v[0]], knot_v, [knot_v[-1]]])
    area = np.concatenate([[0.0], np.cumsum(0.5 * (knot_v[1:] + knot_v[:-1]) * np.diff(knot_s))])

    def integral(x):
        k = np.clip(np.searchsorted(knot_s, x, side="right") - 1, 0, knot_s.size - 2)
        width = knot_s[k + 1] - knot_s[k]
        slope = np.divide(knot_v[k + 1] - knot_v[k], width, out=np.zeros_like(width), where=width > 0)
        dx = x - knot_s[k]
        return area[k] + knot_v[k] * dx + 0.5 * slope * dx ** 2

    h = s[1] - s[0]
    return (integral(s + h / 2) - integral(s - h / 2)) / h


def test_cell_average_equals_the_numpy_form_bitwise():
    rng = np.random.default_rng(5)
    for trial in range(30):
        s = g._grid(float(rng.uniform(100, 5000)), float(rng.choice([1.0, 2.0, 5.0])))
        knots = np.sort(rng.uniform(-50.0, s[-1] + 50.0, int(rng.integers(1, 60))))
        if trial % 3 == 0 and knots.size > 2:
            knots[1] = knots[0]  # a zero-width interval (a curve knot repeated)
        values = rng.normal(0.0, 0.01, knots.size)
        want = _cell_average_numpy(s, knots, values)
        assert np.array_equal(g._cell_average(s, knots, values), want), trial


@pytest.mark.parametrize("name", ["hilly", "motorway", "city"])
def test_keep_builds_the_first_part_of_the_same_road_bitwise(name):
    """keep= (the gym envs' episode setup) draws the whole road but builds only its start: every array equals the
    whole road's first points bit for bit, stops up to the end of the part, and the curve count of the whole road.
    A keep that skipped draws, or a curve past the part that moved a limit or curvature inside it, would differ."""
    gen = getattr(g, name)
    for seed in range(12):
        whole = gen(seed)
        for keep in (2000.0, 1234.5, 17.5, whole.length - 3.0):
            part = gen(seed, keep=keep)
            m = part.distance.size
            assert part.distance[-1] >= keep and (m == whole.distance.size or part.distance[-2] <= keep)
            assert m < whole.distance.size or keep > whole.length - 5.0
            for key in ("distance", "grade", "curvature", "bank", "speed_limit"):
                assert getattr(part, key).tobytes() == getattr(whole, key)[:m].tobytes(), (seed, keep, key)
            assert part.stops.tobytes() == whole.stops[whole.stops <= part.distance[-1]].tobytes()
            assert part.meta["n_curves"] == whole.meta["n_curves"]
    assert np.count_nonzero(gen(3, keep=3000.0).curvature) > 0 or name == "motorway"


@pytest.mark.parametrize("keep", [0.0, -5.0, float("nan")])
def test_keep_must_be_a_positive_length(keep):
    with pytest.raises(RoadProfileError, match=r"keep: expected a positive length \[m\]"):
        g.hilly(0, keep=keep)


def test_load_profile_start_builds_only_the_start_where_the_generator_can():
    part = load_profile_start("hilly", 2000.0, seed=5)
    assert part.distance[-1] == 2005.0 and part.meta["built_m"] == 2005.0
    assert load_profile_start("hilly", None, seed=5).length == 20_000.0
    # long_grades smooths the whole road at once (mode 'nearest' at its end): it is loaded whole
    whole = load_profile_start("long_grades", 2000.0, seed=1)
    assert whole.length == 12_000.0 and "built_m" not in whole.meta
