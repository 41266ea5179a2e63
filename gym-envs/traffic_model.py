"""Compiled multi-lane traffic: IDM car following, MOBIL lane changes, highway-env's lateral controller and
kinematic bicycle, the ego's collision test and the Kinematics observation, for one env's vehicle array.

The model is highway-env 1.x's (``IDMVehicle`` on a straight ``StraightLane`` road, ``Road.neighbour_vehicles``,
``ControlledVehicle.steering_control``, ``Vehicle.step``, ``utils.are_polygons_intersecting``,
``KinematicObservation``), written again for numba from its equations, on the same coordinates: x along the road,
y across it (lane l centred at y = l w, w = 4 m), heading from the x axis. The lanes have no end (highway-env's road
is 10 km long; an episode of EcoTraffic-v0 stays far from its end). tests/gym/test_traffic_model.py steps both
models from the same states and compares them frame by frame.

One env's vehicles are the rows of ``veh`` (columns V_*); row 0 is the ego, which the traffic sees as a vehicle
like the others (its target speed is its initial speed, as highway-env's ``ControlledVehicle``), but whose speed
comes from roadload's powertrain (roadload.gym.traffic). ``beh`` packs the driver-model constants (B_*,
:func:`behaviour_array`); ``geo`` the road (G_*).

Equations (symbols of roadload.gym.config.TrafficBehaviour):

- IDM: a = a_c (1 - (max(v, 0) / v_0)^delta - (d* / d)^2), d* = d_0 + v T + v dv / (2 sqrt(a_c b)),
  dv = v - v_l cos(psi_l - psi), d = x_l - x (centre to centre); no leader: no interaction term.
- MOBIL, candidate lane c (new leader L', new follower F', old leader L, old follower F; accelerations by the
  deciding vehicle's IDM): refuse if a(F' behind me) < -b_safe; else change if
  a(me behind L') - a(me behind L) + p (a(F' behind me) - a(F' behind L') + a(F behind L) - a(F behind me)) >= gain.
- Lateral control: v_y* = -K_y e_y, psi* = asin(v_y* / v) clipped to +-pi/4, psi_dot* = K_psi wrap(psi* - psi),
  steering delta = atan(2 tan(asin(L/2 psi_dot* / v))), clipped to +-pi/3.
- Kinematic bicycle: beta = atan(tan(delta) / 2), x' = v cos(psi + beta), y' = v sin(psi + beta),
  psi' = v sin(beta) / (L/2), v' = a (explicit Euler at the traffic frame rate).
"""

from __future__ import annotations

import math

import numpy as np

from roadload.envs.batch import asin_small, atan_small, cos_small, dependent_jit, sin_small, tan_small

kernel = dependent_jit(__file__)
"""njit(cache=True) keyed by this module's source (and the simulator core's)."""

# --------------------------------------------------------------------------------------------- constants
LENGTH = 5.0
"""Vehicle length [m] (highway-env's Vehicle.LENGTH)."""
WIDTH = 2.0
"""Vehicle width [m]."""
LANE_WIDTH = 4.0
"""Lane width [m] (highway-env's AbstractLane.DEFAULT_WIDTH)."""
LANE_MARGIN = 1.0
"""A vehicle within LANE_WIDTH / 2 + LANE_MARGIN of a lane's centre line counts as on it for the neighbour search."""
MAX_SPEED = 40.0
"""Speed above which the kinematics pulls back [m/s] (Vehicle.MAX_SPEED)."""
PERCEPTION_DISTANCE = 5.0 * MAX_SPEED
"""Vehicles farther than this [m] are not observed."""
KP_LATERAL = 1.0 / 0.6
"""Lateral-position gain [1/s]."""
KP_HEADING = 1.0 / 0.2
"""Heading gain [1/s]."""
MAX_STEERING = math.pi / 3.0
"""Steering-angle limit [rad]."""
NOT_ZERO = 1e-2
"""highway-env's utils.not_zero: divisors closer to 0 are replaced by +-NOT_ZERO."""

