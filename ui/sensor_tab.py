"""Sensor history: every calibration of one serial from the lab's record (hopkinson.lab) — a
table of sensitivity, shock sensitivity, f_n and FBSD ±5 % with their U over time (units in
every column), the same as plots against the calibration date (dated axes) with U as error
bars, and the judgement: drift (E_n of the newest against the earlier ones), the statement of
conformity against the sensor's tolerance, and the due date. The sensor's data (nominal
sensitivity and its unit, tolerance, recalibration interval, owner) is set here too
(`save_sensor`: the lab's record, audited).

The tab opens on the serial set up for the shot (`prefill`). Calibrations the simulator made
are marked "SIMULATED". The record is read on the panel's background worker; the tab only draws
what it returns.
"""

from __future__ import annotations

import getpass
from datetime import datetime
from typing import Any

import numpy as np
import pyqtgraph as pg
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

from hopkinson.analysis.key_figures import Figure
from hopkinson.analysis.sensitivity_units import DEFAULT_UNIT, UNITS
from hopkinson.lab.history import RATIO_UNITS, SensorHistory, load_sensor_history
from hopkinson.lab.history_plot import SHOWN
from hopkinson.lab.repository import SensorInfo, open_repository
from hopkinson.ui.inputs import ComboBox, IntSpinBox, UnitSpinBox
from hopkinson.ui.plots import configure_plot
from hopkinson.ui.widgets import TEXT_COLOURS, section_title
from hopkinson.ui.worker import Background

POINT_BRUSH = pg.mkBrush("#1a73e8")
SIMULATED_BRUSH = pg.mkBrush("#bdc1c6")
DRIFT_COLOUR = "#c5221f"
DAY_S = 86_400.0
MIN_SPAN_S = 30 * DAY_S  # a history within one day still gets a dated axis (not "54.500 … 55.250" seconds)


def load_history(url: str, serial: str, rule: str) -> tuple[SensorHistory, list[dict[str, Any]]]:
    """The sensor's judged history and its certificates (LabError when it is not in the record)."""
    with open_repository(url) as repo:
        history = load_sensor_history(repo, serial, rule)
    return history, list(history.certificates)


def save_sensor(url: str, serial: str, **fields: Any) -> SensorInfo:
    """Set a sensor's data in the lab's record (audited under the OS user)."""
    with open_repository(url) as repo:
        return repo.register_sensor(serial, getpass.getuser(), **fields)


def absolute_unit(history: SensorHistory) -> str | None:
    """The one unit every calibration's absolute sensitivity is stated in (the record's, in the
    sensor's own unit), None when a calibration has none or they differ."""
    units = {c.absolute_unit if c.absolute is not None else None for c in history.calibrations}
    return units.pop() if len(units) == 1 and None not in units else None


def column_unit(history: SensorHistory, key: str, unit: str) -> str:
    """A column's unit: the sensitivities in the sensor's own unit when the record states the
    sensitivity so for every calibration (and every shock sensitivity converts); else relative
    to each shot's nominal when the response was divided by it, or in V/(m/s²)."""
    stated = absolute_unit(history)
    if stated and (key == "sensitivity" or key == "shock_sensitivity" and all(
            absolute_shock(c, stated) is not None for c in history.calibrations if c.figures.get(key) is not None)):
        return stated
    if key in ("sensitivity", "shock_sensitivity"):
        units = {c.response_unit for c in history.calibrations}
        return "× nominal" if units <= set(RATIO_UNITS) else "V/(m/s²)" if units == {"V"} else "as recorded"
    return unit


def shown_figure(c: Any, key: str, history: SensorHistory) -> Figure | None:
    """The figure a column shows for a calibration: in the sensor's unit where the column is (the
    record's stated sensitivity; the shock sensitivity scaled here the same way, shot by shot),
    else the record's figure."""
    stated = absolute_unit(history)
    if stated and key in ("sensitivity", "shock_sensitivity") and column_unit(history, key, "") == stated:
        return c.absolute if key == "sensitivity" else absolute_shock(c, stated)
    return c.figures.get(key)


