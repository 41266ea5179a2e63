"""The compiled EcoDrive-v0 step, the one step of the single env (N = 1) and of the native vector env.

Per vehicle, as named stages: action (u clipped to [-1, 1], speed shield), physics (the simulator core through
:mod:`roadload.envs.batch`: the wheel force of u held for n substeps), route look-ahead, reward terms, done flags,
the 'state' observation and the info values. The records:

* the vehicles: a :class:`roadload.envs.batch.FleetRecords` (state, parameters, road of each vehicle);
* :class:`EcoRecords`: per-episode bookkeeping (``EPISODE`` records: speed limit, previous command, energy,
  time limit, route length, return costs, ...), the env's settings (``SETTINGS``: reward weights, control period,
  lateral limit, stop speed, drive scales), the route tables, speed-shield envelopes and stop lines of every
  vehicle, the preview distances and the observation's scale / bounds;
* :class:`EcoOutputs`: observation, reward, done flags and the info block one step returns.

The route table (grade, curvature, speed limit, schedule time on a uniform grid) and the speed shield are compiled
here too, for the reward, the observation and :class:`roadload.gym.ecodrive.RouteTable`.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from roadload.envs.batch import advance_vehicle, command_wheel_force, dependent_jit, state_of

kernel = dependent_jit(__file__)
"""The decorator of this module's compiled functions: their numba cache is keyed by the simulator core's sources
and this module's."""

PREVIEW_GRID = 1.0
"""Resolution [m] of the resampled route table the preview reads."""
STOP_HORIZON = 1000.0
"""Distance to the next stop is reported up to this value [m] (= 'no stop ahead')."""
SHIELD_GAIN = 2.0
"""Gain of the speed shield [1/(m/s)]: the command is capped at SHIELD_GAIN * (v_envelope - v)."""
NO_SHIELD = 1.0e9
"""Envelope value [m/s] of a vehicle without the speed shield (the cap never binds)."""
GRADE, CURVATURE, SPEED_LIMIT, SCHEDULE = 0, 1, 2, 3
"""Rows of a route table."""

COST_NAMES = ("energy", "time", "speeding", "lateral", "stop", "jerk", "progress")
"""Reward terms, in the order of ``info['terms']`` / ``info['costs']``."""
N_COSTS = len(COST_NAMES)
INFO_SCALARS = ("t", "s", "v", "a", "gear", "speed_limit", "source_energy_total", "road_seed", "route_length",
                "schedule_time")
"""The scalar info keys of a step."""

# rows of the float info block one step returns: INFO_SCALARS without the two integer keys, then return_costs,
# terms and costs (N_COSTS each, COST_NAMES order); the integer block holds gear and road seed
I_T, I_S, I_V, I_A, I_LIMIT, I_ENERGY_TOTAL, I_ROUTE_LENGTH, I_SCHEDULE = range(8)
I_RETURN, I_TERMS, I_COSTS = 8, 8 + N_COSTS, 8 + 2 * N_COSTS
N_INFO = 8 + 3 * N_COSTS
INFO_ROWS = (("t", I_T), ("s", I_S), ("v", I_V), ("a", I_A), ("gear", -1), ("speed_limit", I_LIMIT),
             ("source_energy_total", I_ENERGY_TOTAL), ("road_seed", -2), ("route_length", I_ROUTE_LENGTH),
             ("schedule_time", I_SCHEDULE))
"""Info key -> row of the float block (>= 0) or -1 - row of the integer block."""

EPISODE = np.dtype([
    ("speed_limit", np.float64),            # [m/s] at the vehicle's position
    ("previous_command", np.float64),       # u of the last step
    ("previous_acceleration", np.float64),  # [m/s^2] after the last step
    ("last_source_energy", np.float64),     # [J] source energy after the last step
    ("time_limit", np.float64),             # [s] truncation
    ("route_length", np.float64),           # [m] termination
    ("route_time", np.float64),             # [s] schedule time of the whole route
    ("return_costs", np.float64, (N_COSTS,)),  # weighted terms summed over the episode
    ("terms", np.float64, (N_COSTS,)),      # raw terms of the last step
    ("costs", np.float64, (N_COSTS,)),      # weighted terms of the last step
    ("table_points", np.int64),             # used columns of the route table / envelope
    ("stop_count", np.int64),               # used stop lines
    ("road_seed", np.int64),
])
"""Bookkeeping of one sub-environment's episode."""

