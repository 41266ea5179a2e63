"""Track -> profile: smoothing, grade and curvature on analytic tracks, GPX/CSV loaders, repairs, clear errors."""

import numpy as np
import pytest

from roadload.road_profiles import (ProfileFileError, RoadProfileError, curvature_from_heading, curvature_from_xy,
                                    grade_from_elevation, haversine_distance, latlon_to_xy, load_gpx,
                                    load_profile, load_track_csv, profile_from_track, remove_spikes,
                                    smooth_over_distance)
from roadload.road_profiles.tracks import EARTH_RADIUS


def _circle_latlon(radius, lat0=48.0, lon0=11.0, n=720, turns=1.0):
    """Counter-clockwise circle of ``radius`` [m] as lat/lon [deg] on the spherical Earth."""
    phi = np.linspace(0.0, 2 * np.pi * turns, n)
    x, y = radius * np.cos(phi), radius * np.sin(phi)
    lat = lat0 + np.degrees(y / EARTH_RADIUS)
    lon = lon0 + np.degrees(x / (EARTH_RADIUS * np.cos(np.radians(lat0))))
    return lat, lon


def test_smoothing_keeps_linear_trend_at_the_ends_and_removes_noise():
    rng = np.random.default_rng(0)
    s = np.sort(rng.uniform(0, 2000, 800))
    s[0] = 0.0
    line = 3.0 + 0.05 * s
    np.testing.assert_allclose(smooth_over_distance(s, line, 150.0), line, atol=1e-9)
    noisy = line + rng.normal(0, 1.0, s.size)
    resid = smooth_over_distance(s, noisy, 150.0) - line
    assert resid.std() < 0.3  # ~1/sqrt(samples per window)


def test_grade_of_quantised_ramp():
    s = np.arange(0.0, 3000.0, 1.0)
    z = np.round(100.0 + 0.06 * s)  # elevation quantised to 1 m like the BMW i3 log
    theta = grade_from_elevation(s, z, window=150.0)
    interior = (s > 200) & (s < 2800)
    assert np.abs(np.tan(theta[interior]) - 0.06).max() < 0.003
    # without smoothing the quantisation gives absurd grades: the smoothing is what makes it usable
    raw = np.arctan(np.gradient(z, s))
    assert np.abs(np.tan(raw) - 0.06).max() > 0.4


def test_curvature_of_noisy_circle_and_clothoid():
    rng = np.random.default_rng(1)
    radius = 200.0
    s = np.arange(0.0, 2 * np.pi * radius, 2.0)
    x = radius * np.sin(s / radius) + rng.normal(0, 1.0, s.size)
    y = radius * (1 - np.cos(s / radius)) + rng.normal(0, 1.0, s.size)
    kappa = curvature_from_xy(s, x, y, window=60.0)
    assert np.median(kappa) == pytest.approx(1 / radius, rel=0.03)
    # clockwise: negative
    assert np.median(curvature_from_xy(s, x, -y, window=60.0)) == pytest.approx(-1 / radius, rel=0.03)
    # clothoid: heading s^2 / (2 A^2) -> curvature s / A^2, exact farther than the kernel (+-2 window) from the ends
    a2 = 300.0 ** 2
    s2 = np.linspace(0.0, 500.0, 501)
    k2 = curvature_from_heading(s2, s2 ** 2 / (2 * a2), window=40.0)
    np.testing.assert_allclose(k2[80:-80], s2[80:-80] / a2, atol=1e-9)
    np.testing.assert_allclose(k2, s2 / a2, atol=1e-4)  # end effect of a curvature ramp: < 2 % of its peak


def test_heading_wraps_are_unwrapped():
    s = np.linspace(0.0, 4 * np.pi * 100.0, 2000)
    wrapped = np.angle(np.exp(1j * s / 100.0))  # two full turns of R = 100 m, wrapped to (-pi, pi]
    kappa = curvature_from_heading(s, wrapped, window=30.0)
    np.testing.assert_allclose(kappa[50:-50], 0.01, rtol=1e-6)


def test_haversine_and_local_xy_agree_on_a_circle():
    lat, lon = _circle_latlon(500.0)
    s = haversine_distance(lat, lon)
    assert s[-1] == pytest.approx(2 * np.pi * 500.0, rel=1e-3)
    x, y = latlon_to_xy(lat, lon)
    assert np.hypot(x - x.mean(), y - y.mean()).mean() == pytest.approx(500.0, rel=1e-3)