# vehicle columns
V_X, V_Y, V_HEADING, V_SPEED, V_LANE, V_TARGET_LANE, V_TIMER, V_DELTA, V_TARGET_SPEED = range(9)
V_ACC, V_STEER, V_CRASHED, V_IMPACT, V_IMPACT_X, V_IMPACT_Y = range(9, 15)
N_V = 15
VEHICLE_COLUMNS = ("x", "y", "heading", "speed", "lane", "target_lane", "timer", "delta", "target_speed",
                   "acceleration", "steering", "crashed", "impact", "impact_x", "impact_y")

# driver-model constants (TrafficBehaviour)
B_ACC_MAX, B_COMFORT_ACC, B_COMFORT_DEC, B_JAM, B_TIME_GAP, B_POLITENESS, B_MIN_GAIN, B_MAX_BRAKING, B_DELAY = range(9)
B_BRAKING_SCALE = 9
"""2 sqrt(a_c b) [m/s^2], IDM's braking-term denominator, computed once per batch."""
N_B = 10

# road constants
G_LANES, G_LIMIT = range(2)
N_G = 2


def behaviour_array(behaviour) -> np.ndarray:
    """The B_* constants of a roadload.gym.config.TrafficBehaviour (and B_BRAKING_SCALE derived from them)."""
    b = behaviour
    return np.array([b.max_acceleration, b.comfort_acceleration, b.comfort_deceleration, b.jam_distance,
                     b.time_gap, b.politeness, b.lane_change_min_gain, b.lane_change_max_braking,
                     b.lane_change_delay, 2.0 * math.sqrt(b.comfort_acceleration * b.comfort_deceleration)],
                    dtype=np.float64)


# --------------------------------------------------------------------------------------------- small helpers
@kernel(forceinline=True, refcount=False)
def not_zero(x):
    """x, or +-NOT_ZERO when |x| <= NOT_ZERO (utils.not_zero)."""
    if abs(x) > NOT_ZERO:
        return x
    return NOT_ZERO if x >= 0.0 else -NOT_ZERO


@kernel(forceinline=True, refcount=False)
def wrap_to_pi(x):
    """x wrapped into [-pi, pi) (floored modulo, as Python's %). For |x| <= 1, x + pi lies in (0, 2 pi), where the
    floored modulo returns its argument exactly (fmod is exact and needs no sign fix): (x + pi) - pi, the same
    bits without the modulo (the steering law's heading errors are all in this range)."""
    if -1.0 <= x <= 1.0:
        return (x + math.pi) - math.pi
    return ((x + math.pi) % (2.0 * math.pi)) - math.pi


@kernel(forceinline=True, refcount=False)
def _clip(x, lo, hi):
    return lo if x < lo else (hi if x > hi else x)


@kernel(forceinline=True, refcount=False)
def cos_difference(a, b):
    """cos(a - b), without the call for equal angles (cos 0 = 1 exactly: both headings 0 on a straight lane)."""
    return 1.0 if a == b else cos_small(a - b)


@kernel(forceinline=True, refcount=False)
def cos_heading(h):
    """cos h, without the call on a straight heading (cos 0 = 1)."""
    return cos_small(h)


@kernel(forceinline=True, refcount=False)
def sin_heading(h):
    """sin h, without the call on a straight heading (sin +-0 = +-0, h itself)."""
    return sin_small(h)


@kernel(forceinline=True, refcount=False)
def on_lane(veh, j, lane):
    """Whether vehicle j counts as on ``lane``: |y - y_lane| <= w / 2 + margin (the lanes have no end)."""
    return abs(veh[j, V_Y] - lane * LANE_WIDTH) <= LANE_WIDTH / 2.0 + LANE_MARGIN


@kernel(forceinline=True, refcount=False)
def closest_lane(y, lanes):
    """The lane whose centre line is nearest to y (the first of two at equal distance)."""
    best = 0
    best_d = abs(y)
    for lane in range(1, lanes):
        d = abs(y - lane * LANE_WIDTH)
        if d < best_d:
            best = lane
            best_d = d
    return best


# --------------------------------------------------------------------------------------------- neighbours
@kernel(forceinline=True, refcount=False)
def _nearer(veh, k, s, front, rear, front_x, rear_x):
    """One candidate k of the neighbour search at x = s: (front, rear, front_x, rear_x) updated (the tie rules of
    :func:`neighbours`)."""
    x = veh[k, V_X]
    if s <= x:
        if front < 0 or x <= front_x:
            return k, rear, x, rear_x
    elif rear < 0 or x > rear_x:
        return front, k, front_x, x
    return front, rear, front_x, rear_x


