"""The one driver base: connection life cycle, tracing, one lock per link, bounded reads.

Every driver of the project (and a lab's own, if it likes) derives from `InstrumentDriver`:

    class MyGauge(InstrumentDriver):
        def _open(self) -> None: ...          # open the link; raise InstrumentConnectionError
        def _close_link(self) -> None: ...    # close it (called once per open link; may raise)
        def _link_open(self) -> bool: ...     # is a link open right now?

and gets `connect()`, `close()` (idempotent, never raises), `connected`, `with driver: ...`,
reconnect-on-next-call after a failure (`_ensure_link`), a re-entrant `lock` that serialises
every transaction of the instance (a heartbeat thread and the sequencer share one link), and
the `trace` hook.

Tracing. `driver.trace` is None or a callable that receives one `TraceRecord` per exchange
(direction "->" host to instrument, "<-" instrument to host). Binary payloads are summarised
(`<binary block: 400000 bytes>`), long text is cut. A failing trace hook never breaks the I/O.

Bounded reads. `read_bounded` reads from any byte stream until a terminator, with a maximum
reply size and one overall deadline: an endless or oversized reply is an InstrumentError that
names the instrument and the command, within the timeout, and never grows memory.
"""

from __future__ import annotations

import contextlib
import datetime as _dt
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from types import TracebackType
from typing import Self

from hopkinson.drivers.errors import InstrumentConnectionError, InstrumentError, InstrumentTimeout

TRACE_TEXT_CHARS = 200  # longest text a TraceRecord keeps of one exchange


@dataclass(frozen=True)
class TraceRecord:
    """One instrument exchange as a logbook records it.

    instrument: the driver's name; direction: "->" (host to instrument) or "<-" (reply);
    text: the exchange as printable text (binary summarised); utc: ISO 8601 UTC time.
    """

    instrument: str
    direction: str
    text: str
    utc: str

    def to_dict(self) -> dict[str, str]:
        return {"instrument": self.instrument, "direction": self.direction, "text": self.text, "utc": self.utc}


TraceHook = Callable[[TraceRecord], None]


def utc_now_iso() -> str:
    """Now, UTC, ISO 8601 with microseconds."""
    return _dt.datetime.now(_dt.UTC).isoformat(timespec="microseconds")


def trace_text(data: bytes | str, limit: int = TRACE_TEXT_CHARS) -> str:
    """Printable text of one exchange: ASCII text as is (cut at `limit`), anything else summarised."""
    if isinstance(data, bytes):
        printable = all(32 <= b < 127 or b in (9, 10, 13) for b in data[: limit + 1])
        if not printable:
            return f"<binary block: {len(data)} bytes>" if len(data) > 32 else "<binary: " + data.hex(" ") + ">"
        text = data.decode("ascii")
    else:
        text = data
    text = text.rstrip("\r\n")
    return text if len(text) <= limit else f"{text[:limit]}... ({len(text)} chars)"


class Deadline:
    """One overall time limit for a multi-step read (monotonic clock)."""

    def __init__(self, seconds: float) -> None:
        self.seconds = seconds
        self.end = time.monotonic() + seconds

    def extended(self, extra_s: float) -> Deadline:
        """The same limit made `extra_s` longer: it ends `extra_s` later and states
        `seconds + extra_s` (a message names the limit the user set, not what was left of it)."""
        longer = Deadline(self.seconds + extra_s)
        longer.end = self.end + extra_s
        return longer

    def remaining_s(self) -> float:
        """Seconds left (0 when past)."""
        return max(0.0, self.end - time.monotonic())

    @property
    def expired(self) -> bool:
        return time.monotonic() >= self.end


