"""The panel's main window: state and ARM / FIRE / ABORT on top, rig status and shot set-up on
the left, the shot's plots, the DCM design, the campaign and the log in tabs.

Rules the buttons follow:
- ARM: every instrument connected and no shot running. It starts the shot on the rig I/O
  thread (ui.worker.RigLink); the sequencer checks, evacuates, charges and arms, then waits
  for the fire confirmation (ShotRequest.confirm_timeout_s).
- FIRE: enabled only while the sequencer waits in ARM for the confirmation AND the last
  reading shows every interlock holding. It asks for an explicit confirmation
  (`confirm_fire`, a dialog; tests and --demo-shot replace it) and then gives the
  FireAuthorisation. The sequencer reads the interlocks again before it opens the valve.
- ABORT: always enabled. A running shot is aborted (the sequencer runs SAFE); with no shot
  running the sequencer does SAFE's work without a shot (Sequencer.make_safe).

Instrument errors show as a red banner under the buttons (what, which instrument, what to do),
in the log tab, and on the instrument's lamp; never as a traceback or a frozen window: every
instrument call runs off the GUI thread.
"""

from __future__ import annotations

import logging
from pathlib import Path
from typing import Any

from hopkinson.rig.config import RigConfig
from hopkinson.rig.errors import ConfigError, with_hint
from hopkinson.rig.events import (
    AwaitingConfirmation,
    Fired,
    Reading,
    RigError,
    RigEvent,
    ShotFinished,
    StateEntered,
    StepProgress,
)
from hopkinson.rig.interlocks import INTERLOCKS
from hopkinson.rig.sequencer import State
from hopkinson.rig.shot import ShotOutcome, ShotRequest
from hopkinson.ui.campaign_tab import CampaignTab
from hopkinson.ui.dcm_tab import DcmTab
from hopkinson.ui.log_view import LogTab, LogView
from hopkinson.ui.plots import ShotPlots, ShotView, configure_pyqtgraph, load_shot_view
from hopkinson.ui.sensor_tab import SensorTab
from hopkinson.ui.shot_setup import ShotSetup
from hopkinson.ui.state_bar import StateBar
from hopkinson.ui.status_panel import StatusPanel
from hopkinson.ui.worker import Background, InstrumentLink, RigLink
from PySide6.QtCore import QSettings, Qt, Signal
from PySide6.QtGui import QCloseEvent
from PySide6.QtWidgets import (
    QFrame,
    QHBoxLayout,
    QLabel,
    QMainWindow,
    QMessageBox,
    QPushButton,
    QScrollArea,
    QSplitter,
    QTabWidget,
    QVBoxLayout,
    QWidget,
)

_log = logging.getLogger(__name__)

DEFAULT_CONFIRM_TIMEOUT_S = 600.0  # how long the armed rig waits for a human to press FIRE
MIN_SIZE = (1280, 800)

_BUTTON = ("QPushButton {{ font-size: 15pt; font-weight: 700; padding: 8px 18px; border-radius: 6px; "
           "color: white; background: {bg}; border: 2px solid {border}; min-width: 96px; }} "
           "QPushButton:disabled {{ background: #e8eaed; color: #9aa0a6; border: 2px solid #dadce0; }} "
           "QPushButton:pressed {{ background: {border}; }}")
ARM_STYLE = _BUTTON.format(bg="#1f6fd1", border="#174ea6")
FIRE_STYLE = _BUTTON.format(bg="#e8710a", border="#b45309")
ABORT_STYLE = _BUTTON.format(bg="#d0312d", border="#8c1d18")
_BANNERS = {
    "error": "background: #fce8e6; color: #8c1d18; border: 1px solid #f4b4ae;",
    "warning": "background: #fef7e0; color: #7a4f01; border: 1px solid #f9d97c;",
    "ok": "background: #e6f4ea; color: #0d652d; border: 1px solid #a8dab5;",
    "info": "background: #e8f0fe; color: #174ea6; border: 1px solid #aecbfa;",
}