@kernel(forceinline=True, refcount=False)
def neighbours(veh, m, j, lane):
    """(leader, follower) of vehicle j on ``lane`` among the vehicles on it (Road.neighbour_vehicles): the
    nearest with x >= x_j (of equal x the last in row order) and the nearest with x < x_j (of equal x the first);
    -1 where there is none. Every row is tested for the lane; :func:`lane_neighbours` reads a lane index."""
    s = veh[j, V_X]
    front, rear, front_x, rear_x = -1, -1, 0.0, 0.0
    for k in range(m):
        if k != j and on_lane(veh, k, lane):
            front, rear, front_x, rear_x = _nearer(veh, k, s, front, rear, front_x, rear_x)
    return front, rear


@kernel(forceinline=True, refcount=False)
def index_lanes(veh, m, lanes, members, counts):
    """Stage 'lane index': the rows on each lane (:func:`on_lane`), in row order -> members[lane, :counts[lane]].
    Valid while no vehicle moves (a frame's decisions), so each neighbour search reads one lane's ~m / lanes
    vehicles instead of testing all m."""
    for lane in range(lanes):
        n = 0
        for k in range(m):
            if on_lane(veh, k, lane):
                members[lane, n] = k
                n += 1
        counts[lane] = n


@kernel(forceinline=True, refcount=False)
def lane_neighbours(veh, members, counts, j, lane):
    """:func:`neighbours` of vehicle j on ``lane`` from the lane index of :func:`index_lanes` (the same rows in the
    same order, so the same result)."""
    s = veh[j, V_X]
    front, rear, front_x, rear_x = -1, -1, 0.0, 0.0
    for r in range(counts[lane]):
        k = members[lane, r]
        if k != j:
            front, rear, front_x, rear_x = _nearer(veh, k, s, front, rear, front_x, rear_x)
    return front, rear


def lane_index_arrays(m: int, lanes: int) -> tuple[np.ndarray, np.ndarray]:
    """Work arrays (members, counts) of :func:`index_lanes` for m vehicles on ``lanes`` lanes."""
    return np.zeros((lanes, m), dtype=np.int64), np.zeros(lanes, dtype=np.int64)


# --------------------------------------------------------------------------------------------- IDM
@kernel(forceinline=True, refcount=False)
def desired_gap(veh, beh, e, f):
    """IDM's desired centre-to-centre distance d* [m] of vehicle e behind vehicle f:
    d* = d_0 + v T + v dv / (2 sqrt(a_c b)), dv = v - v_f cos(psi_f - psi) (the closing speed along e's heading)."""
    v = veh[e, V_SPEED]
    dv = v - veh[f, V_SPEED] * cos_difference(veh[f, V_HEADING], veh[e, V_HEADING])
    return beh[B_JAM] + v * beh[B_TIME_GAP] + v * dv / beh[B_BRAKING_SCALE]


@kernel(forceinline=True, refcount=False)
def free_road_acceleration(veh, beh, delta, limit, e):
    """IDM's free-road term a_c (1 - (max(v, 0) / v_0)^delta) [m/s^2] of vehicle e (e < 0: 0), v_0 = its target
    speed capped at the limit, delta the speed exponent of the vehicle that asks (MOBIL evaluates its neighbours
    with its own model, as highway-env). It does not depend on the leader: a decision computes it once per vehicle
    and reuses it behind every candidate leader (:func:`idm_behind`)."""
    if e < 0:
        return 0.0
    v0 = _clip(veh[e, V_TARGET_SPEED], 0.0, limit)
    return beh[B_COMFORT_ACC] * (1.0 - math.pow(max(veh[e, V_SPEED], 0.0) / abs(not_zero(v0)), delta))


@kernel(forceinline=True, refcount=False)
def idm_behind(veh, beh, free, e, f):
    """IDM acceleration [m/s^2] of vehicle e behind vehicle f, a = a_c (1 - (max(v, 0) / v_0)^delta - (d* / d)^2),
    from e's free-road term ``free`` (:func:`free_road_acceleration`): free - a_c (d* / d)^2 (f < 0: free road;
    e < 0: 0)."""
    if e < 0:
        return 0.0
    acc = free
    if f >= 0:
        d = veh[f, V_X] - veh[e, V_X]
        ratio = desired_gap(veh, beh, e, f) / not_zero(d)
        acc -= beh[B_COMFORT_ACC] * ratio * ratio
    return acc


