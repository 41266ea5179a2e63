"""``roadload/EcoTraffic-v0``: eco-driving in multi-lane IDM/MOBIL traffic, compiled and batched.

The scenario of ``roadload/EcoHighway-v0`` (its lanes, density, spawn procedure, IDM/MOBIL traffic with
highway-env's parameters, reward and episode length) on a native backend: the traffic is
:mod:`roadload.gym.traffic_model` (highway-env's models written for numba, equal to highway-env's trajectories to
round-off from the same state, tests/gym/test_traffic_model.py) and the ego drives roadload's compiled powertrain
on a road with grade and curvature (:mod:`roadload.gym.traffic_ego`). One compiled call steps N sub-envs
(``gymnasium.make_vec("roadload/EcoTraffic-v0", num_envs=N, vectorization_mode="vector_entry_point")``,
optionally on numba threads); ``gymnasium.make`` gives the single env, the same kernel on a batch of one.
EcoHighway-v0 stays the reference implementation (roadload.gym.traffic_reference runs it in this env's layout).

Per env step (1 / policy_frequency) the held command drives ``frames_per_action`` traffic frames of
1 / simulation_frequency: the traffic decides (MOBIL, IDM, steering), the ego's powertrain runs 100 Hz substeps
under the wheel force of the command at the frame's starting speed and moves the ego along its heading by the
distance driven, the traffic moves, the ego is tested for collisions.

Action (``lane_changes``): 'off' -> Box(-1, 1, (1,)), the normalised wheel-force command of EcoDrive-v0
(u >= 0: u min(F_peak, P_max / max(v, 1 m/s)); u < 0: u 0.5 m g, regen first); 'box' -> Box(-1, 1, (2,)), the
second entry < -1/3 asks for the left, > 1/3 for the right lane (EcoHighway-v0's 'box').

Safety layer (``shield.enabled``): before it is applied the command is capped at SHIELD_GAIN (v_safe - v), v_safe
the braking envelope behind the leader (roadload.gym.config.TrafficShield); ``info['shield_active']`` tells when
it bound. Spawn (``spawn``): highway-env's, or ``'outside-envelope'``: the ego moved back behind the vehicle ahead
on its lane to that envelope's gap at the two speeds (:func:`spawn_outside_envelope`), so that no policy starts
inside it, or ``'stopping-gap'``: to the envelope's gap behind a vehicle at rest, so that the traffic's braking in
its first seconds (spawned at highway-env's spacing, it closes up) forces no policy to brake either.

Observation (:func:`traffic_observation_layout`): highway-env's Kinematics block (``kinematics_rows`` rows of
presence, x, y, vx, vy; row 0 the ego in absolute values, then the nearest vehicles relative to it; each mapped from
its range to [-1, 1] and clipped) followed by the ego's powertrain and road state: speed, acceleration, the command
it drove, source power, gear, engine / motor speed, grade and curvature at 0, 100 and 200 m ahead, lane, front
gap and closing speed (each SI value / scale, clipped to [-5, 5]).

Reward: EcoHighway-v0's, scale (progress dx - energy E + mechanical_energy dM - collision [crash] - headway
integral (h_min - h)+ dt - jerk integral jerk^2 dt - lane_change [lane change]); raw terms in ``info['terms']``.
Terminates on a collision of the ego, truncates at ``duration`` or the road's end.

Differences from EcoHighway-v0, all by design: the ego's longitudinal position is the distance its powertrain
drove (highway-env integrates its speed by explicit Euler at 10 Hz: a few centimetres apart per episode); the ego's
road may curve (``curvature``; the traffic's lanes stay straight in road coordinates); the lanes have no end
(highway-env's are 10 km); after a crash the frames left in the step are not simulated (the episode ends).

Seeds and autoreset: gymnasium 1.x rules. ``reset(seed=s)`` seeds sub-env i with s + i (the single env with s),
each sub-env's episodes are drawn from its own generator, so sub-env i equals a single env seeded s + i
(tests/gym/test_traffic.py, to 1e-9). Next-step autoreset by default; ``autoreset_mode='same_step'`` for SB3
(roadload.gym.sb3). ``threads=k`` splits the sub-envs over k numba threads (trajectories unchanged).
"""

from __future__ import annotations

import math
from typing import Any, NamedTuple, cast

import gymnasium as gym
import numpy as np
from gymnasium import spaces
from gymnasium.utils import seeding
from numba import prange

from roadload.envs.batch import dependent_jit
from roadload.gym import traffic_ego as _ego
from roadload.gym import traffic_model as _tm
from roadload.gym.actions import BOUND_TOLERANCE, validate_action, validate_actions
from roadload.gym import batched
from roadload.gym.config import SPACE_FIELDS_TRAFFIC, EcoTrafficConfig, GymConfigError, make_config, updated_config
from roadload.gym.ecodrive import SHIELD_GAIN
from roadload.gym.traffic_ego import (PREVIEW, EgoBatch, ego_advance, ego_at_road_end, ego_look_ahead, ego_road,
                                      ego_state, road_key, start_ego)
from roadload.gym.traffic_model import (LANE_WIDTH, V_CRASHED, V_DELTA, V_HEADING, V_LANE, V_SPEED, V_TARGET_LANE,
                                        V_TARGET_SPEED, V_TIMER, V_X, V_Y, N_V, behaviour_array, ego_collisions,
                                        front_gap, kinematics_block, lane_neighbours, leader_gap, move, neighbours,
                                        traffic_act, traffic_move)
from roadload.gym.vector import _prefer_passive_openmp_wait

kernel = dependent_jit(__file__, _tm.__file__, _ego.__file__)
"""The decorator of this module's kernels: their cache is keyed by the core's, the traffic model's, the ego
adapter's and this module's sources."""

EGO_START = 100.0
"""Minimum x of the ego at reset [m] (EcoHighway-v0's)."""
EGO_SPACING = 2.0
"""Spawn spacing factor of the ego (EcoHighway-v0's ``ego_spacing``)."""

