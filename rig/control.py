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
from typing import TYPE_CHECKING, Any

from hopkinson.rig.config import RigConfig
from hopkinson.rig.instruments import Instruments, open_instruments
from hopkinson.rig.lock import LockHolder, RigLock

if TYPE_CHECKING:
    from hopkinson.rig.sequencer import FireAuthorisation, Sequencer
    from hopkinson.rig.shot import ShotOutcome, ShotRequest
    from hopkinson.rig.signals import SignalLatch


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
    rig is held; InstrumentUnreachable (exit 2, one line with the fix) when an instrument
    cannot be reached or the heartbeat cannot be started."""
    with contextlib.ExitStack() as stack:
        lock = stack.enter_context(rig_lock(config, command))
        with _reached(config):  # only the session's set-up: a failure in the shot is the sequencer's to tell
            instruments = stack.enter_context(open_instruments(config, simulated_truth))
            if heartbeat:
                instruments.valves.start_heartbeat()
        try:
            yield Control(instruments, lock)
        finally:
            if heartbeat:
                with contextlib.suppress(Exception):  # closing stops it too; never mask the real error
                    instruments.valves.stop_heartbeat()


@contextlib.contextmanager
def _reached(config: RigConfig) -> Iterator[None]:
    """An instrument failing while the session is set up: one clear line, exit 2 (nothing moved);
    a digitizer that does not answer its configured dialect is asked a plain *IDN?, and the line
    names the dialect to set (as `hopkinson probe` does)."""
    from hopkinson.drivers.errors import InstrumentError
    from hopkinson.rig.dialect_hint import dialect_fix
    from hopkinson.rig.errors import unreachable

    try:
        yield
    except InstrumentError as exc:
        is_digitizer = str(getattr(config.digitizer, "resource", "\0")) in exc.instrument
        raise unreachable(exc, dialect_fix(config) if is_digitizer else None) from None


@dataclass(frozen=True)
class SignalledShot:
    """A shot run under a SignalLatch: its outcome, and the second SAFE a late signal ran."""

    outcome: ShotOutcome
    safe_again: tuple[bool, str | None] | None = None  # (confirmed, problem) when SAFE ran again

    @property
    def safe_confirmed(self) -> bool:
        """Was the rig confirmed safe at the end (by the shot's SAFE, or the second one)?"""
        return self.safe_again[0] if self.safe_again is not None else self.outcome.safe_confirmed


def run_shot_under_signals(sequencer: Sequencer, request: ShotRequest, authorisation: FireAuthorisation,
                           latch: SignalLatch) -> SignalledShot:
    """Run one shot with every termination signal going SAFE: a signal before or during the
    shot aborts it (the abort is held, so one that came before the shot starts aborts it in
    CHECK before anything moves); one that comes once the shot was past its own SAFE (during
    ANALYSE, or after the shot) runs SAFE again, confirmed by reading back."""
    latch.on_signal(sequencer.abort)
    outcome = sequencer.run_shot(request, authorisation)
    safe_again = None
    # past the shot's own SAFE (DONE, or ABORTED by the signal only after FIRE, SAFE and STORE)
    past_safe = outcome.done or (outcome.fired and outcome.safe_confirmed and outcome.aborted_in is None)
    if latch.received is not None and past_safe:
        with contextlib.ExitStack() as stack:
            if outcome.log_path is not None:  # the second SAFE belongs in the shot's record too
                from hopkinson.rig.lock import command_line
                from hopkinson.rig.logbook import Logbook

                with contextlib.suppress(OSError):  # a log that cannot be opened never stops SAFE
                    logbook = stack.enter_context(Logbook(outcome.log_path, command=command_line(),
                                                          what=f"SAFE again after {latch.reason}"))
                    logbook.attach(sequencer.bus)
            safe_again = sequencer.make_safe()
    return SignalledShot(outcome, safe_again)
