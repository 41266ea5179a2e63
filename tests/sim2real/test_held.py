"""The calibration's drive-train loss is identified (one loss error, not a free efficiency per direction), the
directions it held at a physical bound are recorded and travel with the calibrated sim, and the diagnosis reports
an effect along such a direction as not separable from the base error instead of accepting it; an accelerometer
bias must agree with the logged elevation."""

from __future__ import annotations

import importlib.util
import json
from pathlib import Path

import numpy as np
import pytest

from roadload.sim2real.base import BaseBlock, BaseParameter
from roadload.sim2real.calibrate import (CalibrationSettings, bounded_posterior, drivetrain_efficiencies, fit_energy,
                                         fit_force)
from roadload.sim2real.catalog import get_candidate
from roadload.sim2real.diagnose import DiagnosisSettings, elevation_consistency, energy_consistency
from roadload.sim2real.errors import DiagnosisError
from roadload.sim2real.forcemodel import SimForceModel
from roadload.sim2real.held import DRIVETRAIN_LOSS, held_share, separability_check
from roadload.sim2real.selection import NOT_SEPARABLE, Selector, make_split
from roadload.sim2real.simconfig import SimConfig

_spec = importlib.util.spec_from_file_location("sim2real_core_tables", Path(__file__).with_name("test_core.py"))
assert _spec is not None and _spec.loader is not None
_core = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(_core)

SPEC = SimConfig.load("bmw_i3").vehicle
MODEL = SimForceModel.from_spec(SPEC)
ETA = drivetrain_efficiencies(SPEC)[0]


def _table(extra, seed: int = 3, noise: float = 10.0):
    """Synthetic trips (test_core's) with the i3's force model as the sim and ``extra`` added to the measured force."""
    tab = _core.synth(lambda t: 0.0, noise=0.0, seed=seed)
    sim = MODEL.predict(tab)
    rng = np.random.default_rng(seed)
    tab["sim_force"] = tab["sim_drive_force"] = tab["drive_force"] = sim
    tab["mode"] = np.where(sim > 0, "traction", "regen")
    tab["tractive_force"] = sim + extra(tab, sim) + rng.normal(0.0, noise, len(tab))
    tab["residual"] = tab.tractive_force - tab.sim_force
    return tab


def _heavier_and_lossier(tab, sim):
    """A car 200 kg heavier whose drive-train efficiency is 0.92 in both directions (the sim's: η_sim): the
    pipeline reads its force from the torque with η_sim, T i η_sim / r_W in traction, T i / (η_sim r_W) in
    regeneration."""
    true = sim + 200.0 * (9.81 * np.sin(tab.gradient_angle) + tab.acceleration
                          + 9.81 * np.cos(tab.gradient_angle) * MODEL.rolling_resistance_coefficient(tab.speed))
    return np.where(true > 0, true * ETA / 0.92, true * 0.92 / ETA) - sim


@pytest.mark.parametrize("prior_scale", [1.0, 100.0])
def test_drivetrain_efficiency_is_identified_whatever_the_prior(prior_scale):
    """Fitted as two free efficiencies, the symmetric part is collinear with mass and road load and slid to the
    bounds (FASTSim's Zoe: η_t 1.0, η_r 0.7); the one loss error reads η = 0.92 and the mass whatever the prior's
    width."""
    tab = _table(_heavier_and_lossier)
    split = make_split(tab, seed=3, n_folds=4)
    fit = fit_force(tab, split, tab.residual.to_numpy(), SPEC, MODEL,
                    CalibrationSettings(prior_scale=prior_scale), np.zeros(len(tab)))
    assert DRIVETRAIN_LOSS in fit.names and not any(n.startswith("drivetrain_efficiency") for n in fit.names)
    eps = fit.get(DRIVETRAIN_LOSS)
    assert ETA / (1 + eps) == pytest.approx(0.92, abs=0.01)
    assert ETA * (1 - eps) == pytest.approx(0.92, abs=0.01)
    assert fit.get("mass") + fit.get("rotating_inertia") == pytest.approx(200.0, abs=40.0)
    assert not fit.held