# --------------------------------------------------------------------------------------------- MOBIL
@kernel(refcount=False)
def mobil(veh, members, counts, beh, limit, j, lane):
    """MOBIL's decision for vehicle j to change into ``lane`` (IDMVehicle.mobil, no route): safety for the new
    follower, then the politeness-weighted acceleration gain against the threshold (neighbours from the frame's
    lane index, :func:`index_lanes`)."""
    delta = veh[j, V_DELTA]
    new_lead, new_follow = lane_neighbours(veh, members, counts, j, lane)
    free = free_road_acceleration(veh, beh, delta, limit, new_follow)
    new_follow_a = idm_behind(veh, beh, free, new_follow, new_lead)
    new_follow_pred_a = idm_behind(veh, beh, free, new_follow, j)
    if new_follow_pred_a < -beh[B_MAX_BRAKING]:
        return False
    old_lead, old_follow = lane_neighbours(veh, members, counts, j, int(veh[j, V_LANE]))
    free = free_road_acceleration(veh, beh, delta, limit, j)
    self_pred_a = idm_behind(veh, beh, free, j, new_lead)
    self_a = idm_behind(veh, beh, free, j, old_lead)
    free = free_road_acceleration(veh, beh, delta, limit, old_follow)
    old_follow_a = idm_behind(veh, beh, free, old_follow, j)
    old_follow_pred_a = idm_behind(veh, beh, free, old_follow, old_lead)
    gain = self_pred_a - self_a + beh[B_POLITENESS] * (new_follow_pred_a - new_follow_a + old_follow_pred_a
                                                        - old_follow_a)
    return gain >= beh[B_MIN_GAIN]


@kernel(forceinline=True, refcount=False)
def lane_policy_due(veh, beh, j):
    """Whether :func:`change_lane_policy` can do anything for vehicle j this frame: it is changing lanes (the
    abort test runs), or its decision timer has passed the delay (MOBIL runs). On ~9 frames in 10 of a vehicle
    neither holds, and the policy returns at once: this test spares the call."""
    return int(veh[j, V_LANE]) != int(veh[j, V_TARGET_LANE]) or beh[B_DELAY] < veh[j, V_TIMER]


@kernel(refcount=False)
def change_lane_policy(veh, m, members, counts, beh, lanes, limit, j):
    """IDMVehicle.change_lane_policy for vehicle j: during a lane change, abort it when another vehicle heads
    for the same lane within the desired gap ahead; otherwise, once the decision timer exceeds the delay, reset it
    and ask MOBIL for the left, then the right lane (the later accepted one wins)."""
    own = int(veh[j, V_LANE])
    target = int(veh[j, V_TARGET_LANE])
    if own != target:
        for k in range(m):
            if k == j or int(veh[k, V_LANE]) == target or int(veh[k, V_TARGET_LANE]) != target:
                continue
            d = veh[k, V_X] - veh[j, V_X]
            if 0.0 < d < desired_gap(veh, beh, j, k):
                veh[j, V_TARGET_LANE] = own
                break
        return
    if not beh[B_DELAY] < veh[j, V_TIMER]:
        return
    veh[j, V_TIMER] = 0.0
    for side in (-1, 1):
        lane = own + side
        if lane < 0 or lane >= lanes:
            continue
        if abs(veh[j, V_Y] - lane * LANE_WIDTH) > 2.0 * LANE_WIDTH:  # not reachable from here
            continue
        if abs(veh[j, V_SPEED]) < 1.0:  # only while moving
            continue
        if mobil(veh, members, counts, beh, limit, j, lane):
            veh[j, V_TARGET_LANE] = lane


