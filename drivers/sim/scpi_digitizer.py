"""Simulated two-channel digitizer: a SCPI server on a raw TCP socket (VISA `...::SOCKET`).

The server speaks the dialect the real driver uses (drivers/scpi_dialect.py), but parses it
independently here so that tests over loopback check the driver against a second reading of
the protocol, not against itself (the block header is drivers/ieee488_block.block_header,
pinned to known bytes by its own tests). Messages end with "\\n"; message units are separated by
";" (e.g. ":ACQuire:SRATe 1E8;:SYSTem:ERRor?"); headers take the SCPI short or long form in
any case. Replies to the queries of one message are joined by ";" and end with "\\n".

Commands (short form in capitals):
    *IDN?  *RST  *CLS  *OPC?  :SYSTem:ERRor?
    :ACQuire:SRATe <hz> | ?          sample rate
    :ACQuire:POINts <n> | ?          record length (samples per channel)
    :ACQuire:PRETrigger <n> | ?      samples recorded before the trigger
    :CHANnel<1|2>:RANGe <v> | ?      full scale: the channel reads -v .. +v volts
    :TRIGger:SOURce CH1|CH2|EXT | ?  :TRIGger:LEVel <v> | ?  :TRIGger:SLOPe POS|NEG | ?
    :SINGle                          arm one acquisition
    :ABORt                           disarm (state IDLE, acquired data discarded)
    :ACQuire:STATe?                  IDLE | ARMED | TRIGGERED
    :WAVeform:SOURce CH1|CH2 | ?
    :WAVeform:PREamble?              INT16,LSBF,<points>,<x_increment_s>,<trigger_index>,
                                     <y_scale_v>,<y_offset_v>    (volts = code*scale + offset)
    :WAVeform:DATA?                  IEEE 488.2 definite-length block of int16 little-endian

Errors go to the SCPI error queue (read with :SYSTem:ERRor?), as a real instrument does.

While ARMED the server polls `capture(settings)` whenever the client asks the acquisition
state or the waveform: None = not triggered yet; otherwise {channel: volts} (float arrays of
settings.record_length samples, trigger at index settings.pre_trigger_samples), which the
server quantises to int16 with each channel's range and keeps until the next :SINGle.

Faults (drivers/sim/faults.py): `visa-garbled-block` sends the waveform block with a corrupt
length header (the payload follows, so the client's stream is out of step afterwards).
A client that drops its connection (even mid-transfer) only ends its own handler thread.
"""

from __future__ import annotations

import copy
import re
import socket
import socketserver
import threading
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from hopkinson.drivers.ieee488_block import block_header
from hopkinson.drivers.sim.faults import FaultSet

IDENTITY = "Hopkinson-Sim,SIMDIG-2CH,SIM0001,1.0"
CHANNELS = (1, 2)
TRIGGER_SOURCES = ("CH1", "CH2", "EXT")
TRIGGER_SLOPES = ("POS", "NEG")
SAMPLE_RATE_LIMITS_HZ = (1e3, 1e9)
RECORD_LENGTH_LIMITS = (16, 100_000_000)
RANGE_LIMITS_V = (0.01, 50.0)
INT16_FULL_SCALE = 32767
MAX_LINE_BYTES = 65536


@dataclass
class AcquisitionSettings:
    """The digitizer's acquisition settings as the instrument holds them.

    ch_range_v: full scale per channel (the channel reads -range .. +range volts).
    trigger_source: "CH1" | "CH2" | "EXT"; trigger_slope: "POS" | "NEG".
    """

    sample_rate_hz: float = 100e6
    record_length: int = 1_000_000
    pre_trigger_samples: int = 100_000
    ch_range_v: dict[int, float] = field(default_factory=lambda: {1: 1.0, 2: 10.0})
    trigger_source: str = "CH2"
    trigger_level_v: float = 0.1
    trigger_slope: str = "POS"


CaptureFn = Callable[[AcquisitionSettings], "dict[int, np.ndarray] | None"]


