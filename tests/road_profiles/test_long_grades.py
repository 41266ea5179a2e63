"""The heavy-truck road generator: long 3-6 % grades."""

import numpy as np

from roadload.road_profiles import load_profile, long_grades


def test_long_grades_has_several_km_of_3_to_6_percent():
    for seed in range(4):
        p = long_grades(seed, length=12_000.0)
        pct = 100 * np.tan(p.grade)
        assert 3.0 <= np.max(np.abs(pct)) <= 6.05
        steep = np.abs(pct) >= 2.9
        # the longest steep stretch is at least 1.5 km (climbs/descents of 2-4 km, smoothed ends)
        runs, best = 0, 0
        for flag in steep:
            runs = runs + 1 if flag else 0
            best = max(best, runs)
        assert best * (p.distance[1] - p.distance[0]) >= 1500.0
        assert np.all(p.speed_limit == p.speed_limit[0]) and abs(p.speed_limit[0] * 3.6 - 90.0) < 1e-9
    a, b = long_grades(1), load_profile("long_grades", seed=1)
    assert np.array_equal(a.grade, b.grade)
    assert not np.array_equal(long_grades(1).grade, long_grades(2).grade)