TERM_NAMES = ("progress", "energy", "mechanical", "collision", "headway", "jerk", "lane_change")
"""Raw reward terms, in the order of ``info['terms']`` (EcoHighway-v0's keys)."""
INFO_KEYS = ("speed", "crashed", "lane", "s", "t", "source_energy_total", "front_gap", "road_seed", "shield_active")
"""Scalar info keys (EcoHighway-v0's, plus shield_active)."""
_INT_INFO = {"lane", "road_seed"}
_BOOL_INFO = {"crashed", "shield_active"}
N_INFO = len(INFO_KEYS) + len(TERM_NAMES)
I_TERMS = len(INFO_KEYS)

NEIGHBOUR_FEATURES = ("ax", "lane_change", "cut_in_time")
"""The optional features of each observed vehicle (EcoTrafficConfig.neighbour_features), by code 0, 1, 2."""

# shared constants (columns of K)
K_FRAMES, K_N_SUB, K_DT, K_STEP_TIME, K_MIN_HEADWAY, K_LANE_CHANGES, K_ROWS, K_SEE_BEHIND = range(8)
K_SHIELD, K_SHIELD_T, K_SHIELD_B, K_SHIELD_BL, K_SHIELD_MARGIN = range(8, 13)
K_N_FEATURES = 13
"""Number of neighbour features; their NEIGHBOUR_FEATURES codes follow in K_N_FEATURES + 1 ..."""
N_K = K_N_FEATURES + 1 + len(NEIGHBOUR_FEATURES)
# per-env episode values (columns of EP)
EP_TIME, EP_DURATION, EP_U, EP_POWER, EP_ROAD_SEED, EP_SHIELD, EP_GAP = range(7)
N_EP = 7

SCALE = {"v": 30.0, "a": 3.0, "u": 1.0, "power": 50e3, "gear": 6.0, "engine_speed": 600.0, "grade": 0.05,
         "curvature": 0.01, "gap": 100.0, "dv": 30.0}
GAP_CAP = 200.0
"""The observed front gap is capped here [m] (no leader = GAP_CAP)."""
KINEMATICS_FEATURES = ("presence", "x", "y", "vx", "vy")


def traffic_observation_layout(config: EcoTrafficConfig) -> list[tuple[str, str, float]]:
    """(name, SI unit, scale) of each observation entry, in order: the Kinematics block (already normalised to
    [-1, 1]: scale 1) and the powertrain block (observation = value / scale, clipped to [-5, 5])."""
    ranges = {"presence": "1", "x": f"m / {_tm.PERCEPTION_DISTANCE:g} -> [-1, 1]",
              "y": f"m / {LANE_WIDTH * config.lanes_count:g} -> [-1, 1]",
              "vx": f"m/s / {2 * _tm.MAX_SPEED:g} -> [-1, 1]", "vy": f"m/s / {2 * _tm.MAX_SPEED:g} -> [-1, 1]"}
    rows = [(f"{'ego' if r == 0 else f'veh{r}'}_{f}", ranges[f], 1.0)
            for r in range(config.kinematics_rows) for f in KINEMATICS_FEATURES]
    rows += [("v", "m/s", SCALE["v"]), ("a", "m/s^2", SCALE["a"]), ("command", "1", SCALE["u"]),
             ("source_power", "W (mean over the last step)", SCALE["power"]), ("gear", "1", SCALE["gear"]),
             ("engine_speed", "rad/s", SCALE["engine_speed"])]
    rows += [(f"grade@{d:g}m", "rad", SCALE["grade"]) for d in PREVIEW]
    rows += [(f"curvature@{d:g}m", "1/m", SCALE["curvature"]) for d in PREVIEW]
    rows += [("lane", "1 (0 = leftmost, 1 = rightmost)", 1.0),
             ("front_gap", f"m (capped at {GAP_CAP:g})", SCALE["gap"]),
             ("front_closing_speed", "m/s", SCALE["dv"])]
    units = {"ax": ("m/s^2", config.traffic.max_acceleration),
             "lane_change": ("1 (target lane - lane: -1 left, +1 right)", 1.0),
             "cut_in_time": (f"s (capped at {2 * config.traffic.lane_change_delay:g})",
                             2.0 * config.traffic.lane_change_delay)}
    rows += [(f"veh{r}_{f}", *units[f]) for r in range(1, config.kinematics_rows) for f in config.neighbour_features]
    return rows


# --------------------------------------------------------------------------------------------- compiled stages
class TrafficArrays(NamedTuple):
    """Per-sub-env arrays of the compiled step (first axis: sub-env)."""

    vehicles: np.ndarray
    """(N, m, N_V) vehicle rows (roadload.gym.traffic_model.V_*), row 0 the ego."""
    episode: np.ndarray
    """(N, N_EP) episode values (EP_*)."""
    terms: np.ndarray
    """(N, 7) raw reward terms of the last step (TERM_NAMES)."""
    obs: np.ndarray
    """(N, n_obs) float32 observations."""
    look_ahead: np.ndarray
    """(N, 4, len(PREVIEW)) route table at the preview distances (rows: roadload.gym.ecodrive.RouteTable)."""
    order: np.ndarray
    """(N, m) int work array of the Kinematics block's sort."""
    key: np.ndarray
    """(N, m) work array of the Kinematics block's sort."""
    buf: np.ndarray
    """(N, n_obs) observation before scaling."""
    lane_members: np.ndarray
    """(N, lanes, m) int work array of the frame's lane index (traffic_model.index_lanes)."""
    lane_counts: np.ndarray
    """(N, lanes) int work array: vehicles on each lane."""


class TrafficConstants(NamedTuple):
    """What the whole batch shares: the driver models (B_*), the road (G_*), the step (K_*), the reward weights,
    the observation scales and preview, and the spawn constants (limit, delta low / high, decision delay)."""

    behaviour: np.ndarray
    road: np.ndarray
    step: np.ndarray
    weights: np.ndarray
    scale: np.ndarray
    preview: np.ndarray
    spawn: np.ndarray


class StepOutput(NamedTuple):
    """What one step returns per sub-env (fresh arrays every step: an info a user keeps is never overwritten)."""

    reward: np.ndarray
    terminated: np.ndarray
    truncated: np.ndarray
    info: np.ndarray
    """(N_INFO, N): INFO_KEYS rows, then the terms."""


