"""Shot set-up remembered between runs; missing instruments show as disconnected (never a crash),
with ARM refused; a bad set-up is refused with a clear message before anything moves."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import pytest
from PySide6.QtCore import QSettings, Qt

from tests.ui.conftest import dispose, rig_config_for_tests, unreachable_config


def test_setup_is_remembered_between_runs(qtbot, tmp_path):
    from hopkinson.ui.shot_setup import ShotSetup

    config = rig_config_for_tests()
    settings_file = str(tmp_path / "panel.ini")
    first = ShotSetup(config, tmp_path / "shots")
    first.operator.setText("A. Technician")
    first.accelerometer_model.setText("AYZ-3")
    first.accelerometer_serial.setText("SN0042")
    first.sensitivity.setValue(0.35)
    first.pressure.setValue(3.25)
    first.projectile.setCurrentIndex(0)
    first.max_order.setValue(8)
    first.dcm_ratio.setValue(12.5)
    first.dcm_damping.setValue(0.6)
    first.out_dir.setText(str(tmp_path / "elsewhere"))
    first.save(QSettings(settings_file, QSettings.Format.IniFormat))
    dispose(first)

    second = ShotSetup(config, tmp_path / "default")
    second.load(QSettings(settings_file, QSettings.Format.IniFormat))
    request = second.request(confirm_timeout_s=60.0)
    dispose(second)
    assert (request.operator, request.accelerometer_model, request.accelerometer_serial) == \
        ("A. Technician", "AYZ-3", "SN0042")
    assert request.analysis.sensitivity_v_per_m_s2 == pytest.approx(0.35e-6)
    assert request.pressure_bar == pytest.approx(3.25) and request.projectile == 1
    assert request.analysis.max_order == 8 and request.analysis.dcm_ratio == pytest.approx(12.5)
    assert request.analysis.dcm_damping == pytest.approx(0.6) and request.out_dir == tmp_path / "elsewhere"
    assert request.confirm_timeout_s == 60.0


def test_auto_dcm_ratio_means_none(qtbot, tmp_path):
    from hopkinson.ui.shot_setup import ShotSetup

    setup = ShotSetup(rig_config_for_tests(), tmp_path)
    assert setup.dcm_ratio.text() == "auto" and setup.request(1.0).analysis.dcm_ratio is None
    dispose(setup)


def test_no_instruments_show_disconnected_and_arm_is_refused(qtbot, make_panel, tmp_path):
    config = unreachable_config(tmp_path)
    # an idle ABORT keeps trying to make the rig safe for timeouts.safe_s before it gives up
    config = dataclasses.replace(config, timeouts=dataclasses.replace(config.timeouts, safe_s=2.0))
    panel = make_panel(simulate=False, config=config)
    w = panel.window
    qtbot.waitUntil(lambda: all(lamp.level == "fault" for lamp in w.status_panel.instrument_lamps.values()),
                    timeout=15_000)
    for key, lamp in w.status_panel.instrument_lamps.items():
        assert lamp.level == "fault", key
        assert "DISCONNECTED" in w.status_panel.instrument_details[key].text()
    assert not w.arm_button.isEnabled() and "not every instrument" in w.arm_button.toolTip()
    assert w.abort_button.isEnabled()
    w.arm()  # even called directly: nothing starts
    assert not w.busy and not w.link.shot_running
    messages = " ".join(text for _, text in w.log_view.messages())
    assert "valve controller 127.0.0.1" in messages and "not connected" in messages
    assert w.status_panel.pressure_value.text() == "— bar"
    # the window stays alive and answers: ABORT with nothing connected reports it cannot confirm SAFE
    with qtbot.waitSignal(w.link.safe_done, timeout=10_000) as done:
        qtbot.mouseClick(w.abort_button, Qt.MouseButton.LeftButton)
    assert done.args[0] is False and "SAFE NOT CONFIRMED" in done.args[1]
    assert "SAFE NOT CONFIRMED" in w.banner.text()


def test_one_missing_instrument_keeps_the_others_live(qtbot, make_panel, tmp_path):
    from hopkinson.rig.sim_session import sim_session
    from tests.ui.conftest import fast_sim_config

    with sim_session(rig_config_for_tests(), fast_sim_config(), ()) as session:
        config = unreachable_config(tmp_path, keep=("valve_controller", "digitizer"), base=session.config)
        panel = make_panel(simulate=False, config=config)
        w = panel.window
        lamps = w.status_panel.instrument_lamps
        qtbot.waitUntil(lambda: lamps["amplifier"].level == "fault" and lamps["valve_controller"].level == "ok"
                        and lamps["digitizer"].level == "ok", timeout=15_000)
        qtbot.waitUntil(lambda: w.status_panel.reservoir_pressure_bar is not None, timeout=5000)
        assert w.status_panel.instrument_lamps["amplifier"].level == "fault"
        assert w.status_panel.instrument_lamps["valve_controller"].level == "ok"
        assert "Hopkinson-Sim" in w.status_panel.instrument_details["digitizer"].text()
        assert w.status_panel.vacuum_value.text().endswith("mbar") and "—" not in w.status_panel.vacuum_value.text()
        assert not w.arm_button.isEnabled()
        dispose(w)  # before the simulator stops


def test_a_bad_setup_is_refused_before_anything_moves(qtbot, make_panel, tmp_path):
    panel = make_panel()
    w = panel.window
    blocker = tmp_path / "a-file"
    blocker.write_text("not a folder")
    w.setup.out_dir.setText(str(Path(blocker) / "shots"))
    w.arm()
    assert not w.busy and w.banner.isVisible() and "Not armed" in w.banner.text()
    assert "cannot create" in w.banner.text() and str(blocker) in w.banner.text()
    assert panel.world.coils()["fill"] is False and panel.world.shots_fired == 0


def test_instrument_errors_show_on_the_lamps_and_recover(qtbot, make_panel):
    """A dropped controller link and a noisy amplifier line: messages naming the instrument,
    lamps red/amber, the window alive; when the fault goes, the panel reconnects by itself."""
    panel = make_panel()
    w = panel.window
    lamps, details = w.status_panel.instrument_lamps, w.status_panel.instrument_details
    panel.faults.inject("modbus-disconnect")
    qtbot.waitUntil(lambda: lamps["valve_controller"].level == "fault", timeout=15_000)
    assert "DISCONNECTED" in details["valve_controller"].text()
    assert not w.arm_button.isEnabled()
    # The lamp and the banner's message come from separate events of the I/O thread (the links,
    # then the message): on a loaded machine the message may follow the lamp.
    qtbot.waitUntil(lambda: "valve controller" in w.banner.text(), timeout=5_000)
    assert w.banner.isVisible() and "valve controller" in w.banner.text()
    assert "cable" in w.banner.text() or "network" in w.banner.text()
    panel.faults.clear("modbus-disconnect")
    qtbot.waitUntil(lambda: lamps["valve_controller"].level == "ok", timeout=15_000)
    qtbot.waitUntil(w.arm_button.isEnabled, timeout=5000)

    panel.faults.inject("serial-noise")
    qtbot.waitUntil(lambda: lamps["amplifier"].level in ("warn", "fault"), timeout=15_000)
    # The lamp and the log line come from separate events of the I/O thread: the line may follow.
    qtbot.waitUntil(lambda: "bridge amplifier" in " ".join(text for _, text in w.log_view.messages()), timeout=5_000)
    panel.faults.clear("serial-noise")
    qtbot.waitUntil(lambda: lamps["amplifier"].level == "ok", timeout=15_000)


def test_a_second_accelerometer_is_asked_for_only_where_the_rig_records_one(qtbot, tmp_path):
    from hopkinson.rig.shot import ShotRequestError
    from hopkinson.ui.shot_setup import ShotSetup

    plain = rig_config_for_tests()
    setup = ShotSetup(plain, tmp_path)
    assert setup.accelerometer_2_model is None and setup.request(1.0).sensor_identities == {}
    dispose(setup)

    d = plain.digitizer
    config = dataclasses.replace(plain, digitizer=dataclasses.replace(
        d, channels={**d.channels, "response_2": "CH4"}, ranges_v={**d.ranges_v, "response_2": 10.0}))
    settings_file = str(tmp_path / "panel.ini")
    first = ShotSetup(config, tmp_path)
    first.accelerometer_2_model.setText("AYZ-3")
    first.accelerometer_2_serial.setText("SN0002")
    first.save(QSettings(settings_file, QSettings.Format.IniFormat))
    dispose(first)
    second = ShotSetup(config, tmp_path)  # remembered between runs, like the first accelerometer
    second.load(QSettings(settings_file, QSettings.Format.IniFormat))
    request = second.request(1.0)
    assert request.sensor_identities == {"response_2": {"model": "AYZ-3", "serial": "SN0002"}}
    request.check(config)
    second.accelerometer_2_serial.setText("")  # half entered: refused, naming what is missing
    with pytest.raises(ShotRequestError, match="response_2: the accelerometer on it needs both its model and its serial"):
        second.request(1.0).check(config)
    dispose(second)


def test_the_sine_calibration_field_reaches_the_request_and_is_remembered(qtbot, tmp_path):
    """The shot set-up's sine calibration: empty is none; a file is the request's (fitted with
    each shot, analysis.sine_joint) and remembered between runs."""
    from hopkinson.ui.shot_setup import ShotSetup

    config = rig_config_for_tests()
    settings_file = str(tmp_path / "panel.ini")
    first = ShotSetup(config, tmp_path)
    assert first.request(1.0).analysis.sine_calibration is None
    first.sine_calibration.setText(f"  {tmp_path / 'sine.csv'}  ")
    assert first.request(1.0).analysis.sine_calibration == str(tmp_path / "sine.csv")
    first.save(QSettings(settings_file, QSettings.Format.IniFormat))
    dispose(first)
    second = ShotSetup(config, tmp_path)
    second.load(QSettings(settings_file, QSettings.Format.IniFormat))
    assert second.request(1.0).analysis.sine_calibration == str(tmp_path / "sine.csv")
    dispose(second)


def test_the_planner_sets_projectile_and_pressure_for_a_target_peak(qtbot, tmp_path, artifacts_dir):
    """Issue 19 item 3 in the panel: a target in g and the sensor's f_n give each projectile's
    pressure from the bar model; "Use" sets the form; the request then fires the pressure that the
    rig's physics says reaches the target. A target beyond the rig's maximum is said, and "Use" is off."""
    from hopkinson.analysis.bar import predict_shot
    from hopkinson.ui.shot_setup import ShotSetup
    from tests.ui.conftest import save_shot

    config = rig_config_for_tests()
    setup = ShotSetup(config, tmp_path)
    qtbot.addWidget(setup)
    planner = setup.planner
    planner.sensor_fn_khz.setValue(27.0)
    planner.target_g.setValue(50_000)
    assert planner.use_button.isEnabled() and "load No. 3" in planner.result.text()
    qtbot.mouseClick(planner.use_button, Qt.MouseButton.LeftButton)
    request = setup.request(confirm_timeout_s=1.0)
    assert request.projectile == 3
    # the pressure the form now holds gives 50 000 g through the rig's physics (to the form's 0.01 bar)
    fired = predict_shot(config.bar.rig(), 3, pressure_bar=request.pressure_bar)
    assert fired.peak_m_s2 == pytest.approx(50_000 * 9.80665, rel=0.01)
    # No. 3's δ ≤ 1.06/27 kHz = 39.3 µs: the paper's rule holds for it and is shown
    assert "<td>yes</td>" in planner.result.text()
    setup.resize(520, setup.sizeHint().height())
    save_shot(setup, artifacts_dir / "panel-setup-planner.png")
    # beyond the rig: nothing is set, the reason is shown
    before = setup.request(confirm_timeout_s=1.0).pressure_bar
    planner.target_g.setValue(400_000)
    assert not planner.use_button.isEnabled()
    assert "no projectile reaches the target" in planner.result.text() and "maximum" in planner.result.text()
    qtbot.mouseClick(planner.use_button, Qt.MouseButton.LeftButton)
    assert setup.request(confirm_timeout_s=1.0).pressure_bar == before
    # the planner's fields are remembered with the rest of the form
    settings_file = str(tmp_path / "panel.ini")
    setup.save(QSettings(settings_file, QSettings.Format.IniFormat))
    again = ShotSetup(config, tmp_path)
    qtbot.addWidget(again)
    again.load(QSettings(settings_file, QSettings.Format.IniFormat))
    assert again.planner.target_g.value() == 400_000 and again.planner.sensor_fn_khz.value() == 27.0


def test_the_planner_never_sets_a_projectile_the_rig_cannot_load(qtbot, tmp_path):
    """A rig whose [bar] describes a No. 5 (the loader takes Nos. 1–3): the plan may choose it,
    but "Use" stays off and says why; the form keeps its projectile and pressure."""
    from hopkinson.rig.config import BarConfig, BarProjectileConfig, BarSegmentConfig
    from hopkinson.ui.shot_setup import ShotSetup

    five = BarProjectileConfig(5, (BarSegmentConfig("C45", 0.05, 0.016),), contact_stiffness_n_m=1e7)
    config = dataclasses.replace(rig_config_for_tests(), bar=BarConfig(projectiles=(five,)))
    setup = ShotSetup(config, tmp_path)
    qtbot.addWidget(setup)
    before = setup.request(confirm_timeout_s=1.0)
    setup.planner.target_g.setValue(10_000)
    assert setup.planner.plan is not None and setup.planner.plan.chosen == 5
    assert not setup.planner.use_button.isEnabled() and "cannot be loaded" in setup.planner.use_button.text()
    qtbot.mouseClick(setup.planner.use_button, Qt.MouseButton.LeftButton)
    after = setup.request(confirm_timeout_s=1.0)
    assert (after.projectile, after.pressure_bar) == (before.projectile, before.pressure_bar)
