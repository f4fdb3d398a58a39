"""A simulated serial cable: two pseudo-terminals joined at the line's byte time.

`os.openpty()` gives master/slave pairs that pass bytes instantly. A real line at 115 200 baud
takes 86.8 µs per byte (8N1: 10 bits), and a host that ignores this (no inter-frame gap, no
time for the reply) works on a pty and fails on the rig. `PtyLine` makes two ptys:

- `port`: the host's end (e.g. /dev/pts/7), which the driver opens with pyserial exactly as it
  would open /dev/ttyUSB0 (optionally also reachable as the symlink `link_path`);
- `device_port` / `device_fd`: the simulated instrument's end (a pymodbus serial server opens
  the path; a device written here reads and writes the fd).

Two threads pass the bytes between the masters, each direction no faster than the line: a
chunk written at t arrives, a couple of milliseconds' worth at a time, by t + n * byte_time
(after whatever was still on the wire). Bytes sent with nobody listening are dropped, as on a
real line.
"""

from __future__ import annotations

import contextlib
import errno
import fcntl
import os
import select
import threading
import time
import tty

PIECE_S = 0.002  # bytes delivered together: about this much line time


def byte_time_s(baudrate: int, bytesize: int = 8, parity: str = "N", stopbits: int = 1) -> float:
    """Seconds one byte takes on the line: start bit, data bits, parity bit, stop bits."""
    return (1 + bytesize + (parity != "N") + stopbits) / baudrate


class PtyLine:
    """A serial line between the host's pty and a simulated device's pty (module docstring)."""

    def __init__(self, byte_s: float, link_path: str | None = None, name: str = "sim-line") -> None:
        if not byte_s >= 0:
            raise ValueError(f"byte time must be >= 0, got {byte_s!r}")
        self.byte_s = byte_s
        self.link_path = link_path
        self.name = name
        self.port = ""
        self.device_port = ""
        self.device_fd = -1
        self.bytes_passed = 0
        self._fds: list[int] = []
        self._threads: list[threading.Thread] = []
        self._stop = threading.Event()

    def start(self) -> None:
        """Make the two ptys (and the symlink) and start passing bytes."""
        if self._threads:
            raise RuntimeError(f"{self.name} already started")
        host_master, host_slave = os.openpty()
        device_master, device_slave = os.openpty()
        self._fds = [host_master, host_slave, device_master, device_slave]
        for fd in (host_slave, device_slave):
            tty.setraw(fd)  # no echo, no CR/LF translation: bytes pass as sent
        for fd in (host_master, device_master):
            fcntl.fcntl(fd, fcntl.F_SETFL, fcntl.fcntl(fd, fcntl.F_GETFL) | os.O_NONBLOCK)
        self.port = os.ttyname(host_slave)
        self.device_port = os.ttyname(device_slave)
        self.device_fd = device_slave  # the line keeps both slaves open: a master never reads EIO
        if self.link_path:
            with contextlib.suppress(FileNotFoundError):
                os.unlink(self.link_path)
            os.symlink(self.port, self.link_path)
        self._stop.clear()
        self._threads = [
            threading.Thread(target=self._pass, args=(host_master, device_master), name=f"{self.name}-out", daemon=True),
            threading.Thread(target=self._pass, args=(device_master, host_master), name=f"{self.name}-in", daemon=True),
        ]
        for thread in self._threads:
            thread.start()

    def stop(self) -> None:
        """Stop, join the threads, close the ptys, remove the symlink (idempotent)."""
        if not self._threads:
            return
        self._stop.set()
        for thread in self._threads:
            thread.join(5.0)
        self._threads = []
        for fd in self._fds:
            with contextlib.suppress(OSError):
                os.close(fd)
        self._fds = []
        self.device_fd = -1
        if self.link_path and os.path.islink(self.link_path) and os.readlink(self.link_path) == self.port:
            os.unlink(self.link_path)

    def __enter__(self) -> PtyLine:
        self.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()

    def _pass(self, source: int, sink: int) -> None:
        piece = max(1, int(PIECE_S / self.byte_s)) if self.byte_s > 0 else 1 << 16
        free_at = 0.0  # when the line in this direction is next idle
        while not self._stop.is_set():
            ready, _, _ = select.select([source], [], [], 0.05)
            if not ready:
                continue
            try:
                data = os.read(source, 4096)
            except OSError as exc:  # EIO: the other side's pty is not open right now
                if exc.errno not in (errno.EIO, errno.EAGAIN):
                    raise
                self._stop.wait(0.01)
                continue
            start = max(time.monotonic(), free_at)
            for offset in range(0, len(data), piece):
                chunk = data[offset: offset + piece]
                free_at = start = start + len(chunk) * self.byte_s
                if self._stop.wait(max(0.0, start - time.monotonic())):
                    return
                with contextlib.suppress(BlockingIOError, OSError):  # nobody reading: bytes lost
                    os.write(sink, chunk)
                self.bytes_passed += len(chunk)
