"""The event bus: how the sequencer tells the command line, the campaign runner, the panel and
the logbook what it is doing. The core never prints; it publishes typed events.

Every event is a small frozen dataclass deriving from `RigEvent`, with `state` (the sequencer
state it happened in, or "CAMPAIGN"), `message` (one line for people), `utc` (ISO 8601, Z) and
`to_dict()` (JSON-ready, with a `"type"` field naming the class). Consumers dispatch on the
class (`isinstance(event, Fired)`), never on the text of a message.

Shot events (rig.sequencer):

- `StateEntered`: the sequencer entered `state` (published before the state's first action);
- `StepProgress`: a step inside a state ("charging 0.62 of 1.00 bar"), with its figures;
- `Identified`: the instruments' identities (CHECK);
- `AwaitingConfirmation`: armed, the sequencer waits up to `timeout_s` for the fire confirmation;
- `Fired`: the shot was fired, as its `confirmed_by` says (pulse counter, valve read-back, trigger);
- `Stored`: the raw shot file has its final name; `Analysed`: the analysis (or its failure)
  is stored in it;
- `Reading`: gauges and interlocks (up to ~10 Hz while a shot runs, ~2 Hz idle in the panel);
- `Note`, `RigWarning`, `RigError`: a note, a warning, and why the shot is being aborted (with
  an operator `hint` and the failing interlocks' `codes`);
- `ShotFinished`: how the shot ended (the ShotOutcome's fields, without the results dict).

Campaign events (rig.campaign): `CampaignShotStarted`, `CampaignShotEnded` (with the journal
state), `CampaignFinished`.

Subscribers are called synchronously in the publishing thread (the sequencer's), in the order
they subscribed; they must return quickly (the panel hands events to its GUI thread through a
queued signal, the command line prints a line). An exception raised by a subscriber is logged
and swallowed: a failing subscriber never breaks the sequencer. Exceptions that are not
`Exception` (KeyboardInterrupt, SystemExit) do propagate: the sequencer treats them as an
interrupt and still runs SAFE.
"""

from __future__ import annotations

import logging
import queue
import threading
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field, fields
from datetime import UTC, datetime
from typing import Any, ClassVar

_log = logging.getLogger(__name__)

CAMPAIGN_STATE = "CAMPAIGN"  # the `state` of the campaign runner's own events


def utc_now_iso() -> str:
    """The current UTC time as ISO 8601 text ending in Z (as in shot files)."""
    return datetime.now(UTC).isoformat(timespec="microseconds").replace("+00:00", "Z")