class _ScpiError(Exception):
    """A SCPI error to queue: code and message as in IEEE 488.2 / SCPI-99."""

    def __init__(self, code: int, message: str) -> None:
        super().__init__(message)
        self.code = code
        self.message = message


@dataclass
class _Block:
    """A binary block reply: sent raw (not joined with text replies)."""

    payload: memoryview


def _header_matches(node: str, pattern: str) -> bool:
    """SCPI header node match: the short form (capitals of pattern) or the long form."""
    short = "".join(c for c in pattern if c.isupper() or c.isdigit())
    return node.upper() in (short.upper(), pattern.upper())


class _Instrument:
    """The instrument's state and command interpreter (shared by all connections)."""

    def __init__(self, capture: CaptureFn, faults: FaultSet) -> None:
        self._capture = capture
        self.faults = faults
        self.lock = threading.RLock()
        self.reset()

    def reset(self) -> None:
        with self.lock:
            self.settings = AcquisitionSettings()
            self.state = "IDLE"
            self.codes: dict[int, np.ndarray] = {}
            self.scale_v: dict[int, float] = {}
            self.waveform_source = 1
            self.errors: list[tuple[int, str]] = []

    # -- acquisition -------------------------------------------------------------------
    def poll_capture(self) -> None:
        """While ARMED, ask the world whether the trigger came; quantise what it returns."""
        if self.state != "ARMED":
            return
        try:
            volts = self._capture(copy.deepcopy(self.settings))
        except Exception as exc:  # the world failed: report it as the instrument would
            raise _ScpiError(-240, f"Hardware error; simulated capture failed: {exc}") from None
        if volts is None:
            return
        n = self.settings.record_length
        codes: dict[int, np.ndarray] = {}
        scales: dict[int, float] = {}
        for ch in CHANNELS:
            data = np.asarray(volts.get(ch, np.zeros(n)), dtype=float)
            if data.shape != (n,):
                raise _ScpiError(-240, f"simulated capture gave {data.shape} samples on CH{ch}, expected {n}")
            scale = self.settings.ch_range_v[ch] / INT16_FULL_SCALE
            q = np.clip(np.rint(data / scale), -INT16_FULL_SCALE - 1, INT16_FULL_SCALE)
            codes[ch] = q.astype("<i2")
            scales[ch] = scale
        self.codes, self.scale_v, self.state = codes, scales, "TRIGGERED"

    # -- interpreter ---------------------------------------------------------------------
    def execute(self, message: str) -> list[str | _Block]:
        """Run one message (units separated by ';'); return the query replies in order."""
        replies: list[str | _Block] = []
        with self.lock:
            for unit in message.split(";"):
                unit = unit.strip()
                if not unit:
                    continue
                try:
                    reply = self._execute_unit(unit)
                except _ScpiError as exc:
                    self._queue_error(exc.code, f"{exc.message}; {unit}")
                    continue
                if reply is not None:
                    replies.append(reply)
        return replies

    def _queue_error(self, code: int, message: str) -> None:
        if len(self.errors) < 32:
            self.errors.append((code, message.replace('"', "'")))

    def _execute_unit(self, unit: str) -> str | _Block | None:
        header, _, arg = unit.partition(" ")
        arg = arg.strip()
        query = header.endswith("?")
        header = header.rstrip("?")
        if header.startswith("*"):
            return self._common(header.upper(), query)
        nodes = header.lstrip(":").split(":")
        for patterns, handler in self._table():
            if len(patterns) == len(nodes):
                suffix = self._match(nodes, patterns)
                if suffix is not None:
                    return handler(suffix, query, arg)
        raise _ScpiError(-113, "Undefined header")

    @staticmethod
    def _match(nodes: list[str], patterns: tuple[str, ...]) -> int | None:
        """Match header nodes against patterns; return the numeric suffix (0 if none)."""
        suffix = 0
        for node, pattern in zip(nodes, patterns, strict=True):
            if pattern.endswith("<n>"):
                m = re.fullmatch(r"([A-Za-z]+)(\d*)", node)
                if m is None or not _header_matches(m.group(1), pattern[:-3]):
                    return None
                suffix = int(m.group(2) or 1)
            elif not _header_matches(node, pattern):
                return None
        return suffix

    def _table(self) -> list[tuple[tuple[str, ...], Callable[[int, bool, str], str | _Block | None]]]:
        return [
            (("SYSTem", "ERRor"), self._system_error),
            (("ACQuire", "SRATe"), self._sample_rate),
            (("ACQuire", "POINts"), self._points),
            (("ACQuire", "PRETrigger"), self._pretrigger),
            (("ACQuire", "STATe"), self._state),
            (("CHANnel<n>", "RANGe"), self._range),
            (("TRIGger", "SOURce"), self._trigger_source),
            (("TRIGger", "LEVel"), self._trigger_level),
            (("TRIGger", "SLOPe"), self._trigger_slope),
            (("SINGle",), self._single),
            (("ABORt",), self._abort),
            (("WAVeform", "SOURce"), self._waveform_source),
            (("WAVeform", "PREamble"), self._preamble),
            (("WAVeform", "DATA"), self._data),
        ]

    def _common(self, header: str, query: bool) -> str | None:
        if header == "*IDN" and query:
            return IDENTITY
        if header == "*OPC" and query:
            return "1"
        if header == "*RST" and not query:
            errors = self.errors
            self.reset()
            self.errors = errors
            return None
        if header == "*CLS" and not query:
            self.errors.clear()
            return None
        raise _ScpiError(-113, "Undefined header")

    # -- parameter helpers ---------------------------------------------------------------
    @staticmethod
    def _number(arg: str) -> float:
        if not arg:
            raise _ScpiError(-109, "Missing parameter")
        try:
            value = float(arg)
        except ValueError:
            raise _ScpiError(-104, "Data type error") from None
        if not np.isfinite(value):
            raise _ScpiError(-224, "Illegal parameter value")
        return value

    def _integer(self, arg: str) -> int:
        value = self._number(arg)
        if value != int(value):
            raise _ScpiError(-224, "Illegal parameter value")
        return int(value)

    @staticmethod
    def _choice(arg: str, choices: tuple[str, ...]) -> str:
        if not arg:
            raise _ScpiError(-109, "Missing parameter")
        value = arg.upper()
        if value not in choices:
            raise _ScpiError(-224, "Illegal parameter value")
        return value

    @staticmethod
    def _in_range(value: float, limits: tuple[float, float]) -> None:
        if not limits[0] <= value <= limits[1]:
            raise _ScpiError(-222, "Data out of range")

    def _no_change_while_armed(self) -> None:
        if self.state == "ARMED":
            raise _ScpiError(-221, "Settings conflict; acquisition armed")

    # -- handlers: (suffix, query, arg) -> reply -----------------------------------------
    def _system_error(self, _s: int, query: bool, _a: str) -> str:
        if not query:
            raise _ScpiError(-113, "Undefined header")
        if not self.errors:
            return '0,"No error"'
        code, message = self.errors.pop(0)
        return f'{code},"{message}"'

    def _sample_rate(self, _s: int, query: bool, arg: str) -> str | None:
        if query:
            return repr(float(self.settings.sample_rate_hz))
        value = self._number(arg)
        self._in_range(value, SAMPLE_RATE_LIMITS_HZ)
        self._no_change_while_armed()
        self.settings.sample_rate_hz = value
        return None

    def _points(self, _s: int, query: bool, arg: str) -> str | None:
        if query:
            return str(self.settings.record_length)
        value = self._integer(arg)
        self._in_range(value, RECORD_LENGTH_LIMITS)
        self._no_change_while_armed()
        self.settings.record_length = value
        self.settings.pre_trigger_samples = min(self.settings.pre_trigger_samples, value - 1)
        return None

    def _pretrigger(self, _s: int, query: bool, arg: str) -> str | None:
        if query:
            return str(self.settings.pre_trigger_samples)
        value = self._integer(arg)
        if not 0 <= value < self.settings.record_length:
            raise _ScpiError(-221, "Settings conflict; pre-trigger must be below the record length")
        self._no_change_while_armed()
        self.settings.pre_trigger_samples = value
        return None

    def _state(self, _s: int, query: bool, _a: str) -> str:
        if not query:
            raise _ScpiError(-113, "Undefined header")
        self.poll_capture()
        return self.state

    def _range(self, channel: int, query: bool, arg: str) -> str | None:
        if channel not in CHANNELS:
            raise _ScpiError(-114, "Header suffix out of range")
        if query:
            return repr(float(self.settings.ch_range_v[channel]))
        value = self._number(arg)
        self._in_range(value, RANGE_LIMITS_V)
        self._no_change_while_armed()
        self.settings.ch_range_v[channel] = value
        return None

    def _trigger_source(self, _s: int, query: bool, arg: str) -> str | None:
        if query:
            return self.settings.trigger_source
        value = self._choice(arg, TRIGGER_SOURCES)
        self._no_change_while_armed()
        self.settings.trigger_source = value
        return None

    def _trigger_level(self, _s: int, query: bool, arg: str) -> str | None:
        if query:
            return repr(float(self.settings.trigger_level_v))
        value = self._number(arg)
        self._in_range(abs(value), (0.0, RANGE_LIMITS_V[1]))
        self._no_change_while_armed()
        self.settings.trigger_level_v = value
        return None

    def _trigger_slope(self, _s: int, query: bool, arg: str) -> str | None:
        if query:
            return self.settings.trigger_slope
        value = self._choice(arg, TRIGGER_SLOPES)
        self._no_change_while_armed()
        self.settings.trigger_slope = value
        return None

    def _single(self, _s: int, query: bool, _a: str) -> None:
        if query:
            raise _ScpiError(-113, "Undefined header")
        self.codes, self.scale_v, self.state = {}, {}, "ARMED"
        return None

    def _abort(self, _s: int, query: bool, _a: str) -> None:
        if query:
            raise _ScpiError(-113, "Undefined header")
        self.codes, self.scale_v, self.state = {}, {}, "IDLE"
        return None

    def _waveform_source(self, _s: int, query: bool, arg: str) -> str | None:
        if query:
            return f"CH{self.waveform_source}"
        self.waveform_source = int(self._choice(arg, ("CH1", "CH2"))[2:])
        return None

    def _preamble(self, _s: int, query: bool, _a: str) -> str:
        if not query:
            raise _ScpiError(-113, "Undefined header")
        self.poll_capture()
        ch = self.waveform_source
        codes = self.codes.get(ch)
        points = 0 if codes is None else codes.size
        scale = self.scale_v.get(ch, self.settings.ch_range_v[ch] / INT16_FULL_SCALE)
        x_increment_s = 1.0 / self.settings.sample_rate_hz
        return (
            f"INT16,LSBF,{points},{x_increment_s!r},{self.settings.pre_trigger_samples},"
            f"{scale!r},0.0"
        )

    def _data(self, _s: int, query: bool, _a: str) -> _Block:
        if not query:
            raise _ScpiError(-113, "Undefined header")
        self.poll_capture()
        codes = self.codes.get(self.waveform_source)
        if codes is None:
            self._queue_error(-230, "Data corrupt or stale; no acquisition")
            return _Block(memoryview(b""))
        return _Block(memoryview(codes).cast("B"))


