"""The estimator identity check compares bitwise: one changed bit, the sign of a zero, a changed dtype or a missing
array counts as a difference; NaN equals NaN (a skipped sample's residual)."""

import numpy as np

from roadload.experiments.benchmarks.estimator_identity import compare_dumps


def test_compare_dumps_counts_every_kind_of_difference(tmp_path):
    x = np.array([1.0, np.nan, 0.0, -2.5])
    old = dict(same=x, bit=x, zero=x, dtype=np.arange(3), gone=x)
    new = dict(same=x.copy(), bit=np.array([1.0, np.nan, 0.0, np.nextafter(-2.5, 0.0)]),
               zero=np.array([1.0, np.nan, -0.0, -2.5]), dtype=np.arange(3, dtype=np.int32), extra=x)
    np.savez(tmp_path / "old.npz", **old)
    np.savez(tmp_path / "new.npz", **new)
    result = compare_dumps(tmp_path / "old.npz", tmp_path / "new.npz")
    assert (result.arrays, result.values) == (5, 19)
    assert result.differ == ["bit", "dtype", "extra (only in the new dump)", "gone (only in the old dump)", "zero"]