def absolute_shock(c: Any, unit_name: str) -> Figure | None:
    """A calibration's shock sensitivity in `unit_name`: each shot's ratio × the nominal it was
    divided by, combined as the record combines (lab.history.combined_figure); None when a
    shot's nominal is unknown or the unit is not one of analysis.sensitivity_units'."""
    from hopkinson.analysis.sensitivity_units import sensitivity_unit
    from hopkinson.lab.history import combined_figure

    try:
        unit = sensitivity_unit(unit_name)
    except ValueError:
        return None
    scaled = []
    for shot in c.shots:
        figure, nominal = shot.figures.get("shock_sensitivity"), shot.context.get("sensitivity_v_per_m_s2")
        if figure is None or figure.value is None:
            continue
        if shot.response_unit not in RATIO_UNITS or not isinstance(nominal, int | float) or not nominal > 0:
            return None
        k = unit.from_si(float(nominal))
        scaled.append(Figure(figure.value * k, None if figure.u is None else figure.u * k,
                             None if figure.interval is None else (figure.interval[0] * k, figure.interval[1] * k)))
    return combined_figure(scaled) if scaled else None


def nominals(history: SensorHistory) -> set[float]:
    """The nominal sensitivities (V/(m/s²)) the shots' responses were divided by."""
    return {float(v) for c in history.calibrations for s in getattr(c, "shots", ())
            if isinstance(v := s.context.get("sensitivity_v_per_m_s2"), int | float) and v > 0}


