"""The sequencer's progress as a row of steps, CHECK → … → DONE: done steps green, the current
one blue (red when the shot was aborted or faulted), with the current state's text beside; and
the window's header: that row, the simulation badge and the ARM / FIRE / ABORT buttons."""

from __future__ import annotations

from PySide6.QtCore import Qt
from PySide6.QtWidgets import QHBoxLayout, QLabel, QPushButton, QVBoxLayout, QWidget

from hopkinson.rig.sequencer import State

STEPS = (State.CHECK, State.EVACUATE, State.CHARGE, State.ARM, State.FIRE, State.CAPTURE, State.SAFE,
         State.STORE, State.ANALYSE, State.DONE)
_CHIP = ("QLabel {{ border-radius: 8px; padding: 1px 6px; font-size: 8pt; font-weight: 600; "
         "background: {bg}; color: {fg}; }}")
_STYLES = {
    "todo": _CHIP.format(bg="#eceff1", fg="#80868b"),
    "done": _CHIP.format(bg="#d7efdc", fg="#1e6b2e"),
    "current": _CHIP.format(bg="#1f6fd1", fg="white"),
    "failed": _CHIP.format(bg="#d0312d", fg="white"),
    "skipped": _CHIP.format(bg="#f6e1e0", fg="#b3261e"),
}
# What the message line says while the rig works through a shot (states not named: unchanged).
STATE_MESSAGES = {
    State.CHECK: "Preparing the shot: checking the interlocks, then evacuating and charging. ABORT (Esc) stands down.",
    State.FIRE: "FIRED — capturing the shot.",
    State.CAPTURE: "FIRED — capturing the shot.",
    State.SAFE: "Making the rig safe after the shot (valves closed, reservoir vented).",
    State.STORE: "Storing the raw shot.",
    State.ANALYSE: "Shot stored; analysing it (the result follows here).",
}
_STATE_COLOURS = {State.DONE: "#1e6b2e", State.ABORTED: "#b3261e", State.FAULT: "#b3261e", State.IDLE: "#3c4043"}


class StateBar(QWidget):
    """Big state name, its description, and the steps of a shot."""

    def __init__(self, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.state = State.IDLE
        self._visited: list[State] = []
        self.state_label = QLabel("IDLE")
        self.state_label.setMinimumWidth(150)
        self.state_label.setAlignment(Qt.AlignmentFlag.AlignLeft | Qt.AlignmentFlag.AlignVCenter)
        self.text_label = QLabel("no shot running")
        self.text_label.setStyleSheet("color: #3c4043; font-size: 10pt;")
        self.text_label.setWordWrap(True)
        self.chips: dict[State, QLabel] = {}
        chips = QHBoxLayout()
        chips.setSpacing(2)
        for i, step in enumerate(STEPS):
            chip = QLabel(step.value)
            chip.setStyleSheet(_STYLES["todo"])
            chip.setAlignment(Qt.AlignmentFlag.AlignCenter)
            self.chips[step] = chip
            chips.addWidget(chip)
            if i < len(STEPS) - 1:
                arrow = QLabel("›")
                arrow.setStyleSheet("color: #9aa0a6;")
                chips.addWidget(arrow)
        chips.addStretch(1)
        top = QHBoxLayout()
        top.setSpacing(12)
        top.addWidget(self.state_label)
        top.addWidget(self.text_label, 1)
        layout = QVBoxLayout(self)
        layout.setContentsMargins(0, 0, 0, 0)
        layout.setSpacing(2)
        layout.addLayout(top)
        layout.addLayout(chips)
        self._paint()

    def reset(self) -> None:
        """A new shot begins: every step to do."""
        self._visited = []
        self.state = State.IDLE
        self._paint()

    def set_state(self, state: str, text: str = "") -> None:
        """The sequencer entered `state` (its "state" event)."""
        s = State(state)
        if s == State.CHECK:
            self._visited = []
        if s not in self._visited:
            self._visited.append(s)
        self.state = s
        if text:
            self.text_label.setText(text)
        self._paint()

    def set_text(self, text: str) -> None:
        self.text_label.setText(text)

    def _paint(self) -> None:
        colour = _STATE_COLOURS.get(self.state, "#1f6fd1")
        self.state_label.setText(self.state.value)
        self.state_label.setStyleSheet(f"font-size: 20pt; font-weight: 700; color: {colour};")
        ended_badly = self.state in (State.ABORTED, State.FAULT)
        for step, chip in self.chips.items():
            if step == self.state:
                style = "current" if step != State.DONE else "done"
            elif step in self._visited:
                style = "done"
            elif ended_badly:
                style = "skipped"
            else:
                style = "todo"
            if ended_badly and step == self._last_working_step():
                style = "failed"
            chip.setStyleSheet(_STYLES[style])
            chip.setMinimumWidth(chip.fontMetrics().horizontalAdvance(chip.text()) + 18)

    def _last_working_step(self) -> State | None:
        """The step the shot was aborted in (the last one visited before SAFE)."""
        before_safe = [s for s in self._visited if s in STEPS[:6]]
        return before_safe[-1] if before_safe else None


_BUTTON = ("QPushButton {{ font-size: 15pt; font-weight: 700; padding: 8px 18px; border-radius: 6px; "
           "color: white; background: {bg}; border: 2px solid {border}; min-width: 96px; }} "
           "QPushButton:disabled {{ background: #e8eaed; color: #9aa0a6; border: 2px solid #dadce0; }} "
           "QPushButton:pressed {{ background: {border}; }}")
ARM_STYLE = _BUTTON.format(bg="#1f6fd1", border="#174ea6")
FIRE_STYLE = _BUTTON.format(bg="#e8710a", border="#b45309")
ABORT_STYLE = _BUTTON.format(bg="#d0312d", border="#8c1d18")


def action_buttons() -> tuple[QPushButton, QPushButton, QPushButton]:
    """ARM, FIRE and ABORT, big and coloured, each saying what it does and its shortcut."""
    arm, fire, abort = QPushButton("ARM"), QPushButton("FIRE"), QPushButton("ABORT")
    for button, style, tip in (
            (arm, ARM_STYLE, "check, evacuate, charge and arm the rig for the shot set up on the left (F5)"),
            (fire, FIRE_STYLE, "fire the armed shot (asks for confirmation); needs every interlock (Ctrl+Shift+F)"),
            (abort, ABORT_STYLE, "stop now and make the rig safe: fire and fill closed, reservoir vented (Esc)")):
        button.setStyleSheet(style)
        button.setToolTip(tip)
    return arm, fire, abort


def header_row(state_bar: StateBar, note: str, buttons: tuple[QPushButton, ...]) -> QHBoxLayout:
    """The state bar, the simulation badge (when `note`) and the buttons in one row."""
    header = QHBoxLayout()
    header.setContentsMargins(10, 8, 10, 4)
    header.addWidget(state_bar, 1)
    badge = QLabel(note)
    badge.setStyleSheet("QLabel { background: #fef7e0; color: #7a4f01; border: 1px solid #f9d97c; "
                        "border-radius: 4px; padding: 3px 8px; font-weight: 700; font-size: 9pt; }")
    badge.setVisible(bool(note))
    badge.setToolTip("the panel drives a simulated rig: nothing real moves")
    header.addWidget(badge, 0, Qt.AlignmentFlag.AlignTop)
    header.addSpacing(12)
    for button in buttons:
        header.addWidget(button)
    return header
