"""The sensor model on a synthetic truth log (no simulation): each channel's physical relation, latency,
decimation, bias, seeded noise, quantisation, outliers and dropouts give exactly the values the model promises,
and the step API's ``sample`` equals the whole-trip ``measure`` row for row."""

import numpy as np
import pytest

from roadload.envs.effects import EffectsConfig
from roadload.envs import TRUTH_LOG_COLUMNS
from roadload.envs.sensors import CHUNK, SensorConfigError, SensorModel
from roadload.presets import get_preset
from roadload.vehicle import ChannelSensorSpec, SensorSpec

# truth-log rows by name (the log is private to envs/; its column names are public)
_ROW = {name: row for row, name in enumerate(TRUTH_LOG_COLUMNS)}
L_ACC_X_SENS, L_CLUTCH, L_DELTA, L_GEAR, L_PBF, L_T, L_TE, L_V, L_WE, L_WFL, L_YAW = (
    _ROW[n] for n in ("ACC_X_SENS", "CLUTCH", "DELTA", "GEAR", "PBF", "T", "TE", "V", "WE", "WFL", "YAW"))
N_LOG = len(TRUTH_LOG_COLUMNS)

BEV = get_preset("bmw_i3")
ICE = get_preset("gt_rwd")


def _log(n: int) -> np.ndarray:
    """Column-major truth log: substep k at t = k dt, each used row a distinct smooth signal."""
    k = np.arange(n, dtype=float)
    log = np.zeros((N_LOG, n))
    log[L_T] = k * 0.01
    for row in range(1, N_LOG):
        log[row] = 10.0 * row + np.sin(k / (50.0 + row))
    log[L_DELTA] = 0.2 * np.sin(k / 300.0)             # wheel steer angle inside the steering table
    log[L_GEAR] = 1 + (k // 7) % 5                      # gears 1..5
    log[L_CLUTCH] = np.where((k // 11) % 3 == 0, 0.0, 2.0)  # open a third of the time
    return log


def _model(channels: dict, effects=None, vehicle=BEV, seed: int = 3, **spec) -> SensorModel:
    sensors = SensorSpec(channels={n: ChannelSensorSpec(**c) for n, c in channels.items()}, **spec)
    return SensorModel(vehicle, sensors, EffectsConfig(effects or {}), seed)


def _exact(**extra) -> dict:
    """A channel spec with no noise, bias, resolution or latency (plus the given overrides)."""
    return {"noise_std": 0.0, "resolution": 0.0, "latency": 0.0, **extra}


def _runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """(start, length) of the True runs of a boolean array."""
    d = np.diff(np.concatenate([[0], mask.astype(int), [0]]))
    starts, ends = np.flatnonzero(d == 1), np.flatnonzero(d == -1)
    return list(zip(starts.tolist(), (ends - starts).tolist()))


# ------------------------------------------------------------------------------------------ physical relations
def test_noise_free_readings_are_the_channel_relations():
    m = _model({"vehicle_speed": _exact(), "steering_wheel_angle": _exact(), "drive_torque": _exact(),
                "gear": _exact(), "wheel_speed_fl": _exact(), "accel_x": _exact(bias=0.5),
                "engine_speed": _exact(enabled=False)},
               speed_scale_error=0.01, drive_torque_gain_error=0.05, drive_torque_offset=3.0)
    assert m.names == ["vehicle_speed", "steering_wheel_angle", "drive_torque", "gear", "wheel_speed_fl", "accel_x"]
    assert m.units == {"vehicle_speed": "m/s", "steering_wheel_angle": "rad", "drive_torque": "N*m", "gear": "1",
                       "wheel_speed_fl": "rad/s", "accel_x": "m/s^2"}
    log = _log(500)
    t, out, keep = m.measure(log, 500)
    np.testing.assert_array_equal(t, log[L_T])
    assert keep.all() and keep.size == 500
    np.testing.assert_array_equal(out["vehicle_speed"], log[L_V] * 1.01)
    np.testing.assert_array_equal(out["drive_torque"], log[L_TE] * 1.05 + 3.0)
    np.testing.assert_array_equal(out["gear"], np.where(log[L_CLUTCH] > 0, log[L_GEAR], 0.0))
    np.testing.assert_array_equal(out["wheel_speed_fl"], log[L_WFL])
    np.testing.assert_array_equal(out["accel_x"], log[L_ACC_X_SENS] + 0.5)
    st = BEV.steering  # the steering table maps wheel angle -> steering-wheel angle, linearly in between
    np.testing.assert_allclose(out["steering_wheel_angle"],
                               np.interp(log[L_DELTA], st.wheel_angle, st.steering_wheel_angle), rtol=0, atol=0)
    assert out["steering_wheel_angle"][0] == 0.0
    assert np.max(np.abs(out["steering_wheel_angle"])) > 10 * 0.2  # the steering ratio is ~14, not 1
    for n in (1, 2, 77, 500):  # the step API gives the same row
        row = m.sample(log, n)
        assert row["t"] == t[n - 1] and row["valid"] is True
        assert {k: row[k] for k in m.names} == {k: out[k][n - 1] for k in m.names}
    assert m.sample(log, 0) is None


def test_torque_model_error_replaces_the_spec_gain_and_offset():
    m = _model({"drive_torque": _exact()}, {"torque_model_error": {"gain_error": -0.1, "offset": 7.0}},
               drive_torque_gain_error=0.05, drive_torque_offset=3.0)
    log = _log(50)
    np.testing.assert_array_equal(m.measure(log, 50)[1]["drive_torque"], log[L_TE] * 0.9 + 7.0)
    assert m.sample(log, 50)["drive_torque"] == log[L_TE, 49] * 0.9 + 7.0


# ------------------------------------------------------------------------------------------ decimation, latency
def test_decimation_takes_the_last_substep_of_each_sample_period():
    m = _model({"yaw_rate": _exact()}, sample_rate=50.0)
    assert m.decimation == 2
    log = _log(101)
    t, out, _ = m.measure(log, 101)
    np.testing.assert_array_equal(t, log[L_T, 1:101:2])  # substeps 1, 3, ..., 99
    np.testing.assert_array_equal(out["yaw_rate"], log[L_YAW, 1:101:2])
    assert m.sample(log, 1) is None
    assert m.sample(log, 2)["t"] == log[L_T, 1] and m.sample(log, 3)["t"] == log[L_T, 1]
    assert m.sample(log, 101)["yaw_rate"] == out["yaw_rate"][-1]
    t2, out2, _ = m.measure(log, 101, start=40)  # samples from substep 41 on
    np.testing.assert_array_equal(t2, log[L_T, 41:101:2])
    t3, _, _ = m.measure(log, 101, start=41)
    np.testing.assert_array_equal(t3, log[L_T, 41:101:2])


@pytest.mark.parametrize("rate, message", [
    (30.0, "sensors.sample_rate: 30.0 Hz must divide the simulation rate 100 Hz"),
    (200.0, "sensors.sample_rate: 200.0 Hz must divide"),
])
def test_a_sample_rate_that_does_not_divide_the_simulation_rate_is_refused(rate, message):
    with pytest.raises(SensorConfigError, match=message):
        _model({"yaw_rate": _exact()}, sample_rate=rate)
    assert _model({"yaw_rate": _exact()}, sample_rate=100.0).decimation == 1


def test_latency_shifts_each_channel_by_its_own_substeps():
    m = _model({"vehicle_speed": _exact(latency=0.03), "yaw_rate": _exact(latency=0.0)},
               {"sensor_latency": {"extra": 0.02}})
    np.testing.assert_array_equal(m.delay, [5, 2])
    assert m.max_delay == 5
    log = _log(300)
    t, out, _ = m.measure(log, 300)
    src = np.maximum(np.arange(300) - 5, 0)
    np.testing.assert_array_equal(out["vehicle_speed"], log[L_V, src])
    np.testing.assert_array_equal(out["yaw_rate"], log[L_YAW, np.maximum(np.arange(300) - 2, 0)])
    row = m.sample(log, 300)
    assert row["vehicle_speed"] == log[L_V, 294] and row["yaw_rate"] == log[L_YAW, 297]
    # a window of the log that still reaches back max_delay substeps gives the same rows
    tw, ow, _ = m.measure(log[:, 195:], 300, start=200, offset=195)
    np.testing.assert_array_equal(tw, t[200:])
    np.testing.assert_array_equal(ow["vehicle_speed"], out["vehicle_speed"][200:])
    with pytest.raises(ValueError, match=r"channel 'vehicle_speed' needs substep 195, the log starts at 196"):
        m.measure(log[:, 196:], 300, start=200, offset=196)
    assert _model({"yaw_rate": _exact()}).max_delay == 0


# ------------------------------------------------------------------------------------------ bias, noise, quantisation
def test_random_bias_is_seeded_scaled_and_only_on_channels_with_a_reference():
    ch = {"accel_x": _exact(bias=0.1), "yaw_rate": _exact(), "engine_speed": _exact(bias=2.0)}
    one = _model(ch, {"sensor_bias": {"scale": 1.0}}, seed=11).bias
    two = _model(ch, {"sensor_bias": {"scale": 2.0}}, seed=11).bias
    np.testing.assert_array_equal(_model(ch, seed=11).bias, [0.1, 0.0, 2.0])
    np.testing.assert_allclose(two - [0.1, 0.0, 2.0], 2.0 * (one - [0.1, 0.0, 2.0]), rtol=1e-12, atol=1e-15)
    assert one[2] == 2.0  # engine_speed has no reference bias
    assert one[0] != 0.1 and one[1] != 0.0
    # seeded: the same seed gives the same biases; another seed others
    np.testing.assert_array_equal(_model(ch, {"sensor_bias": {}}, seed=11).bias, one)
    assert not np.array_equal(_model(ch, {"sensor_bias": {}}, seed=12).bias, one)
    # drawn from N(0, b_ref^2): over many seeds the spread is the reference (0.05 m/s^2, 0.002 rad/s)
    draws = np.array([_model(ch, {"sensor_bias": {}}, seed=s).bias for s in range(400)])
    assert np.std(draws[:, 0]) == pytest.approx(0.05, rel=0.15)
    assert np.mean(draws[:, 0]) == pytest.approx(0.1, abs=0.015)
    assert np.std(draws[:, 1]) == pytest.approx(0.002, rel=0.15)
    # and it is added to the readings
    log = _log(20)
    assert _model(ch, {"sensor_bias": {}}, seed=11).measure(log, 20)[1]["yaw_rate"][4] == log[L_YAW, 4] + one[1]


def test_noise_has_each_channels_spread_and_is_independent_between_channels_and_chunks():
    names = ["wheel_speed_fl", "accel_x", "yaw_rate", "drive_torque", "brake_pressure_front"]
    sigma = [0.03, 0.08, 0.003, 2.0, 2000.0]
    m = _model({n: _exact(noise_std=s) for n, s in zip(names, sigma)})
    n = 2 * CHUNK
    log = np.zeros((N_LOG, n))
    log[L_T] = np.arange(n) * 0.01
    _, out, _ = m.measure(log, n)
    e = np.array([out[k] for k in names])
    np.testing.assert_allclose(e.std(axis=1), sigma, rtol=0.05)
    np.testing.assert_allclose(e.mean(axis=1) / sigma, 0.0, atol=0.05)
    rho = np.corrcoef(e)
    assert np.abs(rho[~np.eye(len(names), dtype=bool)]).max() < 0.06  # shared sequences give 1
    first, second = e[:, :CHUNK] / np.array(sigma)[:, None], e[:, CHUNK:] / np.array(sigma)[:, None]
    assert max(abs(np.corrcoef(a, b)[0, 1]) for a, b in zip(first, second)) < 0.06  # chunks do not repeat
    # seeded: the same seed gives the same noise; another seed other noise
    again = _model({k: _exact(noise_std=s) for k, s in zip(names, sigma)}).measure(log, n)[1]
    np.testing.assert_array_equal(again["accel_x"], out["accel_x"])
    other = _model({k: _exact(noise_std=s) for k, s in zip(names, sigma)}, seed=4).measure(log, 200)[1]
    assert abs(np.corrcoef(other["accel_x"], out["accel_x"][:200])[0, 1]) < 0.3
    # a noise-free channel reads exactly its bias
    quiet = _model({"accel_x": _exact(bias=0.25)}).measure(log, 100)[1]["accel_x"]
    np.testing.assert_array_equal(quiet, np.full(100, 0.25))


def test_quantisation_rounds_to_the_channel_resolution():
    m = _model({"vehicle_speed": _exact(resolution=0.01, noise_std=0.02), "brake_pressure_front":
                _exact(resolution=10000.0, noise_std=2000.0), "yaw_rate": _exact(noise_std=0.003)})
    log = _log(400)
    _, out, _ = m.measure(log, 400)
    for name, res in (("vehicle_speed", 0.01), ("brake_pressure_front", 10000.0)):
        k = out[name] / res
        np.testing.assert_allclose(k, np.round(k), rtol=0, atol=1e-6)
        assert np.max(np.abs(out[name] - log[L_V if name == "vehicle_speed" else L_PBF])) < 5 * (
            0.02 if res == 0.01 else 2000.0) + res
    k = out["yaw_rate"] / 0.001
    assert np.max(np.abs(k - np.round(k))) > 0.1  # resolution 0: not quantised
    row = m.sample(log, 400)
    assert [row[n] for n in m.names] == [out[n][-1] for n in m.names]


# ------------------------------------------------------------------------------------------ outliers
def _zero_log(n: int) -> np.ndarray:
    log = np.zeros((N_LOG, n))
    log[L_T] = np.arange(n) * 0.01
    log[L_CLUTCH] = 2.0
    return log


def test_isolated_outliers_have_the_rate_size_and_channels_asked_for():
    chans = {"accel_x": _exact(outlier_scale=2.0), "yaw_rate": _exact(outlier_scale=0.1),
             "drive_torque": _exact(outlier_scale=80.0), "gear": _exact()}
    n = 3 * CHUNK
    log = _zero_log(n)
    m = _model(chans, {"sensor_outliers": {"rate": 0.01, "magnitude": 3.0, "channels": "inputs"}})
    _, out, _ = m.measure(log, n)
    assert not out["drive_torque"].any() and not out["gear"].any()  # outputs and discrete channels untouched
    for name, scale in (("accel_x", 2.0), ("yaw_rate", 0.1)):
        hit = out[name][out[name] != 0]
        assert hit.size == pytest.approx(0.01 * n, abs=5 * np.sqrt(0.01 * n))
        assert np.abs(hit).min() >= 3.0 * scale
        assert np.mean(np.abs(hit)) == pytest.approx(3.0 * scale * (1 + np.sqrt(2 / np.pi)), rel=0.1)
        assert np.mean(hit > 0) == pytest.approx(0.5, abs=0.08)
    assert not np.array_equal(out["accel_x"] != 0, out["yaw_rate"] != 0)  # each channel its own draws
    # the step API gives the same outliers
    for k in np.flatnonzero(out["accel_x"])[:5] + 1:
        assert m.sample(log, int(k))["accel_x"] == out["accel_x"][k - 1]
    outputs = _model(chans, {"sensor_outliers": {"rate": 0.01, "channels": "outputs"}}).measure(log, n)[1]
    assert outputs["drive_torque"].any() and not outputs["accel_x"].any() and not outputs["yaw_rate"].any()
    everything = _model(chans, {"sensor_outliers": {"rate": 0.01, "channels": "all"}}).measure(log, n)[1]
    assert everything["drive_torque"].any() and everything["accel_x"].any() and not everything["gear"].any()


def test_outlier_bursts_are_whole_bursts_of_one_sign_also_across_chunks():
    m = _model({"accel_x": _exact(outlier_scale=2.0), "yaw_rate": _exact(outlier_scale=0.1)},
               {"sensor_outliers": {"rate": 0.02, "burst_length": 20, "channel": "accel_x"}})
    n = 4 * CHUNK
    log = _zero_log(n)
    _, out, _ = m.measure(log, n)
    assert not out["yaw_rate"].any()
    x = out["accel_x"]
    bursts = [b for c in range(4) for b in m._outlier_bursts(0, c)]
    assert len(bursts) == pytest.approx(0.02 * n, abs=5 * np.sqrt(0.02 * n))
    expected = np.zeros(n)
    for start, sign, mags in bursts:
        assert mags.shape == (20,) and sign in (-1.0, 1.0) and mags.min() >= 2.0
        expected[start:start + 20] += sign * mags[:max(0, min(20, n - start))]
    np.testing.assert_allclose(x, expected, rtol=0, atol=1e-12)
    # the test's seed has bursts over a chunk boundary: they continue into the next chunk
    assert any(s < kk * CHUNK < s + 20 for s, _, _ in bursts for kk in (1, 2, 3))
    for kk in (CHUNK + 3, 2 * CHUNK + 5, n):
        assert m.sample(log, kk)["accel_x"] == x[kk - 1]


def test_bad_outlier_settings_are_refused_with_the_reason():
    chans = {"accel_x": _exact(), "yaw_rate": _exact()}
    with pytest.raises(SensorConfigError, match=r"'burst_length': must be a whole number of samples, got 2.5"):
        _model(chans, {"sensor_outliers": {"burst_length": 2.5}})
    with pytest.raises(SensorConfigError, match=r"effect 'sensor_outliers' parameter 'channel': unknown or disabled "
                                                r"channel\(s\) \['pitch_rate'\]; enabled channels: \['accel_x', "
                                                r"'yaw_rate'\]"):
        _model(chans, {"sensor_outliers": {"channel": "accel_x+pitch_rate"}})
    with pytest.raises(SensorConfigError, match=r"unknown or disabled channel\(s\) \['\+'\]"):
        _model(chans, {"sensor_outliers": {"channel": "+"}})
    both = _model(chans, {"sensor_outliers": {"channel": " accel_x + yaw_rate "}})
    np.testing.assert_array_equal(both.outlier_on, [True, True])


# ------------------------------------------------------------------------------------------ dropouts
def test_dropouts_are_the_drawn_events_with_the_asked_rate_and_length():
    m = _model({"accel_x": _exact(), "yaw_rate": _exact(), "gear": _exact()},
               {"sensor_dropouts": {"rate": 720.0, "mean_duration": 0.5}})
    chunks = 6
    n = chunks * CHUNK
    log = _zero_log(n)
    _, out, keep = m.measure(log, n)
    assert keep.all()
    events = [e for c in range(chunks) for e in m._dropout_runs(c)]
    hours = n * 0.01 / 3600.0
    assert len(events) == pytest.approx(720.0 * hours, abs=5 * np.sqrt(720.0 * hours))
    assert np.mean([ln for _, ln in events]) == pytest.approx(50.5, rel=0.25)  # ceil(Exp(0.5 s / 10 ms))
    expected = np.zeros(n, dtype=bool)
    for start, length in events:
        assert start // CHUNK < chunks and 1 <= length <= CHUNK
        expected[start:start + length] = True
    assert any(s < k * CHUNK < s + ln for s, ln in events for k in range(1, chunks))  # one crosses a boundary
    for name in ("accel_x", "yaw_rate"):  # every continuous channel (channels 'all'), exactly the events' samples
        np.testing.assert_array_equal(np.isnan(out[name]), expected)
    assert not np.isnan(out["gear"]).any()  # the discrete channels are not in 'all'
    for k in np.flatnonzero(expected)[::97] + 1:
        row = m.sample(log, int(k))
        assert np.isnan(row["accel_x"]) and np.isnan(row["yaw_rate"]) and row["gear"] == 0.0
        assert row["valid"] is True
    assert m.sample(log, int(np.flatnonzero(~expected)[-1]) + 1)["accel_x"] == 0.0


def test_dropouts_on_one_channel_and_missing_samples():
    chans = {"accel_x": _exact(), "yaw_rate": _exact(), "drive_torque": _exact()}
    n = 2 * CHUNK
    log = _zero_log(n)
    one = _model(chans, {"sensor_dropouts": {"rate": 3600.0, "channel": "yaw_rate"}})
    out = one.measure(log, n)[1]
    assert np.isnan(out["yaw_rate"]).sum() > 0.1 * n
    assert not np.isnan(out["accel_x"]).any() and not np.isnan(out["drive_torque"]).any()
    outputs = _model(chans, {"sensor_dropouts": {"rate": 3600.0, "channels": "outputs"}}).measure(log, n)[1]
    assert np.isnan(outputs["drive_torque"]).any() and not np.isnan(outputs["yaw_rate"]).any()
    missing = _model(chans, {"sensor_dropouts": {"rate": 3600.0, "mode": "missing"}})
    _, vals, keep = missing.measure(log, n)
    nan_mode = _model(chans, {"sensor_dropouts": {"rate": 3600.0}}).measure(log, n)[1]
    np.testing.assert_array_equal(~keep, np.isnan(nan_mode["accel_x"]))  # the same events remove whole rows
    assert 0.1 * n < (~keep).sum() < 0.9 * n
    assert not np.isnan(vals["accel_x"]).any()
    gone = int(np.flatnonzero(~keep)[0]) + 1
    row = missing.sample(log, gone)
    assert row["valid"] is False and all(np.isnan(row[k]) for k in chans)
    kept = int(np.flatnonzero(keep)[-1]) + 1
    assert missing.sample(log, kept)["valid"] is True and missing.sample(log, kept)["accel_x"] == 0.0
    with pytest.raises(SensorConfigError, match=r"'sensor_dropouts': parameter 'channel' needs mode 'nan'"):
        _model(chans, {"sensor_dropouts": {"mode": "missing", "channel": "yaw_rate"}})


# ------------------------------------------------------------------------------------------ the whole model
def test_step_api_window_and_whole_trip_agree_with_every_effect_on():
    chans = {n: c for n, c in BEV.sensors.channels.items()}
    m = SensorModel(BEV, BEV.sensors, EffectsConfig({"sensor_outliers": {"rate": 0.01, "burst_length": 3},
                                                     "sensor_dropouts": {"rate": 600.0}, "sensor_bias": {},
                                                     "sensor_latency": {"extra": 0.01}}), 9)
    assert m.names == list(chans)
    n = CHUNK + 500
    log = _log(n)
    t, out, _ = m.measure(log, n)
    for k in (1, 2, CHUNK - 1, CHUNK, CHUNK + 1, n):
        row = m.sample(log, k)
        got = np.array([row[c] for c in m.names])
        want = np.array([out[c][k - 1] for c in m.names])
        np.testing.assert_array_equal(got, want)
    start = CHUNK - 40
    off = start - m.max_delay
    tw, ow, _ = m.measure(log[:, off:], n, start=start, offset=off)
    np.testing.assert_array_equal(tw, t[start:])
    for c in m.names:
        np.testing.assert_array_equal(ow[c], out[c][start:])
    assert len(m._cache) <= 2  # a bounded cache of perturbation chunks, whatever the trip length


def test_channels_the_simulator_cannot_produce_are_refused():
    with pytest.raises(SensorConfigError, match=r"sensors.channels.gnss_speed: the simulator does not produce this "
                                                r"channel; supported: \["):
        _model({"gnss_speed": _exact()})
    with pytest.raises(SensorConfigError, match=r"sensors.channels.battery_current: only a 'bev' drive-train has"):
        _model({"battery_current": _exact()}, vehicle=ICE)
    assert _model({"battery_current": _exact(), "battery_voltage": _exact()}).names == ["battery_current",
                                                                                       "battery_voltage"]
    _model({"engine_speed": _exact(), "gear": _exact()}, vehicle=ICE)  # the ICE channels are fine
    assert _model({"engine_speed": _exact()}, vehicle=ICE).measure(_log(3), 3)[1]["engine_speed"][2] == _log(3)[
        L_WE, 2]


def test_seeded_draws_are_the_same_in_every_version():
    """The perturbations of seed 3 are pinned: a stored trip or a published figure reproduces only while the random
    streams keep their keys (seed, feature, channel, chunk) and their order of draws."""
    m = _model({"accel_x": _exact(noise_std=0.08), "yaw_rate": _exact(outlier_scale=0.1)},
               {"sensor_outliers": {"rate": 0.01, "magnitude": 3.0, "burst_length": 4},
                "sensor_dropouts": {"rate": 720.0}, "sensor_bias": {}})
    np.testing.assert_allclose(m.bias, [-0.01683229201500271, 0.00271853590532371], rtol=1e-12)
    np.testing.assert_allclose(m._chunk(0)[0][0, :3],  # bias + noise
                               [-0.01542800373744787, -0.05763584706924187, -0.16477908007229558], rtol=1e-12)
    bursts = m._outlier_bursts(1, 0)
    assert [(s, sg) for s, sg, _ in bursts[:2]] == [(116, 1.0), (161, 1.0)]
    np.testing.assert_allclose(bursts[0][2], [0.7181451116713385, 0.4477322009987548, 0.5754888229794489,
                                              0.5073200154377321], rtol=1e-12)
    runs = m._dropout_runs(0)
    assert len(runs) == 10 and runs[:3] == [(5209, 21), (8184, 28), (1257, 25)]


def test_burst_signs_are_balanced_and_sizes_are_one_plus_a_half_normal():
    m = _model({"accel_x": _exact(outlier_scale=2.0)}, {"sensor_outliers": {"rate": 0.02, "burst_length": 5}})
    bursts = [b for c in range(4) for b in m._outlier_bursts(0, c)]
    signs = np.array([sg for _, sg, _ in bursts])
    assert np.mean(signs > 0) == pytest.approx(0.5, abs=0.06)
    mags = np.concatenate([mg for _, _, mg in bursts])
    assert mags.min() >= 2.0 and np.mean(mags) == pytest.approx(2.0 * (1 + np.sqrt(2 / np.pi)), rel=0.05)


def test_dropout_rate_and_length_are_per_second_at_a_decimated_rate():
    m = _model({"accel_x": _exact()}, {"sensor_dropouts": {"rate": 720.0, "mean_duration": 0.5}}, sample_rate=50.0)
    events = [e for c in range(6) for e in m._dropout_runs(c)]
    hours = 6 * CHUNK * 0.02 / 3600.0  # samples of 20 ms
    assert len(events) == pytest.approx(720.0 * hours, abs=5 * np.sqrt(720.0 * hours))
    assert np.mean([ln for _, ln in events]) == pytest.approx(25.5, rel=0.25)  # ceil(Exp(0.5 s / 20 ms))
    starts = np.array([s % CHUNK for s, _ in events])
    assert starts.min() < 0.05 * CHUNK and starts.max() > 0.95 * CHUNK  # anywhere in the chunk


def test_gear_reads_zero_only_while_the_clutch_is_open():
    m = _model({"gear": _exact(), "clutch": _exact()})
    log = _log(30)
    log[L_CLUTCH] = np.arange(30) % 3  # open, slipping, locked
    _, out, _ = m.measure(log, 30)
    np.testing.assert_array_equal(out["gear"], np.where(np.arange(30) % 3 > 0, log[L_GEAR], 0.0))
    assert [m.sample(log, k)["gear"] for k in (1, 2, 3)] == [0.0, log[L_GEAR, 1], log[L_GEAR, 2]]


def test_perturbation_chunks_are_cached_for_the_step_api_and_the_cache_keeps_the_latest_two():
    m = _model({"accel_x": _exact(noise_std=0.1)})
    log = np.zeros((N_LOG, 6 * CHUNK))
    log[L_T] = np.arange(6 * CHUNK) * 0.01
    first = m._chunk(0)
    assert m._chunk(0) is first  # a step within a chunk reuses its draws
    m.measure(log, 6 * CHUNK)
    assert sorted(m._cache) == [4, 5]  # the last two: a streamed window's end is the next one's start
    assert m.sample(log, 5 * CHUNK + 7)["accel_x"] == m._cache[5][0][0, 6]


def test_no_enabled_channel_measures_time_only_and_bad_dropout_settings_are_named():
    m = _model({"accel_x": _exact(enabled=False)}, {"sensor_dropouts": {"rate": 3600.0},
                                                    "sensor_outliers": {"rate": 0.1}})
    t, out, keep = m.measure(_log(100), 100)
    assert out == {} and t.size == 100 and keep.all() and m.units == {}
    with pytest.raises(SensorConfigError, match=r"^effect 'sensor_dropouts' parameter 'channel': unknown or disabled "
                                                r"channel\(s\) \['pitch'\]; enabled channels: \['accel_x'\]$"):
        _model({"accel_x": _exact()}, {"sensor_dropouts": {"channel": "pitch"}})
    with pytest.raises(SensorConfigError, match=r"^effect 'sensor_dropouts': parameter 'channel' needs mode 'nan' "
                                                r"\(mode 'missing' removes whole samples of every channel\)$"):
        _model({"accel_x": _exact()}, {"sensor_dropouts": {"mode": "missing", "channel": "accel_x"}})


def test_isolated_outliers_are_the_one_sample_bursts_added_to_bias_and_noise():
    """With burst_length 1 the outliers are drawn exactly as one-sample bursts, on top of the bias (same seed, same
    outliers in a new model); burst_length 2 gives two-sample bursts, never an isolated one."""
    effects = {"sensor_outliers": {"rate": 0.01, "channel": "accel_x"}}
    m = _model({"accel_x": _exact(bias=0.3, outlier_scale=2.0), "yaw_rate": _exact()}, effects)
    n = 2 * CHUNK
    log = _zero_log(n)
    x = m.measure(log, n)[1]["accel_x"]
    expected = np.full(n, 0.3)
    for c in range(2):
        for start, sign, mags in m._outlier_bursts(0, c):
            expected[start] += sign * mags[0]
    np.testing.assert_array_equal(x, expected)
    again = _model({"accel_x": _exact(bias=0.3, outlier_scale=2.0), "yaw_rate": _exact()}, effects)
    np.testing.assert_array_equal(again.measure(log, n)[1]["accel_x"], x)
    pairs = _model({"accel_x": _exact(outlier_scale=2.0)}, {"sensor_outliers": {"rate": 0.002, "burst_length": 2}})
    hit = pairs.measure(log, n)[1]["accel_x"] != 0
    lengths = [ln for _, ln in _runs(hit)]
    assert lengths and min(lengths) >= 2 and hit.sum() >= 2 * len(lengths)


def test_window_starting_in_a_later_chunk_and_trips_ending_one_sample_into_a_chunk():
    m = _model({"accel_x": _exact(noise_std=0.1, resolution=0.01)}, {"sensor_dropouts": {"rate": 600.0},
                                                                     "sensor_outliers": {"rate": 0.01}})
    n = 2 * CHUNK + 1  # the last sample is the first of a third chunk
    log = _log(n)
    t, out, keep = m.measure(log, n)
    assert t.size == n and out["accel_x"].size == n and keep.dtype == bool
    start = CHUNK + 100
    tw, ow, kw = m.measure(log[:, start:], n, start=start, offset=start)
    np.testing.assert_array_equal(tw, t[start:])
    np.testing.assert_array_equal(ow["accel_x"], out["accel_x"][start:])
    assert kw.dtype == bool and kw.size == n - start


def test_sample_without_channels_and_battery_channels_need_a_bev():
    m = _model({"accel_x": _exact(enabled=False)})
    assert m.sample(_log(5), 5) == {"t": 0.04, "valid": True}
    with pytest.raises(SensorConfigError, match=r"sensors.channels.battery_voltage: only a 'bev' drive-train has"):
        _model({"battery_voltage": _exact()}, vehicle=ICE)
