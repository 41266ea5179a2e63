"""Input contracts of the road-profile, route and GPX loaders: time order, unit strings, finiteness and names.
Each bad file is refused with a ProfileFileError naming the file, the field, the value and what is expected
(with its unit); the same file made good loads."""

import json

import numpy as np
import pytest

from roadload.road_profiles import DriveCycle, RoadProfile, load_profile
from roadload.road_profiles.files import ProfileFileError, load_gpx, load_profile_file, load_track_csv, save_profile

N = 60
LAT = 48.1 + np.arange(N) * 2e-4
LON = 11.5 + np.arange(N) * 1e-4


def track_csv(path, time=None, header="time,lat,lon,ele", ele=None):
    time = np.arange(N, dtype=float) if time is None else time
    ele = [f"{500 + 0.1 * i:g}" for i in range(N)] if ele is None else ele
    rows = [f"{a},{b:.6f},{c:.6f},{e}" for a, b, c, e in zip(time, LAT, LON, ele)]
    path.write_text(header + "\n" + "\n".join(rows) + "\n")
    return path


def gpx(path, seconds=None, ele=None):
    seconds = list(range(N)) if seconds is None else seconds
    ele = [500.0] * N if ele is None else ele
    clock = [300 + s for s in seconds]  # [s] after 10:00:00
    pts = "".join(f'<trkpt lat="{a:.6f}" lon="{b:.6f}"><ele>{e}</ele><time>2024-05-01T10:{c // 60:02d}:{c % 60:02d}Z'
                  f'</time></trkpt>' for a, b, c, e in zip(LAT, LON, clock, ele))
    path.write_text('<?xml version="1.0"?><gpx version="1.1" creator="t" xmlns="http://www.topografix.com/GPX/1/1">'
                    f"<trk><trkseg>{pts}</trkseg></trk></gpx>")
    return path


# ------------------------------------------------------------------------------------------------ time order
def test_track_csv_with_time_running_backwards_is_refused(tmp_path):
    t = np.arange(N, dtype=float)
    t[30] = 10.0
    with pytest.raises(ProfileFileError, match=r"column 'time' runs backwards at row 30: 10 s after 29 s \(at row "
                                               r"29\); expected time in driving order \[s\]"):
        load_track_csv(track_csv(tmp_path / "back.csv", t))
    # the same track in order loads, and a repeated time stamp (1 Hz logger, two rows) is not a step back
    t[30] = 29.0
    assert load_track_csv(track_csv(tmp_path / "ok.csv", t)).length > 1000.0


def test_track_csv_date_times_out_of_order_are_refused_and_in_order_load(tmp_path):
    stamps = [f"2024-05-01T10:00:{i:02d}Z" for i in range(N)]
    stamps[40], stamps[41] = stamps[41], stamps[40]
    with pytest.raises(ProfileFileError, match=r"column 'timestamp' runs backwards at row 41: 40 s after 41 s"):
        load_profile(track_csv(tmp_path / "dt.csv", stamps, header="timestamp,lat,lon,ele"))
    stamps[40], stamps[41] = stamps[41], stamps[40]
    assert load_profile(track_csv(tmp_path / "dt_ok.csv", stamps, header="timestamp,lat,lon,ele")).length > 1000.0
    stamps[7] = "yesterday-ish"
    with pytest.raises(ProfileFileError, match=r"column 'timestamp' has a value 'yesterday-ish' at row 7 that is "
                                               r"neither seconds nor a date-time"):
        load_track_csv(track_csv(tmp_path / "dt_bad.csv", stamps, header="timestamp,lat,lon,ele"))


def test_gpx_with_time_running_backwards_is_refused(tmp_path):
    seconds = list(range(N))
    seconds[20:] = [s - 30 for s in seconds[20:]]  # the second half logged before the first
    with pytest.raises(ProfileFileError, match=r"the point time runs backwards at point 20: -10 s after 19 s"):
        load_gpx(gpx(tmp_path / "back.gpx", seconds))
    assert load_gpx(gpx(tmp_path / "ok.gpx")).length > 1000.0


@pytest.mark.parametrize("suffix", [".json", ".csv"])
def test_drive_cycle_with_time_running_backwards_is_refused(tmp_path, suffix):
    path = save_profile(DriveCycle("c", time=[0.0, 1.0, 2.0, 3.0], speed=[0.0, 1.0, 2.0, 2.0]), tmp_path / f"c{suffix}")
    text = path.read_text().replace("3.0", "1.5") if suffix == ".json" else path.read_text().replace("\n3,", "\n1.5,")
    path.write_text(text)
    with pytest.raises(ProfileFileError, match=r"time runs backwards at sample 3: 1.5 s after 2 s"):
        load_profile_file(path)


