"""SAFE: the one procedure that makes the rig safe and confirms it, on every way out.

Run by the sequencer after every shot (done, aborted, timed out, interrupted, failed), by
`Sequencer.make_safe` (the panel's idle ABORT, a signal between shots) and by `hopkinson safe`
(with only the valve controller connected).

1. Fast path: fire closed, fill closed, vent open, pump off; the digitizer disarmed when asked
   (also when an error had closed its link: the driver reopens it for the abort).
2. Then, until confirmed or `timeouts.safe_s` has passed: the valves are read back (their coils
   and, where the controller reports them, their real positions: both must be as wanted) and
   any that is wrong is commanded again; the gauges are read. Confirmed when a whole round had no instrument
   error, every valve is as wanted and the reservoir (plus half a gauge count: the gauge rounds
   to the nearest count) is at or below `limits.vent_done_bar`. Not confirmed in time: the
   problem names every valve not as wanted (a stuck one: its real position against its
   command) and the reservoir pressure; when the last round failed with an instrument error,
   that error and the valves last read in a position other than their command
   (`ValveStates.mismatches`).
3. After a Modbus timeout the controller may still carry out a request it did not answer in
   time (a late "fill open" after SAFE closed it), so SAFE then keeps re-checking for
   `safe_hold_s` before it confirms.
4. A reservoir reading that cannot be true (rig/plausibility.py: a word-order or scale
   mistake reads 4e27 bar, or 2e-41 bar for 5 bar) never counts as vented, and venting is not
   waited for: once the valves read back as wanted, SAFE ends unconfirmed at once, saying the
   pressure is unknown and why (never "fill valve stuck open?"). Once seen (or handed in by
   CHECK), the gauge stays untrusted: a later reading that happens to look right confirms nothing.

SAFE never raises: an instrument error is retried within the time; an interrupt (Ctrl-C) that
arrives meanwhile is held and handed back in the result, for the caller to re-raise once the
rig is safe.
"""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from hopkinson.drivers.errors import InstrumentError, InstrumentTimeout
from hopkinson.rig.errors import HINT_SAFE_NOT_CONFIRMED
from hopkinson.rig.events import RigError
from hopkinson.rig.interlocks import controller_readings, evaluate
from hopkinson.rig.plausibility import RESERVOIR, Implausible, plausible_ranges, read_and_judge
from hopkinson.rig.sequencer.context import POLL_INTERVAL_S, Publisher

if TYPE_CHECKING:
    from hopkinson.drivers.roles import DigitizerRole, ValveControllerRole, ValveStates
    from hopkinson.rig.config import RigConfig

# Interlocks judged for display while the rig is made or kept safe (SAFE, STORE, ANALYSE).
DISPLAY_INTERLOCKS = ("door", "clamp", "estop", "vacuum", "pressure")
WANTED = {"fire_valve": False, "fill_valve": False, "vent_valve": True, "vacuum_pump": False}


@dataclass(frozen=True)
class SafeResult:
    """How SAFE ended: confirmed, or the problem; the last read-back; a held interrupt."""

    confirmed: bool
    problem: str | None = None
    reservoir_pressure_bar: float | None = None
    valves: Any = None  # the last ValveStates read back
    controller_timed_out: bool = False
    interrupt: BaseException | None = None
    elapsed_s: float = 0.0


def safe_hold_s(config: RigConfig) -> float:
    """How long SAFE keeps re-checking the valves after a Modbus timeout (module docstring)."""
    return min(max(1.0, 4.0 * config.valve_controller.timeout_s), config.timeouts.safe_s / 2)


def _as_wanted(states: ValveStates, name: str) -> bool:
    """The actuator's coil is as SAFE wants it and, where the controller reports the valve's
    real position, so is the valve: a fill coil left energised behind a valve the controller's
    regulation happens to hold shut is not "closed" (it opens once the pressure drops)."""
    wanted = WANTED[name]
    return bool(getattr(states, name)) == wanted and (name == "vacuum_pump" or states.is_open(name) == wanted)


def gauge_half_count_bar(valves: ValveControllerRole, config: RigConfig) -> float:
    """Half a count of the reservoir gauge, bar (0 for a float gauge)."""
    resolution = getattr(valves, "pressure_resolution_bar", None)
    if resolution is None:
        resolution = config.valve_controller.gauge_resolution_bar
    return 0.5 * float(resolution)


