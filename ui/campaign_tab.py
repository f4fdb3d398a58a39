"""The Campaign tab: create or edit a plan (ui.plan_editor), load one or open a run folder, run,
pause, resume, abort; a live table of the shots (level, pressure fired, state, peak,
sensitivity ± U in the sensor's unit, FBSD ± U, f_n, the verdict, the DCM's); re-analyse a
shot, open a row's shot (double-click), write the campaign's report and issue its certificate.

The campaign runs through rig.campaign (the same runner as `hopkinson campaign run`) on the
panel's rig I/O thread (ui.worker.RigLink.start_campaign), journaled in the run folder:
- Run: a new run folder under the runs folder (rig.campaign_setup.prepare_run);
- Pause: the runner stops after the shot now running (nothing is cut short);
- Resume: the same run folder again (the journal's resume rules: no shot lost or fired twice);
- Abort: the shot now running is aborted (the sequencer makes the rig safe) and the campaign stops.
Firing needs the plan's `authorise_firing = true`, or the operator's choice when asked
(`confirm_campaign`, a dialog; tests replace it): authorise every shot now (as `--yes`), or
confirm each shot with FIRE as a single shot is (the runner arms each and waits), or cancel.
A plan of more than `confirm_above` shots (rig.plan.CONFIRM_ABOVE_SHOTS, as `hopkinson campaign
run --confirm-above`) also needs its number of shots typed (`confirm_shot_count`, a dialog;
tests replace it), as `--shots N` (rig.plan.check_shot_count). `conditioner_entry` (set by the
window) gives a hand-set conditioner's values, entered before the campaign starts.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

from PySide6.QtCore import Signal
from PySide6.QtWidgets import (
    QFileDialog,
    QHBoxLayout,
    QLabel,
    QLineEdit,
    QProgressBar,
    QPushButton,
    QVBoxLayout,
    QWidget,
)

from hopkinson.analysis.sensitivity_units import DEFAULT_UNIT, UNITS
from hopkinson.rig.campaign_setup import prepare_run
from hopkinson.rig.config import RigConfig
from hopkinson.rig.errors import ConfigError
from hopkinson.rig.events import (
    CAMPAIGN_STATE,
    AwaitingConfirmation,
    CampaignShotEnded,
    CampaignShotStarted,
    Reading,
    RigEvent,
    StateEntered,
)
from hopkinson.rig.journal import DONE_STATES
from hopkinson.rig.plan import (
    CONFIRM_ABOVE_SHOTS,
    MAX_TOTAL_SHOTS,
    CampaignPlan,
    check_shot_count,
    load_plan,
)
from hopkinson.rig.run_folder import RunFolder, open_run_folder
from hopkinson.rig.toml_file import read_toml
from hopkinson.ui.campaign_actions import (
    ShotRow,
    campaign_end_message,
    issue_certificate,
    journal_summary,
    read_shot_row,
    reanalyse_shot,
    write_campaign_report,
)
from hopkinson.ui.campaign_table import CampaignTable
from hopkinson.ui.dialogs import ask_campaign_authorisation, ask_name, ask_shot_count
from hopkinson.ui.linearity_line import LinearityLine
from hopkinson.ui.plan_editor import PlanEditor
from hopkinson.ui.widgets import TEXT_COLOURS, section_title
from hopkinson.ui.worker import Background, RigLink

_DONE = frozenset(state.value for state in DONE_STATES)


class CampaignTab(QWidget):
    """See the module docstring. `started`/`ended` tell the window the rig is busy/free;
    `open_shot` asks it to show a shot file; `say` carries a message for its banner."""

    started = Signal()
    ended = Signal()
    open_shot = Signal(object)  # Path
    say = Signal(str, str)  # level, text

    def __init__(self, link: RigLink, background: Background, runs_dir: Path, config: RigConfig | None = None,
                 parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.link = link
        self.background = background
        self.config = config
        self.plan: CampaignPlan | None = None
        self.plan_path: Path | None = None
        self.run_folder: RunFolder | None = None
        self.running = False
        self.states: dict[str, str] = {}
        self.last_outcome: Any = None
        self.confirm_each = False  # this run's shots are confirmed one by one with FIRE
        self.confirm_timeout_s = 600.0
        self.simulated = link.instruments.simulated_truth is not None
        self._current: str | None = None
        self.confirm_above = CONFIRM_ABOVE_SHOTS
        self.formats: tuple[str, ...] = ("pdf", "html")  # of the report and the certificate
        self.conditioner_entry: Callable[[], dict[str, Any] | None] = lambda: None

        self.new_button = QPushButton("New plan…")
        self.edit_button = QPushButton("Edit plan…")
        self.load_button = QPushButton("Load plan…")
        self.open_button = QPushButton("Open run folder…")
        self.runs_dir = QLineEdit(str(runs_dir))
        self.runs_dir.setToolTip("new run folders are created here")
        self.plan_label = QLabel("No plan loaded: create one (New plan…) or load one.")
        self.plan_label.setWordWrap(True)
        self.run_label = QLabel("")
        self.run_label.setStyleSheet("color: #5f6368;")
        self.run_label.setWordWrap(True)
        self.run_button = QPushButton("Run")
        self.pause_button = QPushButton("Pause")
        self.resume_button = QPushButton("Resume")
        self.abort_button = QPushButton("Abort campaign")
        self.abort_button.setStyleSheet("QPushButton { color: white; background: #d0312d; font-weight: 600; "
                                        "padding: 4px 10px; border-radius: 3px; } "
                                        "QPushButton:disabled { background: #e8eaed; color: #9aa0a6; }")
        for b in (self.run_button, self.pause_button, self.resume_button):
            b.setMinimumWidth(80)
        self.open_shot_button = QPushButton("Open shot")
        self.reanalyse_button = QPushButton("Re-analyse")
        self.report_button = QPushButton("Report")
        self.certificate_button = QPushButton("Certificate…")
        self.open_shot_button.setToolTip("show the selected shot in the Shot tab (or double-click its row)")
        self.reanalyse_button.setToolTip("analyse the selected shot again from its raw data (a failed analysis too)")
        self.report_button.setToolTip("write the campaign's report (PDF and HTML) into the run folder")
        self.certificate_button.setToolTip("record the run in the lab's record and issue its numbered certificate")
        self.progress = QProgressBar()
        self.progress.setFormat("no plan loaded")  # not "0 of 1 shots done" before there is a plan
        self.progress.setRange(0, 1)
        self.progress.setValue(0)
        self.current_label = QLabel("")
        self.current_label.setStyleSheet("font-weight: 600;")
        self.message = QLabel("")
        self.message.setWordWrap(True)
        self.linearity_label = LinearityLine()

        self.table = CampaignTable()
        self.rows = self.table.rows

        top = QHBoxLayout()
        for b in (self.new_button, self.edit_button, self.load_button, self.open_button):
            top.addWidget(b)
        top.addWidget(QLabel("Runs folder"))
        top.addWidget(self.runs_dir, 1)
        controls = QHBoxLayout()
        for b in (self.run_button, self.pause_button, self.resume_button, self.abort_button):
            controls.addWidget(b)
        controls.addSpacing(12)
        controls.addWidget(self.progress, 1)
        row_actions = QHBoxLayout()
        row_actions.addWidget(QLabel("Selected shot:"))
        row_actions.addWidget(self.open_shot_button)
        row_actions.addWidget(self.reanalyse_button)
        row_actions.addStretch(1)
        row_actions.addWidget(QLabel("Campaign:"))
        row_actions.addWidget(self.report_button)
        row_actions.addWidget(self.certificate_button)
        layout = QVBoxLayout(self)
        layout.setContentsMargins(8, 8, 8, 8)
        layout.addWidget(section_title("Campaign"))
        layout.addLayout(top)
        layout.addWidget(self.plan_label)
        layout.addWidget(self.run_label)
        layout.addLayout(controls)
        layout.addWidget(self.current_label)
        layout.addWidget(self.message)
        layout.addWidget(self.linearity_label)
        layout.addWidget(self.table, 1)
        layout.addLayout(row_actions)

        self.new_button.clicked.connect(lambda: self.edit_plan(new=True))
        self.edit_button.clicked.connect(lambda: self.edit_plan(new=False))
        self.load_button.clicked.connect(self._load_clicked)
        self.open_button.clicked.connect(self._open_clicked)
        self.run_button.clicked.connect(self.run)
        self.pause_button.clicked.connect(self.pause)
        self.resume_button.clicked.connect(self.resume)
        self.abort_button.clicked.connect(self.abort)
        self.open_shot_button.clicked.connect(self.open_selected)
        self.reanalyse_button.clicked.connect(self.reanalyse_selected)
        self.report_button.clicked.connect(self.write_report_dialog)
        self.certificate_button.clicked.connect(self.certificate_dialog)
        self.table.cellDoubleClicked.connect(lambda row, _col: self.open_row(row))
        self.table.itemSelectionChanged.connect(self.update_buttons)
        link.campaign_finished.connect(self._finished)
        link.campaign_failed.connect(self._failed)
        self.update_buttons()

    # -- seams ------------------------------------------------------------------------------------
    def confirm_campaign(self, plan: CampaignPlan) -> str:
        """A plan that does not authorise itself: "all" (fire every shot), "each" (confirm each
        shot with FIRE) or "cancel"."""
        a = plan.accelerometer
        return ask_campaign_authorisation(self, plan.name, len(plan.shots), f"{a.model} {a.serial}")

    def confirm_shot_count(self, plan: CampaignPlan) -> int | None:
        """Ask the operator to type the number of shots of a large plan (None: cancelled)."""
        return ask_shot_count(self, plan.name, len(plan.shots), self.confirm_above, MAX_TOTAL_SHOTS)

    def ask_authorised_by(self) -> str | None:
        """Who authorises the certificate (None: cancelled)."""
        return ask_name(self, "Issue the certificate", "Authorised by (name):")

    # -- plan and run folder ----------------------------------------------------------------------
    def edit_plan(self, new: bool = False) -> Path | None:
        """Create a plan, or edit the loaded one (a copy under a new name while a run uses it);
        the plan saved is loaded. Returns where it was saved (None: cancelled)."""
        doc: dict[str, Any] = {}
        if not new and self.plan_path is not None:
            try:
                doc, _text = read_toml(self.plan_path, "plan file")
            except ConfigError as exc:
                self._say(f"Plan not read: {exc}", error=True)
                return None
        editor = self.make_editor(None if new else self.plan, doc)
        editor.exec()
        if editor.saved_path is not None:
            self.load_plan(editor.saved_path)
        return editor.saved_path

    def make_editor(self, plan: CampaignPlan | None, doc: dict[str, Any]) -> PlanEditor:
        """The plan editor (tests drive it without showing it)."""
        return PlanEditor(self, plan, doc, folder=Path(self.runs_dir.text().strip() or "."))

    def load_plan(self, path: Path) -> None:
        """Load a plan (ConfigError shows on the tab); a new run will be created for it."""
        try:
            plan = load_plan(path)
        except ConfigError as exc:
            self._say(f"Plan not loaded: {exc}", error=True)
            return
        self.plan, self.plan_path, self.run_folder = plan, Path(path), None
        self._fill_table(plan)
        self._describe()
        self._say(f"Plan {plan.name!r} loaded: press Run to start a new run.")
        self.update_buttons()

    def open_run_folder(self, path: Path) -> None:
        """Open an existing run folder (to resume it); its journal gives each shot's state."""
        try:
            run = open_run_folder(path)
            plan = run.load_plan()
        except ConfigError as exc:
            self._say(f"Run folder not opened: {exc}", error=True)
            return
        self.plan, self.plan_path, self.run_folder = plan, run.plan_path, run
        self._fill_table(plan)
        self._describe()
        self.update_buttons()
        self.background.run(lambda: journal_summary(run, plan), self._show_summary,
                            lambda exc: self._say(f"Journal not read: {exc}", error=True))

    def _describe(self) -> None:
        plan = self.plan
        if plan is None:
            return
        auth = "authorises firing" if plan.authorise_firing else "does not authorise firing (you will be asked)"
        tolerance = f", tolerance ±{plan.accelerometer.tolerance_percent:g} %" if plan.accelerometer.tolerance_percent \
            else ""
        self.plan_label.setText(f"<b>{plan.name}</b> — {len(plan.shots)} shots on {plan.accelerometer.model} "
                                f"{plan.accelerometer.serial}{tolerance}, operator {plan.operator or '—'}; the plan "
                                f"{auth}. <span style='color:#5f6368'>{plan.path}</span>")
        self.run_label.setText(f"Run folder: {self.run_folder.path}" if self.run_folder else
                               "Run folder: a new one under the runs folder")

    def unit_name(self) -> str:
        name = self.plan.accelerometer.sensitivity_unit if self.plan is not None else None
        return name if name in UNITS else DEFAULT_UNIT

    def _fill_table(self, plan: CampaignPlan) -> None:
        self.states.clear()
        self.linearity_label.clear_points()
        self.linearity_label.show_line(self.rows)
        self.table.fill(plan, self.unit_name())
        for shot in plan.shots:
            self._set_state(shot.id, "PLANNED")
        self.progress.setFormat("%v of %m shots done")
        self.progress.setRange(0, max(1, len(plan.shots)))
        self._update_progress()

    def column(self, name: str) -> list[str]:
        """The texts of a table column by its key (ui.campaign_table.COLUMNS), top to bottom."""
        return self.table.column(name)

    # -- control ------------------------------------------------------------------------------------
    def run(self) -> None:
        """Start a new run of the loaded plan (or continue the opened run folder)."""
        if self.plan is None or self.running:
            return
        if self.run_folder is not None:
            self.resume()
            return
        if not self._authorised():
            return
        try:
            run, plan = prepare_run(self.plan_path, runs_dir=Path(self.runs_dir.text().strip() or "runs"))
        except ConfigError as exc:
            self._say(f"Not started: {exc}", error=True)
            return
        self.run_folder, self.plan = run, plan
        self._describe()
        self._start(run, plan)

    def resume(self) -> None:
        """Continue the current run folder (after a pause, an abort or a crash)."""
        if self.plan is None or self.run_folder is None or self.running:
            return
        if not self._authorised():
            return
        try:
            run, plan = prepare_run(self.run_folder.plan_path, out=self.run_folder.path, resume=True)
        except ConfigError as exc:
            self._say(f"Not resumed: {exc}", error=True)
            return
        self._start(run, plan)

    def pause(self) -> None:
        if self.running:
            self.link.pause_campaign()
            self._say("Pausing: the campaign stops after the shot now running.", level="warning")

    def abort(self) -> None:
        if self.running:
            self.link.abort("campaign aborted on the panel")
            self._say("Aborting: the shot now running goes to the safe state; the campaign stops.", level="warning")

    def _authorised(self) -> bool:
        assert self.plan is not None
        self.confirm_each = False
        if not self.plan.authorise_firing:
            choice = self.confirm_campaign(self.plan)
            if choice == "cancel":
                self._say(f"Not started: the plan {self.plan.name!r} does not authorise firing, and firing was not "
                          "authorised here (neither every shot nor each shot); nothing was fired.", error=True)
                return False
            self.confirm_each = choice == "each"
        total = len(self.plan.shots)
        typed = self.confirm_shot_count(self.plan) if total > self.confirm_above else None
        try:
            check_shot_count(self.plan, self.confirm_above, typed)
        except ConfigError:
            given = "" if typed is None else f" ({typed} was typed)"
            self._say(f"Not started: the plan fires {total} shots, more than {self.confirm_above}, and that number "
                      f"was not confirmed{given}; nothing was fired.", error=True)
            return False
        return True

    def _start(self, run: RunFolder, plan: CampaignPlan) -> None:
        self.running = True
        self.last_outcome = None
        how = "; each shot waits for FIRE" if self.confirm_each else ""
        self._say(f"Campaign running in {run.path}{how}")
        self.started.emit()
        self.update_buttons()
        self.link.start_campaign(run, plan, self.conditioner_entry(),
                                 confirm_each_s=self.confirm_timeout_s if self.confirm_each else None)

    def update_buttons(self) -> None:
        connected = self.link.all_connected
        idle = not self.running and not self.link.shot_running
        has_plan = self.plan is not None
        self.run_button.setEnabled(has_plan and idle and connected and self.run_folder is None)
        self.resume_button.setEnabled(has_plan and idle and connected and self.run_folder is not None
                                      and not self._complete())
        self.pause_button.setEnabled(self.running)
        self.abort_button.setEnabled(self.running)
        for b in (self.new_button, self.load_button, self.open_button):
            b.setEnabled(not self.running)
        self.edit_button.setEnabled(not self.running and has_plan)
        selected = self.selected_shot()
        state = self.states.get(selected or "", "")
        self.open_shot_button.setEnabled(selected is not None and self._file_of(selected) is not None)
        self.reanalyse_button.setEnabled(idle and state in ("ANALYSED", "ANALYSIS_FAILED"))
        has_run = self.run_folder is not None and idle
        self.report_button.setEnabled(has_run and any(s in _DONE for s in self.states.values()))
        self.certificate_button.setEnabled(has_run and any(s == "ANALYSED" for s in self.states.values()))
        tip = "" if connected else "not every instrument is connected"
        self.run_button.setToolTip(tip)
        self.resume_button.setToolTip(tip)

    def _complete(self) -> bool:
        return bool(self.states) and all(s in _DONE for s in self.states.values())

    # -- rows -----------------------------------------------------------------------------------------
    def selected_shot(self) -> str | None:
        rows = {i.row() for i in self.table.selectedIndexes()}
        return self.table.shot_at(rows.pop()) if len(rows) == 1 else None

    def _file_of(self, sid: str) -> Path | None:
        if self.run_folder is None:
            return None
        path = self.run_folder.shot_path(sid)
        return path if path.exists() else None

    def open_row(self, row: int) -> None:
        """Show a row's shot in the Shot tab."""
        sid = self.table.shot_at(row)
        path = self._file_of(sid) if sid is not None else None
        if path is None:
            self._say(f"{sid or 'this row'}: no shot file yet (not fired)", level="warning")
            return
        self.open_shot.emit(path)

    def open_selected(self) -> None:
        sid = self.selected_shot()
        if sid is not None:
            self.open_row(self.rows[sid])

    def reanalyse_selected(self) -> None:
        """Analyse the selected shot again (a new analysis version in its file; the journal follows)."""
        sid, run, plan = self.selected_shot(), self.run_folder, self.plan
        if sid is None or run is None or plan is None or self.running:
            return
        self._say(f"Re-analysing {sid}…", level="info")
        self.reanalyse_button.setEnabled(False)

        def done(outcome: tuple[str, str | None]) -> None:
            state, error = outcome
            self._set_state(sid, state, error or "")
            self._load_results(sid, run.shot_path(sid))
            if error is None:
                self._say(f"{sid} re-analysed: its new analysis is stored in {run.shot_path(sid).name}", level="ok")
            else:
                self._say(f"{sid}: the analysis failed again: {error}", error=True)
            self.update_buttons()

        self.background.run(lambda: reanalyse_shot(run, plan, sid), done,
                            lambda exc: (self._say(f"{sid} not re-analysed: {exc}", error=True),
                                         self.update_buttons()))

    def write_report_dialog(self) -> None:
        """Write the campaign's report into its run folder (PDF and HTML)."""
        run = self.run_folder
        if run is None or self.running:
            self._say("No finished run to report on: run the campaign (or open its run folder) first.", level="warning")
            return
        self._say("Writing the campaign report…", level="info")
        self.background.run(lambda: write_campaign_report(run, self.formats),
                            lambda paths: self._say("Campaign report written: " + ", ".join(str(p) for p in paths),
                                                    level="ok"),
                            lambda exc: self._say(f"Campaign report not written: {exc}", error=True))

    def certificate_dialog(self) -> None:
        """Issue the run's certificate (a specimen marked as simulated data on a simulated rig)."""
        run, config = self.run_folder, self.config
        if run is None or config is None or self.running:
            self._say("No finished run to certify: run the campaign (or open its run folder) first.", level="warning")
            return
        who = self.ask_authorised_by()
        if who is None:
            return
        specimen = self.simulated
        self._say("Issuing the certificate…", level="info")
        self.background.run(lambda: issue_certificate(config, run, who, specimen, self.formats),
                            lambda issued: self._say(f"{'Specimen c' if specimen else 'C'}ertificate {issued[0]} "
                                                     f"issued: {', '.join(str(p) for p in issued[1])}", level="ok"),
                            lambda exc: self._say(f"Certificate not issued: {exc}", error=True))

    # -- events -------------------------------------------------------------------------------------
    def on_event(self, event: RigEvent) -> None:
        """Every rig event (GUI thread): campaign progress, shot ends, the current state."""
        if not self.running:
            return
        if isinstance(event, CampaignShotStarted):
            self._current = event.shot_id
            self._set_state(event.shot_id, "RUNNING…")
            self.table.set_pressure(event.shot_id, event.pressure_bar)
            self.current_label.setText(f"[{event.index}/{event.total}] {event.shot_id}: {event.message}")
        elif isinstance(event, CampaignShotEnded):
            error = event.message.split(": ", 1)[1] if event.journal_state == "ANALYSIS_FAILED" and ": " in \
                event.message else ""
            self._set_state(event.shot_id, event.journal_state, error)
            if event.journal_state in ("ANALYSED", "ANALYSIS_FAILED") and self.run_folder is not None:
                self._load_results(event.shot_id, self.run_folder.shot_path(event.shot_id))
        elif event.state == CAMPAIGN_STATE:
            return
        elif self._current and isinstance(event, StateEntered):
            self.current_label.setText(f"{self._prefix()} {event.state}: {event.message}")
            if self.states.get(self._current, "").endswith("…"):  # the shot's own step, live
                self._set_state(self._current, f"{event.state}…")
        elif self._current and isinstance(event, AwaitingConfirmation):
            self._set_state(self._current, "ARMED: press FIRE…")
            self.current_label.setText(f"{self._prefix()} ARMED: waiting for FIRE (ABORT stands down)")
        elif self._current and isinstance(event, Reading) and event.state in ("CHARGE", "EVACUATE"):
            p, v = event.reservoir_pressure_bar, event.fixture_vacuum_mbar
            self.current_label.setText(f"{self._prefix()} {event.state} {p:.2f} bar, {v:.0f} mbar")

    def _prefix(self) -> str:
        row = self.rows.get(self._current or "", -1)
        return f"[{row + 1}/{len(self.rows)}] {self._current}"

    def _set_state(self, sid: str, state: str, why: str = "") -> None:
        if sid not in self.rows:
            return
        self.states[sid] = state
        self.table.set_state(sid, state, why)
        self._update_progress()

    def _update_progress(self) -> None:
        done = sum(1 for s in self.states.values() if s in _DONE)
        self.progress.setValue(done)

    def _load_results(self, sid: str, path: Path) -> None:
        self.background.run(lambda: read_shot_row(path), lambda row: self._show_results(sid, path, row),
                            lambda exc: self._say(f"{path.name}: results not read: {exc}", error=True))

    def _show_results(self, sid: str, path: Path, shot: ShotRow) -> None:
        self.table.show_shot(sid, path, shot, failed=self.states.get(sid) == "ANALYSIS_FAILED")
        kf = shot.judgement.figures
        if kf is not None and sid in self.rows:
            self.linearity_label.add(sid, kf)
            self.linearity_label.show_line(self.rows)
        self.update_buttons()

    def _show_summary(self, summary: dict[str, Any]) -> None:
        for shot in summary.get("shots", []):
            sid = shot["id"]
            self._set_state(sid, shot["state"], str(shot.get("error") or shot.get("reason") or ""))
            if shot.get("file") and self.run_folder is not None and shot["state"] in ("ANALYSED", "ANALYSIS_FAILED"):
                self._load_results(sid, self.run_folder.shot_path(sid))
        self.update_buttons()

    def _finished(self, outcome: Any) -> None:
        self.running = False
        self._current = None
        self.last_outcome = outcome
        self.current_label.setText("")
        self._show_summary(outcome.summary)
        level, text = campaign_end_message(outcome)
        self._say(text, level=level)
        self.update_buttons()
        self.ended.emit()

    def _failed(self, message: str) -> None:
        self.running = False
        self._current = None
        self.current_label.setText("")
        self._say(f"Campaign not run: {message}", error=True)
        self.update_buttons()
        self.ended.emit()

    def _say(self, text: str, error: bool = False, level: str = "") -> None:
        level = "error" if error else level or "ok"
        self.message.setStyleSheet(f"color: {TEXT_COLOURS[level]};")
        self.message.setText(text)
        if level in ("ok", "warning", "error") and not self.running:
            self.say.emit(level, text)

    # -- dialogs ---------------------------------------------------------------------------------------
    def _load_clicked(self) -> None:
        name, _ = QFileDialog.getOpenFileName(self, "Load a campaign plan", "config/campaigns", "Plans (*.toml)")
        if name:
            self.load_plan(Path(name))

    def _open_clicked(self) -> None:
        folder = QFileDialog.getExistingDirectory(self, "Open a run folder", self.runs_dir.text())
        if folder:
            self.open_run_folder(Path(folder))

