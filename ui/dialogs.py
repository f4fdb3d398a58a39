"""The panel's questions to the technician, each a modal dialog whose default answer is the safe
one (No, Cancel, Keep running). The window and the Campaign tab call them through their own
seams (`confirm_fire`, `confirm_setup`, `ask_close`, `confirm_campaign`, …), which tests replace."""

from __future__ import annotations

from PySide6.QtWidgets import QInputDialog, QMessageBox, QWidget

_YES, _NO = QMessageBox.StandardButton.Yes, QMessageBox.StandardButton.No


def ask_yes_no(parent: QWidget, title: str, text: str) -> bool:
    """A warning answered Yes or No; No is the default (Enter, Esc)."""
    return QMessageBox.warning(parent, title, text, _YES | _NO, _NO) == _YES


def ask_fire(parent: QWidget, text: str) -> bool:
    """FIRE's confirmation: an explicit Yes fires."""
    return ask_yes_no(parent, "Fire the shot?", text)


def ask_arm_anyway(parent: QWidget, problems: list[str]) -> bool:
    """A set-up that misses its target or exceeds the sensor's range: arm it anyway?"""
    return ask_yes_no(parent, "The set-up does not match the plan",
                      "ARM anyway?\n\n" + "\n".join(f"• {p}" for p in problems)
                      + "\n\nChange the pressure or projectile (the planner's \"Use\" sets them for the target), or "
                        "answer Yes to arm as set.")


def _choose(parent: QWidget, icon: QMessageBox.Icon, title: str, text: str, detail: str,
            choices: list[tuple[str, str, QMessageBox.ButtonRole]], default: str) -> str:
    """A question with named answers (key, label, role); the key of the one clicked (Esc: `default`)."""
    box = QMessageBox(icon, title, text, parent=parent)
    box.setInformativeText(detail)
    buttons = {key: box.addButton(label, role) for key, label, role in choices}
    box.setDefaultButton(buttons[default])
    box.setEscapeButton(buttons[default])
    box.exec()
    return next((key for key, button in buttons.items() if box.clickedButton() is button), default)


def ask_close(parent: QWidget) -> str:
    """Closing while a shot or campaign runs: "finish", "abort" or "cancel" (the default)."""
    role = QMessageBox.ButtonRole
    return _choose(parent, QMessageBox.Icon.Question, "A shot is running",
                   "A shot or campaign is running. Close the panel?",
                   "Finish: the shot now running is stored and analysed, then the panel closes (a campaign stops "
                   "after it; Resume continues it).\nAbort: the shot is aborted and the rig made safe now; a shot "
                   "already fired keeps its raw data and is marked for re-analysis.",
                   [("finish", "Finish this shot, then close", role.AcceptRole),
                    ("abort", "Abort now and close", role.DestructiveRole),
                    ("cancel", "Keep running", role.RejectRole)], "cancel")


def ask_campaign_authorisation(parent: QWidget, name: str, shots: int, sensor: str) -> str:
    """A plan that does not authorise firing: "each" (confirm each shot with FIRE), "all" or "cancel"."""
    role = QMessageBox.ButtonRole
    return _choose(parent, QMessageBox.Icon.Warning, "Authorise the campaign",
                   f"The plan {name!r} does not authorise firing. Fire its {shots} shots on {sensor}?",
                   "Confirm each shot: every shot is armed and waits for FIRE, as a single shot does.",
                   [("each", "Confirm each shot", role.AcceptRole),
                    ("all", f"Fire all {shots}", role.DestructiveRole),
                    ("cancel", "Cancel", role.RejectRole)], "cancel")


def ask_shot_count(parent: QWidget, name: str, shots: int, above: int, most: int) -> int | None:
    """The number of shots of a large plan, typed (None: cancelled)."""
    value, ok = QInputDialog.getInt(parent, "Confirm the number of shots",
                                    f"The plan {name!r} fires {shots} shots, more than {above}.\n\n"
                                    "Type its number of shots to fire them:", 0, 0, most)
    return value if ok else None


def ask_name(parent: QWidget, title: str, label: str) -> str | None:
    """A name typed (None: cancelled or empty)."""
    name, ok = QInputDialog.getText(parent, title, label)
    return name.strip() if ok and name.strip() else None
