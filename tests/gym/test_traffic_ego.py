"""The egos of EcoTraffic-v0 start their episodes from the batch's bank of packed starts: each start is the record
``Simulator.reset(noise seed)`` followed by ``Fleet.load`` gives, bit for bit, and every ego reads its own road's
preview table, also after the bank was rebuilt (rows renumbered under egos that did not start)."""

from __future__ import annotations

from roadload.envs.batch import Fleet
from roadload.gym.config import EcoTrafficConfig, make_config
from roadload.gym.traffic_ego import EgoBatch, ego_road, start_ego


def test_bank_starts_equal_the_simulators_reset_also_after_rebuilds():
    cfg = make_config(EcoTrafficConfig, {"effects": ["wind", "brake_pad_drift"], "duration": 5.0})
    batch = EgoBatch(2, cfg.vehicle)
    batch.bank_limit = 4  # twice the batch: the starts below rebuild it
    twin = Fleet(2)
    on_road = {}
    rows_seen = {1: set()}
    # ego 1 climbs to bank row 3, then a start of ego 0 rebuilds the bank (ego 1 moves to row 1 without a start),
    # and the next new road takes row 3 again
    for episode, (index, road_seeds) in enumerate([([0, 1], (0, 1)), ([1], (2,)), ([1], (3,)), ([0], (4,)),
                                                   ([0], (5,)), ([0, 1], (2, 2))]):
        roads = [ego_road(cfg, s) for s in road_seeds]
        noise_seeds = [2 ** 62 + 7 * episode + i for i in index]
        rows, states = batch.prepare(index, roads, noise_seeds)
        records, starts = batch.records, batch.starts.records
        for r, i in enumerate(index):
            start_ego(records, i, starts, rows[r], states[r])
            roads[r].simulator.reset(seed=noise_seeds[r])
            twin.load(i, roads[r].simulator)
            assert records.vehicles[i].tobytes() == twin.records.vehicles[i].tobytes(), (episode, i)
            n = int(records.vehicles[i]["road_points"])
            assert (records.roads[i, :, :n] == twin.records.roads[i, :, :n]).all()
            on_road[i] = roads[r]
        assert len(batch._bank) <= 4
        for i, road in on_road.items():
            k = int(batch.table_slot[i])
            assert (batch.table[k, :, :batch.table_n[k]] == road.route.table).all(), (episode, i)
        rows_seen[1].add(int(batch.table_slot[1]))
    assert {1, 3} <= rows_seen[1]  # ego 1 was moved by a rebuild
