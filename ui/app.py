"""Start the panel: `run_panel(args)` behind `hopkinson panel`.

    hopkinson panel [--config PATH | --sim [--sim-config PATH] [--sim-fault NAME ...]]
                    [--out DIR] [--runs DIR] [--demo-shot] [--screenshot PATH]

--sim starts a simulated rig in-process (free ports, a pty) and points the panel at it; the
rig configuration is then config/rig-sim.toml (only its limits, timeouts and analysis
constants are used). Set-ups are remembered per mode (QSettings "hopkinson"/"panel" for the
real rig, "panel-sim" for the simulator), so simulation never overwrites a real set-up.

--demo-shot (with --sim): fires one shot with the confirmation accepted, waits for its
analysis to be drawn, then (with --screenshot PATH) saves a picture of the whole window
(1280 × 800) and exits: 0 when the shot was done and analysed, 3 when it was aborted or its
analysis failed (one line on stderr), also 3 when it did not finish within DEMO_TIMEOUT_S.
With --screenshot and no display, Qt's offscreen platform is used.
"""

from __future__ import annotations

import argparse
import contextlib
import os
import sys
import tempfile
import traceback
from pathlib import Path
from typing import Any

from hopkinson.fileio import atomic_write
from hopkinson.rig.config import load_rig_config, load_sim_config
from hopkinson.rig.config_paths import DEFAULT_SIM_RIG_CONFIG, default_rig_config
from hopkinson.rig.errors import ConfigError

SCREENSHOT_SIZE = (1280, 800)
DEMO_TIMEOUT_S = 180.0
EXIT_DEMO_FAILED = 3


