"""How the rig commands show events: one plain line each, with its UTC time, or (for scripts,
`--json-events`) one JSON object per line.

    21:16:26.123 CHARGE    charging: 0.620 of 1 bar
    21:16:27.004 CHARGE    ! aborting: valve controller ...: interlock lost: door/guard open
                             → Close the door/guard, then ARM again.

Lines are written whole with one write and flushed (a log collector never sees half a line);
no colours, no carriage returns: they read the same in a terminal, a file or a pipe.
"""

from __future__ import annotations

import json
import sys
import threading
from typing import IO, Any

from hopkinson.rig.events import (
    Analysed,
    AwaitingConfirmation,
    Fired,
    Identified,
    Note,
    Reading,
    RigError,
    RigEvent,
    RigWarning,
    StateEntered,
    StepProgress,
    Stored,
)

_SHOWN = (StateEntered, StepProgress, AwaitingConfirmation, Fired, Stored, Analysed, Note, RigWarning, RigError)
_VERBOSE = (Identified, Reading)


def clock(event: RigEvent) -> str:
    """The event's UTC time of day with milliseconds ("21:16:26.123")."""
    return event.utc[11:23]


def event_line(event: RigEvent, verbose: bool = False) -> str | None:
    """The line of a shot's event (None: not shown). Progress figures appear in every
    StepProgress; readings and identities only when `verbose`."""
    if not isinstance(event, _SHOWN + (_VERBOSE if verbose else ())):
        return None
    if isinstance(event, Reading):
        text = (f"{event.reservoir_pressure_bar:.3f} bar, {event.fixture_vacuum_mbar:.1f} mbar; interlocks "
                + (", ".join(event.problems) or "all hold"))
    else:
        text = event.message
    marker = {"error": "! ", "warning": "warning: "}.get(event.level, "")
    line = f"{clock(event)} {event.state:<9} {marker}{text}"
    hint = getattr(event, "hint", "")
    if hint:
        line += f"\n{' ' * 25}→ {hint}"
    return line


class EventPrinter:
    """A bus subscriber that prints event lines on a stream (stdout by default)."""

    def __init__(self, stream: IO[str] | None = None, verbose: bool = False) -> None:
        self.stream = stream
        self.verbose = verbose

    def __call__(self, event: RigEvent) -> None:
        line = event_line(event, self.verbose)
        if line is not None:
            write_line(self.stream or sys.stdout, line)


class JsonEventStream:
    """A bus subscriber that writes every event as one JSON line (`--json-events`)."""

    def __init__(self, stream: IO[str] | None = None) -> None:
        self.stream = stream
        self._lock = threading.Lock()

    def __call__(self, event: RigEvent) -> None:
        self.write(event.to_dict())

    def write(self, obj: dict[str, Any]) -> None:
        text = json.dumps(obj, separators=(",", ":"), allow_nan=False, default=str)
        with self._lock:
            write_line(self.stream or sys.stdout, text)


def write_line(stream: IO[str], line: str) -> None:
    """One whole line, flushed."""
    stream.write(line + "\n")
    stream.flush()
