"""The property-based contract check (roadload.experiments.contracts): a seeded run at a small size ends with 0
tracebacks and 0 silent acceptances, and the classifier does catch both (a planted hole is counted)."""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import pytest
from roadload.experiments import contracts
from roadload.experiments.contracts import FieldSpec, _config_surface, run, run_surface
from roadload.schema import check_field_types


def test_a_seeded_run_has_no_traceback_and_no_silent_acceptance():
    results = run(132, seed_value=7)
    assert set(results) == {s.name for s in contracts.SURFACES}
    total = sum((c for c in results.values()), start=contracts.Counter())
    bad = {name: dict(c) for name, c in results.items() if c["traceback"] or c["silent acceptance"]}
    assert bad == {}
    # both kinds of expected outcome occur: the generator breaks inputs and leaves others valid
    assert total["clean error"] >= 40 and total["valid result"] >= 20, dict(total)


@dataclass(frozen=True)
class _Leaky:
    """A settings class with a declared bound it never checks: the contract check must notice."""

    gain: float = 1.0
    steps: int = 3

    def __post_init__(self) -> None:
        if self.steps < 1:
            raise ValueError(f"steps: must be >= 1, got {self.steps}")


def test_a_planted_contract_hole_is_counted(tmp_path: Path):
    specs = [FieldSpec("gain", "float", 1.0, lo=0.0), FieldSpec("steps", "int", 3, lo=1)]
    surface = _config_surface("leaky", lambda: specs, lambda data: _Leaky(**data))
    counts, examples = run_surface(surface, 60, 0, tmp_path)
    # gain=NaN / -1 accepted: silent; steps='abc' -> TypeError from the comparison: traceback
    assert counts["silent acceptance"] > 0 and counts["traceback"] > 0, counts
    assert any("gain" in line for line in examples)


def test_a_result_outside_its_bounds_is_a_silent_acceptance(tmp_path: Path):
    specs = [FieldSpec("gain", "float", 1.0, lo=0.0, hi=2.0)]

    def build(data):  # ignores the input and returns an out-of-bounds object
        return _Leaky(gain=5.0)

    counts, _ = run_surface(_config_surface("out of bounds", lambda: specs, build), 20, 0, tmp_path)
    assert counts["valid result"] == 0 and counts["silent acceptance"] > 0, counts


@dataclass(frozen=True)
class _Typed:
    rate: float = 1.0
    count: int = 2
    flag: bool = False
    name: str = "a"
    limit: float | None = None

    def __post_init__(self) -> None:
        check_field_types(self, ValueError)


@pytest.mark.parametrize("field, value, words", [
    ("rate", math.nan, "_Typed.rate: must be a finite number"), ("rate", "abc", "_Typed.rate"),
    ("rate", True, "_Typed.rate"), ("count", 2.5, "_Typed.count: must be an integer"),
    ("flag", math.nan, "_Typed.flag: must be true or false"), ("name", 3.5, "_Typed.name: must be a string"),
    ("limit", math.inf, "_Typed.limit: must be a finite number or None"),
])
def test_check_field_types_names_the_field(field, value, words):
    with pytest.raises(ValueError, match=words.replace(".", r"\.")):
        _Typed(**{field: value})


def test_check_field_types_accepts_ints_for_floats_numpy_scalars_and_none():
    import numpy as np

    t = _Typed(rate=3, count=np.int64(4), flag=np.bool_(True), limit=None)
    assert t.rate == 3 and t.count == 4
    _Typed(rate=np.float32(0.5), limit=2.0)


def test_controller_settings_refuse_wrong_types_naming_the_field():
    from roadload.controllers.base import ControllerError
    from roadload.controllers.cruise import CruiseSettings
    from roadload.controllers.drive import DriveSettings
    from roadload.controllers.mpc import MpcError, MpcSettings

    with pytest.raises(MpcError, match=r"MpcSettings\.jerk_max: must be a finite number, got 'abc'"):
        MpcSettings(jerk_max="abc")
    with pytest.raises(MpcError, match=r"MpcSettings\.n_nodes: must be an integer, got 2\.5"):
        MpcSettings(n_nodes=2.5)
    with pytest.raises(ControllerError, match=r"CruiseSettings\.kp"):
        CruiseSettings(kp="abc")
    with pytest.raises(ControllerError, match=r"DriveSettings\.gear_command: must be true or false"):
        DriveSettings(gear_command=math.nan)
    with pytest.raises(ControllerError, match=r"DriveSettings\.measure_from: must be >= 0 \[m\]"):
        DriveSettings(measure_from=-5.0)


def test_a_vanishing_policy_rate_is_a_clean_config_error_not_an_overflow():
    from roadload.gym.config import EcoHighwayConfig, GymConfigError, make_config

    with pytest.raises(GymConfigError, match="policy_frequency"):
        make_config(EcoHighwayConfig, None, policy_frequency=5e-324)
