"""Shared helpers for the pydantic schemas of user-facing files (mapping, vehicle, sim config, trip metadata).

Every schema forbids unknown keys and declares bounds and units in its fields (``Field(..., description="[kg]")``
or ``json_schema_extra={"unit": "kg"}``). :func:`format_errors` turns a pydantic ``ValidationError`` into one line
per problem that names the field (dotted path), the value given, the expected value and its unit, and, for an
unknown key, the known keys.
"""

from __future__ import annotations

import dataclasses
import math
import numbers
import re
import typing
from typing import Any, Callable

import pydantic
import pydantic.dataclasses
from pydantic import BaseModel, ConfigDict

__all__ = ["StrictModel", "format_errors", "field_unit", "loc_text", "field_info_at", "spec_dataclass",
           "check_field_types"]


class StrictModel(BaseModel):
    """A schema model: unknown keys rejected, no silent type coercion ("abc" is not a number), NaN/inf refused."""

    model_config = ConfigDict(extra="forbid", strict=True, allow_inf_nan=False, frozen=False)


def field_unit(info: Any) -> str | None:
    """The unit of a pydantic FieldInfo: ``json_schema_extra["unit"]`` or a trailing ``[unit]`` in its description."""
    extra = getattr(info, "json_schema_extra", None)
    if isinstance(extra, dict) and extra.get("unit"):
        return str(extra["unit"])
    m = re.search(r"\[([^\]]+)\]\s*$", getattr(info, "description", None) or "")
    return m.group(1) if m else None


def _model_at(model: type[BaseModel] | None, loc: tuple[Any, ...]) -> tuple[type[BaseModel] | None, Any]:
    """Walk a model along an error location; returns (model owning the last named field, that FieldInfo)."""
    owner, info = model, None
    for part in loc:
        if owner is None or not isinstance(part, str):
            continue
        fields = getattr(owner, "model_fields", {})
        if part not in fields:
            return owner, None
        info = fields[part]
        nxt = None
        for tp in _types_of(info.annotation):
            if isinstance(tp, type) and issubclass(tp, BaseModel):
                nxt = tp
                break
        if nxt is None:
            return owner, info
        owner = nxt
    return owner, info


def _types_of(tp: Any) -> list[Any]:
    import typing

    out = [tp]
    for arg in typing.get_args(tp):
        out += _types_of(arg)
    return out


def loc_text(loc: tuple[Any, ...], root: str = "") -> str:
    text = root
    for part in loc:
        if isinstance(part, int):
            text += f"[{part}]"
        else:
            text += ("." if text else "") + str(part)
    return text


def _expected(err: dict[str, Any]) -> str:
    ctx = err.get("ctx") or {}
    kind = err["type"]
    if kind == "greater_than":
        return f"> {ctx['gt']}"
    if kind == "greater_than_equal":
        return f">= {ctx['ge']}"
    if kind == "less_than":
        return f"< {ctx['lt']}"
    if kind == "less_than_equal":
        return f"<= {ctx['le']}"
    return ""


def _clean_loc(loc: tuple[Any, ...], model: type[BaseModel] | None) -> tuple[tuple[Any, ...], bool]:
    """Drop union member tags ('str', 'dict[str,any]', 'function-after[...]') from an error location; returns
    the location and whether a tag was dropped."""
    out: list[Any] = []
    owner: Any = model
    dropped = False
    for part in loc:
        if isinstance(part, int):
            out.append(part)
            continue
        fields = getattr(owner, "model_fields", None) if isinstance(owner, type) else None
        if fields is not None and part in fields:
            out.append(part)
            nxt = None
            for tp in _types_of(fields[part].annotation):
                if isinstance(tp, type) and issubclass(tp, BaseModel):
                    nxt = tp
            owner = nxt
        elif fields is None and not any(c in part for c in "[],") and part not in ("str", "int", "float", "bool"):
            out.append(part)  # a dict key
        else:
            if isinstance(owner, type) and part == getattr(owner, "__name__", None):
                continue
            dropped = True
    return tuple(out), dropped