@kernel(refcount=False)
def envelope_command(gap, v, v_lead, reaction_time, deceleration, leader_deceleration, margin):
    """The shield's cap on the command: SHIELD_GAIN (v_safe - v) [1], v_safe [m/s] the speed that solves
    v T + v^2 / (2 b) = gap - margin + v_l^2 / (2 b_l) (0 when the right side is <= 0): reacting after T and
    braking at b, the ego stops ``margin`` behind a leader at v_l that brakes at b_l (gap bumper to bumper [m])."""
    room = gap - margin + v_lead * v_lead / (2.0 * leader_deceleration)
    if room <= 0.0:
        return SHIELD_GAIN * (0.0 - v)
    t = reaction_time
    v_safe = deceleration * (-t + math.sqrt(t * t + 2.0 * room / deceleration))
    return SHIELD_GAIN * (v_safe - v)


SPAWN_MODES = ("highway-env", "outside-envelope", "stopping-gap")
"""``spawn`` values in the order of their code in the spawn constants."""


@kernel(refcount=False)
def envelope_gap(v, v_lead, reaction_time, deceleration, leader_deceleration, margin):
    """The shortest bumper-to-bumper gap [m] at which the envelope of :func:`envelope_command` lets the ego drive
    at v behind a leader at v_l: margin + v T + v^2 / (2 b) - v_l^2 / (2 b_l) (v_safe = v there), at least 0."""
    need = margin + v * reaction_time + v * v / (2.0 * deceleration) - v_lead * v_lead / (2.0 * leader_deceleration)
    return max(need, 0.0)


@kernel(refcount=False)
def spawn_outside_envelope(veh, m, reaction_time, deceleration, leader_deceleration, margin):
    """Stage 'spawn outside the envelope' (``spawn='outside-envelope'``): the ego (row 0) moved back along its lane
    until the gap to the nearest vehicle ahead on it is :func:`envelope_gap` at the two speeds, so that the
    safety layer does not bind at the first step (highway-env's spawn puts the ego at its initial speed 15-20 m
    behind slower traffic, inside any braking envelope). Every traffic vehicle spawns ahead of the ego, so the
    move back frees a gap without closing another one. Returns the distance moved [m]."""
    lead = neighbours(veh, m, 0, int(veh[0, V_LANE]))[0]
    if lead < 0:
        return 0.0
    gap = veh[lead, V_X] - veh[0, V_X] - _tm.LENGTH
    need = envelope_gap(veh[0, V_SPEED], veh[lead, V_SPEED], reaction_time, deceleration, leader_deceleration,
                        margin)
    if gap >= need:
        return 0.0
    veh[0, V_X] -= need - gap
    return need - gap


@kernel(refcount=False)
def shield_cap(veh, K):
    """Stage 'shield': the lowest :func:`envelope_command` behind the ego's leader on its lane and, while
    changing, on its target lane (1 without a leader)."""
    m = veh.shape[0]
    cap = 1.0
    for lane_k in range(2):
        lane = int(veh[0, V_LANE]) if lane_k == 0 else int(veh[0, V_TARGET_LANE])
        if lane_k == 1 and lane == int(veh[0, V_LANE]):
            break
        f = neighbours(veh, m, 0, lane)[0]
        if f < 0:
            continue
        gap = veh[f, V_X] - veh[0, V_X] - _tm.LENGTH
        v_l = max(veh[f, V_SPEED] * math.cos(veh[f, V_HEADING] - veh[0, V_HEADING]), 0.0)
        cap = min(cap, envelope_command(gap, veh[0, V_SPEED], v_l, K[K_SHIELD_T], K[K_SHIELD_B], K[K_SHIELD_BL],
                                        K[K_SHIELD_MARGIN]))
    return cap


@kernel(forceinline=True, refcount=False)
def _observe(i, ego, tr, c):
    """Stage 'observation' of sub-env i -> tr.obs[i] (float32): the Kinematics block, then the powertrain block
    (value / scale, clipped to [-5, 5]), the route table read at the ego's position first."""
    veh = tr.vehicles[i]
    m = veh.shape[0]
    lanes = int(c.road[_tm.G_LANES])
    K = c.step
    t, s, v, a, energy, mass, climb, gear, omega = ego_state(ego, i)
    la = tr.look_ahead[i]
    ego_look_ahead(ego, i, c.preview, s, la)
    buf = tr.buf[i]
    rows = int(K[K_ROWS])
    kinematics_block(veh, m, lanes, rows, K[K_SEE_BEHIND] > 0.5, tr.order[i], tr.key[i], buf)
    k = rows * 5
    gap, closing = front_gap(veh, m)
    e = tr.episode[i]
    buf[k] = v
    buf[k + 1] = a
    buf[k + 2] = e[EP_U]
    buf[k + 3] = e[EP_POWER]
    buf[k + 4] = gear
    buf[k + 5] = omega
    k += 6
    n_pre = la.shape[1]
    for r in range(2):
        for j in range(n_pre):
            buf[k + r * n_pre + j] = la[r, j]
    k += 2 * n_pre
    buf[k] = veh[0, V_LANE] / max(lanes - 1, 1)
    buf[k + 1] = min(gap, GAP_CAP)
    buf[k + 2] = closing
    if K[K_N_FEATURES] > 0.5:
        neighbour_block(veh, m, rows, tr.order[i], c, tr.lane_members[i], tr.lane_counts[i], buf, k + 3)
    e[EP_GAP] = gap
    out = tr.obs[i]
    scale = c.scale
    for j in range(buf.size):
        o = buf[j] / scale[j]
        out[j] = np.float32(-5.0 if o < -5.0 else (5.0 if o > 5.0 else o))


