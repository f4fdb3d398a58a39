"""Field types of the configuration files' sections (drivers/config_fields.py tells how a
section declares its keys with them): defined here, where the simulator's sections can import
them (drivers/sim/ imports no driver), and named for the drivers and the rig by
drivers/config_fields.py. The diffraction orders are rig.toml's [analysis] and sim.toml's
[world.signals] both. Pydantic only: reading a configuration imports no NumPy."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Annotated, Literal

from pydantic import AfterValidator, AllowInfNan, ConfigDict, Field, Strict, WithJsonSchema

Int = Annotated[int, Strict()]
Number = Annotated[float, Strict(), AllowInfNan(False)]
Flag = Annotated[bool, Strict()]
SECTION = ConfigDict(extra="forbid")


@dataclass(frozen=True)
class Hint:
    """Words a one-line error adds to its reason, where a bound alone does not say enough
    (``Annotated[Number, Field(ge=0), Hint("0 (off) or the filter corner")]``): a key's
    description is for the editor, its hint for the error. Pydantic ignores it."""

    text: str


# A serial line and a Modbus link, as both ends name them.
Baud = Literal[1200, 2400, 4800, 9600, 19200, 38400, 57600, 115200, 230400, 460800, 921600]
Parity = Literal["N", "E", "O"]
StopBits = Literal[1, 2]
Transport = Literal["tcp", "rtu"]


def _distinct(orders: tuple[int, int]) -> tuple[int, int]:
    if orders[0] == orders[1]:
        raise ValueError(f"the two diffraction orders must differ, got {list(orders)}")
    return orders


Order = Annotated[Int, Field(ge=-10, le=10)]
# The interferometer's diffraction orders (phi, xi): beat = v*(phi - xi)/d; rig.toml's [analysis]
# takes the same type.
Orders = Annotated[tuple[Order, Order], AfterValidator(_distinct)]


def one_of(values: tuple[float, ...]) -> tuple[AfterValidator, WithJsonSchema]:
    """Metadata of a number that must be one of `values`: its check and its schema's enum
    (``Annotated[Number, *one_of(GAINS)]``)."""

    def check(value: float) -> float:
        if value not in values:
            raise ValueError(f"must be one of {', '.join(f'{v:g}' for v in values)}, got {value!r}")
        return value

    return AfterValidator(check), WithJsonSchema({"type": "number", "enum": list(values)})
