"""The Campaign tab's table: one row per planned shot, filled as the campaign runs.

Columns: level (a pressure or a target), the pressure fired, projectile, journal state (why it
failed in the tooltip), peak (g), model order, sensitivity ± U in the sensor's unit (header),
FBSD ±5 % ± U and f_n (kHz), the shot's verdict (its line in the tooltip) and the DCM's, the
shot file. A figure the analysis could not determine reads "not determined" (or "not excited"
for f_n) with the reason in its tooltip, never "0 ± 101". Units are in the headers; a figure's
± U goes under its value, so that every column is in view at 1280 × 800.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from PySide6.QtGui import QBrush, QColor
from PySide6.QtWidgets import (
    QAbstractItemView,
    QHeaderView,
    QTableWidget,
    QTableWidgetItem,
    QWidget,
)

from hopkinson.analysis.key_figures import Figure, KeyFigures
from hopkinson.analysis.verdict import Decision
from hopkinson.reports.data import CompensationCheck
from hopkinson.rig.plan import G_M_S2, CampaignPlan
from hopkinson.ui.campaign_actions import ShotRow
from hopkinson.ui.plots import KILO, figure_tooltip, format_figure
from hopkinson.ui.widgets import TEXT_COLOURS

# units in the headers (the sensitivity's is the plan's), a figure's ± U under its value: at
# 1280 × 800 every column, the verdict and the DCM's included, is in view without scrolling
COLUMNS = (("#", "#"), ("Shot", "Shot"), ("Level", "Level"), ("p", "p (bar)"), ("Proj.", "Proj."),
           ("State", "State"), ("Peak", "Peak (g)"), ("Order", "Order"), ("Sensitivity", "Sensitivity"),
           ("FBSD", "FBSD ±5 %\n(kHz)"), ("f_n", "f_n (kHz)"), ("Verdict", "Verdict"), ("DCM", "DCM"),
           ("File", "Shot file"))
COL = {key: i for i, (key, _header) in enumerate(COLUMNS)}
_STATE_COLOURS = {"ARMED: press FIRE": "#b45309", "ANALYSED": "#1e6b2e", "ANALYSIS_FAILED": "#8a5a00", "ABORTED": "#b3261e", "UNKNOWN": "#b3261e",
                  "SKIPPED": "#5f6368", "FIRING": "#1f6fd1", "RECORDED": "#1f6fd1"}


class CampaignTable(QTableWidget):
    """The table (module docstring); rows by shot id in `rows`."""

    def __init__(self, parent: QWidget | None = None) -> None:
        super().__init__(0, len(COLUMNS), parent)
        self.rows: dict[str, int] = {}
        self.setHorizontalHeaderLabels([header for _key, header in COLUMNS])
        self.verticalHeader().setVisible(False)
        self.verticalHeader().setSectionResizeMode(QHeaderView.ResizeMode.ResizeToContents)
        self.setEditTriggers(QAbstractItemView.EditTrigger.NoEditTriggers)
        self.setSelectionBehavior(QAbstractItemView.SelectionBehavior.SelectRows)
        self.setSelectionMode(QAbstractItemView.SelectionMode.SingleSelection)
        self.setAlternatingRowColors(True)
        header = self.horizontalHeader()
        for i in range(len(COLUMNS) - 1):
            header.setSectionResizeMode(i, QHeaderView.ResizeMode.ResizeToContents)
        header.setSectionResizeMode(len(COLUMNS) - 1, QHeaderView.ResizeMode.Stretch)

    def fill(self, plan: CampaignPlan, unit_name: str) -> None:
        """One row per planned shot, its level and projectile; the sensitivity's unit in its header."""
        self.setRowCount(0)
        self.rows.clear()
        self.setHorizontalHeaderItem(COL["Sensitivity"], QTableWidgetItem(f"Sensitivity\n({unit_name})"))
        for shot in plan.shots:
            row = self.rowCount()
            self.insertRow(row)
            self.rows[shot.id] = row
            level = (f"{shot.pressure_bar:g} bar" if shot.target_peak_m_s2 is None  # a target: pressure chosen at firing
                     else f"{shot.target_peak_m_s2 / G_M_S2:,.0f} g".replace(",", "\u00a0"))
            for name, text in (("#", str(shot.index + 1)), ("Shot", shot.id), ("Level", level), ("p", "—"),
                               ("Proj.", f"No. {shot.projectile}")):
                self.setItem(row, COL[name], QTableWidgetItem(text))

    def column(self, name: str) -> list[str]:
        """The texts of a column by its key (COLUMNS), top to bottom."""
        col = COL[name]
        return [self.item(r, col).text() if self.item(r, col) else "" for r in range(self.rowCount())]

    def shot_at(self, row: int) -> str | None:
        return next((sid for sid, r in self.rows.items() if r == row), None)

    def set_state(self, sid: str, state: str, why: str = "") -> None:
        row = self.rows.get(sid)
        if row is None:
            return
        item = QTableWidgetItem(state)
        colour = _STATE_COLOURS.get(state.rstrip("…"), "#1f6fd1" if state.endswith("…") else None)
        if colour:
            item.setForeground(QBrush(QColor(colour)))
        if why:
            item.setToolTip(why)
        self.setItem(row, COL["State"], item)

    def set_pressure(self, sid: str, pressure_bar: float) -> None:
        row = self.rows.get(sid)
        if row is not None:
            self.setItem(row, COL["p"], QTableWidgetItem(f"{pressure_bar:.3g}"))

    def show_shot(self, sid: str, path: Path, shot: ShotRow, failed: bool) -> None:
        """A shot file's row: its pressure, figures and verdict (`failed`: its analysis failed,
        the reason goes into the state's tooltip)."""
        row = self.rows.get(sid)
        if row is None:
            return
        self.setItem(row, COL["File"], QTableWidgetItem(path.name))
        self.set_pressure(sid, shot.pressure_bar)
        if shot.analysis_error and failed and self.item(row, COL["State"]) is not None:
            self.item(row, COL["State"]).setToolTip(shot.analysis_error)
        j = shot.judgement
        verdict = j.verdict
        cells = {"Verdict": (verdict.decision.value, verdict.line())}
        kf = j.figures
        if kf is not None:
            cells |= self._figure_cells(kf, j)
        for name, (text, tip) in cells.items():
            # value over ± U: in one line the figures pushed the verdict out of view
            item = QTableWidgetItem(text.replace(" ± ", "\n± "))
            item.setToolTip(tip)
            if name == "Verdict":
                item.setForeground(QBrush(QColor(TEXT_COLOURS["ok"] if verdict.decision == Decision.ACCEPT
                                                 else TEXT_COLOURS["error"])))
            if name == "DCM" and kf is not None and kf.dcm_recommended is False:
                item.setForeground(QBrush(QColor(TEXT_COLOURS["error"])))
            self.setItem(row, COL[name], item)

    @staticmethod
    def _figure_cells(kf: KeyFigures, j: Any) -> dict[str, tuple[str, str]]:
        """The figures of an analysed shot as (text, tooltip) by column (units in the headers)."""
        peak = kf.peak_acceleration_m_s2
        cells = {
            "Order": (str(kf.order) if kf.order is not None else "—", f"model order; fit {kf.fit_percent:.1f} %"
                      if kf.fit_percent is not None else "model order"),
            "Peak": ("—" if peak is None or peak.value is None else f"{peak.value / G_M_S2:,.0f}".replace(",", "\u00a0"),
                     "peak acceleration of the reference pulse (g)"),
            "FBSD": _fbsd_cell(kf, "5"),
            "f_n": _determined(kf.natural_frequency_hz, KILO, 2, "not excited", "no resonance inside the supported band"),
        }
        zeta = kf.damping_ratio
        if zeta is not None and zeta.value is not None:
            cells["f_n"] = (cells["f_n"][0], f"{cells['f_n'][1]}; ζ = {format_figure(zeta, decimals=4)}".lstrip("; "))
        if j.sensitivity is not None:
            unit = j.unit
            text = j.sensitivity.text().removesuffix(f" {unit.name}")
            cells["Sensitivity"] = (text, f"{j.sensitivity.text()}; {j.sensitivity.ratio_text()}")
        else:
            cells["Sensitivity"] = _determined(kf.sensitivity, 1.0, 4, "not determined", "")
        check = CompensationCheck.of(kf)
        if check is not None and check.recommended is not None:
            reason = check.not_recommended_reason or "compensation does not improve this shot"
            cells["DCM"] = ("recommended", "") if check.recommended else ("NOT recommended", reason)
        return cells


def _determined(figure: Figure | None, scale: float, decimals: int, missing: str, why: str) -> tuple[str, str]:
    """value ± U without its unit (the header has it); `missing` with the reason when the
    analysis could not determine it."""
    if figure is None or figure.value is None:
        reason = getattr(figure, "reason", None) or why
        return missing, reason
    return format_figure(figure, scale, decimals=decimals), figure_tooltip(figure, scale)


def _fbsd_cell(kf: KeyFigures, level: str) -> tuple[str, str]:
    """An FBSD in kHz without the unit (the header has it) and its tooltip; a bound as '> 18'
    with the reason in the tooltip; an edge the analysis could not place (no value, or none
    above 0 Hz) as "not determined", never "0 ± 101"."""
    bound = kf.fbsd_bounds.get(level)
    if bound is not None:
        return f"> {bound.lower_bound_hz / KILO:.3g}", kf.fbsd_text(level, KILO)
    figure = kf.fbsd_hz.get(level)
    if figure is None or figure.value is None or not figure.value > 0:
        reason = getattr(figure, "reason", None) if figure is not None else None
        return "not determined", reason or f"the ±{level} % edge could not be placed from this shot"
    return format_figure(figure, KILO), figure_tooltip(figure, KILO, "kHz")
