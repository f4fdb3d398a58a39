"""The digitizer's VISA session: bounded text and block reads over any VISA library.

`VisaLink` opens one message-based VISA resource with the configured library (`@py` for
pyvisa-py, a system VISA's path, or "@ivi") and terminations, and gives a dialect the three
calls of `ScpiLink`: write, query (text) and query_block (an IEEE 488.2 definite-length block).

Bounded reads. Every read has a size limit and one overall deadline:
- a text reply must end with the read terminator within `max_reply_bytes` and `timeout_s`;
- a block's header must announce at most the dialect's limit (the record it expects), and the
  block must arrive within `timeout_s` plus its size at MIN_BLOCK_RATE_BYTES_S (a slow link).
A reply that streams on without its terminator, or announces more than the limit, is an
InstrumentError naming the instrument and the command, raised within the deadline, with
memory bounded by the limit. After any failure the session is closed (the byte stream is no
longer in step); the driver reopens it on its next call.

How bytes are read. A block is read by length, never up to a termination character: pyvisa's
default `query_binary_values` leaves the termination on, so every 0x0A byte in the payload ends
one low-level read (~15-30 MB/s). Two readers:
- `_SocketReader`, for pyvisa-py's raw TCP socket sessions (`TCPIP::host::port::SOCKET`): the
  driver reads the session's socket itself (pyvisa opened it and still writes to it), with
  select() against the deadline and recv_into() straight into the block's buffer. Written by
  hand because pyvisa-py's own read (0.7-0.8) looks at its timeout only after a quiet spell
  (a reply trickling in a byte every few ms holds one read far past any deadline), receives
  4 KiB per recv() and copies its pending buffer on every read.
- `_VisaReader`, for every other session (a system VISA, other pyvisa-py interfaces): viRead in
  chunks, each with the time left as its timeout (such libraries time a read as a whole).
"""

from __future__ import annotations

import math
import select
import socket
from collections.abc import Callable

import pyvisa
import pyvisa.constants
import pyvisa.errors

from hopkinson.drivers.base import Deadline, read_bounded
from hopkinson.drivers.errors import InstrumentConnectionError, InstrumentError, InstrumentTimeout
from hopkinson.drivers.ieee488_block import BlockFormatError, digit_count, payload_length

BLOCK_CHUNK_BYTES = 1 << 20  # the largest piece one read of a block asks for
MIN_BLOCK_RATE_BYTES_S = 1e6  # a block may take timeout_s + its size at this rate (a 10 Mbit/s link)
TEXT_CHUNK_BYTES = 4096
_QUIET = (pyvisa.constants.StatusCode.success_max_count_read, pyvisa.constants.StatusCode.success_device_not_present)


class _SocketReader:
    """Reads a pyvisa-py TCPIP SOCKET session's socket directly (module docstring). Bytes that
    arrive beyond a text reply's terminator stay in the session's pending buffer, where
    pyvisa-py itself keeps them."""

    def __init__(self, session: object) -> None:
        self._session = session
        self._socket: socket.socket = session.interface  # type: ignore[attr-defined]

    @staticmethod
    def fits(session: object) -> bool:
        return isinstance(getattr(session, "interface", None), socket.socket) and isinstance(
            getattr(session, "_pending_buffer", None), bytearray)

    def _fill(self, wait_s: float) -> bool:
        """Receive what has arrived into the pending buffer (False: nothing within wait_s)."""
        ready, _, _ = select.select([self._socket], [], [], wait_s)
        if not ready:
            return False
        data = self._socket.recv(BLOCK_CHUNK_BYTES)
        if not data:
            raise ConnectionError("the instrument closed the connection")
        self._session._pending_buffer += data  # type: ignore[attr-defined]
        return True

    def read(self, count: int, wait_s: float, terminator: bytes = b"") -> bytes:
        """At most `count` bytes (and not past `terminator`), waiting at most wait_s for any."""
        pending: bytearray = self._session._pending_buffer  # type: ignore[attr-defined]
        if not pending and not self._fill(wait_s):
            return b""
        end = pending.find(terminator) if terminator else -1
        take = min(count, end + len(terminator) if end >= 0 else len(pending))
        out = bytes(pending[:take])
        del pending[:take]
        return out

    def read_into(self, view: memoryview, wait_s: float) -> int:
        """Fill the start of `view` with what has arrived (0: nothing within wait_s)."""
        pending: bytearray = self._session._pending_buffer  # type: ignore[attr-defined]
        if pending:
            take = min(len(view), len(pending))
            view[:take] = pending[:take]
            del pending[:take]
            return take
        ready, _, _ = select.select([self._socket], [], [], wait_s)
        if not ready:
            return 0
        got = self._socket.recv_into(view[:BLOCK_CHUNK_BYTES])
        if not got:
            raise ConnectionError("the instrument closed the connection")
        return got


