"""A line-based instrument on a serial port (pyserial): the base of the bridge amplifier's
driver and of a lab's own serial instrument.

- The port is opened exclusively (pyserial `exclusive=True`, an advisory lock every pyserial
  user honours): a second process gets a clear "held by another process" error instead of
  sharing the line and reading the other's replies.
- `exchange(line)` flushes stale input, writes one line and reads one reply line, bounded: at
  most `max_line_bytes`, within `timeout_s` overall (drivers/base.read_bounded). A device
  that streams without a newline is an InstrumentError within the timeout.
- Each line sent and received is traced.
"""

from __future__ import annotations

import serial

from hopkinson.drivers.base import InstrumentDriver, TraceHook, read_bounded
from hopkinson.drivers.errors import InstrumentConnectionError

PARITIES = {"N": serial.PARITY_NONE, "E": serial.PARITY_EVEN, "O": serial.PARITY_ODD}


class SerialLineDriver(InstrumentDriver):
    """An instrument that answers each line with one line (module docstring)."""

    terminator = b"\n"
    max_line_bytes = 256

    def __init__(self, port: str, *, baudrate: int = 115200, bytesize: int = 8, parity: str = "N",
                 stopbits: int = 1, timeout_s: float = 1.0, name: str | None = None,
                 trace: TraceHook | None = None) -> None:
        super().__init__(name or f"serial instrument {port}", timeout_s=timeout_s, trace=trace)
        if parity not in PARITIES:
            raise ValueError(f"{self.name}: parity must be N, E or O, got {parity!r}")
        self.port = port
        self.baudrate = baudrate
        self.bytesize = bytesize
        self.parity = parity
        self.stopbits = stopbits
        self._serial: serial.Serial | None = None

    @property
    def byte_time_s(self) -> float:
        """Seconds per byte on the line (start, data, parity and stop bits)."""
        return (1 + self.bytesize + (self.parity != "N") + self.stopbits) / self.baudrate

    def _open(self) -> None:
        try:
            self._serial = serial.Serial(self.port, self.baudrate, bytesize=self.bytesize,
                                         parity=PARITIES[self.parity], stopbits=self.stopbits,
                                         timeout=self.timeout_s, write_timeout=self.timeout_s, exclusive=True)
        except (serial.SerialException, OSError, ValueError) as exc:
            busy = "lock" in str(exc).lower()
            hint = " (held by another process: `hopkinson status` names it)" if busy else ""
            raise InstrumentConnectionError(self.name, "open", f"cannot open serial port: {exc}{hint}") from exc

    def _close_link(self) -> None:
        port, self._serial = self._serial, None
        if port is not None:
            port.close()

    def _link_open(self) -> bool:
        return self._serial is not None

    def exchange(self, line: bytes, command: str) -> bytes:
        """Send `line`, return the reply line (with its terminator); `command` names it in errors."""
        with self.lock:
            self._ensure_link(command)
            port = self._serial
            assert port is not None
            try:
                port.reset_input_buffer()  # stale or noisy bytes from an earlier exchange
                self._trace_out(line)
                port.write(line)
                port.flush()
                reply = read_bounded(lambda n, wait_s: self._read(port, n, wait_s), terminator=self.terminator,
                                     max_bytes=self.max_line_bytes, timeout_s=self.timeout_s,
                                     instrument=self.name, command=command)
            except (serial.SerialException, OSError) as exc:
                self._drop()
                raise InstrumentConnectionError(self.name, command, f"serial port failed: {exc}") from exc
            self._trace_in(reply)
            return reply

    @staticmethod
    def _read(port: serial.Serial, n: int, wait_s: float) -> bytes:
        """What is waiting (at most n bytes), or the first byte within wait_s."""
        port.timeout = wait_s
        return port.read(max(1, min(n, port.in_waiting)))
