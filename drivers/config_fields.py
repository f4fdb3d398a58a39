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

Used by drivers/ and rig/; the simulator keeps its own copy (drivers/sim/config_fields.py),
as drivers/sim/ imports no driver.
"""

from __future__ import annotations

from typing import Annotated, Literal

from pydantic import AllowInfNan, ConfigDict, Strict

Int = Annotated[int, Strict()]
Number = Annotated[float, Strict(), AllowInfNan(False)]
Text = Annotated[str, Strict()]
Flag = Annotated[bool, Strict()]

SECTION = ConfigDict(extra="forbid")
# A serial line and a Modbus link, as both ends name them.
Baud = Literal[1200, 2400, 4800, 9600, 19200, 38400, 57600, 115200, 230400, 460800, 921600]
Parity = Literal["N", "E", "O"]
StopBits = Literal[1, 2]
Transport = Literal["tcp", "rtu"]