class _VisaReader:
    """viRead in chunks with the time left as the timeout (module docstring)."""

    def __init__(self, inst: pyvisa.resources.MessageBasedResource) -> None:
        self._inst = inst

    def read(self, count: int, wait_s: float, terminator: bytes = b"") -> bytes:
        inst = self._inst
        inst.timeout = max(1, math.ceil(wait_s * 1000))
        try:
            with inst.ignore_warning(*_QUIET):
                data, _ = inst.visalib.read(inst.session, min(count, TEXT_CHUNK_BYTES if terminator else BLOCK_CHUNK_BYTES))
        except pyvisa.errors.VisaIOError as exc:
            if exc.error_code == pyvisa.constants.StatusCode.error_timeout:
                return b""
            raise
        return bytes(data)

    def read_into(self, view: memoryview, wait_s: float) -> int:
        data = self.read(len(view), wait_s)
        view[:len(data)] = data
        return len(data)


class VisaLink:
    """One VISA session to the digitizer (module docstring). Not thread-safe: the driver's
    lock serialises its use."""

    def __init__(
        self,
        instrument: str,
        resource: str,
        *,
        library: str = "@py",
        read_termination: str = "\n",
        write_termination: str = "\n",
        timeout_s: float = 5.0,
        max_reply_bytes: int = 65536,
        trace_out: Callable[[str], None] | None = None,
        trace_in: Callable[[str], None] | None = None,
    ) -> None:
        self.instrument = instrument
        self.resource = resource
        self.library = library
        self.read_termination = read_termination
        self.write_termination = write_termination
        self.timeout_s = timeout_s
        self.max_reply_bytes = max_reply_bytes
        self._trace_out = trace_out or (lambda text: None)
        self._trace_in = trace_in or (lambda text: None)
        self._rm: pyvisa.ResourceManager | None = None
        self._inst: pyvisa.resources.MessageBasedResource | None = None
        self._reader: _SocketReader | _VisaReader | None = None

    @property
    def is_open(self) -> bool:
        return self._inst is not None

    def open(self) -> None:
        """Open the session (InstrumentConnectionError naming the library or the address)."""
        self.close()
        try:
            self._rm = pyvisa.ResourceManager(self.library)
        except Exception as exc:  # a missing system VISA raises OSError/ValueError/...
            raise InstrumentConnectionError(self.instrument, "open", f"cannot load the VISA library "
                                            f"{self.library!r}: {exc}") from exc
        try:
            inst = self._rm.open_resource(
                self.resource,
                open_timeout=max(1, int(self.timeout_s * 1000)),
                timeout=max(1, int(self.timeout_s * 1000)),
                read_termination=self.read_termination or None,
                write_termination=self.write_termination,
            )
        except Exception as exc:  # pyvisa-py raises bare Exception for a bad address or a refusal
            self.close()
            raise InstrumentConnectionError(self.instrument, "open", f"cannot open the VISA session: {exc}") from exc
        if not isinstance(inst, pyvisa.resources.MessageBasedResource):
            self.close()
            raise InstrumentConnectionError(self.instrument, "open", f"{self.resource} is not a message-based "
                                                                     "VISA resource")
        self._inst = inst
        sessions = getattr(inst.visalib, "sessions", None)
        session = sessions.get(inst.session) if isinstance(sessions, dict) else None
        self._reader = _SocketReader(session) if _SocketReader.fits(session) else _VisaReader(inst)

    def close(self) -> None:
        """Close this session (idempotent; never raises).

        The resource manager is left open: pyvisa keeps one per VISA library and process, and
        closing it would close every other session of that library in this process (another
        digitizer, the panel's and a command's sessions).
        """
        inst = self._inst
        self._inst, self._rm, self._reader = None, None, None
        if inst is not None:
            try:
                inst.close()
            except Exception:  # closing a broken session must not hide the first error
                pass

    # -- ScpiLink ---------------------------------------------------------------------------
    def write(self, command: str) -> None:
        inst = self._session(command)
        self._trace_out(command)
        try:
            inst.write(command)
        except (pyvisa.errors.VisaIOError, OSError) as exc:
            raise self._failed(command, exc) from exc

    def query(self, command: str) -> str:
        """Send `command`; its text reply without the terminator (bounded in size and time)."""
        self.write(command)
        reader = self._reader_for(command)
        terminator = (self.read_termination or "\n").encode("ascii")
        try:
            raw = read_bounded(lambda n, wait_s: reader.read(n, wait_s, terminator), terminator=terminator,
                               max_bytes=self.max_reply_bytes, timeout_s=self.timeout_s,
                               instrument=self.instrument, command=command)
        except InstrumentError:
            self.close()
            raise
        except (pyvisa.errors.VisaIOError, OSError) as exc:
            raise self._failed(command, exc) from exc
        try:
            text = raw[: len(raw) - len(terminator)].decode("ascii")
        except UnicodeDecodeError:
            self.close()
            raise InstrumentError(self.instrument, command, "garbled reply: not ASCII text", raw) from None
        self._trace_in(text)
        return text.strip()

    def query_block(self, command: str, max_bytes: int, header_max: int = 0) -> tuple[str, memoryview]:
        """Send `command`; read (optional header text,) one definite-length block of at most
        `max_bytes` and the read terminator after it."""
        self.write(command)
        reader, inst = self._reader_for(command), self._session(command)
        term = inst.read_termination
        deadline = Deadline(self.timeout_s)
        inst.read_termination = None  # 0x0A in the payload must not end a (VISA) read
        try:
            header = self._read_header_text(reader, command, header_max, deadline)
            prefix = b"#" + bytes(self._read_exact(reader, command, 1, deadline))
            digits = bytes(self._read_exact(reader, command, digit_count(prefix), deadline))
            length = payload_length(digits)
            if length > max_bytes:
                raise self._garbled(command, f"block announces {length} bytes, more than the {max_bytes} "
                                             "expected (an oversized reply)", prefix + digits)
            end = (term or "").encode("ascii")
            block_deadline = deadline.extended(length / MIN_BLOCK_RATE_BYTES_S)
            body = self._read_exact(reader, command, length + len(end), block_deadline)
            if body[length:] != end:
                raise self._garbled(command, f"block not followed by the terminator {end!r}: "
                                             f"{bytes(body[length:])!r}")
        except InstrumentError:
            self.close()
            raise
        except BlockFormatError as exc:
            self.close()
            raise self._garbled(command, str(exc)) from None
        except (pyvisa.errors.VisaIOError, OSError) as exc:
            raise self._failed(command, exc) from exc
        finally:
            if self._inst is inst:
                inst.read_termination = term
        self._trace_in(f"{header}<binary block: {length} bytes>")
        return header, memoryview(body)[:length]

    # -- reading ------------------------------------------------------------------------------
    def _read_exact(self, reader: _SocketReader | _VisaReader, command: str, count: int,
                    deadline: Deadline) -> bytearray:
        """Exactly `count` bytes before the deadline (InstrumentTimeout otherwise)."""
        out = bytearray(count)
        view, got = memoryview(out), 0
        while got < count:
            wait_s = deadline.remaining_s()
            if wait_s <= 0:
                raise InstrumentTimeout(self.instrument, command, f"no complete reply within "
                                        f"{deadline.seconds:.3g} s ({got} of {count} bytes came)")
            got += reader.read_into(view[got:], wait_s)
        return out

    def _read_header_text(self, reader: _SocketReader | _VisaReader, command: str, header_max: int,
                          deadline: Deadline) -> str:
        """Text before the block's '#' (at most header_max bytes; none when header_max is 0)."""
        text = bytearray()
        while True:
            byte = bytes(self._read_exact(reader, command, 1, deadline))
            if byte == b"#":
                return text.decode("ascii", "replace")
            text += byte
            if len(text) > header_max:
                what = "does not start with '#'" if header_max == 0 else f"has no '#' within {header_max} bytes"
                raise self._garbled(command, f"block {what}", bytes(text))

    def _reader_for(self, command: str) -> _SocketReader | _VisaReader:
        self._session(command)
        assert self._reader is not None
        return self._reader

    # -- errors ---------------------------------------------------------------------------------
    def _session(self, command: str) -> pyvisa.resources.MessageBasedResource:
        if self._inst is None:
            raise InstrumentConnectionError(self.instrument, command, "not connected")
        return self._inst

    def _garbled(self, command: str, problem: str, reply: bytes = b"") -> InstrumentError:
        return InstrumentError(self.instrument, command, f"garbled binary block: {problem}", reply)

    def _failed(self, command: str, exc: Exception) -> InstrumentError:
        """A transport failure as an InstrumentError; the (out-of-step) session is closed."""
        self.close()
        if isinstance(exc, pyvisa.errors.VisaIOError) and exc.error_code == pyvisa.constants.StatusCode.error_timeout:
            return InstrumentTimeout(self.instrument, command,
                                     f"no complete reply within {self.timeout_s:g} s (or the connection dropped)")
        return InstrumentConnectionError(self.instrument, command, f"connection failed: {exc}")
