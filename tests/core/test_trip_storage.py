"""The chapter-5 pipeline and an estimator give the same result on a trip stored 'exact' (float64) and 'compact'
(float32 on the sensor grid / truth to 15 significant bits), read column-selectively with load_for_pipeline."""

import numpy as np
import pytest

from roadload import Trip
from roadload.envs.simulator import simulate
from roadload.estimators.evaluation import estimate
from roadload.estimators.knowledge import knowledge_for_preset
from roadload.estimators.models import get_model
from roadload.estimators.pipeline import PIPELINE_CHANNELS, load_for_pipeline, model_data, run_pipeline
from roadload.road_profiles import load_profile


@pytest.mark.slow  # ~40 s idle, ~110 s on the shared machine
def test_pipeline_and_estimator_agree_across_storage_precisions(tmp_path):
    road = load_profile("hilly", seed=3, length=8000.0)
    trip = simulate("bmw_i3", road, effects=["wind", "sensor_outliers"], seed=5, duration=240.0)
    exact = trip.save(tmp_path / "exact.parquet")
    compact = simulate("bmw_i3", road, effects=["wind", "sensor_outliers"], seed=5, duration=240.0,
                       out=tmp_path / "compact.parquet", precision="compact", chunk_seconds=50.0)
    assert compact.stat().st_size < exact.stat().st_size / 2.5
    knowledge = knowledge_for_preset("bmw_i3")
    m4 = get_model("M4")
    results = {}
    for name, path in (("exact", exact), ("compact", compact)):
        loaded = load_for_pipeline(path)
        assert loaded.truth is None and set(loaded.channels) <= set(PIPELINE_CHANNELS)
        states = run_pipeline(loaded, knowledge).states
        t, A, B = model_data(states, m4)
        est = estimate(t, A, B, m4, "RRLM", m4.nominal_parameters(knowledge.nominal))
        results[name] = (states, est.X)
    (s_exact, x_exact), (s_compact, x_compact) = results["exact"], results["compact"]
    # measured channels are stored losslessly: the pipeline states and the estimate are identical
    assert s_exact.equals(s_compact)
    np.testing.assert_array_equal(x_exact, x_compact)
    assert np.all(np.isfinite(x_exact[-1]))
    # the truth comes back as float64 within its storage rounding (15 significant bits: relative 2^-15)
    truth_c = Trip.load(compact, channels=[], truth_channels=["mass", "tractive_force"]).truth
    np.testing.assert_allclose(truth_c["tractive_force"], trip.truth["tractive_force"], rtol=2.0 ** -15, atol=1e-3)
    assert truth_c["mass"].dtype == np.float64
