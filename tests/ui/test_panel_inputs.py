"""The panel's fields and message line (issue 42): a number field states its unit and refuses a
value outside its plausible range naming the unit; the mouse wheel changes a field only when it
has the focus; the message line keeps one height whatever it says, in its level's colours."""

from __future__ import annotations

import pytest
from PySide6.QtCore import QCoreApplication, QPoint, QPointF, Qt
from PySide6.QtGui import QWheelEvent
from PySide6.QtWidgets import QScrollArea, QVBoxLayout, QWidget

from tests.ui.conftest import dispose


def wheel(widget, steps: int) -> QWheelEvent:
    centre = QPointF(widget.rect().center())
    event = QWheelEvent(centre, QPointF(widget.mapToGlobal(centre.toPoint())), QPoint(0, 0), QPoint(0, 120 * steps),
                        Qt.MouseButton.NoButton, Qt.KeyboardModifier.NoModifier, Qt.ScrollPhase.NoScrollPhase, False)
    QCoreApplication.sendEvent(widget, event)
    return event


def test_a_value_out_of_range_is_refused_naming_its_unit(qtbot):
    from hopkinson.ui.inputs import UnitSpinBox

    spin = UnitSpinBox("Sensor f_n", "kHz", (1.0, 2000.0), 27.0, decimals=1, special="not named")
    qtbot.addWidget(spin)
    accepted: list[float] = []
    spin.value_accepted.connect(accepted.append)
    assert spin.text() == "27.0 kHz" and "plausible: 1 … 2000 kHz" in spin.toolTip()
    with qtbot.waitSignal(spin.refused) as refused:
        qtbot.keyClicks(spin.lineEdit(), "\b" * 10 + "27000")  # typed: no keystroke is swallowed silently
        qtbot.keyClick(spin.lineEdit(), Qt.Key.Key_Return)
    assert refused.args[0] == "Sensor f_n: 27000 kHz is outside 1 … 2000 kHz; kept 27 kHz"
    assert spin.value() == 27.0 and accepted == []  # what uses the value never saw 27000
    spin.setValue(30.5)
    spin.setValue(0.0)  # the "not named" choice
    assert accepted == [30.5, 0.0] and spin.text() == "not named"
    with qtbot.waitSignal(spin.refused) as refused:
        spin.setValue(0.5)
    assert refused.args[0] == "Sensor f_n: 0.5 kHz is outside 1 … 2000 kHz; kept not named"


def test_the_wheel_changes_a_field_only_with_the_focus(qtbot):
    from hopkinson.ui.inputs import ComboBox, UnitSpinBox

    form = QWidget()
    layout = QVBoxLayout(form)
    spin = UnitSpinBox("Pressure", "bar", (0.2, 8.0), 2.0, step=0.1)
    combo = ComboBox()
    combo.addItems(["No. 1", "No. 2", "No. 3"])
    combo.setCurrentIndex(2)
    for widget in (spin, combo):
        layout.addWidget(widget)
    scroll = QScrollArea()
    scroll.setWidget(form)
    qtbot.addWidget(scroll)
    scroll.show()
    qtbot.waitExposed(scroll)
    for widget in (spin, combo):
        event = wheel(widget, -2)
        assert not event.isAccepted()  # passed on: the form scrolls
    assert spin.value() == 2.0 and combo.currentIndex() == 2
    spin.setFocus()
    qtbot.waitUntil(spin.hasFocus, timeout=2000)
    wheel(spin, -2)
    assert spin.value() == pytest.approx(1.8)


def test_the_message_line_keeps_its_height_and_colours(qtbot):
    from hopkinson.ui.widgets import TEXT_COLOURS, Banner

    banner = Banner()
    qtbot.addWidget(banner)
    banner.resize(900, 40)
    banner.show()
    heights = set()
    for level, text in (("idle", ""), ("info", "ARMED — press FIRE."), ("ok", "Shot done."),
                        ("warning", "Not taken: 27000 kHz. " * 3), ("error", "The valve controller does not answer. " * 30)):
        banner.show_message(level, text)
        QCoreApplication.processEvents()
        heights.add(banner.height())
        assert banner.full_text == text
        colour = {"error": "#8c1d18", "warning": "#7a4f01", "ok": "#0d652d", "info": "#174ea6", "idle": "#3c4043"}
        assert f"color: {colour[level]}" in banner.styleSheet()
    assert len(heights) == 1  # nothing under it moves
    assert banner.text().endswith("…") and banner.toolTip() == banner.full_text  # cut, and whole in the tooltip
    assert TEXT_COLOURS["error"] != TEXT_COLOURS["ok"]
    with pytest.raises(ValueError, match="banner level"):
        banner.show_message("green", "x")


