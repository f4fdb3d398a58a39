"""Modbus register map of the valve/vacuum controller: where each signal lives and how it scales.

A lab's PLC decides its own layout, so every address, type, word order, scale and offset comes
from `config/rig.toml`:

- coils (True = open / running) and discrete inputs (each True when its name says so) are bit
  addresses; -1 = the controller has no such bit. Bit maps may have gaps: the driver reads
  each contiguous run of mapped addresses on its own, never the span between them.
- a value in holding or input registers is a `Register`: address, type (int16, uint16, int32,
  uint32, float32), word order of 32-bit values ("big": high word first, the Modicon
  convention; "little": low word first), and engineering value = raw * scale + offset.
  address -1 = absent. A plain integer in the config is a uint16 at that address, scale 1.

Every field declares its own bounds and meaning (drivers/config_fields.py): rig/config.py
validates a rig file's [valve_controller.*] tables against these classes.

Encoding refuses what a register cannot hold (RegisterRangeError, a ValueError): a value is
never clipped or wrapped on its way to the controller. The byte packing is pymodbus's own
(`convert_to_registers` / `convert_from_registers`).
"""

from __future__ import annotations

import dataclasses
import math
import struct
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field, fields
from typing import Annotated, Any, Literal

from pydantic import BeforeValidator, Field
from pymodbus.client.mixin import ModbusClientMixin

from hopkinson.drivers.config_fields import SECTION, Hint, Int, Number

_DT = ModbusClientMixin.DATATYPE
REGISTER_TYPES: dict[str, tuple[_DT, int, float, float]] = {
    # type: (pymodbus data type, words, lowest raw, highest raw)
    "int16": (_DT.INT16, 1, -(2**15), 2**15 - 1),
    "uint16": (_DT.UINT16, 1, 0, 2**16 - 1),
    "int32": (_DT.INT32, 2, -(2**31), 2**31 - 1),
    "uint32": (_DT.UINT32, 2, 0, 2**32 - 1),
    "float32": (_DT.FLOAT32, 2, -3.4028234663852886e38, 3.4028234663852886e38),
}
WORD_ORDERS = ("big", "little")
RegisterType = Literal["int16", "uint16", "int32", "uint32", "float32"]  # the keys of REGISTER_TYPES
WordOrder = Literal["big", "little"]
# A bit's address: -1 = the controller has no such bit; a signal every controller has: 0 and up.
Bit = Annotated[Int, Field(ge=-1, le=65535, description="address 0..65535, or -1: the controller has none"),
                Hint("-1 (none) or an address 0..65535")]
RequiredBit = Annotated[Int, Field(ge=0, le=65535, description="address 0..65535")]
FLOAT32_SMALLEST_READING = 1e-9  # a float32 reading closer to zero (but not zero) is no rig gauge's


class RegisterRangeError(ValueError):
    """A value the register cannot hold (out of range, or not a finite number)."""


