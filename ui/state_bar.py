"""The sequencer's progress as a row of steps, CHECK → … → DONE: done steps green, the current
one blue (red when the shot was aborted or faulted), with the current state's text beside."""

from __future__ import annotations

from hopkinson.rig.sequencer import State
from PySide6.QtCore import Qt
from PySide6.QtWidgets import QHBoxLayout, QLabel, QVBoxLayout, QWidget

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