def test_gpx_circle_with_ramp(tmp_path):
    import gpxpy.gpx

    radius, slope = 300.0, 0.04
    lat, lon = _circle_latlon(radius, n=400, turns=1.5)
    s = haversine_distance(lat, lon)
    gpx = gpxpy.gpx.GPX()
    track = gpxpy.gpx.GPXTrack(name="ring")
    seg = gpxpy.gpx.GPXTrackSegment()
    for la, lo, si in zip(lat, lon, s):
        seg.points.append(gpxpy.gpx.GPXTrackPoint(la, lo, elevation=200.0 + slope * si))
    track.segments.append(seg)
    gpx.tracks.append(track)
    path = tmp_path / "ring.gpx"
    path.write_text(gpx.to_xml())
    p = load_profile(path)
    assert p.name == "ring"
    assert p.length == pytest.approx(s[-1], rel=1e-6)
    assert np.diff(p.distance) == pytest.approx(np.full(p.distance.size - 1, 5.0), rel=0.01)
    interior = (p.distance > 100) & (p.distance < p.length - 100)
    np.testing.assert_allclose(p.curvature[interior], 1 / radius, rtol=0.03)
    np.testing.assert_allclose(np.tan(p.grade), slope, atol=0.002)
    assert p.meta["licence"] and p.meta["source"] == "ring.gpx"


def test_csv_track_latlon_aliases_and_explicit_columns(tmp_path):
    lat, lon = _circle_latlon(150.0, n=500)
    s = haversine_distance(lat, lon)
    path = tmp_path / "t.csv"
    path.write_text("Latitude,Longitude,Altitude\n" + "".join(f"{a:.9f},{b:.9f},{100 - 0.02 * c:.3f}\n"
                                                           for a, b, c in zip(lat, lon, s)))
    p = load_track_csv(path, licence="CC0")
    interior = (p.distance > 60) & (p.distance < p.length - 60)
    np.testing.assert_allclose(p.curvature[interior], 1 / 150.0, rtol=0.03)
    np.testing.assert_allclose(np.tan(p.grade), -0.02, atol=0.002)
    assert p.meta["licence"] == "CC0"
    path2 = tmp_path / "named.csv"
    path2.write_text("phi,lam,h\n" + "".join(f"{a:.9f},{b:.9f},{c * 0.01:.3f}\n" for a, b, c in zip(lat, lon, s)))
    q = load_profile(path2, lat="phi", lon="lam", elevation="h")
    np.testing.assert_allclose(np.tan(q.grade), 0.01, atol=0.002)


def test_csv_distance_elevation_and_compass_heading(tmp_path):
    s = np.arange(0.0, 1000.0, 2.0)
    course = np.degrees(s / 250.0)  # clockwise compass course turning right: R = 250 m
    path = tmp_path / "d.csv"
    path.write_text("distance,elevation,course\n" + "".join(f"{a},{0.03 * a},{c}\n" for a, c in zip(s, course)))
    p = load_track_csv(path, heading="course")
    interior = (p.distance > 60) & (p.distance < p.length - 60)
    np.testing.assert_allclose(p.curvature[interior], -1 / 250.0, rtol=0.02)
    np.testing.assert_allclose(np.tan(p.grade), 0.03, atol=1e-6)


def test_standstill_spikes_and_clipping_are_repaired_and_counted():
    s = np.concatenate([np.arange(0.0, 500.0, 1.0), np.full(30, 500.0), np.arange(500.0, 2000.0, 1.0)])
    z = 50.0 + 0.02 * s
    z[100] = -5400.0  # GNSS start-up glitch
    z[700:720] = np.nan
    z[1500:] += 30.0  # a 30 m step: absurd grade once differentiated with a short window
    p = profile_from_track(s, elevation=z, elevation_window=20.0, max_grade=0.2)
    rep = p.meta["repairs"]
    assert rep["samples_dropped_too_close"] == 30
    assert rep["elevation_spikes_replaced"] == 1
    assert rep["elevation_missing_interpolated"] == 20
    assert rep["grade_clipped"] > 0
    assert np.abs(np.tan(p.grade)).max() <= 0.2 + 1e-12
    assert np.tan(p.grade[(p.distance > 20) & (p.distance < 400)]) == pytest.approx(0.02, abs=1e-6)


def test_remove_spikes_leaves_clean_data_alone():
    s = np.linspace(0, 1000, 201)
    z = 10 * np.sin(s / 100)
    cleaned, n = remove_spikes(s, z, threshold=5.0)
    assert n == 0 and np.array_equal(cleaned, z)