@dataclass(frozen=True)
class Register:
    """One value in holding or input registers (module docstring); address -1 = absent."""

    __pydantic_config__ = SECTION
    address: Bit = -1
    type: Annotated[RegisterType, Field(description="how the value is packed")] = "uint16"
    word_order: Annotated[WordOrder, Field(description="32-bit values: big = high word first (Modicon), "
                                                       "little = low word first"),
                          Hint("big: high word first; little: low word first")] = "big"
    scale: Annotated[Number, Field(description="value = raw * scale + offset; non-zero")] = 1.0
    offset: Number = 0.0

    def __post_init__(self) -> None:
        if self.type not in REGISTER_TYPES:
            raise ValueError(f"register type must be one of {', '.join(REGISTER_TYPES)}, got {self.type!r}")
        if self.word_order not in WORD_ORDERS:
            raise ValueError(f"word order must be 'big' or 'little', got {self.word_order!r}")
        if not (math.isfinite(self.scale) and self.scale != 0 and math.isfinite(self.offset)):
            raise ValueError(f"register scale must be finite and non-zero, offset finite "
                             f"(got {self.scale!r}, {self.offset!r})")

    @property
    def present(self) -> bool:
        return self.address >= 0

    @property
    def words(self) -> int:
        """16-bit registers the value takes (1 or 2)."""
        return REGISTER_TYPES[self.type][1]

    @property
    def addresses(self) -> range:
        return range(self.address, self.address + self.words)

    @property
    def is_float(self) -> bool:
        return self.type == "float32"

    @property
    def resolution(self) -> float:
        """Engineering units per count (0 for float32: no fixed step)."""
        return 0.0 if self.is_float else abs(self.scale)

    def value_range(self) -> tuple[float, float]:
        """Lowest and highest engineering value the register can hold."""
        _, _, low, high = REGISTER_TYPES[self.type]
        ends = (low * self.scale + self.offset, high * self.scale + self.offset)
        return min(ends), max(ends)

    def holds(self, value: float) -> bool:
        low, high = self.value_range()
        return math.isfinite(value) and low <= value <= high

    def encode(self, value: float) -> list[int]:
        """The register words for engineering `value` (rounded to a count for integer types)."""
        if not math.isfinite(value):
            raise RegisterRangeError(f"{value!r} is not a finite number")
        data_type, _, low, high = REGISTER_TYPES[self.type]
        raw: float = (value - self.offset) / self.scale
        if not self.is_float:
            raw = round(raw)
        if not low <= raw <= high:
            lo, hi = self.value_range()
            raise RegisterRangeError(f"{value:g} outside what the {self.type} register holds ({lo:g} .. {hi:g})")
        try:
            return ModbusClientMixin.convert_to_registers(raw, data_type, word_order=self._order)
        except (struct.error, OverflowError) as exc:  # float32 rounding at the very edge
            raise RegisterRangeError(f"{value:g} cannot be packed as {self.type}: {exc}") from None

    def decode(self, words: Sequence[int]) -> float:
        """Engineering value of the register words."""
        return self.raw(words) * self.scale + self.offset

    def raw(self, words: Sequence[int]) -> float:
        """The words as the register's type reads them, before scale and offset."""
        if len(words) != self.words:
            raise ValueError(f"{self.type} needs {self.words} words, got {len(words)}")
        data_type = REGISTER_TYPES[self.type][0]
        return float(ModbusClientMixin.convert_from_registers(  # type: ignore[arg-type]
            list(words), data_type, word_order=self._order))

    def implausibly_small(self, words: Sequence[int]) -> bool:
        """True for a float32 that is not zero yet below FLOAT32_SMALLEST_READING in magnitude:
        no instrument reports such a number, but two words in the wrong order often read as one
        (2.0 with its words swapped reads 2.3e-41)."""
        if not self.is_float:
            return False
        raw = self.raw(words)
        return raw != 0.0 and abs(raw) < FLOAT32_SMALLEST_READING

    def reinterpretations(self) -> list[Register]:
        """The same address read the other ways a PLC's documentation is commonly misread: a
        32-bit value in the other word order, or as the other 32-bit types in either order; a
        16-bit value with the other signedness. Scale and offset are kept."""
        if self.words == 1:
            others = [dataclasses.replace(self, type="int16" if self.type == "uint16" else "uint16")]
        else:
            others = [dataclasses.replace(self, type=t, word_order=o)
                      for t in ("float32", "int32", "uint32") for o in WORD_ORDERS]
            others.sort(key=lambda r: (r.type != self.type, r.word_order == self.word_order))
        return [r for r in others if r != self]

    def changes_from(self, other: Register) -> str:
        """How this register is written differently from `other`, as TOML keys
        ('word_order = "little"', 'type = "int32", word_order = "little"')."""
        return ", ".join(f'{name} = "{getattr(self, name)}"' for name in ("type", "word_order")
                         if getattr(self, name) != getattr(other, name))

    def describe(self, table: str) -> str:
        """Where and how the value is read: 'input registers 0..1, float32 big, x0.001'."""
        span = f"{self.address}" if self.words == 1 else f"{self.address}..{self.address + 1}"
        order = f" {self.word_order}" if self.words == 2 else ""
        scaled = f", x{self.scale:g}" if self.scale != 1.0 else ""
        scaled += f" {self.offset:+g}" if self.offset else ""
        return f"{table.replace('_', ' ')} {span}, {self.type}{order}{scaled}"

    @property
    def _order(self) -> Literal["big", "little"]:
        return "little" if self.word_order == "little" else "big"


def _reg(address: int, scale: float = 1.0, type_: str = "uint16") -> Register:
    return Register(address, type=type_, scale=scale)


def _address_only(value: Any) -> Any:
    """A register written as a plain address: a uint16 there, scale 1."""
    return {"address": value} if isinstance(value, int) and not isinstance(value, bool) else value


# A register field of a map: a table, or a plain address (a uint16 at that address, scale 1).
RegisterField = Annotated[Register, BeforeValidator(_address_only, json_schema_input_type=int | Register)]


ACTUATORS = ("fire_valve", "fill_valve", "vent_valve", "vacuum_pump")


@dataclass(frozen=True)
class CoilMap:
    """Coil addresses of the four actuators (True = open / running) and, for a PLC that fires
    on a coil of its own (docs/plc-fire-styles.md), that fire coil (-1 = none: the fire
    styles that need a coil then use fire_valve)."""

    __pydantic_config__ = SECTION
    fire_valve: RequiredBit = 0
    fill_valve: RequiredBit = 1
    vent_valve: RequiredBit = 2
    vacuum_pump: RequiredBit = 3
    fire_command: Annotated[Bit, Field(description="a coil of its own that starts the PLC's timed pulse "
                                                   "(docs/plc-fire-styles.md; -1: none)")] = -1


