"""Seeded road generators: reproducibility and the documented statistics."""

import numpy as np
import pytest

from roadload.road_profiles import RoadProfileError, city, hilly, load_profile, motorway

KMH = 1 / 3.6
FIELDS = ("distance", "grade", "curvature", "bank", "speed_limit", "stops")


def _segments(mask):
    """(start, end) index pairs of contiguous True runs."""
    edges = np.diff(np.concatenate([[0], mask.astype(int), [0]]))
    return list(zip(np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)))


@pytest.mark.parametrize("gen", [hilly, motorway, city])
def test_same_seed_identical_different_seed_differs(gen):
    a, b, c = gen(7, length=6000.0), gen(7, length=6000.0), gen(8, length=6000.0)
    for f in FIELDS:
        np.testing.assert_array_equal(getattr(a, f), getattr(b, f))
    assert a.meta == b.meta and a.meta["seed"] == 7
    assert not np.array_equal(a.grade, c.grade)
    assert not np.array_equal(a.curvature, c.curvature)


def test_load_profile_by_name_passes_seed_and_length():
    p = load_profile("city", seed=3, length=3000.0)
    q = city(3, length=3000.0)
    np.testing.assert_array_equal(p.curvature, q.curvature)
    assert p.length == pytest.approx(3000.0)


def test_hilly_grade_statistics_and_curve_limits():
    maxima, p99, runs = [], [], []
    for seed in range(5):
        p = hilly(seed)
        g = np.tan(p.grade)
        maxima.append(np.abs(g).max())
        p99.append(np.percentile(np.abs(g), 99))
        sign_change = np.flatnonzero(np.diff(np.sign(g)) != 0)
        runs.extend(np.diff(p.distance[sign_change]))
        # curve advisory: nowhere faster than sqrt(a_y / |kappa|) with a_y = 2 m/s^2, never above 100 km/h
        with np.errstate(divide="ignore"):
            v_curve = np.sqrt(2.0 / np.abs(p.curvature))
        assert np.all(p.speed_limit <= v_curve + 1e-9)
        assert p.speed_limit.max() == pytest.approx(100 * KMH)
        assert np.abs(p.curvature).max() <= 1 / 60 + 1e-9
        # superelevated towards the inside of each curve
        assert np.all(p.bank * p.curvature <= 0)
    assert max(maxima) <= 0.08
    assert min(p99) > 0.04  # peaks reach the hilly range, not a flat road
    # climbs/descents: Rice mean pi*l = 942 m for l = 300 m
    assert 600.0 < np.mean(runs) < 1300.0


def test_motorway_bounds_zones_and_bank():
    p = motorway(11, length=60_000.0)
    assert np.abs(np.tan(p.grade)).max() <= 0.04
    assert np.abs(p.curvature).max() <= 1 / 720 + 1e-12
    assert p.speed_limit.max() <= 130 * KMH + 1e-9
    assert set(np.round(p.speed_limit / KMH)) <= {100.0, 110.0, 120.0, 130.0}
    assert p.stops.size == 0
    arcs = _segments(np.abs(p.curvature) > 0)
    assert len(arcs) == p.meta["n_curves"] or len(arcs) == p.meta["n_curves"] - 1  # the last may run past the end
    for i, j in arcs[:-1]:
        kappa = p.curvature[i:j]
        turn = np.degrees(abs(np.trapezoid(kappa, p.distance[i:j])))
        assert 9.0 < turn < 61.0  # heading change 10-60 deg
        peak = np.argmax(np.abs(kappa))
        q = np.tan(abs(p.bank[i + peak]))
        assert 0.025 - 1e-9 <= q <= 0.06 + 1e-9
        assert np.sign(p.bank[i + peak]) == -np.sign(kappa[peak])


def test_city_stops_turns_and_zones():
    spacing, share_30 = [], []
    for seed in range(6):
        p = city(seed)
        assert np.abs(np.tan(p.grade)).max() <= 0.03
        assert p.speed_limit.max() <= 50 * KMH + 1e-9
        assert np.all(p.bank == 0)
        spacing.extend(np.diff(np.concatenate([[0.0], p.stops])))
        share_30.append(np.mean(np.isclose(p.speed_limit, 30 * KMH)))
        turns = [(i, j) for i, j in _segments(np.abs(p.curvature) > 1 / 40) if j < p.distance.size]
        assert len(turns) >= 1
        for i, j in turns:
            lo, hi = max(i - 3, 0), min(j + 3, p.distance.size)
            assert abs(np.trapezoid(p.curvature[lo:hi], p.distance[lo:hi])) == pytest.approx(np.pi / 2, rel=0.02)
            assert p.speed_limit[i:j].max() <= np.sqrt(2.5 * 25.0) + 1e-9  # turn speed for R <= 25 m
    assert 250.0 < np.mean(spacing) < 1000.0
    assert 0.1 < np.mean(share_30) < 0.6


@pytest.mark.parametrize("kw", [{"length": -5.0}, {"length": 20.0}, {"step": 0.0}])
def test_generator_rejects_bad_length(kw):
    with pytest.raises(RoadProfileError, match="length|step"):
        hilly(0, **kw)