# ------------------------------------------------------------------------------------------------ units
@pytest.fixture
def road_json(tmp_path):
    s = np.arange(0.0, 501.0, 10.0)
    z = np.zeros_like(s)
    path = save_profile(RoadProfile("r", s, z, z, z, np.full_like(s, 20.0)), tmp_path / "r.json")
    return path, json.loads(path.read_text())


@pytest.mark.parametrize("units,needle", [
    ({"speed_limit": "km/h"}, r"units.speed_limit \(JSON\) is 'km/h'; expected 'm/s'"),
    ({"grade": "%"}, r"units.grade \(JSON\) is '%'; expected 'rad'"),
    ({"distance": "ft"}, r"units.distance \(JSON\) is 'ft'; expected 'm'"),
    ({"speed": "m/s"}, r"units.speed \(JSON\): unknown field; the fields are \['bank', 'curvature'"),
    ("SI", r"'units' \(JSON\) must map field names to unit strings, got 'SI'"),
], ids=["km/h", "percent", "feet", "unknown", "not-a-map"])
def test_profile_json_with_other_units_is_refused(road_json, units, needle):
    path, doc = road_json
    doc["units"] = units if isinstance(units, str) else {**doc["units"], **units}
    path.write_text(json.dumps(doc))
    with pytest.raises(ProfileFileError, match=needle):
        load_profile_file(path)


def test_profile_csv_header_with_other_units_is_refused(tmp_path):
    path = save_profile(DriveCycle("c", time=[0.0, 1.0, 2.0], speed=[0.0, 1.0, 2.0]), tmp_path / "c.csv")
    path.write_text(path.read_text().replace('"speed": "m/s"', '"speed": "mph"'))
    with pytest.raises(ProfileFileError, match=r"units.speed \(header line\) is 'mph'; expected 'm/s'"):
        load_profile_file(path)


# ------------------------------------------------------------------------------------------------ finiteness
def test_infinite_values_are_refused_with_their_row(tmp_path):
    ele = ["500"] * N
    ele[5] = "inf"
    with pytest.raises(ProfileFileError, match=r"column 'ele' has a non-finite value inf at row 5; expected a finite "
                                               r"elevation \[m\]"):
        load_track_csv(track_csv(tmp_path / "inf.csv", ele=ele))
    ele[5] = ""  # an empty cell is a missing elevation: interpolated and counted, not refused
    prof = load_track_csv(track_csv(tmp_path / "gap.csv", ele=ele))
    assert prof.meta["repairs"]["elevation_missing_interpolated"] == 1
    with pytest.raises(ProfileFileError, match=r"point 3 has a non-finite elevation \[m\] inf"):
        load_gpx(gpx(tmp_path / "inf.gpx", ele=[500.0, 500.0, 500.0, float("inf")] + [500.0] * (N - 4)))


def test_heading_text_is_refused_not_interpolated(tmp_path):
    path = tmp_path / "hdg.csv"
    path.write_text("distance,hdg\n" + "\n".join(f"{10 * i},{'north' if i == 3 else 10}" for i in range(20)))
    with pytest.raises(ProfileFileError, match=r"column 'hdg' has a non-numeric value 'north' at row 3; expected "
                                               r"the heading"):
        load_track_csv(path, heading="hdg")


# ------------------------------------------------------------------------------------------------ names
@pytest.mark.parametrize("name", [5, "", " padded", None], ids=["number", "empty", "padded", "null"])
def test_profile_name_must_be_a_clean_string(road_json, name):
    path, doc = road_json
    doc["name"] = name
    path.write_text(json.dumps(doc))
    with pytest.raises(ProfileFileError, match=r"name must be a non-empty string without leading or trailing "
                                               rf"spaces, got {name!r}"):
        load_profile_file(path)


def test_two_columns_for_one_role_are_ambiguous(tmp_path):
    path = tmp_path / "two.csv"
    path.write_text("lat,latitude,lon\n" + "\n".join(f"{a:.6f},{a + 1:.6f},{b:.6f}" for a, b in zip(LAT, LON)))
    with pytest.raises(ProfileFileError, match=r"columns \['lat', 'latitude'\] all look like the latitude \[deg\]; "
                                               r"pass lat=<column name>"):
        load_track_csv(path)
    assert load_track_csv(path, lat="lat").length > 1000.0  # naming the column resolves it