def read_bounded(
    read: Callable[[int, float], bytes],
    *,
    terminator: bytes,
    max_bytes: int,
    timeout_s: float,
    instrument: str,
    command: str,
) -> bytes:
    """Read up to and including `terminator`, at most `max_bytes`, within `timeout_s` overall.

    read(n, wait_s) returns at most n bytes, waiting at most wait_s for the first one (b"" when
    none came). Raises InstrumentError when `max_bytes` arrive without the terminator (an
    oversized or endless reply) and InstrumentTimeout at the deadline; both carry what came.
    """
    deadline = Deadline(timeout_s)
    buffer = bytearray()
    while True:
        end = buffer.find(terminator)
        if end >= 0:
            return bytes(buffer[: end + len(terminator)])
        if len(buffer) >= max_bytes:
            raise InstrumentError(instrument, command, f"reply longer than {max_bytes} bytes without "
                                  f"{terminator!r} (an endless or oversized reply)", bytes(buffer[:80]))
        wait_s = deadline.remaining_s()
        if wait_s <= 0:
            problem = f"no complete reply within {timeout_s:g} s"
            raise InstrumentTimeout(instrument, command, problem, bytes(buffer[:80]))
        buffer += read(max_bytes - len(buffer), wait_s)


class InstrumentDriver:
    """Base of every driver: life cycle, lock, trace hook (module docstring).

    name: how errors and traces name the instrument (e.g. "valve controller modbus-tcp://...").
    timeout_s: the per-transaction deadline. trace: optional TraceRecord hook.
    """

    def __init__(self, name: str, *, timeout_s: float = 1.0, trace: TraceHook | None = None) -> None:
        if not (isinstance(timeout_s, int | float) and 0 < timeout_s < float("inf")):
            raise ValueError(f"{name}: timeout_s must be a positive number of seconds, got {timeout_s!r}")
        self.name = name
        self.timeout_s = float(timeout_s)
        self.trace: TraceHook | None = trace
        self.lock = threading.RLock()  # held for every transaction of this instance
        self._wanted = False  # connect() called and close() not: a failed link reopens on the next call

    # -- what a driver provides --------------------------------------------------------------
    def _open(self) -> None:
        """Open the link (raise InstrumentConnectionError when it cannot be opened)."""
        raise NotImplementedError

    def _close_link(self) -> None:
        """Close the open link (may raise; the base swallows it)."""
        raise NotImplementedError

    def _link_open(self) -> bool:
        """True while a link is open."""
        raise NotImplementedError

    # -- life cycle ----------------------------------------------------------------------------
    @property
    def instrument(self) -> str:
        """How errors name this instrument (the same as `name`)."""
        return self.name

    @property
    def connected(self) -> bool:
        return self._link_open()

    def connect(self) -> None:
        """Open the link afresh (an old one is closed first)."""
        with self.lock:
            self._drop()
            try:
                self._open()
            except InstrumentError:
                self._drop()
                raise
            except Exception as exc:  # a library's own exception type: name the instrument
                self._drop()
                raise InstrumentConnectionError(self.name, "open", f"cannot open: {exc}") from exc
            self._wanted = True

    def close(self) -> None:
        """Close the link (idempotent; never raises)."""
        with self.lock:
            self._wanted = False
            self._drop()

    def _drop(self) -> None:
        """Close the link after a failure (the next call reopens it when connect() was called)."""
        if self._link_open():
            with contextlib.suppress(Exception):  # closing a broken link must not hide the first error
                self._close_link()

    def _ensure_link(self, command: str) -> None:
        """Before a transaction: reopen a link a failure closed; refuse when never connected."""
        if self._link_open():
            return
        if not self._wanted:
            raise InstrumentConnectionError(self.name, command, "not connected (use `with` or connect())")
        self.connect()

    def __enter__(self) -> Self:
        self.connect()
        return self

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.close()

    # -- tracing ------------------------------------------------------------------------------
    def _trace(self, direction: str, data: bytes | str) -> None:
        hook = self.trace
        if hook is None:
            return
        with contextlib.suppress(Exception):  # a logbook problem never breaks the instrument I/O
            hook(TraceRecord(self.name, direction, trace_text(data), utc_now_iso()))

    def _trace_out(self, data: bytes | str) -> None:
        self._trace("->", data)

    def _trace_in(self, data: bytes | str) -> None:
        self._trace("<-", data)

    def __repr__(self) -> str:
        state = "connected" if self.connected else "closed"
        return f"<{type(self).__name__} {self.name!r} {state}>"

