"""CAN-like sensors: turn the simulator's truth log into measured channels with latency, bias, noise,
quantisation, outliers and dropouts.

Per channel j and sample k (names and SI units from ``roadload.channels``):
    y_k = Q( h_j(truth_{k - d_j}) + b_j + sigma_j e_k + o_k ),   NaN where a dropout hits,
with the sensor's physical relation h_j (e.g. the body-fixed accelerometer reads a + g sin(theta + pitch),
eq. 4.4/5.2; the CAN torque is T_E (1 + gain error) + offset), latency d_j samples, bias b_j (spec + the random
``sensor_bias`` effect), white noise sigma_j, outliers o_k (``sensor_outliers``) and quantisation Q to the channel's
resolution. Dropouts (``sensor_dropouts``) set runs to NaN or remove rows ('missing' mode).

All randomness is drawn in fixed chunks of samples from generators keyed by (seed, feature, channel, chunk), so a
sample's value does not depend on how the trip was cut into steps: ``SensorModel.sample`` (the step API's
``observe()``) returns exactly the row that ``SensorModel.measure`` (the whole-trip Trip) produces.
"""

from __future__ import annotations

from collections import OrderedDict
from typing import Sequence

import numpy as np

from roadload.channels import MEASURED
from roadload.vehicle import SensorSpec, VehicleSpec

from .effects import EffectsConfig
from .layout import (
    L_ACC_X_SENS, L_ACC_Y_SENS, L_CLUTCH, L_DELTA, L_ELEV, L_GEAR, L_IBAT, L_PBF, L_PBR, L_T, L_TAMB, L_TE, L_V,
    L_VBAT, L_WE, L_WFL, L_WFR, L_WRL, L_WRR, L_YAW,
)

INPUT_CHANNELS = ("vehicle_speed", "wheel_speed_fl", "wheel_speed_fr", "wheel_speed_rl", "wheel_speed_rr",
                  "accel_x", "accel_y", "yaw_rate", "steering_wheel_angle")
OUTPUT_CHANNELS = ("drive_torque", "brake_pressure_front", "brake_pressure_rear")
DISCRETE_CHANNELS = ("gear", "clutch")
# reference size of a random sensor bias (effect sensor_bias, scale 1)
BIAS_REFERENCE = {"accel_x": 0.05, "accel_y": 0.05, "yaw_rate": 0.002, "steering_wheel_angle": 0.01,
                  "vehicle_speed": 0.05, "drive_torque": 5.0, "brake_pressure_front": 2e4,
                  "brake_pressure_rear": 2e4, "ambient_temperature": 1.0, "elevation": 5.0,
                  "battery_current": 0.5, "battery_voltage": 0.5}
CHUNK = 8192

_SIMPLE = {"wheel_speed_fl": L_WFL, "wheel_speed_fr": L_WFR, "wheel_speed_rl": L_WRL, "wheel_speed_rr": L_WRR,
           "accel_x": L_ACC_X_SENS, "accel_y": L_ACC_Y_SENS, "yaw_rate": L_YAW, "engine_speed": L_WE,
           "clutch": L_CLUTCH, "brake_pressure_front": L_PBF, "brake_pressure_rear": L_PBR,
           "ambient_temperature": L_TAMB, "battery_voltage": L_VBAT, "battery_current": L_IBAT, "elevation": L_ELEV}
SUPPORTED_CHANNELS = tuple(_SIMPLE) + ("vehicle_speed", "steering_wheel_angle", "drive_torque", "gear")


class SensorConfigError(ValueError):
    """The sensor configuration asks for something the simulator cannot produce."""