@kernel(forceinline=True, refcount=False)
def cut_in_time(veh, members, counts, beh, limit, j, lane, cap):
    """Time [s] until vehicle j turns into ``lane`` by :func:`change_lane_policy`: 0 while it changes into it
    (target lane ``lane``, not yet its lane); on an adjacent lane, moving, with MOBIL accepting ``lane`` at the
    present state, the time left to its next decision, max(delay - timer, 0); else ``cap`` (on ``lane`` already, or
    no change wanted). The lane index (members, counts) must be the present positions' (:func:`index_lanes`)."""
    own = int(veh[j, V_LANE])
    if own == lane:
        return cap
    target = int(veh[j, V_TARGET_LANE])
    if target == lane:
        return 0.0
    if target != own or abs(own - lane) != 1 or abs(veh[j, V_SPEED]) < 1.0:
        return cap  # changing elsewhere, not adjacent, or not moving (change_lane_policy's conditions)
    if abs(veh[j, V_Y] - lane * LANE_WIDTH) > 2.0 * LANE_WIDTH:
        return cap
    if not mobil(veh, members, counts, beh, limit, j, lane):
        return cap
    return min(max(beh[B_DELAY] - veh[j, V_TIMER], 0.0), cap)


# --------------------------------------------------------------------------------------------- lateral control
@kernel(forceinline=True, refcount=False)
def steering_control(veh, j):
    """Steering angle [rad] that brings vehicle j onto its target lane's centre line (module docstring)."""
    v = veh[j, V_SPEED]
    lateral = veh[j, V_Y] - veh[j, V_TARGET_LANE] * LANE_WIDTH
    if lateral == 0.0 and veh[j, V_HEADING] == 0.0:  # on the centre line, straight: every stage below gives 0
        return 0.0
    lateral_speed_command = -KP_LATERAL * lateral
    heading_command = asin_small(_clip(lateral_speed_command / not_zero(v), -1.0, 1.0))
    heading_ref = _clip(heading_command, -math.pi / 4.0, math.pi / 4.0)
    heading_rate_command = KP_HEADING * wrap_to_pi(heading_ref - veh[j, V_HEADING])
    slip = asin_small(_clip(LENGTH / 2.0 / not_zero(v) * heading_rate_command, -1.0, 1.0))
    return _clip(atan_small(2.0 * tan_small(slip)), -MAX_STEERING, MAX_STEERING)


# --------------------------------------------------------------------------------------------- one frame
@kernel(forceinline=True, refcount=False)
def traffic_act(veh, m, beh, geo, members, counts):
    """Decisions of one frame (Road.act), in row order: the lane index of the frame's positions (no vehicle moves
    while the traffic decides; :func:`index_lanes` -> members, counts); the ego (row 0) only steers towards its
    target lane; every traffic vehicle runs MOBIL's lane-change policy, steers, and takes the IDM acceleration
    behind its leader (and behind the leader on its target lane while changing), clipped to +-a_max. Crashed
    vehicles keep their last command (their kinematics brakes them to a stop)."""
    lanes = int(geo[G_LANES])
    limit = geo[G_LIMIT]
    index_lanes(veh, m, lanes, members, counts)
    veh[0, V_STEER] = steering_control(veh, 0)
    for j in range(1, m):
        if veh[j, V_CRASHED] > 0.5:
            continue
        if lane_policy_due(veh, beh, j):
            change_lane_policy(veh, m, members, counts, beh, lanes, limit, j)
        veh[j, V_STEER] = steering_control(veh, j)
        own = int(veh[j, V_LANE])
        free = free_road_acceleration(veh, beh, veh[j, V_DELTA], limit, j)
        acc = idm_behind(veh, beh, free, j, lane_neighbours(veh, members, counts, j, own)[0])
        target = int(veh[j, V_TARGET_LANE])
        if own != target:
            acc = min(acc, idm_behind(veh, beh, free, j, lane_neighbours(veh, members, counts, j, target)[0]))
        veh[j, V_ACC] = _clip(acc, -beh[B_ACC_MAX], beh[B_ACC_MAX])


