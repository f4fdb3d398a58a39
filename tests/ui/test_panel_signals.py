"""The panel on SIGTERM, SIGHUP and SIGINT (in-process; ui/worker.py's RigLink catches them): a
running shot is aborted, SAFE runs and is confirmed by reading back, the window closes, and the
simulated controller's own valves are safe. `hopkinson panel` as a real process gets SIGTERM in
tests/rig/test_signals_processes.py."""

from __future__ import annotations

import os
import signal
import time

from PySide6.QtCore import Qt

from hopkinson.rig.events import Reading

SHOT_TIMEOUT_MS = 60_000


def _assert_safe(panel) -> None:
    world = panel.world
    assert world.coils() == {"fire": False, "fill": False, "vent": True, "pump": False}, world.coils()
    assert world.reservoir_pressure_bar() <= panel.window.config.limits.vent_done_bar
    assert world.watchdog_state() == "off"  # the heartbeat session was ended, not lost


def test_sigterm_while_idle_vents_the_rig_and_closes_the_panel(qtbot, make_panel) -> None:
    panel = make_panel(time_scale=20.0)
    w, world = panel.window, panel.world
    assert world.watchdog_state() == "armed"  # the panel controls the rig: it feeds the watchdog
    world.set_vent_valve(False)  # left charged, as a dead PC without a watchdog would
    world.set_pressure_setpoint_bar(2.0)
    world.set_fill_valve(True)
    with qtbot.waitSignal(w.link.interrupted, timeout=10_000) as got:
        os.kill(os.getpid(), signal.SIGTERM)
    assert got.args == ["interrupted (SIGTERM)"]
    qtbot.waitUntil(lambda: not w.isVisible(), timeout=SHOT_TIMEOUT_MS)
    assert w.link.interrupted_reason == "interrupted (SIGTERM)"
    assert w.link.last_safe == (True, "rig safe: fire and fill valves closed, vent open, pump off")
    _assert_safe(panel)


def test_sighup_during_charge_aborts_the_shot_and_closes_the_panel(qtbot, make_panel) -> None:
    panel = make_panel(time_scale=5.0)  # charging 2 bar takes ~0.8 s
    w = panel.window
    w.setup.pressure.setValue(2.0)
    finished = []
    w.link.shot_finished.connect(finished.append)
    sent = []

    def on_event(event) -> None:
        if isinstance(event, Reading) and event.state == "CHARGE" and not sent:
            sent.append(time.monotonic())
            os.kill(os.getpid(), signal.SIGHUP)

    w.link.event.connect(on_event)
    qtbot.mouseClick(w.arm_button, Qt.MouseButton.LeftButton)
    # The window hides as soon as it starts closing; the shot's end reaches this test through a
    # queued signal, which a loaded machine may deliver a moment later.
    qtbot.waitUntil(lambda: not w.isVisible() and bool(finished), timeout=SHOT_TIMEOUT_MS)
    (outcome,) = finished
    assert outcome.final_state == "ABORTED" and outcome.aborted_in == "CHARGE" and not outcome.fired
    assert "interrupted (SIGHUP)" in outcome.error and outcome.safe_confirmed
    assert w.link.last_safe is not None and w.link.last_safe[0] is True
    assert panel.world.shots_fired == 0
    _assert_safe(panel)
