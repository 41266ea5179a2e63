"""Drive cycles against the regulation figures (shared data) and the distance-domain helpers (synthetic)."""

import numpy as np
import pytest

from roadload.road_profiles import (DriveCycle, cycle_position, cycle_stops, cycle_to_profile, ftp75,
                                    load_profile, speed_at_position)
from roadload.road_profiles import cycles as cycles_module

MILE = 1609.344


@pytest.mark.parametrize("name, duration, distance_km, tol_km, vmax_kmh", [
    ("wltc3", 1800, 23.266, 0.01, 131.3),   # GTR 15 class 3b: 23 266 m
    ("wltc3b", 1800, 23.266, 0.01, 131.3),
    ("wltc3a", 1800, 23.194, 0.01, 131.3),
    ("udds", 1369, 7.45 * MILE / 1000, 0.02, 91.2),  # 7.45 mi
    ("hwfet", 765, 10.26 * MILE / 1000, 0.02, 96.4),  # 10.26 mi
    ("us06", 600, 8.01 * MILE / 1000, 0.02, 129.2),   # 8.01 mi; EPA quotes 596 s of driving in the 600 s schedule
])
def test_standard_cycles_match_regulation(shared_data, name, duration, distance_km, tol_km, vmax_kmh):
    c = load_profile(name)
    assert isinstance(c, DriveCycle)
    assert c.duration == pytest.approx(duration)
    assert c.distance / 1000 == pytest.approx(distance_km, abs=tol_km)
    assert c.speed.max() * 3.6 == pytest.approx(vmax_kmh, abs=0.2)
    assert c.grade is None  # standard cycles are flat
    assert "Apache-2.0" in c.meta["licence"]


def test_wltc_phases_compose_the_cycle(shared_data):
    whole = load_profile("wltc3b")
    parts = [load_profile(n) for n in ("wltc3_low", "wltc3b_medium", "wltc3b_high", "wltc3_extrahigh")]
    assert sum(p.duration for p in parts) + 3 == pytest.approx(whole.duration)  # phases share their end seconds
    assert sum(p.distance for p in parts) == pytest.approx(whole.distance, rel=1e-3)


def test_ftp75_composed_from_udds(shared_data):
    udds = load_profile("udds")
    c = ftp75()
    assert c.duration == 1874.0  # regulation: 1874 s of driving
    assert c.distance / MILE == pytest.approx(11.04, abs=0.02)
    np.testing.assert_array_equal(c.speed[:1370], udds.speed)
    np.testing.assert_array_equal(c.speed[1370:], udds.speed[1:506])
    soaked = ftp75(include_soak=True)
    assert soaked.duration == 1874.0 + 600.0
    assert soaked.distance == pytest.approx(c.distance)
    lo, hi = soaked.meta["phases"]["soak"]
    assert np.all(soaked.speed[(soaked.time >= lo) & (soaked.time <= hi)] == 0)


def test_graded_real_cycles(shared_data):
    trip = load_profile("tsdc_300s")
    assert trip.duration == 300.0 and trip.grade is not None
    assert np.abs(trip.grade).max() < np.arctan(0.06) and np.abs(trip.grade).max() > np.arctan(0.03)
    truck = load_profile("longhaul_truck")
    assert truck.distance / 1000 == pytest.approx(805.0, abs=1.0)
    assert np.tan(truck.grade).min() == pytest.approx(-0.0232, abs=1e-3)
    assert np.tan(truck.grade).max() == pytest.approx(0.0290, abs=1e-3)
    road = cycle_to_profile(truck)
    assert road.length == pytest.approx(truck.distance, rel=1e-9)
    # the profile's elevation gain equals the cycle's: integral of sin(grade) ds
    s = cycle_position(truck)
    assert road.elevation()[-1] == pytest.approx(np.trapezoid(np.sin(truck.grade), s), abs=5.0)


def test_udds_in_distance_domain(shared_data):
    udds = load_profile("udds")
    stops = cycle_stops(udds)
    # UDDS: 17 standstills after the start, the last at the end of the cycle
    assert stops.size == 16 or stops.size == 17
    assert stops[-1] == pytest.approx(udds.distance, abs=1.0)
    np.testing.assert_allclose(speed_at_position(udds, stops), 0.0, atol=0.1)  # standstill: v < 0.1 m/s
    road = cycle_to_profile(udds)
    np.testing.assert_array_equal(road.stops, stops)


def test_distance_domain_helpers_on_a_synthetic_cycle():
    # accelerate 0 -> 10 m/s in 10 s, cruise 10 s, brake to 0 in 10 s, stand 5 s, go 2 m/s for 5 s
    t = np.arange(0.0, 41.0)
    v = np.interp(t, [0, 10, 20, 30, 35, 36, 40], [0, 10, 10, 0, 0, 2, 2])
    c = DriveCycle("synthetic", t, v)
    s = cycle_position(c)
    assert s[30] == pytest.approx(50 + 100 + 50)
    assert c.distance == pytest.approx(s[-1])
    assert speed_at_position(c, 25.0) == pytest.approx(np.sqrt(2 * 1.0 * 25.0), rel=0.02)  # v^2 = 2 a s
    assert speed_at_position(c, 100.0) == pytest.approx(10.0)
    np.testing.assert_allclose(cycle_stops(c), [200.0])
    road = cycle_to_profile(c, step=1.0)
    assert road.speed_limit.min() == pytest.approx(1.0)  # floored: a limit must be positive
    assert road.at(100.0)["speed_limit"] == pytest.approx(10.0)


def test_missing_shared_data_names_what_to_set(monkeypatch):
    monkeypatch.setattr(cycles_module, "shared_data_dir", lambda: None)
    with pytest.raises(FileNotFoundError, match="ROADLOAD_DATA"):
        load_profile("wltc3")
    with pytest.raises(FileNotFoundError, match="ROADLOAD_DATA"):
        load_profile("ftp75")
