"""The Campaign tab's work besides firing (issue 42): a failed analysis is named in its row and
re-analysed from the tab, a row's shot opens in the Shot tab, the campaign's report and its
(specimen) certificate are issued from the tab; the plan editor keeps what it does not show;
how a campaign ended is said without command lines."""

from __future__ import annotations

import dataclasses
from pathlib import Path
from types import SimpleNamespace

from PySide6.QtCore import QCoreApplication

from hopkinson.rig.journal import Journal, ShotState
from hopkinson.rig.plan import load_plan
from hopkinson.rig.shotfile import read_shot
from hopkinson.rig.shotfile_writer import add_analysis
from tests.ui.conftest import quick_config

CAMPAIGN_TIMEOUT_MS = 120_000
PLAN = """
name = "actions"
operator = "panel test"
authorise_firing = true

[accelerometer]
model = "SIM-ACC"
serial = "SN-ACT"
sensitivity_v_per_m_s2 = 2.0e-7
sensitivity_unit = "mV/g"

[defaults]
projectile = 3

[defaults.analysis]
max_order = 6
draws = 60

[[shots]]
pressure_bar = 2.0
[shots.analysis]
max_order = 5
"""


def test_reanalyse_open_report_and_certificate_from_the_tab(qtbot, make_panel, tmp_path):
    panel = make_panel(config=quick_config())
    w = panel.window
    tab = w.campaign_tab
    plan_path = tmp_path / "plan.toml"
    plan_path.write_text(PLAN, encoding="utf-8")
    tab.load_plan(plan_path)
    assert tab.table.horizontalHeaderItem(8).text() == "Sensitivity\n(mV/g)"
    with qtbot.waitSignal(tab.ended, timeout=CAMPAIGN_TIMEOUT_MS):
        tab.run()
    run = tab.run_folder
    path = run.shot_path("s001-r1")
    qtbot.waitUntil(lambda: tab.column("Verdict")[0] != "", timeout=20_000)
    assert tab.column("Sensitivity")[0].startswith("0.0019")  # 0.2 µV/(m/s²) is 0.00196 mV/g

    # the analysis fails (as if by an older method): the row says so, with the reason in its tooltip
    add_analysis(path, {}, error="analysis failed: no pulse found in the reference")
    with Journal.open(run) as journal:
        journal.mark("s001-r1", ShotState.ANALYSIS_FAILED, error="analysis failed: no pulse found in the reference")
    tab.open_run_folder(run.path)
    qtbot.waitUntil(lambda: tab.column("State") == ["ANALYSIS_FAILED"] and tab.column("Verdict")[0] == "REPEAT",
                    timeout=20_000)
    state = tab.table.item(0, 5)
    assert "no pulse found" in state.toolTip()
    tab.table.selectRow(0)
    assert tab.reanalyse_button.isEnabled() and tab.open_shot_button.isEnabled()
    tab.reanalyse_selected()
    qtbot.waitUntil(lambda: tab.column("State") == ["ANALYSED"], timeout=60_000)
    assert "re-analysed" in tab.message.text()
    shot = read_shot(path, load_raw=False)
    assert shot.state == "analysed" and len(shot.analyses) == 3  # the first, the failure, the new one
    with Journal.open(run) as journal:
        assert journal.status("s001-r1").state == ShotState.ANALYSED
    qtbot.waitUntil(lambda: tab.column("Verdict")[0] in ("ACCEPT", "REPEAT") and "±" in tab.column("FBSD")[0],
                    timeout=20_000)

    # a row opens its shot in the Shot tab (double-click)
    with qtbot.waitSignal(w.shot_view_shown, timeout=20_000) as shown:
        tab.table.cellDoubleClicked.emit(0, 1)
    assert shown.args[0].path == path and w.tabs.currentWidget() is w.plots
    assert w.plots.verdict_bar.isVisible() and w.banner.full_text.startswith("s001-r1.h5: ")

    # the campaign's report, then its specimen certificate (the shots are simulated); HTML: the
    # PDFs are the reports' and the lab's own tests'
    tab.formats = ("html",)
    tab.write_report_dialog()
    qtbot.waitUntil(lambda: "report written" in tab.message.text() or "not written" in tab.message.text(),
                    timeout=60_000)
    assert "Campaign report written" in tab.message.text(), tab.message.text()
    assert (run.report_dir / "report.html").is_file() and "s001-r1" in (run.report_dir / "report.html").read_text()
    tab.ask_authorised_by = lambda: "A. Signer"
    tab.certificate_dialog()
    qtbot.waitUntil(lambda: "ertificate" in tab.message.text() and "Issuing" not in tab.message.text(),
                    timeout=60_000)
    assert tab.message.text().startswith("Specimen certificate "), tab.message.text()
    assert list(run.report_dir.glob("certificate-*SIM*.html")), list(run.report_dir.iterdir())


