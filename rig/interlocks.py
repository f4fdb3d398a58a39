"""Interlock checks: what must hold before (and while) the rig charges, arms and fires.

The interlocks, by code (`InterlockCode`; each carries the operator's hint, `code.hint`):

    door       door/guard closed                      (controller discrete input)
    clamp      fixture clamped                        (controller discrete input)
    estop      e-stop healthy                         (controller discrete input)
    vacuum     fixture vacuum below limits.fixture_vacuum_max_mbar (absolute)
    pressure   reservoir pressure where it should be (see `pressure_check`)
    digitizer  digitizer armed (and the arm command acknowledged: the driver checks the
               instrument's error queue with every setting)
    amplifier  bridge amplifier not overloaded

Which of them a state needs is REQUIRED (keyed by the sequencer's state names). Reading the
instruments (`read_readings`) is kept apart from judging the readings (`evaluate`, pure), so
the rules are tested without a rig. What the operator is told to do comes from the failing
interlocks' codes, never from the words of their detail text.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Collection
from dataclasses import dataclass
from enum import StrEnum
from typing import TYPE_CHECKING

from hopkinson.rig.config import LimitsConfig
from hopkinson.rig.events import Reading

if TYPE_CHECKING:
    from hopkinson.drivers.roles import ValveControllerRole
    from hopkinson.rig.instruments import Instruments


class InterlockCode(StrEnum):
    """The interlocks; `hint` is what the operator does when one does not hold."""

    DOOR = "door"
    CLAMP = "clamp"
    ESTOP = "estop"
    VACUUM = "vacuum"
    PRESSURE = "pressure"
    DIGITIZER = "digitizer"
    AMPLIFIER = "amplifier"

    @property
    def hint(self) -> str:
        return _HINTS[self]


_HINTS: dict[InterlockCode, str] = {
    InterlockCode.DOOR: "Close the door/guard, then ARM again.",
    InterlockCode.CLAMP: "Clamp the fixture, then ARM again.",
    InterlockCode.ESTOP: "Clear the cause, reset the e-stop, then ARM again.",
    InterlockCode.VACUUM: "Check the fixture seal and the vacuum pump, then ARM again.",
    InterlockCode.PRESSURE: "Check the reservoir: fill valve, leaks and the pressure set-point; the rig was vented.",
    InterlockCode.DIGITIZER: "Check the digitizer (trigger settings, another client using it), then ARM again.",
    InterlockCode.AMPLIFIER: "Check the accelerometer cable and the amplifier range; clear the overload.",
}

C = InterlockCode
INTERLOCKS: tuple[str, ...] = tuple(code.value for code in InterlockCode)
_BASIC = (C.DOOR.value, C.CLAMP.value, C.ESTOP.value, C.AMPLIFIER.value)

# Interlocks each sequencer state watches (the vacuum is the goal of EVACUATE, not a condition).
REQUIRED: dict[str, tuple[str, ...]] = {
    "CHECK": _BASIC,
    "EVACUATE": _BASIC,
    "CHARGE": (*_BASIC, C.VACUUM.value, C.PRESSURE.value),
    "ARM": INTERLOCKS,
    "FIRE": INTERLOCKS,
}


@dataclass(frozen=True)
class RigReadings:
    """One reading of every input the interlocks use; None = not read this time."""

    reservoir_pressure_bar: float
    fixture_vacuum_mbar: float
    door_closed: bool
    fixture_clamped: bool
    estop_healthy: bool
    amplifier_overloaded: bool | None = None
    digitizer_state: str | None = None  # "IDLE" | "ARMED" | "TRIGGERED"


@dataclass(frozen=True)
class Interlock:
    """One interlock judged: ok, and in words what is wrong (or what it is)."""

    code: InterlockCode
    ok: bool
    detail: str

    @property
    def name(self) -> str:
        return self.code.value

    @property
    def hint(self) -> str:
        return self.code.hint


@dataclass(frozen=True)
class InterlockReport:
    """Readings and the interlocks judged from them (only the required ones)."""

    readings: RigReadings
    checks: tuple[Interlock, ...]

    @property
    def all_ok(self) -> bool:
        return all(check.ok for check in self.checks)

    def problems(self) -> list[str]:
        """What is wrong, one plain phrase per failing interlock."""
        return [check.detail for check in self.checks if not check.ok]

    def failing(self) -> list[InterlockCode]:
        """Codes of the failing interlocks."""
        return [check.code for check in self.checks if not check.ok]

    def hints(self) -> list[str]:
        """What the operator does, one hint per failing interlock."""
        return [check.hint for check in self.checks if not check.ok]

    def as_dict(self) -> dict[str, bool]:
        return {check.name: check.ok for check in self.checks}

    def details(self) -> dict[str, str]:
        return {check.name: check.detail for check in self.checks}

    def reading(self, state: str, *, idle: bool = False) -> Reading:
        """The `Reading` event of this report."""
        r = self.readings
        return Reading(state=str(state), message="readings", reservoir_pressure_bar=r.reservoir_pressure_bar,
                       fixture_vacuum_mbar=r.fixture_vacuum_mbar, interlocks=self.as_dict(),
                       details=self.details(), amplifier_overloaded=r.amplifier_overloaded,
                       digitizer_state=r.digitizer_state, idle=idle)


def pressure_check(pressure_bar: float, limits: LimitsConfig, setpoint_bar: float | None,
                   charging: bool) -> Interlock:
    """The pressure interlock.

    Always: a finite reading (a gauge or register fault reads NaN, which no comparison would
    catch), at most limits.max_pressure_bar. With a set-point, while charging: at most
    set-point + tolerance (the fill must not overshoot); charged (ARM, FIRE): within the
    tolerance of the set-point.
    """
    p = pressure_bar
    if not math.isfinite(p):
        return Interlock(C.PRESSURE, False, f"reservoir gauge reads {p} (not a number: check the gauge and its "
                                            "register)")
    if p > limits.max_pressure_bar:
        return Interlock(C.PRESSURE, False, f"reservoir {p:.3f} bar above the limit {limits.max_pressure_bar:g} bar")
    if setpoint_bar is None:
        return Interlock(C.PRESSURE, True, f"reservoir {p:.3f} bar")
    tol = limits.pressure_tolerance_bar
    if p > setpoint_bar + tol:
        return Interlock(C.PRESSURE, False,
                         f"reservoir {p:.3f} bar above the set-point {setpoint_bar:g} bar + {tol:g} bar "
                         "(fill valve not closing?)")
    if not charging and p < setpoint_bar - tol:
        return Interlock(C.PRESSURE, False,
                         f"reservoir {p:.3f} bar below the set-point {setpoint_bar:g} bar - {tol:g} bar (leaking?)")
    return Interlock(C.PRESSURE, True, f"reservoir {p:.3f} bar")


def evaluate(readings: RigReadings, limits: LimitsConfig, required: Collection[str],
             setpoint_bar: float | None = None, charging: bool = False) -> InterlockReport:
    """Judge the `required` interlocks from `readings` (pure; see the module docstring)."""
    unknown = set(required) - set(INTERLOCKS)
    if unknown:
        raise ValueError(f"unknown interlock(s) {sorted(unknown)}; known: {', '.join(INTERLOCKS)}")
    checks = [_judge(C(name), readings, limits, setpoint_bar, charging) for name in INTERLOCKS if name in required]
    return InterlockReport(readings, tuple(checks))


def _judge(code: InterlockCode, r: RigReadings, limits: LimitsConfig, setpoint_bar: float | None,
           charging: bool) -> Interlock:
    """One interlock from the readings."""
    if code == C.DOOR:
        return Interlock(code, r.door_closed, "door/guard closed" if r.door_closed else "door/guard open")
    if code == C.CLAMP:
        return Interlock(code, r.fixture_clamped, "fixture clamped" if r.fixture_clamped else "fixture not clamped")
    if code == C.ESTOP:
        return Interlock(code, r.estop_healthy, "e-stop healthy" if r.estop_healthy else "e-stop tripped")
    if code == C.VACUUM:
        if not math.isfinite(r.fixture_vacuum_mbar):
            return Interlock(code, False, f"fixture vacuum gauge reads {r.fixture_vacuum_mbar} (not a number: check "
                                          "the gauge and its register)")
        ok = r.fixture_vacuum_mbar <= limits.fixture_vacuum_max_mbar
        relation = "at or below" if ok else "above"
        return Interlock(code, ok, f"fixture vacuum {r.fixture_vacuum_mbar:.1f} mbar {relation} "
                                   f"{limits.fixture_vacuum_max_mbar:g} mbar")
    if code == C.PRESSURE:
        return pressure_check(r.reservoir_pressure_bar, limits, setpoint_bar, charging)
    if code == C.DIGITIZER:
        ok = r.digitizer_state == "ARMED"
        return Interlock(code, ok, "digitizer armed" if ok else f"digitizer not armed (state {r.digitizer_state})")
    ok = r.amplifier_overloaded is False
    detail = {False: "amplifier not overloaded", True: "amplifier overloaded"}.get(
        r.amplifier_overloaded, "amplifier overload status not read")  # type: ignore[arg-type]
    return Interlock(code, ok, detail)


def read_readings(instruments: Instruments, *, amplifier: bool = True, digitizer: bool = False) -> RigReadings:
    """Read the controller's gauges and inputs (and the amplifier/digitizer when asked).

    Instrument errors propagate (InstrumentError names the instrument and the command).
    """
    readings = controller_readings(instruments.valves)
    return dataclasses.replace(
        readings,
        amplifier_overloaded=instruments.amplifier.overloaded() if amplifier else None,
        digitizer_state=instruments.digitizer.acquisition_state() if digitizer else None,
    )


def controller_readings(valves: ValveControllerRole) -> RigReadings:
    """The controller's gauges and interlock inputs only (what SAFE and `hopkinson safe` need)."""
    inputs = valves.interlocks()
    return RigReadings(
        reservoir_pressure_bar=valves.reservoir_pressure_bar(),
        fixture_vacuum_mbar=valves.fixture_vacuum_mbar(),
        door_closed=inputs.door_closed,
        fixture_clamped=inputs.fixture_clamped,
        estop_healthy=inputs.estop_healthy,
    )
