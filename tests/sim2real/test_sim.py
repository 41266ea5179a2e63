"""sim2real with the simulator: a withheld effect identified blind on short trips, the report files, bad input."""

from __future__ import annotations

import json

import pytest
from typer.testing import CliRunner

from roadload.envs.effects import EffectsConfig
from roadload.sim2real.diagnose import DiagnosisSettings, diagnose, sim_trips
from roadload.sim2real.errors import DiagnosisError
from roadload.sim2real.report import write_report
from roadload.sim2real.simconfig import SimConfig
from roadload.sim2real.table import build_table

ROADS = (("hilly", 21), ("city", 22))
FLOOR_ROADS = (("hilly", 31), ("city", 32))


@pytest.fixture(scope="module")
def sim() -> SimConfig:
    return SimConfig.load("bmw_i3")


@pytest.fixture(scope="module")
def payload_diagnosis(sim):
    real = sim_trips(sim, ROADS, 420.0, effects=EffectsConfig.parse({"payload": {"initial_payload": 250.0,
                                                                                  "change_std": 0.0}}))
    settings = DiagnosisSettings(floor_roads=FLOOR_ROADS, floor_duration=420.0, n_boot=150, segment_length=30.0)
    return real, diagnose(real, sim, settings)


def test_withheld_payload_is_identified_and_the_gap_shrinks(payload_diagnosis):
    _, d = payload_diagnosis
    assert d.identified[:1] == ["mass_offset"]
    eff = d.effects[0]
    assert eff.parameters["delta m_V"] == pytest.approx(250.0, rel=0.15)
    assert eff.sim_switch == "payload"
    assert eff.sim_parameters["initial_payload"] == pytest.approx(eff.parameters["delta m_V"])
    assert d.shrinkage("rmse") > 0.5
    # switched on in the simulator with the fitted mass, the re-simulated sim closes most of the gap too
    assert d.gap_after_sim is not None and d.shrinkage("rmse", simulator=True) > 0.5
    # before: the gap is localised where a mass error shows, in acceleration
    dep = d.notes.strongest_departures_before
    assert dep and dep[0].regime in ("acceleration", "mode")


def test_report_files_and_schema(payload_diagnosis, tmp_path):
    _, d = payload_diagnosis
    paths = write_report(d, tmp_path / "out")
    for key in ("report", "json", "residual_map", "residual_time", "regimes", "ranking"):
        assert paths[key].is_file() and paths[key].stat().st_size > 0
    js = json.loads(paths["json"].read_text())
    assert js["schema_version"] == 1
    assert {"before", "after", "after_simulator", "shrinkage", "per_regime"} <= set(js["gap"])
    assert js["effects"][0]["name"] == "mass_offset" and "std_errors" in js["effects"][0]
    assert js["ranking"][0]["delta_aic"] == 0.0
    assert js["split"]["n_test"] > 0 and "unexplained" in js
    assert "mass_offset" in paths["report"].read_text()
    assert not list((tmp_path / "out").glob(".*.tmp"))


def test_trip_without_needed_channels_is_named(sim, payload_diagnosis):
    real, _ = payload_diagnosis
    bad = real[0].copy()
    bad.measured = bad.measured.drop(columns=["accel_x"])
    bad.units.pop("accel_x")
    with pytest.raises(DiagnosisError, match="accel_x"):
        build_table([bad], sim)


def test_sim_config_of_another_vehicle_is_rejected(payload_diagnosis):
    real, _ = payload_diagnosis
    with pytest.raises(DiagnosisError, match="gt_rwd"):
        build_table(real[:1], SimConfig.load("gt_rwd"))


def test_requested_candidate_without_its_channels_is_an_error(sim, payload_diagnosis):
    real, _ = payload_diagnosis
    no_brakes = []
    for t in real:
        c = t.copy()
        c.measured = c.measured.drop(columns=["brake_pressure_front", "brake_pressure_rear"])
        for k in ("brake_pressure_front", "brake_pressure_rear"):
            c.units.pop(k)
        no_brakes.append(c)
    settings = DiagnosisSettings(candidates=("mass_offset", "friction_brake"), floor_roads=(), resimulate=False,
                                 n_boot=50, segment_length=30.0, strict_candidates=True)
    with pytest.raises(DiagnosisError, match="brake_force"):
        diagnose(no_brakes, sim, settings)


def test_sim_config_file_errors(tmp_path):
    p = tmp_path / "sim.json"
    p.write_text(json.dumps({"vehicle": "bmw_i3", "effect": {}}))
    with pytest.raises(DiagnosisError, match="unknown keys"):
        SimConfig.load(p)
    p.write_text(json.dumps({"vehicle": "no_such_car"}))
    with pytest.raises(DiagnosisError, match="no_such_car"):
        SimConfig.load(p)
    p.write_text(json.dumps({"vehicle": "bmw_i3", "effects": {"effects": {"wind": {"speed": 3}}}}))
    with pytest.raises(DiagnosisError, match="speed"):
        SimConfig.load(p)
    cfg = SimConfig.load("bmw_i3").with_effect("spec:sensors.channels.accel_x.bias", {"delta": 0.1})
    assert cfg.vehicle.sensors.channels["accel_x"].bias == pytest.approx(0.1)
    with pytest.raises(DiagnosisError, match="no field"):
        SimConfig.load("bmw_i3").with_effect("spec:tires.nope", {"delta": 1.0})


def test_cli_diagnose_reports_missing_trip_clearly(tmp_path):
    from roadload.experiments.cli import _load, app

    _load()
    res = CliRunner().invoke(app, ["diagnose", "--sim", "bmw_i3", "--real", str(tmp_path / "missing.parquet"),
                                   "--out", str(tmp_path / "o")])
    assert res.exit_code == 2
    assert "no trip file" in res.output
    assert not (tmp_path / "o").exists()


def test_withheld_auxiliary_load_is_found_on_the_energy_side(sim):
    real = sim_trips(sim, (("city", 41),), 360.0, effects=EffectsConfig.parse({"auxiliary_load": {"power": 1500.0}}))
    settings = DiagnosisSettings(candidates=("mass_offset", "auxiliary_power"), floor_roads=(("city", 42),),
                                 floor_duration=360.0, resimulate=False, n_boot=100, segment_length=30.0)
    d = diagnose(real, sim, settings)
    assert d.energy is not None
    assert [e.name for e in d.energy.effects] == ["auxiliary_power"]
    p = d.energy.effects[0].parameters["delta P_aux"]
    assert p == pytest.approx(1500.0, rel=0.05)
    assert d.energy.effects[0].sim_parameters == {"power": pytest.approx(p)}
    assert abs(d.energy.power_residual_after.median) < 0.05 * abs(d.energy.power_residual_before.median)