def make_rig_safe(valves: ValveControllerRole, config: RigConfig, events: Publisher, *,
                  digitizer: DigitizerRole | None = None, controller_timed_out: bool = False,
                  poll_s: float = POLL_INTERVAL_S, untrusted_gauge: Implausible | None = None) -> SafeResult:
    """Make the rig safe and confirm it by reading back (module docstring); never raises.
    untrusted_gauge: the reservoir gauge already read something that cannot be true (CHECK's
    finding): no reading of it confirms "vented"."""
    limits = config.limits
    start = time.monotonic()
    deadline = start + config.timeouts.safe_s
    setters: dict[str, Callable[[bool], None]] = {
        "fire_valve": valves.set_fire_valve, "fill_valve": valves.set_fill_valve,
        "vent_valve": valves.set_vent_valve, "vacuum_pump": valves.set_vacuum_pump}
    problem: str | None = None
    errors = 0  # instrument errors so far: a round without a new one can confirm
    interrupt: BaseException | None = None
    timed_out = controller_timed_out

    def attempt(action: Callable[[], Any]) -> Any:
        nonlocal problem, errors, interrupt, timed_out
        try:
            return action()
        except InstrumentError as exc:
            problem, errors = str(exc), errors + 1
            if isinstance(exc, InstrumentTimeout) and exc.instrument == valves.name:
                timed_out = True
        except Exception as exc:  # keep going: every other step may still work
            problem, errors = f"sequencer: unexpected error: {type(exc).__name__}: {exc}", errors + 1
            logging.getLogger(__name__).exception("in SAFE")
        except BaseException as exc:  # an interrupt: held until the rig is safe
            if interrupt is None:
                interrupt = exc
        return None

    for name, wanted in WANTED.items():  # the fast path first
        attempt(lambda name=name, wanted=wanted: setters[name](wanted))
    if digitizer is not None:  # a link an error closed is reopened for it (the driver's rule): never left armed
        attempt(lambda: _disarm(digitizer, events))

    half_count = gauge_half_count_bar(valves, config)
    reservoir_rule = plausible_ranges(config)[RESERVOIR]
    finding: Implausible | None = untrusted_gauge  # once seen, the gauge stays untrusted
    confirmed = False
    states = readings = last_states = None
    while True:
        errors_before = errors
        states = attempt(valves.valves)
        last_states = states if states is not None else last_states
        wrong = [] if states is None else [n for n in WANTED if not _as_wanted(states, n)]
        for name in wrong:  # not as wanted (or changed late): command it again
            attempt(lambda name=name: setters[name](WANTED[name]))
        readings = attempt(lambda: controller_readings(valves))
        if readings is not None:
            report = evaluate(readings, limits, DISPLAY_INTERLOCKS)
            attempt(lambda report=report: events.reading(report))
        vented = readings is not None and readings.reservoir_pressure_bar + half_count <= limits.vent_done_bar
        if readings is not None and (vented or not reservoir_rule.holds(readings.reservoir_pressure_bar)) \
                and math.isfinite(readings.reservoir_pressure_bar):  # NaN: waited for (a gauge fault may clear)
            judged = attempt(lambda: read_and_judge(valves, config, RESERVOIR))  # with its words: the cause
            finding = finding or (judged[1] if judged is not None else None)
            vented = vented and judged is not None and finding is None
        clean_round = errors == errors_before and states is not None and readings is not None
        now = time.monotonic()
        hold_until = start + (safe_hold_s(config) if timed_out else 0.0)
        if clean_round and not wrong and vented and now >= hold_until:
            confirmed = True
            break
        if clean_round and not wrong and finding is not None and now >= hold_until:
            problem = (f"{valves.name}: the valves read back safe (fire and fill closed, vent open, pump off), but "
                       f"{finding.message}: the reservoir pressure is unknown")
            break
        if now >= deadline:
            if clean_round:
                problem = _what_is_wrong(valves.name, states, wrong, readings.reservoir_pressure_bar, vented, config,
                                         finding)
            elif last_states is not None and last_states.mismatches():  # a stuck valve seen before the error
                problem = f"{problem}; last read back: {'; '.join(last_states.mismatches())}"
            break
        try:
            time.sleep(poll_s)
        except BaseException as exc:  # an interrupt while we sleep: hold it, carry on
            if interrupt is None:
                interrupt = exc
    pressure = readings.reservoir_pressure_bar if readings is not None else None
    elapsed = time.monotonic() - start
    if confirmed:
        attempt(lambda: events.note(f"rig safe: fire and fill closed, vent open, pump off, reservoir "
                                    f"{pressure:.3f} bar (confirmed by reading back in {elapsed:.2f} s)"))
    else:
        attempt(lambda: events.publish(RigError(state=events.state, message=f"SAFE NOT CONFIRMED: {problem}",
                                                source=valves.name, hint=HINT_SAFE_NOT_CONFIRMED)))
    return SafeResult(confirmed, None if confirmed else problem, pressure, states, timed_out, interrupt, elapsed)


def _disarm(digitizer: DigitizerRole, events: Publisher) -> None:
    """Disarm the digitizer; one that cannot be reached is said, not hidden (SAFE goes on)."""
    try:
        digitizer.abort()
    except InstrumentError as exc:
        events.warn(f"SAFE could not disarm the digitizer ({exc}): it may still be armed; it holds no record of "
                    "this rig's to keep")


def _what_is_wrong(name: str, states: ValveStates, wrong: list[str], pressure_bar: float, vented: bool,
                   config: RigConfig, finding: Implausible | None = None) -> str:
    """Every reason SAFE could not confirm, in one line."""
    parts = []
    for valve in wrong:
        label = valve.replace("_", " ")
        if valve == "vacuum_pump":
            parts.append(f"{label} still on")
            continue
        word = {True: "open", False: "shut"}
        position = getattr(states, f"{valve}_position", None)
        told = word[bool(getattr(states, valve))]
        seen = f"{word[bool(position)]} (commanded {told})" if position is not None else f"{told} (coil)"
        parts.append(f"{label} {seen}, wanted {word[WANTED[valve]]} after {config.timeouts.safe_s:g} s")
    if finding is not None:
        parts.append(f"{finding.message}: the reservoir pressure is unknown")
    elif not vented:
        parts.append(f"reservoir still at {pressure_bar:.3f} bar after venting for {config.timeouts.safe_s:g} s "
                     f"(needs at most {config.limits.vent_done_bar:g} bar; fill valve stuck open?)")
    return f"{name}: " + "; ".join(parts)
