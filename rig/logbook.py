"""The lab record: a JSON-lines log of everything the rig did, one object per line.

    <shot>.log.jsonl            beside each shot file (the sequencer writes it, from CHECK on,
                                also for a shot aborted before anything was recorded)
    <run>/campaign.log.jsonl    in each campaign run folder (every event of every shot, the
                                resume findings, the end; appended to by every resume)
    --log-file PATH             a copy of a command's events wherever the operator wants it

Each line is one JSON object with at least "type", "utc" (ISO 8601, UTC, "Z"), "level"
("info" | "warning" | "error") and "message":

- "LogOpened": who wrote the log (software version, pid, user, host, command);
- every rig event, as `RigEvent.to_dict()` ("StateEntered", "Reading", "RigWarning",
  "RigError", "Identified" (the instruments' identities), "ShotFinished", ...);
- "Trace" (with `--trace`): one instrument exchange: "instrument", "direction" ("->" sent,
  "<-" received) and "text" (binary blocks summarised, e.g. "<binary block: 400000 bytes>").

The file is opened for appending, never through a symlink (O_NOFOLLOW), and each line is
written whole with one write(): a crash leaves at most the last line unfinished, and readers
(`read_log`) skip such a line. It is fsynced when closed. A log is a stream, so it is the one
kind of file the application does not write through `hopkinson.fileio.atomic_write`.

A failure to write the log never stops the rig: the first one is reported once (a
RigWarning on the bus when there is one) and the log is then closed.
"""

from __future__ import annotations

import contextlib
import json
import logging
import os
import socket
import threading
from collections.abc import Callable
from pathlib import Path
from typing import Any

from hopkinson.rig.events import EventBus, RigEvent, RigWarning, utc_now_iso
from hopkinson.rig.lock import current_user

LOG_SUFFIX = ".log.jsonl"
CAMPAIGN_LOG_NAME = "campaign.log.jsonl"

_log = logging.getLogger(__name__)


def shot_log_path(shot_path: str | os.PathLike[str]) -> Path:
    """The log of a shot file: `<name>.h5` -> `<name>.log.jsonl` in the same folder."""
    path = Path(shot_path)
    return path.with_name(path.stem + LOG_SUFFIX)


def _jsonable(value: Any) -> Any:
    return str(value)


class Logbook:
    """An open JSON-lines log (module docstring). Thread-safe; use as a context manager or
    `close()` it. `attach(bus)` writes every event of the bus until `close()`."""

    def __init__(self, path: str | os.PathLike[str], *, command: str = "", what: str = "") -> None:
        self.path = Path(path)
        flags = os.O_WRONLY | os.O_APPEND | os.O_CREAT | getattr(os, "O_NOFOLLOW", 0) | getattr(os, "O_CLOEXEC", 0)
        self._fd: int | None = os.open(self.path, flags, 0o644)
        self._lock = threading.Lock()
        self._detach: list[Callable[[], None]] = []
        self._bus: EventBus | None = None
        self.failure: str | None = None
        from hopkinson import __version__

        self.write({"type": "LogOpened", "utc": utc_now_iso(), "level": "info",
                    "message": f"log of {what or 'the rig'} opened", "software_version": __version__,
                    "pid": os.getpid(), "user": current_user(), "host": socket.gethostname(), "command": command})

    def write(self, obj: dict[str, Any]) -> None:
        """One object as one line (never raises: a failure is reported once, then the log closes)."""
        line = (json.dumps(obj, separators=(",", ":"), default=_jsonable) + "\n").encode("utf-8")
        with self._lock:
            if self._fd is None:
                return
            try:
                os.write(self._fd, line)
                return
            except OSError as exc:
                self.failure = f"{self.path}: the log could not be written ({exc.strerror or exc}); it is closed"
                self._close_locked()
        _log.warning("%s", self.failure)
        if self._bus is not None:
            with contextlib.suppress(Exception):
                self._bus.publish(RigWarning(state="LOG", message=self.failure))

    def event(self, event: RigEvent) -> None:
        """A bus subscriber: write the event."""
        self.write(event.to_dict())

    def trace(self, record: Any) -> None:
        """A driver trace hook: write one instrument exchange (drivers.base.TraceRecord)."""
        self.write({"type": "Trace", "utc": _z(getattr(record, "utc", "") or utc_now_iso()), "level": "info",
                    "message": f"{record.instrument} {record.direction} {record.text}",
                    "instrument": record.instrument, "direction": record.direction, "text": record.text})

    def attach(self, bus: EventBus) -> Logbook:
        """Write every event of `bus` from now until close(); returns self."""
        self._bus = bus
        self._detach.append(bus.subscribe(self.event))
        return self

    @property
    def open(self) -> bool:
        return self._fd is not None

    def close(self) -> None:
        """Stop listening, fsync and close (idempotent)."""
        for detach in self._detach:
            detach()
        self._detach.clear()
        with self._lock:
            self._close_locked()

    def _close_locked(self) -> None:
        if self._fd is not None:
            with contextlib.suppress(OSError):
                os.fsync(self._fd)
            with contextlib.suppress(OSError):
                os.close(self._fd)
            self._fd = None

    def __enter__(self) -> Logbook:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def _z(utc: str) -> str:
    """ISO 8601 UTC with a "Z" (drivers stamp "+00:00")."""
    return utc.replace("+00:00", "Z")


def read_log(path: str | os.PathLike[str]) -> list[dict[str, Any]]:
    """Every whole line of a log, in order (an unfinished last line is skipped)."""
    out = []
    with open(path, encoding="utf-8") as fh:
        for line in fh:
            if not line.endswith("\n"):
                break
            with contextlib.suppress(json.JSONDecodeError):
                out.append(json.loads(line))
    return out
