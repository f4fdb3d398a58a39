"""The panel fires a shot through its real widgets on the simulated rig: ARM, FIRE with the
confirmation, the plots holding the shot's data and the FBSD labels the analysed values; the
window stays responsive; screenshots of every tab go to test-artifacts/."""

from __future__ import annotations

import json
import math
import threading

import numpy as np
import pytest
from PySide6.QtCore import Qt, QTimer

from hopkinson.rig.shotfile import read_shot
from tests.sim_truth import true_fbsd_hz
from tests.ui.conftest import quick_config, save_shot, unreachable_config

SHOT_TIMEOUT_MS = 60_000


def expected_khz(value_hz: float, results: dict, level: str) -> str:
    """The strip's FBSD text, computed here: "5.91 kHz", or value ± U to U's two significant
    digits when the results carry the uncertainty (issue 10's JSON contract)."""
    u = ((results.get("uncertainty") or {}).get("fbsd_hz") or {}).get(level)
    if not u:
        return f"{value_hz / 1e3:.2f} kHz"
    big = (u["interval"][1] - u["interval"][0]) / 2 / 1e3
    decimals = max(0, 1 - math.floor(math.log10(big)))
    return f"{value_hz / 1e3:.{decimals}f} ± {big:.{decimals}f} kHz"


def fire_one_shot(qtbot, panel, confirm: bool = True):
    """Press ARM, wait for FIRE to light, press FIRE (confirmation answered), wait for the end."""
    w = panel.window
    asked: list[bool] = []

    def confirm_fire() -> bool:
        asked.append(True)
        return confirm

    w.confirm_fire = confirm_fire
    assert w.arm_button.isEnabled() and not w.fire_button.isEnabled()
    qtbot.mouseClick(w.arm_button, Qt.MouseButton.LeftButton)
    qtbot.waitUntil(w.fire_button.isEnabled, timeout=SHOT_TIMEOUT_MS)
    assert w.state_bar.state == "ARM" and w.awaiting_confirmation
    assert not w.arm_button.isEnabled()
    with qtbot.waitSignal(w.link.shot_finished, timeout=SHOT_TIMEOUT_MS) as finished:
        qtbot.mouseClick(w.fire_button, Qt.MouseButton.LeftButton)
    assert asked == [True]
    return finished.args[0]