@kernel(forceinline=True, refcount=False)
def move(veh, j, lanes, dt, distance):
    """Kinematic bicycle step of vehicle j (Vehicle.step): the position advances by ``distance`` along
    psi + beta (the traffic passes v dt; the ego the distance its powertrain drove), a pending collision impact is
    applied (and crashes the vehicle), the heading turns, the lane is updated. The speed is set by the caller."""
    steer = veh[j, V_STEER]
    heading = veh[j, V_HEADING]
    straight = steer == 0.0 and heading == 0.0  # cos 0 = 1 and sin 0 = 0: the same numbers without the trigonometry
    if straight:
        veh[j, V_X] += distance
    else:
        beta = atan_small(0.5 * tan_small(steer))
        veh[j, V_X] += distance * cos_small(heading + beta)
        veh[j, V_Y] += distance * sin_small(heading + beta)
        veh[j, V_HEADING] += veh[j, V_SPEED] * sin_small(beta) / (LENGTH / 2.0) * dt
    if veh[j, V_IMPACT] > 0.5:
        veh[j, V_X] += veh[j, V_IMPACT_X]
        veh[j, V_Y] += veh[j, V_IMPACT_Y]
        veh[j, V_CRASHED] = 1.0
        veh[j, V_IMPACT] = 0.0
        straight = False
    if not straight:
        veh[j, V_LANE] = closest_lane(veh[j, V_Y], lanes)


@kernel(forceinline=True, refcount=False)
def traffic_move(veh, m, geo, dt):
    """Kinematics of the traffic vehicles (rows 1..m-1) over one frame: the decision timer runs, then
    :func:`kinematic_step`."""
    lanes = int(geo[G_LANES])
    for j in range(1, m):
        veh[j, V_TIMER] += dt
        kinematic_step(veh, j, lanes, dt)


@kernel(forceinline=True, refcount=False)
def kinematic_step(veh, j, lanes, dt):
    """Vehicle.step of vehicle j with its acceleration command: crashed vehicles steer straight and brake to a
    stop (a = -v), speeds above MAX_SPEED are pulled back, then the bicycle step and v <- v + a dt."""
    v = veh[j, V_SPEED]
    if veh[j, V_CRASHED] > 0.5:
        veh[j, V_STEER] = 0.0
        veh[j, V_ACC] = -v
    if v > MAX_SPEED:
        veh[j, V_ACC] = min(veh[j, V_ACC], MAX_SPEED - v)
    elif v < -MAX_SPEED:
        veh[j, V_ACC] = max(veh[j, V_ACC], -MAX_SPEED - v)
    move(veh, j, lanes, dt, v * dt)
    veh[j, V_SPEED] = v + veh[j, V_ACC] * dt


# --------------------------------------------------------------------------------------------- collisions
@kernel(forceinline=True, refcount=False)
def _corners(veh, j, out):
    """The rectangle of vehicle j (length x width, rotated by its heading) as 5 points, the first repeated."""
    c = math.cos(veh[j, V_HEADING])
    s = math.sin(veh[j, V_HEADING])
    hl = LENGTH / 2.0
    hw = WIDTH / 2.0
    for p in range(4):
        lx = -hl if p < 2 else hl
        ly = -hw if (p == 0 or p == 3) else hw
        out[p, 0] = c * lx - s * ly + veh[j, V_X]
        out[p, 1] = s * lx + c * ly + veh[j, V_Y]
    out[4, 0] = out[0, 0]
    out[4, 1] = out[0, 1]


@kernel(forceinline=True, refcount=False)
def _project(poly, nx, ny):
    lo = poly[0, 0] * nx + poly[0, 1] * ny
    hi = lo
    for p in range(1, 5):
        q = poly[p, 0] * nx + poly[p, 1] * ny
        if q < lo:
            lo = q
        if q > hi:
            hi = q
    return lo, hi


@kernel(forceinline=True, refcount=False)
def _interval_distance(min_a, max_a, min_b, max_b):
    return min_b - max_a if min_a < min_b else min_a - max_b


@kernel(forceinline=True, refcount=False)
def within_reach(veh, a, b, dt):
    """The sphere pre-check of :func:`rectangles_collide`: the centres of a and b are at most their half diagonals
    plus a's travel v_a dt apart, sqrt(dx^2 + dy^2) <= sqrt(L^2 + W^2) + v_a dt (|dx| first: most pairs are far
    along the road)."""
    dx = veh[b, V_X] - veh[a, V_X]
    dy = veh[b, V_Y] - veh[a, V_Y]
    reach = math.sqrt(LENGTH * LENGTH + WIDTH * WIDTH) + veh[a, V_SPEED] * dt
    return not (abs(dx) > reach or math.sqrt(dx * dx + dy * dy) > reach)


