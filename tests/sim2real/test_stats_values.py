"""The diagnosis statistics value by value against hand computations: block ids, robust summaries, McGill
notches, the block bootstrap (median, p-value, mean difference) and the CR1 cluster-robust covariance."""

import numpy as np
import pytest

from roadload.sim2real.errors import DiagnosisError
from roadload.sim2real.stats import (block_bootstrap_mean_difference, block_bootstrap_median, block_ids,
                                     cluster_covariance, notch_interval)
from roadload.sim2real.records import RobustSummary


def test_blocks_start_at_each_trips_own_first_time():
    # trip b starts at t = 100 s: its blocks count from there, not from 0 s or from trip a's start
    ids = block_ids(np.array([1, 1, 1, 2, 2, 2]), np.array([0.0, 9.9, 10.0, 100.0, 109.0, 121.0]), 10.0)
    assert ids.tolist() == [0, 0, 1, 2, 2, 3]
    # many blocks in the first trip, one in the second: keys must not collide across trips
    t = np.concatenate([np.arange(0.0, 50.0, 1.0), [0.0]])
    ids = block_ids(np.array([0] * 50 + [1]), t, 10.0)
    assert ids.tolist() == [i // 10 for i in range(50)] + [5]
    assert ids.dtype == np.int64


def test_block_id_errors_name_the_problem():
    with pytest.raises(DiagnosisError, match=r"trip index and time differ in shape: \(2,\) vs \(3,\)"):
        block_ids(np.zeros(2), np.zeros(3), 10.0)
    for bad in (0.0, -1.0, float("nan")):
        with pytest.raises(DiagnosisError, match="block length must be > 0 s"):
            block_ids(np.zeros(3), np.arange(3.0), bad)


def test_robust_summary_by_hand():
    r = np.array([1.0, -2.0, 3.0, np.nan, 10.0, np.inf])
    s = RobustSummary.of(r)
    x = np.array([1.0, -2.0, 3.0, 10.0])
    assert s.n == 4 and s.mean == pytest.approx(3.0) and s.median == pytest.approx(2.0)
    assert s.mad == pytest.approx(1.482602218505602 * 2.5, rel=1e-3)  # |x - 2| = 1, 4, 1, 8 -> median 2.5
    assert s.medse == pytest.approx(np.median(x ** 2)) and s.rmse == pytest.approx(np.sqrt(np.mean(x ** 2)))
    empty = RobustSummary.of(np.array([np.nan]))
    assert empty.n == 0 and all(np.isnan(getattr(empty, k)) for k in ("mean", "median", "mad", "medse", "rmse"))


def test_notch_is_median_plus_minus_1_57_iqr_over_root_m():
    x = np.arange(1.0, 101.0)  # median 50.5, IQR 49.5
    med, lo, hi = notch_interval(np.append(x, np.nan))
    assert med == pytest.approx(50.5)
    assert hi - med == pytest.approx(1.57 * 49.5 / 10.0) and med - lo == pytest.approx(1.57 * 49.5 / 10.0)
    med, lo, hi = notch_interval(x, n_effective=4)  # 4 independent blocks: twice the half width of 100 -> /2
    assert hi - med == pytest.approx(1.57 * 49.5 / 2.0)
    assert notch_interval(x, n_effective=0)[2] - 50.5 == pytest.approx(1.57 * 49.5)  # m clamped to 1
    assert all(np.isnan(v) for v in notch_interval(np.array([np.nan])))


def test_bootstrap_median_edge_cases():
    rng = np.random.default_rng(0)
    assert block_bootstrap_median(np.array([np.nan]), np.array([0]), rng)[3] == 1.0
    assert np.isnan(block_bootstrap_median(np.array([np.nan]), np.array([0]), rng)[0])
    med, lo, hi, p = block_bootstrap_median(np.array([1.0, 2.0, 4.0]), np.array([7, 7, 7]), rng)
    assert (med, lo, hi, p) == (2.0, -np.inf, np.inf, 1.0)  # one block: no evidence


def test_bootstrap_median_of_two_blocks_enumerated():
    """Blocks {-1, -1} and {10, 10}: a resample draws (a,a), (a,b), (b,a) or (b,b); the weighted median (the first
    sorted sample reaching half the weight) is -1, -1, -1 or 10. So P(median <= 0) = 3/4, P(median >= 0) = 1/4 and
    the two-sided p-value is 2 min(3/4, 1/4) = 1/2."""
    x, b = np.array([-1.0, -1.0, 10.0, 10.0]), np.array([0, 0, 1, 1])
    med, lo, hi, p = block_bootstrap_median(x, b, np.random.default_rng(5), n_boot=4000, level=0.9)
    assert med == 4.5  # the sample median itself
    assert lo == -1.0 and hi == 10.0
    assert p == pytest.approx(0.5, abs=0.04)
    shifted = block_bootstrap_median(x + 2.0, b, np.random.default_rng(5), n_boot=4000)
    assert shifted[3] == pytest.approx(1.0 / 4000)  # every median > 0: p is floored at 1 / n_boot, not 0
    flipped = block_bootstrap_median(-x - 2.0, b, np.random.default_rng(5), n_boot=4000)
    assert flipped[3] == pytest.approx(1.0 / 4000)
    zero = block_bootstrap_median(np.zeros(4), b, np.random.default_rng(5), n_boot=100)
    assert zero[3] == 1.0  # every median is 0: both tails are 1, p capped at 1


def test_bootstrap_median_interval_widens_with_the_level():
    blocks = np.repeat(np.arange(40), 5)
    x = np.repeat(np.random.default_rng(3).normal(0.0, 1.0, 40), 5)
    wide = block_bootstrap_median(x, blocks, np.random.default_rng(9), n_boot=500, level=0.99)
    narrow = block_bootstrap_median(x, blocks, np.random.default_rng(9), n_boot=500, level=0.5)
    assert wide[1] < narrow[1] < narrow[2] < wide[2]
    assert 0.2 < narrow[3] <= 1.0  # centred data: no evidence against median = 0


def test_bootstrap_mean_difference_weights_every_sample():
    # block 0 has 3 samples of difference 1, block 1 one sample of difference 5: the mean is per sample, 8/4
    a, b, blocks = np.array([1.0, 1.0, 1.0, 5.0, np.nan]), np.zeros(5), np.array([0, 0, 0, 1, 1])
    mean, lo, hi = block_bootstrap_mean_difference(a, b, blocks, np.random.default_rng(0), n_boot=2000)
    assert mean == pytest.approx(2.0)
    assert lo == pytest.approx(1.0) and hi == pytest.approx(5.0)  # all-block-0 and all-block-1 resamples
    one = block_bootstrap_mean_difference(a[:3], b[:3], blocks[:3], np.random.default_rng(0))
    assert one == (pytest.approx(1.0), -np.inf, np.inf)
    assert all(np.isnan(v) for v in block_bootstrap_mean_difference(np.array([np.nan]), np.zeros(1), np.zeros(1),
                                                                       np.random.default_rng(0)))
    narrow = block_bootstrap_mean_difference(a, b, blocks, np.random.default_rng(0), n_boot=2000, level=0.1)
    assert lo < narrow[1] <= narrow[2] < hi


def test_cluster_covariance_is_the_cr1_sandwich():
    rng = np.random.default_rng(4)
    n, blocks = 12, np.repeat(np.arange(4), 3)
    A = np.column_stack([np.ones(n), rng.normal(size=n)])
    r, w = rng.normal(size=n), rng.uniform(0.5, 2.0, n)
    bread = np.linalg.inv(A.T @ (w[:, None] * A))
    meat = sum(np.outer(A[blocks == g].T @ (w * r)[blocks == g], A[blocks == g].T @ (w * r)[blocks == g])
               for g in range(4))
    cr1 = (4 / 3) * (11 / 10)
    np.testing.assert_allclose(cluster_covariance(A, r, blocks, w), cr1 * bread @ meat @ bread, rtol=1e-10)
    unweighted = np.linalg.inv(A.T @ A)
    meat1 = sum(np.outer(A[blocks == g].T @ r[blocks == g], A[blocks == g].T @ r[blocks == g]) for g in range(4))
    np.testing.assert_allclose(cluster_covariance(A, r, blocks), cr1 * unweighted @ meat1 @ unweighted, rtol=1e-10)