def test_arm_fire_shows_the_shot_and_its_analysis(qtbot, make_panel, artifacts_dir, tmp_path):
    panel = make_panel(config=quick_config())  # what the panel shows of the uncertainty, not the uncertainty
    w = panel.window
    save_shot(w, artifacts_dir / "panel-idle.png")

    # the GUI thread must keep running its event loop while the shot is captured and analysed
    ticks: list[str] = []
    heartbeat = QTimer()
    heartbeat.timeout.connect(lambda: ticks.append(w.state_bar.state))
    heartbeat.start(10)
    threads: set[str] = set()
    w.link.bus.subscribe(lambda e: threads.add(threading.current_thread().name))
    # what the sensor's data sheet states, in per cent (the rig config's 5 % and 3 % until changed)
    stated = tuple(w.setup.stated.spins.values())  # transverse, asymmetry
    assert [s.value() for s in stated] == [100 * w.config.uncertainty.transverse_sensitivity_rel,
                                           100 * w.config.uncertainty.asymmetry_bound_rel] == [5.0, 3.0]
    stated[0].setValue(1.0)
    stated[1].setValue(6.0)

    with qtbot.waitSignal(w.shot_view_shown, timeout=SHOT_TIMEOUT_MS) as shown:
        outcome = fire_one_shot(qtbot, panel)
    heartbeat.stop()
    assert outcome.done and outcome.analysis_error is None, outcome.error or outcome.analysis_error
    assert panel.world.shots_fired == 1
    assert w.state_bar.state == "DONE" and w.arm_button.isEnabled() and not w.fire_button.isEnabled()
    assert threading.main_thread().name not in threads  # every rig event came from a worker thread
    assert {"CAPTURE", "ANALYSE"} <= set(ticks)  # the GUI ticked while capturing and analysing

    # the plots hold this shot's data, read back independently from its file
    view = shown.args[0]
    shot = read_shot(outcome.shot_path)
    # the stated values reached the analysis and the file: the transverse row is S_t·r_T/√3 (a
    # rectangle of half-width S_t·r_T) of the DC gain, with the rig's r_T
    params, settings = shot.results["params"], shot.meta.config["shot_settings"]
    assert (params["transverse_sensitivity_rel"], params["asymmetry_bound_rel"]) == (0.01, 0.06)
    assert (settings["transverse_sensitivity_rel"], settings["asymmetry_bound_rel"]) == (0.01, 0.06)
    (row,) = [b for b in shot.results["uncertainty"]["budget"] if b["source"].startswith("transverse sensitivity")]
    motion = w.config.uncertainty.transverse_motion_rel
    assert row["u_rel_by_figure"]["dc_gain"] == pytest.approx(0.01 * motion / math.sqrt(3), rel=1e-9)
    plots = w.plots
    x, y = plots.pm_curve.getOriginalDataset()
    assert np.array_equal(y, shot.raw.volts("doppler")) and np.allclose(x, shot.raw.time_s)
    x, y = plots.reference_curve.getOriginalDataset()
    assert np.allclose(y * 1e3, shot.record.reference) and x.size == shot.record.n_samples
    x, y = plots.response_curve.getOriginalDataset()
    assert np.allclose(y * 1e3, shot.record.response)
    orders, losses = plots.loss_curve.getOriginalDataset()
    ident = shot.results["identification"]
    assert list(orders) == [i + 1 for i, v in enumerate(ident["loss_by_order"]) if v is not None and v > 0]
    assert plots.order_line.value() == ident["order"] == view.order
    px, py = plots.pole_scatter.getData()
    poles = np.array([complex(*p) for p in shot.results["model"]["poles"]])
    assert sorted(px) == pytest.approx(sorted(poles.real)) and sorted(py) == pytest.approx(sorted(poles.imag))

    # FBSD: labels and marker lines show the analysed values; those match the simulated truth
    fbsd = shot.results["fbsd_hz"]
    comp = shot.results["dcm"]["compensated_fbsd_hz"]
    strip = plots.strip.values
    for key in ("5", "10"):  # value ± U (two significant digits of U) once the shot carries its uncertainty
        assert strip[f"fbsd_{key}"].text() == expected_khz(fbsd[key], shot.results, key)
    assert strip["comp_5"].text() == f"{comp['5'] / 1e3:.2f} kHz"
    for key in ("5", "10"):
        line = plots.fbsd_lines[key]
        assert line.isVisible() and line.value() == pytest.approx(math.log10(fbsd[key] / 1e3))
        assert f"{fbsd[key] / 1e3:.1f} kHz" in line.label.toPlainText()
    truth = shot.meta.simulated_truth
    assert fbsd["5"] == pytest.approx(true_fbsd_hz(truth, 0.05), rel=0.05)
    assert fbsd["10"] == pytest.approx(true_fbsd_hz(truth, 0.10), rel=0.05)

    # the DCM tab took the shot's model and design
    dcm = w.dcm_tab
    assert dcm.model is not None and dcm.ratio.value() == pytest.approx(shot.results["dcm"]["design"]["ratio"], rel=1e-3)
    assert dcm.compensated_fbsd["5"].text() == f"{comp['5'] / 1e3:.2f} kHz"

    # the set-up is remembered, the log tells the story
    kinds = [k for k, _ in w.log_view.messages()]
    assert "result" in kinds and "state" in kinds
    save_shot(w, artifacts_dir / "panel-shot.png")
    w.tabs.setCurrentWidget(w.dcm_tab)
    save_shot(w, artifacts_dir / "panel-dcm.png")
    w.tabs.setCurrentWidget(w.log_tab)
    save_shot(w, artifacts_dir / "panel-log.png")
    w.tabs.setCurrentWidget(w.campaign_tab)
    save_shot(w, artifacts_dir / "panel-campaign-idle.png")

    # the Log tab can be saved: JSON lines, one object per row, oldest first, with full UTC times
    w.log_tab.save(tmp_path / "panel.log.jsonl")
    rows = [json.loads(line) for line in (tmp_path / "panel.log.jsonl").read_text().splitlines()]
    assert [(r["kind"], r["message"]) for r in rows] == w.log_view.messages()
    assert all(r["utc"].endswith("Z") and len(r["utc"]) >= 20 for r in rows)
    assert "Log saved to" in w.log_tab.message.text()
    w.log_tab.save(tmp_path / "panel.log.txt")
    text_rows = (tmp_path / "panel.log.txt").read_text().splitlines()
    assert text_rows[0] == "utc\tstate\tkind\tmessage" and len(text_rows) == len(rows) + 1


def test_fire_not_confirmed_keeps_the_rig_armed_then_abort_stands_down(qtbot, make_panel):
    panel = make_panel()
    w = panel.window
    w.confirm_fire = lambda: False
    qtbot.mouseClick(w.arm_button, Qt.MouseButton.LeftButton)
    qtbot.waitUntil(w.fire_button.isEnabled, timeout=SHOT_TIMEOUT_MS)
    qtbot.mouseClick(w.fire_button, Qt.MouseButton.LeftButton)  # the operator answers No
    assert w.fire_button.isEnabled() and w.state_bar.state == "ARM" and not w.authorisation.given
    with qtbot.waitSignal(w.link.shot_finished, timeout=SHOT_TIMEOUT_MS) as finished:
        qtbot.mouseClick(w.abort_button, Qt.MouseButton.LeftButton)
    outcome = finished.args[0]
    assert outcome.final_state == "ABORTED" and outcome.aborted_in == "ARM" and not outcome.fired
    assert panel.world.shots_fired == 0
    coils = panel.world.coils()
    assert coils["fire"] is False and coils["fill"] is False and coils["vent"] is True


