"""The Campaign tab runs a plan through rig.campaign on the simulated rig: run, pause, resume,
abort, the table of shots with their results, and the authorisation rule."""

from __future__ import annotations

from pathlib import Path

from PySide6.QtCore import Qt

from hopkinson.analysis.key_figures import KeyFigures
from hopkinson.analysis.linearity import fit_linearity
from hopkinson.rig.events import CampaignShotStarted, Reading
from hopkinson.rig.journal import Journal
from hopkinson.rig.shot_verdict import judge
from hopkinson.rig.shotfile import read_shot
from hopkinson.ui.campaign_table import COL
from tests.ui.conftest import save_shot
from tests.ui.test_panel_shot import expected_khz

CAMPAIGN_TIMEOUT_MS = 120_000
PLAN = """
name = "ui-test"
operator = "panel test"
authorise_firing = {authorise}

[accelerometer]
model = "SIM-ACC"
serial = "SIM0001"

[defaults]
projectile = 3

[defaults.analysis]
max_order = 6
dcm_ratio = 12.5
dcm_damping = 0.707
draws = 50  # the fewest: what the tab shows of the uncertainty, not the uncertainty itself

[[shots]]
pressure_bar = 1.5
repeats = 2

[[shots]]
pressure_bar = 2.5
"""


def write_plan(folder: Path, authorise: bool = True) -> Path:
    path = folder / "plan.toml"
    path.write_text(PLAN.format(authorise="true" if authorise else "false"), encoding="utf-8")
    return path


