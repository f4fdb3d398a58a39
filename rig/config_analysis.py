"""Configuration sections made of analysis options, derived from their one declaration.

`options_section(...)` returns a frozen dataclass pydantic validates (rig/config_errors.py) whose
keys are options of analysis.options.AnalysisOptions: each key's type, default, bounds, unit and
description are the option's own (its `Rule` becomes pydantic's Field bounds), and a section
from a file is checked by AnalysisOptions itself too (the rules beyond a bound: two different
orders, …). The rig's [analysis] and [uncertainty] (rig/config.py) and a campaign
plan's [defaults.analysis] / [shots.analysis] (rig/plan.py) are such sections.
"""

from __future__ import annotations

import dataclasses
import functools
import sys
from collections.abc import Mapping
from typing import Annotated, Any, Literal

from pydantic import AfterValidator, AllowInfNan, BeforeValidator, Field, Strict

from hopkinson.analysis.options import AnalysisOptions, OptionError, Rule
from hopkinson.drivers.config_fields import SECTION, Flag, Int, Number, Text

_OPTIONS = {f.name: f for f in dataclasses.fields(AnalysisOptions)}
_KINDS = {float: Number, int: Int, bool: Flag, str: Text}


def options_section(name: str, module: str, doc: str, keys: Mapping[str, str] | tuple[str, ...], *,
                    unset: tuple[str, ...] = (), words: Mapping[str, Mapping[str, Any]] | None = None,
                    narrower: Mapping[str, Mapping[str, float]] | None = None,
                    apart: Mapping[str, str] | None = None) -> type:
    """A section class named `name` (defined in `module`) whose keys are analysis options.

    keys: the option names, or key -> option name where the file's key differs. unset: keys
    whose default is "not given" (None: the value comes from elsewhere, e.g. the rig's).
    words: key -> {word: value} also accepted ("auto" -> None). narrower: key -> bounds this
    file asks beyond the option's own (e.g. a plan's DCM ratio at least 1). apart: key -> option
    whose rule the key obeys, though `options()` leaves it out (e.g. a second sensor's gain)."""
    keys = dict(keys) if isinstance(keys, Mapping) else {k: k for k in keys}
    words, narrower, apart = dict(words or {}), dict(narrower or {}), dict(apart or {})
    spec = []
    for key, option in (keys | apart).items():
        declared = _OPTIONS[option]
        hint = _annotation(declared.type, declared.metadata["rule"], narrower.get(key, {}))
        unit = declared.metadata["unit"]
        description = declared.metadata["doc"] + (f", {unit}" if unit else "")
        default = None if key in unset else declared.default
        if key in unset:
            hint = hint | None
        if key in words:
            table = words[key]
            hint = Annotated[hint, BeforeValidator(lambda v, table=table: table.get(v, v) if isinstance(v, str) else v,
                                                   json_schema_input_type=hint | Literal[tuple(table)])]
        checked = AfterValidator(functools.partial(_checked, option))
        spec.append((key, Annotated[hint, checked, Field(description=description)], dataclasses.field(default=default)))

    def analysis_options(self: Any) -> dict[str, Any]:
        """The values given, keyed as AnalysisOptions options (None: not given)."""
        return {option: getattr(self, key) for key, option in keys.items()}

    cls = dataclasses.make_dataclass(name, spec, frozen=True, namespace={
        "__doc__": doc, "__module__": module, "__pydantic_config__": SECTION,
        "analysis_options": analysis_options})
    setattr(sys.modules[module], name, cls)
    return cls


def _checked(option: str, value: Any) -> Any:
    """`value` as AnalysisOptions checks `option` (ValueError: what it must be)."""
    try:
        AnalysisOptions.from_options(**{option: value})
    except OptionError as exc:
        raise ValueError(exc.need) from None
    return value


def _annotation(declared_type: Any, rule: Rule, narrower: Mapping[str, float]) -> Any:
    """The pydantic type of an option: strict scalar, bounds of its rule, None when optional."""
    if declared_type == "tuple[int, int]":  # the diffraction orders
        order = Annotated[Int, Field(ge=rule.ge, le=rule.le)]
        return tuple[order, order]
    base = Annotated[float, Strict(), AllowInfNan(True)] if rule.infinite else _KINDS[rule.kind]
    bounds = {k: v for k, v in (("gt", rule.gt), ("ge", rule.ge), ("le", rule.le)) if v is not None}
    for side in ({"gt", "ge"}, {"le"}):  # a file's own narrower bound replaces the option's on that side
        if side & set(narrower):
            bounds = {k: v for k, v in bounds.items() if k not in side}
    bounds.update(narrower)
    hint = Annotated[base, Field(**bounds)] if bounds else base
    return hint | None if rule.optional else hint
