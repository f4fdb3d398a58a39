"""A configuration file read through its pydantic declaration, and its first error as one line.

`validate(root, data, path)` returns the `root` dataclass built from a parsed TOML file, or
raises ConfigError "FILE: KEY: what was wrong", e.g.
``rig.toml: valve_controller.port: must be at most 65535, got 70000 (the controller's TCP port)``.
The key is dotted, list items indexed (``world.accelerometer.modes[0].damping_ratio``); the
reason is said in the project's words, with the key's `Hint` where it has one
(drivers/sim/config_fields.py). Pydantic's own text is used only for an error kind not listed here.

Campaign plans count their [[shots]] from 1 and write ranges as ``1..3`` or ``> 0``
(`first_index=1, symbolic=True`), as their messages always have.
"""

from __future__ import annotations

import dataclasses
import functools
import types
import typing
from pathlib import Path
from typing import Any

import annotated_types
from pydantic import TypeAdapter, ValidationError
from pydantic.fields import FieldInfo
from pydantic.json_schema import SkipJsonSchema

from hopkinson.drivers.config_fields import Hint
from hopkinson.rig.errors import ConfigError

_TYPE_WORDS = {"int_type": "an integer", "int_parsing": "an integer", "int_from_float": "an integer",
               "float_type": "a number", "float_parsing": "a number", "string_type": "a string",
               "bool_type": "true or false", "bool_parsing": "true or false",
               "dataclass_type": "a table", "dict_type": "a table", "model_type": "a table",
               "list_type": "an array", "tuple_type": "an array"}
_BOUND_WORDS = {"gt": "greater than", "ge": "at least", "lt": "less than", "le": "at most"}


def validate(root: Any, data: Any, path: Path, *, first_index: int = 0, symbolic: bool = False) -> Any:
    """`root` (a dataclass type) made from `data`; ConfigError naming `path`, the key and the reason."""
    try:
        return _adapter(root).validate_python(data)
    except ValidationError as exc:
        raise config_error(exc, path, root, first_index=first_index, symbolic=symbolic) from None


def schema(root: Any) -> dict[str, Any]:
    """The JSON Schema of `root` (what an editor checks and completes a file with)."""
    return _adapter(root).json_schema()


@functools.cache
def _adapter(root: Any) -> TypeAdapter[Any]:
    return TypeAdapter(root)


def config_error(exc: ValidationError, path: Path, root: Any, *, first_index: int = 0,
                 symbolic: bool = False) -> ConfigError:
    """The first error of `exc` as one line (module docstring)."""
    error = exc.errors(include_url=False)[0]
    loc = error["loc"]
    if error["type"] == "missing" and loc and isinstance(loc[-1], int):  # a fixed-length array, too short
        loc = loc[:-1]
        error = {**error, "type": "too_short", "ctx": {"actual_length": len(error["input"])}}
    key, field, parent = _locate(root, loc, first_index)
    return ConfigError(f"{path}: {key or 'top level'}: {_reason(error, field, parent, key, symbolic)}")


@dataclasses.dataclass
class _Field:
    """What the declaration says about one key: its type (without Annotated) and FieldInfo."""

    annotation: Any
    info: FieldInfo | None = None
    hint: Any = None  # as declared (Annotated, unions)


def _locate(root: Any, loc: tuple[Any, ...], first_index: int) -> tuple[str, _Field, _Field | None]:
    """The dotted key of `loc`, the declaration there and its parent's."""
    here, parent, key = _Field(root), None, ""
    for step in loc:
        child = _step(here.annotation, step)
        if child is None:  # a union member's tag or a validator's name: not part of the key
            continue
        parent, here = here, child
        key = f"{key}[{step + first_index}]" if isinstance(step, int) else (f"{key}.{step}" if key else step)
    return key, here, parent


def _step(tp: Any, step: Any) -> _Field | None:
    tp = _strip(tp)
    if isinstance(step, str) and dataclasses.is_dataclass(tp):
        hints = typing.get_type_hints(tp, include_extras=True)
        if step not in hints:
            return _Field(Any)  # an unknown key
        return _Field(_strip(hints[step]), FieldInfo.from_annotation(hints[step]), hints[step])
    origin, args = typing.get_origin(tp), typing.get_args(tp)
    if origin is dict and isinstance(step, str):
        return _Field(_strip(args[1]) if args else Any)
    if origin in (tuple, list) and isinstance(step, int):
        if origin is list or (len(args) == 2 and args[1] is Ellipsis):
            item = args[0]
        else:
            item = args[step] if step < len(args) else Any
        return _Field(_strip(item), FieldInfo.from_annotation(item), item)
    return None


def _strip(tp: Any) -> Any:
    """`tp` without Annotated and without None in a union."""
    while typing.get_origin(tp) is typing.Annotated:
        tp = typing.get_args(tp)[0]
    if typing.get_origin(tp) in (typing.Union, types.UnionType):
        options = [a for a in typing.get_args(tp) if a is not type(None)]
        if len(options) == 1:
            return _strip(options[0])
    return tp


