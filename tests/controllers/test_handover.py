"""closed_loop.Handover and DriveSettings.warmup_driver: cruise control drives every paired
run's warm-up, so the MPCs start the measured segment in the same state whatever their force model. Before, each
MPC drove its own warm-up: on a 40 t truck the online MPC entered a descent 2.4 m/s faster than the oracle, and the
net-energy metric charged that kinetic energy at fuel cost (+4.5 MJ) although both then braked on the descent."""

import numpy as np
import pytest

from roadload.controllers.base import ControllerError
from roadload.controllers.closed_loop import Handover
from roadload.controllers.cruise import CruiseController
from roadload.controllers.drive import DriveSettings, drive
from roadload.road_profiles import hilly


@pytest.fixture(scope="module")
def road():
    whole = hilly(1, keep=1600.0)
    keep = whole.distance <= 1600.0
    from roadload.road_profiles import RoadProfile
    return RoadProfile("hilly1[:1600m]", whole.distance[keep], whole.grade[keep], whole.curvature[keep],
                       whole.bank[keep], whole.speed_limit[keep], stops=np.zeros(0))


def _run(road, force_model, warmup_driver):
    st = DriveSettings(controller="mpc", force_model=force_model, time_weight=8000.0, measure_from=700.0,
                       warmup_driver=warmup_driver)
    res, _ = drive("bmw_i3", road, seed=3, settings=st)
    return res


def test_cruise_warmup_gives_every_force_model_the_same_segment_start(road):
    runs = {fm: _run(road, fm, "cruise") for fm in ("oracle", "abc", "online")}
    starts = [r.metrics["segment_start_speed"] for r in runs.values()]
    assert max(starts) - min(starts) < 1e-9  # the same cruise-control warm-up, bit for bit
    t700 = [float(np.interp(700.0, r.log["s"], r.log["t"])) for r in runs.values()]
    assert max(t700) - min(t700) < 1e-9
    # the MPC drives the segment: the runs differ after the switch, and the MPC's stats are reported
    assert len({round(r.metrics["segment_time"], 6) for r in runs.values()}) > 1
    assert runs["oracle"].metrics["ctl_solves"] > 0
    # the online estimator learnt from the cruise-control warm-up (updates before the switch at t700)
    history = runs["online"].metrics["online"]["history"]
    assert sum(0 < t < t700[0] for t in history["t"]) >= 2
    own = {fm: _run(road, fm, "mpc") for fm in ("oracle", "abc")}
    assert abs(own["oracle"].metrics["segment_start_speed"] - own["abc"].metrics["segment_start_speed"]) > 1e-6


def test_handover_and_warmup_driver_refuse_bad_settings():
    with pytest.raises(ValueError, match="switch"):
        Handover(CruiseController(), CruiseController(), float("nan"))
    with pytest.raises(ControllerError, match="warmup_driver"):
        DriveSettings(warmup_driver="human")
