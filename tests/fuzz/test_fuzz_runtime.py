"""Fuzzed contract of the runtime surfaces: controller settings, MPC plans, gym actions, output paths."""

from __future__ import annotations

import dataclasses
import os

import gymnasium as gym
import numpy as np
import pytest
from gymnasium import spaces
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

import roadload  # noqa: F401  (registers the gym ids)
from roadload.controllers.base import ControllerError
from roadload.controllers.cruise import CruiseSettings
from roadload.controllers.drive import DriveSettings
from roadload.controllers.energy import generic_ev
from roadload.road_load import RoadLoadParameters
from roadload.controllers.mpc import MpcError, MpcSettings, Preview
from roadload.controllers.mpc_controller import MpcControllerSettings, get_solver
from roadload.fileio import TMP_MARK, OutputPathError, atomic_path, check_output_path, write_text
from roadload.gym.actions import validate_action, validate_actions

FUZZ = settings(max_examples=30, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
NON_FINITE = [float("nan"), float("inf"), float("-inf")]

# ----------------------------------------------------------------------------------------------- controller settings
MPC_FLOATS = [f.name for f in dataclasses.fields(MpcSettings) if isinstance(f.default, float)]
CRUISE_FLOATS = [f.name for f in dataclasses.fields(CruiseSettings) if isinstance(f.default, float)]
MPC_CONTROLLER_FLOATS = ["replan_period", "speed_gain", "lookahead_time", "plan_tolerance", "min_plan_left"]
SETTING_CASES = (
    [(MpcControllerSettings, name, v, ControllerError) for name in MPC_CONTROLLER_FLOATS for v in NON_FINITE + [-1.0]]
    + [(MpcControllerSettings, "replan_period", 0.0, ControllerError)]
    + [(MpcSettings, name, v, MpcError) for name in MPC_FLOATS for v in NON_FINITE]
    + [(CruiseSettings, name, v, ControllerError) for name in CRUISE_FLOATS for v in NON_FINITE]
    + [(DriveSettings, "time_weight", v, ControllerError) for v in NON_FINITE + [-1.0]]
    + [(DriveSettings, "dt", v, ControllerError) for v in NON_FINITE + [0.0, -0.1]]
    + [
        (MpcSettings, "speed_margin", -50.0, MpcError),
        (MpcSettings, "speed_margin", -1e-3, MpcError),
        (MpcSettings, "accel_weight", -1.0, MpcError),
        (MpcSettings, "qp_tolerance", 0.0, MpcError),
        (MpcSettings, "max_iterations", 0, MpcError),
        (MpcSettings, "sqp_iterations", 0, MpcError),
        (MpcSettings, "n_nodes", 1, MpcError),
        (MpcSettings, "decel_max", 0.0, MpcError),
        (MpcSettings, "time_weight", -1.0, MpcError),
        (MpcSettings, "solver", "cplex", MpcError),
        (MpcSettings, "warm_tol", 2.0, MpcError),
        (CruiseSettings, "fraction", 1.5, ControllerError),
        (CruiseSettings, "ki", -0.1, ControllerError),
        (DriveSettings, "controller", "teleport", ControllerError),
        (DriveSettings, "force_model", "crystal_ball", ControllerError),
    ]
)


@pytest.mark.parametrize(
    "cls,name,value,error", SETTING_CASES, ids=[f"{c.__name__}.{n}={v!r}" for c, n, v, _ in SETTING_CASES]
)
def test_controller_setting_refused(cls, name, value, error, ledger):
    with pytest.raises(error) as err:
        cls(**{name: value})
    assert name.split("_")[0] in str(err.value) or repr(value) in str(err.value), str(err.value)
    ledger.record("controllers", "error")


@FUZZ
@given(weight=st.one_of(st.sampled_from(NON_FINITE), st.floats(max_value=-1e-9, allow_nan=False, allow_infinity=False)))
def test_time_weight_fuzz(weight, ledger):
    with pytest.raises(ControllerError, match="time_weight"):
        DriveSettings(time_weight=weight)
    ledger.record("controllers", "error")


@pytest.fixture(scope="module")
def small_ocp():
    energy = generic_ev()
    params = RoadLoadParameters.from_physical(1420.0, 0.009, 0.0, 0.0, 0.7, 1.2, 60000.0)
    out = {}
    for name, st_ in {
        "nominal": MpcSettings(n_nodes=20, ds=10.0),
        "weak_brakes": MpcSettings(n_nodes=20, ds=10.0, decel_max=0.01),
    }.items():
        out[name] = get_solver(st_, energy)
    return out, energy, params


def _preview(energy, cap, n=20, ds=10.0):
    return Preview(
        s=ds * np.arange(n + 1),
        grade=np.zeros(n),
        curvature=np.zeros(n),
        speed_cap=cap,
        ratio=energy.ratio_for_speed(np.full(n, 15.0)),
    )


def test_relaxed_plans_carry_a_flag(small_ocp, ledger):
    ocps, energy, params = small_ocp
    free = ocps["nominal"].solve(15.0, 0.0, _preview(energy, np.full(21, 25.0)), params)
    assert free.success and not free.relaxed and free.relaxed_nodes == 0
    # 20 m/s into a cap of 0: the cap cannot be honoured at once
    capped = ocps["nominal"].solve(20.0, 0.0, _preview(energy, np.zeros(21)), params)
    assert capped.relaxed and capped.relaxed_nodes >= 5
    assert not capped.success and {v.constraint for v in capped.violations} == {"speed_cap"}
    ledger.record("controllers", "repair")
    # an impossible stop: 100 m ahead at 25 m/s with decel_max = 0.01 m/s^2
    cap = np.full(21, 30.0)
    cap[10:12] = 1.0
    stop = ocps["weak_brakes"].solve(25.0, 0.0, _preview(energy, cap), params)
    assert stop.relaxed_nodes == 2
    assert not stop.success and stop.status.startswith("relaxed: speed_cap at 100 m"), stop.status
    ledger.record("controllers", "repair")


# ----------------------------------------------------------------------------------------------- gym actions
BOX1 = spaces.Box(-1.0, 1.0, shape=(1,), dtype=np.float32)
BOX2 = spaces.Box(-1.0, 1.0, shape=(2,), dtype=np.float32)
DICT = spaces.Dict({"force": BOX1, "lane_change": spaces.Discrete(3)})
ACTION_CASES = [
    (BOX1, np.zeros((2, 2)), "shape (2, 2)"),
    (BOX1, np.zeros(0), "shape (0,)"),
    (BOX1, "full", "str"),
    (BOX1, None, "NoneType"),
    (BOX1, np.zeros(3), "shape (3,)"),
    (BOX1, [0.1, 0.2], "shape (2,)"),
    (BOX1, [float("nan")], "non-finite"),
    (BOX1, [float("inf")], "non-finite"),
    (BOX1, [2.0], "outside"),
    (BOX1, [-1.5], "outside"),
    (BOX1, {"a": 1}, "dict"),
    (BOX1, [object()], "dtype"),
    (BOX1, [[0.1]], "shape (1, 1)"),
    (BOX1, np.array(["a"]), "dtype"),
    (BOX1, b"x", "bytes"),
    (BOX1, [True], "dtype"),
    (BOX1, [1 + 2j], "dtype"),
    (BOX2, [0.1], "shape (1,)"),
    (BOX2, 0.3, "shape ()"),
    (BOX2, [0.1, 5.0], "outside"),
    (DICT, [0.1, 1], "dict"),
    (DICT, {"force": [0.1]}, "keys"),
    (DICT, {"force": [0.1], "lane_change": 5}, "lane_change"),
    (DICT, {"force": [0.1], "lane_change": 0.5}, "lane_change"),
    (DICT, {"force": [9.0], "lane_change": 1}, "force"),
    (DICT, {"force": [0.1], "lane_change": 1, "x": 0}, "keys"),
]


@pytest.mark.parametrize("space,action,needle", ACTION_CASES, ids=[f"{i}" for i in range(len(ACTION_CASES))])
def test_action_refused(space, action, needle, ledger):
    with pytest.raises(ValueError) as err:
        validate_action(action, space)
    assert needle in str(err.value) and "expected" in str(err.value), str(err.value)
    ledger.record("gym", "error")


@pytest.fixture(scope="module")
def ecodrive():
    env = gym.make("roadload/EcoDrive-v0", road="city", route_length=1500.0)
    env.reset(seed=0)
    yield env
    env.close()


@pytest.mark.parametrize(
    "action",
    [np.zeros((2, 2)), np.zeros(0), "full", None, np.zeros(3), [float("nan")], [3.0]],
    ids=["2x2", "empty", "str", "None", "3", "nan", "3.0"],
)
def test_ecodrive_step_refuses(ecodrive, action, ledger):
    with pytest.raises(ValueError, match=r"action: expected a float array of shape \(1,\) with values in \[-1, 1\]"):
        ecodrive.step(action)
    ledger.record("gym", "error")


def test_ecodrive_step_accepts_scalar_and_array(ecodrive):
    """A (1,) float32 array and a plain float are the same action: from the same state they give the same step."""
    results = []
    for action in (np.array([0.2], dtype=np.float32), 0.2):
        ecodrive.reset(seed=3)
        obs, reward, terminated, truncated, info = ecodrive.step(action)
        assert ecodrive.observation_space.contains(obs) and np.isfinite(reward) and not (terminated or truncated)
        assert info["a"] > 0.0  # u = +0.2 is traction: the car moves off
        results.append((obs, reward, info["s"], info["v"]))
    (obs_a, r_a, s_a, v_a), (obs_b, r_b, s_b, v_b) = results
    np.testing.assert_array_equal(obs_a, obs_b)
    assert (r_a, s_a, v_a) == (r_b, s_b, v_b)


@FUZZ
@given(action=hnp.arrays(np.float64, hnp.array_shapes(min_dims=0, max_dims=3, max_side=4), elements=st.floats(-3, 3)))
def test_box_actions_fuzz(action, ledger):
    """Any array either is a valid (1,)-action (then returned as is) or is refused naming shape and bounds."""
    ok_shape = action.shape in ((1,), ())
    ok_bounds = bool(np.all(np.abs(action) <= 1.0))
    if ok_shape and ok_bounds:
        np.testing.assert_allclose(validate_action(action, BOX1), action.reshape(1), rtol=1e-6, atol=1e-7)
        return
    with pytest.raises(ValueError, match=r"expected a float array of shape \(1,\) with values in \[-1, 1\]"):
        validate_action(action, BOX1)
    ledger.record("gym", "error")


@pytest.mark.parametrize(
    "actions,n",
    [(np.zeros((3, 2)), 3), (np.zeros((2, 1)), 3), (np.zeros(4), 3), ([[0.1], [5.0]], 2), ("x", 2), (None, 2)],
)
def test_batch_actions_refused(actions, n, ledger):
    with pytest.raises(ValueError, match="actions: expected"):
        validate_actions(actions, BOX1, n)
    ledger.record("gym", "error")


def test_batch_actions_accepted():
    out = validate_actions(np.full(4, 0.5), BOX1, 4)
    assert out.shape == (4, 1) and out.dtype == np.float32


# ----------------------------------------------------------------------------------------------- output paths
def _cases(tmp_path):
    (tmp_path / "adir").mkdir()
    (tmp_path / "afile").write_text("x")
    return [
        (tmp_path / "adir", "file", "is a directory"),
        (tmp_path / "afile" / "out.parquet", "file", "is a file"),
        (tmp_path / "afile" / "deeper" / "out.parquet", "file", "is a file"),
        (tmp_path / "afile", "dir", "is a file"),
        (tmp_path / "afile" / "sub", "dir", "is a file"),
        ("", "file", "empty path"),
    ]


def test_output_paths_refused(tmp_path, ledger):
    for path, kind, needle in _cases(tmp_path):
        with pytest.raises(OutputPathError) as err:
            check_output_path(path, kind, what="--out")
        assert needle in str(err.value) and "--out" in str(err.value)
        ledger.record("output_path", "error")
    assert (tmp_path / "afile").read_text() == "x"


def test_interrupted_write_leftover_is_removed(tmp_path, ledger):
    target = write_text(tmp_path / "out.json", "old")
    dead_pid = 2**22 + 12345  # above the default pid_max: no such process
    leftover = tmp_path / f".out.json{TMP_MARK}{dead_pid}-abc.json"
    leftover.write_text("half")
    alive = tmp_path / f".out.json{TMP_MARK}{os.getpid()}-xyz.json"  # our own (a concurrent write): kept
    alive.write_text("mine")
    with pytest.raises(RuntimeError):
        with atomic_path(target) as tmp:
            assert TMP_MARK in tmp.name
            raise RuntimeError("writer died")
    assert not leftover.exists() and alive.exists() and target.read_text() == "old"
    ledger.record("output_path", "repair")


TABLE_INPUTS = len(SETTING_CASES) + 2 + len(ACTION_CASES) + 7 + 6 + 6 + 1