class _Handler(socketserver.BaseRequestHandler):
    """One client connection: read "\\n"-terminated messages, send the replies."""

    server: _ThreadingServer

    def handle(self) -> None:
        sock: socket.socket = self.request
        sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        self.server.track(sock, add=True)
        buffer = bytearray()
        try:
            while True:
                data = sock.recv(65536)
                if not data:
                    return
                buffer.extend(data)
                while (end := buffer.find(b"\n")) >= 0:
                    line = bytes(buffer[:end]).decode("ascii", "replace")
                    del buffer[: end + 1]
                    self._answer(sock, self.server.instrument.execute(line))
                if len(buffer) > MAX_LINE_BYTES:  # garbage without newline: drop it
                    buffer.clear()
        except OSError:
            return  # the client went away (possibly mid-transfer) or the server stops
        finally:
            self.server.track(sock, add=False)

    def _answer(self, sock: socket.socket, replies: list[str | _Block]) -> None:
        if not replies:
            return
        text = [r for r in replies if isinstance(r, str)]
        blocks = [r for r in replies if isinstance(r, _Block)]
        if text:
            sock.sendall((";".join(text) + "\n").encode("ascii"))
        for block in blocks:
            header = block_header(len(block.payload))
            if self.server.instrument.faults.active("visa-garbled-block"):
                # Corrupt length header: the digit count survives, the length digits do not.
                header = header[:2] + b"?\x0a" + b"X" * max(len(header) - 4, 0)
            sock.sendall(header)
            sock.sendall(block.payload)  # sent from the array's memory: no 20 MB copy
            sock.sendall(b"\n")