def test_the_plan_editor_writes_a_plan_and_keeps_what_it_does_not_show(tmp_path):
    from hopkinson.rig.toml_file import read_toml
    from hopkinson.ui.plan_editor import (
        PRESSURE,
        TARGET,
        PlanEntry,
        PlanFields,
        entries_of,
        plan_document,
        save_plan,
    )

    source = tmp_path / "source.toml"
    source.write_text(PLAN, encoding="utf-8")
    doc, _text = read_toml(source, "plan file")
    entries = entries_of(doc)
    assert [(e.kind, e.value, e.projectile, e.repeats) for e in entries] == [(PRESSURE, 2.0, 3, 1)]
    fields = PlanFields("edited", "A. Technician", "SIM-ACC", "SN-ACT", 1.96, "µV/g", 5.0, False,
                        stated={"transverse_sensitivity_rel": 0.015, "asymmetry_bound_rel": 0.04})
    edited = plan_document(fields, entries + [PlanEntry(TARGET, 50_000.0, 2, 3)], doc)
    plan = save_plan(edited, tmp_path / "edited.toml")
    assert plan.name == "edited" and not plan.authorise_firing
    assert plan.accelerometer.sensitivity_unit == "µV/g" and plan.accelerometer.tolerance_percent == 5.0
    assert (plan.accelerometer.transverse_sensitivity_rel, plan.accelerometer.asymmetry_bound_rel) == (0.015, 0.04)
    unstated = plan_document(dataclasses.replace(fields, stated={"transverse_sensitivity_rel": None}), entries, edited)
    assert not {"transverse_sensitivity_rel", "asymmetry_bound_rel"} & set(unstated["accelerometer"])  # the rig's
    assert abs(plan.accelerometer.sensitivity_v_per_m_s2 - 1.96e-6 / 9.80665) < 1e-15
    assert [s.id for s in plan.shots] == ["s001-r1", "s002-r1", "s002-r2", "s002-r3"]
    assert plan.shots[0].pressure_bar == 2.0 and plan.shots[0].analysis.max_order == 5  # its override kept
    assert plan.shots[1].target_peak_m_s2 == 50_000 * 9.80665 and plan.shots[1].projectile == 2
    assert plan.shots[1].analysis.draws == 60  # [defaults.analysis] kept
    assert load_plan(tmp_path / "edited.toml").fingerprint == plan.fingerprint  # what was checked was written