SETTINGS = np.dtype([
    ("weights", np.float64, (N_COSTS + 1,)),  # EcoDriveReward: energy, time, speeding, lateral, stop, jerk,
                                              # progress, scale
    ("control_period", np.float64),         # [s]
    ("lateral_limit", np.float64),          # [m/s^2] comfort limit of the reward
    ("stop_speed", np.float64),             # [m/s]
    ("n_substeps", np.int64),
    ("peak_traction_force", np.float64),    # [N] DriveScales
    ("peak_power", np.float64),             # [W]
    ("full_brake_force", np.float64),       # [N]
])
"""The settings every sub-environment of one env shares."""


class EcoRecords(NamedTuple):
    """Per-episode bookkeeping and the route of every sub-env, plus the shared settings and work arrays."""

    episodes: np.ndarray
    """(N,) EPISODE records."""
    settings: np.ndarray
    """(1,) SETTINGS record."""
    tables: np.ndarray
    """(N, 4, points) route tables (GRADE, CURVATURE, SPEED_LIMIT, SCHEDULE rows on the PREVIEW_GRID)."""
    envelopes: np.ndarray
    """(N, points) speed-shield envelopes [m/s] (NO_SHIELD without the shield)."""
    stops: np.ndarray
    """(N, stops) stop lines [m], increasing."""
    preview: np.ndarray
    """(m,) preview distances [m], the first 0."""
    obs_bounds: np.ndarray
    """(3, n_obs) scale, low, high of the observation entries (low / high already divided by the scale)."""
    look_ahead: np.ndarray
    """(N, 4, m) work: the route table at s + preview."""
    obs_work: np.ndarray
    """(N, n_obs) work: the observation in SI units."""


class EcoOutputs(NamedTuple):
    """What one step returns per sub-env."""

    obs: np.ndarray
    """(N, n_obs) float32 observations."""
    reward: np.ndarray
    """(N,) rewards."""
    terminated: np.ndarray
    """(N,) bool."""
    truncated: np.ndarray
    """(N,) bool."""
    info: np.ndarray
    """(N_INFO, N) float info block (rows I_*)."""
    ints: np.ndarray
    """(2, N) int64: gear, road seed."""


# --------------------------------------------------------------------------------------------- route table
@kernel(inline="always")
def grid_cell(x, n):
    """Grid position x (in grid steps) clamped to [0, n - 1.001] -> (cell index i, fraction f in [0, 1))."""
    if x < 0.0:
        x = 0.0
    elif x > n - 1.001:
        x = n - 1.001
    i = int(x)
    return i, x - i


@kernel()
def look_ahead(table, grid, points, s, out):
    """Linear interpolation of every row of ``table`` (uniform grid step ``grid`` [m]) at s + points -> out."""
    n = table.shape[1]
    for j in range(points.size):
        i, f = grid_cell((s + points[j]) / grid, n)
        for r in range(table.shape[0]):
            out[r, j] = table[r, i] * (1.0 - f) + table[r, i + 1] * f


@kernel()
def braking_envelope(limit, grid, margin, decel, out):
    """Backward pass: out[k] = min over y >= x_k of sqrt((v_lim(y) - margin)^2 + 2 decel (y - x_k)) on the grid."""
    n = limit.size
    nxt = max(limit[n - 1] - margin, 0.0)
    out[n - 1] = nxt
    for k in range(n - 2, -1, -1):
        own = max(limit[k] - margin, 0.0)
        reach = math.sqrt(nxt * nxt + 2.0 * decel * grid)
        nxt = own if own < reach else reach
        out[k] = nxt


@kernel()
def shield_command(envelope, n, s, v, u):
    """The speed shield: the command u capped at SHIELD_GAIN * (v_env(s) - v), clipped to [-1, 1], with v_env the
    braking envelope (first n grid points) linearly interpolated at s [m], v [m/s]."""
    i, f = grid_cell(s / PREVIEW_GRID, n)
    cap = SHIELD_GAIN * (envelope[i] * (1.0 - f) + envelope[i + 1] * f - v)
    if cap < -1.0:
        cap = -1.0
    return u if u < cap else cap


# --------------------------------------------------------------------------------------------- observation
@kernel(inline="always")
def route_rows(buf, k, la, t, s, e, stops):
    """The route part of an observation from entry k on: grade, curvature, speed limit at s + preview (rows of the
    look-ahead la), time deficit t - t_ref(s) [s], remaining distance [m], distance to the next stop line at or ahead
    of s (<= STOP_HORIZON) [m], previous command."""
    m = la.shape[1]
    for r in range(3):
        for j in range(m):
            buf[k + r * m + j] = la[r, j]
    k += 3 * m
    buf[k] = t - la[SCHEDULE, 0]
    buf[k + 1] = max(e.route_length - s, 0.0)
    nxt = STOP_HORIZON
    for j in range(e.stop_count):  # bisect_left: first stop >= s
        if stops[j] >= s:
            nxt = min(stops[j] - s, STOP_HORIZON)
            break
    buf[k + 2] = nxt
    buf[k + 3] = e.previous_command


