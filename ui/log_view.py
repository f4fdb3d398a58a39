"""The log of events and errors: one row per event (UTC time, state, kind, message), errors in
red and warnings in amber, newest at the bottom. Readings are not logged (they come at 10 Hz);
the gauges show them. `LogTab` adds *Save log…*: the rows as JSON lines (`.jsonl`, one object
per row with the full UTC time, like the shots' own logs) or as tab-separated text (any other
name), written atomically."""

from __future__ import annotations

import json
from collections import deque
from pathlib import Path

from PySide6.QtGui import QBrush, QColor
from PySide6.QtWidgets import (
    QAbstractItemView,
    QFileDialog,
    QHBoxLayout,
    QHeaderView,
    QLabel,
    QPushButton,
    QTableWidget,
    QTableWidgetItem,
    QVBoxLayout,
    QWidget,
)

from hopkinson.fileio import atomic_write, check_output_path
from hopkinson.rig.events import Reading, RigEvent, utc_now_iso

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
        self.rows: deque[dict[str, str]] = deque(maxlen=MAX_ROWS)  # what is shown, for saving

    def add_event(self, event: RigEvent) -> None:
        """Log a rig event (readings are skipped)."""
        if isinstance(event, Reading):
            return
        self.add_row(event.utc, event.state, event.label, event.message)

    def add_message(self, level: str, text: str, state: str = "") -> None:
        """Log a panel message ("info", "warning", "error")."""
        self.add_row(utc_now_iso(), state, level, text)

    def add_row(self, utc: str, state: str, kind: str, message: str) -> None:
        self.rows.append({"utc": utc, "state": state, "kind": kind, "message": message})
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

    def save(self, path: str | Path) -> Path:
        """Write the rows, oldest first: JSON lines for a `.jsonl`/`.json` name, else
        tab-separated text with a header line; atomically (hopkinson.fileio)."""
        path = check_output_path(path, what="log")  # never over a shot file
        if path.suffix.lower() in (".jsonl", ".json"):
            text = "".join(json.dumps(row, ensure_ascii=False) + "\n" for row in self.rows)
        else:
            lines = ["\t".join(("utc", "state", "kind", "message"))]
            lines += ["\t".join(row[k].replace("\t", " ").replace("\n", " ") for k in ("utc", "state", "kind", "message"))
                      for row in self.rows]
            text = "\n".join(lines) + "\n"
        return atomic_write(path, text)


class LogTab(QWidget):
    """The Log tab: the log table with a *Save log…* button."""

    def __init__(self, log_view: LogView, default_folder: Path = Path("."), parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.log_view = log_view
        self.default_folder = default_folder
        self.save_button = QPushButton("Save log…")
        self.save_button.setToolTip("write the log as JSON lines (.jsonl) or text (.txt)")
        self.message = QLabel("")
        self.message.setStyleSheet("color: #3c4043;")
        bar = QHBoxLayout()
        bar.setContentsMargins(0, 0, 0, 0)
        bar.addWidget(self.message, 1)
        bar.addWidget(self.save_button)
        layout = QVBoxLayout(self)
        layout.setContentsMargins(4, 4, 4, 4)
        layout.setSpacing(4)
        layout.addLayout(bar)
        layout.addWidget(log_view, 1)
        self.save_button.clicked.connect(self.save_dialog)

    def save(self, path: Path) -> None:
        """Save the log to `path` and say where (or why not) under the button."""
        try:
            written = self.log_view.save(path)
        except (OSError, ValueError) as exc:
            self.message.setStyleSheet("color: #b3261e;")
            self.message.setText(f"Log not saved: {exc}")
            return
        self.message.setStyleSheet("color: #0d652d;")
        self.message.setText(f"Log saved to {written} ({len(self.log_view.rows)} rows)")

    def save_dialog(self) -> None:
        stamp = utc_now_iso().replace(":", "").replace("-", "")[:15]
        name, _ = QFileDialog.getSaveFileName(self, "Save the log", str(self.default_folder / f"panel-{stamp}.log.jsonl"),
                                              "JSON lines (*.jsonl);;Text (*.txt)")
        if name:
            self.save(Path(name))

