"""Taking control of the rig: the lock first, then the instruments, then the link watchdog.

    with controlled_rig(config, command="hopkinson shot ...") as control:
        sequencer = Sequencer(control.instruments, config, bus)
        ...
    # on the way out, whatever happened: heartbeat stopped (watchdog disarmed), instruments
    # closed, lock released

Order matters. The rig lock (rig/lock.py) is taken before anything is connected or commanded,
so a second shot, campaign, panel or `hopkinson safe` on the same rig is refused at once and
touches nothing. Then the instruments are connected and a heartbeat session is started on the
valve controller: while this process controls the rig its driver feeds the controller's link
watchdog, and if the process dies or hangs, the controller itself de-energises fill and fire,
stops the pump and vents within `valve_controller.watchdog_s`.
"""

from __future__ import annotations

import contextlib
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from typing import Any

from hopkinson.rig.config import RigConfig
from hopkinson.rig.instruments import Instruments, open_instruments
from hopkinson.rig.lock import LockHolder, RigLock


@dataclass
class Control:
    """A process's control of one rig: its instruments and its lock."""

    instruments: Instruments
    lock: RigLock

    @property
    def reclaimed(self) -> LockHolder | None:
        """The holder a dead process left in the lock, when this process took it over."""
        return self.lock.reclaimed


@contextlib.contextmanager
def rig_lock(config: RigConfig, command: str | None = None) -> Iterator[RigLock]:
    """Just the lock (for the panel, which connects its instruments itself)."""
    lock = RigLock.acquire(config, command)
    try:
        yield lock
    finally:
        lock.release()


@contextlib.contextmanager
def controlled_rig(config: RigConfig, command: str | None = None,
                   simulated_truth: Callable[[], dict[str, Any] | None] | None = None,
                   heartbeat: bool = True) -> Iterator[Control]:
    """Lock, connect, start the heartbeat (module docstring). RigLockError (exit 2) when the
    rig is held; InstrumentError when an instrument cannot be reached or the heartbeat cannot
    be started."""
    with rig_lock(config, command) as lock, open_instruments(config, simulated_truth) as instruments:
        if heartbeat:
            instruments.valves.start_heartbeat()
        try:
            yield Control(instruments, lock)
        finally:
            if heartbeat:
                with contextlib.suppress(Exception):  # closing stops it too; never mask the real error
                    instruments.valves.stop_heartbeat()
