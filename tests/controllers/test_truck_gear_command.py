"""The MPC's gear command: an ICE plant shifts by its own load-dependent strategy, while the
MPC's fuel model plans with a speed-only shift rule. On a climb the plant downshifted where the plan assumed the
higher gear, so a 0.1 m/s difference in cruise speed between two force models changed the fuel of the whole climb
by ~4 % (truck 15 t, long grades seed 6). ``gear_command`` makes the plant drive the planned gear."""

import numpy as np
import pytest

from roadload.controllers.drive import DriveSettings, drive
from roadload.controllers.mpc_controller import MpcControllerSettings
from roadload.controllers.sim_plant import SimulatorPlant
from roadload.controllers.vehicle_models import energy_model_from_spec
from roadload.experiments.controller_comparison import TRUCK_MPC
from roadload.presets import get_preset, truck_spec
from roadload.controllers.base import ControllerError
from roadload.road_profiles import RoadProfile


@pytest.fixture(scope="module")
def truck_energy():
    return energy_model_from_spec(truck_spec(15_000.0))


def test_gear_with_hysteresis_holds_the_gear_within_the_band(truck_energy):
    en = truck_energy
    top = len(en.gear_ratios) - 1  # 0-based top gear
    vs = en.shift_speeds[top - 1]  # the last upshift speed [m/s]
    assert en.gear_with_hysteresis(vs + 0.1, None, 0.5) == top  # no previous gear: the rule's own
    assert en.gear_with_hysteresis(vs - 0.1, None, 0.5) == top - 1
    assert en.gear_with_hysteresis(vs - 0.4, top, 0.5) == top  # held in the band below the shift speed
    assert en.gear_with_hysteresis(vs - 0.6, top, 0.5) == top - 1  # out of the band: the rule's gear
    assert en.gear_with_hysteresis(vs + 0.4, top - 1, 0.5) == top - 1
    assert en.gear_with_hysteresis(vs + 0.6, top - 1, 0.5) == top
    assert en.gear_with_hysteresis(vs + 0.6, 0, 0.5) == top  # a far-off previous gear is pulled into the band
    ev = energy_model_from_spec(get_preset("bmw_i3"))
    assert ev.gear_with_hysteresis(20.0, None, 0.5) == 0


def _climb() -> RoadProfile:
    s = np.arange(0.0, 2500.0, 5.0)
    grade = np.arctan(np.clip((s - 600.0) / 200.0, 0.0, 1.0) * 0.04)  # flat, then a 4 % climb
    return RoadProfile("climb", s, grade, np.zeros_like(s), np.zeros_like(s), np.full_like(s, 24.5))


@pytest.mark.parametrize("gear_command", [False, True])
def test_gear_command_makes_the_plant_drive_the_planned_gear(monkeypatch, truck_energy, gear_command):
    steps = []
    step = SimulatorPlant.step

    def recording(self, cmd):
        out = step(self, cmd)
        steps.append((cmd.gear if cmd is not None else None, out.obs.gear, out.obs.v))
        return out

    monkeypatch.setattr(SimulatorPlant, "step", recording)
    st = DriveSettings(controller="mpc", force_model="oracle", time_weight=120_000.0, mpc=TRUCK_MPC,
                       gear_command=gear_command)
    res, _ = drive(truck_spec(15_000.0), _climb(), seed=0, settings=st)
    assert res.metrics["arrived"]
    requested = [(g, plant) for g, plant, _ in steps if g is not None]
    if not gear_command:
        assert not requested  # the transmission's own strategy throughout
        return
    assert len(requested) > 500  # most of the climb is driven above gear_min_speed
    # the plant drives the requested gear (1-based), which is the shift rule's gear of the measured speed
    assert np.mean([g == plant for g, plant in requested]) > 0.99
    for (g, _, _), (_, _, v_prev) in zip(steps[1:], steps[:-1]):
        if g is not None:
            assert abs(int(truck_energy.gear_for_speed(v_prev)) + 1 - g) <= 1


def test_gear_command_settings_are_checked():
    with pytest.raises(ControllerError, match="gear_band"):
        MpcControllerSettings(gear_band=float("nan"))
    with pytest.raises(ControllerError, match="gear_min_speed"):
        MpcControllerSettings(gear_min_speed=-1.0)


KICK_DOWN_REGRESSION = ("known regression: since the gear request kicks down where the commanded force needs full "
                        "load, the abc model's heavier mass picks a lower gear on this climb: abc +4.9 % over the "
                        "oracle at equal time (263 vs 264 s) with the gear command, where it was within 0.5 %")


@pytest.mark.slow
@pytest.mark.xfail(strict=True, reason=KICK_DOWN_REGRESSION)
def test_gear_command_removes_the_gear_penalty_of_the_wrong_force_model_on_a_climb():
    """truck 15 t, long grades seed 6, lambda 131 kJ/s: without the gear command the abc MPC used 4.1 % more fuel
    than the oracle at nearly the same time (the plant downshifted on the 4 % climb at 23.74 m/s, not at 23.84);
    with it, within 0.5 %."""
    from dataclasses import replace

    from roadload.experiments.controller_comparison import VEHICLE_CASES, paired_road
    case = VEHICLE_CASES["truck_15t"]
    road = paired_road("long_grades", 6, 2000.0)
    base = replace(case.settings(), measure_from=2000.0, controller="mpc", time_weight=131_490.858,
                   multistart_period=5.0)
    energy = {}
    for gc in (False, True):
        for fm in ("oracle", "abc"):
            res, _ = drive(case.vehicle(), road, seed=6, settings=replace(base, force_model=fm, gear_command=gc))
            energy[fm, gc] = res.metrics["energy_net_J"]
    assert energy["abc", False] / energy["oracle", False] - 1 > 0.03
    assert abs(energy["abc", True] / energy["oracle", True] - 1) < 0.005
