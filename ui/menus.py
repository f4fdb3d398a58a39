"""The panel's menu bar and keyboard shortcuts.

File: open a shot file, export the shot's report, its DCM, the campaign's report and
certificate, save the log, quit. Rig: reconnect, ARM (F5), FIRE (Ctrl+Shift+F), ABORT (Esc),
make safe. Help: keyboard shortcuts, about (with the version).

FIRE's shortcut is guarded exactly as its button: it calls the window's `fire()`, which does
nothing unless the sequencer waits armed with every interlock holding, and then asks for the
explicit confirmation (default No). ABORT (Esc) works from anywhere in the main window; in a
dialog Esc closes the dialog only.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from PySide6.QtCore import Qt
from PySide6.QtGui import QAction, QKeySequence
from PySide6.QtWidgets import QMainWindow, QMenu, QMessageBox

ARM_KEY = "F5"
FIRE_KEY = "Ctrl+Shift+F"
ABORT_KEY = "Esc"
SHORTCUTS = (
    (ARM_KEY, "ARM: check, evacuate, charge and arm the shot set up on the left"),
    (FIRE_KEY, "FIRE the armed shot (only when FIRE is lit; asks for confirmation)"),
    (ABORT_KEY, "ABORT: stop now and make the rig safe"),
    ("Ctrl+O", "open a shot file"),
    ("Ctrl+E", "export the shot's calibration report"),
    ("Ctrl+Q", "quit (asks first while a shot or campaign runs)"),
)


def build_menus(window: Any) -> dict[str, QAction]:
    """Add the menu bar to `window` (ui.main_window.MainWindow); its actions by name."""
    bar = window.menuBar()
    actions: dict[str, QAction] = {}

    def add(menu: QMenu, name: str, text: str, slot: Callable[[], Any], key: str = "") -> QAction:
        action = QAction(text, window)
        if key:
            action.setShortcut(QKeySequence(key))
            action.setShortcutContext(Qt.ShortcutContext.WindowShortcut)
        action.triggered.connect(lambda _checked=False: slot())
        menu.addAction(action)
        actions[name] = action
        return action

    file_menu = bar.addMenu("&File")
    add(file_menu, "open_shot", "&Open shot file…", window.open_shot_dialog, "Ctrl+O")
    file_menu.addSeparator()
    add(file_menu, "export_report", "Export shot &report…", window.export_report_dialog, "Ctrl+E")
    add(file_menu, "export_dcm", "Export &DCM…", window.dcm_tab.export_dcm_dialog)
    add(file_menu, "campaign_report", "Campaign report…", window.campaign_tab.write_report_dialog)
    add(file_menu, "certificate", "Issue &certificate…", window.campaign_tab.certificate_dialog)
    add(file_menu, "save_log", "Save &log…", window.log_tab.save_dialog)
    file_menu.addSeparator()
    add(file_menu, "quit", "&Quit", window.close, "Ctrl+Q")

    rig_menu = bar.addMenu("&Rig")
    add(rig_menu, "reconnect", "Re&connect the instruments", window.reconnect)
    rig_menu.addSeparator()
    add(rig_menu, "arm", "&ARM", window.arm, ARM_KEY)
    add(rig_menu, "fire", "&FIRE… (when lit)", window.fire, FIRE_KEY)
    # the main window's: Esc in a dialog (a file dialog, FIRE's confirmation) closes that dialog only
    add(rig_menu, "abort", "A&BORT", window.abort, ABORT_KEY)
    add(rig_menu, "safe", "Make &safe (vent, valves closed)", window.abort)

    help_menu = bar.addMenu("&Help")
    add(help_menu, "shortcuts", "&Keyboard shortcuts", lambda: show_shortcuts(window))
    add(help_menu, "about", "&About", lambda: show_about(window))
    return actions


def about_text() -> str:
    from hopkinson.rig.shotfile import software_version

    return (f"hopkinson {software_version()}\n\nHopkinson-bar shock calibration of high-g accelerometers: "
            "the rig, its shots and campaigns, the sensor's dynamic model, its uncertainty (GUM-S1), "
            "FBSD and DCM, reports and the lab's record.")


def show_about(window: QMainWindow) -> None:
    QMessageBox.about(window, "About the hopkinson panel", about_text())


def show_shortcuts(window: QMainWindow) -> None:
    QMessageBox.information(window, "Keyboard shortcuts", "\n".join(f"{key}\t{what}" for key, what in SHORTCUTS))