@kernel(refcount=False)
def neighbour_block(veh, m, rows, order, c, members, counts, buf, k):
    """Stage 'neighbour features' -> buf[k:]: for each observed vehicle (the Kinematics block's rows 1 on, order
    from :func:`kinematics_block`; zeros for missing rows), the features coded in K (NEIGHBOUR_FEATURES): its
    acceleration command a [m/s^2], target lane - lane, and traffic_model.cut_in_time into the ego's lane [s]
    (MOBIL on the present positions' lane index); a missing row reads 0, its cut-in time the cap."""
    K = c.step
    n_f = int(K[K_N_FEATURES])
    lanes = int(c.road[_tm.G_LANES])
    cap = 2.0 * c.behaviour[_tm.B_DELAY]
    ego_lane = int(veh[0, V_LANE])
    _tm.index_lanes(veh, m, lanes, members, counts)
    for r in range(rows - 1):
        present = buf[(r + 1) * 5] > 0.5
        j = order[r]
        for f in range(n_f):
            code = int(K[K_N_FEATURES + 1 + f])
            x = cap if code == 2 else 0.0  # a missing row: nobody to cut in
            if present and code == 0:
                x = veh[j, _tm.V_ACC]
            elif present and code == 1:
                x = veh[j, V_TARGET_LANE] - veh[j, V_LANE]
            elif present:
                x = _tm.cut_in_time(veh, members, counts, c.behaviour, c.road[_tm.G_LIMIT], j, ego_lane, cap)
            buf[k + r * n_f + f] = x


@kernel(forceinline=True, refcount=False)
def _gather_info(i, ego, tr, with_terms, info):
    """Stage 'info' of sub-env i -> column i of the info block (INFO_KEYS, then the terms, zero without)."""
    t, s, v, a, energy, mass, climb, gear, omega = ego_state(ego, i)
    veh = tr.vehicles[i]
    e = tr.episode[i]
    info[0, i] = v
    info[1, i] = veh[0, V_CRASHED]
    info[2, i] = veh[0, V_LANE]
    info[3, i] = s
    info[4, i] = t
    info[5, i] = energy
    info[6, i] = e[EP_GAP]
    info[7, i] = e[EP_ROAD_SEED]
    info[8, i] = e[EP_SHIELD]
    terms = tr.terms[i]
    for k in range(7):
        info[I_TERMS + k, i] = terms[k] if with_terms else 0.0


@kernel(forceinline=True, refcount=False)
def _frame(i, ui, ego, tr, c, work):
    """One traffic frame of sub-env i under the command ui: the traffic decides (MOBIL, IDM, steering; the ego
    steers to its target lane); the ego's powertrain runs n_sub substeps under the wheel force of ui at the
    frame's starting speed and the ego moves the distance driven along its heading; the terms accumulate
    (distance, source energy, mechanical energy 0.5 m v^2 + m g h, jerk^2 dt, the headway deficit
    (h_min - gap / max(v, 1))+ dt behind the leader before the traffic moves); the traffic moves; the ego is tested
    for collisions. Returns whether the ego crashed."""
    veh = tr.vehicles[i]
    m = veh.shape[0]
    K = c.step
    dt = K[K_DT]
    tm = tr.terms[i]
    members = tr.lane_members[i]
    counts = tr.lane_counts[i]
    traffic_act(veh, m, c.behaviour, c.road, members, counts)
    t0, s0, v0, a0, en0, mass0, climb0, g0, w0 = ego_state(ego, i)
    ego_advance(ego, i, ui, int(K[K_N_SUB]))
    t1, s1, v1, a1, en1, mass1, climb1, g1, w1 = ego_state(ego, i)
    move(veh, 0, int(c.road[_tm.G_LANES]), dt, s1 - s0)
    veh[0, V_SPEED] = v1
    tm[0] += s1 - s0
    tm[1] += en1 - en0
    tm[2] += 0.5 * mass1 * (v1 * v1 - v0 * v0) + climb1 - climb0
    jerk = (a1 - a0) / dt
    tm[5] += jerk * jerk * dt
    h_min = K[K_MIN_HEADWAY]
    if h_min > 0.0:
        # the lane index still holds: only the ego (whom the search skips) has moved
        gap, closing = leader_gap(veh, lane_neighbours(veh, members, counts, 0, int(veh[0, V_LANE]))[0])
        headway = gap / max(v1, 1.0)
        if headway < h_min:
            tm[4] += (h_min - headway) * dt
    traffic_move(veh, m, c.road, dt)
    return ego_collisions(veh, m, dt, work)


@kernel(refcount=False)
def _step_range(lo, hi, active, u, lane_request, ego, tr, c, out, work):
    """One env step of sub-envs lo..hi-1 as named stages: action (clip, lane request, shield), frames
    (:func:`_frame`), done flags, reward, observation, info. A sub-env that is not active (reset in this step:
    next-step autoreset) gets reward 0, no done flags and its info only. Weights W = (progress, energy,
    mechanical, collision, headway, jerk, lane_change, scale)."""
    K = c.step
    W = c.weights
    lanes = int(c.road[_tm.G_LANES])
    for i in range(lo, hi):
        veh = tr.vehicles[i]
        e = tr.episode[i]
        tm = tr.terms[i]
        for k in range(7):
            tm[k] = 0.0
        if not active[i]:
            out.reward[i] = 0.0
            out.terminated[i] = False
            out.truncated[i] = False
            _gather_info(i, ego, tr, False, out.info)
            continue
        # stage 'action': u clipped to [-1, 1]; a lane request moves the target lane by one (if it exists)
        ui = u[i]
        ui = -1.0 if ui < -1.0 else (1.0 if ui > 1.0 else ui)
        if K[K_LANE_CHANGES] > 0.5 and lane_request[i] != 0:
            target = int(veh[0, V_TARGET_LANE]) + lane_request[i]
            target = 0 if target < 0 else (lanes - 1 if target > lanes - 1 else target)
            if target != int(veh[0, V_TARGET_LANE]) and abs(veh[0, V_Y] - target * LANE_WIDTH) <= 2 * LANE_WIDTH:
                veh[0, V_TARGET_LANE] = target
                tm[6] = 1.0
        # stage 'shield': u <= SHIELD_GAIN (v_safe - v), at least full braking
        e[EP_SHIELD] = 0.0
        if K[K_SHIELD] > 0.5:
            cap = shield_cap(veh, K)
            if cap < ui:
                ui = max(cap, -1.0)
                e[EP_SHIELD] = 1.0
        # stage 'frames'
        crashed = False
        energy0 = ego_state(ego, i)[4]
        for _ in range(int(K[K_FRAMES])):
            if _frame(i, ui, ego, tr, c, work):
                crashed = True
                break
        tm[3] = 1.0 if crashed else 0.0
        # stage 'done flags': a crash terminates; the duration or the road's end truncates
        e[EP_TIME] += K[K_STEP_TIME]
        out.terminated[i] = crashed
        out.truncated[i] = (not crashed) and (e[EP_TIME] >= e[EP_DURATION] or ego_at_road_end(ego, i))
        # stage 'reward'
        out.reward[i] = W[7] * (W[0] * tm[0] - W[1] * tm[1] + W[2] * tm[2] - W[3] * tm[3] - W[4] * tm[4]
                                - W[5] * tm[5] - W[6] * tm[6])
        e[EP_U] = ui
        e[EP_POWER] = (ego_state(ego, i)[4] - energy0) / K[K_STEP_TIME]
        # stage 'observation' and stage 'info'
        _observe(i, ego, tr, c)
        _gather_info(i, ego, tr, True, out.info)