class _ThreadingServer(socketserver.ThreadingTCPServer):
    allow_reuse_address = True
    daemon_threads = False  # stop() joins every handler thread
    block_on_close = True

    def __init__(self, address: tuple[str, int], instrument: _Instrument) -> None:
        self.instrument = instrument
        self._clients: set[socket.socket] = set()
        self._clients_lock = threading.Lock()
        self._stopping = False
        super().__init__(address, _Handler)

    def track(self, sock: socket.socket, add: bool) -> None:
        with self._clients_lock:
            if not add:
                self._clients.discard(sock)
                return
            self._clients.add(sock)
            stopping = self._stopping
        if stopping:  # accepted just as stop() began: end it like the others
            sock.shutdown(socket.SHUT_RDWR)

    def drop_clients(self, stopping: bool = False) -> int:
        """Shut every client connection down (unblocks their handler threads)."""
        with self._clients_lock:
            self._stopping = self._stopping or stopping
            clients = list(self._clients)
        for sock in clients:
            try:
                sock.shutdown(socket.SHUT_RDWR)
            except OSError:
                pass
        return len(clients)


class SimDigitizerServer:
    """The simulated digitizer's SCPI socket server on loopback.

    capture(settings) -> {channel: volts} | None is polled while the instrument is armed.
    port=0 picks a free port; `port` and `resource` are valid after start().
    """

    def __init__(
        self,
        capture: CaptureFn,
        faults: FaultSet,
        host: str = "127.0.0.1",
        port: int = 0,
    ) -> None:
        self.host = host
        self.port = port
        self.faults = faults
        self._instrument = _Instrument(capture, faults)
        self._server: _ThreadingServer | None = None
        self._thread: threading.Thread | None = None

    @property
    def resource(self) -> str:
        """The VISA resource name, e.g. "TCPIP0::127.0.0.1::5025::SOCKET"."""
        return f"TCPIP0::{self.host}::{self.port}::SOCKET"

    @property
    def settings(self) -> AcquisitionSettings:
        """A copy of the instrument's current acquisition settings."""
        with self._instrument.lock:
            return copy.deepcopy(self._instrument.settings)

    @property
    def state(self) -> str:
        """IDLE | ARMED | TRIGGERED (without polling the capture function)."""
        with self._instrument.lock:
            return self._instrument.state

    def start(self) -> None:
        """Bind and serve in a background thread; returns once the port is bound."""
        if self._server is not None:
            raise RuntimeError("simulated digitizer already started")
        self._server = _ThreadingServer((self.host, self.port), self._instrument)
        self.port = self._server.server_address[1]
        self._thread = threading.Thread(
            target=self._server.serve_forever,
            kwargs={"poll_interval": 0.05},
            name=f"sim-digitizer:{self.port}",
        )
        self._thread.start()

    def drop_connections(self) -> int:
        """Simulate a dropped link: close every open client connection; return how many."""
        return self._server.drop_clients() if self._server is not None else 0

    def stop(self) -> None:
        """Stop serving, close client connections and join every thread. Idempotent."""
        server, thread = self._server, self._thread
        if server is None:
            return
        server.shutdown()
        if thread is not None:
            thread.join()
        server.drop_clients(stopping=True)
        server.server_close()  # joins the handler threads (block_on_close)
        self._server = None
        self._thread = None

    def __enter__(self) -> SimDigitizerServer:
        self.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()