def _use_offscreen_without_display() -> None:
    """Screenshots need no screen: fall back to Qt's offscreen platform without one."""
    if os.environ.get("QT_QPA_PLATFORM"):
        return
    if sys.platform.startswith("linux") and not (os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")):
        os.environ["QT_QPA_PLATFORM"] = "offscreen"


def run_panel(args: argparse.Namespace) -> int:
    """Run the panel until its window is closed (or the demo shot is done); the exit code."""
    if args.demo_shot and not args.sim:
        raise ConfigError("--demo-shot needs --sim (it fires a shot without asking)")
    if args.sim_fault and not args.sim:
        raise ConfigError("--sim-fault needs --sim")
    if args.screenshot is not None and not Path(args.screenshot).parent.resolve().is_dir():
        raise ConfigError(f"--screenshot: folder {Path(args.screenshot).parent} does not exist")
    if args.screenshot is not None:
        _use_offscreen_without_display()
    config = load_rig_config(args.config or (DEFAULT_SIM_RIG_CONFIG if args.sim else default_rig_config()))

    try:
        from PySide6.QtCore import QSettings
        from PySide6.QtWidgets import QApplication
    except ImportError as exc:  # Qt's system libraries missing
        raise ConfigError(f"the panel needs Qt (PySide6) and its system libraries: {exc}") from None

    with contextlib.ExitStack() as stack:
        truth = None
        note = ""
        if args.sim:
            from hopkinson.rig.sim_session import sim_session

            session = stack.enter_context(sim_session(config, load_sim_config(args.sim_config), args.sim_fault))
            config, truth = session.config, session.simulated_truth
            note = "SIMULATED RIG" + (f" (faults: {', '.join(args.sim_fault)})" if args.sim_fault else "")
        app = QApplication.instance() or QApplication(sys.argv[:1])
        app.setApplicationName("hopkinson panel")
        if args.demo_shot:
            tmp = stack.enter_context(tempfile.TemporaryDirectory(prefix="hopkinson-panel-"))
            settings = QSettings(str(Path(tmp) / "settings.ini"), QSettings.Format.IniFormat)
        else:
            settings = QSettings("hopkinson", "panel-sim" if args.sim else "panel")

        from hopkinson.ui.main_window import MainWindow

        window = MainWindow(config, settings=settings, simulated_truth=truth, out_dir=args.out,
                            runs_dir=args.runs, title_note=note)
        errors: list[str] = []
        previous_hook = sys.excepthook
        sys.excepthook = _excepthook(window, errors)
        try:
            if args.screenshot is not None or args.demo_shot or not window.restored_geometry:
                window.resize(*SCREENSHOT_SIZE)  # else as the technician left it (ui.main_window)
            window.show()
            window.start()
            if args.demo_shot:
                return _demo_shot(app, window, args.screenshot, errors)
            if args.screenshot is not None:
                from PySide6.QtCore import QTimer

                QTimer.singleShot(1500, lambda: (_save_screenshot(window, Path(args.screenshot)), window.close()))
            app.exec()
            if window.link.interrupted_reason:  # a signal: the link aborted (or ran SAFE) before closing
                sys.stderr.write(f"hopkinson: error: {window.link.interrupted_reason}: {window.link.safe_summary()}\n")
                return 3
            return 0
        finally:
            sys.excepthook = previous_hook
            dispose(app, window)


def dispose(app: Any, window: Any) -> None:
    """Close and delete the window now, while Qt still runs: PySide6 6.12 with many pyqtgraph
    items can crash in the interpreter's final garbage collection when the widgets are left to it."""
    import gc

    from PySide6.QtCore import QCoreApplication, QEvent

    window.close()
    window.deleteLater()
    QCoreApplication.sendPostedEvents(None, QEvent.Type.DeferredDelete)
    app.processEvents()
    gc.collect()


def _excepthook(window: Any, errors: list[str]) -> Any:
    """Uncaught exceptions in Qt slots: one line in the log and the banner, never a dead window."""
    def hook(exc_type: type[BaseException], exc: BaseException, tb: Any) -> None:
        line = f"internal error: {exc_type.__name__}: {exc}"
        errors.append(line)
        sys.stderr.write("".join(traceback.format_exception(exc_type, exc, tb, limit=3)))
        with contextlib.suppress(Exception):
            window.log_view.add_message("error", line)
            window.show_banner("error", "The panel met an internal error (the rig is unaffected): "
                                        f"{exc or exc_type.__name__}. The details are in the Log tab.")
    return hook


def _save_screenshot(window: Any, path: Path) -> Path:
    """Grab the whole window (at least 1280 × 800) into a PNG, written atomically (hopkinson.fileio)."""
    from PySide6.QtWidgets import QApplication

    if window.width() < SCREENSHOT_SIZE[0] or window.height() < SCREENSHOT_SIZE[1]:
        window.resize(max(window.width(), SCREENSHOT_SIZE[0]), max(window.height(), SCREENSHOT_SIZE[1]))
    QApplication.processEvents()
    pixmap = window.grab()

    def save(tmp: Path) -> None:
        if not pixmap.save(str(tmp), "PNG"):
            raise OSError("Qt could not encode the picture")

    try:
        return atomic_write(path, save)
    except (OSError, ValueError) as exc:
        raise ConfigError(f"--screenshot: could not write {path}: {exc}") from None


def _demo_shot(app: Any, window: Any, screenshot: str | None, errors: list[str]) -> int:
    """Fire one shot with the confirmation accepted; screenshot once its analysis is drawn."""
    from PySide6.QtCore import QElapsedTimer, QTimer

    window.confirm_fire = lambda: True
    window.confirm_setup = lambda _problems: True  # the demo fires as set up, without asking
    setup = window.setup
    if not setup.operator.text():
        setup.operator.setText("demo")
    if not setup.accelerometer_model.text():
        setup.accelerometer_model.setText("SIM-ACC")
        setup.accelerometer_serial.setText("SIM0001")
    state: dict[str, Any] = {"armed": False, "code": None, "message": ""}
    clock = QElapsedTimer()
    clock.start()

    def finish(code: int, message: str = "") -> None:
        if state["code"] is not None:
            return
        state["code"], state["message"] = code, message
        if screenshot is not None:
            _save_screenshot(window, Path(screenshot))
        app.quit()

    def tick() -> None:
        if state["code"] is not None:
            return
        if clock.elapsed() > DEMO_TIMEOUT_S * 1000:
            window.abort()
            finish(EXIT_DEMO_FAILED, f"the demo shot did not finish within {DEMO_TIMEOUT_S:g} s")
            return
        if not state["armed"] and window.link.all_connected and not window.busy:
            state["armed"] = True
            window.tabs.setCurrentWidget(window.plots)
            window.arm()
        elif window.fire_allowed():
            window.fire()

    def settle() -> None:
        """Done once the shot has ended and (when a file was written) its view is drawn."""
        outcome = state.get("outcome")
        if outcome is None or (outcome.shot_path is not None and not state.get("view")):
            return
        if not outcome.done:
            finish(EXIT_DEMO_FAILED, outcome.error or f"shot ended in {outcome.final_state}")
        elif outcome.analysis_error:
            finish(EXIT_DEMO_FAILED, f"the shot is recorded but {outcome.analysis_error}")
        else:
            finish(0)

    def shot_finished(outcome: Any) -> None:
        state["outcome"] = outcome
        settle()

    def view_shown(_view: Any) -> None:
        def drawn() -> None:  # let the plots paint before the picture is taken
            state["view"] = True
            settle()
        QTimer.singleShot(400, drawn)

    def shot_failed(message: str) -> None:
        finish(EXIT_DEMO_FAILED, message)

    window.link.shot_finished.connect(shot_finished)
    window.link.shot_failed.connect(shot_failed)
    window.shot_view_shown.connect(view_shown)
    window.shot_view_failed.connect(lambda _message: view_shown(None))
    timer = QTimer(window)
    timer.timeout.connect(tick)
    timer.start(100)
    app.exec()
    timer.stop()
    if errors and state["code"] == 0:
        state["code"], state["message"] = 1, errors[0]
    if state["code"] is None:
        state["code"], state["message"] = EXIT_DEMO_FAILED, "the panel closed before the demo shot finished"
    if state["code"] != 0:
        sys.stderr.write(f"hopkinson: error: demo shot: {state['message']}\n")
    elif screenshot is not None:
        print(f"screenshot: {screenshot}", flush=True)
    return int(state["code"])
