"""The FASTSim cross-check's vehicle mapping: the preset's motor power and regeneration limit, the start charge."""

import numpy as np
import pytest

pytest.importorskip("fastsim")

from roadload.experiments.fastsim_check import (INITIAL_SOC, fastsim_energy, fastsim_vehicle,  # noqa: E402
                                                limited_battery_power, regeneration_limit)
from roadload.experiments.worlds.common import WorldError  # noqa: E402
from roadload.experiments.worlds.fastsim_world import run_fastsim  # noqa: E402
from roadload.road_profiles import RoadProfile  # noqa: E402


def descent(grade=-0.06, length=3000.0):
    s = np.arange(0.0, length + 1, 5.0)
    z = np.zeros_like(s)
    return RoadProfile("descent", s, np.full_like(s, grade), z, z, np.full_like(s, 30.0))


def test_mapping_carries_the_presets_motor_power_and_regeneration_limit():
    d = fastsim_vehicle("bmw_i3")
    assert d["pt_type"]["BEV"]["em"]["pwr_out_max_watts"] == pytest.approx(125e3)
    # i3: 50 kW and 87 N m at the motor (ratio 9.665, r_W 0.35 m): the torque limit below 20.8 m/s
    assert regeneration_limit("bmw_i3", 25.0) == pytest.approx(50e3)
    assert regeneration_limit("bmw_i3", 10.0) == pytest.approx(87.0 * 10.0 * 9.665 / 0.35)


def test_regeneration_above_the_limit_is_friction_braking():
    # braking from 30 to 5 m/s in 10 s: ~90 kW at the motor, above the 50 kW limit
    t = np.arange(0.0, 60.01, 0.1)
    v = np.interp(t, [0, 20, 30, 40, 60], [0, 30, 30, 5, 5])
    out = run_fastsim(fastsim_vehicle(), t, v, np.zeros_like(t), initial_soc=INITIAL_SOC)
    limit = regeneration_limit("bmw_i3", out["speed"])
    assert out["source_mech"].min() < -80e3  # FASTSim itself regenerates all of it
    limited = limited_battery_power(out, limit)
    regen = out["source_mech"] < 0
    # the electrical power regenerated never exceeds the mechanical limit (efficiency <= 1) plus the auxiliaries
    assert np.all(-limited[regen] <= limit[regen] + 1e-6)
    assert np.all(limited >= out["battery_electrical"] - 1e-9)
    assert np.sum(limited - out["battery_electrical"]) * 0.1 > 50e3  # > 50 kJ less regenerated
    # where the limit is not reached nothing changes
    below = ~regen | (-out["source_mech"] <= limit)
    assert np.array_equal(limited[below], out["battery_electrical"][below])


def test_a_long_descent_from_the_start_runs_at_half_charge():
    # FASTSim's walk() starts at max_soc, cuts the charge power after seconds of regeneration and fails the run
    road = descent()
    t = np.arange(0.0, 150.01, 0.5)
    v = np.minimum(15.0, t)
    s = np.concatenate([[0.0], np.cumsum(0.5 * (v[1:] + v[:-1]) * 0.5)])
    with pytest.raises(RuntimeError, match="charge power"):
        run_fastsim(fastsim_vehicle(), t, v, np.full_like(t, -0.06))
    out = fastsim_energy(t, s, v, road)
    assert out["energy_J"] < 0  # it regenerates on the descent
    assert out["trace_miss"] < 0.05


def test_initial_charge_is_checked():
    t = np.arange(0.0, 5.01, 0.1)
    with pytest.raises(WorldError, match="initial_soc"):
        run_fastsim(fastsim_vehicle(), t, np.full_like(t, 10.0), np.zeros_like(t), initial_soc=1.2)


def test_fastsims_efficiency_chain_reproduces_fastsims_battery_power():
    """The chain that scores roadload's traces with FASTSim's efficiency gives FASTSim's own battery power for
    FASTSim's wheel power: drive, a 6 % climb, and braking above the regeneration limit."""
    from roadload.experiments.fastsim_check import fastsim_efficiency_power

    t = np.arange(0.0, 80.01, 0.1)
    v = np.interp(t, [0, 20, 30, 40, 80], [0, 30, 30, 5, 15])
    grade = np.where((t > 45) & (t < 70), 0.06, 0.0)
    out = run_fastsim(fastsim_vehicle(), t, v, grade, initial_soc=INITIAL_SOC)
    limited = limited_battery_power(out, regeneration_limit("bmw_i3", out["speed"]))
    chain = fastsim_efficiency_power(out["transmission_out"], out["speed"])
    assert out["transmission_out"].max() > 60e3 and out["source_mech"].min() < -80e3
    np.testing.assert_allclose(chain[1:], limited[1:], rtol=1e-9, atol=1e-6)
    # FASTSim 3.1 regenerates at its curve's value at zero power fraction (0.84) whatever the power
    regen = out["source_mech"] < -1e3
    np.testing.assert_allclose(out["motor_electrical"][regen] / out["source_mech"][regen], 0.84, rtol=1e-9)


def test_roadload_trace_scored_with_fastsims_efficiency():
    """An analytic trace: 20 kW at the wheels for 10 s, then 10 kW regenerated for 10 s, at 20 m/s."""
    from roadload.envs import TRUTH_LOG_COLUMNS
    from roadload.experiments.fastsim_check import roadload_trace_fastsim_efficiency

    n, r = 2000, 0.35
    truth = np.zeros((n, len(TRUTH_LOG_COLUMNS)))
    col = {c: i for i, c in enumerate(TRUTH_LOG_COLUMNS)}
    truth[:, col["T"]] = np.arange(n) * 0.01
    truth[:, col["V"]] = 20.0
    truth[:, col["POS"]] = 20.0 * truth[:, col["T"]]
    wheel = np.where(np.arange(n) < n // 2, 20e3, -10e3)
    # the regenerating half brakes 2 kW of it by friction: rim torque = -12 kW / v * r, friction 2 kW / v
    truth[:, col["RIM"]] = np.where(wheel > 0, wheel, wheel - 2e3) / 20.0 * r
    truth[:, col["FBRAKE"]] = np.where(wheel > 0, 0.0, 2e3 / 20.0)
    truth[:, col["PSRC"]] = 1e3
    out = roadload_trace_fastsim_efficiency(truth, 0.0, 1e9)
    eta_t, aux = 0.92, 300.0
    drive_eta = np.interp(20e3 / eta_t / 125e3, [0.1, 0.2], [0.92, 0.94])
    expected = 10.0 * (20e3 / eta_t / drive_eta + aux) + 10.0 * (-10e3 * eta_t * 0.84 + aux)
    assert out["fastsim_efficiency_J"] == pytest.approx(expected, rel=1e-3)
    assert out["roadload_J"] == pytest.approx(20e3, rel=1e-3)
    assert out["wheel_drive_J"] == pytest.approx(200e3, rel=1e-3)
    assert out["wheel_regeneration_J"] == pytest.approx(-100e3, rel=1e-3)
    assert out["fastsim_efficiency_driving_J"] == pytest.approx(10.0 * (20e3 / eta_t / drive_eta + aux), rel=1e-3)
    assert out["roadload_driving_J"] + out["roadload_not_driving_J"] == pytest.approx(out["roadload_J"])
