"""Shared fixtures: the shared driving data, and the road profiles several test modules drive on (built once per
session; their arrays are read-only so no test can change the road another test sees)."""

import os

# libgomp reads OMP_WAIT_POLICY once, when torch first loads it: set the native vector env's policy before any test
# imports torch, as the roadload command does, or a multi-threaded vector env warns that it cannot take effect
os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")
# `pytest -n 2` runs one test process per core; OpenBLAS would start a pool of one thread per core in each of them
# (numpy's and scipy's each), whose threads spin while they wait: on the busy cores that costs CPU the tests need.
# Measured, tests/sim2real twice at once on 2 cores: 118 s CPU per run with the pools, 97 s with one BLAS thread.
# Set before numpy loads (nothing imports it before this file), unless the caller chose a count.
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

from typing import Any, Callable

import numpy as np
import pytest

from roadload.data import shared_data_dir
from roadload.road_profiles import RoadProfile, load_profile


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """A nightly test is also a slow one: the README's ``pytest -m "not slow"`` (which CI runs) leaves both out."""
    for item in items:
        if item.get_closest_marker("nightly") and not item.get_closest_marker("slow"):
            item.add_marker(pytest.mark.slow)


@pytest.fixture
def shared_data():
    """Path to ../shared/data; skips the test with a reason when it is absent."""
    path = shared_data_dir()
    if path is None:
        pytest.skip("needs the shared driving data (../shared/data or $ROADLOAD_DATA); not present on this machine")
    return path


def _read_only(road: RoadProfile) -> RoadProfile:
    for value in vars(road).values():
        if isinstance(value, np.ndarray):
            value.flags.writeable = False
    return road


def _straight_road(length: float, grade: Any, curvature: Any, limit: Any, stops: tuple[float, ...]) -> RoadProfile:
    s = np.arange(0.0, length + 1.0, 10.0)
    g = grade(s) if callable(grade) else np.full_like(s, grade)
    k = curvature(s) if callable(curvature) else np.full_like(s, curvature)
    lim = limit(s) if callable(limit) else np.full_like(s, limit)
    return RoadProfile("test", s, g, k, np.zeros_like(s), lim, stops=np.asarray(stops, float))


@pytest.fixture(scope="session")
def straight_road() -> Callable[..., RoadProfile]:
    """Factory of the straight test roads of the simulator and effect tests: 10 m resolution, bank 0, grade [1],
    curvature [1/m] and speed limit [m/s] constant or a function of the distance s [m], stops at the given
    distances [m]. Each argument set is built once per session (roads given as functions are built per call)."""
    built: dict[tuple, RoadProfile] = {}

    def make(length: float = 3000.0, grade: Any = 0.0, curvature: Any = 0.0, limit: Any = 25.0,
             stops: tuple[float, ...] | list[float] = ()) -> RoadProfile:
        key = (float(length), grade, curvature, limit, tuple(float(x) for x in stops))
        if any(callable(a) for a in (grade, curvature, limit)):
            return _read_only(_straight_road(length, grade, curvature, limit, key[-1]))
        if key not in built:
            built[key] = _read_only(_straight_road(length, grade, curvature, limit, key[-1]))
        return built[key]

    return make


@pytest.fixture(scope="session")
def hilly_road() -> RoadProfile:
    """The generated 'hilly' road, seed 1, 4 km (the generator is prefix-stable: its first 2 or 3 km equal
    load_profile('hilly', seed=1, length=2000 / 3000))."""
    return _read_only(load_profile("hilly", seed=1, length=4000.0))


@pytest.fixture(scope="session")
def rolling_road() -> Callable[..., RoadProfile]:
    """Factory of the short rolling test road of the simulator API tests: 10 m resolution, grade 0.02 sin(s/200),
    curvature 0.003 sin(s/150) [1/m], limit 20 m/s, stops [m]; each argument set built once per session."""
    built: dict[tuple, RoadProfile] = {}

    def make(length: float = 1500.0, stops: tuple[float, ...] | list[float] = ()) -> RoadProfile:
        key = (float(length), tuple(float(x) for x in stops))
        if key not in built:
            s = np.arange(0.0, length + 1.0, 10.0)
            road = RoadProfile("short", s, 0.02 * np.sin(s / 200.0), 0.003 * np.sin(s / 150.0), np.zeros_like(s),
                               np.full_like(s, 20.0), stops=np.asarray(key[1], float))
            built[key] = _read_only(road)
        return built[key]

    return make


@pytest.fixture(scope="session")
def sine_hill_road() -> RoadProfile:
    """1.2 km at 5 m resolution, grade 0.04 sin(2 pi s / 1 km), limit 80 km/h then 50 km/h after 1 km: the
    closed-loop (controller + simulator) test road."""
    s = np.arange(0.0, 1200.0 + 1, 5.0)
    grade = 0.04 * np.sin(2 * np.pi * s / 1000.0)
    limit = np.where(s > 1000, 50 / 3.6, 80 / 3.6)
    return _read_only(RoadProfile("short", s, grade, np.zeros_like(s), np.zeros_like(s), limit))