def _jsonable(value: Any) -> Any:
    if isinstance(value, Mapping):
        return {str(k): _jsonable(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_jsonable(v) for v in value]
    if value is None or isinstance(value, bool | int | float | str):
        return value
    return str(value)


@dataclass(frozen=True, kw_only=True)
class RigEvent:
    """One thing the rig did or saw; `state` is the sequencer state it happened in.

    LEVEL: "info", "warning" or "error"; LABEL: a word for a log's "kind" column (display
    only: consumers dispatch on the class).
    """

    LEVEL: ClassVar[str] = "info"
    LABEL: ClassVar[str] = "event"

    state: str
    message: str
    utc: str = field(default_factory=utc_now_iso)

    @property
    def type(self) -> str:
        """The event's type name (its class name): the `"type"` of `to_dict()`."""
        return type(self).__name__

    @property
    def level(self) -> str:
        return self.LEVEL

    @property
    def label(self) -> str:
        """"state", "progress", "warning", "error", ...: the level when it is not "info"."""
        return self.level if self.level != "info" else self.LABEL

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready: {"type": ..., "utc": ..., "state": ..., "message": ..., fields...}."""
        out: dict[str, Any] = {"type": self.type, "level": self.level}
        for f in fields(self):
            out[f.name] = _jsonable(getattr(self, f.name))
        return out


@dataclass(frozen=True, kw_only=True)
class StateEntered(RigEvent):
    """The sequencer entered `state`; `timeout_s` is the state's limit (None: none)."""

    LABEL: ClassVar[str] = "state"

    timeout_s: float | None = None


@dataclass(frozen=True, kw_only=True)
class StepProgress(RigEvent):
    """A step inside a state; the figures that apply are set, the others None."""

    LABEL: ClassVar[str] = "progress"

    reservoir_pressure_bar: float | None = None
    target_bar: float | None = None
    fixture_vacuum_mbar: float | None = None
    samples: int | None = None
    sample_rate_hz: float | None = None


@dataclass(frozen=True, kw_only=True)
class Identified(RigEvent):
    """The instruments' identities (name -> what each says it is), read in CHECK."""

    LABEL: ClassVar[str] = "identity"

    identities: Mapping[str, str] = field(default_factory=dict)


@dataclass(frozen=True, kw_only=True)
class AwaitingConfirmation(RigEvent):
    """Armed: the sequencer waits up to `timeout_s` for the fire confirmation."""

    LABEL: ClassVar[str] = "progress"

    timeout_s: float


@dataclass(frozen=True, kw_only=True)
class Fired(RigEvent):
    """The shot was fired, as something confirmed (`confirmed_by`: the controller's pulse
    counter, the fire valve's read-back, or the digitizer's trigger); never on the command alone."""

    LABEL: ClassVar[str] = "fired"

    reservoir_pressure_bar: float
    pulse_s: float
    pulse_count: int | None = None
    confirmed_by: str = ""


@dataclass(frozen=True, kw_only=True)
class Stored(RigEvent):
    """The raw shot file is on disk under its final name."""

    LABEL: ClassVar[str] = "stored"

    shot_path: str


@dataclass(frozen=True, kw_only=True)
class Analysed(RigEvent):
    """The analysis of `shot_path` is stored in it (`error` set when it failed)."""

    LABEL: ClassVar[str] = "analysed"

    shot_path: str
    error: str | None = None

    @property
    def ok(self) -> bool:
        return self.error is None

    @property
    def level(self) -> str:
        return "info" if self.error is None else "warning"


@dataclass(frozen=True, kw_only=True)
class Reading(RigEvent):
    """Gauges and interlocks. interlocks: name -> holds (only those judged); details: name ->
    what it is in words; problems: the failing ones' words, in order."""

    LABEL: ClassVar[str] = "reading"

    reservoir_pressure_bar: float
    fixture_vacuum_mbar: float
    interlocks: Mapping[str, bool] = field(default_factory=dict)
    details: Mapping[str, str] = field(default_factory=dict)
    amplifier_overloaded: bool | None = None
    digitizer_state: str | None = None
    idle: bool = False  # read by the panel between shots, not by a running shot

    @property
    def problems(self) -> list[str]:
        return [self.details.get(name, name) for name, ok in self.interlocks.items() if not ok]


@dataclass(frozen=True, kw_only=True)
class Note(RigEvent):
    """A note for the operator."""

    LABEL: ClassVar[str] = "note"


@dataclass(frozen=True, kw_only=True)
class RigWarning(RigEvent):
    """Something the operator should know; the shot goes on."""

    LEVEL: ClassVar[str] = "warning"


@dataclass(frozen=True, kw_only=True)
class RigError(RigEvent):
    """Why the shot is being aborted (published before SAFE runs), or SAFE/STORE failing.

    source: the instrument (or "operator", "sequencer"); hint: what the operator should do;
    codes: the failing interlocks (rig.interlocks.InterlockCode values), if that is why.
    """

    LEVEL: ClassVar[str] = "error"

    source: str = ""
    hint: str = ""
    codes: tuple[str, ...] = ()


@dataclass(frozen=True, kw_only=True)
class ShotFinished(RigEvent):
    """The end of a shot (rig.shot.ShotOutcome's fields; the results stay in the outcome)."""

    LABEL: ClassVar[str] = "result"

    final_state: str
    exit_code: int
    fired: bool
    safe_confirmed: bool
    shot_path: str | None = None
    error: str | None = None
    hint: str = ""
    analysis_error: str | None = None
    aborted_in: str | None = None
    warnings: tuple[str, ...] = ()

    @property
    def level(self) -> str:
        return "info" if self.final_state == "DONE" and not self.analysis_error else (
            "warning" if self.final_state == "DONE" else "error")


@dataclass(frozen=True, kw_only=True)
class CampaignShotStarted(RigEvent):
    """The campaign is about to fire shot `shot_id` (`index` of `total`, 1-based)."""

    LABEL: ClassVar[str] = "campaign"

    shot_id: str
    index: int
    total: int
    pressure_bar: float
    projectile: int
    target_peak_m_s2: float | None = None  # automatic level control: the entry's target (pressure_bar chosen for it)


@dataclass(frozen=True, kw_only=True)
class CampaignShotEnded(RigEvent):
    """A campaign shot's journal state changed at its end (or after its analysis from file)."""

    LABEL: ClassVar[str] = "campaign"

    shot_id: str
    index: int
    total: int
    journal_state: str
    final_state: str | None = None  # the sequencer's, when the shot was fired in this run


@dataclass(frozen=True, kw_only=True)
class CampaignFinished(RigEvent):
    """The campaign run ended: exit code 0 (complete), 3 (stopped with shots left) or 2 (a shot
    that cannot be planned, found between shots: nothing of it fired)."""

    LABEL: ClassVar[str] = "campaign"

    exit_code: int
    run_folder: str

    @property
    def level(self) -> str:
        return "info" if self.exit_code == 0 else "error"


EVENT_TYPES: dict[str, type[RigEvent]] = {cls.__name__: cls for cls in (
    StateEntered, StepProgress, Identified, AwaitingConfirmation, Fired, Stored, Analysed, Reading, Note, RigWarning,
    RigError, ShotFinished, CampaignShotStarted, CampaignShotEnded, CampaignFinished)}

Subscriber = Callable[[RigEvent], None]


class EventBus:
    """Thread-safe publish/subscribe of RigEvents (see the module docstring for the rules)."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._subscribers: list[Subscriber] = []

    def subscribe(self, callback: Subscriber) -> Callable[[], None]:
        """Call `callback(event)` for every event from now on; returns the unsubscribe function."""
        with self._lock:
            self._subscribers.append(callback)

        def unsubscribe() -> None:
            with self._lock:
                if callback in self._subscribers:
                    self._subscribers.remove(callback)

        return unsubscribe

    def publish(self, event: RigEvent) -> RigEvent:
        """Hand `event` to every subscriber (a subscriber's Exception is logged, not raised);
        returns the event."""
        with self._lock:
            subscribers = list(self._subscribers)  # a callback may (un)subscribe while called
        for callback in subscribers:
            try:
                callback(event)
            except Exception:  # a broken display must not stop the rig
                _log.exception("event subscriber %r failed on a %s event", callback, event.type)
        return event


class EventQueue:
    """A subscriber that keeps events in a queue.Queue, for consumers in another thread.

        events = EventQueue(bus, types=(RigError,))
        ...
        for event in events.drain(): ...
    """

    def __init__(self, bus: EventBus, types: tuple[type[RigEvent], ...] | None = None) -> None:
        self.queue: queue.Queue[RigEvent] = queue.Queue()
        self._types = types
        self.unsubscribe = bus.subscribe(self._put)

    def _put(self, event: RigEvent) -> None:
        if self._types is None or isinstance(event, self._types):
            self.queue.put(event)

    def drain(self) -> list[RigEvent]:
        """Every event queued so far, oldest first (does not block)."""
        out = []
        while True:
            try:
                out.append(self.queue.get_nowait())
            except queue.Empty:
                return out
