"""Eq. 5.2 with and without the body-pitch correction: the accelerometer reads dv/dt + g sin(theta +
k dv/dt), so the uncorrected gradient angle carries k dv/dt."""

import numpy as np
import pytest

from roadload.controllers.drive import DriveSettings, drive
from roadload.estimators.knowledge import knowledge_for_preset
from roadload.estimators.pipeline import PipelineError, PipelineSettings, run_pipeline
from roadload.road_profiles import hilly


def test_pitch_correction_removes_the_acceleration_correlated_grade_error():
    _, plant = drive("bmw_i3", hilly(seed=3, length=3000.0), seed=3, settings=DriveSettings(controller="human"))
    trip = plant.sim.to_trip()
    knowledge = knowledge_for_preset("bmw_i3")
    assert knowledge.pitch_gradient == pytest.approx(0.005)
    truth_t = trip.truth["t"].to_numpy(float)
    truth_grade = trip.truth["grade"].to_numpy(float)
    slopes = {}
    for corrected in (False, True):
        st = run_pipeline(trip, knowledge, PipelineSettings(pitch_correction=corrected)).states
        ok = st["speed"].to_numpy(float) > 3.0
        t = st["t"].to_numpy(float)[ok]
        err = st["gradient_angle"].to_numpy(float)[ok] - np.interp(t, truth_t, truth_grade)
        acc = st["acceleration"].to_numpy(float)[ok]
        slopes[corrected] = np.polyfit(acc, err, 1)[0]  # grade error per m/s^2 of acceleration
    assert slopes[False] == pytest.approx(0.005, abs=0.0015)  # eq. 5.2 sees the pitch k dv/dt
    assert abs(slopes[True]) < 0.0015


def test_pipeline_settings_reject_unknown_gradient_source():
    with pytest.raises(PipelineError, match="gradient"):
        PipelineSettings(gradient="gps")
