"""Where the simulated controller keeps each signal, and how it packs values into registers.

This is the simulator's own side of the Modbus register protocol, written independently of
the driver (drivers/registers.py): tests that run the driver against this simulator then
check both against the protocol, not one against itself.

A map is {table: {signal: Point}} for the four Modbus tables. A `Point` is an address and,
for registers, a type (int16, uint16, int32, uint32, float32), a word order ("big" = high word
first) and raw = (value - offset) / scale. Like a real gauge's converter, a value beyond what
the register holds reads as the nearest end of its range.
"""

from __future__ import annotations

import math
import struct
from dataclasses import dataclass

# type: (struct code, words, lowest raw, highest raw)
TYPES: dict[str, tuple[str, int, float, float]] = {
    "int16": ("h", 1, -32768, 32767),
    "uint16": ("H", 1, 0, 65535),
    "int32": ("i", 2, -(2**31), 2**31 - 1),
    "uint32": ("I", 2, 0, 2**32 - 1),
    "float32": ("f", 2, -3.4e38, 3.4e38),
}

# The signals the simulated controller has, per table.
SIGNALS: dict[str, tuple[str, ...]] = {
    "coils": ("fire_valve", "fill_valve", "vent_valve", "vacuum_pump", "fire_command"),
    "discrete_inputs": ("door_closed", "fixture_clamped", "estop_healthy",
                        "fire_valve_open", "fill_valve_open", "vent_valve_open"),
    "holding_registers": ("pressure_setpoint", "projectile", "heartbeat", "watchdog_ms", "fire_pulse_ms",
                          "fire_command"),
    "input_registers": ("reservoir_pressure", "fixture_vacuum", "watchdog_state", "fire_pulse_count"),
}
BIT_TABLES = ("coils", "discrete_inputs")

# How the simulated PLC fires (the simulator's own reading of docs/plc-fire-styles.md):
# pulse_register: a write to fire_pulse_ms fires a pulse that long; preset_and_coil and
# plc_preset_coil: fire_pulse_ms holds a preset (starting at SimModbusServer's fire_preset_ms)
# and a rising edge of the fire coil (coils.fire_command, else coils.fire_valve) fires it;
# preset_and_command: the preset, fired when fire_command is written the command value;
# host_timed_coil: the fire_valve coil is the valve itself.
FIRE_STYLES = ("pulse_register", "preset_and_coil", "preset_and_command", "plc_preset_coil", "host_timed_coil")


@dataclass(frozen=True)
class Point:
    """One signal's place: an address (bits) or an address with a register format."""

    address: int
    type: str = "uint16"
    word_order: str = "big"
    scale: float = 1.0
    offset: float = 0.0

    @property
    def words(self) -> int:
        return TYPES[self.type][1]

    @property
    def addresses(self) -> range:
        return range(self.address, self.address + self.words)

    def pack(self, value: float) -> list[int]:
        """The register words that show `value` (saturated at the register's range)."""
        code, _, low, high = TYPES[self.type]
        raw = (value - self.offset) / self.scale
        raw = min(max(raw, low), high) if math.isfinite(raw) else high
        data = struct.pack(">" + code, raw if self.type == "float32" else int(round(raw)))
        words = [int.from_bytes(data[i:i + 2], "big") for i in range(0, len(data), 2)]
        return words[::-1] if self.word_order == "little" else words

    def unpack(self, words: list[int]) -> float:
        """The value written as these register words."""
        ordered = words[::-1] if self.word_order == "little" else words
        data = b"".join(int(w).to_bytes(2, "big") for w in ordered)
        (raw,) = struct.unpack(">" + TYPES[self.type][0], data)
        return raw * self.scale + self.offset


ControllerMap = dict[str, dict[str, Point]]


def default_map() -> ControllerMap:
    """The simulated controller's layout (config/sim.toml and config/rig-sim.toml spell it out):
    valve positions after a gap in the discrete inputs, a 32-bit pulse counter after a gap."""
    return {
        "coils": {"fire_valve": Point(0), "fill_valve": Point(1), "vent_valve": Point(2), "vacuum_pump": Point(3)},
        "discrete_inputs": {"door_closed": Point(0), "fixture_clamped": Point(1), "estop_healthy": Point(2),
                            "fire_valve_open": Point(8), "fill_valve_open": Point(9), "vent_valve_open": Point(10)},
        "holding_registers": {"pressure_setpoint": Point(0, scale=0.001), "projectile": Point(1),
                              "heartbeat": Point(2), "watchdog_ms": Point(3), "fire_pulse_ms": Point(4)},
        "input_registers": {"reservoir_pressure": Point(0, scale=0.001), "fixture_vacuum": Point(1, scale=0.1),
                            "watchdog_state": Point(2), "fire_pulse_count": Point(4, type="uint32")},
    }
