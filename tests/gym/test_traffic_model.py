"""The compiled traffic of roadload/EcoTraffic-v0 (roadload.gym.traffic_model): IDM's equilibrium against its
closed form, MOBIL's refusal of occupied gaps, the collision test, and frame-by-frame agreement with highway-env's
own vehicles, collision test and Kinematics observation from the same states."""

import math
from types import SimpleNamespace

import numpy as np
import pytest
from highway_env import utils as hw_utils
from highway_env.envs.common.observation import KinematicObservation
from highway_env.road.road import Road, RoadNetwork
from highway_env.vehicle.behavior import IDMVehicle
from highway_env.vehicle.controller import ControlledVehicle
from highway_env.vehicle.kinematics import Vehicle

from roadload.gym import traffic_model as tm
from roadload.gym.config import TrafficBehaviour
from roadload.gym.traffic import spawn_traffic

BEH = tm.behaviour_array(TrafficBehaviour())
WORK = np.zeros((2, 5, 2))


def _vehicles(rows):
    """A vehicle array from rows of (x, y-lane, speed, target speed, delta[, heading])."""
    veh = np.zeros((len(rows), tm.N_V))
    for j, row in enumerate(rows):
        x, lane, v, v0, delta = row[:5]
        veh[j, [tm.V_X, tm.V_Y, tm.V_SPEED, tm.V_TARGET_SPEED, tm.V_DELTA]] = x, lane * tm.LANE_WIDTH, v, v0, delta
        veh[j, tm.V_LANE] = veh[j, tm.V_TARGET_LANE] = lane
        veh[j, tm.V_HEADING] = row[5] if len(row) > 5 else 0.0
    return veh


def _index(veh, lanes):
    """The lane index (members, counts) of the vehicles' current positions."""
    members, counts = tm.lane_index_arrays(veh.shape[0], lanes)
    tm.index_lanes(veh, veh.shape[0], lanes, members, counts)
    return members, counts


def _act(veh, geo):
    """traffic_act on all rows of veh with fresh lane-index arrays."""
    tm.traffic_act(veh, veh.shape[0], BEH, geo, *tm.lane_index_arrays(veh.shape[0], int(geo[0])))


def _spawned(seed, n=20, lanes=3):
    veh = np.zeros((n + 1, tm.N_V))
    spawn_traffic(veh, np.random.default_rng(seed).random(4 * (n + 1)), lanes, 25.0, 30.0, 1.0, 3.5, 4.5, 1.0)
    return veh


# --------------------------------------------------------------------------------------------- IDM
@pytest.mark.parametrize("v_lead, v0, delta", [(15.0, 25.0, 4.0), (22.0, 24.0, 3.6), (8.0, 30.0, 4.4)])
def test_idm_equilibrium_gap_matches_closed_form(v_lead, v0, delta):
    """Behind a leader at constant speed v on a one-lane road, IDM settles at a = 0, i.e. at the centre distance
    d_eq = (d_0 + v T) / sqrt(1 - (v / v_0)^delta)."""
    # row 0 (the leader, kinematic with a = 0) ahead; row 1 the IDM follower, starting too close and too fast
    veh = _vehicles([(500.0, 0, v_lead, v_lead, 4.0), (440.0, 0, v_lead + 3.0, v0, delta)])
    geo = np.array([1.0, 40.0])
    tm.run_traffic(veh, 2, BEH, geo, 0.1, 6000, WORK)  # 600 s
    b = TrafficBehaviour()
    d_eq = (b.jam_distance + v_lead * b.time_gap) / math.sqrt(1.0 - (v_lead / v0) ** delta)
    gap = veh[0, tm.V_X] - veh[1, tm.V_X]
    assert veh[1, tm.V_SPEED] == pytest.approx(v_lead, abs=1e-9)
    assert gap == pytest.approx(d_eq, abs=1e-6)
    assert not veh[0, tm.V_CRASHED]
    # the same follower on a free road accelerates at a_c (1 - (v / v_0)^delta)
    free = _vehicles([(0.0, 0, 10.0, 10.0, 4.0), (1000.0, 0, 12.0, v0, delta)])
    _act(free, geo)
    assert free[1, tm.V_ACC] == pytest.approx(b.comfort_acceleration * (1 - (12.0 / v0) ** delta), rel=1e-12)