def test_a_change_pushed_beyond_its_range_is_held_and_what_the_bound_held_back_recorded():
    rng = np.random.default_rng(0)
    A = rng.normal(size=(2000, 3))
    y = A @ np.array([3.0, -0.5, -1.004]) + rng.normal(0, 0.1, 2000)
    rows = np.ones(2000, bool)
    bounds = np.array([[-1.0, 1.0]] * 3)
    x, _, back = bounded_posterior(A, y, np.ones(2000), rows, np.arange(2000) // 20, np.full(3, 10.0), bounds)
    assert x[0] == 1.0 and x[2] == -1.0 and x[1] == pytest.approx(-0.5, abs=0.1)   # the other refitted given them
    assert back[0] == pytest.approx(2.0, abs=0.1) and back[1] == 0.0
    assert back[2] == 0.0           # beyond its bound by less than 2.58 standard errors: a value at the edge


def test_held_share_counts_only_the_side_the_data_wanted():
    rng = np.random.default_rng(1)
    d = rng.normal(size=(500, 1))
    other = rng.normal(size=500)
    assert held_share(2.0 * d[:, 0], d, np.array([3.0])) == pytest.approx(1.0)
    assert held_share(-2.0 * d[:, 0], d, np.array([3.0])) == pytest.approx(0.0)   # against the held side
    assert held_share(2.0 * d[:, 0], d, np.array([0.5])) == pytest.approx(1.0 - 1.5 ** 2 / 2.0 ** 2)  # at most Δ
    assert held_share(other, d, np.array([3.0])) < 0.05
    assert held_share(other, np.zeros((500, 0)), np.zeros(0)) == 0.0


def _drive_loss_residual(tab, sim):
    """A drive-train 5 % lossier than the sim's in both directions (ε = +0.05 on |F_drive|)."""
    return 0.05 * np.abs(sim)


def test_an_effect_along_a_held_direction_is_reported_not_separable():
    """Against a calibration that held the drive-train loss at its bound with the data wanting more loss, a
    drive-efficiency residual is the calibration's own: not accepted, reported as not separable. With the bound
    held on the other side, by far less than the residual shows, or nothing held, it is accepted as
    `drive_efficiency`."""
    tab = _table(_drive_loss_residual, seed=5)
    split = make_split(tab, seed=5, n_folds=4)

    def run(held):
        check = separability_check(held, tab, split.train, MODEL, SPEC, "force")
        sel = Selector(tab, tab.residual.to_numpy(), split, MODEL, robust=False, n_boot=100, seed=5,
                       consistent=check)
        ranked, _ = sel.rank(["drive_efficiency", "mass_offset", "drag_area", "rolling_scale"])
        return ranked, sel.forward(ranked)

    ranked, steps = run({})
    assert ranked[0].name == "drive_efficiency" and steps[0].accepted
    for held in ({DRIVETRAIN_LOSS: -0.1}, {DRIVETRAIN_LOSS: 0.005}):      # the other side; 10 x smaller
        _, steps = run(held)
        assert steps[0].effect == "drive_efficiency" and steps[0].accepted, held
    _, steps = run({DRIVETRAIN_LOSS: 0.1})
    first = next(s for s in steps if s.effect == "drive_efficiency")
    assert not first.accepted and first.reason.startswith(NOT_SEPARABLE)
    assert "drivetrain_loss" in first.reason
    assert separability_check({}, tab, split.train, MODEL, SPEC, "force") is None
    assert separability_check({"motor_loss_scale": -0.5}, tab, split.train, MODEL, SPEC, "force") is None
    c = separability_check({DRIVETRAIN_LOSS: 0.1}, tab, split.train, MODEL, SPEC, "force")
    assert c is not None and c(get_candidate("mass_offset"), {"mass offset [kg]": 100.0}, None, 50.0) is None


def test_held_directions_travel_with_the_sim_config(tmp_path):
    sim = SimConfig(SPEC, held_at_bound={DRIVETRAIN_LOSS: 0.02, "motor_loss_scale": -0.4})
    back = SimConfig.from_dict(json.loads(json.dumps({**sim.to_dict(), "vehicle": "bmw_i3"})))
    assert back.held_at_bound == {DRIVETRAIN_LOSS: 0.02, "motor_loss_scale": -0.4}
    assert sim.with_effect("payload", {"initial_payload": 100.0}).held_at_bound == sim.held_at_bound
    assert "held_at_bound" not in SimConfig(SPEC).to_dict()
    with pytest.raises(DiagnosisError, match="held_at_bound"):
        SimConfig.from_dict({"vehicle": "bmw_i3", "held_at_bound": {"mass": "a lot"}})


def _elevation_block(b: float, se: float) -> BaseBlock:
    return BaseBlock([BaseParameter("accelerometer bias (from the logged elevation)", "accel_bias",
                                    "accelerometer bias b", "m/s^2", b, se, 1500.0 * abs(b), True, in_fit=False)])


def test_an_accelerometer_bias_the_elevation_does_not_show_is_rejected():
    """FASTSim's rolling resistance x 1.3 was named `accel_bias` (b = -0.028 m/s², a constant 44 N) while the
    logged elevation showed no bias: such a fit is inconsistent; a bias the elevation shows (beyond the sim's own
    sensor bias, which a calibration writes into the spec) passes."""
    s = DiagnosisSettings()
    bias = get_candidate("accel_bias")
    check = elevation_consistency(_elevation_block(0.001, 0.0005), SimConfig(SPEC), 1500.0, s)
    reason = check(bias, {"accelerometer bias b": -0.028}, None, 42.0)
    assert reason and reason.startswith("inconsistent with the logged elevation")
    assert check(bias, {"accelerometer bias b": 0.0012}, None, 1.8) is None
    assert check(get_candidate("rolling_scale"), {"rolling factor - 1": 0.3}, None, 42.0) is None
    biased = SimConfig(SPEC.replace(**{"sensors.channels.accel_x.bias": 0.05}))
    check = elevation_consistency(_elevation_block(0.15, 0.002), biased, 1500.0, s)
    assert check(bias, {"accelerometer bias b": 0.1}, None, 150.0) is None          # 0.15 - 0.05 beyond the sim
    assert check(bias, {"accelerometer bias b": 0.3}, None, 450.0) is not None          # 0.2 too much
    wide = elevation_consistency(_elevation_block(0.0, 0.05), SimConfig(SPEC), 1500.0, s)
    assert wide(bias, {"accelerometer bias b": 0.1}, None, 150.0) is None            # the elevation cannot tell
    assert elevation_consistency(None, SimConfig(SPEC), 1500.0, s) is None
    assert elevation_consistency(_elevation_block(0.0, 0.001), SimConfig(SPEC), 1500.0,
                                 DiagnosisSettings(elevation_consistency=False)) is None


def _power_table(gain: float, seed: int = 4):
    """test_core's trips with a motor: the battery-power residual of a drive-torque signal reading ``gain`` high
    (P_el,sim from the logged torque over-predicts by g T ω) plus noise."""
    tab = _core.synth(lambda t: 0.0, noise=0.0, seed=seed)
    rng = np.random.default_rng(seed)
    tab["motor_speed"] = tab.speed * 27.6
    tab["drive_torque"] = MODEL.predict(tab) * 0.35 / 9.665
    tab["power_residual"] = -gain * tab.drive_torque * tab.motor_speed + rng.normal(0.0, 300.0, len(tab))
    return tab


def test_a_torque_signal_kept_at_the_sims_records_what_the_reference_wanted():
    tab = _power_table(0.04)
    split = make_split(tab, seed=4, n_folds=4)
    kept = fit_energy(tab, split, SPEC, MODEL, CalibrationSettings(), signal=False)
    fitted = fit_energy(tab, split, SPEC, MODEL, CalibrationSettings(), signal=True)
    assert kept.get("torque_signal_gain") == 0.0 and kept.get("torque_signal_offset") == 0.0
    assert fitted.get("torque_signal_gain") == pytest.approx(0.04, abs=0.005)
    assert kept.held["torque_signal_gain"] == pytest.approx(fitted.get("torque_signal_gain"))
    assert "torque_signal_gain" not in fitted.held
    quiet = fit_energy(_power_table(0.0), split, SPEC, MODEL, CalibrationSettings(), signal=False)
    assert "torque_signal_gain" not in quiet.held      # nothing wanted: nothing held back


def test_no_energy_consistency_where_the_calibration_found_the_gain_is_no_signal():
    """A calibration that kept the signal at the sim's against the reference trips' -T ω term found that term is
    no torque signal on this car: no check then; without that finding the same block rejects a payload."""
    tab = _table(lambda t, sim: 0.0)
    tab["drive_force"] = MODEL.predict(tab)
    split = make_split(tab, seed=3, n_folds=4)
    block = BaseBlock([BaseParameter("drive-torque signal gain", "torque_scale", "drive-torque signal gain error g",
                                     "1", 0.04, 0.005, 400.0, True)])
    mass = get_candidate("mass_offset")
    s = DiagnosisSettings()
    assert energy_consistency(block, tab, split, s)(mass, {"delta m_V": 150.0}, None, 60.0) is not None
    assert energy_consistency(block, tab, split, s, {"torque_signal_gain": -0.055}) is None
    assert energy_consistency(block, tab, split, s, {"motor_loss_scale": -0.3}) is not None
