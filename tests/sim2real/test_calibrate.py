"""Calibrate, then diagnose against the calibration: a base error and an auxiliary load on different trips are
separated; the calibrated spec round-trips through simulate, diagnose --sim and the MPC's force models; the
drive-train efficiency is reported as an efficiency; per-trip sizes and the test that they differ; an effect
injected into a real-log fixture (the i3 logger's CSV layout, written here from simulated data) is recovered."""

from __future__ import annotations

import importlib.util
import json
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from roadload.envs.effects import EffectsConfig
from roadload.io import import_log
from roadload.sim2real import DiagnosisSettings, SimConfig, diagnose
from roadload.sim2real.base import base_calibration
from roadload.sim2real.calibrate import CalibrationSettings, calibrate
from roadload.sim2real.diagnose import sim_trips
from roadload.sim2real.errors import DiagnosisError
from roadload.sim2real.inject import inject
from roadload.sim2real.report import calibration_paths, write_calibration
from roadload.sim2real.robust import robust_target
from roadload.sim2real.selection import make_split
from roadload.vehicle import load_vehicle

_spec = importlib.util.spec_from_file_location("sim2real_core_tables", Path(__file__).with_name("test_core.py"))
assert _spec is not None and _spec.loader is not None
_core = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(_core)
MODEL, synth = _core.MODEL, _core.synth

FLOOR = (("hilly", 9101),)
SMALL = DiagnosisSettings(floor_roads=FLOOR, floor_duration=300.0, n_boot=60, n_null=99, resimulate=False,
                          replay=False)
CAL = CalibrationSettings(floor_roads=FLOOR, floor_duration=300.0, passes=1)


@pytest.fixture(scope="module")
def truth() -> SimConfig:
    """The "car": the bmw_i3 preset 150 kg heavier, 10 % more drag area, a 800 W auxiliary load instead of 300 W
    and a drive-torque signal reading 7 % high (the preset's own sensor model reads 2 % high)."""
    spec = SimConfig.load("bmw_i3").vehicle
    return SimConfig(spec.replace(**{"body.mass": 1550.0, "aero.drag_coefficient": spec.aero.drag_coefficient * 1.1,
                                     "drivetrain.battery.auxiliary_power": 800.0,
                                     "sensors.drive_torque_gain_error": 0.07}), name="the car")


@pytest.fixture(scope="module")
def calibration(truth):
    reference = sim_trips(truth, (("hilly", 21), ("city", 22), ("motorway", 23)), 600.0)
    return calibrate(reference, SimConfig.load("bmw_i3"), CAL)


def test_calibration_recovers_the_base_vehicle(calibration):
    c = calibration
    assert c.parameter("mass").calibrated == pytest.approx(1550.0, abs=60.0)
    assert c.parameter("drag_area").calibrated == pytest.approx(0.759, rel=0.06)
    assert c.parameter("auxiliary_power").calibrated == pytest.approx(800.0, abs=100.0)
    assert c.parameter("torque_signal_gain").calibrated == pytest.approx(0.07, abs=0.01)
    for p in c.parameters:       # every value with an uncertainty, inside its physical range
        assert np.isfinite(p.calibrated_std) and p.calibrated_std >= 0 and p.low <= p.calibrated <= p.high
    assert c.heldout.force_shrinkage > 0.5        # re-run against the written spec, held-out segments


def test_base_error_and_auxiliary_load_on_different_trips_are_separated(truth, calibration):
    """The reference trips carry the base error, the new trips also an auxiliary load of 1500 W: against the
    calibration the load is named with its size; against the preset the base error's 500 W of auxiliary power and
    its torque-signal gain ride along with it."""
    loaded = SimConfig(truth.vehicle, EffectsConfig.parse({"auxiliary_load": {"power": 1500.0}}))
    trips = sim_trips(loaded, (("city", 31), ("hilly", 32)), 600.0)
    d = diagnose(trips, calibration.sim_config, SMALL)
    assert d.energy is not None and [e.name for e in d.energy.effects][:1] == ["auxiliary_power"]
    assert d.energy.effects[0].parameters["delta P_aux"] == pytest.approx(1500.0, rel=0.15)
    assert not d.effects, [e.name for e in d.effects]           # the base error is the calibration's
    preset = diagnose(trips, SimConfig.load("bmw_i3"), SMALL)
    aux = [e for e in (preset.energy.effects if preset.energy else []) if e.name == "auxiliary_power"]
    assert not aux or abs(aux[0].parameters["delta P_aux"] / 1500.0 - 1.0) > 0.25 or preset.effects