# --------------------------------------------------------------------------------------------- MOBIL
def _stuck_behind_slow_leader(other=None):
    """Vehicle 1 in the middle lane, 30 m behind a slow leader (vehicle 2), MOBIL due; the right lane occupied
    alongside (vehicle 3, 2 m ahead); the left lane empty unless ``other`` = (x, speed) puts a vehicle on it. The
    ego (row 0) is far behind on the right lane."""
    rows = [(0.0, 2, 20.0, 20.0, 4.0), (300.0, 1, 25.0, 25.0, 4.0), (330.0, 1, 15.0, 15.0, 4.0),
            (302.0, 2, 25.0, 25.0, 4.0)]
    if other is not None:
        rows.append((other[0], 0, other[1], other[1], 4.0))
    veh = _vehicles(rows)
    veh[1, tm.V_TIMER] = 2.0  # a decision is due
    return veh


def test_lane_index_search_equals_the_full_search():
    """The neighbour search over the frame's lane index finds the same leader and follower as the search over all
    rows, for every vehicle and lane, with vehicles between lanes (on two lanes at once) and tied positions."""
    rng = np.random.default_rng(4)
    for trial in range(200):
        m = int(rng.integers(1, 30))
        veh = np.zeros((m, tm.N_V))
        veh[:, tm.V_X] = np.round(rng.uniform(0.0, 200.0, m), 0 if trial % 2 else 6)  # whole metres: ties
        veh[:, tm.V_Y] = rng.uniform(-3.0, 11.0, m)
        members, counts = _index(veh, 3)
        assert counts.sum() >= m  # every y in [-3, 11] is on at least one lane
        for j in range(m):
            for lane in range(3):
                assert tm.lane_neighbours(veh, members, counts, j, lane) == tm.neighbours(veh, m, j, lane)


def test_mobil_changes_into_a_free_lane_and_never_into_an_occupied_gap():
    geo = np.array([3.0, 30.0])
    free = _stuck_behind_slow_leader()
    assert tm.mobil(free, *_index(free, 3), BEH, 30.0, 1, 0)  # the incentive is there
    assert not tm.mobil(free, *_index(free, 3), BEH, 30.0, 1, 2)  # but the right lane is occupied alongside
    tm.change_lane_policy(free, free.shape[0], *_index(free, 3), BEH, 3, 30.0, 1)
    assert free[1, tm.V_TARGET_LANE] == 0
    # a vehicle alongside on the left lane, from a length behind to a length ahead: refused every time
    for dx in np.linspace(-tm.LENGTH + 0.01, tm.LENGTH - 0.01, 41):
        for speed in (15.0, 25.0, 30.0):
            veh = _stuck_behind_slow_leader((300.0 + dx, speed))
            assert not tm.mobil(veh, *_index(veh, 3), BEH, 30.0, 1, 0), (dx, speed)
            _act(veh, geo)
            assert veh[1, tm.V_TARGET_LANE] == 1, (dx, speed)


def test_mobil_lane_changes_in_simulated_traffic_keep_the_target_gap_free():
    """Every lane change decided in 40 s of dense traffic (30 spawns, 3 lanes) starts with no vehicle overlapping
    the changing vehicle on the target lane (centre distance below a length)."""
    geo = np.array([3.0, 30.0])
    decided = 0
    for seed in range(30):
        veh = _spawned(seed, n=24)
        m = veh.shape[0]
        veh[0, tm.V_ACC] = 0.0
        for _ in range(400):
            before = veh[:, tm.V_TARGET_LANE].copy()
            _act(veh, geo)
            for j in range(1, m):
                if veh[j, tm.V_TARGET_LANE] == before[j] or veh[j, tm.V_TARGET_LANE] == veh[j, tm.V_LANE]:
                    continue  # no decision, or an aborted change
                lane = int(veh[j, tm.V_TARGET_LANE])
                on = np.abs(veh[:, tm.V_Y] - lane * tm.LANE_WIDTH) <= tm.LANE_WIDTH / 2 + tm.LANE_MARGIN
                on[j] = False
                assert not np.any(on & (np.abs(veh[:, tm.V_X] - veh[j, tm.V_X]) < tm.LENGTH)), (seed, j)
                decided += 1
            veh[0, tm.V_SPEED] = min(veh[0, tm.V_SPEED], 21.0)
            tm.kinematic_step(veh, 0, 3, 0.1)
            tm.traffic_move(veh, m, geo, 0.1)
    assert decided > 20  # the check saw real lane changes


