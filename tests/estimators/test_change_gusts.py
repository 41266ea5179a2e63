"""The CUSUM test on block means (roadload.estimators.change.GUST_ROBUST) on simulated drives with gusts: the
per-sample test takes the gusts' correlated residuals for changes, the block test does not, and it still fires
after a payload step.

The drives are the drift condition's wind (3 m/s, 1.5 m/s gusts of 5 s) on 4 km generated hilly roads with the
bends taken out, so the mean wind keeps one angle to the car and the gusts are what changes (on a winding road
M4, which has no wind terms, also sees the headwind change with the heading). Seeds 200-202: GUST_ROBUST was chosen
on seeds 100-104 (winding roads); these are held out.
"""

import numpy as np
import pytest

from roadload.envs import simulate
from roadload.estimators import chapter5_settings, make_estimator
from roadload.estimators.change import GUST_ROBUST, ChangeDetection, CusumDetector, reset_covariance
from roadload.estimators.knowledge import knowledge_for_preset
from roadload.estimators.models import get_model
from roadload.estimators.pipeline import model_data, run_pipeline
from roadload.road_profiles import RoadProfile, hilly

SEEDS = (200, 201, 202)
WIND = "wind:mean_speed=3,gust_std=1.5"  # the drift condition's wind (experiments.controller_comparison)
STEP_AT = 100.0  # [s] a 300 kg payload step (four passengers)
STEP = f"mass_ramp:magnitude=300,onset={STEP_AT:g},ramp=0"


def triggered_rows(seed: int, effects: list[str]):
    """(t, A, B) of M4 from the chapter-5 pipeline on a cruise drive of the straightened hilly road."""
    r = hilly(seed=seed, length=4000.0)
    road = RoadProfile("straight", r.distance, r.grade, np.zeros_like(r.distance), r.bank, r.speed_limit)
    trip = simulate("bmw_i3", road, effects=effects, seed=seed)
    return model_data(run_pipeline(trip, knowledge_for_preset("bmw_i3")).states, get_model("M4"))


@pytest.fixture(scope="module")
def drives():
    return {seed: (triggered_rows(seed, [WIND]), triggered_rows(seed, [WIND, STEP])) for seed in SEEDS}


def alarm_times(rows, detection: ChangeDetection) -> list[float]:
    """Times [s] of the alarms of RRLM (section 5.5 settings, from the nominal parameters) with the detector and
    its covariance reset, as the online force model runs them."""
    t, A, B = rows
    model = get_model("M4")
    est = make_estimator("RRLM", x0=model.nominal_parameters(knowledge_for_preset("bmw_i3").nominal),
                         **chapter5_settings("M4")["RRLM"])
    det = CusumDetector(detection)
    diagonal = detection.reset_diagonal(model.parameter_names)
    times = []
    for ti, a, b in zip(t, A, B):
        if det.update(float(b - a @ est.x)):
            reset_covariance(est, diagonal, det.scale)
            times.append(float(ti))
        est.update(a, b)
    return times


def test_gusts_set_off_the_per_sample_test_but_not_the_block_test(drives):
    """Measured: the per-sample test 26-28 alarms per 4 km, the block test 0, 1, 1."""
    per_sample = [len(alarm_times(gust, ChangeDetection())) for gust, _ in drives.values()]
    blocks = [len(alarm_times(gust, GUST_ROBUST)) for gust, _ in drives.values()]
    assert min(per_sample) >= 15, per_sample
    assert max(blocks) <= 1 and sum(blocks) <= 2, blocks


def test_the_block_test_fires_after_a_payload_step(drives):
    """Measured: 25 s and 17 s after the step on seeds 200 and 202; on 201 only the alarm the gust-only drive has
    too (79 s, before the step)."""
    detected = [any(STEP_AT < t <= STEP_AT + 30.0 for t in alarm_times(step, GUST_ROBUST))
                for _, step in drives.values()]
    assert sum(detected) >= 2, detected