@kernel(parallel=True)
def _step_threads(n_chunks, active, u, lane_request, ego, tr, c, out, work):
    """_step_range over n_chunks contiguous blocks of sub-envs, one numba thread each."""
    n = active.shape[0]
    for k in prange(n_chunks):
        _step_range(k * n // n_chunks, (k + 1) * n // n_chunks, active, u, lane_request, ego, tr, c, out, work[k])


@kernel(refcount=False)
def spawn_traffic(vi, uniforms, lanes, initial_speed, limit, density, delta_low, delta_high, delay):
    """Stage 'spawn': the ego (row 0) and the traffic vehicles placed as EcoHighway-v0 places them (highway-env's
    Vehicle.create_random), from ``uniforms`` (U(0, 1): the m lanes, the m spacing factors, then the speeds and the
    speed exponents of the m - 1 traffic vehicles): the ego on a random lane at x = (3 + f_0) o_0 (at least
    EGO_START), each traffic vehicle on a random lane f_k o_k ahead of the one before, with f = U(0.9, 1.1),
    o = spacing (12 m + v 1 s) exp(-5 lanes / 40) (spacing EGO_SPACING for the ego, 1 / density for the
    traffic), traffic speeds U(0.7, 0.8) x the limit (also their desired speeds), IDM exponents
    U(delta_low, delta_high), decision timers (x + y) pi mod the delay."""
    m = vi.shape[0]
    crowding = math.exp(-5.0 / 40.0 * lanes)
    for j in range(m):
        for col in range(N_V):
            vi[j, col] = 0.0
        lane = min(int(uniforms[j] * lanes), lanes - 1)
        vi[j, V_Y] = lane * LANE_WIDTH
        vi[j, V_LANE] = lane
        vi[j, V_TARGET_LANE] = lane
    f0 = 0.9 + 0.2 * uniforms[m]
    offset0 = EGO_SPACING * (12.0 + initial_speed) * crowding
    x = 3.0 * offset0 + offset0 * f0
    if x < EGO_START:
        x += EGO_START
    vi[0, V_X] = x
    vi[0, V_SPEED] = initial_speed
    vi[0, V_TARGET_SPEED] = initial_speed
    for j in range(1, m):
        speed = 0.7 * limit + 0.1 * limit * uniforms[2 * m + j - 1]
        x += (1.0 / density) * (12.0 + speed) * crowding * (0.9 + 0.2 * uniforms[m + j])
        vi[j, V_X] = x
        vi[j, V_SPEED] = speed
        vi[j, V_TARGET_SPEED] = speed
        vi[j, V_DELTA] = delta_low + (delta_high - delta_low) * uniforms[3 * m + j - 2]
        vi[j, V_TIMER] = ((x + vi[j, V_Y]) * math.pi) % delay


@kernel(refcount=False)
def _start_episodes(index, uniforms, params, rows, random_states, ego, starts, tr, c, info):
    """The start of an episode for sub-envs ``index``: the ego at its road's start (start ``rows[r]`` of the bank,
    the effects' random state; traffic_ego.start_ego), traffic spawned from their uniforms, episode values zeroed
    (params = initial speed, density, duration, road seed), the first observation and info."""
    lanes = int(c.road[_tm.G_LANES])
    sp = c.spawn
    for r in range(index.size):
        i = index[r]
        p = params[r]
        start_ego(ego, i, starts, rows[r], random_states[r])
        spawn_traffic(tr.vehicles[i], uniforms[r], lanes, p[0], sp[0], p[1], sp[1], sp[2], sp[3])
        if sp[4] > 0.5:
            K = c.step
            # 'stopping-gap' (2): the envelope of a leader at rest, b_l -> inf drops its v_l^2 / (2 b_l)
            b_lead = K[K_SHIELD_BL] if sp[4] < 1.5 else math.inf
            spawn_outside_envelope(tr.vehicles[i], tr.vehicles.shape[1], K[K_SHIELD_T], K[K_SHIELD_B], b_lead,
                                   K[K_SHIELD_MARGIN])
        e = tr.episode[i]
        for col in range(e.size):
            e[col] = 0.0
        e[EP_DURATION] = p[2]
        e[EP_ROAD_SEED] = p[3]
        for col in range(tr.terms.shape[1]):
            tr.terms[i, col] = 0.0
        _observe(i, ego, tr, c)
        _gather_info(i, ego, tr, False, info)


@kernel(refcount=False)
def _read_actions(actions, tol, u, lane):
    """Stage 'actions' of the vector env: the batched actions (n, d) -> u (n,), entry 0 rounded to float32 (the
    action space's dtype), and lane (n,), -1 / 0 / +1 of entry 1 (< -1/3: left, > 1/3: right; 0 when d = 1).
    Returns False (u and lane partly written) at the first entry that is not finite or outside [-1 - tol, 1 + tol]."""
    n, d = actions.shape
    for i in range(n):
        for j in range(d):
            x = actions[i, j]
            if not (x >= -1.0 - tol and x <= 1.0 + tol):
                return False
        u[i] = np.float64(np.float32(actions[i, 0]))
        lane[i] = 0
        if d > 1:
            y = np.float64(np.float32(actions[i, 1]))
            lane[i] = -1 if y < -1.0 / 3.0 else (1 if y > 1.0 / 3.0 else 0)
    return True


# --------------------------------------------------------------------------------------------- the batch
class TrafficBatch:
    """N EcoTraffic-v0 episodes in per-env arrays, stepped by one compiled call (shared by the single and the
    vector env). ``config``: the shared configuration (spaces, frequencies, reward, traffic model, shield);
    sub-envs may differ in the fields of PER_ENV_FIELDS."""

    PER_ENV_FIELDS = ("road", "road_seed", "road_seed_range", "curvature", "initial_speed", "vehicles_density",
                      "duration", "effects")
    """Fields sub-envs may set apart (reset options); the others are the batch's."""

    def __init__(self, n: int, config: EcoTrafficConfig, threads: int = 1) -> None:
        self.n = n
        self.threads = threads
        self.config = config
        self.configs = [config] * n
        self.m = config.vehicles_count + 1
        self.layout = traffic_observation_layout(config)
        self.n_obs = len(self.layout)
        m = self.m
        self.arrays = TrafficArrays(vehicles=np.zeros((n, m, N_V)), episode=np.zeros((n, N_EP)),
                                    terms=np.zeros((n, 7)), obs=np.zeros((n, self.n_obs), dtype=np.float32),
                                    look_ahead=np.zeros((n, 4, PREVIEW.size)), order=np.zeros((n, m), np.int64),
                                    key=np.zeros((n, m)), buf=np.zeros((n, self.n_obs)),
                                    lane_members=np.zeros((n, config.lanes_count, m), np.int64),
                                    lane_counts=np.zeros((n, config.lanes_count), np.int64))
        self.ego = EgoBatch(n, config.vehicle)
        self.work = np.zeros((max(threads, 1), 2, 5, 2))
        self._reset_info = np.zeros((N_INFO, n))
        self._set_shared(config)

    @property
    def veh(self) -> np.ndarray:
        return self.arrays.vehicles

    @property
    def obs(self) -> np.ndarray:
        return self.arrays.obs

    def _set_shared(self, cfg: EcoTrafficConfig) -> None:
        self.config = cfg
        sh = cfg.shield
        w = cfg.reward
        step = np.array([cfg.frames_per_action, cfg.n_substeps, 1.0 / cfg.simulation_frequency,
                         1.0 / cfg.policy_frequency, cfg.min_time_headway, cfg.lane_changes == "box",
                         cfg.kinematics_rows, cfg.see_behind, sh.enabled, sh.reaction_time, sh.deceleration,
                         sh.leader_deceleration, sh.margin, len(cfg.neighbour_features)]
                        + [NEIGHBOUR_FEATURES.index(f) for f in cfg.neighbour_features]
                        + [-1] * (len(NEIGHBOUR_FEATURES) - len(cfg.neighbour_features)), dtype=np.float64)
        self.constants = TrafficConstants(
            behaviour=behaviour_array(cfg.traffic),
            road=np.array([cfg.lanes_count, cfg.speed_limit], dtype=np.float64),
            step=step,
            weights=np.array([w.progress, w.energy, w.mechanical_energy, w.collision, w.headway, w.jerk,
                              w.lane_change, w.scale]),
            scale=np.array([row[2] for row in self.layout]),
            preview=PREVIEW.copy(),
            spawn=np.array([cfg.speed_limit, cfg.traffic.delta_range[0], cfg.traffic.delta_range[1],
                            cfg.traffic.lane_change_delay, SPAWN_MODES.index(cfg.spawn)]))

    def shared_changes(self, cfg: EcoTrafficConfig) -> list[str]:
        """Fields that differ from the shared configuration outside PER_ENV_FIELDS."""
        base = self.config.model_dump()
        new = cfg.model_dump()
        return [k for k in new if k not in self.PER_ENV_FIELDS and new[k] != base[k]]

    def reset(self, index: list[int], rngs: list[np.random.Generator], cfgs: list[EcoTrafficConfig]) -> None:
        """New episodes of sub-envs ``index``, each drawn from its generator (one block of uniforms: the
        traffic's, the road seed's unless the config fixes it, the seed of the ego's effect noise) under its
        config."""
        k = len(index)
        n_u = 4 * self.m - 2
        uniforms = np.empty((k, n_u + 2))
        params = np.empty((k, 4))
        roads = []
        noise_seeds = []
        keys: dict[int, tuple] = {}  # per config object: its road key and values
        for r, (i, g, cfg) in enumerate(zip(index, rngs, cfgs)):
            known = keys.get(id(cfg))
            if known is None:
                if cfg.vehicle != self.config.vehicle:
                    raise GymConfigError(f"options.vehicle: the batch runs one vehicle ({self.config.vehicle!r}), "
                                         f"got {cfg.vehicle!r}; make a new env")
                known = keys[id(cfg)] = (road_key(cfg), cfg.road_seed, cfg.road_seed_range, cfg.initial_speed,
                                         cfg.vehicles_density, cfg.duration)
            base, fixed_seed, (low, high), v0, density, duration = known
            u = uniforms[r]
            u[:] = g.random(n_u + 2)  # the traffic's uniforms, then the road seed's and the effect noise seed's
            road_seed = fixed_seed if fixed_seed is not None else low + min(int(u[n_u] * (high - low)),
                                                                            high - low - 1)
            roads.append(ego_road(cfg, road_seed, base))
            noise_seeds.append(int(u[n_u + 1] * 2.0 ** 63))
            self.configs[i] = cfg
            params[r] = (v0, density, duration, road_seed)
        rows, random_states = self.ego.prepare(index, roads, noise_seeds)
        self._reset_info = np.zeros((N_INFO, self.n))
        _start_episodes(np.asarray(index, dtype=np.int64), uniforms, params, rows, random_states, self.ego.records,
                        self.ego.starts.records, self.arrays, self.constants, self._reset_info)

    def step(self, active: np.ndarray, u: np.ndarray, lane_request: np.ndarray) -> StepOutput:
        """The compiled step of every sub-env (active ones move)."""
        n = self.n
        out = StepOutput(np.empty(n), np.empty(n, dtype=bool), np.empty(n, dtype=bool), np.empty((N_INFO, n)))
        if self.threads > 1:
            _step_threads(self.threads, active, u, lane_request, self.ego.records, self.arrays, self.constants, out,
                          self.work)
        else:
            _step_range(0, n, active, u, lane_request, self.ego.records, self.arrays, self.constants, out,
                        self.work[0])
        return out

    @staticmethod
    def info_values(block: np.ndarray, i: int, with_terms: bool) -> dict[str, Any]:
        """The single env's info dict of column i."""
        out: dict[str, Any] = {}
        for r, key in enumerate(INFO_KEYS):
            x = float(block[r, i])
            out[key] = bool(x > 0.5) if key in _BOOL_INFO else (int(x) if key in _INT_INFO else x)
        out["terms"] = {k: float(block[I_TERMS + j, i]) if with_terms else 0.0 for j, k in enumerate(TERM_NAMES)}
        return out


def _action_space(cfg: EcoTrafficConfig) -> spaces.Box:
    return spaces.Box(-1.0, 1.0, shape=(1 if cfg.lane_changes == "off" else 2,), dtype=np.float32)


def _observation_space(n_obs: int) -> spaces.Box:
    return spaces.Box(-5.0, 5.0, shape=(n_obs,), dtype=np.float32)


def _lane_requests(a: np.ndarray) -> np.ndarray:
    """-1 (left) / 0 / +1 (right) of the second action entries."""
    return np.where(a < -1.0 / 3.0, -1, np.where(a > 1.0 / 3.0, 1, 0)).astype(np.int64)


# --------------------------------------------------------------------------------------------- the single env
class EcoTrafficEnv(gym.Env):
    """One EcoTraffic-v0 episode at a time (module docstring): the compiled batch step on a batch of one.
    ``gymnasium.make("roadload/EcoTraffic-v0", config={...})`` or keyword overrides; ``reset(options={...})`` may
    change every field that does not shape the spaces (SPACE_FIELDS_TRAFFIC) or the vehicle."""

    metadata: dict[str, Any] = {"render_modes": []}

    def __init__(self, config: EcoTrafficConfig | dict | None = None, render_mode: str | None = None,
                 **overrides: Any) -> None:
        super().__init__()
        if render_mode is not None:
            raise GymConfigError(f"render_mode: EcoTraffic-v0 does not render, got {render_mode!r}; "
                                 f"EcoHighway-v0 renders the same scenario")
        cfg: EcoTrafficConfig = make_config(EcoTrafficConfig, config, **overrides)
        self._batch = TrafficBatch(1, cfg)
        self.layout = self._batch.layout
        self.action_space = _action_space(cfg)
        self.observation_space = _observation_space(self._batch.n_obs)
        self._active = np.ones(1, dtype=bool)
        # build the first road now: a bad vehicle, road or effect fails at construction, not at reset
        ego_road(cfg, cfg.road_seed if cfg.road_seed is not None else cfg.road_seed_range[0])

    @property
    def config(self) -> EcoTrafficConfig:
        return self._batch.config

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        super().reset(seed=seed)
        cfg = updated_config(self._batch.config, options, SPACE_FIELDS_TRAFFIC)
        if cfg.vehicle != self._batch.config.vehicle:
            self._batch = TrafficBatch(1, cfg)
        elif self._batch.shared_changes(cfg):
            self._batch._set_shared(cfg)
        self._batch.reset([0], [self.np_random], [cfg])
        return self._batch.obs[0].copy(), TrafficBatch.info_values(self._batch._reset_info, 0, False)

    def step(self, action):
        a = validate_action(action, self.action_space)
        u = np.array([float(a[0])])
        lane = _lane_requests(a[1:2]) if a.size > 1 else np.zeros(1, dtype=np.int64)
        reward, term, trunc, info = self._batch.step(self._active, u, lane)
        return (self._batch.obs[0].copy(), float(reward[0]), bool(term[0]), bool(trunc[0]),
                TrafficBatch.info_values(info, 0, True))

    @property
    def vehicles(self) -> np.ndarray:
        """The vehicles' state rows (columns roadload.gym.traffic_model.VEHICLE_COLUMNS; row 0 the ego), a copy."""
        return self._batch.veh[0].copy()

    @property
    def ego(self) -> dict[str, Any]:
        """The ego's powertrain state as named SI values."""
        return _ego.describe(self._batch.ego, 0)

    @property
    def road_profile(self):
        """The ego's road in this episode."""
        return self._batch.ego.loaded(0).profile


# --------------------------------------------------------------------------------------------- the vector env
class EcoTrafficVectorEnv(gym.vector.VectorEnv):
    """N EcoTraffic-v0 sub-environments in one compiled call (module docstring). ``autoreset_mode``:
    'next_step' (default) or 'same_step'; ``threads``: numba threads splitting the sub-envs."""

    metadata = {"render_modes": [], "autoreset_mode": gym.vector.AutoresetMode.NEXT_STEP}

    def __init__(self, num_envs: int = 1, config: EcoTrafficConfig | dict | None = None,
                 autoreset_mode: str | gym.vector.AutoresetMode = "next_step", threads: int = 1,
                 **overrides: Any) -> None:
        num_envs, threads = batched.check_counts(num_envs, threads)
        mode = batched.autoreset_mode(autoreset_mode)
        self.autoreset_mode = mode
        self.metadata = {**self.metadata, "autoreset_mode": mode}
        self.threads = min(threads, num_envs)
        if self.threads > 1:
            _prefer_passive_openmp_wait()
        cfg: EcoTrafficConfig = make_config(EcoTrafficConfig, config, **overrides)
        self.num_envs = int(num_envs)
        self._batch = TrafficBatch(self.num_envs, cfg, self.threads)
        self.layout = self._batch.layout
        self.single_action_space = _action_space(cfg)
        self.single_observation_space = _observation_space(self._batch.n_obs)
        self.action_space = gym.vector.utils.batch_space(self.single_action_space, self.num_envs)
        self.observation_space = gym.vector.utils.batch_space(self.single_observation_space, self.num_envs)
        self._rngs = [seeding.np_random()[0] for _ in range(self.num_envs)]
        self._needs_reset = np.ones(self.num_envs, dtype=bool)
        self._all_active = np.ones(self.num_envs, dtype=bool)
        self._u = np.zeros(self.num_envs)
        self._lane = np.zeros(self.num_envs, dtype=np.int64)
        ego_road(cfg, cfg.road_seed if cfg.road_seed is not None else cfg.road_seed_range[0])

    @property
    def config(self) -> EcoTrafficConfig:
        return self._batch.config

    def _reset_envs(self, index: np.ndarray, seeds: list[int | None] | None = None,
                    options: dict[str, Any] | None = None) -> None:
        """New episodes of sub-envs ``index`` (seeding their generators first where a seed is given)."""
        cfgs = []
        for r, i in enumerate(index):
            if seeds is not None and seeds[r] is not None:
                self._rngs[i], _ = seeding.np_random(seeds[r])
            cfg = self._batch.configs[i]
            if options:
                cfg = updated_config(cfg, options, SPACE_FIELDS_TRAFFIC)
                changed = self._batch.shared_changes(cfg)
                if changed:
                    raise GymConfigError(f"reset options {changed}: the vector env applies these to all sub-envs "
                                         f"at construction (make_vec(..., {changed[0]}=...)); per sub-env it takes "
                                         f"{', '.join(TrafficBatch.PER_ENV_FIELDS)}")
            cfgs.append(cfg)
        self._batch.reset([int(i) for i in index], [self._rngs[i] for i in index], cfgs)

    def reset(self, *, seed: int | list[int | None] | None = None, options: dict[str, Any] | None = None):
        """Reset every sub-env (``options['reset_mask']``: only those where it is True)."""
        seeds = batched.sub_env_seeds(seed, self.num_envs)
        mask, opts = batched.reset_mask(options, self.num_envs)
        index = np.flatnonzero(mask)
        self._reset_envs(index, [seeds[i] for i in index], opts)
        self._needs_reset[mask] = False
        return self._batch.obs.copy(), self._info(self._batch._reset_info, mask, None)

    def _actions(self, actions: Any) -> tuple[np.ndarray, np.ndarray]:
        """(command (n,), lane request (n,)) from the batched actions (one compiled pass on the fast path,
        validate_actions first otherwise and for every bad action); the arrays are the env's own, rewritten at
        every step."""
        n = self.num_envs
        space = cast(spaces.Box, self.single_action_space)
        if not (type(actions) is np.ndarray and actions.shape == (n, space.shape[0])
                and actions.dtype in (np.float32, np.float64)
                and _read_actions(actions, BOUND_TOLERANCE, self._u, self._lane)):
            _read_actions(validate_actions(actions, space, n), BOUND_TOLERANCE, self._u, self._lane)
        return self._u, self._lane

    def step(self, actions):
        u, lane = self._actions(actions)
        n = self.num_envs
        reset_now = self._needs_reset
        if reset_now.any():
            active = ~reset_now
            self._reset_envs(np.flatnonzero(reset_now))
            self._needs_reset = np.zeros(n, dtype=bool)
        else:
            active = self._all_active
        reward, term, trunc, block = self._batch.step(active, u, lane)
        info = self._info(block, self._all_active, active)
        if self.autoreset_mode == gym.vector.AutoresetMode.NEXT_STEP:
            self._needs_reset = term | trunc
            return self._batch.obs.copy(), reward, term, trunc, info
        done = term | trunc
        obs = self._batch.obs.copy()
        if done.any():
            final_obs = np.where(done[:, None], obs, 0.0).astype(np.float32)
            self._reset_envs(np.flatnonzero(done))
            obs = self._batch.obs.copy()
            fresh = self._info(self._batch._reset_info, done, None)
            info = {**fresh, "final_obs": final_obs, "_final_obs": done, "final_info": info, "_final_info": done}
        return obs, reward, term, trunc, info

    @staticmethod
    def _info(block: np.ndarray, mask: np.ndarray, with_terms: np.ndarray | None) -> dict[str, Any]:
        """gymnasium vector info: one array per key of the single env's info, '_key' = which sub-envs have it."""
        info: dict[str, Any] = {}
        for r, key in enumerate(INFO_KEYS):
            row = block[r]
            info[key] = row > 0.5 if key in _BOOL_INFO else (row.astype(np.int64) if key in _INT_INFO else row)
            info["_" + key] = mask
        if with_terms is not None and with_terms.any():
            tmask = with_terms & mask
            d: dict[str, Any] = {k: block[I_TERMS + j] for j, k in enumerate(TERM_NAMES)}
            for k in TERM_NAMES:
                d["_" + k] = tmask
            info["terms"] = d
            info["_terms"] = tmask
        return info

    @property
    def vehicles(self) -> np.ndarray:
        """(num_envs, vehicles, columns) vehicle states (roadload.gym.traffic_model.VEHICLE_COLUMNS), a copy."""
        return self._batch.veh.copy()


def make_vector_env(num_envs: int = 1, **kwargs: Any) -> EcoTrafficVectorEnv:
    """The ``vector_entry_point`` of roadload/EcoTraffic-v0 (``gymnasium.make_vec`` passes num_envs + env kwargs)."""
    kwargs.pop("max_episode_steps", None)
    if kwargs.pop("render_mode", None) is not None:
        raise GymConfigError("render_mode: EcoTraffic-v0 does not render")
    return EcoTrafficVectorEnv(num_envs=num_envs, **kwargs)


__all__ = ["EcoTrafficEnv", "EcoTrafficVectorEnv", "TrafficBatch", "make_vector_env", "spawn_traffic",
           "envelope_command", "envelope_gap", "spawn_outside_envelope",
           "traffic_observation_layout", "TERM_NAMES", "INFO_KEYS"]