def test_calibrated_spec_round_trips_through_simulate_diagnose_and_the_mpc(calibration, tmp_path):
    from roadload.controllers.vehicle_models import abc_parameters, energy_model_from_spec
    from roadload.experiments.cli import _load, app

    paths = write_calibration(calibration, tmp_path / "calibrated.json")
    assert {k: p.is_file() for k, p in paths.items()} == {k: True for k in paths}
    spec = load_vehicle(paths["spec"])
    assert SimConfig.load(paths["sim"]).vehicle.to_dict() == spec.to_dict()
    assert spec.body.mass == pytest.approx(calibration.parameter("mass").calibrated)
    assert spec.drivetrain.battery.auxiliary_power == pytest.approx(calibration.parameter("auxiliary_power").calibrated)
    assert SimConfig.load(paths["spec"]).vehicle.to_dict() == spec.to_dict()       # diagnose --sim reads it
    assert abc_parameters(spec).mass == pytest.approx(spec.body.mass)              # the MPC's force models
    assert energy_model_from_spec(spec) is not None
    record = json.loads(paths["json"].read_text())
    assert record["calibrated_spec"] == "calibrated.json" and record["parameters"][0]["unit"]
    assert "| parameter | sim | calibrated |" in paths["report"].read_text()
    _load()
    out = tmp_path / "trip.parquet"
    res = CliRunner().invoke(app, ["simulate", "--vehicle", str(paths["spec"]), "--road", "city", "--duration",
                                   "60", "--out", str(out)])
    assert res.exit_code == 0, res.output
    assert out.is_file()
    with pytest.raises(DiagnosisError, match=r"ends in \.json"):
        calibration_paths(tmp_path / "calibrated.txt")


def _efficiency_block(eta_true: float):
    """Base block on trips whose true drive-train efficiency is ``eta_true`` while the sim's is MODEL's."""
    eta = MODEL.drivetrain_efficiency

    def extra(tab):      # measured force: T i η_sim / r_W in traction, T i / (η_sim r_W) in regeneration
        f = MODEL.predict(tab)
        return np.where(f > 0, f * (eta / eta_true - 1.0), f * (eta_true / eta - 1.0))
    tab = synth(extra, noise=5.0, seed=2)
    split = make_split(tab, seed=2, n_folds=4)
    tg = robust_target(tab, tab.residual.to_numpy(), split.train, split.segments, split.fold, split.n_folds)
    block, _ = base_calibration(tab, tg, split, MODEL)
    return block.parameter("drive_efficiency")


def test_calibrated_efficiency_is_reported_as_an_efficiency():
    """A car with η = 0.90 against a sim with η = 0.97: the block says η_t = η_r = 0.90 (it said η_sim (1 + ε) =
    1.045 before), and an efficiency above 1 is flagged."""
    e = _efficiency_block(0.90)
    assert e.physical.calibrated == pytest.approx(0.90, abs=0.01)
    assert e.physical.calibrated_regen == pytest.approx(0.90, abs=0.01)
    assert 0 < e.physical.calibrated <= 1 and e.physical.flag is None
    high = _efficiency_block(1.05)
    assert high.physical.flag and "implausible efficiency" in high.physical.flag