def test_the_panel_remembers_its_window_and_tab_and_has_menus(qtbot, make_panel, tmp_path):
    from PySide6.QtCore import QSettings

    from hopkinson.ui.main_window import MainWindow
    from hopkinson.ui.menus import about_text
    from tests.ui.conftest import unreachable_config

    config = unreachable_config(tmp_path)
    panel = make_panel(simulate=False, connect=False, config=config)
    w = panel.window
    assert [a.text() for a in w.menuBar().actions()] == ["&File", "&Rig", "&Help"]
    assert w.actions["arm"].shortcut().toString() == "F5" and w.actions["abort"].shortcut().toString() == "Esc"
    assert w.actions["fire"].shortcut().toString() == "Ctrl+Shift+F" and not w.actions["fire"].isEnabled()
    assert about_text().startswith("hopkinson ") and "unknown" not in about_text().split("\n")[0]
    w.tabs.setCurrentWidget(w.campaign_tab)
    w.resize(1400, 900)
    QCoreApplication.processEvents()
    geometry = bytes(w.saveGeometry())
    dispose(w)  # closing saves the window's geometry (size, place, maximised) and its tab
    settings = QSettings(str(panel.settings_path), QSettings.Format.IniFormat)
    assert bytes(settings.value("window/geometry")) == geometry
    again = MainWindow(config, settings=settings, out_dir=tmp_path / "shots", runs_dir=tmp_path / "runs")
    try:  # (the offscreen screen is 800 × 800: Qt fits the restored size to it, so only the call is checked)
        assert again.restored_geometry and again.tabs.currentWidget() is again.campaign_tab
    finally:
        dispose(again)


def test_shortcuts_arm_and_abort_and_fire_is_guarded(qtbot, make_panel):
    """F5 arms, Esc aborts, Ctrl+Shift+F fires only when FIRE is lit (and asks, as the button)."""
    panel = make_panel()
    w = panel.window
    asked: list[bool] = []
    w.confirm_fire = lambda: asked.append(True) or False
    w.actions["fire"].trigger()  # not armed: nothing, not even the question
    assert asked == [] and panel.world.shots_fired == 0
    w.actions["arm"].trigger()
    qtbot.waitUntil(w.fire_button.isEnabled, timeout=60_000)
    w.actions["fire"].trigger()  # armed: the same confirmation as the button; answered No
    assert asked == [True] and w.state_bar.state == "ARM"
    with qtbot.waitSignal(w.link.shot_finished, timeout=60_000) as finished:
        w.actions["abort"].trigger()
    assert finished.args[0].final_state == "ABORTED" and panel.world.shots_fired == 0


def test_the_set_up_prediction_is_the_planners_inverse_and_names_its_problems():
    """At the pressure the planner gives for a target (analysis.bar.plan_shot, the inverse), the
    set-up's prediction reaches that target; 7 bar instead is over it and over a 100 000 g range."""
    from hopkinson.analysis.bar import plan_shot
    from hopkinson.ui.setup_check import fire_question, predict_setup
    from tests.ui.conftest import rig_config_for_tests

    rig = rig_config_for_tests().bar.rig()
    target = 50_000 * 9.80665
    plan = plan_shot(rig, target)
    option = next(o for o in plan.options if o.projectile == 3)
    on_plan = predict_setup(rig, 3, option.pressure_bar, target, 100_000 * 9.80665)
    assert on_plan.peak_m_s2 == pytest.approx(target, rel=0.01) and on_plan.problems() == []
    assert on_plan.width_10_s == pytest.approx(option.width_10_s, rel=0.02)
    assert on_plan.band_hz == pytest.approx(option.supported_band_hz, rel=0.02)
    over = predict_setup(rig, 3, 7.0, target, 100_000 * 9.80665)
    problems = over.problems()
    assert len(problems) == 2 and "above the target 50\u00a0000 g (tolerance ±10 %)" in problems[0]
    assert "exceeds the sensor's range 100\u00a0000 g" in problems[1]
    question = fire_question("Reservoir 7 bar", over)
    assert f"Predicted peak {over.peak_text()}" in question and "⚠ the predicted peak" in question