def test_how_a_campaign_ended_is_said_for_the_panel():
    from hopkinson.ui.campaign_actions import campaign_end_message

    def outcome(code: int, message: str, **counts: int) -> SimpleNamespace:
        by_state = {"ANALYSED": 0, "ANALYSIS_FAILED": 0, "SKIPPED": 0, "PLANNED": 0} | counts
        summary = {"by_state": by_state, "total": sum(by_state.values()), "needs_decision": []}
        return SimpleNamespace(exit_code=code, message=message, summary=summary, last_shot=None,
                               complete=all(by_state[s] == 0 for s in ("PLANNED",)))

    level, text = campaign_end_message(outcome(3, "campaign stopped with 1 of 3 shots done; paused by the operator; "
                                                  "continue with --resume --out runs/x", ANALYSED=1, PLANNED=2))
    assert level == "warning" and text == ("Campaign paused: 1 of 3 shots done. Press Resume in the Campaign tab "
                                           "to go on.")
    level, text = campaign_end_message(outcome(4, "campaign complete", ANALYSED=2, ANALYSIS_FAILED=1))  # exit 4
    assert level == "ok" and text.startswith("Campaign complete: 3 of 3 shots done (1 with a failed analysis")
    level, text = campaign_end_message(None, "Campaign not run: not connected")
    assert level == "error" and text == "Campaign not run: not connected"
    for code, message in ((3, "campaign stopped with 0 of 1 shots done; s001-r1: aborted in CHARGE; continue with "
                              "--resume --out runs/x"),):
        level, text = campaign_end_message(outcome(code, message, PLANNED=1))
        assert "--resume" not in text and "aborted in CHARGE" in text and level == "warning"


def test_a_campaign_shot_started_is_shown_live(qtbot):
    """(the table's live state: a shot waiting for FIRE says so, not "FIRING")"""
    from hopkinson.ui.campaign_table import CampaignTable

    table = CampaignTable()
    qtbot.addWidget(table)
    plan_path = Path(__file__).resolve().parents[2] / "config" / "campaigns" / "demo.toml"
    table.fill(load_plan(plan_path), "µV/(m/s²)")
    table.set_state("s001-r1", "ARMED: press FIRE…")
    table.set_pressure("s001-r1", 1.5)
    assert table.column("State")[0] == "ARMED: press FIRE…" and table.column("p")[0] == "1.5"


def test_closing_mid_campaign_with_abort_keeps_the_fired_shot_and_no_traceback(qtbot, make_panel, tmp_path, capfd):
    """Closing while a fired shot is analysed, answering "abort": the rig goes safe, the shot's raw
    data stays and it is marked for re-analysis (Resume redoes it); no "cannot schedule new
    futures after shutdown" on stderr (issue 42)."""
    import sys

    caught: list[str] = []
    previous = sys.excepthook
    sys.excepthook = lambda kind, exc, tb: caught.append(f"{kind.__name__}: {exc}")
    try:
        panel = make_panel(config=quick_config())
        w = panel.window
        tab = w.campaign_tab
        plan_path = tmp_path / "plan.toml"
        plan_path.write_text(PLAN + "\n[[shots]]\npressure_bar = 2.0\n", encoding="utf-8")
        tab.load_plan(plan_path)
        tab.run()
        qtbot.waitUntil(lambda: w.state_bar.state == "ANALYSE", timeout=CAMPAIGN_TIMEOUT_MS)
        run = tab.run_folder
        asked: list[bool] = []
        w.ask_close = lambda: asked.append(True) or "abort"
        w.close()
        qtbot.waitUntil(lambda: not w.isVisible(), timeout=CAMPAIGN_TIMEOUT_MS)
        for _ in range(20):  # what the closed window still receives (the campaign's end) is delivered
            QCoreApplication.processEvents()
        assert asked == [True] and panel.world.shots_fired == 1
        coils = panel.world.coils()
        assert coils["fire"] is False and coils["fill"] is False and coils["vent"] is True
        shot = read_shot(run.shot_path("s001-r1"), load_raw=True)
        assert shot.raw is not None  # the fired shot's data is kept
        with Journal.open(run) as journal:
            status = journal.status("s001-r1")
            redo = [s.id for s in journal.pending_analysis()]
        assert status.state == ShotState.ANALYSED or "s001-r1" in redo, status  # analysed, or to be redone
        assert journal_states(run) == {"s002-r1": "PLANNED"} | {"s001-r1": status.state.value}
    finally:
        sys.excepthook = previous
    assert caught == []
    err = capfd.readouterr().err
    assert "Traceback" not in err and "cannot schedule new futures" not in err


def journal_states(run) -> dict[str, str]:
    with Journal.open(run) as journal:
        return {s.shot.id: s.state.value for s in journal.statuses()}
