"""Small widgets the panel shares: a coloured indicator lamp with a caption, section headers,
and the colours every part of the panel uses for ok / warning / fault / unknown."""

from __future__ import annotations

from PySide6.QtCore import QSize, Qt
from PySide6.QtGui import QColor, QPainter, QPen
from PySide6.QtWidgets import QHBoxLayout, QLabel, QSizePolicy, QWidget

OK = "#2e9d43"  # green: holds / connected
WARN = "#e0a010"  # amber: not yet reached / answered badly
FAULT = "#d0312d"  # red: failed / disconnected
IDLE = "#9aa0a6"  # grey: unknown / not read
ACTIVE = "#1f6fd1"  # blue: the sequencer's current state

LEVEL_COLOURS = {"ok": OK, "warn": WARN, "fault": FAULT, "unknown": IDLE, "active": ACTIVE}


class Lamp(QWidget):
    """A round indicator lamp; `level` is "ok", "warn", "fault", "unknown" or "active"."""

    def __init__(self, diameter: int = 14, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self._diameter = diameter
        self._level = "unknown"
        self.setFixedSize(QSize(diameter + 2, diameter + 2))

    @property
    def level(self) -> str:
        return self._level

    def set_level(self, level: str) -> None:
        if level not in LEVEL_COLOURS:
            raise ValueError(f"lamp level must be one of {', '.join(LEVEL_COLOURS)}, got {level!r}")
        if level != self._level:
            self._level = level
            self.update()

    def paintEvent(self, _event: object) -> None:  # noqa: N802 (Qt's name)
        painter = QPainter(self)
        painter.setRenderHint(QPainter.RenderHint.Antialiasing)
        colour = QColor(LEVEL_COLOURS[self._level])
        painter.setPen(QPen(colour.darker(150), 1))
        painter.setBrush(colour)
        painter.drawEllipse(1, 1, self._diameter, self._diameter)
        painter.end()


class LampLabel(QWidget):
    """A lamp followed by a caption; the tooltip carries the detail (what is wrong)."""

    def __init__(self, caption: str, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.lamp = Lamp()
        self.caption = QLabel(caption)
        layout = QHBoxLayout(self)
        layout.setContentsMargins(0, 0, 0, 0)
        layout.setSpacing(6)
        layout.addWidget(self.lamp, 0, Qt.AlignmentFlag.AlignVCenter)
        layout.addWidget(self.caption, 1)
        self.setSizePolicy(QSizePolicy.Policy.Preferred, QSizePolicy.Policy.Fixed)

    @property
    def level(self) -> str:
        return self.lamp.level

    def set_state(self, level: str, detail: str = "") -> None:
        self.lamp.set_level(level)
        if detail != self.toolTip():
            self.setToolTip(detail)
            self.caption.setToolTip(detail)


def section_title(text: str) -> QLabel:
    """A bold, small-caps header for a group of readouts."""
    label = QLabel(text.upper())
    label.setStyleSheet("color: #5f6368; font-weight: 600; font-size: 10pt; letter-spacing: 1px;")
    return label