class SensorTab(QWidget):
    """The "Sensor history" tab (module doc)."""

    def __init__(self, background: Background, database_url: str = "", decision_rule: str = "simple") -> None:
        super().__init__()
        self.background = background
        self.database_url = database_url
        self.decision_rule = decision_rule
        self.history: SensorHistory | None = None
        self._prefilled = ""

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

        # the sensor's data, as the lab's record keeps it
        self.nominal = UnitSpinBox("Nominal sensitivity", "", UNITS[DEFAULT_UNIT].plausible_range(), 0.0, decimals=4,
                                   special="not set")
        self.unit = ComboBox()
        for name in UNITS:
            self.unit.addItem(name, name)
        self.unit.setCurrentIndex(self.unit.findData(DEFAULT_UNIT))
        self.unit.currentIndexChanged.connect(
            lambda: self.nominal.set_plausible(*UNITS[str(self.unit.currentData())].plausible_range()))
        self.tolerance = UnitSpinBox("Tolerance", "%", (0.1, 50.0), 0.0, decimals=1, special="not set",
                                     tip="the sensor's tolerance on its nominal sensitivity (conformity, flags)")
        self.interval = IntSpinBox(0, 3650, 0)
        self.interval.setSuffix(" days")
        self.interval.setSpecialValueText("not set")
        self.interval.setToolTip("recalibration interval: the due date is the last calibration plus this")
        self.owner = QLineEdit()
        self.owner.setPlaceholderText("owner (the certificate's customer)")
        self.save_button = QPushButton("Save sensor data")
        self.save_button.clicked.connect(self.save_sensor_data)
        self.save_message = QLabel("")
        for spin in (self.nominal, self.tolerance):
            spin.refused.connect(lambda text: self._said("warning", f"Not taken: {text}."))
        for spin in (self.nominal, self.tolerance, self.interval):
            spin.setMaximumWidth(120)
        self.owner.setMinimumWidth(160)
        data = QHBoxLayout()
        data.addWidget(QLabel("Nominal"))
        data.addWidget(self.nominal)
        data.addWidget(self.unit)
        data.addWidget(QLabel("Tolerance ±"))
        data.addWidget(self.tolerance)
        data.addWidget(QLabel("Recalibrate every"))
        data.addWidget(self.interval)
        data.addWidget(self.owner, 1)
        data.addWidget(self.save_button)

        self.table = QTableWidget(0, 4 + len(SHOWN))
        self.table.horizontalHeader().setSectionResizeMode(QHeaderView.ResizeMode.ResizeToContents)
        self.table.verticalHeader().setVisible(False)
        self.table.setEditTriggers(QTableWidget.EditTrigger.NoEditTriggers)
        self._set_headers(None)

        self.plots: dict[str, pg.PlotWidget] = {}
        grid = QGridLayout()
        for i, (key, label, _scale, unit) in enumerate(SHOWN):
            plot = pg.PlotWidget(axisItems={"bottom": pg.DateAxisItem(utcOffset=0)})
            configure_plot(plot, label, unit or "value", "calibration date (UTC)")
            self.plots[key] = plot
            grid.addWidget(plot, i // 2, i % 2)

        layout = QVBoxLayout(self)
        layout.addLayout(row)
        layout.addLayout(data)
        layout.addWidget(self.save_message)
        layout.addWidget(self.summary)
        layout.addWidget(self.flags)
        layout.addWidget(section_title("Calibrations"))
        layout.addWidget(self.table, 2)
        layout.addLayout(grid, 3)

    def _set_headers(self, history: SensorHistory | None) -> None:
        heads = ["date (UTC)", "rig", "campaign", "source"]
        for key, label, _scale, unit in SHOWN:
            shown = column_unit(history, key, unit) if history is not None else unit
            heads.append(f"{label} ({shown})" if shown else label)
        self.table.setHorizontalHeaderLabels(heads)

    # -- the serial --------------------------------------------------------------------------------
    def prefill(self, serial: str) -> None:
        """Open on `serial` (the shot's), unless the technician typed another one here."""
        typed = self.serial_edit.text().strip()
        if not serial or typed == serial or (typed and typed != self._prefilled):
            return
        self._prefilled = serial
        self.serial_edit.setText(serial)
        self.show_serial()

    def show_serial(self) -> None:
        serial = self.serial_edit.text().strip()
        if not serial:
            return
        self.summary.setText(f"reading the history of {serial}…")
        self.background.run(lambda: load_history(self.database_url, serial, self.decision_rule),
                            on_done=self._show, on_error=self._show_error)

    def save_sensor_data(self) -> None:
        """Write the sensor's data (nominal in its unit, tolerance, interval, owner) to the record."""
        serial = self.serial_edit.text().strip()
        if not serial:
            self._said("warning", "Enter the sensor's serial number first.")
            return
        unit = UNITS[str(self.unit.currentData())]
        fields = {"nominal_sensitivity": self.nominal.value() or None, "sensitivity_unit": unit.name,
                  "tolerance_percent": self.tolerance.value() or None, "interval_days": self.interval.value() or None,
                  "owner": self.owner.text().strip() or None}
        self.background.run(lambda: save_sensor(self.database_url, serial, **fields),
                            lambda _info: (self._said("ok", f"Sensor {serial}: data saved in the lab's record."),
                                           self.show_serial()),
                            lambda exc: self._said("error", f"Sensor data not saved: {exc}"))

    def _said(self, level: str, text: str) -> None:
        self.save_message.setStyleSheet(f"color: {TEXT_COLOURS[level]};")
        self.save_message.setText(text)

    def _show_error(self, exc: BaseException) -> None:
        self.history = None
        self.summary.setText(f"<span style='color:{DRIFT_COLOUR}'>{exc}</span>")
        self.flags.setText("")

    def _show(self, loaded: tuple[SensorHistory, list[dict[str, str]]]) -> None:
        history, certificates = loaded
        self.history = history
        s = history.sensor
        self._fill_sensor_data(s)
        nominal = (f"nominal {s.nominal_sensitivity:g} {s.sensitivity_unit}".rstrip() if s.nominal_sensitivity
                   else "no nominal")
        parts = [f"<b>{s.serial}</b> {s.model or ''}", f"owner {s.owner or '—'}", nominal,
                 f"tolerance ±{s.tolerance_percent:g} %" if s.tolerance_percent is not None else "no tolerance",
                 f"recalibrate every {s.interval_days} days" if s.interval_days else "no interval",
                 f"{len(history.calibrations)} calibrations"]
        simulated = sum(1 for c in history.calibrations if getattr(c, "simulated", False))
        if simulated:
            parts.append(f"{simulated} SIMULATED")
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
        used = nominals(history)
        if len(used) > 1 and {c.response_unit for c in history.calibrations} <= set(RATIO_UNITS):
            unit = UNITS[DEFAULT_UNIT]
            compared = history.drift.get("sensitivity")
            how = ("E_n compares the absolute sensitivities" if compared is not None and compared.unit
                   else "their ratios to nominal are not compared")
            lines.append(f"The shots were analysed with {len(used)} different nominals "
                         f"({', '.join(f'{unit.from_si(v):.4g}' for v in sorted(used))} {unit.name}): {how}.")
        flags = history.flags
        colour = DRIFT_COLOUR if flags else "#137333"
        self.flags.setText(f"<span style='color:{colour}'><b>{'; '.join(flags) or 'no flags'}</b></span><br>"
                           + "<br>".join(lines))
        self._set_headers(history)
        self._fill_table(history)
        self._draw(history)

    def _fill_sensor_data(self, s: SensorInfo) -> None:
        index = self.unit.findData(s.sensitivity_unit) if s.sensitivity_unit in UNITS else -1
        if index >= 0:
            self.unit.setCurrentIndex(index)
        self.nominal.setValue(s.nominal_sensitivity or 0.0)
        self.tolerance.setValue(s.tolerance_percent or 0.0)
        self.interval.setValue(s.interval_days or 0)
        self.owner.setText(s.owner or "")

    def _fill_table(self, history: SensorHistory) -> None:
        rows = list(reversed(history.calibrations))  # newest first
        self.table.setRowCount(len(rows))
        for r, c in enumerate(rows):
            source = "SIMULATED" if getattr(c, "simulated", False) else "rig"
            cells = [c.utc_time[:16].replace("T", " "), c.rig, c.campaign or "—", source]
            cells += [_text(shown_figure(c, key, history), scale) for key, _label, scale, _unit in SHOWN]
            for col, text in enumerate(cells):
                self.table.setItem(r, col, QTableWidgetItem(text))

    def _draw(self, history: SensorHistory) -> None:
        for key, _label, scale, unit in SHOWN:
            plot = self.plots[key]
            plot.clear()
            plot.getPlotItem().setLabel("left", column_unit(history, key, unit) or "value")  # the title names it
            x, values, expanded, simulated = _series(history, key, scale)
            if not x:
                continue
            plot.addItem(pg.ErrorBarItem(x=np.asarray(x), y=np.asarray(values), height=2 * np.asarray(expanded),
                                         beam=0.0, pen=pg.mkPen("#5f6368")))
            brushes = [SIMULATED_BRUSH if sim else POINT_BRUSH for sim in simulated] or POINT_BRUSH
            plot.plot(x, values, pen=None, symbol="o", symbolSize=6, symbolBrush=brushes)
            drift = history.drift.get(key)
            if drift is not None and drift.drifted:
                plot.plot([x[-1]], [values[-1]], pen=None, symbol="o", symbolSize=10,
                          symbolBrush=pg.mkBrush(DRIFT_COLOUR))
            plot.getPlotItem().enableAutoRange(axis="y")
            plot.setXRange(*_date_range(x), padding=0)


def _series(history: SensorHistory, key: str, scale: float) -> tuple[list[float], list[float], list[float], list[bool]]:
    """(UTC timestamps, values, U, simulated?) of what a column shows, over the calibrations that have it."""
    out: tuple[list[float], list[float], list[float], list[bool]] = ([], [], [], [])
    for c in history.calibrations:
        figure = shown_figure(c, key, history)
        if figure is None or figure.value is None:
            continue
        out[0].append(datetime.fromisoformat(c.utc_time.replace("Z", "+00:00")).timestamp())
        out[1].append(figure.value / scale)
        out[2].append((figure.expanded or 0.0) / scale)
        out[3].append(bool(getattr(c, "simulated", False)))
    return out


def _date_range(x: list[float]) -> tuple[float, float]:
    """At least MIN_SPAN_S around the calibrations, so the axis shows dates, not seconds."""
    lo, hi = min(x), max(x)
    pad = max(0.08 * (hi - lo), 0.5 * max(0.0, MIN_SPAN_S - (hi - lo)), DAY_S)
    return lo - pad, hi + pad


def _text(figure: Figure | None, scale: float) -> str:
    """value ± U without the unit (the column's header has it)."""
    return figure.format(scale) if figure is not None and figure.value is not None else "—"

