"""FIRE only when armed with every interlock holding; ABORT always reaches the safe state —
through the real widgets, against the simulated rig with its faults."""

from __future__ import annotations

import pytest
from PySide6.QtCore import QObject, Qt, Slot

from hopkinson.rig.events import Reading
from hopkinson.rig.interlocks import INTERLOCKS
from hopkinson.rig.sequencer import FireAuthorisation
from tests.ui.conftest import unreachable_config

SHOT_TIMEOUT_MS = 60_000


def assert_rig_safe(world, vent_done_bar: float) -> None:
    """The world's own valves (not what the panel believes): fire and fill shut, vent open."""
    coils = world.coils()
    assert coils["fire"] is False and coils["fill"] is False and coils["vent"] is True, coils
    assert world.reservoir_pressure_bar() <= vent_done_bar


class FireWatch(QObject):
    """Records whether the FIRE button was ever enabled (checked at every rig event), while in
    its `with` block. A QObject child of the window, in the GUI thread: the rig's events reach
    it queued from the sequencer's thread, and a call still queued when the block ends must
    find it alive. A plain Python object's bound method (PySide holds its instance weakly) was
    called from such a queued event after the test had dropped the object: an AttributeError
    in the slot, then a segmentation fault of the test worker (stop 34 disconnected it on exit,
    which did not remove the calls already queued; it crashed again in 1 of 4 full runs)."""

    def __init__(self, window) -> None:
        super().__init__(window)  # lives and dies with the window
        self.window = window
        self.ever_enabled = False

    def __enter__(self) -> FireWatch:
        self.window.link.event.connect(self._check)
        return self

    def __exit__(self, *_exc) -> None:
        self.window.link.event.disconnect(self._check)

    @Slot(object)
    def _check(self, _event) -> None:
        self.ever_enabled |= self.window.fire_button.isEnabled()


def _reading(interlocks: dict) -> Reading:
    return Reading(state="ARM", message="readings", reservoir_pressure_bar=1.0, fixture_vacuum_mbar=50.0,
                   interlocks=interlocks)


def test_fire_rule_needs_armed_waiting_and_every_interlock(make_panel, tmp_path):
    """The rule itself, on synthetic readings (no timing involved)."""
    w = make_panel(simulate=False, connect=False, config=unreachable_config(tmp_path)).window
    all_ok = dict.fromkeys(INTERLOCKS, True)
    w.busy, w.awaiting_confirmation, w.authorisation = True, True, FireAuthorisation()
    w.state_bar.set_state("ARM")
    w.last_reading = _reading(all_ok)
    assert w.fire_allowed()
    for name in INTERLOCKS:
        w.last_reading = _reading({**all_ok, name: False})
        assert not w.fire_allowed(), name
    idle = {k: v for k, v in all_ok.items() if k != "digitizer"}  # an idle reading never judges the digitizer
    w.last_reading = _reading(idle)
    assert not w.fire_allowed()
    w.last_reading = _reading(all_ok)
    w.awaiting_confirmation = False
    assert not w.fire_allowed()
    w.awaiting_confirmation = True
    w.authorisation.give()
    assert not w.fire_allowed()  # already fired


def test_door_open_fire_never_enabled_shot_aborted_in_check(qtbot, make_panel):
    panel = make_panel(faults=("door-open",))
    w = panel.window
    qtbot.waitUntil(lambda: w.status_panel.interlock_lamps["door"].level == "fault", timeout=5000)
    assert "door/guard open" in w.status_panel.interlock_lamps["door"].toolTip()
    w.confirm_fire = lambda: pytest.fail("FIRE must not be offered with the door open")
    with FireWatch(w) as watch, qtbot.waitSignal(w.link.shot_finished, timeout=SHOT_TIMEOUT_MS) as finished:
        qtbot.mouseClick(w.arm_button, Qt.MouseButton.LeftButton)
    outcome = finished.args[0]
    assert outcome.final_state == "ABORTED" and outcome.aborted_in == "CHECK" and not outcome.fired
    assert not watch.ever_enabled and not w.fire_button.isEnabled()
    assert panel.world.shots_fired == 0
    assert w.banner.isVisible() and "door/guard open" in w.banner.text() and "Close the door" in w.banner.text()
    assert w.state_bar.state == "ABORTED"
    assert_rig_safe(panel.world, w.config.limits.vent_done_bar)


def test_interlock_lost_while_armed_disables_fire_and_aborts(qtbot, make_panel):
    panel = make_panel()
    w = panel.window
    w.confirm_fire = lambda: True
    qtbot.mouseClick(w.arm_button, Qt.MouseButton.LeftButton)
    qtbot.waitUntil(w.fire_button.isEnabled, timeout=SHOT_TIMEOUT_MS)
    with qtbot.waitSignal(w.link.shot_finished, timeout=SHOT_TIMEOUT_MS) as finished:
        panel.faults.inject("estop")  # the e-stop trips while the rig waits for FIRE
        qtbot.waitUntil(lambda: not w.fire_button.isEnabled(), timeout=5000)
        w.fire()  # a click that slips through is refused by the rule, not by luck
    outcome = finished.args[0]
    assert outcome.final_state == "ABORTED" and outcome.aborted_in == "ARM" and not outcome.fired
    assert panel.world.shots_fired == 0
    assert "e-stop" in w.banner.text()
    assert w.status_panel.interlock_lamps["estop"].level == "fault"
    assert_rig_safe(panel.world, w.config.limits.vent_done_bar)


def test_abort_mid_charge_reaches_the_safe_state(qtbot, make_panel):
    panel = make_panel(time_scale=10.0)  # slow enough to press ABORT while charging
    w = panel.window
    w.setup.pressure.setValue(4.0)
    qtbot.mouseClick(w.arm_button, Qt.MouseButton.LeftButton)
    qtbot.waitUntil(lambda: w.state_bar.state == "CHARGE", timeout=SHOT_TIMEOUT_MS)
    qtbot.waitUntil(lambda: panel.world.reservoir_pressure_bar() > 0.3, timeout=10_000)
    assert panel.world.coils()["fill"] is True  # really charging
    assert w.abort_button.isEnabled()
    with qtbot.waitSignal(w.link.shot_finished, timeout=SHOT_TIMEOUT_MS) as finished:
        qtbot.mouseClick(w.abort_button, Qt.MouseButton.LeftButton)
    outcome = finished.args[0]
    assert outcome.final_state == "ABORTED" and outcome.aborted_in == "CHARGE" and outcome.safe_confirmed
    assert not outcome.fired and panel.world.shots_fired == 0
    assert_rig_safe(panel.world, w.config.limits.vent_done_bar)
    assert w.state_bar.state == "ABORTED" and "#d0312d" in w.state_bar.chips["CHARGE"].styleSheet()
    assert "aborted" in w.banner.text().lower() and w.banner_level == "error"
    assert w.arm_button.isEnabled() and not w.fire_button.isEnabled()


def test_abort_when_idle_commands_the_valves_safe(qtbot, make_panel):
    panel = make_panel()
    w = panel.window
    world = panel.world
    world.set_vent_valve(False)  # a rig left in an odd state (e.g. after a FAULT)
    world.set_fill_valve(True)
    with qtbot.waitSignal(w.link.safe_done, timeout=10_000) as done:
        qtbot.mouseClick(w.abort_button, Qt.MouseButton.LeftButton)
    assert done.args[0] is True
    coils = world.coils()
    assert coils["fire"] is False and coils["fill"] is False and coils["vent"] is True and coils["pump"] is False
    assert w.banner_level == "ok"
