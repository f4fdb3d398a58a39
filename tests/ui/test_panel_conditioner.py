"""A conditioner set by hand (`[amplifier] driver = "manual"`): the shot set-up asks for what its
front panel shows, remembers it between runs, and the panel enters it into the conditioner on
the rig's I/O thread before the shot, so the shot file records it. A campaign plan of more shots
than the confirmation threshold fires only once its number is typed, as `--shots N`."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import pytest
from PySide6.QtCore import QSettings, Qt

from hopkinson.rig.config import RigConfig
from hopkinson.rig.events import StateEntered
from hopkinson.rig.shotfile import read_shot
from tests.ui.conftest import dispose, quick_config, rig_config_for_tests, save_shot
from tests.ui.test_campaign_tab import CAMPAIGN_TIMEOUT_MS, write_plan
from tests.ui.test_panel_shot import SHOT_TIMEOUT_MS

ENTERED = {"gain": 10.0, "excitation_v": 5.0, "lowpass_hz": 200_000.0, "sensitivity_v_per_m_s2": 2.5e-6,
           "identity": "Kistler 5015A SN 7"}


def manual_config() -> RigConfig:
    """The test rig with its amplifier set by hand; rig.toml's values differ from what is entered."""
    base = quick_config()  # (the analysis is aborted: fewer draws left running in its abandoned thread)
    amp = dataclasses.replace(base.amplifier, driver="manual", gain=1.0, excitation_v=0.0, lowpass_hz=0.0,
                              sensitivity_v_per_m_s2=0.0, identity="as in rig.toml")
    return dataclasses.replace(base, amplifier=amp)


def enter(setup, values: dict) -> None:
    c = setup.conditioner
    c.gain.setValue(values["gain"])
    c.excitation.setValue(values["excitation_v"])
    c.lowpass.setValue(values["lowpass_hz"] / 1e3)
    c.sensitivity.setValue(values["sensitivity_v_per_m_s2"] / 1e-6)
    c.identity.setText(values["identity"])


def test_the_conditioner_fields_start_from_rig_toml_and_are_remembered(qtbot, tmp_path: Path) -> None:
    from hopkinson.ui.shot_setup import ShotSetup

    bridge = ShotSetup(rig_config_for_tests(), tmp_path)
    assert bridge.conditioner is None and bridge.conditioner_entry() is None  # read back over its line instead
    dispose(bridge)
    first = ShotSetup(manual_config(), tmp_path)
    assert first.conditioner_entry() == {"gain": 1.0, "excitation_v": 0.0, "lowpass_hz": 0.0,
                                         "sensitivity_v_per_m_s2": None, "identity": "as in rig.toml"}
    assert first.conditioner.lowpass.text() == "off" and first.conditioner.sensitivity.text() == "not entered"
    enter(first, ENTERED)
    settings_file = str(tmp_path / "panel.ini")
    first.save(QSettings(settings_file, QSettings.Format.IniFormat))
    dispose(first)
    second = ShotSetup(manual_config(), tmp_path)
    second.load(QSettings(settings_file, QSettings.Format.IniFormat))
    entry = second.conditioner_entry()
    dispose(second)
    assert entry == {**ENTERED, "sensitivity_v_per_m_s2": pytest.approx(2.5e-6)}  # µV in the form


def test_a_shot_records_the_conditioner_values_entered_on_the_panel(qtbot, make_panel, artifacts_dir) -> None:
    panel = make_panel(config=manual_config())
    w = panel.window
    enter(w.setup, ENTERED)
    assert w.status_panel.instrument_lamps["amplifier"].level == "ok"
    save_shot(w.setup, artifacts_dir / "panel-setup-manual-conditioner.png")
    save_shot(w, artifacts_dir / "panel-manual-conditioner.png")

    def abort_the_analysis(event) -> None:  # the analysis is not what this test is about: the shot is kept
        if isinstance(event, StateEntered) and event.state == "ANALYSE":
            w.link.abort("test: analysis not needed")

    w.link.event.connect(abort_the_analysis)
    w.confirm_fire = lambda: True
    qtbot.mouseClick(w.arm_button, Qt.MouseButton.LeftButton)
    qtbot.waitUntil(w.fire_button.isEnabled, timeout=SHOT_TIMEOUT_MS)  # CHECK took the entered values
    with qtbot.waitSignal(w.link.shot_finished, timeout=SHOT_TIMEOUT_MS) as finished:
        qtbot.mouseClick(w.fire_button, Qt.MouseButton.LeftButton)
    outcome = finished.args[0]
    assert outcome.fired and outcome.shot_path is not None, outcome.error
    meta = read_shot(outcome.shot_path, load_raw=False).meta
    settings = meta.config["shot_settings"]
    assert settings["amplifier_source"] == "entered" and settings["amplifier_identity"] == ENTERED["identity"]
    for key in ("gain", "excitation_v", "lowpass_hz", "sensitivity_v_per_m_s2"):
        assert settings[f"amplifier_{key}"] == pytest.approx(ENTERED[key]), key
        assert meta.config["amplifier"][key] == pytest.approx(ENTERED[key]), key  # the configuration it ran with
    assert meta.instruments["amplifier"] == ENTERED["identity"]
    assert w.link.instruments.amplifier.settings().gain == ENTERED["gain"]
    assert ENTERED["identity"] in w.status_panel.instrument_details["amplifier"].text()


def test_a_large_plan_fires_only_once_its_number_of_shots_is_typed(qtbot, make_panel, tmp_path: Path) -> None:
    panel = make_panel()
    tab = panel.window.campaign_tab
    tab.confirm_above = 2  # the plan's 3 shots are "many" here (default rig.plan.CONFIRM_ABOVE_SHOTS)
    tab.load_plan(write_plan(tmp_path))
    runs = Path(tab.runs_dir.text())
    asked: list[str] = []
    for typed, shown in ((None, "was not confirmed; nothing was fired"), (2, "was not confirmed (2 was typed)")):
        tab.confirm_shot_count = lambda plan, typed=typed: asked.append(plan.name) or typed
        qtbot.mouseClick(tab.run_button, Qt.MouseButton.LeftButton)
        assert not tab.running and tab.run_folder is None and shown in tab.message.text(), tab.message.text()
        assert "fires 3 shots, more than 2" in tab.message.text()
    assert asked == ["ui-test", "ui-test"] and not runs.exists() and panel.world.shots_fired == 0

    tab.confirm_shot_count = lambda plan: asked.append(plan.name) or 3
    with qtbot.waitSignal(tab.ended, timeout=CAMPAIGN_TIMEOUT_MS):
        qtbot.mouseClick(tab.run_button, Qt.MouseButton.LeftButton)
        assert tab.running
        tab.abort()  # held, and honoured before anything moves
    assert len(asked) == 3 and tab.run_folder is not None and tab.run_folder.path.parent == runs
    assert tab.last_outcome.exit_code == 3 and panel.world.shots_fired == 0
