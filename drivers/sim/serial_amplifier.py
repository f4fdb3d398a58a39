"""The simulated bridge amplifier: a serial device at the end of a simulated line, in front of
the World.

The device sits on the far end of a `PtyLine` (drivers/sim/serial_line.py): the driver opens
`port` (e.g. /dev/pts/7) with pyserial, exactly as it would open /dev/ttyUSB0, and every byte
takes the line's byte time (`baudrate`, 8N1). The protocol is the one documented in
drivers/amplifier.py; this module implements the amplifier's side of it on its own (framing,
checksum, the settings it accepts), so loopback tests check the driver's reading against the
simulator's. Optionally a symlink (`link_path`) gives the port a stable name.

Fault `serial-noise`: every reply has one byte flipped (its checksum no longer matches), as
line noise would do.
"""

from __future__ import annotations

import contextlib
import os
import select
import threading

from hopkinson.drivers.sim.faults import FaultSet
from hopkinson.drivers.sim.serial_line import PtyLine, byte_time_s
from hopkinson.drivers.sim.world import World
from hopkinson.drivers.sim.world_params import AMP_EXCITATION_RANGE_V as EXCITATION_RANGE_V
from hopkinson.drivers.sim.world_params import AMP_GAINS as GAINS
from hopkinson.drivers.sim.world_params import AMP_LOWPASS_HZ as LOWPASS_HZ

MAX_LINE_BYTES = 256  # a longer line without an end is dropped


def checksum(payload: bytes) -> str:
    """NMEA-0183 style: XOR of the payload bytes as two upper-case hex digits."""
    value = 0
    for byte in payload:
        value ^= byte
    return f"{value:02X}"


class SimSerialAmplifier:
    """The amplifier's serial face. `port` is the path the driver opens (after start())."""

    def __init__(self, world: World, faults: FaultSet, link_path: str | None = None,
                 baudrate: int = 115200) -> None:
        self.world = world
        self.faults = faults
        self.line = PtyLine(byte_time_s(baudrate), link_path=link_path, name="sim-amplifier-line")
        self.baudrate = baudrate
        self.lines_served = 0
        self._thread: threading.Thread | None = None
        self._stop = threading.Event()

    @property
    def port(self) -> str:
        """The serial port the driver opens (valid after start())."""
        return self.line.port

    @property
    def link_path(self) -> str | None:
        return self.line.link_path

    # -- life cycle -----------------------------------------------------------------------
    def start(self) -> None:
        """Start the line (and its symlink) and serve the device end in a background thread."""
        if self._thread is not None:
            raise RuntimeError("simulated amplifier already started")
        self.line.start()
        self._stop.clear()
        self._thread = threading.Thread(target=self._serve, args=(self.line.device_fd,), name="sim-amplifier",
                                        daemon=True)
        self._thread.start()

    def stop(self) -> None:
        """Stop serving, join the thread, stop the line (idempotent)."""
        if self._thread is None:
            return
        self._stop.set()
        self._thread.join(5.0)
        self._thread = None
        self.line.stop()

    def __enter__(self) -> SimSerialAmplifier:
        self.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()

    # -- serving --------------------------------------------------------------------------
    def _serve(self, fd: int) -> None:
        buffer = bytearray()
        while not self._stop.is_set():
            ready, _, _ = select.select([fd], [], [], 0.05)
            if not ready:
                continue
            try:
                data = os.read(fd, 4096)
            except OSError:  # the line is going away
                self._stop.wait(0.05)
                continue
            buffer.extend(data)
            while (end := buffer.find(b"\n")) >= 0:
                line = bytes(buffer[:end]).rstrip(b"\r")
                del buffer[: end + 1]
                self._reply(fd, line)
            if len(buffer) > MAX_LINE_BYTES:
                buffer.clear()

    def _reply(self, fd: int, line: bytes) -> None:
        payload = self.handle(line).encode("ascii")
        out = bytearray(payload + b"*" + checksum(payload).encode("ascii") + b"\n")
        if self.faults.active("serial-noise") and payload:
            out[len(payload) // 2] ^= 0x04  # one flipped bit: the checksum no longer matches
        self.lines_served += 1
        with contextlib.suppress(OSError):
            os.write(fd, bytes(out))

    def handle(self, line: bytes) -> str:
        """The reply payload for one received line (without its end of line)."""
        try:
            text = line.decode("ascii").strip()
        except UnicodeDecodeError:
            return "? ERR SYNTAX"
        body, star, digits = text.rpartition("*")
        if star and len(digits) == 2 and body:
            verb = body.split(" ", 1)[0].rstrip("?")
            if digits.upper() != checksum(body.encode("ascii")):
                return f"{verb} ERR CHECKSUM"
            text = body
        if not text:
            return "? ERR SYNTAX"
        head, _, arg = text.partition(" ")
        arg = arg.strip().upper()
        query = head.endswith("?")
        verb = head.rstrip("?").upper()
        try:
            value = self._command(verb, query, arg)
        except _Refused as exc:
            return f"{verb} ERR {exc}"
        return f"{verb} {value}"

    def _command(self, verb: str, query: bool, arg: str) -> str:
        w = self.world
        if verb == "*IDN" and query:
            return w.params.amplifier.identity
        if verb == "EXC":
            if query:
                return f"{w.amp_settings().excitation_v:.3f}"
            value = _number(arg)
            if not EXCITATION_RANGE_V[0] <= value <= EXCITATION_RANGE_V[1]:
                raise _Refused("RANGE")
            w.set_amp_excitation_v(value)
            return "OK"
        if verb == "GAIN":
            if query:
                return f"{w.amp_settings().gain:g}"
            value = _number(arg)
            if value not in GAINS:
                raise _Refused("RANGE")
            w.set_amp_gain(value)
            return "OK"
        if verb == "LP":
            if query:
                corner = w.amp_settings().lowpass_hz
                return "OFF" if corner == 0 else f"{corner:g}"
            value = 0.0 if arg == "OFF" else _number(arg)
            if value != 0 and value not in LOWPASS_HZ:
                raise _Refused("RANGE")
            w.set_amp_lowpass_hz(value)
            return "OK"
        if verb == "AZ" and not query and not arg:
            w.amp_auto_zero()
            return "OK"
        if verb == "SHUNT":
            if query:
                return "ON" if w.amp_settings().shunt_on else "OFF"
            if arg not in ("ON", "OFF"):
                raise _Refused("SYNTAX")
            w.set_amp_shunt(arg == "ON")
            return "OK"
        if verb == "OVL":
            if query:
                return "1" if w.amp_overloaded() else "0"
            if arg != "CLR":
                raise _Refused("SYNTAX")
            w.clear_amp_overload()
            return "OK"
        if verb == "OUT" and query:
            return f"{w.amp_output_v():.4f}"
        raise _Refused("UNKNOWN")


class _Refused(Exception):
    """An ERR reply with this reason."""


def _number(arg: str) -> float:
    try:
        return float(arg)
    except ValueError:
        raise _Refused("SYNTAX") from None
