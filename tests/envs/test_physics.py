"""Simulator physics: energy balance, analytic steady states, coast-down, single-track yaw gain."""

import numpy as np

from roadload.envs.coast_down import neutral_road_load, road_load_coefficients
import pytest
from scipy.optimize import brentq

from roadload.envs import Action, Simulator, get_preset, simulate
from roadload.road_profiles import RoadProfile
from roadload.units import G, air_density


def hilly_road(length=8000.0, stops=(3000.0,)):
    s = np.arange(0.0, length + 1.0, 5.0)
    grade = 0.05 * np.sin(s / 350.0) + 0.02 * np.sin(s / 97.0)
    curvature = 0.004 * np.sin(s / 260.0)
    return RoadProfile("hilly-test", s, grade, curvature, np.zeros_like(s), np.full_like(s, 22.0),
                       stops=np.asarray(stops, float))


def flat_road(length=20000.0, grade=0.0, limit=60.0):
    s = np.array([0.0, length])
    return RoadProfile("flat", s, [grade, grade], [0.0, 0.0], [0.0, 0.0], [limit, limit])


def kinetic_energy(spec, v, gear, omega_e):
    """1/2 (m + (4 I_W + i_D^2 I_D)/r^2) v^2 + 1/2 (I_E + I_C + I_G(G)) omega_E^2, straight from the spec."""
    d, t = spec.drivetrain, spec.tires
    m_w = spec.body.mass + (4 * t.wheel_inertia + d.final_drive ** 2 * d.differential_inertia) / t.dynamic_radius ** 2
    j = d.source_inertia + d.clutch_inertia + (d.gearbox_inertia[gear - 1] if gear >= 1 else 0.0)
    return 0.5 * m_w * v ** 2 + 0.5 * j * omega_e ** 2


@pytest.mark.parametrize("preset", ["gt_rwd", "bmw_i3"])
def test_energy_balance_closes_over_hilly_trip(preset):
    spec = get_preset(preset)
    road = hilly_road()
    trip = simulate(spec, road, seed=5)
    e = trip.meta["energy"]
    tr = trip.truth
    s_end = tr["position"].iloc[-1]
    gear_end = int(tr["gear"].iloc[-1])
    ke0 = kinetic_energy(spec, 0.0, 1, spec.drivetrain.engine.idle_speed if preset == "gt_rwd" else 0.0)
    ke1 = kinetic_energy(spec, tr["speed"].iloc[-1], gear_end, tr["engine_speed"].iloc[-1])
    d_pe = spec.body.mass * G * (np.interp(s_end, road.distance, road.elevation()) - 0.0)
    dissipated = sum(e[k] for k in ("gearbox_loss", "differential_loss", "clutch_loss", "brake_loss",
                                    "rolling_loss", "aero_loss", "cornering_loss"))
    drive_work = e["shaft_work"]
    assert s_end > 7990.0  # the trip reached the end of the road
    assert abs(drive_work - (ke1 - ke0 + d_pe + dissipated)) / drive_work < 0.005
    # every dissipation path is exercised (hills -> brakes, stop -> clutch for the ICE)
    for k in ("gearbox_loss", "differential_loss", "brake_loss", "rolling_loss", "aero_loss", "cornering_loss"):
        assert e[k] > 0.0, k
    if preset == "gt_rwd":
        assert e["clutch_loss"] > 0.0
    assert e["source"] > drive_work  # fuel / battery energy exceeds shaft work
    assert np.ptp(road.elevation()) > 20.0  # a hilly trip indeed


def steady_speed(spec, force, grade, rho):
    t = spec.tires
    toe = t.cornering_stiffness_front * t.toe_in * np.sin(t.toe_in)

    def residual(v):
        return (force - spec.body.mass * G * np.sin(grade)
                - t.rolling_resistance_coefficient(v) * spec.body.mass * G * np.cos(grade)
                - 0.5 * rho * spec.aero.drag_area * v ** 2 - toe)
    return brentq(residual, 0.5, 120.0)