def _merge_unions(errors: list[dict[str, Any]], model: type[BaseModel] | None) -> list[dict[str, Any]]:
    """One error per location: the alternatives of a union become one 'expected X or Y' error."""
    merged: dict[tuple[Any, ...], dict[str, Any]] = {}
    order = []
    for err in errors:
        raw = tuple(err["loc"])
        if err["type"] == "extra_forbidden" and raw:  # the unknown key itself is no field: keep it
            loc, dropped = _clean_loc(raw[:-1], model)
            loc = loc + raw[-1:]
        else:
            loc, dropped = _clean_loc(raw, model)
        err = dict(err, loc=loc)
        if loc in merged and dropped:
            prev = merged[loc]
            prev["msg"] = prev["msg"] + " or " + err["msg"].removeprefix("Input should be ")
            continue
        if loc not in merged:
            order.append(loc)
        merged[loc] = err
    return [merged[loc] for loc in order]


def format_errors(exc: pydantic.ValidationError, model: type[BaseModel] | None = None, root: str = "",
                  limit: int = 5) -> str:
    """One line per error: ``<root>.<field>: <problem>, got <value>; expected <bound> [unit]`` (at most `limit`)."""
    lines = []
    errors = _merge_unions([dict(e) for e in exc.errors(include_url=False)], model)
    for err in errors[:limit]:
        loc = err["loc"]
        where = loc_text(loc, root) or root or "input"
        owner, info = _model_at(model, loc)
        unit = field_unit(info) if info is not None else None
        if err["type"] == "extra_forbidden":
            parent_owner, _ = _model_at(model, loc[:-1]) if len(loc) > 1 else (model, None)
            known = sorted(getattr(parent_owner, "model_fields", {})) if parent_owner is not None else []
            lines.append(f"{where}: unknown key; known keys: {', '.join(known)}")
            continue
        if err["type"] == "missing":
            lines.append(f"{where}: missing required field" + (f" [{unit}]" if unit else ""))
            continue
        msg = err["msg"]
        msg = msg[0].lower() + msg[1:] if msg else msg
        msg = msg.removeprefix("value error, ")
        bound = _expected(err)
        text = f"{where}: {msg}"
        if bound and unit:
            text = f"{where}: must be {bound} [{unit}]"
        elif unit and "[" not in msg:
            text += f" (unit: {unit})"
        if "input" in err:
            value = err["input"]
            if not isinstance(value, dict):
                text += f", got {value!r}"
            elif err["type"] != "value_error":
                text += ", got an object"
        lines.append(text)
    if len(errors) > limit:
        lines.append(f"... and {len(errors) - limit} more problems")
    return "; ".join(lines)


def field_info_at(root: Any, loc: tuple[Any, ...]) -> tuple[Any, Any]:
    """Walk a pydantic model or pydantic dataclass along an error location (field names, list indices, dict keys);
    returns (the type owning the last named field, that field's FieldInfo) — (owner, None) when the location ends
    in a list item or dict value without its own FieldInfo, or leaves the declared types."""
    import typing

    from pydantic.fields import FieldInfo

    tp: Any = root
    owner: Any = root
    info: Any = None
    for part in loc:
        tp = _unwrap_optional(tp)
        fields = getattr(tp, "__pydantic_fields__", None) or getattr(tp, "model_fields", None)
        origin = typing.get_origin(tp)
        if isinstance(fields, dict) and isinstance(part, str):
            if part not in fields:
                return tp, None
            owner, info = tp, fields[part]
            tp = info.annotation
        elif origin is list and isinstance(part, int):
            item = typing.get_args(tp)[0]
            info = FieldInfo.from_annotation(item) if typing.get_origin(item) is typing.Annotated else None
            tp = typing.get_args(item)[0] if typing.get_origin(item) is typing.Annotated else item
        elif origin is dict:
            tp, info = typing.get_args(tp)[1], None
        else:
            return owner, None
    return owner, info


