"""Plausibility of the controller's readings: a number that cannot be true is caught before
anything moves, at `probe` and at CHECK, and named with its register and the likely cause.

Each signal has a physical range (`plausible_ranges`, from [limits] and [plausibility]):

    reservoir_pressure   what the reservoir gauge can read (gauge bar; never below -1.013 bar)
    fixture_vacuum       an absolute pressure: 0 .. ~1100 mbar
    pressure_setpoint    within the limits: 0 .. limits.max_pressure_bar
    fire_pulse_count     a whole count of 0 .. plausibility.pulse_count_max pulses, and it does
                         not move while nothing fires
    watchdog_state, watchdog_ms, fire_pulse_ms, projectile: their codes' and values' ranges

A reading outside its range, not a number, not whole where it counts, a float32 that is not
zero but below 1e-9 (no rig gauge reports 2.4e-43: two words swapped often read so), or a
32-bit count that is an exact multiple of 65536 while the other word order reads a small one,
is implausible. `judge` then tries what a register map commonly gets wrong, in this order: the
other word order, the other register types (Register.reinterpretations), a unit or a power of
ten in the scale; the first reading that would be plausible is the likely cause, with the
rig.toml change that gives it. The judging is pure; `read_and_judge` reads a signal (its raw
words too, from the project's Modbus driver) and judges it.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from hopkinson.drivers.registers import Register, RegisterMap

if TYPE_CHECKING:
    from hopkinson.rig.config import RigConfig

RESERVOIR = "input_registers.reservoir_pressure"
VACUUM = "input_registers.fixture_vacuum"
SETPOINT = "holding_registers.pressure_setpoint"
PULSE_COUNT = "input_registers.fire_pulse_count"
# Signals CHECK judges (read through the role, so a lab's own driver is judged too).
CHECKED_AT_CHECK = (RESERVOIR, VACUUM, SETPOINT, PULSE_COUNT)
_ROLE_READS = {RESERVOIR: "reservoir_pressure_bar", VACUUM: "fixture_vacuum_mbar",
               SETPOINT: "pressure_setpoint_bar", PULSE_COUNT: "fire_pulse_count"}
# Units a register may really be in, per the unit the rig wants: (name, factor to the rig's unit).
_UNITS = {
    "bar": (("mbar", 1e-3), ("kPa", 1e-2), ("Pa", 1e-5), ("psi", 0.0689476), ("MPa", 10.0)),
    "mbar": (("Pa", 1e-2), ("kPa", 10.0), ("bar", 1e3), ("Torr", 1.333224), ("psi", 68.9476)),
}


@dataclass(frozen=True)
class Plausible:
    """What a signal can read at all: `low` .. `high` `unit` (whole numbers when `whole`)."""

    what: str
    unit: str
    low: float
    high: float
    why: str
    whole: bool = False

    def holds(self, value: float) -> bool:
        return math.isfinite(value) and self.low <= value <= self.high and (not self.whole or value == int(value))

    def show(self, value: float) -> str:
        """'4.07e+27 bar', '292552705'."""
        text = f"{value:.6g}" if not (self.whole and math.isfinite(value) and value == int(value)) else f"{int(value)}"
        return f"{text} {self.unit}".strip()


@dataclass(frozen=True)
class Implausible:
    """A reading that cannot be true: the signal, its value, where it was read, what it can be,
    the likely cause and the fix."""

    signal: str  # "input_registers.reservoir_pressure"
    rule: Plausible
    value: float
    where: str  # "input registers 0..1, float32 big"
    problem: str  # why it cannot be true
    cause: str  # the likely cause
    fix: str

    @property
    def message(self) -> str:
        return (f"{self.rule.what} reads {self.rule.show(self.value)} ({self.signal}: {self.where}), "
                f"which cannot be true ({self.problem}): {self.cause}")

    def __str__(self) -> str:
        return self.message


class ImplausibleReading(ValueError):
    """A reading that cannot be true (for `probe`'s steps: carries the fix)."""

    def __init__(self, finding: Implausible) -> None:
        super().__init__(finding.message)
        self.finding = finding
        self.fix = finding.fix


def plausible_ranges(config: RigConfig) -> dict[str, Plausible]:
    """signal ("table.name") -> its plausible range (module docstring)."""
    from hopkinson.rig.config import PlausibilityConfig

    p = getattr(config, "plausibility", None) or PlausibilityConfig()
    limits = config.limits
    low, high = p.reservoir_range_bar(limits)
    return {
        RESERVOIR: Plausible("the reservoir pressure", "bar", low, high,
                             f"the reservoir gauge reads {low:g} .. {high:g} bar, [plausibility] in rig.toml"),
        VACUUM: Plausible("the fixture vacuum", "mbar", 0.0, p.vacuum_max_mbar,
                          f"an absolute pressure lies between 0 and {p.vacuum_max_mbar:g} mbar"),
        SETPOINT: Plausible("the pressure set-point", "bar", 0.0, limits.max_pressure_bar,
                            f"a set-point lies within the limits 0 .. {limits.max_pressure_bar:g} bar"),
        PULSE_COUNT: Plausible("the fire pulse count", "", 0, p.pulse_count_max,
                               f"a whole count of 0 .. {p.pulse_count_max} pulses, more than a fire valve lives",
                               whole=True),
        "input_registers.watchdog_state": Plausible("the watchdog state", "", 0, 2, "0 off, 1 armed, 2 tripped",
                                                    whole=True),
        "holding_registers.watchdog_ms": Plausible("the watchdog time", "ms", 0, 3_600_000, "0 .. 1 h"),
        "holding_registers.fire_pulse_ms": Plausible("the fire pulse length", "ms", 0, 60_000, "0 .. 60 s"),
        "holding_registers.projectile": Plausible("the projectile", "", 0, 3, "0 (none) or 1 .. 3", whole=True),
    }


def judge(signal: str, value: float, rule: Plausible, register: Register | None = None,
          words: Sequence[int] | None = None) -> Implausible | None:
    """None when `value` can be true; else what is wrong and its likely cause (module docstring).
    `register` and `words`: how and from what the value was decoded (to try the other readings)."""
    where = register.describe(signal.split(".")[0]) if register is not None else "read by the driver"
    problem = _problem(value, rule, register, words)
    if problem is None:
        return None
    cause, fix = _likely_cause(signal, value, rule, register, words)
    return Implausible(signal, rule, value, where, problem, cause, fix)


def _problem(value: float, rule: Plausible, register: Register | None, words: Sequence[int] | None) -> str | None:
    if not math.isfinite(value):
        return "not a number"
    if register is not None and words is not None and register.implausibly_small(words):
        return "a float32 this close to zero is no instrument's reading"
    if not rule.holds(value):
        return rule.why
    swapped = _swapped_small_count(rule, register, words)
    if swapped is not None:
        return f"{rule.show(value)} is exactly {int(value) // 65536} × 65536, and the other word order reads {swapped}"
    return None


def _swapped_small_count(rule: Plausible, register: Register | None, words: Sequence[int] | None) -> int | None:
    """A whole 32-bit count whose words came in the wrong order reads n × 65536; the right order
    reads n. The other order's reading when this is so, else None."""
    if not rule.whole or register is None or words is None or register.words != 2 or register.is_float:
        return None
    raw = register.raw(words)
    if raw == 0 or raw % 65536:
        return None
    other = register.reinterpretations()[0]  # the same type in the other word order
    small = other.raw(words)
    return int(other.decode(words)) if 0 < small < 65536 else None


def _likely_cause(signal: str, value: float, rule: Plausible, register: Register | None,
                  words: Sequence[int] | None) -> tuple[str, str]:
    key = f"valve_controller.{signal}"
    if register is not None and words is not None:
        for other in register.reinterpretations():
            reading = other.decode(words)
            if rule.holds(reading) and not other.implausibly_small(words) and _problem(reading, rule, other, words) is None:
                change = other.changes_from(register)
                kind = "the word order" if change.startswith("word_order") else "the register type"
                return (f"{kind}? read as {change} it is {rule.show(reading)}, which is plausible",
                        f"in rig.toml set {key} = {{ address = {register.address}, {_keys(other)} }}")
    if math.isfinite(value) and value != 0 and register is not None:
        for name, factor in _UNITS.get(rule.unit, ()):
            if rule.holds(value * factor):
                return (f"the unit? in {name} it would read {rule.show(value * factor)} (scale x{factor:g})",
                        f"check the unit of {key} in the PLC's documentation and set its scale "
                        f"(now {register.scale:g}) to match")
        for power in (1, -1, 2, -2, 3, -3, 4, -4, 6, -6):
            if rule.holds(value * 10.0**power):
                return (f"the scale? x1e{power:+d} it would read {rule.show(value * 10.0**power)}",
                        f"check {key}'s scale (now {register.scale:g}) against the PLC's documentation")
    return ("no other word order, register type or scale makes it plausible: check its address (a 0-based "
            "protocol address, not a 4xxxx number?), its type and its unit",
            f"compare {key} with the PLC's documentation; `hopkinson probe` reads every signal")


def _keys(register: Register) -> str:
    keys = f'type = "{register.type}", word_order = "{register.word_order}"'
    if register.scale != 1.0:
        keys += f", scale = {register.scale:g}"
    if register.offset:
        keys += f", offset = {register.offset:g}"
    return keys


def _modbus_register(valves: Any, signal: str) -> Register | None:
    """The signal's Register when `valves` is the project's Modbus driver and maps it."""
    register_map = getattr(valves, "map", None)
    if not isinstance(register_map, RegisterMap) or not hasattr(valves, "read_words"):
        return None
    table, name = signal.split(".")
    entry = getattr(getattr(register_map, table), name, None)
    if isinstance(entry, int):
        entry = Register(entry)
    return entry if isinstance(entry, Register) and entry.present else None


def read_signal(valves: Any, signal: str) -> tuple[float, Register | None, list[int] | None]:
    """(value, register, words): from the raw words with the project's Modbus driver, else
    through the role's method. InstrumentError when it cannot be read."""
    register = _modbus_register(valves, signal)
    if register is None:
        return float(getattr(valves, _ROLE_READS[signal])()), None, None
    table = signal.split(".")[0].replace("_", " ")
    got = valves.read_words(table, register.addresses)
    words = [got[a] for a in register.addresses]
    return register.decode(words), register, words


def read_and_judge(valves: Any, config: RigConfig, signal: str) -> tuple[float, Implausible | None]:
    """Read one signal and judge it (InstrumentError when it cannot be read)."""
    value, register, words = read_signal(valves, signal)
    return value, judge(signal, value, plausible_ranges(config)[signal], register, words)


def controller_findings(valves: Any, config: RigConfig) -> tuple[dict[str, float], list[Implausible]]:
    """The readings CHECK judges (CHECKED_AT_CHECK; the pulse count where the controller has a
    counter) and what cannot be true among them."""
    readings: dict[str, float] = {}
    findings: list[Implausible] = []
    for signal in CHECKED_AT_CHECK:
        if signal == PULSE_COUNT and not getattr(valves, "has_pulse_counter", True):
            continue
        readings[signal], finding = read_and_judge(valves, config, signal)
        if finding is not None:
            findings.append(finding)
    return readings, findings


def counter_moved(rule: Plausible, before: float, after: float, seconds: float) -> Implausible | None:
    """A pulse count that moved while nothing fired cannot be a count of fire pulses."""
    if before == after:
        return None
    return Implausible(PULSE_COUNT, rule, after, "read twice", f"it moved from {rule.show(before)} in {seconds:.2g} s "
                       "while nothing fired", "the register is not the pulse counter (address or type), or "
                       "another program is firing this rig",
                       "compare valve_controller.input_registers.fire_pulse_count with the PLC's documentation")