@pytest.mark.parametrize("preset,gear,force", [("bmw_i3", None, 1000.0), ("gt_rwd", 5, 1600.0)])
def test_steady_state_speed_on_constant_grade_matches_analytic(preset, gear, force):
    spec = get_preset(preset)
    grade = np.arctan(0.03)
    rho = float(air_density(293.15, 101325.0))
    v_star = steady_speed(spec, force, grade, rho)
    sim = Simulator(spec, flat_road(60000.0, grade=grade), seed=0, initial_speed=0.85 * v_star)
    for _ in range(900):
        res = sim.step(Action(traction_force=force, gear=gear), n_substeps=100)
    assert abs(res.v - v_star) < 0.005, (res.v, v_star)
    assert abs(res.tractive_force - force) < 0.5
    if gear is not None:
        assert res.gear == gear


def coast_down_coefficients(spec):
    """Coast down from 130 to 15 km/h in neutral on a flat road, decelerations in 1 km/h bins -> a + b v + c v^2."""
    v0, v1 = 135 / 3.6, 12 / 3.6
    sim = Simulator(spec, flat_road(10000.0), seed=0, initial_speed=v0)
    t_hist, v_hist = [0.0], [v0]
    while sim.state.v > v1:
        r = sim.step(Action(gear=0), n_substeps=10)
        t_hist.append(r.t)
        v_hist.append(r.v)
    t_hist, v_hist = np.array(t_hist), np.array(v_hist)
    edges = np.arange(130, 14, -1) / 3.6
    t_cross = np.interp(-edges, -v_hist, t_hist)  # v decreases monotonically
    decel = -np.diff(edges) / np.diff(t_cross)
    v_mid = 0.5 * (edges[1:] + edges[:-1])
    force = spec.effective_mass(0) * decel
    c, b, a = np.polyfit(v_mid, force, 2)
    return (a, b, c), v_mid


@pytest.mark.parametrize("preset", ["gt_rwd", "gt_awd", "bmw_i3"])
def test_coast_down_recovers_road_load_coefficients(preset):
    spec = get_preset(preset)
    (a, b, c), speeds = coast_down_coefficients(spec)
    a0, b0, c0 = road_load_coefficients(spec, speeds=speeds)  # the same speed points as the coast-down fit
    assert a == pytest.approx(a0, rel=0.02)
    assert b == pytest.approx(b0, rel=0.02)
    assert c == pytest.approx(c0, rel=0.02)
    # the coefficients mean what they say: a ~ m g f_r0, c ~ rho/2 c_x A
    assert a0 == pytest.approx(spec.body.mass * G * spec.tires.rolling_resistance_f0, rel=0.25)
    assert c0 == pytest.approx(0.5 * float(air_density(293.15, 101325.0)) * spec.aero.drag_area, rel=0.25)


@pytest.mark.parametrize("speed", [8.0, 20.0, 30.0])
def test_single_track_steady_yaw_rate_gain(speed):
    spec = get_preset("gt_rwd")
    delta = 0.004
    sim = Simulator(spec, flat_road(5000.0), seed=0, initial_speed=speed)
    force = float(neutral_road_load(spec, speed)) + 40.0
    for _ in range(80):  # 8 s
        res = sim.step(Action(traction_force=force, steer=delta), n_substeps=10)
    last = sim.to_trip().truth.iloc[-1]
    gain = last["yaw_rate"] / delta
    expected = spec.yaw_rate_gain(last["speed"])
    assert gain == pytest.approx(expected, rel=0.01)
    # and the kinematic (Ackermann) gain v/l differs by the understeer term at speed
    if speed >= 20.0:
        assert abs(gain - last["speed"] / spec.body.wheelbase) / gain > 0.05
    assert res.lateral_acceleration == pytest.approx(last["speed"] * last["yaw_rate"], rel=0.02)
