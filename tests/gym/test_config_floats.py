"""Every float option of the gym configs, found from the schemas themselves (nested reward models and float tuples
included), refuses NaN and +-inf and every value beyond its declared bounds, naming the field, the value and the
expected range with its unit."""

import math
import typing

import pytest
from pydantic import BaseModel

from roadload.gym.config import EcoDriveConfig, EcoHighwayConfig, GymConfigError, make_config


def float_options(cls: type[BaseModel], prefix: tuple[str, ...] = ()):
    """(path, field info, is_tuple) of every float-valued option of ``cls``, nested models followed."""
    for name, info in cls.model_fields.items():
        ann = info.annotation
        if isinstance(ann, type) and issubclass(ann, BaseModel):
            yield from float_options(ann, prefix + (name,))
            continue
        args = typing.get_args(ann)
        if typing.get_origin(ann) is tuple and args and args[0] is float:
            yield prefix + (name,), info, True
        elif ann is float or float in args:
            yield prefix + (name,), info, False


def overrides(path, value):
    out = value
    for part in reversed(path[1:]):
        out = {part: out}
    return {path[0]: out}


CASES = [(cls, path, info, is_tuple) for cls in (EcoDriveConfig, EcoHighwayConfig)
         for path, info, is_tuple in float_options(cls)]
IDS = [f"{c.__name__}.{'.'.join(p)}" for c, p, _, _ in CASES]


def test_the_schemas_have_float_options():
    """The walk finds the options (a walk that found none would make every test below vacuous)."""
    names = {".".join(p) for _, p, _, _ in CASES}
    assert {"preview_distances", "shield_deceleration", "reward.time", "reward.scale", "vehicles_density",
            "initial_speed"} <= names, names
    assert len(CASES) >= 30


@pytest.mark.parametrize("cls,path,info,is_tuple", CASES, ids=IDS)
@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf], ids=["nan", "inf", "-inf"])
def test_non_finite_float_option_is_refused(cls, path, info, is_tuple, bad):
    value = (25.0, bad) if is_tuple else bad
    with pytest.raises(GymConfigError) as err:
        make_config(cls, **overrides(path, value))
    text = str(err.value)
    assert ".".join(path) in text and repr(bad) in text and "finite" in text, text
    if info.description:
        assert "expected: " + info.description in text, text  # the description carries the unit


def bounds(info):
    for m in info.metadata:
        for key in ("gt", "ge", "lt", "le"):
            if getattr(m, key, None) is not None:
                yield key, float(getattr(m, key))


BOUND_CASES = [(cls, path, key, limit) for cls, path, info, is_tuple in CASES if not is_tuple
               for key, limit in bounds(info)]


@pytest.mark.parametrize("cls,path,key,limit", BOUND_CASES,
                         ids=[f"{c.__name__}.{'.'.join(p)}.{k}" for c, p, k, _ in BOUND_CASES])
def test_float_option_beyond_its_bound_is_refused(cls, path, key, limit):
    step = max(abs(limit) * 1e-3, 1e-3)
    value = {"gt": limit, "ge": limit - step, "lt": limit, "le": limit + step}[key]
    with pytest.raises(GymConfigError) as err:
        make_config(cls, **overrides(path, value))
    op = {"gt": ">", "ge": ">=", "lt": "<", "le": "<="}[key]
    number = str(int(limit)) if limit.is_integer() else repr(limit)
    assert ".".join(path) in str(err.value) and f"{op} {number}" in str(err.value), str(err.value)


def test_a_finite_in_range_value_is_kept():
    cfg = make_config(EcoDriveConfig, preview_distances=(25.0, 80.0), reward={"time": 2500.0})
    assert cfg.preview_distances == (25.0, 80.0) and cfg.reward.time == 2500.0