# --------------------------------------------------------------------------------------------- collisions
def test_collision_is_detected_in_a_hand_built_case():
    # the ego at 20 m/s, 1 m (bumper to bumper) behind a stopped car on its lane: overlapping after one frame
    veh = _vehicles([(100.0, 1, 20.0, 20.0, 4.0), (106.0, 1, 0.0, 0.0, 4.0), (104.0, 0, 20.0, 20.0, 4.0)])
    geo = np.array([3.0, 30.0])
    assert not tm.ego_collisions(veh, 3, 0.1, WORK)  # 1 m apart now, but 2 m of closing within the frame
    assert veh[0, tm.V_IMPACT] == 1.0 and veh[1, tm.V_IMPACT] == 1.0 and veh[2, tm.V_IMPACT] == 0.0
    tm.run_traffic(veh, 3, BEH, geo, 0.1, 1, WORK)
    assert veh[0, tm.V_CRASHED] == 1.0 and veh[1, tm.V_CRASHED] == 1.0
    assert veh[2, tm.V_CRASHED] == 0.0  # alongside on the next lane: no contact
    # overlapping now: crashed at once
    veh = _vehicles([(100.0, 1, 20.0, 20.0, 4.0), (103.0, 1, 20.0, 20.0, 4.0)])
    assert tm.ego_collisions(veh, 2, 0.1, WORK)
    # side by side on neighbouring lanes at equal speed: never
    veh = _vehicles([(100.0, 1, 25.0, 25.0, 4.0), (101.0, 0, 25.0, 25.0, 4.0)])
    assert not tm.ego_collisions(veh, 2, 0.1, WORK) and veh[0, tm.V_IMPACT] == 0.0


def test_separating_axis_test_equals_highway_envs():
    rng = np.random.default_rng(3)
    hits = 0
    for _ in range(1200):
        veh = np.zeros((2, tm.N_V))
        veh[:, tm.V_X] = rng.uniform(0, 8, 2)
        veh[:, tm.V_Y] = rng.uniform(0, 4, 2)
        veh[:, tm.V_HEADING] = rng.uniform(-0.6, 0.6, 2)
        veh[:, tm.V_SPEED] = rng.uniform(0, 30, 2)
        mine = tm.rectangles_collide(veh, 0, 1, 0.1, WORK)
        road = Road(RoadNetwork.straight_road_network(3), np_random=np.random.RandomState(0))
        a, b = (Vehicle(road, veh[j, [tm.V_X, tm.V_Y]], veh[j, tm.V_HEADING], veh[j, tm.V_SPEED]) for j in (0, 1))
        if np.linalg.norm(b.position - a.position) > (a.diagonal + b.diagonal) / 2 + a.speed * 0.1:
            ref = (False, False, None)
        else:
            ref = hw_utils.are_polygons_intersecting(a.polygon(), b.polygon(), a.velocity * 0.1, b.velocity * 0.1)
        assert (mine[0], mine[1]) == (ref[0], ref[1])
        if ref[1]:
            assert np.allclose(mine[2:], ref[2], atol=1e-9)
            hits += 1
    assert hits > 120


# --------------------------------------------------------------------------------------------- against highway-env
class _KinematicEgo(ControlledVehicle):
    """highway-env's ego of the comparison: lane keeping, a constant acceleration command."""

    acc = 0.0

    def act(self, action=None):
        self.follow_road()
        steer = float(np.clip(self.steering_control(self.target_lane_index), -self.MAX_STEERING_ANGLE,
                              self.MAX_STEERING_ANGLE))
        Vehicle.act(self, {"steering": steer, "acceleration": self.acc})