def test_run_pause_resume_abort_and_the_table(qtbot, make_panel, tmp_path, artifacts_dir):
    panel = make_panel(time_scale=5.0)  # charging 1.5 bar takes ~0.6 s: time to press Abort
    w = panel.window
    tab = w.campaign_tab
    w.tabs.setCurrentWidget(tab)
    assert tab.progress.text() == "no plan loaded"  # it read "0 of 1 shots done" without a plan
    tab.load_plan(write_plan(tmp_path))
    assert tab.column("Shot") == ["s001-r1", "s001-r2", "s002-r1"] and set(tab.column("State")) == {"PLANNED"}
    assert tab.progress.text() == "0 of 3 shots done"
    assert tab.run_button.isEnabled() and not tab.pause_button.isEnabled()

    # Run, and Pause while the first shot runs: the campaign stops after that shot
    def pause_on_first_shot(event):
        if isinstance(event, CampaignShotStarted) and event.shot_id == "s001-r1":
            tab.pause_button.click()
    w.link.event.connect(pause_on_first_shot)
    with qtbot.waitSignal(tab.ended, timeout=CAMPAIGN_TIMEOUT_MS):
        qtbot.mouseClick(tab.run_button, Qt.MouseButton.LeftButton)
        assert w.busy and not w.arm_button.isEnabled() and tab.pause_button.isEnabled()
    w.link.event.disconnect(pause_on_first_shot)
    assert tab.last_outcome.exit_code == 3 and "paused" in tab.last_outcome.message
    assert tab.column("State") == ["ANALYSED", "PLANNED", "PLANNED"]
    assert panel.world.shots_fired == 1
    # the worker's "shot ended" and the lamps' state reach the window as their own events, maybe just
    # after `ended` on a loaded machine: wait for them (the buttons must still come right)
    qtbot.waitUntil(lambda: tab.resume_button.isEnabled() and w.arm_button.isEnabled(), timeout=5000)
    assert tab.resume_button.isEnabled() and not tab.run_button.isEnabled() and w.arm_button.isEnabled()

    # Resume, and Abort the second shot while it charges: it goes SAFE, the campaign stops
    current: list[str] = []
    filling_when_pressed: list[bool] = []

    def abort_in_charge(event):
        if isinstance(event, CampaignShotStarted):
            current.append(event.shot_id)
        # on the first CHARGE reading (the sequencer reads only after opening the fill valve), not
        # on entering CHARGE: that state event can reach the GUI before the valve has opened
        if (isinstance(event, Reading) and event.state == "CHARGE" and current[-1:] == ["s001-r2"]
                and not filling_when_pressed):
            filling_when_pressed.append(panel.world.coils()["fill"])
            tab.abort_button.click()
    w.link.event.connect(abort_in_charge)
    with qtbot.waitSignal(tab.ended, timeout=CAMPAIGN_TIMEOUT_MS):
        qtbot.mouseClick(tab.resume_button, Qt.MouseButton.LeftButton)
    w.link.event.disconnect(abort_in_charge)
    assert filling_when_pressed == [True]  # Abort was pressed while the reservoir was charging
    assert tab.last_outcome.exit_code == 3
    assert tab.column("State") == ["ANALYSED", "ABORTED", "PLANNED"]
    assert panel.world.shots_fired == 1
    coils = panel.world.coils()
    assert coils["fire"] is False and coils["fill"] is False and coils["vent"] is True

    # Resume to the end: the aborted shot is retried, every shot fired exactly once
    with qtbot.waitSignal(tab.ended, timeout=CAMPAIGN_TIMEOUT_MS):
        qtbot.mouseClick(tab.resume_button, Qt.MouseButton.LeftButton)
    assert tab.last_outcome.exit_code == 0 and tab.last_outcome.complete, tab.last_outcome.message
    qtbot.waitUntil(lambda: all(tab.column("FBSD")), timeout=10_000)  # results read from the shot files
    assert tab.column("State") == ["ANALYSED"] * 3 and panel.world.shots_fired == 3
    assert tab.progress.value() == tab.progress.maximum() == 3
    run = tab.run_folder
    for row, sid in enumerate(("s001-r1", "s001-r2", "s002-r1")):
        results = read_shot(run.shot_path(sid), load_raw=False).results
        assert tab.column("FBSD")[row].replace("\n", " ") + " kHz" == expected_khz(results["fbsd_hz"]["5"],
                                                                                  results, "5")
        verdict = results["dcm"].get("recommended")  # the DCM's check on the shot (issue 11)
        if verdict is not None:
            assert tab.column("DCM")[row] == ("recommended" if verdict else "NOT recommended")
        assert tab.column("Order")[row] == str(results["identification"]["order"])
        assert tab.column("File")[row] == f"{sid}.h5"
        assert tab.column("p")[row] == f"{read_shot(run.shot_path(sid), load_raw=False).meta.pressure_bar:.3g}"
        # the shot's verdict and its sensitivity in the sensor's unit (µV/(m/s²): the plan names none)
        judgement = judge(results, {})
        assert tab.column("Verdict")[row] == judgement.verdict.decision.value
        nominal_uv = results["params"]["sensitivity_v_per_m_s2"] * 1e6
        shown = float(tab.column("Sensitivity")[row].split("\n")[0])
        assert abs(shown - KeyFigures.from_results(results).sensitivity.value * nominal_uv) < 1e-3
    header = [tab.table.horizontalHeaderItem(c).text() for c in range(tab.table.columnCount())]
    assert header[COL["f_n"]] == "f_n (kHz)" and header[COL["DCM"]] == "DCM" and "kHz" not in tab.column("f_n")[0]
    assert header[COL["Sensitivity"]] == "Sensitivity\n(µV/(m/s²))" and header[COL["Peak"]] == "Peak (g)"
    # the verdict and the DCM's in view at the panel's 1280 × 800, no scrolling (it was behind the scroll bar)
    for name in ("Verdict", "DCM"):
        assert tab.table.columnViewportPosition(COL[name]) + tab.table.columnWidth(COL[name]) <= \
            tab.table.viewport().width(), name
    with Journal.open(run) as journal:
        assert [s.fire_count for s in journal.statuses()] == [1, 1, 1]
    assert not tab.resume_button.isEnabled()  # nothing left to do
    # amplitude linearity over the plan's two levels (issue 19): the line through the stored shots'
    # quasi-static gains (analysis.static_gain; issue 40 item 5) at the amplitude each is measured at,
    # with the u that differs from shot to shot (docs/systematic-effects.md: S_sh, a peak ratio, reads
    # the resonance's ringing on these pulses and is not determined here)
    figures = [KeyFigures.from_results(read_shot(run.shot_path(sid), load_raw=False).results)
               for sid in ("s001-r1", "s001-r2", "s002-r1")]
    assert all(kf.shock_sensitivity is None and "not the sensitivity for this pulse" in
               kf.not_determined["shock_sensitivity"] for kf in figures)
    fit = fit_linearity([kf.static_gain_amplitude_m_s2 for kf in figures], [kf.static_gain.value for kf in figures],
                        [kf.shot_specific_u("static_gain") for kf in figures])
    assert tab.linearity_label.text().endswith(f"slope {fit.text()}") and "n = 3" in tab.linearity_label.text()
    tips = tab.linearity_label.toolTip().splitlines()
    assert [t.split(":")[0] for t in tips] == ["s001-r1", "s001-r2", "s002-r1"] and "% from the line" in tips[0]
    save_shot(w, artifacts_dir / "panel-campaign.png")


def test_a_plan_without_authorisation_fires_nothing_unless_confirmed(qtbot, make_panel, tmp_path):
    panel = make_panel()
    tab = panel.window.campaign_tab
    tab.load_plan(write_plan(tmp_path, authorise=False))
    asked = []
    tab.confirm_campaign = lambda plan: asked.append(plan.name) or "cancel"
    qtbot.mouseClick(tab.run_button, Qt.MouseButton.LeftButton)
    assert asked == ["ui-test"] and not tab.running
    assert "not authorised" in tab.message.text() and tab.run_folder is None
    assert panel.world.shots_fired == 0


def test_a_bad_plan_is_named_with_its_problem(qtbot, make_panel, tmp_path):
    tab = make_panel().window.campaign_tab
    bad = tmp_path / "bad.toml"
    bad.write_text(PLAN.format(authorise="true").replace("pressure_bar = 2.5", "pressure_bar = -1"))
    tab.load_plan(bad)
    assert tab.plan is None and "Plan not loaded" in tab.message.text() and "pressure_bar" in tab.message.text()
    assert not tab.run_button.isEnabled()
