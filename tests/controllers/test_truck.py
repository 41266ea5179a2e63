"""The heavy truck: preset, engine brake in the MPC's energy model, the speed-band cruise control and
the deliberately wrong force model of the sensitivity map."""

import numpy as np
import pytest

from roadload.controllers.cruise import CruiseSettings
from roadload.controllers.drive import DriveSettings, drive
from roadload.controllers.energy import EnergyModelError, with_loss_error
from roadload.controllers.force_model import ErroredForceModel, FixedForceModel, ForceModelError
from roadload.road_load import RoadLoadParameters
from roadload.controllers.base import split_wheel_force
from roadload.controllers.vehicle_models import abc_parameters, energy_model_from_spec
from roadload.presets import TRUCK_MASS_RANGE, get_preset, truck_spec
from roadload.road_profiles import RoadProfile
from roadload.units import G
from roadload.vehicle import VehicleSpecError


def test_truck_preset_is_a_valid_40t_12_speed_vehicle():
    spec = get_preset("truck_40t")
    assert spec.mass == 40_000.0 and spec.drivetrain.n_gears == 12
    assert spec.drag_area == pytest.approx(5.7)
    # 85 km/h in 12th at ~1170 rpm
    rpm = 85 / 3.6 / spec.tires.dynamic_radius * spec.drivetrain.final_drive * 60 / (2 * np.pi)
    assert 1100 < rpm < 1250
    assert truck_spec(15_000.0).mass == 15_000.0
    with pytest.raises(VehicleSpecError, match="gross_mass"):
        truck_spec(TRUCK_MASS_RANGE[1] + 1.0)


def test_truck_energy_model_brakes_with_the_engine_for_free():
    en = energy_model_from_spec("truck_40t")
    assert en.kind == "ice" and en.regenerates
    assert en.max_regen_power > 300e3  # engine brake + retarder ~450 kW
    top = en.gear_ratios[-1]
    # fuel for braking is zero: the ICE's regen force does not enter the fuel power
    assert en.source_power(0.0, 20e3, 22.0, top) == pytest.approx(en.source_power(0.0, 0.0, 22.0, top))
    cmd = split_wheel_force(-30e3, 22.0, en, top)
    assert cmd.regen > 8e3 and cmd.regen + cmd.brake == pytest.approx(30e3)  # ~180 kW engine brake in 12th
    # the Willans fit: brake efficiency of the diesel at cruise ~ 40-46 %
    f, v = 5000.0, 23.6
    eff = f * v / en.source_power(f, 0.0, v, top)
    assert 0.38 < eff < 0.47
    with pytest.raises(EnergyModelError, match="loss error"):
        with_loss_error(en, -1.0)
    assert with_loss_error(en, 0.3).loss[0] == pytest.approx(1.3 * en.loss[0])


def test_abc_of_the_fleet_uses_the_nominal_half_load_mass():
    p = abc_parameters(truck_spec(27_500.0))
    assert p.mass == 27_500.0
    assert p.c0 == pytest.approx(27_500.0 * G * 0.0055, rel=0.15)  # coast-down a_V ~ m g f_r0 (+ drive-train)
    assert 800 < p.rotational_mass < 1300  # top gear: wheels + drive-train


def _descent() -> RoadProfile:
    s = np.arange(0.0, 3500.0, 5.0)
    grade = np.where(s < 700.0, 0.0, np.arctan(-0.04))
    return RoadProfile("descent", s, grade, np.zeros_like(s), np.zeros_like(s), np.full_like(s, 25.0))


@pytest.mark.slow
def test_speed_band_cruise_lets_the_truck_roll_downhill():
    road, spec = _descent(), truck_spec(40_000.0)
    out = {}
    for band in (0.0, 0.8):
        st = DriveSettings(controller="cruise", force_model="abc",
                           cruise=CruiseSettings(fraction=0.95, overspeed=band))
        res, _ = drive(spec, road, seed=0, settings=st)
        out[band] = res
    v_set = 0.95 * 25.0

    def late(res):  # mean speed over the last 1000 m of the descent
        log = res.log
        return float(log["v"][log["s"] > 2500.0].mean())

    assert abs(late(out[0.0]) - v_set) < 0.5  # holds the set speed downhill (brakes)
    assert late(out[0.8]) > v_set + 0.6  # rolls into the band [v_set, v_set + 0.8]
    assert out[0.8].log["v"].max() < 25.0 + 0.1  # never above the limit
    # downhill both run in fuel cut: the band arrives earlier on the same fuel (what it saves at equal time)
    assert out[0.8].metrics["energy_J"] <= out[0.0].metrics["energy_J"] * (1 + 1e-9)
    assert out[0.8].metrics["trip_time"] < out[0.0].metrics["trip_time"] - 2.0


def test_errored_force_model_scales_the_right_terms():
    p = RoadLoadParameters(mass=1000.0, c0=100.0, c1=2.0, c2=0.4, c4=1e-5, k_corner=30.0, rotational_mass=50.0)
    wrong = ErroredForceModel(FixedForceModel(p), {"mass": 0.2, "rolling": -0.5, "drag_area": 0.3,
                                                   "grade_bias": 0.01})
    q = wrong.parameters()
    assert q.mass == pytest.approx(1200.0) and q.rotational_mass == 50.0
    assert q.c0 == pytest.approx(100.0 * 1.2 * 0.5 + 1200.0 * G * np.sin(0.01))
    assert q.c1 == pytest.approx(2.0 * 1.2 * 0.5) and q.c2 == pytest.approx(0.52)
    assert q.k_corner == pytest.approx(30.0 * 1.44)
    with pytest.raises(ForceModelError, match="unknown"):
        ErroredForceModel(FixedForceModel(p), {"wheel_count": 1.0})
    with pytest.raises(ForceModelError, match="> -1"):
        ErroredForceModel(FixedForceModel(p), {"mass": -1.0})
