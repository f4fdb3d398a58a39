"""The panel's main window: state and ARM / FIRE / ABORT on top, one message line under them,
rig status and shot set-up on the left, the shot (verdict, figures, plots), the DCM design, the
campaign, the sensor's history and the log in tabs; a menu bar and shortcuts (ui.menus).

Rules the buttons follow:
- ARM: every instrument connected and no shot running. Before anything moves, the set-up is
  compared with its target and the sensor's range (ui.setup_check): a shot predicted to miss
  the target by more than the level tolerance, or to exceed the range, is armed only when the
  technician says so (`confirm_setup`, a dialog defaulting to No). It then starts the shot on
  the rig I/O thread (ui.worker.RigLink); the sequencer checks, evacuates, charges and arms,
  then waits for the fire confirmation (ShotRequest.confirm_timeout_s).
- FIRE: enabled only while the sequencer waits in ARM for the confirmation AND the last
  reading shows every interlock holding. It asks for an explicit confirmation stating the
  predicted peak, pulse width and band (`confirm_fire`, a dialog defaulting to No; tests and
  --demo-shot replace it) and then gives the FireAuthorisation. The sequencer reads the
  interlocks again before it opens the valve. A campaign whose firing is confirmed shot by
  shot uses the same FIRE for each of its shots.
- ABORT: always enabled. A running shot is aborted (the sequencer runs SAFE); with no shot
  running the sequencer does SAFE's work without a shot (Sequencer.make_safe).

Messages: one line under the buttons, always two lines high (ui.widgets.Banner): what the rig
does now, red for errors, amber for warnings, green for success; the full text of every message
is in the Log tab. Never a traceback or a frozen window: every instrument call runs off the GUI
thread.

Closing while a shot or campaign runs asks first (`ask_close`): finish the shot now running
(it keeps its analysis), or abort it now (a shot already fired keeps its raw data and is marked
for re-analysis: the campaign's Resume or `hopkinson analyse` redoes it), or keep running.
The window's size, position, maximised state and last tab are remembered.
"""

from __future__ import annotations

import logging
from pathlib import Path
from typing import Any

from PySide6.QtCore import QSettings, QTimer, Signal
from PySide6.QtGui import QCloseEvent
from PySide6.QtWidgets import (
    QFileDialog,
    QMainWindow,
    QTabWidget,
)