@kernel(refcount=False)
def rectangles_collide(veh, a, b, dt, work):
    """Separating-axis test of vehicles a and b (utils.are_polygons_intersecting): (intersecting now, intersecting
    after both move by their velocity x dt, the push-out vector (x, y) of the smaller overlap). A sphere
    pre-check skips pairs farther apart than their half diagonals plus a's travel."""
    if not within_reach(veh, a, b, dt):
        return False, False, 0.0, 0.0
    pa = work[0]
    pb = work[1]
    _corners(veh, a, pa)
    _corners(veh, b, pb)
    # relative displacement over dt
    ddx = (veh[a, V_SPEED] * math.cos(veh[a, V_HEADING]) - veh[b, V_SPEED] * math.cos(veh[b, V_HEADING])) * dt
    ddy = (veh[a, V_SPEED] * math.sin(veh[a, V_HEADING]) - veh[b, V_SPEED] * math.sin(veh[b, V_HEADING])) * dt
    intersecting = True
    will_intersect = True
    min_distance = np.inf
    axis_x = 0.0
    axis_y = 0.0
    cx = 0.0
    cy = 0.0
    for p in range(4):
        cx += pa[p, 0] - pb[p, 0]
        cy += pa[p, 1] - pb[p, 1]
    for poly_index in range(2):
        poly = pa if poly_index == 0 else pb
        for e in range(4):
            nx = -poly[e + 1, 1] + poly[e, 1]
            ny = poly[e + 1, 0] - poly[e, 0]
            norm = math.sqrt(nx * nx + ny * ny)
            nx /= norm
            ny /= norm
            min_a, max_a = _project(pa, nx, ny)
            min_b, max_b = _project(pb, nx, ny)
            if _interval_distance(min_a, max_a, min_b, max_b) > 0.0:
                intersecting = False
            sweep = nx * ddx + ny * ddy
            if sweep < 0.0:
                min_a += sweep
            else:
                max_a += sweep
            distance = _interval_distance(min_a, max_a, min_b, max_b)
            if distance > 0.0:
                will_intersect = False
            if not intersecting and not will_intersect:
                break
            if abs(distance) < min_distance:
                min_distance = abs(distance)
                sign = 1.0 if (cx * nx + cy * ny) > 0.0 else -1.0
                axis_x = sign * nx
                axis_y = sign * ny
        if not intersecting and not will_intersect:
            break
    if will_intersect:
        return intersecting, True, min_distance * axis_x, min_distance * axis_y
    return intersecting, False, 0.0, 0.0


@kernel(forceinline=True, refcount=False)
def ego_collisions(veh, m, dt, work):
    """The ego's collision test against every other vehicle (RoadObject.handle_collisions; the traffic does not
    test itself, as in highway-fast-v0 and EcoHighway-v0): overlapping now crashes both; overlapping within dt at
    their velocities pushes them apart by half the overlap each at the next frame, which crashes them then.
    Returns whether the ego is crashed."""
    for k in range(1, m):
        if not within_reach(veh, 0, k, dt):  # the test's own pre-check, here to spare the call
            continue
        now, soon, tx, ty = rectangles_collide(veh, 0, k, dt, work)
        if soon:
            veh[0, V_IMPACT] = 1.0
            veh[0, V_IMPACT_X] = tx / 2.0
            veh[0, V_IMPACT_Y] = ty / 2.0
            veh[k, V_IMPACT] = 1.0
            veh[k, V_IMPACT_X] = -tx / 2.0
            veh[k, V_IMPACT_Y] = -ty / 2.0
        if now:
            veh[0, V_CRASHED] = 1.0
            veh[k, V_CRASHED] = 1.0
    return veh[0, V_CRASHED] > 0.5


# --------------------------------------------------------------------------------------------- observation
@kernel(forceinline=True, refcount=False)
def _lmap(v, lo, hi):
    """v mapped from [lo, hi] to [-1, 1] and clipped (utils.lmap + KinematicObservation's clip)."""
    return _clip(-1.0 + (v - lo) * 2.0 / (hi - lo), -1.0, 1.0)


