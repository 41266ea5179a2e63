"""The traffic benchmark's old/new comparison: runs paired in order, ratios per run, medians per thread count."""

import pytest

from roadload.experiments.benchmarks.traffic import compare_rounds


def _run(rates: dict[int, tuple[float, float]], load: float) -> dict:
    return {"rows": [{"threads": t, "steps_per_cpu_s": cpu, "steps_per_s": wall, "load_1min": load}
                     for t, (cpu, wall) in rates.items()], "ratios": []}


def test_compare_pairs_the_runs_in_order_and_takes_medians():
    old = [_run({1: (100.0, 50.0), 2: (90.0, 80.0)}, 1.0), _run({1: (200.0, 40.0), 2: (95.0, 70.0)}, 3.0),
           _run({1: (110.0, 60.0), 2: (85.0, 90.0)}, 2.0)]
    new = [_run({1: (120.0, 55.0), 2: (99.0, 96.0)}, 1.0), _run({1: (220.0, 52.0), 2: (95.0, 70.0)}, 3.0),
           _run({1: (154.0, 60.0), 2: (102.0, 99.0)}, 2.0)]
    table = compare_rounds(old, new).set_index("threads")
    one = table.loc[1]
    # per-run ratios 1.2, 1.1, 1.4 (a load swing between runs cancels in each pair): median 1.2, not 220/200
    assert one.new_over_old_cpu == pytest.approx(1.2)
    assert one.range_cpu == "1.100-1.400"
    assert one.old_per_cpu_s == 110.0 and one.new_per_cpu_s == 154.0
    assert one.new_over_old_wall == pytest.approx(1.1)  # 1.1, 1.3, 1.0
    two = table.loc[2]
    assert two.new_over_old_cpu == pytest.approx(1.1)  # 1.1, 1.0, 1.2
    assert two.load_1min == 2.0
