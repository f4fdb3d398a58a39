"""Every way out goes SAFE: SIGINT, SIGTERM and SIGHUP sent in every state of a shot.

In-process, so the whole matrix is cheap: a real signal (os.kill of this process) is sent from
a subscriber when the sequencer enters the state (before the state's first action), with the
command line's own SignalLatch and `run_shot_under_signals` (what `hopkinson shot` runs).
The simulated world's own valves are read back after each case. The real processes
(`hopkinson shot`, `campaign run`, `panel`) are tested for a representative set in
test_signals_processes.py.
"""

from __future__ import annotations

import contextlib
import os
import signal
import time

import pytest

from hopkinson.rig.control import run_shot_under_signals
from hopkinson.rig.events import RigEvent, StateEntered
from hopkinson.rig.sequencer import FireAuthorisation, Sequencer
from hopkinson.rig.signals import SignalLatch
from tests.rig.conftest import quick_analysis

SIGNALS = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)
BEFORE_FIRE = ("CHECK", "EVACUATE", "CHARGE", "ARM", "FIRE")  # the shot is aborted there, never fired
AFTER_FIRE = ("CAPTURE", "SAFE", "STORE", "ANALYSE", "DONE")  # the record is kept, SAFE runs (again)


def _kill_on_entering(state: str, sig: signal.Signals, latch: list[SignalLatch]):
    """Send `sig` when the sequencer enters `state`, and let the latch's watcher see it (as a
    signal arriving while the state runs would be seen at the state's next check)."""
    sent: list[bool] = []

    def on_event(event: RigEvent) -> None:
        if isinstance(event, StateEntered) and event.state == state and not sent:
            sent.append(True)
            os.kill(os.getpid(), sig)
            deadline = time.monotonic() + 5.0
            while latch[0].received is None and time.monotonic() < deadline:
                time.sleep(0.001)

    return on_event


def test_every_signal_in_every_state_ends_safe(rig) -> None:
    fired = 0
    for sig in SIGNALS:
        for state in ("IDLE", *BEFORE_FIRE, *AFTER_FIRE):
            sequencer = Sequencer(rig.instruments, rig.config, rig.bus, analyse=quick_analysis)
            holder: list[SignalLatch] = []
            unsubscribe = rig.bus.subscribe(_kill_on_entering(state, sig, holder))
            with SignalLatch() as latch:
                holder.append(latch)
                if state == "IDLE":
                    os.kill(os.getpid(), sig)  # before the shot: held, honoured in CHECK before anything moves
                shot = run_shot_under_signals(sequencer, rig.request(pressure_bar=1.5), FireAuthorisation.pre_given(),
                                              latch)
            unsubscribe()
            case = f"{sig.name} in {state}: {shot.outcome.error or shot.outcome.analysis_error}"
            outcome = shot.outcome
            assert latch.received == sig, case
            assert shot.safe_confirmed, case
            rig.assert_safe()  # the world's own valves and gauge
            assert rig.world.coils()["pump"] is False, case
            if state in ("IDLE", *BEFORE_FIRE):
                assert outcome.final_state == "ABORTED" and outcome.exit_code == 3, case
                assert outcome.aborted_in == ("CHECK" if state == "IDLE" else state), case
                assert not outcome.fired and rig.world.shots_fired == fired, case
                assert f"aborted: interrupted ({sig.name})" in outcome.error, case
            else:  # fired already: the record is kept and SAFE ran again after the signal
                fired += 1
                assert outcome.fired and rig.world.shots_fired == fired, case
                assert outcome.shot_path is not None and outcome.shot_path.exists(), case
                assert shot.safe_again == (True, None), case
                if state != "DONE":  # the analysis was abandoned (the stored shot can be re-analysed)
                    assert outcome.analysis_error.startswith(f"analysis abandoned: interrupted ({sig.name})"), case
                    assert outcome.analysis_to_redo, case  # a resume or `hopkinson analyse` redoes it
            if state == "IDLE":
                assert [e.state for e in rig.recorder.of(StateEntered)][-3:] == ["CHECK", "SAFE", "ABORTED"]
    assert fired == len(SIGNALS) * len(AFTER_FIRE)


def test_a_signal_between_two_shots_aborts_the_next_one_before_it_moves(rig) -> None:
    """The abort is held: never lost, never needs re-sending."""
    sequencer = Sequencer(rig.instruments, rig.config, rig.bus, analyse=quick_analysis)
    assert sequencer.run_shot(rig.request(), FireAuthorisation.pre_given()).done
    sequencer.abort("operator pressed ABORT between shots")
    assert sequencer.abort_requested
    outcome = sequencer.run_shot(rig.request(), FireAuthorisation.pre_given())
    assert outcome.aborted_in == "CHECK" and "between shots" in outcome.error and not outcome.fired
    assert not sequencer.abort_requested  # used up by the shot that honoured it
    assert rig.world.coils()["pump"] is False and rig.world.shots_fired == 1
    # CHECK did not get as far as the amplifier: the abort was honoured before the first command
    assert [e.state for e in rig.recorder.of(StateEntered)][-3:] == ["CHECK", "SAFE", "ABORTED"]


@pytest.mark.parametrize("nested", [False, True])
def test_signal_latch_calls_back_from_its_watcher_and_restores_the_handlers(nested: bool) -> None:
    before = signal.getsignal(signal.SIGTERM)
    got: list[str] = []
    with SignalLatch() as outer:
        with SignalLatch() if nested else contextlib.nullcontext(outer) as latch:
            latch.on_signal(got.append)
            os.kill(os.getpid(), signal.SIGHUP)
            for _ in range(100):
                if got:
                    break
                time.sleep(0.01)
    assert got == ["interrupted (SIGHUP)"] and latch.received == signal.SIGHUP
    assert signal.getsignal(signal.SIGTERM) == before
    late: list[str] = []
    latch.on_signal(late.append)  # a callback added after the signal is called at once
    assert late == ["interrupted (SIGHUP)"]