@kernel(inline="always")
def scaled_observation(buf, bounds, out):
    """out = clip(buf / scale, low, high) as float32 (bounds rows: scale, low, high)."""
    for j in range(buf.size):
        o = buf[j] / bounds[0, j]
        if o < bounds[1, j]:
            o = bounds[1, j]
        elif o > bounds[2, j]:
            o = bounds[2, j]
        out[j] = np.float32(o)


@kernel(inline="always")
def observe_state(i, fleet, eco, out):
    """The 'state' observation of sub-env i -> out.obs[i]: speed [m/s], acceleration [m/s^2], then the route rows
    at the true position (look-ahead eco.look_ahead[i] already filled)."""
    x = state_of(fleet, i)
    buf = eco.obs_work[i]
    buf[0] = x.speed
    buf[1] = x.acceleration
    route_rows(buf, 2, eco.look_ahead[i], x.time, x.position, eco.episodes[i], eco.stops[i])
    scaled_observation(buf, eco.obs_bounds, out.obs[i])


# --------------------------------------------------------------------------------------------- one step
@kernel(inline="always")
def wheel_force(settings, u, v):
    """Signed wheel-force request [N] of the normalised command u in [-1, 1] at speed v [m/s] (DriveScales):
    u min(F_peak, P_max / max(v, 1)) for u >= 0, u F_brake for u < 0."""
    if u >= 0.0:
        return u * min(settings.peak_traction_force, settings.peak_power / max(v, 1.0))
    return u * settings.full_brake_force


@kernel(inline="always")
def shielded_action(i, u, fleet, eco):
    """Stage 'action': u clipped to [-1, 1], then capped by the speed shield u <= SHIELD_GAIN (v_env(s) - v)
    (no-op without the shield: envelope = NO_SHIELD)."""
    u = -1.0 if u < -1.0 else (1.0 if u > 1.0 else u)
    x = state_of(fleet, i)
    return shield_command(eco.envelopes[i], eco.episodes[i].table_points, x.position, x.speed, u)


@kernel(inline="always")
def limit_ahead(i, fleet, eco):
    """Stage 'look-ahead': the route table at s + preview -> eco.look_ahead[i] (preview 0 first: its column 0 is
    the speed limit at s itself, stored in the episode record). Returns the speed limit [m/s]."""
    e = eco.episodes[i]
    la = eco.look_ahead[i]
    look_ahead(eco.tables[i, :, :e.table_points], PREVIEW_GRID, eco.preview, state_of(fleet, i).position, la)
    e.speed_limit = la[SPEED_LIMIT, 0]
    return e.speed_limit


@kernel(inline="always")
def stops_crossed_fast(e, stops, s0, s1, v0, v1, stop_speed):
    """Stop lines s0 < s_stop <= s1 crossed faster than stop_speed [m/s] (speed interpolated linearly)."""
    count = 0.0
    for j in range(e.stop_count):
        st = stops[j]
        if st > s0 and st <= s1:
            frac = (st - s0) / max(s1 - s0, 1e-9)
            if v0 + frac * (v1 - v0) > stop_speed:
                count += 1.0
    return count


@kernel(inline="always")
def reward_terms(i, fleet, eco, s0, v0, limit0, limit):
    """Stage 'reward terms' (EcoDriveReward) into the episode record's terms: energy E_source(t1) - E_source(t0)
    [J], dt [s], speeding (mean(v) - mean(v_lim))+ dt [m], lateral (|a_y| - a_max)+ dt [m/s], stop lines crossed
    too fast, jerk^2 dt with jerk = (a1 - a0) / dt, progress min(s1, L) - min(s0, L) [m]."""
    x = state_of(fleet, i)
    e = eco.episodes[i]
    cfg = eco.settings[0]
    dt = cfg.control_period
    s1 = x.position
    v1 = x.speed
    tm = e.terms
    tm[2] = max(0.0, 0.5 * (v0 + v1 - limit0 - limit)) * dt
    tm[3] = max(0.0, abs(x.lateral_acceleration) - cfg.lateral_limit) * dt
    tm[4] = stops_crossed_fast(e, eco.stops[i], s0, s1, v0, v1, cfg.stop_speed)
    jerk = (x.acceleration - e.previous_acceleration) / dt
    length = e.route_length
    tm[6] = min(s1, length) - min(s0, length)
    tm[0] = x.source_energy - e.last_source_energy
    e.last_source_energy = x.source_energy
    tm[1] = dt
    tm[5] = jerk * jerk * dt


