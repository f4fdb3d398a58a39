"""The Campaign tab: load a plan (or open a run folder), run, pause, resume, abort; a table of
the shots with their journal state and results, and the campaign's progress.

The campaign runs through rig.campaign (the same runner as `hopkinson campaign run`) on the
panel's rig I/O thread (ui.worker.RigLink.start_campaign), journaled in the run folder:
- Run: a new run folder under the runs folder (rig.campaign.prepare_run);
- Pause: the runner stops after the shot now running (nothing is cut short);
- Resume: the same run folder again (the journal's resume rules: no shot lost or fired twice);
- Abort: the shot now running is aborted (the sequencer makes the rig safe) and the campaign stops.
Firing needs the plan's `authorise_firing = true` or the operator's explicit confirmation
(`confirm_campaign`, a dialog; tests replace it), exactly as `--yes` on the command line. A plan
of more than `confirm_above` shots (rig.plan.CONFIRM_ABOVE_SHOTS, as `hopkinson campaign run
--confirm-above`) also needs its number of shots typed (`confirm_shot_count`, a dialog; tests
replace it), as `--shots N` (rig.plan.check_shot_count). `conditioner_entry` (set by the window)
gives a hand-set conditioner's values, entered before the campaign starts.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

from hopkinson.analysis.key_figures import KeyFigures
from hopkinson.reports.data import CompensationCheck
from hopkinson.reports.statistics import LinearityPoint, campaign_linearity, linearity_points
from hopkinson.rig.campaign import CAMPAIGN_STATE, check_authorisation, prepare_run
from hopkinson.rig.errors import ConfigError
from hopkinson.rig.events import (
    CampaignShotEnded,
    CampaignShotStarted,
    Reading,
    RigEvent,
    StateEntered,
)
from hopkinson.rig.journal import DONE_STATES, Journal
from hopkinson.rig.plan import (
    CONFIRM_ABOVE_SHOTS,
    G_M_S2,
    MAX_TOTAL_SHOTS,
    CampaignPlan,
    check_shot_count,
    load_plan,
)
from hopkinson.rig.run_folder import RunFolder, open_run_folder
from hopkinson.ui.plots import KILO, figure_tooltip, format_figure
from hopkinson.ui.widgets import section_title
from hopkinson.ui.worker import Background, RigLink
from PySide6.QtCore import Signal
from PySide6.QtGui import QBrush, QColor
from PySide6.QtWidgets import (
    QAbstractItemView,
    QFileDialog,
    QHBoxLayout,
    QHeaderView,
    QInputDialog,
    QLabel,
    QLineEdit,
    QMessageBox,
    QProgressBar,
    QPushButton,
    QTableWidget,
    QTableWidgetItem,
    QVBoxLayout,
    QWidget,
)

# units in the headers, the DCM's verdict before the (long) file name, a figure's ± U under its
# value (_show_results): at 1280 × 800 the verdict was off the right edge, behind a scroll bar
COLUMNS = ("#", "Shot", "p (bar)", "Proj.", "State", "Order", "f_n (kHz)", "ζ", "FBSD ±5 %\n(kHz)",
           "FBSD ±10 %\n(kHz)", "Shock\nsens.", "DCM", "Shot file")
DCM_COLUMN, FILE_COLUMN = COLUMNS.index("DCM"), COLUMNS.index("Shot file")
_STATE_COLOURS = {"ANALYSED": "#1e6b2e", "ANALYSIS_FAILED": "#8a5a00", "ABORTED": "#b3261e", "UNKNOWN": "#b3261e",
                  "SKIPPED": "#5f6368", "FIRING": "#1f6fd1", "RECORDED": "#1f6fd1"}
_DONE = frozenset(state.value for state in DONE_STATES)


class CampaignTab(QWidget):
    """See the module docstring. `started`/`ended` tell the window the rig is busy/free."""

    started = Signal()
    ended = Signal()

    def __init__(self, link: RigLink, background: Background, runs_dir: Path,
                 parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.link = link
        self.background = background
        self.plan: CampaignPlan | None = None
        self.plan_path: Path | None = None
        self.run_folder: RunFolder | None = None
        self.running = False
        self.rows: dict[str, int] = {}
        self.states: dict[str, str] = {}
        self.last_outcome: Any = None
        self._current: str | None = None
        self.confirm_above = CONFIRM_ABOVE_SHOTS
        self.conditioner_entry: Callable[[], dict[str, Any] | None] = lambda: None

        self.load_button = QPushButton("Load plan…")
        self.open_button = QPushButton("Open run folder…")
        self.runs_dir = QLineEdit(str(runs_dir))
        self.runs_dir.setToolTip("new run folders are created here")
        self.plan_label = QLabel("No plan loaded.")
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
        self.progress = QProgressBar()
        self.progress.setFormat("no plan loaded")  # not "0 of 1 shots done" before there is a plan
        self.progress.setRange(0, 1)
        self.progress.setValue(0)
        self.current_label = QLabel("")
        self.current_label.setStyleSheet("font-weight: 600;")
        self.message = QLabel("")
        self.message.setWordWrap(True)
        # amplitude linearity (ISO 16063-22) over the analysed shots' levels; each point in the tooltip
        self.linearity_label = QLabel("")
        self.linearity_label.setWordWrap(True)
        self._linearity: dict[str, LinearityPoint] = {}

        self.table = QTableWidget(0, len(COLUMNS))
        self.table.setHorizontalHeaderLabels(COLUMNS)
        self.table.verticalHeader().setVisible(False)
        self.table.verticalHeader().setSectionResizeMode(QHeaderView.ResizeMode.ResizeToContents)
        self.table.setEditTriggers(QAbstractItemView.EditTrigger.NoEditTriggers)
        self.table.setSelectionBehavior(QAbstractItemView.SelectionBehavior.SelectRows)
        self.table.setAlternatingRowColors(True)
        header = self.table.horizontalHeader()
        for i in range(len(COLUMNS) - 1):
            header.setSectionResizeMode(i, QHeaderView.ResizeMode.ResizeToContents)
        header.setSectionResizeMode(len(COLUMNS) - 1, QHeaderView.ResizeMode.Stretch)

        top = QHBoxLayout()
        top.addWidget(self.load_button)
        top.addWidget(self.open_button)
        top.addWidget(QLabel("Runs folder"))
        top.addWidget(self.runs_dir, 1)
        controls = QHBoxLayout()
        for b in (self.run_button, self.pause_button, self.resume_button, self.abort_button):
            controls.addWidget(b)
        controls.addSpacing(12)
        controls.addWidget(self.progress, 1)
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

        self.load_button.clicked.connect(self._load_clicked)
        self.open_button.clicked.connect(self._open_clicked)
        self.run_button.clicked.connect(self.run)
        self.pause_button.clicked.connect(self.pause)
        self.resume_button.clicked.connect(self.resume)
        self.abort_button.clicked.connect(self.abort)
        link.campaign_finished.connect(self._finished)
        link.campaign_failed.connect(self._failed)
        self.update_buttons()

    # -- seams ------------------------------------------------------------------------------------
    def confirm_campaign(self, plan: CampaignPlan) -> bool:
        """Ask the operator to authorise firing a plan that does not authorise itself."""
        answer = QMessageBox.warning(
            self, "Authorise the campaign",
            f"The plan {plan.name!r} does not authorise firing (authorise_firing = false).\n\n"
            f"Fire its {len(plan.shots)} shots on {plan.accelerometer.model} {plan.accelerometer.serial} "
            "without asking before each one?",
            QMessageBox.StandardButton.Yes | QMessageBox.StandardButton.No, QMessageBox.StandardButton.No)
        return answer == QMessageBox.StandardButton.Yes

    def confirm_shot_count(self, plan: CampaignPlan) -> int | None:
        """Ask the operator to type the number of shots of a large plan (None: cancelled)."""
        total = len(plan.shots)
        value, ok = QInputDialog.getInt(
            self, "Confirm the number of shots",
            f"The plan {plan.name!r} fires {total} shots, more than {self.confirm_above}.\n\n"
            "Type its number of shots to fire them:", 0, 0, MAX_TOTAL_SHOTS)
        return value if ok else None

    # -- plan and run folder ----------------------------------------------------------------------
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
        self.background.run(lambda: _journal_summary(run, plan), self._show_summary,
                            lambda exc: self._say(f"Journal not read: {exc}", error=True))

    def _describe(self) -> None:
        plan = self.plan
        if plan is None:
            return
        auth = "authorises firing" if plan.authorise_firing else "does NOT authorise firing (you will be asked)"
        self.plan_label.setText(f"<b>{plan.name}</b> — {len(plan.shots)} shots on {plan.accelerometer.model} "
                                f"{plan.accelerometer.serial}, operator {plan.operator or '—'}; the plan {auth}. "
                                f"<span style='color:#5f6368'>{plan.path}</span>")
        self.run_label.setText(f"Run folder: {self.run_folder.path}" if self.run_folder else
                               "Run folder: a new one under the runs folder")

    def _fill_table(self, plan: CampaignPlan) -> None:
        self.table.setRowCount(0)
        self.rows.clear()
        self.states.clear()
        self._linearity.clear()
        self._update_linearity()
        for shot in plan.shots:
            row = self.table.rowCount()
            self.table.insertRow(row)
            self.rows[shot.id] = row
            level = (f"{shot.pressure_bar:g}" if shot.target_peak_m_s2 is None  # a target: chosen at firing
                     else f"→ {shot.target_peak_m_s2 / G_M_S2:.4g} g")
            for col, text in enumerate((str(shot.index + 1), shot.id, level,
                                        f"No. {shot.projectile}", "PLANNED")):
                self.table.setItem(row, col, QTableWidgetItem(text))
            self.states[shot.id] = "PLANNED"
        self.progress.setFormat("%v of %m shots done")
        self.progress.setRange(0, max(1, len(plan.shots)))
        self._update_progress()

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
            self._say("Pausing: the campaign stops after the shot now running.")

    def abort(self) -> None:
        if self.running:
            self.link.abort("campaign aborted on the panel")
            self._say("Aborting: the shot now running goes to the safe state; the campaign stops.", error=True)

    def _authorised(self) -> bool:
        assert self.plan is not None
        confirmed = self.plan.authorise_firing or self.confirm_campaign(self.plan)
        try:
            check_authorisation(self.plan, confirmed)
        except ConfigError as exc:
            self._say(str(exc), error=True)
            return False
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
        self._say(f"Campaign running in {run.path}")
        self.started.emit()
        self.update_buttons()
        self.link.start_campaign(run, plan, self.conditioner_entry())

    def update_buttons(self) -> None:
        connected = self.link.all_connected
        idle = not self.running and not self.link.shot_running
        has_plan = self.plan is not None
        self.run_button.setEnabled(has_plan and idle and connected and self.run_folder is None)
        self.resume_button.setEnabled(has_plan and idle and connected and self.run_folder is not None
                                      and not self._complete())
        self.pause_button.setEnabled(self.running)
        self.abort_button.setEnabled(self.running)
        self.load_button.setEnabled(not self.running)
        self.open_button.setEnabled(not self.running)
        tip = "" if connected else "not every instrument is connected"
        self.run_button.setToolTip(tip)
        self.resume_button.setToolTip(tip)

    def _complete(self) -> bool:
        return bool(self.states) and all(s in _DONE for s in self.states.values())

    # -- events -------------------------------------------------------------------------------------
    def on_event(self, event: RigEvent) -> None:
        """Every rig event (GUI thread): campaign progress, shot ends, the current state."""
        if not self.running:
            return
        if isinstance(event, CampaignShotStarted):
            self._current = event.shot_id
            self._set_state(event.shot_id, "FIRING…")
            self.current_label.setText(f"[{event.index}/{event.total}] {event.shot_id}: {event.message}")
        elif isinstance(event, CampaignShotEnded):
            self._set_state(event.shot_id, event.journal_state)
            if event.journal_state in ("ANALYSED", "ANALYSIS_FAILED") and self.run_folder is not None:
                self._load_results(event.shot_id, self.run_folder.shot_path(event.shot_id))
        elif event.state == CAMPAIGN_STATE:
            return
        elif self._current and isinstance(event, StateEntered):
            self.current_label.setText(f"{self._prefix()} {event.state}: {event.message}")
        elif self._current and isinstance(event, Reading) and event.state in ("CHARGE", "EVACUATE"):
            p, v = event.reservoir_pressure_bar, event.fixture_vacuum_mbar
            self.current_label.setText(f"{self._prefix()} {event.state} {p:.2f} bar, {v:.0f} mbar")

    def _prefix(self) -> str:
        row = self.rows.get(self._current or "", -1)
        return f"[{row + 1}/{len(self.rows)}] {self._current}"

    def _set_state(self, sid: str, state: str) -> None:
        row = self.rows.get(sid)
        if row is None:
            return
        self.states[sid] = state
        item = QTableWidgetItem(state)
        colour = _STATE_COLOURS.get(state.rstrip("…"))
        if colour:
            item.setForeground(QBrush(QColor(colour)))
        self.table.setItem(row, 4, item)
        self._update_progress()

    def _update_progress(self) -> None:
        done = sum(1 for s in self.states.values() if s in _DONE)
        self.progress.setValue(done)

    def _load_results(self, sid: str, path: Path) -> None:
        def load() -> dict[str, Any] | None:
            from hopkinson.rig.shotfile import read_shot

            return read_shot(path, load_raw=False).results

        self.background.run(load, lambda results: self._show_results(sid, path, results),
                            lambda exc: self._say(f"{path.name}: results not read: {exc}", error=True))

    def _show_results(self, sid: str, path: Path, results: dict[str, Any] | None) -> None:
        row = self.rows.get(sid)
        if row is None:
            return
        self.table.setItem(row, FILE_COLUMN, QTableWidgetItem(path.name))
        if not results or "model" not in results:
            return
        kf = KeyFigures.from_results(results)  # the shot's key figures, as the Shot tab and the report show them
        cells = {
            5: (str(kf.order) if kf.order is not None else "—", ""),
            6: (format_figure(kf.natural_frequency_hz, KILO), figure_tooltip(kf.natural_frequency_hz, KILO, "kHz")),
            7: (format_figure(kf.damping_ratio, decimals=4), figure_tooltip(kf.damping_ratio)),
            8: _fbsd_cell(kf, "5"),
            9: _fbsd_cell(kf, "10"),
            10: (format_figure(kf.shock_sensitivity, decimals=4), figure_tooltip(kf.shock_sensitivity)),
        }
        for point in linearity_points([(sid, kf)]):
            self._linearity[sid] = point
        self._update_linearity()
        check = CompensationCheck.of(kf)
        if check is not None and check.recommended is not None:
            reason = check.not_recommended_reason or "compensation does not improve this shot"
            cells[DCM_COLUMN] = ("recommended", "") if check.recommended else ("NOT recommended", reason)
        for col, (text, tip) in cells.items():
            # value over ± U: in one line the figures pushed the DCM's verdict out of view
            item = QTableWidgetItem(text.replace(" ± ", "\n± "))
            item.setToolTip(tip)
            if col == DCM_COLUMN and check is not None and check.recommended is False:
                item.setForeground(QBrush(QColor("#b3261e")))
            self.table.setItem(row, col, item)

    def _update_linearity(self) -> None:
        """The line through the analysed shots' shock sensitivities (reports.statistics), shown
        once they cover two or more levels; each point with its U in the tooltip."""
        points = [self._linearity[sid] for sid in self.rows if sid in self._linearity]
        fit, _note = campaign_linearity(points)
        if fit is None:
            self.linearity_label.setText("")
            self.linearity_label.setToolTip("")
            return
        self.linearity_label.setText(f"Amplitude linearity (ISO 16063-22), shock sensitivity against the peak: "
                                     f"slope {fit.text()}")
        lines = [f"{p.label}: {p.peak_m_s2 / G_M_S2:,.0f} g, S_sh {p.sensitivity:.5g}"
                 + (f" ± {p.expanded:.2g}" if p.expanded is not None else "") + f" ({100 * r:+.2f} % from the line)"
                 for p, r in zip(points, fit.residuals_rel, strict=True)]
        self.linearity_label.setToolTip("\n".join(lines))

    def _show_summary(self, summary: dict[str, Any]) -> None:
        for shot in summary.get("shots", []):
            sid = shot["id"]
            self._set_state(sid, shot["state"])
            if shot.get("file") and self.run_folder is not None and shot["state"] in ("ANALYSED", "ANALYSIS_FAILED"):
                self._load_results(sid, self.run_folder.shot_path(sid))
        self.update_buttons()

    def _finished(self, outcome: Any) -> None:
        self.running = False
        self._current = None
        self.last_outcome = outcome
        self.current_label.setText("")
        self._show_summary(outcome.summary)
        self._say(outcome.message + ("" if outcome.complete else " — on the panel: press Resume."),
                  error=outcome.exit_code != 0)  # 4: complete, some analyses failed (nothing to resume)
        self.update_buttons()
        self.ended.emit()

    def _failed(self, message: str) -> None:
        self.running = False
        self._current = None
        self.current_label.setText("")
        self._say(f"Campaign not run: {message}", error=True)
        self.update_buttons()
        self.ended.emit()

    def _say(self, text: str, error: bool = False) -> None:
        self.message.setStyleSheet("color: #b3261e;" if error else "color: #1e6b2e;")
        self.message.setText(text)

    # -- dialogs ---------------------------------------------------------------------------------------
    def _load_clicked(self) -> None:
        name, _ = QFileDialog.getOpenFileName(self, "Load a campaign plan", "config/campaigns", "Plans (*.toml)")
        if name:
            self.load_plan(Path(name))

    def _open_clicked(self) -> None:
        folder = QFileDialog.getExistingDirectory(self, "Open a run folder", self.runs_dir.text())
        if folder:
            self.open_run_folder(Path(folder))


def _journal_summary(run: RunFolder, plan: CampaignPlan) -> dict[str, Any]:
    """The journal's summary of a run folder (opens it briefly: takes and releases the run lock)."""
    journal = Journal.open(run, plan)
    try:
        return journal.summary()
    finally:
        journal.close()


def _fbsd_cell(kf: KeyFigures, level: str) -> tuple[str, str]:
    """An FBSD in kHz without the unit (the header has it) and its tooltip; a bound as '> 18'
    with the reason in the tooltip."""
    bound = kf.fbsd_bounds.get(level)
    if bound is not None:
        return f"> {bound.lower_bound_hz / KILO:.3g}", kf.fbsd_text(level, KILO)
    figure = kf.fbsd_hz.get(level)
    return format_figure(figure, KILO), figure_tooltip(figure, KILO, "kHz")
