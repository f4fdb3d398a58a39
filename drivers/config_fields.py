"""Field types of the configuration files' sections (rig.toml, sim.toml, campaign plans).

A section is a frozen dataclass whose fields carry their own checks, read by pydantic when a
file is loaded (rig/config.py): one line per key, with its type, default, bounds and
description::

    @dataclass(frozen=True)
    class LimitsConfig:
        __pydantic_config__ = SECTION
        max_pressure_bar: Annotated[Number, Field(gt=0, le=100, description="never charge above this")] = 8.0

The scalar types are strict: a TOML string is never read as a number, nor a boolean as an
integer; an integer is a number; a number must be finite. `SECTION` refuses unknown keys.
Code that builds a section itself (tests, the panel) is not checked: the checks run on load.

Used by drivers/ and rig/. The types are defined once, in drivers/sim/config_fields.py (the
simulator's sections use them too, and drivers/sim/ imports no driver); this module names them
for the drivers and the rig, and adds Text.
"""

from __future__ import annotations

from typing import Annotated

from pydantic import Strict

from hopkinson.drivers.sim.config_fields import (
    SECTION,
    Baud,
    Flag,
    Hint,
    Int,
    Number,
    Parity,
    StopBits,
    Transport,
)

Text = Annotated[str, Strict()]
__all__ = ["SECTION", "Baud", "Flag", "Hint", "Int", "Number", "Parity", "StopBits", "Text", "Transport"]