def test_per_trip_sizes_differ_more_than_chance_only_when_they_do(truth, calibration):
    trips = []
    for k, power in enumerate((500.0, 1500.0, 2500.0)):
        cfg = SimConfig(truth.vehicle, EffectsConfig.parse({"auxiliary_load": {"power": power}}))
        trips += sim_trips(cfg, (("city", 41 + k),), 500.0)
    d = diagnose(trips, calibration.sim_config, SMALL)
    aux = d.energy.effects[0]
    sizes = [s.values["delta P_aux"] for s in aux.per_trip.sizes]
    assert sizes == pytest.approx([500.0, 1500.0, 2500.0], abs=150.0)
    assert aux.per_trip.differ and aux.per_trip.p_value < 1e-6
    same = []
    for k in range(3):
        cfg = SimConfig(truth.vehicle, EffectsConfig.parse({"auxiliary_load": {"power": 1500.0}}))
        same += sim_trips(cfg, (("city", 41 + k),), 500.0)
    d_same = diagnose(same, calibration.sim_config, SMALL)
    assert not d_same.energy.effects[0].per_trip.differ
    assert d_same.trip_info and d_same.trip_info[0].trip.startswith("sim-city")


# ------------------------------------------------------------------------------------------ a real-log fixture
TUM_COLUMNS = {"t": "Time [s]", "vehicle_speed": "Velocity [km/h]", "elevation": "Elevation [m]",
               "drive_torque": "Motor Torque [Nm]", "accel_x": "Longitudinal Acceleration [m/s^2]",
               "battery_voltage": "Battery Voltage [V]", "battery_current": "Battery Current [A]",
               "ambient_temperature": "Ambient Temperature [°C]"}


def write_tum_log(trip, path: Path) -> Path:
    """A trip written the way the TUM i3 logger writes it: 10 Hz, ';', latin-1, km/h, °C, discharge negative."""
    m = trip.measured.iloc[::10][list(TUM_COLUMNS)].copy()
    m["vehicle_speed"] *= 3.6
    m["ambient_temperature"] -= 273.15
    m["battery_current"] *= -1.0
    m["elevation"] = m["elevation"].round(0)
    m.columns = list(TUM_COLUMNS.values())
    m.to_csv(path, sep=";", index=False, encoding="latin-1", float_format="%.4f")
    return path


def test_injected_load_is_recovered_from_a_real_log_fixture(truth, tmp_path):
    paths = [write_tum_log(t, tmp_path / f"Trip{k}.csv")
             for k, t in enumerate(sim_trips(truth, (("city", 51), ("hilly", 52), ("motorway", 53)), 600.0))]
    logged = [import_log(p, "bmw-i3") for p in paths]
    cal = calibrate(logged, SimConfig.load("bmw_i3"), CAL)
    copies = [inject(t, "aux_load", 1500.0) for t in logged]
    assert copies[0].meta["injected"] == {"effect": "aux_load", "size": 1500.0, "unit": "W",
                                          "channel": "battery_voltage,battery_current"}
    d = diagnose(copies, cal.sim_config, SMALL)
    assert d.energy is not None and d.energy.effects and d.energy.effects[0].name == "auxiliary_power"
    assert d.energy.effects[0].parameters["delta P_aux"] == pytest.approx(1500.0, rel=0.25)
    with pytest.raises(DiagnosisError, match=r"must lie in \[0, 20000\] \[W\]"):
        inject(logged[0], "aux_load", 5e4)
    with pytest.raises(DiagnosisError, match="unknown injected effect"):
        inject(logged[0], "payload", 1.0)


def test_frame_written_as_the_logger_writes_it_reads_back(truth, tmp_path):
    trip = sim_trips(truth, (("city", 61),), 120.0)[0]
    back = import_log(write_tum_log(trip, tmp_path / "TripX.csv"), "bmw-i3")
    v = trip.measured["vehicle_speed"].to_numpy()[::10]
    got = back.channel("vehicle_speed")[:len(v)]
    ok = np.isfinite(got)
    err = np.abs(got[ok] - v[ok])           # km/h at 4 decimals, back in m/s (the importer clips negative speed)
    assert ok.mean() > 0.99 and np.median(err) < 1e-4 and np.quantile(err, 0.99) < 0.05