@dataclass(frozen=True)
class DiscreteInputMap:
    """Discrete-input addresses: interlocks (True = safe) and valve positions (True = open;
    -1 = the controller reports no position)."""

    __pydantic_config__ = SECTION
    door_closed: Annotated[RequiredBit, Field(description="interlock: True = the door is closed")] = 0
    fixture_clamped: Annotated[RequiredBit, Field(description="interlock: True = the fixture is clamped")] = 1
    estop_healthy: Annotated[RequiredBit, Field(description="interlock: True = the e-stop chain is healthy")] = 2
    fire_valve_open: Annotated[Bit, Field(description="limit switch: True = open (-1: none)")] = 8
    fill_valve_open: Annotated[Bit, Field(description="limit switch: True = open (-1: none)")] = 9
    vent_valve_open: Annotated[Bit, Field(description="limit switch: True = open (-1: none)")] = 10


@dataclass(frozen=True)
class HoldingRegisterMap:
    """Holding registers the host writes.

    pressure_setpoint: reservoir set-point (bar). projectile: the projectile type loaded
    (1..3; -1 = none). heartbeat: link-watchdog register (0 = stop, 1 = start a session and
    clear a trip, 2..65535 = beats). watchdog_ms: the watchdog time the controller applies
    (absent: the controller's own setting). fire_pulse_ms: the fire pulse's length in ms, timed
    by the controller: writing it starts the pulse, or it is the preset a fire coil or command
    word starts (the fire style, docs/plc-fire-styles.md). fire_command: the command word that
    starts a pulse of the preset (-1 = none).
    """

    __pydantic_config__ = SECTION
    pressure_setpoint: RegisterField = field(default_factory=lambda: _reg(0, 0.001))
    projectile: Bit = 1
    heartbeat: Bit = 2
    watchdog_ms: RegisterField = field(default_factory=lambda: _reg(3))
    fire_pulse_ms: RegisterField = field(default_factory=lambda: _reg(4))
    fire_command: Annotated[Bit, Field(description="the command word that starts a pulse of the preset "
                                                   "(docs/plc-fire-styles.md; -1: none)")] = -1


@dataclass(frozen=True)
class InputRegisterMap:
    """Input registers the host reads.

    reservoir_pressure (gauge bar), fixture_vacuum (absolute mbar), watchdog_state (0 off,
    1 armed, 2 tripped; -1 = not reported), fire_pulse_count (pulses fired).
    """

    __pydantic_config__ = SECTION
    reservoir_pressure: RegisterField = field(default_factory=lambda: _reg(0, 0.001))
    fixture_vacuum: RegisterField = field(default_factory=lambda: _reg(1, 0.1))
    watchdog_state: Bit = 2
    fire_pulse_count: RegisterField = field(default_factory=lambda: _reg(4, type_="uint32"))


@dataclass(frozen=True)
class RegisterMap:
    """Where every signal of the controller lives, and how its values scale.

    The defaults are the reference layout (config/rig.toml's, and the simulator's): valve
    positions after a gap in the discrete inputs, a 32-bit pulse counter after a gap in the
    input registers."""

    __pydantic_config__ = SECTION
    coils: CoilMap = field(default_factory=CoilMap)
    discrete_inputs: DiscreteInputMap = field(default_factory=DiscreteInputMap)
    holding_registers: HoldingRegisterMap = field(default_factory=HoldingRegisterMap)
    input_registers: InputRegisterMap = field(default_factory=InputRegisterMap)

    def blocks(self) -> dict[str, dict[str, int | Register]]:
        """{table name: {signal: address or Register}} for every mapped signal."""
        out: dict[str, dict[str, int | Register]] = {}
        for block in fields(self):
            table = getattr(self, block.name)
            entries = {f.name: getattr(table, f.name) for f in fields(table)}
            out[block.name] = {k: v for k, v in entries.items()
                               if (v.present if isinstance(v, Register) else v >= 0)}
        return out

    def overlaps(self) -> list[str]:
        """Signals that share an address in one table ("holding_registers.a and .b at 3")."""
        problems = []
        for block, entries in self.blocks().items():
            seen: dict[int, str] = {}
            for name, entry in entries.items():
                for address in (entry.addresses if isinstance(entry, Register) else [entry]):
                    if address in seen:
                        problems.append(f"{block}.{seen[address]} and {block}.{name} both use address {address}")
                    seen.setdefault(address, name)
        return problems


def contiguous_runs(addresses: Iterable[int]) -> list[tuple[int, int]]:
    """(start, count) of each run of consecutive addresses, sorted; duplicates merged."""
    runs: list[tuple[int, int]] = []
    for address in sorted(set(addresses)):
        if runs and runs[-1][0] + runs[-1][1] == address:
            runs[-1] = (runs[-1][0], runs[-1][1] + 1)
        else:
            runs.append((address, 1))
    return runs