def _unwrap_optional(tp: Any) -> Any:
    import types
    import typing

    if typing.get_origin(tp) in (typing.Union, types.UnionType):
        inner = [a for a in typing.get_args(tp) if a is not type(None)]
        if len(inner) == 1:
            return inner[0]
    return tp


_T = typing.TypeVar("_T")


@typing.dataclass_transform(field_specifiers=(dataclasses.field, pydantic.Field))
def spec_dataclass(config: ConfigDict, error: Callable[[pydantic.ValidationError, Any], Exception],
                   frozen: bool = False) -> Callable[[type[_T]], type[_T]]:
    """Decorator: a pydantic dataclass (validated on construction; attribute access, positional arguments and
    ``dataclasses.replace`` as with a stdlib dataclass; immutable and hashable with ``frozen``) whose
    ValidationError is re-raised as the one-line domain error ``error(exc, cls)`` (e.g. VehicleSpecError naming
    the field, the bound and the unit)."""

    def wrap(cls: type[_T]) -> type[_T]:
        pcls: Any = pydantic.dataclasses.dataclass(cls, config=config, frozen=frozen)
        init = pcls.__init__

        def __init__(self: Any, *args: Any, **kwargs: Any) -> None:
            try:
                init(self, *args, **kwargs)
            except pydantic.ValidationError as exc:
                raise error(exc, pcls) from None

        __init__.__doc__ = init.__doc__
        pcls.__init__ = __init__
        return typing.cast(type[_T], pcls)

    return wrap


_SCALAR_WORDS = {float: "a finite number", int: "an integer", bool: "true or false", str: "a string"}


def _scalar_of(tp: Any) -> tuple[type | None, bool]:
    """(scalar type, None allowed) of a field annotation; (None, ...) for anything but float/int/bool/str."""
    import types

    optional = False
    if typing.get_origin(tp) in (typing.Union, types.UnionType):
        args = typing.get_args(tp)
        optional = type(None) in args
        rest = [a for a in args if a is not type(None)]
        if len(rest) != 1:
            return None, optional
        tp = rest[0]
    return (tp if tp in _SCALAR_WORDS else None), optional


def check_field_types(obj: Any, error: Callable[[str], Exception]) -> None:
    """Refuse a settings dataclass whose scalar field (float / int / bool / str, optionally ``| None``) holds a value
    of another type, or a float field that is NaN or infinite: raises ``error("<Class>.<field>: must be ..., got
    <value>")``. An int is a valid float; a bool is never a number. Call it first in ``__post_init__``, so that the
    range checks after it compare numbers."""
    import sys

    namespace = vars(sys.modules[type(obj).__module__])
    for f in dataclasses.fields(obj):
        try:  # annotations are strings under ``from __future__ import annotations``
            annotation = eval(f.type, namespace) if isinstance(f.type, str) else f.type  # noqa: S307
        except Exception:  # noqa: BLE001 -- a type only imported for type checking: not a scalar field
            continue
        kind, optional = _scalar_of(annotation)
        value = getattr(obj, f.name)
        if kind is None or (optional and value is None):
            continue
        if kind is float:
            ok = isinstance(value, numbers.Real) and not isinstance(value, bool) and math.isfinite(value)
        elif kind is int:
            ok = isinstance(value, numbers.Integral) and not isinstance(value, bool)
        elif kind is bool:
            ok = isinstance(value, bool) or getattr(getattr(value, "dtype", None), "kind", "") == "b"  # numpy's too
        else:
            ok = isinstance(value, kind)
        if not ok:
            raise error(f"{type(obj).__name__}.{f.name}: must be {_SCALAR_WORDS[kind]}"
                        + (" or None" if optional else "") + f", got {value!r}")