def _highway_road(veh, lanes=3, limit=30.0):
    road = Road(network=RoadNetwork.straight_road_network(lanes, speed_limit=limit, length=10_000),
                np_random=np.random.RandomState(0), record_history=False)
    ego = _KinematicEgo(road, veh[0, [tm.V_X, tm.V_Y]].copy(), veh[0, tm.V_HEADING], veh[0, tm.V_SPEED])
    ego.acc = veh[0, tm.V_ACC]
    road.vehicles.append(ego)
    for j in range(1, veh.shape[0]):
        v = IDMVehicle(road, veh[j, [tm.V_X, tm.V_Y]].copy(), veh[j, tm.V_HEADING], veh[j, tm.V_SPEED],
                       target_speed=veh[j, tm.V_TARGET_SPEED])
        v.timer = veh[j, tm.V_TIMER]
        v.DELTA = veh[j, tm.V_DELTA]
        v.check_collisions = False  # as EcoHighway-v0 / highway-fast-v0
        road.vehicles.append(v)
    return road


@pytest.mark.parametrize("seed, ego_acc", [(0, 0.0), (5, 0.6)])
def test_trajectories_equal_highway_envs_from_the_same_state(seed, ego_acc):
    """40 s of 20 IDM/MOBIL vehicles around a kinematic ego: positions, headings, speeds, lanes and target lanes
    equal highway-env's to 1e-9, frame by frame, through lane changes and the ego's collision."""
    veh = _spawned(seed)
    veh[0, tm.V_ACC] = ego_acc
    road = _highway_road(veh)
    geo = np.array([3.0, 30.0])
    cols = [tm.V_X, tm.V_Y, tm.V_HEADING, tm.V_SPEED, tm.V_LANE, tm.V_TARGET_LANE]
    changes = 0
    for _ in range(400):
        lanes = veh[:, tm.V_LANE].copy()
        tm.run_traffic(veh, veh.shape[0], BEH, geo, 0.1, 1, WORK)
        road.act()
        road.step(0.1)
        ref = np.array([[v.position[0], v.position[1], v.heading, v.speed, v.lane_index[2], v.target_lane_index[2]]
                        for v in road.vehicles])
        np.testing.assert_allclose(veh[:, cols], ref, rtol=0, atol=1e-9)
        assert bool(veh[0, tm.V_CRASHED]) == road.vehicles[0].crashed
        changes += int(np.count_nonzero(veh[1:, tm.V_LANE] != lanes[1:]))
    assert changes > 0 or seed != 0  # seed 0 sees lane changes: MOBIL was exercised


def test_kinematics_block_equals_highway_envs_observation():
    rng = np.random.default_rng(0)
    for seed in range(5):
        veh = _spawned(seed)
        geo = np.array([3.0, 30.0])
        tm.run_traffic(veh, veh.shape[0], BEH, geo, 0.1, int(rng.integers(0, 200)), WORK)
        road = _highway_road(veh)
        for rows, behind in ((5, False), (8, True)):
            env = SimpleNamespace(road=road, vehicle=road.vehicles[0], PERCEPTION_DISTANCE=tm.PERCEPTION_DISTANCE,
                                  np_random=np.random.default_rng(0))
            ref = KinematicObservation(env, vehicles_count=rows, see_behind=behind).observe().reshape(-1)
            out = np.zeros(rows * 5)
            tm.kinematics_block(veh, veh.shape[0], 3, rows, behind, np.zeros(veh.shape[0], np.int64),
                                np.zeros(veh.shape[0]), out)
            np.testing.assert_allclose(out.astype(np.float32), ref, rtol=0, atol=1e-6)


# --------------------------------------------------------------------------------------------- angle wrap
def test_wrap_to_pi_without_the_modulo_equals_the_floored_modulo():
    """wrap_to_pi's branch for |x| <= 1, (x + pi) - pi, gives the bits of ((x + pi) mod 2 pi) - pi (Python's
    floored modulo), and the modulo is kept outside it."""
    rng = np.random.default_rng(12)
    tiny = np.exp(rng.uniform(-745.0, 0.0, 1000)) * rng.choice([-1, 1], 1000)
    xs = np.concatenate([rng.uniform(-1.0, 1.0, 3000), tiny,
                         [0.0, -0.0, 1.0, -1.0, np.nextafter(1.0, 2.0), -np.nextafter(1.0, 2.0), 3.0, -3.0, 7.0, 50.0]])
    for x in xs:
        want = ((float(x) + math.pi) % (2.0 * math.pi)) - math.pi
        assert np.float64(tm.wrap_to_pi(float(x))).tobytes() == np.float64(want).tobytes(), x
