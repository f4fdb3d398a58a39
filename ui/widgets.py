"""Small widgets the panel shares: a coloured indicator lamp with a caption, section headers,
and the colours every part of the panel uses for ok / warning / fault / unknown."""

from __future__ import annotations

import re

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


# Message colours: errors red, warnings amber, success green, information blue, idle grey.
BANNER_STYLES = {
    "error": "background: #fce8e6; color: #8c1d18; border: 1px solid #f4b4ae;",
    "warning": "background: #fef7e0; color: #7a4f01; border: 1px solid #f9d97c;",
    "ok": "background: #e6f4ea; color: #0d652d; border: 1px solid #a8dab5;",
    "info": "background: #e8f0fe; color: #174ea6; border: 1px solid #aecbfa;",
    "idle": "background: #f8f9fa; color: #3c4043; border: 1px solid #dadce0;",
}
TEXT_COLOURS = {"error": "#b3261e", "warning": "#8a5a00", "ok": "#1e6b2e", "info": "#174ea6", "idle": "#3c4043"}
BANNER_LINES = 2


class Banner(QLabel):
    """The panel's message line: always there and always two lines high, so nothing under it
    moves when a message comes or goes; a longer message is cut with "…" and shown whole in
    its tooltip (and in the log)."""

    def __init__(self, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.level = "idle"
        self.full_text = ""
        self.setWordWrap(True)
        self.setTextFormat(Qt.TextFormat.PlainText)
        self.setTextInteractionFlags(Qt.TextInteractionFlag.TextSelectableByMouse)
        self.setSizePolicy(QSizePolicy.Policy.Ignored, QSizePolicy.Policy.Fixed)
        self.show_message("idle", "")

    def show_message(self, level: str, text: str) -> None:
        """Show `text` in the colours of `level` (BANNER_STYLES)."""
        if level not in BANNER_STYLES:
            raise ValueError(f"banner level must be one of {', '.join(BANNER_STYLES)}, got {level!r}")
        self.level, self.full_text = level, text
        self.setStyleSheet(f"QLabel {{ {BANNER_STYLES[level]} padding: 3px 10px; border-radius: 4px; "
                           "font-size: 10pt; }")
        self.ensurePolished()
        metrics = self.fontMetrics()
        self.setFixedHeight(BANNER_LINES * metrics.lineSpacing() + 2 * 3 + 2 + 2)
        self._fit()

    def resizeEvent(self, event: object) -> None:  # noqa: N802 (Qt's name)
        super().resizeEvent(event)  # type: ignore[arg-type]
        self._fit()

    def _fit(self) -> None:
        """The text cut to what two lines of the current width hold."""
        text = self.full_text
        metrics = self.fontMetrics()
        width = max(50, self.contentsRect().width() - 24)
        room = BANNER_LINES * width - 3 * metrics.averageCharWidth() * BANNER_LINES
        shown = text if metrics.horizontalAdvance(text) <= room else metrics.elidedText(
            text, Qt.TextElideMode.ElideRight, room)
        super().setText(shown)
        self.setToolTip(text if shown != text else "")


_PYTHON_TUPLE = re.compile(r",? got \(.*\)$")  # "…, got ((0.6+0.1j),)": a repr appended to a message
_PREFIX = re.compile(r"^(?:(DCM|analysis): )+")
_COMPLEX = re.compile(r"\(([-+]?[\d.e+-]+[-+][\d.e+-]+j)\)")


def plain_message(text: str) -> str:
    """A message from the layers below written for a technician: no repeated "DCM: " prefix, no
    Python repr of the value appended, complex numbers as 0.6+0.1j, names in words."""
    out = _PYTHON_TUPLE.sub("", _PREFIX.sub("", text.strip()))
    out = _COMPLEX.sub(r"\1", out)
    return out.replace("extra_poles", "extra poles")
