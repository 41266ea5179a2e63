"""The real long-haul grade windows of the truck comparison: distinct, non-overlapping,
graded, and no silent repeats past the last window. Needs the shared data (skips without it)."""

import numpy as np
import pytest

from roadload.experiments.controller_comparison import (LONGHAUL_MIN_GRADE_RANGE, longhaul_windows,
                                                        paired_road)


def test_longhaul_windows_are_distinct_graded_and_bounded(shared_data, monkeypatch):
    monkeypatch.setenv("ROADLOAD_DATA", str(shared_data))
    starts = longhaul_windows()
    assert len(starts) >= 6  # at least 6 seeds per payload for the headline table
    assert np.all(np.diff(starts) >= 10_000.0)  # non-overlapping 10 km windows
    roads = [paired_road("longhaul_real", seed) for seed in range(len(starts))]
    for seed, road in enumerate(roads):
        assert road.meta["window_start_m"] == starts[seed]
        assert 9_900.0 < road.length <= 10_000.0
        assert np.ptp(np.tan(road.grade)) > LONGHAUL_MIN_GRADE_RANGE
        assert np.all(road.speed_limit == 25.0) and road.stops.size == 0
    with pytest.raises(ValueError, match=f"seeds 0..{len(starts) - 1}"):
        paired_road("longhaul_real", len(starts))