@kernel(inline="always")
def weighted_reward(e, weights):
    """Stage 'reward': cost_k = w_k term_k (progress: -w_progress ds), summed into the episode's return costs;
    r = -scale * sum_k cost_k."""
    total = 0.0
    for k in range(N_COSTS):
        e.costs[k] = (-weights[6] * e.terms[6]) if k == 6 else weights[k] * e.terms[k]
        total += e.costs[k]
        e.return_costs[k] += e.costs[k]
    return -weights[N_COSTS] * total


@kernel(inline="always")
def gather_info(i, fleet, eco, with_terms, out):
    """Stage 'info' of sub-env i: the info values (terms / costs only for a vehicle that stepped, zeros
    otherwise) -> column i of the info block (float rows I_*) and of the integer block (gear, road seed)."""
    x = state_of(fleet, i)
    e = eco.episodes[i]
    info = out.info
    info[I_T, i] = x.time
    info[I_S, i] = x.position
    info[I_V, i] = x.speed
    info[I_A, i] = x.acceleration
    info[I_LIMIT, i] = e.speed_limit
    info[I_ENERGY_TOTAL, i] = x.source_energy
    info[I_ROUTE_LENGTH, i] = e.route_length
    info[I_SCHEDULE, i] = e.route_time
    out.ints[0, i] = np.int64(x.gear)  # truncation, as ndarray.astype(np.int64)
    out.ints[1, i] = e.road_seed
    for k in range(N_COSTS):
        info[I_RETURN + k, i] = e.return_costs[k]
        info[I_TERMS + k, i] = e.terms[k] if with_terms else 0.0
        info[I_COSTS + k, i] = e.costs[k] if with_terms else 0.0


@kernel(inline="always")
def eco_step(i, u, fleet, eco, out):
    """One env step of sub-env i with the normalised command u: action, physics, look-ahead, reward terms, done
    flags (terminated at the route end, truncated at the time limit), reward, 'state' observation, info."""
    x = state_of(fleet, i)
    e = eco.episodes[i]
    cfg = eco.settings[0]
    s0 = x.position
    v0 = x.speed
    ui = shielded_action(i, u, fleet, eco)
    limit0 = e.speed_limit
    # stage 'physics': the wheel force of ui held for n substeps of the simulator core
    command_wheel_force(fleet, i, wheel_force(cfg, ui, v0), np.nan)
    advance_vehicle(fleet, i, cfg.n_substeps)
    limit = limit_ahead(i, fleet, eco)
    reward_terms(i, fleet, eco, s0, v0, limit0, limit)
    # stage 'done flags'
    terminated = x.position >= e.route_length - 1e-6
    out.terminated[i] = terminated
    out.truncated[i] = (not terminated) and x.time >= e.time_limit - 1e-9
    out.reward[i] = weighted_reward(e, cfg.weights)
    e.previous_command = ui
    e.previous_acceleration = x.acceleration
    observe_state(i, fleet, eco, out)
    gather_info(i, fleet, eco, True, out)


@kernel(inline="always")
def idle_step(i, fleet, eco, out):
    """A sub-env that does not step (reset in this step, next-step autoreset): reward 0, no done flags, its info
    without terms."""
    out.reward[i] = 0.0
    out.terminated[i] = False
    out.truncated[i] = False
    gather_info(i, fleet, eco, False, out)


@kernel()
def step_range(lo, hi, active, u, fleet, eco, out):
    """eco_step for the active sub-envs lo..hi-1, idle_step for the others."""
    for i in range(lo, hi):
        if active[i]:
            eco_step(i, u[i], fleet, eco, out)
        else:
            idle_step(i, fleet, eco, out)


@kernel()
def start_episode(i, fleet, eco, out):
    """Sub-env i after its episode setup: the look-ahead and speed limit at the start position, its 'state'
    observation and its info without terms."""
    limit_ahead(i, fleet, eco)
    observe_state(i, fleet, eco, out)
    gather_info(i, fleet, eco, False, out)


@kernel()
def gather_info_all(fleet, eco, out):
    """Stage 'info' of every sub-env without terms (the info of reset())."""
    for i in range(fleet.vehicles.shape[0]):
        gather_info(i, fleet, eco, False, out)
