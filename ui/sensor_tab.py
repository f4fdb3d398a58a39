"""Sensor history: every calibration of one serial from the lab's record (hopkinson.lab) — a
table of sensitivity, shock sensitivity, f_n and FBSD ±5 % with their U over time, the same
as plots with U as error bars, and the judgement: drift (E_n of the newest against the
earlier ones), the statement of conformity against the sensor's tolerance, and the due date.
The record is read on the panel's background worker; the tab only draws what it returns."""

from __future__ import annotations

from typing import Any

import pyqtgraph as pg
from hopkinson.analysis.key_figures import Figure
from hopkinson.lab.history import SensorHistory, sensor_history
from hopkinson.lab.history_plot import SHOWN, history_series
from hopkinson.lab.repository import open_repository
from hopkinson.ui.plots import configure_plot
from hopkinson.ui.widgets import section_title
from hopkinson.ui.worker import Background
from PySide6.QtWidgets import (
    QGridLayout,
    QHBoxLayout,
    QHeaderView,
    QLabel,
    QLineEdit,
    QPushButton,
    QTableWidget,
    QTableWidgetItem,
    QVBoxLayout,
    QWidget,
)

POINT_BRUSH = pg.mkBrush("#1a73e8")
DRIFT_COLOUR = "#c5221f"


def load_history(url: str, serial: str, rule: str) -> tuple[SensorHistory, list[dict[str, str]]]:
    """The sensor's judged history and its certificates (LabError when it is not in the record)."""
    from hopkinson.lab.errors import LabError

    with open_repository(url) as repo:
        sensor = repo.sensor(serial)
        if sensor is None:
            raise LabError(f"sensor {serial}: not in the lab's record")
        return sensor_history(sensor, repo.calibrations(serial), rule), repo.certificates(serial)


class SensorTab(QWidget):
    """The "Sensor history" tab (module doc)."""

    def __init__(self, background: Background, database_url: str = "", decision_rule: str = "simple") -> None:
        super().__init__()
        self.background = background
        self.database_url = database_url
        self.decision_rule = decision_rule
        self.history: SensorHistory | None = None

        self.serial_edit = QLineEdit()
        self.serial_edit.setPlaceholderText("serial number")
        self.serial_edit.returnPressed.connect(self.show_serial)
        self.show_button = QPushButton("Show history")
        self.show_button.clicked.connect(self.show_serial)
        self.summary = QLabel("Enter a sensor's serial number.")
        self.summary.setWordWrap(True)
        self.flags = QLabel("")
        self.flags.setWordWrap(True)
        row = QHBoxLayout()
        row.addWidget(QLabel("Sensor"))
        row.addWidget(self.serial_edit, 1)
        row.addWidget(self.show_button)

        self.table = QTableWidget(0, 3 + len(SHOWN))
        self.table.setHorizontalHeaderLabels(["date (UTC)", "rig", "campaign"] + [s[1] for s in SHOWN])
        self.table.horizontalHeader().setSectionResizeMode(QHeaderView.ResizeMode.ResizeToContents)
        self.table.verticalHeader().setVisible(False)
        self.table.setEditTriggers(QTableWidget.EditTrigger.NoEditTriggers)

        self.plots: dict[str, pg.PlotWidget] = {}
        grid = QGridLayout()
        for i, (key, label, _scale, unit) in enumerate(SHOWN):
            plot = pg.PlotWidget(axisItems={"bottom": pg.DateAxisItem()})
            configure_plot(plot, label, f"{label} ({unit})" if unit else label, "calibration date")
            self.plots[key] = plot
            grid.addWidget(plot, i // 2, i % 2)

        layout = QVBoxLayout(self)
        layout.addLayout(row)
        layout.addWidget(self.summary)
        layout.addWidget(self.flags)
        layout.addWidget(section_title("Calibrations"))
        layout.addWidget(self.table, 2)
        layout.addLayout(grid, 3)

    def show_serial(self) -> None:
        serial = self.serial_edit.text().strip()
        if not serial:
            return
        self.summary.setText(f"reading the history of {serial}…")
        self.background.run(lambda: load_history(self.database_url, serial, self.decision_rule),
                            on_done=self._show, on_error=self._show_error)

    def _show_error(self, exc: BaseException) -> None:
        self.history = None
        self.summary.setText(f"<span style='color:{DRIFT_COLOUR}'>{exc}</span>")
        self.flags.setText("")

    def _show(self, loaded: tuple[SensorHistory, list[dict[str, str]]]) -> None:
        history, certificates = loaded
        self.history = history
        s = history.sensor
        parts = [f"<b>{s.serial}</b> {s.model or ''}", f"owner {s.owner or '—'}",
                 f"tolerance ±{s.tolerance_percent:g} %" if s.tolerance_percent is not None else "no tolerance",
                 f"{len(history.calibrations)} calibrations"]
        if history.due is not None:
            parts.append(f"due {history.due.isoformat()}")
        if certificates:
            parts.append(f"last certificate {certificates[-1]['number']}")
        self.summary.setText(" · ".join(parts))
        lines = []
        if history.conformity is not None:
            lines.append(history.conformity.statement())
        labels = {key: label for key, label, _scale, _unit in SHOWN}
        for key, drift in history.drift.items():
            if key in self.plots and drift.e_n is not None:
                lines.append(f"{labels[key]}: E_n = {drift.e_n:+.2f}" + (" — DRIFTED" if drift.drifted else ""))
        flags = history.flags
        colour = DRIFT_COLOUR if flags else "#137333"
        self.flags.setText(f"<span style='color:{colour}'><b>{'; '.join(flags) or 'no flags'}</b></span><br>"
                           + "<br>".join(lines))
        self._fill_table(history)
        self._draw(history)

    def _fill_table(self, history: SensorHistory) -> None:
        rows = list(reversed(history.calibrations))  # newest first
        self.table.setRowCount(len(rows))
        for r, c in enumerate(rows):
            cells = [c.utc_time[:16].replace("T", " "), c.rig, c.campaign or "—"]
            cells += [_text(c.figures.get(key), scale, unit) for key, _label, scale, unit in SHOWN]
            for col, text in enumerate(cells):
                self.table.setItem(r, col, QTableWidgetItem(text))

    def _draw(self, history: SensorHistory) -> None:
        for key, _label, scale, _unit in SHOWN:
            plot = self.plots[key]
            plot.clear()
            dates, values, expanded = history_series(history, key, scale)
            if not dates:
                continue
            x = [d.timestamp() for d in dates]
            plot.addItem(pg.ErrorBarItem(x=_array(x), y=_array(values), height=_array([2 * e for e in expanded]),
                                         beam=0.0, pen=pg.mkPen("#5f6368")))
            plot.plot(x, values, pen=None, symbol="o", symbolSize=6, symbolBrush=POINT_BRUSH)
            drift = history.drift.get(key)
            if drift is not None and drift.drifted:
                plot.plot([x[-1]], [values[-1]], pen=None, symbol="o", symbolSize=10,
                          symbolBrush=pg.mkBrush(DRIFT_COLOUR))
            plot.getPlotItem().enableAutoRange()


def _array(values: list[float]) -> Any:
    import numpy as np

    return np.asarray(values, dtype=float)


def _text(figure: Figure | None, scale: float, unit: str) -> str:
    return figure.format(scale, unit=unit) if figure is not None and figure.value is not None else "—"


