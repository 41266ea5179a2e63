"""The one registry type: registration, explicit replacement, pass-through of instances, errors listing names."""

import pytest

from roadload.registry import Registry


class Thing:
    def __init__(self, name):
        self.name = name


def test_register_get_replace_and_errors():
    reg: Registry[Thing] = Registry("thing", Thing, ValueError, normalise=str.lower)
    a = reg.register("Alpha", Thing("a"))
    assert reg.get("ALPHA") is a and "alpha" in reg and reg.names() == ["alpha"] and list(reg) == ["alpha"]
    assert reg.get(a) is a  # an instance passes through
    with pytest.raises(ValueError, match="already registered; pass replace_existing=True"):
        reg.register("alpha", Thing("b"))
    b = reg.register("alpha", Thing("b"), replace_existing=True)
    assert reg.get("alpha") is b and len(reg) == 1
    with pytest.raises(ValueError, match=r"unknown thing 'beta'; known: alpha"):
        reg.get("beta")
    with pytest.raises(ValueError, match="must be a Thing, got int"):
        reg.register("gamma", 3)
    with pytest.raises(ValueError, match="non-empty name"):
        reg.register("", Thing("x"))
    assert reg.find("nothing") is None
