"""Termination signals while a process drives the rig: every way out goes SAFE.

    with SignalLatch() as latch:              # SIGINT, SIGTERM and SIGHUP are caught from here on
        ... connect ...
        latch.on_signal(sequencer.abort)      # called once, with "interrupted (SIGTERM)", at once
        outcome = sequencer.run_shot(...)     #   if a signal came already
    if latch.received: ... exit code 3 ...

The handler itself only notes the signal: it runs in the main thread between two bytecodes,
where taking a lock the interrupted code holds would deadlock and printing would re-enter the
stream. The signal number also reaches a watcher thread through `signal.set_wakeup_fd`, which
CPython writes from its C-level handler; the watcher calls the callbacks at once, even while
the main thread sits in C code (a Qt event loop, a blocking read). The callbacks must be safe
to call from another thread and idempotent (`Sequencer.abort` holds the abort: it is never
re-sent).

Only the main thread can install handlers; elsewhere the latch catches nothing (and says so
through `active`). Latches nest: one entered while another is active listens to the outer
one's signals instead of installing handlers of its own.
"""

from __future__ import annotations

import contextlib
import os
import select
import signal
import threading
from collections.abc import Callable
from types import FrameType
from typing import Any

RIG_SIGNALS = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)
_STOP = b"\0"  # written by the latch itself to end the watcher (no signal has number 0)
_installed: list[SignalLatch] = []  # the latch that holds the handlers (at most one)


class SignalLatch:
    """Catch termination signals for a block (module docstring)."""

    def __init__(self, signals: tuple[signal.Signals, ...] = RIG_SIGNALS) -> None:
        self.signals = signals
        self.received: signal.Signals | None = None
        self.active = False
        self._callbacks: list[Callable[[str], Any]] = []
        self._lock = threading.Lock()
        self._previous: dict[signal.Signals, Any] = {}
        self._previous_fd = -1
        self._pipe: tuple[int, int] | None = None
        self._watcher: threading.Thread | None = None
        self._outer: SignalLatch | None = None

    @property
    def reason(self) -> str:
        """"interrupted (SIGTERM)", or "" before any signal."""
        return f"interrupted ({self.received.name})" if self.received is not None else ""

    def on_signal(self, callback: Callable[[str], Any]) -> None:
        """Call `callback(reason)` when a signal comes (at once if one came already)."""
        with self._lock:
            self._callbacks.append(callback)
            pending = self.received is not None
        if pending:
            self._call(callback)

    def _call(self, callback: Callable[[str], Any]) -> None:
        try:
            callback(self.reason)
        except Exception:  # a callback's failure must not stop the others (nor the watcher)
            import logging

            logging.getLogger(__name__).exception("signal callback %r failed", callback)

    def _from_outer(self, reason: str) -> None:
        outer = self._outer
        if outer is not None and outer.received is not None and self.active:
            self._note(int(outer.received))

    def _note(self, signum: int) -> None:
        """Record the first signal and call every callback (watcher thread)."""
        with self._lock:
            if self.received is not None:
                return
            self.received = signal.Signals(signum)
            callbacks = list(self._callbacks)
        for callback in callbacks:
            self._call(callback)

    def _handler(self, signum: int, _frame: FrameType | None) -> None:
        if self.received is None and self._watcher is None:  # no watcher: note it here (rare)
            self.received = signal.Signals(signum)

    def _watch(self, read_fd: int) -> None:
        while True:
            try:
                select.select([read_fd], [], [])
                data = os.read(read_fd, 64)
            except InterruptedError:
                continue
            except OSError:
                return
            for byte in data:
                if byte == _STOP[0]:
                    return
                if byte in {int(s) for s in self.signals}:
                    self._note(byte)

    def __enter__(self) -> SignalLatch:
        if threading.current_thread() is not threading.main_thread():
            return self
        if _installed:  # nested: listen to the latch that holds the handlers
            self._outer = _installed[0]
            self.active = True
            self._outer.on_signal(self._from_outer)
            return self
        read_fd, write_fd = os.pipe()
        os.set_blocking(write_fd, False)
        self._pipe = (read_fd, write_fd)
        self._previous = {sig: signal.signal(sig, self._handler) for sig in self.signals}
        self._previous_fd = signal.set_wakeup_fd(write_fd, warn_on_full_buffer=False)
        self._watcher = threading.Thread(target=self._watch, args=(read_fd,), name="signal-latch", daemon=True)
        self._watcher.start()
        self.active = True
        _installed.append(self)
        return self

    def __exit__(self, *exc: object) -> None:
        if not self.active:
            return
        self.active = False
        if self._outer is not None:
            with self._outer._lock:
                if self._from_outer in self._outer._callbacks:
                    self._outer._callbacks.remove(self._from_outer)
            self._outer = None
            return
        if self in _installed:
            _installed.remove(self)
        with contextlib.suppress(ValueError, OSError):
            signal.set_wakeup_fd(self._previous_fd)
        for sig, old in self._previous.items():
            signal.signal(sig, old)
        assert self._pipe is not None
        read_fd, write_fd = self._pipe
        with contextlib.suppress(OSError):
            os.write(write_fd, _STOP)
        if self._watcher is not None:
            self._watcher.join(2.0)
        for fd in (read_fd, write_fd):
            with contextlib.suppress(OSError):
                os.close(fd)


@contextlib.contextmanager
def exit_cleanly_on_termination(signals: tuple[signal.Signals, ...] = (signal.SIGTERM, signal.SIGHUP)) -> Any:
    """For commands that drive no rig: SIGTERM and SIGHUP raise `Interrupted` (a BaseException,
    like KeyboardInterrupt), so `with` blocks unwind and half-written files are removed; the
    exit code is 128 + the signal's number. Main thread only (elsewhere a no-op)."""
    from hopkinson.rig.errors import Interrupted

    if threading.current_thread() is not threading.main_thread():
        yield
        return

    def handler(signum: int, _frame: FrameType | None) -> None:
        sig = signal.Signals(signum)
        raise Interrupted(sig.name, 128 + int(sig))

    previous = {sig: signal.signal(sig, handler) for sig in signals}
    try:
        yield
    finally:
        for sig, old in previous.items():
            signal.signal(sig, old)
