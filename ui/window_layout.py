"""How the main window lays its parts out: the left column (rig status over the shot set-up,
scrolling) and the central widget (the header, the message line, the column beside the tabs)."""

from __future__ import annotations

from PySide6.QtCore import Qt
from PySide6.QtWidgets import (
    QFrame,
    QHBoxLayout,
    QLayout,
    QScrollArea,
    QSplitter,
    QVBoxLayout,
    QWidget,
)


def _stack(spacing: int) -> tuple[QWidget, QVBoxLayout]:
    """A widget whose parts stack from the top, without margins, `spacing` px apart."""
    widget = QWidget()
    layout = QVBoxLayout(widget)
    layout.setContentsMargins(0, 0, 0, 0)
    layout.setSpacing(spacing)
    return widget, layout


def left_column(status: QWidget, setup: QWidget) -> QScrollArea:
    """The status panel over the shot set-up, a rule between them, in a scroll area 350–420 px wide."""
    left, left_layout = _stack(spacing=2)
    left_layout.addWidget(status)
    rule = QFrame()
    rule.setFrameShape(QFrame.Shape.HLine)
    rule.setStyleSheet("color: #dadce0;")
    left_layout.addWidget(rule)
    left_layout.addWidget(setup)
    left_layout.addStretch(1)
    scroll = QScrollArea()
    scroll.setWidget(left)
    scroll.setWidgetResizable(True)
    scroll.setHorizontalScrollBarPolicy(Qt.ScrollBarPolicy.ScrollBarAlwaysOff)
    scroll.setMinimumWidth(350)
    scroll.setMaximumWidth(420)
    scroll.setFrameShape(QFrame.Shape.NoFrame)
    return scroll


def central_widget(header: QLayout, banner: QWidget, left: QWidget, tabs: QWidget) -> QWidget:
    """The header over the message line over the left column beside the tabs (the tabs stretch)."""
    splitter = QSplitter(Qt.Orientation.Horizontal)
    splitter.addWidget(left)
    splitter.addWidget(tabs)
    splitter.setStretchFactor(0, 0)
    splitter.setStretchFactor(1, 1)
    splitter.setSizes([360, 920])

    central, layout = _stack(spacing=0)
    layout.addLayout(header)
    banner_row = QHBoxLayout()
    banner_row.setContentsMargins(10, 0, 10, 4)
    banner_row.addWidget(banner)
    layout.addLayout(banner_row)
    layout.addWidget(splitter, 1)
    return central
