"""The log of events and errors: one row per event (UTC time, state, kind, message), errors in
red and warnings in amber, newest at the bottom. Readings are not logged (they come at 10 Hz);
the gauges show them."""

from __future__ import annotations

from hopkinson.rig.events import RigEvent, utc_now_iso
from PySide6.QtGui import QBrush, QColor
from PySide6.QtWidgets import (
    QAbstractItemView,
    QHeaderView,
    QTableWidget,
    QTableWidgetItem,
    QWidget,
)

MAX_ROWS = 5000
_COLOURS = {"error": "#b3261e", "warning": "#8a5a00", "result": "#0b57d0"}


class LogView(QTableWidget):
    """Events and panel messages, as a table a technician can scroll and copy from."""

    COLUMNS = ("Time (UTC)", "State", "Kind", "Message")

    def __init__(self, parent: QWidget | None = None) -> None:
        super().__init__(0, len(self.COLUMNS), parent)
        self.setHorizontalHeaderLabels(self.COLUMNS)
        self.verticalHeader().setVisible(False)
        self.setEditTriggers(QAbstractItemView.EditTrigger.NoEditTriggers)
        self.setSelectionBehavior(QAbstractItemView.SelectionBehavior.SelectRows)
        self.setWordWrap(False)
        self.setAlternatingRowColors(True)
        header = self.horizontalHeader()
        header.setSectionResizeMode(0, QHeaderView.ResizeMode.ResizeToContents)
        header.setSectionResizeMode(1, QHeaderView.ResizeMode.ResizeToContents)
        header.setSectionResizeMode(2, QHeaderView.ResizeMode.ResizeToContents)
        header.setSectionResizeMode(3, QHeaderView.ResizeMode.Stretch)
        self.verticalHeader().setDefaultSectionSize(20)

    def add_event(self, event: RigEvent) -> None:
        """Log a rig event (readings are skipped)."""
        if event.kind == "reading":
            return
        level = event.data.get("level", "")
        kind = "warning" if level == "warning" else event.kind
        self.add_row(event.utc, event.state, kind, event.message)

    def add_message(self, level: str, text: str, state: str = "") -> None:
        """Log a panel message ("info", "warning", "error")."""
        self.add_row(utc_now_iso(), state, level, text)

    def add_row(self, utc: str, state: str, kind: str, message: str) -> None:
        if self.rowCount() >= MAX_ROWS:
            self.removeRow(0)
        row = self.rowCount()
        self.insertRow(row)
        time_text = utc[11:23] if len(utc) >= 23 else utc
        for column, text in enumerate((time_text, state, kind, message)):
            item = QTableWidgetItem(text)
            if column == 0:
                item.setToolTip(utc)
            if column == 3:
                item.setToolTip(message)
            colour = _COLOURS.get(kind)
            if colour:
                item.setForeground(QBrush(QColor(colour)))
            self.setItem(row, column, item)
        self.scrollToBottom()

    def messages(self) -> list[tuple[str, str]]:
        """(kind, message) of every row, oldest first (for tests and export)."""
        return [(self.item(r, 2).text(), self.item(r, 3).text()) for r in range(self.rowCount())]
