"""The simulated bridge amplifier: a serial device on a pseudo-terminal, in front of the World.

`os.openpty()` gives a master/slave pair; this device serves on the master and the driver
opens the slave's path (e.g. /dev/pts/7) with pyserial, exactly as it would open
/dev/ttyUSB0. The protocol is the one documented in drivers/amplifier.py; lines are
split and parsed here independently of the driver, so loopback tests check one reading
against the other (the checksum is the driver's `checksum`, pinned to known bytes by
tests/drivers/test_amplifier.py). Optionally a symlink (`link_path`) gives the device a stable name for a config file.

Fault `serial-noise`: every reply has one byte flipped (its checksum no longer matches), as
line noise would do.
"""

from __future__ import annotations

import contextlib
import os
import select
import threading
import tty

from hopkinson.drivers.amplifier import (
    EXCITATION_RANGE_V,
    GAINS,
    LOWPASS_HZ,
    MAX_LINE_BYTES,
    checksum,
)
from hopkinson.drivers.sim.faults import FaultSet
from hopkinson.drivers.sim.world import World


class SimSerialAmplifier:
    """The amplifier's serial face. `port` is the path the driver opens (after start())."""

    def __init__(self, world: World, faults: FaultSet, link_path: str | None = None) -> None:
        self.world = world
        self.faults = faults
        self.link_path = link_path
        self.port = ""
        self.lines_served = 0
        self._master: int | None = None
        self._slave: int | None = None
        self._thread: threading.Thread | None = None
        self._stop = threading.Event()

    # -- life cycle -----------------------------------------------------------------------
    def start(self) -> None:
        """Create the pty (and the symlink) and serve it in a background thread."""
        if self._thread is not None:
            raise RuntimeError("simulated amplifier already started")
        master, slave = os.openpty()
        tty.setraw(slave)  # no echo, no CR/LF translation: bytes pass as sent
        self._master, self._slave = master, slave
        self.port = os.ttyname(slave)
        if self.link_path:
            with contextlib.suppress(FileNotFoundError):
                os.unlink(self.link_path)
            os.symlink(self.port, self.link_path)
        self._stop.clear()
        self._thread = threading.Thread(target=self._serve, name="sim-amplifier", daemon=True)
        self._thread.start()

    def stop(self) -> None:
        """Stop serving, join the thread, close the pty and remove the symlink (idempotent)."""
        if self._thread is None:
            return
        self._stop.set()
        self._thread.join(5.0)
        self._thread = None
        for fd in (self._master, self._slave):
            if fd is not None:
                with contextlib.suppress(OSError):
                    os.close(fd)
        self._master = self._slave = None
        if self.link_path and os.path.islink(self.link_path) and os.readlink(self.link_path) == self.port:
            os.unlink(self.link_path)

    def __enter__(self) -> SimSerialAmplifier:
        self.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()

    # -- serving --------------------------------------------------------------------------
    def _serve(self) -> None:
        assert self._master is not None
        master = self._master
        buffer = bytearray()
        while not self._stop.is_set():
            ready, _, _ = select.select([master], [], [], 0.05)
            if not ready:
                continue
            try:
                data = os.read(master, 4096)
            except OSError:  # no slave open at the moment (EIO): wait for one
                self._stop.wait(0.05)
                continue
            buffer.extend(data)
            while (end := buffer.find(b"\n")) >= 0:
                line = bytes(buffer[:end]).rstrip(b"\r")
                del buffer[: end + 1]
                self._reply(master, line)
            if len(buffer) > MAX_LINE_BYTES:
                buffer.clear()

    def _reply(self, master: int, line: bytes) -> None:
        payload = self.handle(line).encode("ascii")
        out = bytearray(payload + b"*" + checksum(payload).encode("ascii") + b"\n")
        if self.faults.active("serial-noise") and payload:
            out[len(payload) // 2] ^= 0x04  # one flipped bit: the checksum no longer matches
        self.lines_served += 1
        with contextlib.suppress(OSError):
            os.write(master, bytes(out))

    def handle(self, line: bytes) -> str:
        """The reply payload for one received line (without its end of line)."""
        try:
            text = line.decode("ascii").strip()
        except UnicodeDecodeError:
            return "? ERR SYNTAX"
        body, star, digits = text.rpartition("*")
        if star and len(digits) == 2 and body:
            verb = body.split(" ", 1)[0].rstrip("?")
            if digits.upper() != checksum(body):
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
