"""The speed shield of EcoDrive-v0: full throttle stays under every speed limit (within the evaluation's 0.1 m/s
tolerance) on hilly and city roads, the envelope brakes ahead of a lower limit, and without the shield the same
policy speeds."""

import numpy as np
import pytest

from roadload.controllers.closed_loop import VIOLATION_TOLERANCE
from roadload.gym.ecodrive import EcoDriveEnv, RouteTable


def _full_throttle(config):
    env = EcoDriveEnv(config=config)
    env.reset(seed=3)
    excess, done = [], False
    while not done:
        _, _, te, tr, info = env.step(np.array([1.0], dtype=np.float32))
        excess.append(info["v"] - info["speed_limit"])
        done = te or tr
    return np.array(excess), te


@pytest.mark.parametrize("road", ["hilly", "city"])
def test_full_throttle_under_the_shield_never_exceeds_the_limit(road):
    cfg = {"road": road, "road_seed": 50_003, "route_length": 1500.0}
    shielded, arrived = _full_throttle({**cfg, "speed_shield": True})
    assert arrived
    assert shielded.max() <= VIOLATION_TOLERANCE, shielded.max()
    free, _ = _full_throttle(cfg)
    assert free.max() > 2.0  # the same policy speeds without the shield


def test_braking_envelope_reaches_a_lower_limit_at_the_given_deceleration():
    route = RouteTable.__new__(RouteTable)
    limit = np.where(np.arange(301) < 200, 30.0, 10.0)
    route.table = np.vstack([np.zeros(301), np.zeros(301), limit, np.zeros(301)])
    env = route.braking_envelope(margin=0.5, deceleration=1.0)
    assert env[250] == pytest.approx(9.5)
    assert env[199] == pytest.approx(np.sqrt(9.5 ** 2 + 2.0 * 1.0))
    assert env[100] == pytest.approx(np.sqrt(9.5 ** 2 + 2.0 * 100.0))
    assert env[0:150].max() < 29.5 and env[-1] == pytest.approx(9.5)
    assert env[0] == pytest.approx(np.sqrt(9.5 ** 2 + 2.0 * 200.0))  # 22.1 m/s, 200 m before the drop
