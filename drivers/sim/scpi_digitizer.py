"""Simulated digitizer: a message-based instrument on a raw TCP socket (VISA `...::SOCKET`).

One socket server (`SimDigitizerServer`) hosts one simulated instrument, in the dialect asked
for: "generic" (drivers/sim/digitizer_generic.py), "keysight" (drivers/sim/digitizer_keysight.py),
"tektronix" (drivers/sim/digitizer_tektronix.py) or "lecroy" (drivers/sim/digitizer_lecroy.py).
Each implements its side of its protocol from the vendor's documentation, independently of the
drivers (drivers/sim imports no driver module), so the tests over loopback check a driver
against a second reading of the protocol.

What every dialect shares: the message framing (drivers/sim/scpi_messages.py), the IEEE 488.2
common commands, the acquisition and the transfer formats (drivers/sim/scpi_instrument.py), and
this server.

Faults (drivers/sim/faults.py): `visa-garbled-block` sends the waveform block with a corrupt
length header (the payload follows, so the client's stream is out of step afterwards);
`visa-endless-reply`, while the instrument is armed or holds a record, answers a query's text
and then streams digits and commas with no terminator until the client hangs up (in every
dialect: the reply never ends, so only the client's size limit or deadline can end the read);
`no-trigger` (the world's) fires without a capture. A client that drops its connection (even
mid-transfer) only ends its own handler thread.
"""

from __future__ import annotations

import copy
import importlib
import socket
import socketserver
import threading

from hopkinson.drivers.sim.faults import FaultSet
from hopkinson.drivers.sim.scpi_instrument import AcquisitionSettings, CaptureFn, SimDigitizer
from hopkinson.drivers.sim.scpi_messages import Block, block_bytes

MAX_LINE_BYTES = 65536
ENDLESS_CHUNK = b"1," * 4096  # the `visa-endless-reply` fault's stream: never a terminator

SIM_DIALECTS = {
    "generic": "hopkinson.drivers.sim.digitizer_generic:GenericSimDigitizer",
    "keysight": "hopkinson.drivers.sim.digitizer_keysight:KeysightSimDigitizer",
    "tektronix": "hopkinson.drivers.sim.digitizer_tektronix:TektronixSimDigitizer",
    "lecroy": "hopkinson.drivers.sim.digitizer_lecroy:LeCroySimDigitizer",
}


def sim_instrument_class(dialect: str) -> type[SimDigitizer]:
    """The simulated instrument of a dialect name (ValueError naming the known ones)."""
    target = SIM_DIALECTS.get(dialect)
    if target is None:
        raise ValueError(f"no simulated digitizer speaks {dialect!r} (known: {', '.join(SIM_DIALECTS)})")
    module, _, name = target.partition(":")
    return getattr(importlib.import_module(module), name)


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
                    line = bytes(buffer[:end]).decode("ascii", "replace").rstrip("\r")
                    del buffer[: end + 1]
                    self._answer(sock, self.server.instrument.execute(line, self.server.stopping))
                if len(buffer) > MAX_LINE_BYTES:  # garbage without newline: drop it
                    buffer.clear()
        except OSError:
            return  # the client went away (possibly mid-transfer) or the server stops
        finally:
            self.server.track(sock, add=False)

    def _answer(self, sock: socket.socket, replies: list[str | Block]) -> None:
        if not replies:
            return
        instrument = self.server.instrument
        if (isinstance(replies[0], str) and instrument.faults.active("visa-endless-reply")
                and instrument.state != "IDLE"):
            sock.sendall(replies[0].encode("ascii"))
            while not self.server.stopping.is_set():  # until the client hangs up (OSError) or stop()
                sock.sendall(ENDLESS_CHUNK)
            return
        text: list[bytes] = []
        for i, reply in enumerate(replies):
            if i:
                text.append(b";")
            if isinstance(reply, str):
                text.append(reply.encode("ascii"))
                continue
            header = block_bytes(reply)
            if self.server.instrument.faults.active("visa-garbled-block"):
                # Corrupt length header: the digit count survives, the length digits do not.
                cut = len(reply.prefix) + 2
                header = header[:cut] + b"?\x0a" + b"X" * max(len(header) - cut - 2, 0)
            sock.sendall(b"".join(text) + header + reply.lead)
            text = []
            sock.sendall(reply.payload)  # sent from the record's memory: no 20 MB copy
        text.append(b"\n")
        sock.sendall(b"".join(text))


class _ThreadingServer(socketserver.ThreadingTCPServer):
    allow_reuse_address = True
    daemon_threads = False  # stop() joins every handler thread
    block_on_close = True

    def __init__(self, address: tuple[str, int], instrument: SimDigitizer) -> None:
        self.instrument = instrument
        self.stopping = threading.Event()
        self._clients: set[socket.socket] = set()
        self._clients_lock = threading.Lock()
        super().__init__(address, _Handler)

    def track(self, sock: socket.socket, add: bool) -> None:
        with self._clients_lock:
            if not add:
                self._clients.discard(sock)
                return
            self._clients.add(sock)
            stopping = self.stopping.is_set()
        if stopping:  # accepted just as stop() began: end it like the others
            sock.shutdown(socket.SHUT_RDWR)

    def drop_clients(self, stopping: bool = False) -> int:
        """Shut every client connection down (unblocks their handler threads)."""
        with self._clients_lock:
            if stopping:
                self.stopping.set()
            clients = list(self._clients)
        for sock in clients:
            try:
                sock.shutdown(socket.SHUT_RDWR)
            except OSError:
                pass
        return len(clients)


class SimDigitizerServer:
    """The simulated digitizer's socket server on loopback, in one dialect.

    capture(settings) -> {channel: volts} | None is polled while the instrument is armed.
    port=0 picks a free port; `port` and `resource` are valid after start().
    """

    def __init__(
        self,
        capture: CaptureFn,
        faults: FaultSet,
        host: str = "127.0.0.1",
        port: int = 0,
        dialect: str = "generic",
    ) -> None:
        self.host = host
        self.port = port
        self.faults = faults
        self.dialect = dialect
        self._instrument = sim_instrument_class(dialect)(capture, faults)
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
    def channels_on(self) -> dict[int, bool]:
        """Each channel's on/off state as the instrument holds it (a copy)."""
        with self._instrument.lock:
            return dict(self._instrument.channel_on)

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