class MainWindow(QMainWindow):
    """The technician's panel for one rig (module docstring).

    config: the rig configuration (addresses, limits); simulated_truth: the simulator's
    truth getter (simulation); settings: where the shot set-up is remembered; out_dir: the
    default shot folder; runs_dir: where campaign run folders go.
    """

    shot_view_shown = Signal(object)  # a ShotView was drawn (tests and --demo-shot wait on it)
    shot_view_failed = Signal(str)  # a shot file could not be shown (the message)

    def __init__(self, config: RigConfig, *, settings: QSettings | None = None,
                 simulated_truth: Any = None, out_dir: Path = Path("shots"), runs_dir: Path = Path("runs"),
                 title_note: str = "", confirm_timeout_s: float = DEFAULT_CONFIRM_TIMEOUT_S,
                 poll_interval_ms: int | None = None) -> None:
        super().__init__()
        configure_pyqtgraph()
        self.config = config
        self.settings = settings if settings is not None else QSettings("hopkinson", "panel")
        self.confirm_timeout_s = confirm_timeout_s
        self.link = RigLink(config, simulated_truth, self, **({"poll_interval_ms": poll_interval_ms}
                                                                if poll_interval_ms else {}))
        self.background = Background(self)
        self.authorisation: Any = None
        self.request: ShotRequest | None = None
        self.busy = False  # a shot or a campaign runs (from ARM / Run until its end is reported)
        self.awaiting_confirmation = False
        self.last_reading: Reading | None = None
        self.last_outcome: ShotOutcome | None = None
        self.last_view: ShotView | None = None
        self._setup_enabled: bool | None = None

        self.setWindowTitle("Hopkinson-bar shock calibration" + (f" — {title_note}" if title_note else ""))
        self.setMinimumSize(*MIN_SIZE)

        # header: state and buttons
        self.state_bar = StateBar()
        self.arm_button = QPushButton("ARM")
        self.fire_button = QPushButton("FIRE")
        self.abort_button = QPushButton("ABORT")
        self.arm_button.setStyleSheet(ARM_STYLE)
        self.fire_button.setStyleSheet(FIRE_STYLE)
        self.abort_button.setStyleSheet(ABORT_STYLE)
        self.arm_button.setToolTip("check, evacuate, charge and arm the rig for the shot set up on the left")
        self.fire_button.setToolTip("fire the armed shot (asks for confirmation); needs every interlock")
        self.abort_button.setToolTip("stop now and make the rig safe (fire and fill closed, reservoir vented)")
        self.banner = QLabel("")
        self.banner.setWordWrap(True)
        self.banner.setTextInteractionFlags(Qt.TextInteractionFlag.TextSelectableByMouse)
        self.banner.setVisible(False)
        self.banner_level = ""

        header = QHBoxLayout()
        header.setContentsMargins(10, 8, 10, 4)
        header.addWidget(self.state_bar, 1)
        self.mode_badge = QLabel(title_note)
        self.mode_badge.setStyleSheet("QLabel { background: #fef7e0; color: #7a4f01; border: 1px solid #f9d97c; "
                                      "border-radius: 4px; padding: 3px 8px; font-weight: 700; font-size: 9pt; }")
        self.mode_badge.setVisible(bool(title_note))
        self.mode_badge.setToolTip("the panel drives a simulated rig: nothing real moves")
        header.addWidget(self.mode_badge, 0, Qt.AlignmentFlag.AlignTop)
        header.addSpacing(12)
        for button in (self.arm_button, self.fire_button, self.abort_button):
            header.addWidget(button)

        # left: status and set-up
        self.status_panel = StatusPanel(config.limits)
        self.setup = ShotSetup(config, out_dir)
        self.setup.load(self.settings)
        left = QWidget()
        left_layout = QVBoxLayout(left)
        left_layout.setContentsMargins(0, 0, 0, 0)
        left_layout.setSpacing(2)
        left_layout.addWidget(self.status_panel)
        rule = QFrame()
        rule.setFrameShape(QFrame.Shape.HLine)
        rule.setStyleSheet("color: #dadce0;")
        left_layout.addWidget(rule)
        left_layout.addWidget(self.setup)
        left_layout.addStretch(1)
        scroll = QScrollArea()
        scroll.setWidget(left)
        scroll.setWidgetResizable(True)
        scroll.setHorizontalScrollBarPolicy(Qt.ScrollBarPolicy.ScrollBarAlwaysOff)
        scroll.setMinimumWidth(350)
        scroll.setMaximumWidth(420)
        scroll.setFrameShape(QFrame.Shape.NoFrame)

        # tabs
        self.plots = ShotPlots()
        self.dcm_tab = DcmTab(export_report=self.export_report)
        self.campaign_tab = CampaignTab(self.link, self.background, runs_dir)
        self.campaign_tab.conditioner_entry = self.setup.conditioner_entry  # a hand-set conditioner's values
        self.log_view = LogView()
        self.log_tab = LogTab(self.log_view, default_folder=out_dir)
        self.tabs = QTabWidget()
        self.tabs.addTab(self.plots, "Shot")
        self.tabs.addTab(self.dcm_tab, "DCM design")
        self.tabs.addTab(self.campaign_tab, "Campaign")
        self.sensor_tab = SensorTab(self.background, config.database.url, config.lab.decision_rule)
        self.tabs.addTab(self.sensor_tab, "Sensor history")
        self.tabs.addTab(self.log_tab, "Log")

        splitter = QSplitter(Qt.Orientation.Horizontal)
        splitter.addWidget(scroll)
        splitter.addWidget(self.tabs)
        splitter.setStretchFactor(0, 0)
        splitter.setStretchFactor(1, 1)
        splitter.setSizes([360, 920])

        central = QWidget()
        layout = QVBoxLayout(central)
        layout.setContentsMargins(0, 0, 0, 0)
        layout.setSpacing(0)
        layout.addLayout(header)
        banner_row = QHBoxLayout()
        banner_row.setContentsMargins(10, 0, 10, 4)
        banner_row.addWidget(self.banner)
        layout.addLayout(banner_row)
        layout.addWidget(splitter, 1)
        self.setCentralWidget(central)
        self.statusBar().showMessage("connecting to the rig…")

        # wiring
        self.arm_button.clicked.connect(self.arm)
        self.fire_button.clicked.connect(self.fire)
        self.abort_button.clicked.connect(self.abort)
        self.link.event.connect(self._on_event)
        self.link.links_changed.connect(self._on_links)
        self.link.shot_finished.connect(self._on_shot_finished)
        self.link.shot_failed.connect(self._on_shot_failed)
        self.link.message.connect(self._on_message)
        self.link.safe_done.connect(self._on_safe_done)
        self.campaign_tab.started.connect(self._campaign_started)
        self.campaign_tab.ended.connect(self._campaign_ended)
        self.status_panel.set_links(self.link.links)
        self.update_buttons()

    # -- start / stop -------------------------------------------------------------------------------
    def start(self) -> None:
        """Connect to the rig and start the idle readings."""
        self.link.start()

    def closeEvent(self, event: QCloseEvent) -> None:  # noqa: N802 (Qt's name)
        self.setup.save(self.settings)
        if self.busy:
            self.statusBar().showMessage("aborting the shot and making the rig safe before closing…")
        self.link.shutdown()
        self.background.shutdown()
        super().closeEvent(event)

    # -- seams --------------------------------------------------------------------------------------
    def confirm_fire(self) -> bool:
        """Ask the operator to confirm the shot (explicit Yes; the default is No)."""
        r = self.request
        what = (f"Reservoir {r.pressure_bar:g} bar, projectile No. {r.projectile}, accelerometer "
                f"{r.accelerometer_model or '—'} {r.accelerometer_serial}".rstrip()) if r else ""
        answer = QMessageBox.warning(
            self, "Fire the shot?",
            f"FIRE the armed shot now?\n\n{what}\n\nEvery interlock holds. Make sure nobody is at the bar.",
            QMessageBox.StandardButton.Yes | QMessageBox.StandardButton.No, QMessageBox.StandardButton.No)
        return answer == QMessageBox.StandardButton.Yes

    # -- buttons ------------------------------------------------------------------------------------
    def arm(self) -> None:
        """ARM: start the shot set up on the left (see the module docstring)."""
        if self.busy or not self.link.all_connected:
            return
        self.setup.save(self.settings)
        try:
            request = self.setup.request(self.confirm_timeout_s)
            out_dir = Path(request.out_dir)
            try:
                out_dir.mkdir(parents=True, exist_ok=True)
            except OSError as exc:
                raise ConfigError(f"shot folder {out_dir}: cannot create it: {exc.strerror or exc}") from None
            request.check(self.config)
        except ConfigError as exc:
            self.show_banner("error", f"Not armed: {exc}")
            self.log_view.add_message("error", f"not armed: {exc}")
            return
        self.request = request
        self.busy = True
        self.awaiting_confirmation = False
        self.state_bar.reset()
        self.state_bar.set_text("starting the shot…")
        self.hide_banner()
        self.plots.clear("Shot running…")
        what = f"{request.accelerometer_model} {request.accelerometer_serial}".strip()
        self.log_view.add_message("info", f"ARM: {request.pressure_bar:g} bar, projectile No. {request.projectile}"
                                          + (f", {what}" if what else ""))
        self.authorisation = self.link.start_shot(request, self.setup.conditioner_entry())
        self.update_buttons()

    def fire(self) -> None:
        """FIRE: confirm, then give the authorisation the armed sequencer waits for."""
        if not self.fire_allowed():
            self.update_buttons()
            return
        if not self.confirm_fire():
            self.log_view.add_message("info", "FIRE not confirmed: the rig stays armed (ABORT to stand down)")
            return
        if not self.fire_allowed():  # an interlock may have gone while the dialog was open
            self.show_banner("error", "Not fired: an interlock dropped while confirming.")
            return
        self.authorisation.give()
        self.awaiting_confirmation = False
        self.log_view.add_message("info", "FIRE confirmed by the operator")
        self.update_buttons()

    def abort(self) -> None:
        """ABORT: always; stops a running shot or campaign, or commands the valves safe."""
        self.log_view.add_message("warning", "ABORT pressed")
        if self.authorisation is not None and self.busy:
            self.authorisation.withdraw()
        self.show_banner("warning", "ABORT: making the rig safe (fire and fill closed, reservoir vented)…")
        self.link.abort("ABORT pressed on the panel")
        self.awaiting_confirmation = False
        self.update_buttons()

    def fire_allowed(self) -> bool:
        """FIRE's rule: the sequencer waits in ARM for the confirmation and every interlock holds."""
        if not (self.busy and self.awaiting_confirmation and self.authorisation is not None):
            return False
        if self.authorisation.given or self.state_bar.state != State.ARM:
            return False
        return self.interlocks_all_ok()

    def interlocks_all_ok(self) -> bool:
        """Did the last reading judge every interlock (as in ARM) and find each holding?"""
        reading = self.last_reading
        if reading is None:
            return False
        return all(reading.interlocks.get(name) is True for name in INTERLOCKS)

    def update_buttons(self) -> None:
        connected = self.link.all_connected
        self.arm_button.setEnabled(not self.busy and connected)
        self.arm_button.setToolTip("" if connected else "cannot arm: not every instrument is connected")
        self.fire_button.setEnabled(self.fire_allowed())
        self.abort_button.setEnabled(True)
        if self._setup_enabled != (not self.busy):
            self._setup_enabled = not self.busy
            self.setup.set_enabled_for_shot(self._setup_enabled)
        self.campaign_tab.update_buttons()

    # -- banner -------------------------------------------------------------------------------------
    def show_banner(self, level: str, text: str) -> None:
        self.banner_level = level
        self.banner.setStyleSheet(f"QLabel {{ {_BANNERS[level]} padding: 6px 10px; border-radius: 4px; "
                                  "font-size: 10pt; }")
        self.banner.setText(text)
        self.banner.setVisible(True)

    def hide_banner(self) -> None:
        self.banner.setVisible(False)
        self.banner_level = ""

    # -- rig events (GUI thread) ------------------------------------------------------------------------
    def _on_event(self, event: RigEvent) -> None:
        self.log_view.add_event(event)
        self.campaign_tab.on_event(event)
        if isinstance(event, Reading):
            self.last_reading = event
            self.status_panel.show_reading(event)
            self.plots.trend.add_reading(event.reservoir_pressure_bar, event.fixture_vacuum_mbar)
        elif isinstance(event, StateEntered):
            if event.state in State.__members__:
                self.state_bar.set_state(event.state, event.message)
            if event.state != State.ARM:
                self.awaiting_confirmation = False
            self.statusBar().showMessage(f"{event.state}: {event.message}")
        elif isinstance(event, AwaitingConfirmation | StepProgress | Fired):
            if isinstance(event, AwaitingConfirmation):
                self.awaiting_confirmation = True
                self.show_banner("info", "ARMED — every interlock is watched. Press FIRE to fire the shot "
                                         "(you will be asked to confirm), or ABORT to stand down.")
            if event.state in State.__members__:
                self.state_bar.set_text(event.message)
            self.statusBar().showMessage(f"{event.state}: {event.message}")
        elif isinstance(event, RigError):
            self.show_banner("error", with_hint(event.message, event.hint))
        elif isinstance(event, ShotFinished) and event.shot_path:
            self.load_shot(Path(event.shot_path))
        self.update_buttons()

    def _on_links(self, links: dict[str, InstrumentLink]) -> None:
        self.status_panel.set_links(links)
        if not links["valve_controller"].usable:
            self.status_panel.show_disconnected()
        down = [link.label for link in links.values() if link.status == "disconnected"]
        if down:
            self.statusBar().showMessage(f"not connected: {', '.join(down)} (retrying)")
        else:
            self.statusBar().showMessage("rig connected")
        self.update_buttons()

    def _on_message(self, level: str, text: str) -> None:
        self.log_view.add_message(level, text)
        if level == "error":
            self.show_banner("error", text)

    def _on_safe_done(self, ok: bool, text: str) -> None:
        self.log_view.add_message("info" if ok else "error", text)
        self.show_banner("ok" if ok else "error", text)

    def _on_shot_finished(self, outcome: ShotOutcome) -> None:
        self.last_outcome = outcome
        self._shot_ended()
        if outcome.done and not outcome.analysis_error:
            self.show_banner("ok", f"Shot done: {outcome.shot_path}")
        elif outcome.done:
            self.show_banner("warning", f"Shot recorded in {outcome.shot_path}, but {outcome.analysis_error}")
        elif outcome.final_state == State.FAULT:
            self.show_banner("error", f"FAULT — {outcome.error}. Check the rig by hand before anything else.")
        else:
            self.show_banner("error", with_hint(outcome.error or f"shot ended in {outcome.final_state}", outcome.hint))
        for warning in outcome.warnings:
            self.log_view.add_message("warning", warning)

    def _on_shot_failed(self, message: str) -> None:
        self._shot_ended()
        self.show_banner("error", f"Shot not run: {message}")
        self.log_view.add_message("error", f"shot not run: {message}")

    def _shot_ended(self) -> None:
        self.busy = False
        self.awaiting_confirmation = False
        self.authorisation = None
        self.update_buttons()

    def _campaign_started(self) -> None:
        self.busy = True
        self.hide_banner()
        self.state_bar.reset()
        self.update_buttons()

    def _campaign_ended(self) -> None:
        self.busy = False
        outcome = self.campaign_tab.last_outcome
        if outcome is None:
            self.show_banner("error", self.campaign_tab.message.text())
        elif outcome.exit_code == 0:
            self.show_banner("ok", f"Campaign: {outcome.message} ({outcome.run_folder})")
        else:
            last = outcome.last_shot
            self.show_banner("error", with_hint(f"Campaign: {outcome.message}", last.hint if last is not None else ""))
        self.update_buttons()

    # -- shots ----------------------------------------------------------------------------------------
    def load_shot(self, path: Path) -> None:
        """Read a shot file off the GUI thread and show it in the Shot and DCM tabs."""
        self.background.run(lambda: load_shot_view(path), self.show_shot_view,
                            lambda exc: self._shot_not_loaded(path, exc))

    def _shot_not_loaded(self, path: Path, exc: BaseException) -> None:
        self.log_view.add_message("error", f"{path}: not shown: {exc}")
        self.plots.clear(f"{path}: could not be shown: {exc}")
        self.shot_view_failed.emit(f"{path}: could not be shown: {exc}")

    def show_shot_view(self, view: ShotView) -> None:
        self.last_view = view
        self.plots.show_view(view)
        if view.model is not None and view.dcm is not None:
            design = view.dcm.design or {}
            self.dcm_tab.set_model(view.model, design.get("ratio", 1.0), design.get("damping", 0.707),
                                   [complex(*p) for p in design.get("extra_poles", [])], view.record,
                                   source=view.path.name if view.path else "", shot_path=view.path,
                                   support=view.support, band_limit_hz=view.band_limit_hz,
                                   not_recommended_reason=(view.compensation.not_recommended_text
                                                           if view.compensation else None))
        self.shot_view_shown.emit(view)

    def export_report(self, path: Path) -> None:
        """Write the calibration report of the shot shown (PDF or HTML, by suffix) off the GUI
        thread; it reports the shot as analysed (hopkinson report), not a DCM tuned in the tab."""
        view = self.last_view
        if view is None or view.path is None:
            self.show_banner("warning", "No shot to report on yet.")
            return
        from hopkinson.fileio import UnsafeOutputError, check_output_path

        try:  # never over the shot itself or another shot file (issue 18)
            check_output_path(path, [view.path], what="report")
        except UnsafeOutputError as exc:
            self.show_banner("error", f"Report not written: {exc}")
            return

        def write() -> Path:
            from hopkinson.reports.writers import write_report
            from hopkinson.rig.report_data import shot_report

            return write_report(shot_report(view.path), [path])[0]

        self.background.run(write, lambda p: self.show_banner("ok", f"Report written to {p}"),
                            lambda exc: self.show_banner("error", f"Report not written: {exc}"))
