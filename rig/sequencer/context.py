"""What one shot carries through the steps: the request, the fire authorisation, the held abort,
the state's clock, the event publisher, and everything the steps learn on the way.

The steps (rig/sequencer/steps.py) are functions of a `ShotContext`; they stop the shot by
raising `Abort` (or letting an InstrumentError through), and never print.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from hopkinson.rig.errors import HINT_OPERATOR_ABORT, HINT_TIMEOUT, HINT_WATCHDOG
from hopkinson.rig.events import EventBus, Note, RigEvent, RigWarning, StepProgress
from hopkinson.rig.interlocks import REQUIRED, InterlockReport, evaluate, read_readings
from hopkinson.rig.sequencer.states import State, state_timeout_s

if TYPE_CHECKING:
    from hopkinson.rig.config import RigConfig
    from hopkinson.rig.instruments import Instruments
    from hopkinson.rig.shot import CapturedShot, ShotRequest

POLL_INTERVAL_S = 0.05  # watch loops: one read of the interlocks per poll
READINGS_INTERVAL_S = 0.1  # Reading events at most 10 Hz
PROGRESS_INTERVAL_S = 0.5  # StepProgress events of evacuation/charging at most 2 Hz


class FireAuthorisation:
    """The confirmation that the shot may be fired; thread-safe.

    The panel calls give() when the operator confirms (withdraw() takes it back while the
    sequencer waits in ARM); `pre_given()` is for `--yes` and a campaign's authorisation.
    """

    def __init__(self) -> None:
        self._event = threading.Event()

    @classmethod
    def pre_given(cls) -> FireAuthorisation:
        authorisation = cls()
        authorisation.give()
        return authorisation

    def give(self) -> None:
        self._event.set()

    def withdraw(self) -> None:
        self._event.clear()

    @property
    def given(self) -> bool:
        return self._event.is_set()


class AbortRequest:
    """An abort, held from the moment it is asked until it is honoured (thread-safe).

    `request` only sets a flag and remembers the first reason: it is safe from any thread and
    from a signal watcher, and asking again changes nothing. The sequencer honours it at its
    next check (or, asked before a shot starts, in that shot's CHECK, before anything moves).
    """

    def __init__(self) -> None:
        self._event = threading.Event()
        self._lock = threading.Lock()
        self._reason = ""

    def request(self, reason: str) -> None:
        with self._lock:
            if not self._event.is_set():
                self._reason = reason or "abort requested"
                self._event.set()

    @property
    def requested(self) -> bool:
        return self._event.is_set()

    @property
    def reason(self) -> str:
        return self._reason

    def wait(self, timeout_s: float) -> bool:
        """Sleep up to `timeout_s`, woken early by an abort; True when one is held."""
        return self._event.wait(timeout_s)

    def clear(self) -> None:
        with self._lock:
            self._event.clear()
            self._reason = ""


class Abort(Exception):
    """Stop the shot: `source` is the instrument (or "operator", "sequencer"), `reason` why,
    `hint` what the operator does, `codes` the failing interlocks when that is why."""

    def __init__(self, source: str, reason: str, hint: str = "", codes: tuple[str, ...] = ()) -> None:
        super().__init__(f"{source}: {reason}")
        self.source = source
        self.reason = reason
        self.hint = hint
        self.codes = codes


class Publisher:
    """The bus, with the sequencer's rules for frequent events: a Reading the first time in a
    state and then at most every READINGS_INTERVAL_S; a StepProgress at most every
    PROGRESS_INTERVAL_S unless forced."""

    def __init__(self, bus: EventBus) -> None:
        self.bus = bus
        self.state = State.IDLE
        self._last_reading_t = -1e9
        self._last_reading_state: State | None = None
        self._last_progress_t = -1e9

    def publish(self, event: RigEvent) -> RigEvent:
        return self.bus.publish(event)

    def reading(self, report: InterlockReport) -> None:
        now = time.monotonic()
        if self.state != self._last_reading_state or now - self._last_reading_t >= READINGS_INTERVAL_S:
            self._last_reading_t, self._last_reading_state = now, self.state
            self.bus.publish(report.reading(self.state))

    def progress(self, message: str, force: bool = False, **figures: Any) -> None:
        now = time.monotonic()
        if force or now - self._last_progress_t >= PROGRESS_INTERVAL_S:
            self._last_progress_t = now
            self.bus.publish(StepProgress(state=self.state, message=message, **figures))

    def note(self, message: str) -> None:
        self.bus.publish(Note(state=self.state, message=message))

    def warn(self, message: str) -> None:
        self.bus.publish(RigWarning(state=self.state, message=message))


BeforeFire = Callable[["ShotContext"], None]
AfterStore = Callable[["ShotContext", Any], None]


@dataclass
class ShotContext:
    """One shot on its way through the states (module docstring).

    before_fire: called in FIRE after every check, immediately before the fire pulse is
    commanded (a campaign journals FIRING there); an exception from it aborts the shot unfired.
    after_store: called with the shot file's path once the raw data has its final name.
    """

    request: ShotRequest
    authorisation: FireAuthorisation
    instruments: Instruments
    config: RigConfig
    abort: AbortRequest
    events: Publisher
    params: Any = None  # the AnalysisOptions, checked before anything moves
    poll_s: float = POLL_INTERVAL_S
    before_fire: BeforeFire | None = None
    after_store: AfterStore | None = None
    # the state's clock
    timeout_s: float | None = None
    deadline: float = 0.0
    # what the steps learn
    setpoint_bar: float | None = None
    fired: bool = False  # the fire command went out (the projectile may be on its way)
    fire_confirmed_by: str | None = None  # what confirmed the shot (pulse counter, valve read-back, trigger)
    pulse_count: int | None = None
    captured: CapturedShot | None = None
    identities: dict[str, str] = field(default_factory=dict)
    settings: dict[str, Any] = field(default_factory=dict)
    warnings: list[str] = field(default_factory=list)
    controller_timed_out: bool = False
    untrusted_gauge: Any = None  # CHECK's Implausible reading of the reservoir gauge: SAFE trusts it no more
    interrupt: BaseException | None = None
    last_report: InterlockReport | None = None

    @property
    def state(self) -> State:
        return self.events.state

    def start_clock(self, state: State) -> None:
        """The state's own time limit starts now."""
        self.timeout_s = state_timeout_s(self.config, state)
        self.deadline = time.monotonic() + (self.timeout_s if self.timeout_s is not None else 0.0)

    def set_deadline(self, wait_s: float) -> None:
        """A wait with its own limit (e.g. the fire confirmation), replacing the state's."""
        self.timeout_s, self.deadline = None, time.monotonic() + wait_s

    def checkpoint(self, source: str, waiting_for: str, honour_abort: bool = True) -> None:
        """Raise Abort when an abort is held (if honoured) or the state's time is up."""
        if honour_abort and self.abort.requested:
            raise Abort("operator", f"aborted: {self.abort.reason}", HINT_OPERATOR_ABORT)
        if self.timeout_s is not None and time.monotonic() > self.deadline:
            raise Abort(source, f"timed out after {self.timeout_s:g} s {waiting_for}", HINT_TIMEOUT)

    def pause(self, source: str, waiting_for: str) -> None:
        """Wait one poll interval (woken early by an abort), then check."""
        self.abort.wait(self.poll_s)
        self.checkpoint(source, waiting_for)

    def warn(self, message: str) -> None:
        """A warning kept with the shot (in its outcome) and published."""
        self.warnings.append(message)
        self.events.warn(message)

    def watch(self, state: State, *, charging: bool = False, digitizer: bool = False,
              required: tuple[str, ...] | None = None) -> InterlockReport:
        """Read and judge the interlocks of `state`; publish a Reading; Abort if one is lost."""
        names = required if required is not None else REQUIRED[state.value]
        readings = read_readings(self.instruments, amplifier="amplifier" in names, digitizer=digitizer)
        report = evaluate(readings, self.config.limits, names, self.setpoint_bar, charging)
        self.last_report = report
        self.events.reading(report)
        if not report.all_ok:
            self._raise_if_watchdog_tripped()
            failing = report.failing()
            raise Abort(self.source_of(failing[0]), f"interlock lost: {'; '.join(report.problems())}",
                        " ".join(dict.fromkeys(report.hints())), tuple(code.value for code in failing))
        return report

    def _raise_if_watchdog_tripped(self) -> None:
        """An interlock lost because the controller's link watchdog tripped (this process's
        heartbeat was missed: it de-energised and vented) is said as such."""
        valves = self.instruments.valves
        try:
            tripped = valves.watchdog_tripped()
        except Exception:  # noqa: BLE001 - only a better reason: the interlock's own stands otherwise
            return
        if tripped:
            raise Abort(valves.name, "the controller's link watchdog tripped (a heartbeat was missed): it closed fill "
                                     "and fire and vented the rig", HINT_WATCHDOG)

    def source_of(self, interlock: str) -> str:
        """The instrument an interlock is read from."""
        if interlock == "digitizer":
            return self.instruments.digitizer.instrument
        if interlock == "amplifier":
            return self.instruments.amplifier.name
        return self.instruments.valves.name