def _reason(error: Any, field: _Field, parent: _Field | None, key: str, symbolic: bool) -> str:
    kind, value, ctx = error["type"], error["input"], error.get("ctx") or {}
    hints = [m.text for m in (field.info.metadata if field.info is not None else ()) if isinstance(m, Hint)]
    hint = f" ({hints[0]})" if hints else ""
    if kind == "missing":
        table = dataclasses.is_dataclass(field.annotation)
        return "missing section" if table else "missing key"
    if kind in ("unexpected_keyword_argument", "extra_forbidden"):
        where = key.rpartition(".")[0] or "top level"
        known = _field_names(parent.annotation if parent is not None else None)
        what = "section" if isinstance(value, dict) else "key"
        return f"unknown {what} in {where} (known: {', '.join(sorted(known))})"
    if kind in _TYPE_WORDS:
        return f"must be {_TYPE_WORDS[kind]}{hint}, got {_type_name(value)}"
    if kind == "finite_number":
        return f"must be a finite number, got {value}"
    if kind in ("too_short", "too_long"):
        return _length(field.annotation, kind, ctx) + hint
    if kind in ("greater_than", "greater_than_equal", "less_than", "less_than_equal"):
        if symbolic:
            return f"must be {_range_text(field, ctx)}{hint} (got {value})"
        bound, limit = next(iter(ctx.items()))
        return f"must be {_BOUND_WORDS[bound]} {limit:g}{hint}, got {value!r}"
    if kind in ("literal_error", "enum"):
        choices = ", ".join(str(c) for c in typing.get_args(field.annotation)) or ctx.get("expected", "")
        return f"must be one of {choices}{hint}, got {value!r}"
    if kind == "string_pattern_mismatch":
        return f"must match {ctx.get('pattern')}{hint}, got {value!r}"
    if kind in ("value_error", "assertion_error"):
        return str(ctx.get("error", error["msg"]))
    message = str(error["msg"])
    return message[:1].lower() + message[1:]


def _length(tp: Any, kind: str, ctx: dict[str, Any]) -> str:
    args = typing.get_args(tp)
    fixed = typing.get_origin(tp) is tuple and not (len(args) == 2 and args[1] is Ellipsis)
    actual = ctx.get("actual_length")
    if fixed:
        return f"must have {len(args)} items, got {actual}"
    if kind == "too_short":
        need = ctx.get("min_length")
        return f"must have at least {need} item{'s' if need != 1 else ''}, got {actual}"
    return f"must have at most {ctx.get('max_length')} items, got {actual}"


def _range_text(field: _Field, ctx: dict[str, Any]) -> str:
    """A field's bounds as a plan writes them: "1..3" (integers, both ends), "> 0 and <= 1"."""
    bounds = {**ctx, **_bounds(field.hint)}
    if field.annotation is int and "ge" in bounds and "le" in bounds:
        return f"{bounds['ge']}..{bounds['le']}"
    parts = [f"{sign} {bounds[name]:g}" for name, sign in (("gt", ">"), ("ge", ">="), ("lt", "<"), ("le", "<="))
             if name in bounds]
    return " and ".join(parts)


def _bounds(hint: Any) -> dict[str, float]:
    """gt, ge, lt, le declared anywhere in `hint` (inside Annotated, unions and Field)."""
    out: dict[str, float] = {}
    if typing.get_origin(hint) is typing.Annotated:
        base, *metadata = typing.get_args(hint)
        out.update(_bounds(base))
        for item in metadata:
            for constraint in (item.metadata if isinstance(item, FieldInfo) else [item]):
                for name in ("gt", "ge", "lt", "le"):
                    if isinstance(constraint, getattr(annotated_types, name.capitalize())):
                        out[name] = getattr(constraint, name)
    elif typing.get_origin(hint) in (typing.Union, types.UnionType):
        for option in typing.get_args(hint):
            out.update(_bounds(option))
    return out


def _field_names(tp: Any) -> list[str]:
    """The keys a table may have (a field kept out of the schema is not a key of the file)."""
    tp = _strip(tp)
    if not dataclasses.is_dataclass(tp):
        return []
    hints = typing.get_type_hints(tp, include_extras=True)
    return [f.name for f in dataclasses.fields(tp)
            if not any(isinstance(m, SkipJsonSchema) for m in getattr(hints[f.name], "__metadata__", ()))]


def _type_name(value: Any) -> str:
    """How a TOML value is described in messages, e.g. "a string ('5020')"."""
    names = {bool: "a boolean", int: "an integer", float: "a number", str: "a string", list: "an array",
             dict: "a table"}
    name = names.get(type(value), type(value).__name__)
    return name if isinstance(value, dict | list) else f"{name} ({value!r})"