from hopkinson.rig.config import RigConfig
from hopkinson.rig.errors import ConfigError, with_hint
from hopkinson.rig.events import (
    AwaitingConfirmation,
    CampaignShotStarted,
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
from hopkinson.ui.campaign_tab import CampaignTab, campaign_end_message
from hopkinson.ui.dcm_tab import DcmTab
from hopkinson.ui.dialogs import ask_arm_anyway, ask_close, ask_fire
from hopkinson.ui.log_view import LogTab, LogView
from hopkinson.ui.menus import build_menus
from hopkinson.ui.plots import ShotView, configure_pyqtgraph, load_shot_view
from hopkinson.ui.sensor_tab import SensorTab
from hopkinson.ui.setup_check import SetupPrediction, fire_question, predict_setup
from hopkinson.ui.shot_setup import ShotSetup
from hopkinson.ui.shot_tab import ShotPlots, verdict_level
from hopkinson.ui.state_bar import STATE_MESSAGES, StateBar, action_buttons, header_row
from hopkinson.ui.status_panel import StatusPanel
from hopkinson.ui.widgets import Banner
from hopkinson.ui.window_layout import central_widget, left_column
from hopkinson.ui.worker import Background, InstrumentLink, RigLink

_log = logging.getLogger(__name__)

DEFAULT_CONFIRM_TIMEOUT_S = 600.0  # how long the armed rig waits for a human to press FIRE
MIN_SIZE = (1280, 800)
FIRED_STATES = (State.FIRE, State.CAPTURE, State.SAFE, State.STORE, State.ANALYSE)

# QSettings keys of the window itself
GEOMETRY_KEY, TAB_KEY = "window/geometry", "window/tab"


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
        self.prediction: SetupPrediction | None = None  # the armed shot's, for FIRE's confirmation
        self.busy = False  # a shot or a campaign runs (from ARM / Run until its end is reported)
        self.awaiting_confirmation = False
        self.last_reading: Reading | None = None
        self.last_outcome: ShotOutcome | None = None
        self.last_view: ShotView | None = None
        self._setup_enabled: bool | None = None
        self._armed_text = "The armed shot"  # a campaign shot's, for FIRE's confirmation
        self._announce: Path | None = None  # the shot whose verdict the message line gives when shown
        self._close_when_idle = False  # "finish the shot, then close" was chosen
        self._closing = False

        self.setWindowTitle("Hopkinson-bar shock calibration" + (f" — {title_note}" if title_note else ""))
        self.setMinimumSize(*MIN_SIZE)

        # header: state, the buttons, the message line
        self.state_bar = StateBar()
        self.arm_button, self.fire_button, self.abort_button = action_buttons()
        self.banner = Banner()
        header = header_row(self.state_bar, title_note, (self.arm_button, self.fire_button, self.abort_button))

        # left: status and set-up
        self.status_panel = StatusPanel(config.limits)
        self.setup = ShotSetup(config, out_dir, background=self.background)
        self.setup.load(self.settings)
        self.left_scroll = left_column(self.status_panel, self.setup)

        # tabs
        self.plots = ShotPlots()
        self.dcm_tab = DcmTab(export_report=self.export_report)
        self.campaign_tab = CampaignTab(self.link, self.background, runs_dir, config)
        self.campaign_tab.conditioner_entry = self.setup.conditioner_entry  # a hand-set conditioner's values
        self.campaign_tab.confirm_timeout_s = confirm_timeout_s
        self.log_view = LogView()
        self.log_tab = LogTab(self.log_view, default_folder=out_dir)
        self.tabs = QTabWidget()
        self.tabs.addTab(self.plots, "Shot")
        self.tabs.addTab(self.dcm_tab, "DCM design")
        self.tabs.addTab(self.campaign_tab, "Campaign")
        self.sensor_tab = SensorTab(self.background, config.database.url, config.lab.decision_rule)
        self.tabs.addTab(self.sensor_tab, "Sensor history")
        self.tabs.addTab(self.log_tab, "Log")

        self.setCentralWidget(central_widget(header, self.banner, self.left_scroll, self.tabs))
        self.statusBar().showMessage("connecting to the rig…")
        self.actions = build_menus(self)

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
        self.campaign_tab.open_shot.connect(self.open_shot)
        self.campaign_tab.say.connect(self._on_message)
        self.setup.refused.connect(self._on_refused)
        self.setup.advice.connect(self._on_advice)
        self.tabs.currentChanged.connect(self._tab_changed)
        self.status_panel.set_links(self.link.links)
        self.restored_geometry = self._restore_window()
        self.hide_banner()
        self.update_buttons()

    # -- start / stop -------------------------------------------------------------------------------
    def start(self) -> None:
        """Connect to the rig and start the idle readings."""
        self.link.start()

    def closeEvent(self, event: QCloseEvent) -> None:  # noqa: N802 (Qt's name)
        if self.busy and not self._closing and not self.link.interrupted_reason:
            choice = self.ask_close()
            if choice == "cancel":
                event.ignore()
                return
            if choice == "finish" and self.state_bar.state in FIRED_STATES:
                self._close_when_idle = True
                if self.link.campaign_running:
                    self.link.pause_campaign()
                self.show_banner("warning", "Closing once the shot now running is stored and analysed "
                                            "(the campaign stops after it)…")
                event.ignore()
                return
            self.log_view.add_message("warning", "closing: the shot now running is aborted (the rig goes safe)")
        self._closing = True
        self._save_window()
        if self.busy:
            self.statusBar().showMessage("aborting the shot and making the rig safe before closing…")
        self.link.shutdown()
        self.background.shutdown()
        super().closeEvent(event)

    def _restore_window(self) -> bool:
        """Size, position, maximised state and the last tab, as they were (True when found)."""
        geometry = self.settings.value(GEOMETRY_KEY)
        tab = self.settings.value(TAB_KEY)
        if tab is not None and str(tab).isdigit() and int(tab) < self.tabs.count():
            self.tabs.setCurrentIndex(int(tab))
        return bool(geometry) and self.restoreGeometry(geometry)

    def _save_window(self) -> None:
        self.setup.save(self.settings)
        self.settings.setValue(GEOMETRY_KEY, self.saveGeometry())
        self.settings.setValue(TAB_KEY, self.tabs.currentIndex())
        self.settings.sync()

    # -- seams --------------------------------------------------------------------------------------
    def confirm_fire(self) -> bool:
        """Ask the operator to confirm the shot (explicit Yes; the default is No)."""
        return ask_fire(self, self.fire_question())

    def fire_question(self) -> str:
        """FIRE's confirmation: what is armed and what the bar model predicts for it."""
        r = self.request
        what = (f"Reservoir {r.pressure_bar:g} bar, projectile No. {r.projectile}, accelerometer "
                f"{r.accelerometer_model or '—'} {r.accelerometer_serial}".rstrip()) if r else self._armed_text
        return fire_question(what, self.prediction)

    def confirm_setup(self, problems: list[str]) -> bool:
        """Ask whether to arm a set-up that misses its target or exceeds the sensor's range (default No)."""
        return ask_arm_anyway(self, problems)

    def ask_close(self) -> str:
        """Closing while a shot or campaign runs: "finish", "abort" or "cancel"."""
        return ask_close(self)

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
        prediction = self.setup.prediction()
        problems = prediction.problems() if prediction is not None else []
        if problems and not self.confirm_setup(problems):
            self.show_banner("warning", "Not armed: " + "; ".join(problems) + ". Change the set-up, or ARM again "
                                        "and confirm.")
            self.log_view.add_message("warning", "not armed (set-up against the plan): " + "; ".join(problems))
            return
        for problem in problems:
            self.log_view.add_message("warning", f"armed although {problem} (confirmed)")
        self.request, self.prediction = request, prediction
        self.busy = True
        self.awaiting_confirmation = False
        self.state_bar.reset()
        self.state_bar.set_text("starting the shot…")
        self.show_banner("info", STATE_MESSAGES[State.CHECK])
        self.plots.clear("Shot running…")
        what = f"{request.accelerometer_model} {request.accelerometer_serial}".strip()
        self.log_view.add_message("info", f"ARM: {request.pressure_bar:g} bar, projectile No. {request.projectile}"
                                          + (f", {what}" if what else "")
                                          + (f"; predicted {prediction.summary()}" if prediction else ""))
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
        if self._closing:
            return
        self.log_view.add_message("warning", "ABORT pressed")
        if self.authorisation is not None and self.busy:
            self.authorisation.withdraw()
        self.show_banner("warning", "ABORT: making the rig safe (fire and fill closed, reservoir vented)…")
        self.link.abort("ABORT pressed on the panel")
        self.awaiting_confirmation = False
        self.update_buttons()

    def _predict(self, projectile: int, pressure_bar: float, target_m_s2: float | None) -> SetupPrediction | None:
        try:
            return predict_setup(self.config.bar.rig(), projectile, pressure_bar, target_m_s2)
        except ValueError:
            return None

    def reconnect(self) -> None:
        """Rig ▸ Reconnect: try every instrument not answering now (it is retried every few s anyway)."""
        self.link.retry_now()
        self.show_banner("info", "Reconnecting the instruments that are not answering…")

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
        fire = self.fire_allowed()
        self.fire_button.setEnabled(fire)
        self.actions["fire"].setEnabled(fire)
        self.actions["arm"].setEnabled(not self.busy and connected)
        self.abort_button.setEnabled(True)
        if self._setup_enabled != (not self.busy):
            self._setup_enabled = not self.busy
            self.setup.set_enabled_for_shot(self._setup_enabled)
        self.campaign_tab.update_buttons()

    # -- messages -------------------------------------------------------------------------------------
    @property
    def banner_level(self) -> str:
        """The message line's level ("" when it only says what to do next)."""
        return "" if self.banner.level == "idle" else self.banner.level

    def show_banner(self, level: str, text: str) -> None:
        self.banner.show_message(level, text)

    def hide_banner(self) -> None:
        """Back to saying what to do next."""
        self.banner.show_message("idle", "Set up the shot on the left and press ARM (F5); open a shot file with "
                                         "Ctrl+O; a campaign runs from its tab.")

    def _on_advice(self, level: str, text: str) -> None:
        """What the lab's record says of the set-up's sensor (ui.sensor_lookup)."""
        if not self.busy:
            self.show_banner(level, text)
            self.log_view.add_message("warning" if level == "warning" else "info", text)

    def _on_refused(self, text: str) -> None:
        self.show_banner("warning", f"Not taken: {text}.")
        self.log_view.add_message("warning", f"not taken: {text}")

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
                self._follow_state(State(event.state))
            if event.state != State.ARM:
                self.awaiting_confirmation = False
            self.statusBar().showMessage(f"{event.state}: {event.message}")
        elif isinstance(event, AwaitingConfirmation | StepProgress | Fired):
            if isinstance(event, AwaitingConfirmation):
                self.awaiting_confirmation = True
                if self.authorisation is None and self.link.shot_authorisation is not None:
                    self.authorisation = self.link.shot_authorisation  # a campaign shot confirmed on its own
                self.show_banner("info", "ARMED — every interlock is watched. Press FIRE to fire the shot "
                                         "(you will be asked to confirm), or ABORT to stand down.")
            if event.state in State.__members__:
                self.state_bar.set_text(event.message)
            self.statusBar().showMessage(f"{event.state}: {event.message}")
        elif isinstance(event, CampaignShotStarted):
            self.authorisation = None  # the next shot's own, when it is confirmed shot by shot
            self.request = None
            self.prediction = self._predict(event.projectile, event.pressure_bar, event.target_peak_m_s2)
            self._armed_text = (f"Campaign shot {event.shot_id} ({event.index} of {event.total}): reservoir "
                                f"{event.pressure_bar:.3g} bar, projectile No. {event.projectile}")
            self.show_banner("info", f"Campaign: shot {event.index} of {event.total} ({event.shot_id}) — "
                                     f"{event.message.removeprefix(f'shot {event.shot_id}: ')}")
        elif isinstance(event, RigError):
            self.show_banner("error", with_hint(event.message, event.hint))
        elif isinstance(event, ShotFinished) and event.shot_path:
            self.load_shot(Path(event.shot_path))
        self.update_buttons()

    def _follow_state(self, state: State) -> None:
        """The message line follows the shot (it never keeps saying ARMED once fired)."""
        text = STATE_MESSAGES.get(state)
        if text is not None and self.busy and self.banner.level in ("info", "idle"):
            self.show_banner("info", text)

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
        if level in ("error", "warning", "ok"):
            self.show_banner(level, text)

    def _on_safe_done(self, ok: bool, text: str) -> None:
        self.log_view.add_message("info" if ok else "error", text)
        self.show_banner("ok" if ok else "error", text[:1].upper() + text[1:])

    def _on_shot_finished(self, outcome: ShotOutcome) -> None:
        self.last_outcome = outcome
        self._announce = outcome.shot_path
        self._shot_ended()
        if outcome.done and not outcome.analysis_error:
            self.show_banner("ok", f"Shot done and analysed: {outcome.shot_path.name if outcome.shot_path else ''} "
                                   "— its verdict follows.")
        elif outcome.done:
            self.show_banner("error", f"The shot is recorded ({outcome.shot_path}), but its analysis failed: "
                                      f"{outcome.analysis_error.removeprefix('analysis failed: ')}. Re-analyse it "
                                      "or repeat the shot.")
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
        self._close_if_asked()

    def _campaign_started(self) -> None:
        self.busy = True
        self.authorisation = None
        self.show_banner("info", "Campaign starting: checking the plan against the rig…")
        self.state_bar.reset()
        self.update_buttons()

    def _campaign_ended(self) -> None:
        self.busy = False
        self.authorisation = None
        self.awaiting_confirmation = False
        level, text = campaign_end_message(self.campaign_tab.last_outcome, self.campaign_tab.message.text())
        self.show_banner(level, text)
        self.update_buttons()
        self._close_if_asked()

    def _close_if_asked(self) -> None:
        if self._close_when_idle and not self.busy:
            self._closing = True
            QTimer.singleShot(0, self.close)

    # -- tabs ---------------------------------------------------------------------------------------------
    def _tab_changed(self, index: int) -> None:
        """The Sensor history opens on the sensor set up for the shot (unless another was typed)."""
        if self.tabs.widget(index) is self.sensor_tab:
            self.sensor_tab.prefill(self.setup.accelerometer_serial.text().strip())

    # -- shots ----------------------------------------------------------------------------------------
    def open_shot_dialog(self) -> None:
        name, _ = QFileDialog.getOpenFileName(self, "Open a shot file", self.setup.out_dir.text(),
                                              "Shot files (*.h5);;all files (*)")
        if name:
            self.open_shot(Path(name))

    def open_shot(self, path: Path) -> None:
        """Show a shot file the technician chose, and its verdict in the message line."""
        self._announce = Path(path)
        self.tabs.setCurrentWidget(self.plots)
        self.load_shot(Path(path))

    def load_shot(self, path: Path) -> None:
        """Read a shot file off the GUI thread and show it in the Shot and DCM tabs."""
        self.background.run(lambda: load_shot_view(path), self.show_shot_view,
                            lambda exc: self._shot_not_loaded(path, exc))

    def _shot_not_loaded(self, path: Path, exc: BaseException) -> None:
        self.log_view.add_message("error", f"{path}: not shown: {exc}")
        self.plots.clear(f"{path.name}: could not be shown: {exc}")
        self.show_banner("error", f"{path.name} could not be shown: {exc}")
        self.shot_view_failed.emit(f"{path}: could not be shown: {exc}")

    def show_shot_view(self, view: ShotView) -> None:
        self.last_view = view
        self.plots.show_view(view)
        self.dcm_tab.show_shot(view)
        if view.judgement is not None and view.path is not None and view.path == self._announce:
            verdict = view.judgement.verdict
            self.show_banner(verdict_level(verdict), f"{view.path.name}: {verdict.decision.value} — {verdict.reason}")
            self.log_view.add_message("result", f"{view.path.name}: {verdict.line()}")
        self.shot_view_shown.emit(view)

    def export_report_dialog(self) -> None:
        view = self.last_view
        if view is None or view.path is None:
            self.show_banner("warning", "No shot to report on yet: fire or open a shot first.")
            return
        name, _ = QFileDialog.getSaveFileName(self, "Export the calibration report",
                                              str(view.path.with_name(view.path.stem + "-report.pdf")),
                                              "PDF report (*.pdf);;HTML report (*.html)")
        if name:
            self.export_report(Path(name))

    def export_report(self, path: Path) -> None:
        """Write the calibration report of the shot shown (PDF or HTML, by suffix) off the GUI
        thread; it reports the shot as analysed (hopkinson report), not a DCM tuned in the tab."""
        view = self.last_view
        if view is None or view.path is None:
            self.show_banner("warning", "No shot to report on yet: fire or open a shot first.")
            return
        from hopkinson.fileio import UnsafeOutputError, check_output_path

        try:  # never over the shot itself or another shot file
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
