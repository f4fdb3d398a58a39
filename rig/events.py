"""The event bus: how the sequencer tells the command line, the campaign runner and the panel
what it is doing. The core never prints; it publishes RigEvents.

Kinds of event (RigEvent.kind):

- "state":    the sequencer entered `state` (published before the state's first action, so a
              subscriber that journals the FIRE state has written it before the fire valve opens);
- "progress": a step inside a state ("charging 0.62 of 1.00 bar", "armed: waiting for the fire
              confirmation" with data {"awaiting_confirmation": True, "timeout_s": ...});
- "reading":  {"reservoir_pressure_bar", "fixture_vacuum_mbar", "interlocks": {name: bool}, ...}
              at up to ~10 Hz while a shot runs;
- "log":      a note for the operator (data may hold {"level": "warning"});
- "error":    why the shot is being aborted (published before SAFE runs);
- "result":   the end of a shot: {"shot_path", "results" (analysis dict or None), "error",
              "final_state", "exit_code", "fired", ...}.

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
from collections.abc import Callable
from dataclasses import dataclass, field
from datetime import UTC, datetime
from typing import Any

EVENT_KINDS = ("state", "progress", "reading", "log", "error", "result")

_log = logging.getLogger(__name__)


def utc_now_iso() -> str:
    """The current UTC time as ISO 8601 text ending in Z (as in shot files)."""
    return datetime.now(UTC).isoformat(timespec="microseconds").replace("+00:00", "Z")


@dataclass(frozen=True)
class RigEvent:
    """One thing the rig did or saw; `state` is the sequencer state it happened in."""

    kind: str
    state: str
    message: str
    data: dict[str, Any] = field(default_factory=dict)
    utc: str = field(default_factory=utc_now_iso)

    def __post_init__(self) -> None:
        if self.kind not in EVENT_KINDS:
            raise ValueError(f"event kind must be one of {', '.join(EVENT_KINDS)}, got {self.kind!r}")


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

    def publish(self, event: RigEvent) -> None:
        """Hand `event` to every subscriber; a subscriber's Exception is logged, not raised."""
        with self._lock:
            subscribers = list(self._subscribers)  # a callback may (un)subscribe while called
        for callback in subscribers:
            try:
                callback(event)
            except Exception:  # a broken display must not stop the rig
                _log.exception("event subscriber %r failed on %s event", callback, event.kind)

    def emit(self, kind: str, state: str, message: str, **data: Any) -> RigEvent:
        """Build a RigEvent (UTC time now) and publish it; returns the event."""
        event = RigEvent(kind, str(state), message, dict(data))
        self.publish(event)
        return event


class EventQueue:
    """A subscriber that keeps events in a queue.Queue, for consumers in another thread.

        events = EventQueue(bus)
        ...
        for event in events.drain(): ...
    """

    def __init__(self, bus: EventBus, kinds: tuple[str, ...] | None = None) -> None:
        self.queue: queue.Queue[RigEvent] = queue.Queue()
        self._kinds = kinds
        self.unsubscribe = bus.subscribe(self._put)

    def _put(self, event: RigEvent) -> None:
        if self._kinds is None or event.kind in self._kinds:
            self.queue.put(event)

    def drain(self) -> list[RigEvent]:
        """Every event queued so far, oldest first (does not block)."""
        out = []
        while True:
            try:
                out.append(self.queue.get_nowait())
            except queue.Empty:
                return out