def test_profile_from_track_speed_limit_in_curves():
    s = np.linspace(0.0, 1000.0, 1001)
    psi = np.where(s < 500, 0.0, (s - 500) / 50.0)  # straight, then R = 50 m
    p = profile_from_track(s, heading=psi, default_speed_limit=25.0, curve_lateral_acceleration=2.0,
                           heading_window=10.0)
    assert p.at(200.0)["speed_limit"] == pytest.approx(25.0)
    assert p.at(800.0)["speed_limit"] == pytest.approx(np.sqrt(2.0 * 50.0), rel=0.01)


@pytest.mark.parametrize("kw, match", [
    ({"distance": [0.0, 5.0, 3.0]}, "decreases at index 2"),
    ({"distance": [0.0, np.nan, 3.0]}, "distance: 1 NaN"),
    ({"distance": [0.0, 1.0, 2.0], "elevation": [1.0, 2.0]}, "elevation: expected 3"),
    ({"elevation": [1.0, 2.0]}, "distance: required"),
    ({"distance": [0.0, 0.1, 0.2]}, "shorter than"),
])
def test_profile_from_track_errors(kw, match):
    with pytest.raises(RoadProfileError, match=match):
        profile_from_track(**kw)


def test_malformed_track_files(tmp_path):
    bad_gpx = tmp_path / "bad.gpx"
    bad_gpx.write_text("<gpx><trk><trkseg><trkpt lat='1' lon=")
    with pytest.raises(ProfileFileError, match="bad.gpx"):
        load_gpx(bad_gpx)
    one = tmp_path / "one.gpx"
    one.write_text('<?xml version="1.0"?><gpx version="1.1" creator="t" xmlns="http://www.topografix.com/GPX/1/1">'
                   '<trk><trkseg><trkpt lat="48.0" lon="11.0"/></trkseg></trk></gpx>')
    with pytest.raises(ProfileFileError, match="fewer than 2"):
        load_gpx(one)
    nocols = tmp_path / "nocols.csv"
    nocols.write_text("a,b\n1,2\n3,4\n")
    with pytest.raises(ProfileFileError, match=r"needs lat/lon or a distance column; columns are \['a', 'b'\]"):
        load_profile(nocols)
    text = tmp_path / "text.csv"
    text.write_text("distance,elevation\n0,1\n5,abc\n10,3\n")
    with pytest.raises(ProfileFileError,
                       match=r"'elevation' has a non-numeric value 'abc' at row 1; expected the elevation \[m\]"):
        load_track_csv(text)
    with pytest.raises(ProfileFileError, match="no column 'height'"):
        load_track_csv(text, elevation="height")
    swapped = tmp_path / "swapped.csv"
    swapped.write_text("lat,lon\n11,480\n11.1,480.1\n")
    with pytest.raises(ProfileFileError, match="out of range"):
        load_track_csv(swapped)


def test_gpx_route_without_elevation_gives_flat_profile(tmp_path):
    lat, lon = _circle_latlon(400.0, n=200, turns=0.5)
    pts = "".join(f'<rtept lat="{a:.9f}" lon="{b:.9f}"/>' for a, b in zip(lat, lon))
    path = tmp_path / "route.gpx"
    path.write_text('<?xml version="1.0"?><gpx version="1.1" creator="t" xmlns="http://www.topografix.com/GPX/1/1">'
                    f"<rte>{pts}</rte></gpx>")
    p = load_gpx(path, step=2.0)
    assert np.all(p.grade == 0) and not p.meta["processing"]["has_elevation"]
    interior = (p.distance > 80) & (p.distance < p.length - 80)
    np.testing.assert_allclose(p.curvature[interior], 1 / 400.0, rtol=0.03)
    assert p.length == pytest.approx(np.pi * 400.0, rel=1e-3)


def test_heading_gap_across_the_wrap_is_not_a_turn():
    s = np.linspace(0.0, 1000.0, 501)
    psi = np.angle(np.exp(1j * (np.pi - 0.05 + s / 5000.0)))  # R = 5 km, crosses +-pi near the middle
    psi[240:260] = np.nan  # GNSS heading missing right at the wrap
    p = profile_from_track(s, heading=psi)
    assert p.meta["repairs"]["heading_missing_interpolated"] == 20
    np.testing.assert_allclose(p.curvature, 1 / 5000.0, atol=2e-5)