@kernel(refcount=False)
def kinematics_block(veh, m, lanes, rows, see_behind, order, key, out):
    """highway-env's Kinematics observation (KinematicObservation, features presence, x, y, vx, vy, normalised
    and clipped, sorted) of the ego -> out[rows * 5]: row 0 the ego's absolute values, then the nearest
    ``rows - 1`` vehicles within PERCEPTION_DISTANCE (with ``see_behind`` False only those less than 2 lengths
    behind), sorted by |x - x_ego|, relative to the ego; missing rows are zeros. Ranges: x +-PERCEPTION_DISTANCE,
    y +-w x lanes, vx, vy +-2 MAX_SPEED. ``order`` (int, m) and ``key`` (float, m) are work arrays."""
    y_range = LANE_WIDTH * lanes
    v_range = 2.0 * MAX_SPEED
    x0 = veh[0, V_X]
    y0 = veh[0, V_Y]
    vx0 = veh[0, V_SPEED] * cos_heading(veh[0, V_HEADING])
    vy0 = veh[0, V_SPEED] * sin_heading(veh[0, V_HEADING])
    for c in range(rows * 5):
        out[c] = 0.0
    out[0] = 1.0
    out[1] = _lmap(x0, -PERCEPTION_DISTANCE, PERCEPTION_DISTANCE)
    out[2] = _lmap(y0, -y_range, y_range)
    out[3] = _lmap(vx0, -v_range, v_range)
    out[4] = _lmap(vy0, -v_range, v_range)
    n = 0
    for k in range(1, m):
        dx = veh[k, V_X] - x0
        dy = veh[k, V_Y] - y0
        if math.sqrt(dx * dx + dy * dy) >= PERCEPTION_DISTANCE:
            continue
        if not see_behind and not (-2.0 * LENGTH < dx):
            continue
        # stable insertion by |dx| (Python's sorted keeps the row order of equal keys)
        d = abs(dx)
        p = n
        while p > 0 and key[p - 1] > d:
            key[p] = key[p - 1]
            order[p] = order[p - 1]
            p -= 1
        key[p] = d
        order[p] = k
        n += 1
    for r in range(min(n, rows - 1)):
        k = order[r]
        c = (r + 1) * 5
        out[c] = 1.0
        out[c + 1] = _lmap(veh[k, V_X] - x0, -PERCEPTION_DISTANCE, PERCEPTION_DISTANCE)
        out[c + 2] = _lmap(veh[k, V_Y] - y0, -y_range, y_range)
        out[c + 3] = _lmap(veh[k, V_SPEED] * cos_heading(veh[k, V_HEADING]) - vx0, -v_range, v_range)
        out[c + 4] = _lmap(veh[k, V_SPEED] * sin_heading(veh[k, V_HEADING]) - vy0, -v_range, v_range)


@kernel(refcount=False)
def front_gap(veh, m):
    """(bumper-to-bumper gap [m] to the ego's leader on its lane, inf if none; closing speed [m/s], positive when
    approaching), as EcoHighway-v0's ego."""
    return leader_gap(veh, neighbours(veh, m, 0, int(veh[0, V_LANE]))[0])


@kernel(forceinline=True, refcount=False)
def leader_gap(veh, f):
    """:func:`front_gap` behind the ego's leader f (-1: none)."""
    if f < 0:
        return np.inf, 0.0
    gap = veh[f, V_X] - veh[0, V_X] - LENGTH
    return gap, veh[0, V_SPEED] - veh[f, V_SPEED] * cos_difference(veh[f, V_HEADING], veh[0, V_HEADING])


# --------------------------------------------------------------------------------------------- a bare traffic run
@kernel()
def run_traffic(veh, m, beh, geo, dt, frames, work):
    """``frames`` frames of traffic alone, the ego row moved kinematically with its acceleration command like any
    vehicle (no powertrain; the command is kept, braking replaces it after a crash): the reference the fidelity
    test compares with highway-env's Road.act / Road.step."""
    lanes = int(geo[G_LANES])
    acc = veh[0, V_ACC]
    members = np.empty((lanes, m), dtype=np.int64)
    counts = np.empty(lanes, dtype=np.int64)
    for _ in range(frames):
        traffic_act(veh, m, beh, geo, members, counts)
        veh[0, V_ACC] = acc
        kinematic_step(veh, 0, lanes, dt)
        traffic_move(veh, m, geo, dt)
        ego_collisions(veh, m, dt, work)