def test_a_shot_whose_analysis_failed_still_shows_its_raw_channels(qtbot, make_panel, tmp_path):
    from hopkinson.rig.shotfile import RawChannel, RawShot, ShotMeta
    from hopkinson.rig.shotfile_writer import add_analysis, write_raw_shot

    n = 5000
    t = np.arange(n)
    raw = RawShot({"doppler": RawChannel((1000 * np.sin(t / 7)).astype(np.int16), 1e-4, 0.0),
                   "response": RawChannel((t % 300).astype(np.int16), 1e-3, -0.1)}, 1e-8, 500)
    path = write_raw_shot(tmp_path / "failed.h5", raw, ShotMeta("t", "ACC", "1", 2.0, 3))
    add_analysis(path, {}, error="analysis failed: no pulse found in the reference")
    w = make_panel(simulate=False, connect=False, config=unreachable_config(tmp_path)).window
    with qtbot.waitSignal(w.shot_view_shown, timeout=20_000):
        w.load_shot(path)
    plots = w.plots
    x, y = plots.pm_curve.getOriginalDataset()
    assert np.allclose(y, raw.volts("doppler")) and np.allclose(x, raw.time_s)
    _, y = plots.response_curve.getOriginalDataset()
    assert np.allclose(y, raw.volts("response"))
    assert "no pulse found" in plots.accel_note.toPlainText()
    assert plots.strip.values["fbsd_5"].text() == "—" and w.dcm_tab.model is None


def test_export_report_of_the_shot_shown(qtbot, make_panel, tmp_path):
    panel = make_panel(config=quick_config())
    w = panel.window
    with qtbot.waitSignal(w.shot_view_shown, timeout=SHOT_TIMEOUT_MS):
        fire_one_shot(qtbot, panel)
    target = tmp_path / "report.html"
    w.export_report(target)
    qtbot.waitUntil(lambda: w.banner_level in ("ok", "error") and "Report" in w.banner.text(), timeout=60_000)
    assert w.banner_level == "ok", w.banner.text()
    html = target.read_text(encoding="utf-8")
    shot = read_shot(w.last_view.path, load_raw=False)
    assert w.last_view.path.stem in html  # the report of this shot, with its analysed FBSD
    fbsd5 = shot.results["fbsd_hz"]["5"]
    u5 = ((shot.results.get("uncertainty") or {}).get("fbsd_hz") or {}).get("5")
    assert (expected_khz(fbsd5, shot.results, "5") if u5 else f"{fbsd5 / 1e3:.4g} kHz") in html


def test_the_shot_tab_shows_the_uncertainty_and_the_dcm_check(qtbot, make_panel, tmp_path, artifacts_dir):
    """A shot whose results carry the uncertainty and the DCM's check (the JSON contracts of
    issues 10 and 11): the strip shows value ± U and a DCM not recommended with its reason."""
    from hopkinson.analysis.shot_analysis import AnalysisOptions, analyse_record
    from hopkinson.rig.shotfile import RawChannel, RawShot, ShotMeta
    from hopkinson.rig.shotfile_writer import add_analysis, write_raw_shot
    from tests.reports.contract import contract_results
    from tests.reports.simulated_shots import SENSOR_A, simulated_record

    record = simulated_record(SENSOR_A, 30_000, 1)
    results = contract_results(analyse_record(record, AnalysisOptions(max_order=6, uncertainty=False)),
                               recommended=False)  # (contract_results gives it the contract's uncertainty)
    n = record.n_samples
    codes = (1000 * np.sin(np.arange(n) / 7)).astype(np.int16)
    path = write_raw_shot(tmp_path / "u.h5", RawShot({"doppler": RawChannel(codes, 1e-4, 0.0),
                                                      "response": RawChannel(codes, 1e-3, 0.0)}, 1e-6, 200),
                          ShotMeta("t", "SIM-ACC", "U1", 2.0, 3))
    add_analysis(path, results, record=record)
    w = make_panel(simulate=False, connect=False, config=unreachable_config(tmp_path)).window
    with qtbot.waitSignal(w.shot_view_shown, timeout=20_000):
        w.load_shot(path)
    strip = w.plots.strip
    u = results["uncertainty"]["main_mode"]["natural_frequency_hz"]
    big = 1.96 * u["u"] / 1e3
    decimals = max(0, 1 - math.floor(math.log10(big)))
    assert strip.values["resonance"].text() == f"{u['value'] / 1e3:.{decimals}f} ± {big:.{decimals}f} kHz"
    assert strip.values["fbsd_5"].text() == expected_khz(results["fbsd_hz"]["5"], results, "5")
    assert strip.verdict.text().startswith("DCM NOT RECOMMENDED: the compensated RMS error (6.1 %)")
    assert strip.values["check_rms"].text() == "4.95 % → 6.1 %"
    save_shot(w, artifacts_dir / "panel-shot-uncertainty.png")
    w.tabs.setCurrentWidget(w.dcm_tab)
    # the DCM tab, where the DCM is exported, says the shot's DCM is not recommended (it said nothing)
    assert w.dcm_tab.verdict.isVisible()
    assert w.dcm_tab.verdict.text().startswith("The shot's DCM is NOT RECOMMENDED: the compensated RMS error (6.1 %)")
    save_shot(w, artifacts_dir / "panel-dcm-uncertainty.png")

