"""Interlock checks: what must hold before (and while) the rig charges, arms and fires.

The interlocks, by name:

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
the rules are tested without a rig.
"""

from __future__ import annotations

from collections.abc import Collection
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from hopkinson.rig.config import LimitsConfig

if TYPE_CHECKING:
    from hopkinson.rig.instruments import Instruments

INTERLOCKS = ("door", "clamp", "estop", "vacuum", "pressure", "digitizer", "amplifier")
_BASIC = ("door", "clamp", "estop", "amplifier")

# Interlocks each sequencer state watches (the vacuum is the goal of EVACUATE, not a condition).
REQUIRED: dict[str, tuple[str, ...]] = {
    "CHECK": _BASIC,
    "EVACUATE": _BASIC,
    "CHARGE": (*_BASIC, "vacuum", "pressure"),
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

    name: str
    ok: bool
    detail: str


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

    def failing(self) -> list[str]:
        """Names of the failing interlocks."""
        return [check.name for check in self.checks if not check.ok]

    def as_dict(self) -> dict[str, bool]:
        return {check.name: check.ok for check in self.checks}

    def event_data(self) -> dict[str, Any]:
        """The data of a "reading" event."""
        r = self.readings
        data: dict[str, Any] = {
            "reservoir_pressure_bar": r.reservoir_pressure_bar,
            "fixture_vacuum_mbar": r.fixture_vacuum_mbar,
            "interlocks": self.as_dict(),
            "problems": self.problems(),
        }
        if r.amplifier_overloaded is not None:
            data["amplifier_overloaded"] = r.amplifier_overloaded
        if r.digitizer_state is not None:
            data["digitizer_state"] = r.digitizer_state
        return data


def pressure_check(pressure_bar: float, limits: LimitsConfig, setpoint_bar: float | None,
                   charging: bool) -> Interlock:
    """The pressure interlock.

    Always: pressure at most limits.max_pressure_bar. With a set-point, while charging: at
    most set-point + tolerance (the fill must not overshoot); charged (ARM, FIRE): within the
    tolerance of the set-point.
    """
    p = pressure_bar
    if p > limits.max_pressure_bar:
        return Interlock("pressure", False, f"reservoir {p:.3f} bar above the limit {limits.max_pressure_bar:g} bar")
    if setpoint_bar is None:
        return Interlock("pressure", True, f"reservoir {p:.3f} bar")
    tol = limits.pressure_tolerance_bar
    if p > setpoint_bar + tol:
        return Interlock("pressure", False,
                         f"reservoir {p:.3f} bar above the set-point {setpoint_bar:g} bar + {tol:g} bar "
                         "(fill valve not closing?)")
    if not charging and p < setpoint_bar - tol:
        return Interlock("pressure", False,
                         f"reservoir {p:.3f} bar below the set-point {setpoint_bar:g} bar - {tol:g} bar (leaking?)")
    return Interlock("pressure", True, f"reservoir {p:.3f} bar")


def evaluate(readings: RigReadings, limits: LimitsConfig, required: Collection[str],
             setpoint_bar: float | None = None, charging: bool = False) -> InterlockReport:
    """Judge the `required` interlocks from `readings` (pure; see the module docstring)."""
    unknown = set(required) - set(INTERLOCKS)
    if unknown:
        raise ValueError(f"unknown interlock(s) {sorted(unknown)}; known: {', '.join(INTERLOCKS)}")
    r = readings
    checks: list[Interlock] = []
    for name in INTERLOCKS:
        if name not in required:
            continue
        if name == "door":
            checks.append(Interlock(name, r.door_closed, "door/guard closed" if r.door_closed else "door/guard open"))
        elif name == "clamp":
            checks.append(Interlock(name, r.fixture_clamped,
                                    "fixture clamped" if r.fixture_clamped else "fixture not clamped"))
        elif name == "estop":
            checks.append(Interlock(name, r.estop_healthy, "e-stop healthy" if r.estop_healthy else "e-stop tripped"))
        elif name == "vacuum":
            ok = r.fixture_vacuum_mbar <= limits.fixture_vacuum_max_mbar
            relation = "at or below" if ok else "above"
            checks.append(Interlock(name, ok, f"fixture vacuum {r.fixture_vacuum_mbar:.1f} mbar {relation} "
                                              f"{limits.fixture_vacuum_max_mbar:g} mbar"))
        elif name == "pressure":
            checks.append(pressure_check(r.reservoir_pressure_bar, limits, setpoint_bar, charging))
        elif name == "digitizer":
            ok = r.digitizer_state == "ARMED"
            checks.append(Interlock(name, ok, "digitizer armed" if ok else f"digitizer not armed (state {r.digitizer_state})"))
        elif name == "amplifier":
            ok = r.amplifier_overloaded is False
            detail = {False: "amplifier not overloaded", True: "amplifier overloaded"}.get(
                r.amplifier_overloaded, "amplifier overload status not read")  # type: ignore[arg-type]
            checks.append(Interlock(name, ok, detail))
    return InterlockReport(readings, tuple(checks))


def read_readings(instruments: Instruments, *, amplifier: bool = True, digitizer: bool = False) -> RigReadings:
    """Read the controller's gauges and inputs (and the amplifier/digitizer when asked).

    Instrument errors propagate (InstrumentError names the instrument and the command).
    """
    valves = instruments.valves
    inputs = valves.interlocks()
    return RigReadings(
        reservoir_pressure_bar=valves.reservoir_pressure_bar(),
        fixture_vacuum_mbar=valves.fixture_vacuum_mbar(),
        door_closed=inputs.door_closed,
        fixture_clamped=inputs.fixture_clamped,
        estop_healthy=inputs.estop_healthy,
        amplifier_overloaded=instruments.amplifier.overloaded() if amplifier else None,
        digitizer_state=instruments.digitizer.acquisition_state() if digitizer else None,
    )