class SensorModel:
    """Measured channels from the truth log (see module doc)."""

    def __init__(self, vehicle: VehicleSpec, sensors: SensorSpec, effects: EffectsConfig, seed: int,
                 dt: float = 0.01) -> None:
        self.vehicle = vehicle
        self.spec = sensors
        self.seed = int(seed)
        self.dt = dt
        step = 1.0 / (sensors.sample_rate * dt)
        if abs(step - round(step)) > 1e-9 or round(step) < 1:
            raise SensorConfigError(f"sensors.sample_rate: {sensors.sample_rate} Hz must divide the simulation rate "
                                    f"{1.0 / dt:g} Hz")
        self.decimation = int(round(step))
        self.names = [n for n, c in sensors.channels.items() if c.enabled]
        self._check_channels(vehicle)
        cs = [sensors.channels[n] for n in self.names]
        self.noise = np.array([c.noise_std for c in cs])
        self.resolution = np.array([c.resolution for c in cs])
        self._errors(effects, np.array([c.bias for c in cs]), np.array([c.latency for c in cs]))
        self.outliers = effects.params("sensor_outliers") if effects.enabled("sensor_outliers") else None
        if self.outliers is not None:
            self._outlier_setup(self.outliers, np.array([c.outlier_scale for c in cs]))
        self.dropouts = effects.params("sensor_dropouts") if effects.enabled("sensor_dropouts") else None
        if self.dropouts is not None:
            self._dropout_setup(self.dropouts)
        self._cache: OrderedDict[int, tuple[np.ndarray, np.ndarray | None, np.ndarray | None]] = OrderedDict()
        st = vehicle.steering
        self._steer_x = np.asarray(st.wheel_angle, float)
        self._steer_y = np.asarray(st.steering_wheel_angle, float)
        # log column each channel reads (for the vectorised single-sample path)
        special = {"vehicle_speed": L_V, "steering_wheel_angle": L_DELTA, "drive_torque": L_TE, "gear": L_GEAR}
        self._col = np.array([_SIMPLE.get(n, special.get(n, 0)) for n in self.names], dtype=np.int64)

    def _check_channels(self, vehicle: VehicleSpec) -> None:
        """Every enabled channel is one the simulator produces (battery channels need a BEV)."""
        for n in self.names:
            if n not in SUPPORTED_CHANNELS:
                raise SensorConfigError(f"sensors.channels.{n}: the simulator does not produce this channel; "
                                        f"supported: {sorted(SUPPORTED_CHANNELS)}")
            if n in ("battery_voltage", "battery_current") and vehicle.drivetrain.kind != "bev":
                raise SensorConfigError(f"sensors.channels.{n}: only a 'bev' drive-train has a traction battery")

    def _errors(self, effects: EffectsConfig, bias: np.ndarray, latency: np.ndarray) -> None:
        """Biases (plus a seeded random bias per channel with 'sensor_bias'), latencies in substeps (plus the
        extra of 'sensor_latency') and the drive-torque gain error / offset ('torque_model_error' replaces
        them)."""
        if effects.enabled("sensor_latency"):
            latency = latency + float(effects.params("sensor_latency")["extra"])
        self.delay = np.round(latency / self.dt).astype(np.int64)
        self.bias = bias
        if effects.enabled("sensor_bias"):
            g = np.random.default_rng([self.seed, 4])
            ref = np.array([BIAS_REFERENCE.get(n, 0.0) for n in self.names])
            self.bias = self.bias + g.standard_normal(len(self.names)) * ref * float(
                effects.params("sensor_bias")["scale"])
        self.gain_error = self.spec.drive_torque_gain_error
        self.offset = self.spec.drive_torque_offset
        if effects.enabled("torque_model_error"):
            p = effects.params("torque_model_error")
            self.gain_error, self.offset = float(p["gain_error"]), float(p["offset"])

    def _group(self, which: str, explicit: str = "", effect: str = "") -> np.ndarray:
        """Which enabled channels an effect acts on: the explicit '+'-separated list, else 'inputs', 'outputs' or
        all continuous channels."""
        if explicit:
            wanted = [w.strip() for w in explicit.split("+") if w.strip()]
            unknown = [w for w in wanted if w not in self.names]
            if unknown or not wanted:
                raise SensorConfigError(f"effect {effect!r} parameter 'channel': unknown or disabled channel(s) "
                                        f"{unknown or [explicit]}; enabled channels: {self.names}")
            return np.array([n in wanted for n in self.names], dtype=bool)
        sel: Sequence[str]
        if which == "inputs":
            sel = INPUT_CHANNELS
        elif which == "outputs":
            sel = OUTPUT_CHANNELS
        else:
            sel = [n for n in self.names if n not in DISCRETE_CHANNELS]
        return np.array([n in sel for n in self.names], dtype=bool)

    def _outlier_setup(self, p: dict, scale: np.ndarray) -> None:
        self.outlier_on = self._group(str(p["channels"]), str(p.get("channel", "")), "sensor_outliers")
        self.outlier_size = scale * float(p["magnitude"])
        burst = float(p.get("burst_length", 1.0))
        if burst != round(burst):
            raise SensorConfigError(f"effect 'sensor_outliers' parameter 'burst_length': must be a whole number "
                                    f"of samples, got {burst!r}")
        self.burst_length = int(burst)

    def _dropout_setup(self, p: dict) -> None:
        self.dropout_on = self._group(str(p["channels"]), str(p.get("channel", "")), "sensor_dropouts")
        self.missing_mode = p["mode"] == "missing"
        if self.missing_mode and p.get("channel", ""):
            raise SensorConfigError("effect 'sensor_dropouts': parameter 'channel' needs mode 'nan' (mode "
                                    "'missing' removes whole samples of every channel)")

    @property
    def units(self) -> dict[str, str]:
        return {n: MEASURED[n].unit for n in self.names}

    # ------------------------------------------------------------------ physical relation h_j
    def _true(self, name: str, log: np.ndarray, rows) -> np.ndarray:
        """The channel's error-free reading at the given substeps (index array) of the column-major log."""
        if name in _SIMPLE:
            return log[_SIMPLE[name], rows]
        if name == "vehicle_speed":
            return log[L_V, rows] * (1.0 + self.spec.speed_scale_error)
        if name == "steering_wheel_angle":
            return np.interp(log[L_DELTA, rows], self._steer_x, self._steer_y)
        if name == "drive_torque":
            return log[L_TE, rows] * (1.0 + self.gain_error) + self.offset
        if name == "gear":
            return log[L_GEAR, rows] * (log[L_CLUTCH, rows] > 0.0)
        raise SensorConfigError(f"no sensor model for channel {name!r}")  # pragma: no cover - checked in __init__

    # ------------------------------------------------------------------ random perturbations, chunk by chunk
    def _dropout_runs(self, c: int) -> list[tuple[int, int]]:
        """(start, length) of dropout events that begin in chunk c (absolute sample indices)."""
        p = self.dropouts
        if p is None:  # effect 'sensor_dropouts' off
            return []
        g = np.random.default_rng([self.seed, 3, c])
        dt_meas = self.dt * self.decimation
        n = g.poisson(float(p["rate"]) / 3600.0 * CHUNK * dt_meas)
        starts = c * CHUNK + g.integers(0, CHUNK, size=n)
        lengths = np.minimum(np.ceil(g.exponential(float(p["mean_duration"]) / dt_meas, size=n)), CHUNK)
        return list(zip(starts.tolist(), lengths.astype(int).tolist()))

    def _outlier_bursts(self, j: int, c: int) -> list[tuple[int, float, np.ndarray]]:
        """(start, sign, sizes) of the outlier bursts of channel j that begin in chunk c (absolute sample index;
        sizes: burst_length values magnitude outlier_scale (1 + |N(0,1)|))."""
        if self.outliers is None:  # effect 'sensor_outliers' off
            return []
        go = np.random.default_rng([self.seed, 2, j, c])
        starts = np.flatnonzero(go.random(CHUNK) < float(self.outliers["rate"]))
        signs = np.where(go.random(starts.size) < 0.5, -1.0, 1.0)
        mags = self.outlier_size[j] * (1.0 + np.abs(go.standard_normal((starts.size, self.burst_length))))
        return [(c * CHUNK + int(st), float(sg), m) for st, sg, m in zip(starts, signs, mags)]

    def _chunk(self, c: int) -> tuple[np.ndarray, np.ndarray | None, np.ndarray | None]:
        """(additive errors (channels, CHUNK), NaN mask or None, missing-sample mask or None) of chunk c (cached)."""
        hit = self._cache.get(c)
        if hit is not None:
            return hit
        add = np.empty((len(self.names), CHUNK))
        for j in range(len(self.names)):
            self._channel_errors(j, c, add[j])
        nan = missing = None
        if self.dropouts is not None:
            drop = self._dropped(c)
            if self.missing_mode:
                missing = drop
            else:
                nan = self.dropout_on[:, None] & drop[None, :]
        out = (add, nan, missing)
        self._cache[c] = out
        # two chunks: the one a streamed window ends in is the next window's first; more would only hold 2.6 MB
        # each (40 channels x CHUNK float64) through the write of a chunk, when a simulation peaks
        while len(self._cache) > 2:
            self._cache.popitem(last=False)
        return out

    def _channel_errors(self, j: int, c: int, add: np.ndarray) -> None:
        """Bias, seeded noise and outliers (single samples, or bursts that may start in the chunk before) of
        channel j in chunk c -> add."""
        g = np.random.default_rng([self.seed, 1, j, c])
        add[:] = self.bias[j] + self.noise[j] * g.standard_normal(CHUNK) if self.noise[j] > 0 else self.bias[j]
        if self.outliers is None or not self.outlier_on[j]:
            return
        if self.burst_length > 1:
            for cc in (c - 1, c):
                for start, sign, mags in (self._outlier_bursts(j, cc) if cc >= 0 else ()):
                    a = max(start - c * CHUNK, 0)
                    b = min(start + mags.size - c * CHUNK, CHUNK)
                    if b > a:
                        off = a - (start - c * CHUNK)
                        add[a:b] += sign * mags[off:off + b - a]
            return
        go = np.random.default_rng([self.seed, 2, j, c])
        u = go.random(CHUNK)
        idx = np.flatnonzero(u < float(self.outliers["rate"]))
        if idx.size:
            signs = np.where(go.random(idx.size) < 0.5, -1.0, 1.0)
            add[idx] += signs * self.outlier_size[j] * (1.0 + np.abs(go.standard_normal(idx.size)))

    def _dropped(self, c: int) -> np.ndarray:
        """Samples of chunk c inside a dropout (events that start in this chunk or the one before)."""
        drop = np.zeros(CHUNK, dtype=bool)
        for cc in (c - 1, c):
            for start, length in (self._dropout_runs(cc) if cc >= 0 else ()):
                a = max(start - c * CHUNK, 0)
                b = min(start + length - c * CHUNK, CHUNK)
                if b > a:
                    drop[a:b] = True
        return drop

    def _quantise(self, values: np.ndarray, j: int) -> np.ndarray:
        res = self.resolution[j]
        return np.round(values / res) * res if res > 0 else values

    # ------------------------------------------------------------------ whole trip / one sample
    def measure(self, log: np.ndarray, n: int, start: int = 0, offset: int = 0
                ) -> tuple[np.ndarray, dict[str, np.ndarray], np.ndarray]:
        """(t, channels, keep) for the substeps start..n-1 (absolute indices) of the column-major log (N_LOG, >=
        n - offset) whose column 0 holds substep ``offset``: measured sample i uses substep (i+1) m - 1 with the
        decimation m; ``keep`` is False for samples removed by 'missing' dropouts. The log must still hold the
        substeps the latencies reach back to (start - max delay); a window gives exactly the rows the whole-trip
        call gives for the same samples (randomness is keyed by absolute sample index)."""
        m = self.decimation
        i0 = (max(start, 0) + m) // m - 1  # first sample i with (i+1) m - 1 >= start
        rows = np.arange((i0 + 1) * m - 1, n, m)
        n_meas = rows.size
        t = log[L_T, rows - offset].copy()
        out: dict[str, np.ndarray] = {}
        keep = np.ones(n_meas, dtype=bool)
        c0 = i0 // CHUNK
        c1 = (i0 + n_meas + CHUNK - 1) // CHUNK if n_meas else c0
        perturb = [self._chunk(c) for c in range(c0, c1)]
        lo = i0 - c0 * CHUNK
        for j, name in enumerate(self.names):
            src = np.maximum(rows - self.delay[j], 0)
            if n_meas and src.min() < offset:
                raise ValueError(f"measure: channel {name!r} needs substep {int(src.min())}, the log starts at "
                                 f"{offset}")
            val = self._true(name, log, src - offset)
            if perturb:
                val = val + np.concatenate([p[0][j] for p in perturb])[lo:lo + n_meas]
            val = self._quantise(val, j)
            if self.dropouts is not None and not self.missing_mode and perturb:
                val[np.concatenate([p[1][j] for p in perturb if p[1] is not None])[lo:lo + n_meas]] = np.nan
            out[name] = val
        if self.dropouts is not None and self.missing_mode and perturb:
            keep = ~np.concatenate([p[2] for p in perturb])[lo:lo + n_meas]
        return t, out, keep

    @property
    def max_delay(self) -> int:
        """The longest latency [substeps]: how far back the log must reach for a window (see measure)."""
        return int(self.delay.max(initial=0))

    def sample(self, log: np.ndarray, n: int) -> dict[str, float] | None:
        """The latest measured sample given n substeps (None before the first sample); values are NaN and
        'valid' is False when a 'missing' dropout removed it. Vectorised over channels; bit-identical to the
        corresponding row of ``measure``."""
        i = n // self.decimation - 1
        if i < 0:
            return None
        row = (i + 1) * self.decimation - 1
        add, nan, missing = self._chunk(i // CHUNK)
        ii = i % CHUNK
        src = np.maximum(row - self.delay, 0)
        base = log[self._col, src]
        val = np.empty(base.size)
        for j, name in enumerate(self.names):  # the same expressions as _true(), one element each
            if name in _SIMPLE:
                val[j] = base[j]
            elif name == "vehicle_speed":
                val[j] = base[j] * (1.0 + self.spec.speed_scale_error)
            elif name == "steering_wheel_angle":
                val[j] = np.interp(base[j], self._steer_x, self._steer_y)
            elif name == "drive_torque":
                val[j] = base[j] * (1.0 + self.gain_error) + self.offset
            else:  # gear: shown as 0 while the clutch is open
                val[j] = base[j] * (log[L_CLUTCH, src[j]] > 0.0)
        val = val + add[:, ii]
        q = self.resolution > 0
        val[q] = np.round(val[q] / self.resolution[q]) * self.resolution[q]
        valid = missing is None or not missing[ii]
        if not valid:
            val[:] = np.nan
        elif nan is not None:
            val[nan[:, ii]] = np.nan
        out: dict[str, float] = {"t": float(log[L_T, row])}
        out.update(zip(self.names, val.tolist()))
        out["valid"] = valid
        return out
