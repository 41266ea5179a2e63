"""Real routes from the shared data: bus routes, race tracks, GradeIT GPS traces."""

import numpy as np
import pytest

from roadload.road_profiles import RoadProfile, load_profile, racetrack


def test_bus_route_constraints(shared_data):
    p = load_profile("bus_route91")
    assert isinstance(p, RoadProfile)
    assert p.length == pytest.approx(5970.7, abs=1.0)  # SOURCE.md: 5.97 km
    assert p.stops.size == 14 and p.stops[0] == 371.0 and p.stops[-1] == 5970.0
    assert len(p.meta["stop_dwell_s"]) == 14
    assert len(p.meta["traffic_lights"]) == 13
    assert p.meta["licence"] == "LGPL-3.0"
    assert p.speed_limit.max() == pytest.approx(50 / 3.6)
    # corner speed applied at each corner position
    for corner in p.meta["corners"]:
        assert p.at(corner["position_m"])["speed_limit"] == pytest.approx(corner["max_speed_mps"])
    measured = load_profile("bus_route91_measured")
    assert measured.distance == pytest.approx(p.length, rel=0.01)
    p185 = load_profile("bus_route185")
    assert p185.length == pytest.approx(15896.4, abs=1.0)
    assert p185.at(5000.0)["speed_limit"] == pytest.approx(60 / 3.6)  # posted 60 km/h from 4617 m


@pytest.mark.parametrize("track, official_km", [("Monza", 5.793), ("Spa", 7.004), ("Silverstone", 5.891)])
def test_racetrack_lap_closes(shared_data, track, official_km):
    p = racetrack(track)
    assert p.length / 1000 == pytest.approx(official_km, rel=0.02)
    # one closed lap turns by exactly one full revolution (not true for figure-eight Suzuka)
    assert abs(np.trapezoid(p.curvature, p.distance)) == pytest.approx(2 * np.pi, rel=0.01)
    # periodic: no start/finish artefact
    assert p.curvature[0] == pytest.approx(p.curvature[-1], abs=2e-3)
    with np.errstate(divide="ignore"):
        assert np.all(p.speed_limit <= np.sqrt(6.0 / np.abs(p.curvature)) + 1e-9)
    two = load_profile(f"racetrack_{track.lower()}", laps=2)
    assert two.length == pytest.approx(2 * p.length, rel=1e-3)


def test_gradeit_route(shared_data):
    p = load_profile("gradeit_sf_bridge")
    assert p.length / 1000 == pytest.approx(104.5, abs=0.5)  # SOURCE.md: 104.5 km
    assert np.all(p.grade == 0) and "no elevation" in p.meta["grade_meaning"]
    assert "BSD-3" in p.meta["licence"]
    # a road: mostly straight, radii of real curves not below a tight urban corner
    assert np.median(np.abs(p.curvature)) < 1 / 1000
    assert np.abs(p.curvature).max() < 1 / 8
    limits_kmh = np.round(p.speed_limit * 3.6, 6)
    assert np.all(limits_kmh % 10 == 0) and limits_kmh.min() >= 30
