"""The Shot tab: the shot's verdict, its key figures and its plots.

- `VerdictBar`: ACCEPT (green) or REPEAT (red) and the one line behind it (analysis.verdict via
  rig.shot_verdict: fit, band, resonance excited or not, level reached, sensitivity against
  its tolerance, DCM recommended or not).
- `ResultsStrip`: the key figures (analysis.key_figures), each value ± U (k ≈ 2) when the shot
  carries its uncertainty; the sensitivity in the sensor's own unit with its ratio to nominal
  beside it; a figure the analysis could not determine says so, with the reason in its
  tooltip; the DCM's check on the shot and, when it is not recommended, why.
- `WarningsBox`: the analysis' warnings ranked (analysis.verdict.rank_warnings), the first
  three in full, the others behind "Details"; they scroll, never cut off.
- `ShotPlots`: all of it over a 2 × 3 grid of plots (ui.plots), in a splitter the technician
  can drag; legends sit under the plots, never over the data.
"""

from __future__ import annotations

import math

import numpy as np
import pyqtgraph as pg
from PySide6.QtCore import Qt
from PySide6.QtWidgets import (
    QFrame,
    QGridLayout,
    QHBoxLayout,
    QLabel,
    QPushButton,
    QScrollArea,
    QSplitter,
    QVBoxLayout,
    QWidget,
)

from hopkinson.analysis.key_figures import Figure, KeyFigures
from hopkinson.analysis.sensitivity_units import G_M_S2
from hopkinson.analysis.verdict import (
    TOP_WARNINGS,
    Check,
    Decision,
    ShotVerdict,
    Status,
    rank_warnings,
)
from hopkinson.reports.data import CompensationCheck
from hopkinson.rig.shot_verdict import ShotJudgement
from hopkinson.ui.plots import (
    BAND_LIMIT_TIP,
    KILO,
    LEVEL_KEYS,
    PM_PEN,
    REF_PEN,
    RESP_PEN,
    LiveTrend,
    MagnitudePlot,
    ShotView,
    _plot,
    _short,
    figure_tooltip,
    format_figure,
    format_khz,
    legend_below,
    pulse_window_s,
    set_y_to_curves,
)
from hopkinson.ui.widgets import TEXT_COLOURS

_DECISION_STYLE = {
    Decision.ACCEPT: "background: #1e8e3e; color: white;",
    Decision.REPEAT: "background: #d0312d; color: white;",
}
_STATUS_COLOURS = {Status.OK: "#202124", Status.NOTE: "#5f6368", Status.FLAG: TEXT_COLOURS["warning"],
                   Status.FAIL: TEXT_COLOURS["error"]}


def verdict_level(verdict: ShotVerdict) -> str:
    """The message line's level for a verdict: green when every check passed, amber for an
    ACCEPT with a flag, red for a REPEAT."""
    if verdict.decision == Decision.REPEAT:
        return "error"
    return "ok" if verdict.reason == "every check passed" else "warning"


class VerdictBar(QFrame):
    """ACCEPT / REPEAT and its reason in one line (module docstring)."""

    def __init__(self, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.decision: Decision | None = None
        self.badge = QLabel("")
        self.badge.setAlignment(Qt.AlignmentFlag.AlignCenter)
        self.badge.setMinimumWidth(92)
        self.line = QLabel("")
        self.line.setWordWrap(True)
        self.line.setTextFormat(Qt.TextFormat.RichText)
        self.line.setTextInteractionFlags(Qt.TextInteractionFlag.TextSelectableByMouse)
        layout = QHBoxLayout(self)
        layout.setContentsMargins(0, 0, 0, 0)
        layout.setSpacing(8)
        layout.addWidget(self.badge, 0, Qt.AlignmentFlag.AlignTop)
        layout.addWidget(self.line, 1)
        self.clear()

    def clear(self) -> None:
        self.decision = None
        self.badge.setText("")
        self.badge.setStyleSheet("")
        self.badge.setVisible(False)
        self.line.setText("")
        self.setVisible(False)

    def show_verdict(self, verdict: ShotVerdict) -> None:
        self.decision = verdict.decision
        self.badge.setText(verdict.decision.value)
        self.badge.setStyleSheet(f"QLabel {{ {_DECISION_STYLE[verdict.decision]} font-size: 13pt; font-weight: 700; "
                                 "padding: 2px 10px; border-radius: 4px; }")
        self.badge.setVisible(True)
        failing = [f for f in verdict.findings if f.status == Status.FAIL]
        others = [f for f in verdict.findings if f.status != Status.FAIL]
        parts = [f"<span style='color:{_STATUS_COLOURS[f.status]}'>{_escape(f.text)}</span>" for f in failing + others]
        self.line.setText("<span style='font-size:10pt'>" + " · ".join(parts) + "</span>")
        self.line.setToolTip(verdict.line())
        self.setVisible(True)

    def text(self) -> str:
        """The verdict as one line of plain text ("" when none)."""
        return self.line.toolTip() if self.decision is not None else ""


class WarningsBox(QWidget):
    """The warnings, the first TOP_WARNINGS in full and the rest behind "Details" (module docstring)."""

    def __init__(self, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.all: tuple[str, ...] = ()
        self.top = QLabel("")
        self.top.setWordWrap(True)
        self.top.setStyleSheet(f"color: {TEXT_COLOURS['warning']}; font-size: 9pt;")
        self.top.setTextInteractionFlags(Qt.TextInteractionFlag.TextSelectableByMouse)
        self.more = QLabel("")
        self.more.setWordWrap(True)
        self.more.setStyleSheet("color: #5f6368; font-size: 9pt;")
        self.more.setTextInteractionFlags(Qt.TextInteractionFlag.TextSelectableByMouse)
        self.more.setVisible(False)
        self.details_button = QPushButton("")
        self.details_button.setFlat(True)
        self.details_button.setStyleSheet("QPushButton { color: #1a73e8; text-align: left; padding: 0; }")
        self.details_button.setCursor(Qt.CursorShape.PointingHandCursor)
        self.details_button.clicked.connect(self.toggle_details)
        layout = QVBoxLayout(self)
        layout.setContentsMargins(0, 0, 0, 0)
        layout.setSpacing(1)
        layout.addWidget(self.top)
        layout.addWidget(self.details_button, 0, Qt.AlignmentFlag.AlignLeft)
        layout.addWidget(self.more)
        self.show_warnings(())

    def show_warnings(self, warnings: tuple[str, ...] | list[str]) -> None:
        self.all = rank_warnings(warnings)
        top, rest = self.all[:TOP_WARNINGS], self.all[TOP_WARNINGS:]
        self.top.setText("\n".join(f"⚠ {w}" for w in top))
        self.more.setText("\n".join(f"⚠ {w}" for w in rest))
        self.more.setVisible(False)
        self.details_button.setVisible(bool(rest))
        self._label_button()
        self.setVisible(bool(self.all))

    def toggle_details(self) -> None:
        self.more.setVisible(not self.more.isVisible())
        self._label_button()

    def _label_button(self) -> None:
        rest = len(self.all) - TOP_WARNINGS
        self.details_button.setText(f"▾ hide the other {rest} warnings" if self.more.isVisible()
                                    else f"▸ details: {rest} more warning{'s' if rest != 1 else ''}")

    def text(self) -> str:
        """The warnings shown in full (the first three)."""
        return self.top.text()


class ResultsStrip(QFrame):
    """The shot's key figures (module docstring)."""

    FIELDS = (
        ("sensitivity", "Sensitivity"),
        ("nominal", "vs nominal"),
        ("shock", "Shock sens."),
        ("fbsd_5", "FBSD ±5 %"),
        ("fbsd_10", "FBSD ±10 %"),
        ("resonance", "Resonance"),
        ("comp_5", "DCM ±5 %"),
        ("comp_10", "DCM ±10 %"),
        ("damping", "Damping ζ"),
        ("model", "Model"),
        ("peak", "Peak"),
        ("pulse", "Pulse width"),
        ("band", "Supported band"),
        ("band_limit", "DCM low-pass"),
        ("noise_gain", "DCM noise gain"),
        ("check_rms", "DCM RMS error"),
        ("check_peak", "DCM peak error"),
    )  # peak and width apart: "489 km/s² (49904 g), 36.0 µs" in one cell was cut off at 1280 × 800
    COLUMNS = 3

    def __init__(self, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.setFrameShape(QFrame.Shape.StyledPanel)
        self.setStyleSheet("ResultsStrip { background: #f8f9fa; border: 1px solid #dadce0; border-radius: 4px; }")
        layout = QGridLayout(self)
        layout.setContentsMargins(10, 3, 10, 3)
        layout.setHorizontalSpacing(8)
        layout.setVerticalSpacing(1)
        self.values: dict[str, QLabel] = {}
        for i, (key, caption) in enumerate(self.FIELDS):
            row, col = divmod(i, self.COLUMNS)
            title = QLabel(caption)
            title.setStyleSheet("color: #5f6368; font-size: 9pt;")
            title.setAlignment(Qt.AlignmentFlag.AlignRight | Qt.AlignmentFlag.AlignVCenter)
            value = QLabel("—")
            value.setStyleSheet("font-size: 10pt; font-weight: 600;")
            value.setWordWrap(True)  # a figure wider than its column wraps at a space instead of being cut off
            value.setTextInteractionFlags(Qt.TextInteractionFlag.TextSelectableByMouse)
            layout.addWidget(title, row, 2 * col)
            layout.addWidget(value, row, 2 * col + 1)
            layout.setColumnStretch(2 * col + 1, 1)
            self.values[key] = value
        self.grid = layout
        rows = -(-len(self.FIELDS) // self.COLUMNS)
        self.verdict = QLabel("")  # the DCM's verdict, when it is not recommended
        self.verdict.setWordWrap(True)
        self.verdict.setStyleSheet(f"color: {TEXT_COLOURS['error']}; font-size: 9pt; font-weight: 700;")
        self.verdict.setVisible(False)
        layout.addWidget(self.verdict, rows, 0, 1, 2 * self.COLUMNS)
        self.warnings = WarningsBox()
        layout.addWidget(self.warnings, rows + 1, 0, 1, 2 * self.COLUMNS)

    def clear(self) -> None:
        for label in self.values.values():
            label.setText("—")
            label.setToolTip("")
            label.setStyleSheet("font-size: 10pt; font-weight: 600;")
        self.verdict.setText("")
        self.verdict.setVisible(False)
        self.warnings.show_warnings(())

    def _set(self, key: str, text: str, tooltip: str = "", colour: str = "") -> None:
        self.values[key].setText(text)
        self.values[key].setToolTip(tooltip)
        if colour:
            self.values[key].setStyleSheet(f"font-size: 10pt; font-weight: 600; color: {colour};")

    def _figure(self, key: str, figure: Figure | None, scale: float, unit: str, decimals: int, tip: str,
                not_determined: str = "") -> None:
        """A figure as value ± U; "not determined" (with its reason in the tooltip) when the
        analysis could not estimate it."""
        if figure is not None and (figure.value is None or not math.isfinite(figure.value)):
            reason = figure.not_determined or not_determined
            self._set(key, "not determined", f"{tip}: not determined" + (f" — {reason}" if reason else ""),
                      TEXT_COLOURS["warning"])
            return
        if figure is None and not_determined:
            self._set(key, "not determined", f"{tip}: not determined — {not_determined}", TEXT_COLOURS["warning"])
            return
        self._set(key, format_figure(figure, scale, unit, decimals), f"{tip}; " + figure_tooltip(figure, scale, unit))

    def show_figures(self, kf: KeyFigures | None, check: CompensationCheck | None = None,
                     dcm_ratio: float | None = None, judgement: ShotJudgement | None = None) -> None:
        """Show a shot's key figures (the DCM's check on it, when stored; its judgement, for the
        sensitivity in the sensor's unit)."""
        self.clear()
        if kf is None:
            return
        band = kf.supported_band_hz
        for level in LEVEL_KEYS:
            bound = kf.fbsd_bounds.get(level)
            figure = kf.fbsd_hz.get(level)
            if bound is not None:
                self._set(f"fbsd_{level}", f"> {bound.lower_bound_hz / KILO:.1f} kHz", bound.reason)
            else:
                self._figure(f"fbsd_{level}", figure, KILO, "kHz", 2, f"FBSD ±{level} % of the model")
            self._set(f"comp_{level}", format_khz(kf.compensated_fbsd_hz.get(level)),
                      f"DCM r = {dcm_ratio:.3g}" if dcm_ratio else "")
        self._set("model", f"order {kf.order}" + (f", fit {kf.fit_percent:.1f} %" if kf.fit_percent is not None else "")
                  if kf.order is not None else "—", "model order; fit = 100·(1 − ‖y − ŷ‖/‖y − ȳ‖)")
        outside = ("no resonance inside the supported band" + (f" ({band[0] / KILO:.3g}–{band[1] / KILO:.3g} kHz)"
                                                               if band else "")
                   + ": a peak the magnitude plot shows beyond it is the model's extrapolation")
        self._figure("resonance", kf.natural_frequency_hz, KILO, "kHz", 2,
                     "main mode: the lowest supported complex pole pair", outside)
        self._figure("damping", kf.damping_ratio, 1.0, "", 3, "damping ratio of the main mode",
                     outside if kf.natural_frequency_hz is None else "")
        self._set("band", "—" if band is None else f"{band[0] / KILO:.3g}–{band[1] / KILO:.3g} kHz",
                  "the band the excitation supports (the identification fits inside it)")
        self._sensitivities(kf, judgement)
        if kf.peak_acceleration_m_s2 is not None and kf.peak_acceleration_m_s2.value is not None:
            peak = kf.peak_acceleration_m_s2.value  # as the report: km/s² and g
            self._set("peak", f"{peak / KILO:.0f} km/s² ({peak / G_M_S2:.0f} g)",
                      "peak acceleration of the reference pulse")
        if kf.pulse_width_s is not None and kf.pulse_width_s.value is not None:
            self._set("pulse", f"{kf.pulse_width_s.value * 1e6:.1f} µs",
                      "pulse width at 10 % of the peak (ISO 16063-22)")
        if check is not None:
            self._show_check(check)
        warnings = check.other_warnings(kf.warnings) if check is not None else list(kf.warnings)
        self.warnings.show_warnings(warnings)
        self._share_width()

    def _sensitivities(self, kf: KeyFigures, judgement: ShotJudgement | None) -> None:
        """In the sensor's unit with the ratio to nominal beside it when the shot says its
        nominal; else as the analysis has it (× nominal, or V/(m/s²))."""
        absolute = judgement.sensitivity if judgement is not None else None
        if absolute is None:
            per = "× nominal" if kf.response_unit == "m/s^2" else "V/(m/s²)" if kf.response_unit == "V" else ""
            self._figure("sensitivity", kf.sensitivity, 1.0, per, 4, "DC gain of the model")
            self._figure("shock", kf.shock_sensitivity, 1.0, per, 4, "ISO 16063-13 peak ratio",
                         kf.not_determined.get("shock_sensitivity", ""))
            return
        assert judgement is not None
        unit = judgement.unit
        self._set("sensitivity", absolute.text(), f"DC gain of the model, in {unit.name} (U: 95 %, k ≈ 2)")
        shock = judgement.shock_sensitivity
        if shock is not None:
            self._set("shock", shock.text(), f"ISO 16063-13 peak ratio, in {unit.name}")
        else:
            self._figure("shock", kf.shock_sensitivity, 1.0, "", 4, "ISO 16063-13 peak ratio",
                         kf.not_determined.get("shock_sensitivity", ""))
        if absolute.ratio is None:
            return
        finding = judgement.verdict.finding(Check.SENSITIVITY)
        flagged = finding is not None and finding.status == Status.FLAG
        nominal = f"nominal {unit.from_si(judgement.nominal_si or 0.0):.4g} {unit.name}"
        tolerance = (f"; tolerance ±{judgement.tolerance_percent:g} %" if judgement.tolerance_percent
                     else "; no tolerance set")
        self._set("nominal", absolute.ratio_text().replace(" nominal", ""), nominal + tolerance,
                  TEXT_COLOURS["error"] if flagged else "")

    def _share_width(self) -> None:
        """Give each column of figures a share of the width in proportion to its longest figure
        (equal shares wrapped "1.6073 ± 0.0091 × nominal" beside a half-empty column)."""
        keys = [key for key, _caption in self.FIELDS]
        for col in range(self.COLUMNS):
            widths = []
            for key in keys[col::self.COLUMNS]:
                label = self.values[key]
                label.ensurePolished()  # the style sheet's font
                widths.append(label.fontMetrics().horizontalAdvance(label.text()))
            self.grid.setColumnStretch(2 * col + 1, max(1, *widths))

    def _show_check(self, check: CompensationCheck) -> None:
        tip = "error over the pulse relative to its peak: without → with the DCM, on this shot itself"
        for key, pair in (("check_rms", check.rms_error_pct), ("check_peak", check.peak_error_pct)):
            self._set(key, "—" if pair is None else f"{_pct(pair[0])} → {_pct(pair[1])}", tip)
        self._set("band_limit", "—" if check.band_limit_hz is None else f"{check.band_limit_hz / KILO:.1f} kHz",
                  f"band limit of the compensation: {BAND_LIMIT_TIP}")
        if check.noise_gain is not None:
            self._set("noise_gain", f"×{check.noise_gain:.3g}" + (f" (limit ×{check.noise_gain_limit:.3g})"
                                                                  if check.noise_gain_limit else ""),
                      "RMS amplification of white noise by the DCM at the analysis rate")
        if check.not_recommended_text is not None:
            self.verdict.setText(f"DCM NOT RECOMMENDED: {check.not_recommended_text}")
            self.verdict.setVisible(True)


def _pct(value: float | None) -> str:
    return "—" if value is None else f"{value:.3g} %"


def _escape(text: str) -> str:
    from html import escape

    return escape(text, quote=False)


class ShotPlots(QWidget):
    """The last shot: its verdict and key figures over a 2 × 3 grid of plots (module docstring)."""

    def __init__(self, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.view: ShotView | None = None
        self.title = QLabel("No shot yet — set up the shot and press ARM.")
        self.title.setStyleSheet("font-size: 10pt; color: #3c4043;")
        self.title.setWordWrap(True)
        self.verdict_bar = VerdictBar()
        self.strip = ResultsStrip()

        self.pm_plot = _plot("PM beat (Doppler channel)", "PM signal", "time from trigger", "V", "s")
        self.pm_curve = self.pm_plot.plot([], [], pen=PM_PEN)
        self.pm_curve.setDownsampling(auto=True, method="peak")
        self.pm_curve.setClipToView(True)
        self.pm_plot.setMouseEnabled(x=True, y=False)

        self.accel_plot = _plot("Reference and response", "acceleration (km/s²)", "time", None, "s")
        legend_below(self.accel_plot)
        self.response_curve = self.accel_plot.plot([], [], pen=RESP_PEN, name="accelerometer")
        self.reference_curve = self.accel_plot.plot([], [], pen=REF_PEN, name="reference")
        self.reference_curve.setZValue(5)
        self.accel_note = pg.TextItem("", color=TEXT_COLOURS["error"], anchor=(0, 0))
        self.accel_plot.addItem(self.accel_note, ignoreBounds=True)

        self.loss_plot = _plot("Loss by model order", "loss (response units²)", "model order")
        self.loss_plot.setLogMode(x=False, y=True)
        legend_below(self.loss_plot)
        self.loss_curve = self.loss_plot.plot([], [], pen=pg.mkPen("#1f6fd1", width=2), symbol="o", symbolSize=6,
                                              symbolBrush="#1f6fd1", name="bias-corrected")
        self.arx_curve = self.loss_plot.plot([], [], pen=pg.mkPen("#9aa0a6", width=1.5), symbol="t", symbolSize=6,
                                             symbolBrush="#9aa0a6", name="least squares")
        self.order_line = pg.InfiniteLine(angle=90, pen=pg.mkPen("#d0312d", width=2),
                                          label="chosen order",
                                          labelOpts={"position": 0.12, "color": "#d0312d", "fill": (255, 255, 255, 200)})
        self.order_line.setVisible(False)
        self.loss_plot.addItem(self.order_line)

        self.mag_plot = MagnitudePlot("Magnitude |H(f)/H(0)|", "model", "with DCM", legend_columns=3)
        self.fbsd_lines = self.mag_plot.fbsd_lines

        self.pz_plot = _plot("Pole-zero map (z-plane)", "imaginary", "real")
        self.pz_plot.setAspectLocked(True)
        legend_below(self.pz_plot, columns=2)
        theta = np.linspace(0, 2 * np.pi, 721)
        self.pz_plot.plot(np.cos(theta), np.sin(theta), pen=pg.mkPen("#9aa0a6", width=1))
        self.pole_scatter = pg.ScatterPlotItem(symbol="x", size=11, pen=pg.mkPen("#1f6fd1", width=2),
                                               brush=pg.mkBrush("#1f6fd1"), name="poles")
        self.zero_scatter = pg.ScatterPlotItem(symbol="o", size=9, pen=pg.mkPen("#1f6fd1", width=1.5),
                                               brush=pg.mkBrush(None), name="zeros")
        self.dcm_scatter = pg.ScatterPlotItem(symbol="+", size=11, pen=pg.mkPen("#d0312d", width=2),
                                              brush=pg.mkBrush("#d0312d"), name="DCM poles")
        self.truth_scatter = pg.ScatterPlotItem(symbol="d", size=10, pen=pg.mkPen("#2e9d43", width=1.5),
                                                brush=pg.mkBrush(None), name="true (sim.)")
        for item in (self.pole_scatter, self.zero_scatter, self.dcm_scatter, self.truth_scatter):
            self.pz_plot.addItem(item)

        self.trend = LiveTrend()

        plots = QWidget()
        rows = QVBoxLayout(plots)
        rows.setContentsMargins(0, 0, 0, 0)
        rows.setSpacing(6)
        # the shot's response and magnitude first and widest; the live gauges, PM beat, losses, poles smaller
        for stretch, widgets in ((3, ((self.accel_plot, 2), (self.mag_plot, 2), (self.trend, 1))),
                                 (2, ((self.pm_plot, 1), (self.loss_plot, 1), (self.pz_plot, 1)))):
            row = QHBoxLayout()
            row.setSpacing(6)
            for widget, width in widgets:
                row.addWidget(widget, width)
            rows.addLayout(row, stretch)

        results = QWidget()
        top = QVBoxLayout(results)
        top.setContentsMargins(0, 0, 4, 0)
        top.setSpacing(3)
        top.addWidget(self.title)
        top.addWidget(self.verdict_bar)
        top.addWidget(self.strip)
        self.results_scroll = QScrollArea()
        self.results_scroll.setWidgetResizable(True)
        self.results_scroll.setFrameShape(QFrame.Shape.NoFrame)
        self.results_scroll.setWidget(results)
        self.results_scroll.setHorizontalScrollBarPolicy(Qt.ScrollBarPolicy.ScrollBarAlwaysOff)

        self.splitter = QSplitter(Qt.Orientation.Vertical)
        self.splitter.addWidget(self.results_scroll)
        self.splitter.addWidget(plots)
        self.splitter.setStretchFactor(0, 0)
        self.splitter.setStretchFactor(1, 1)
        self.splitter.setChildrenCollapsible(False)
        layout = QVBoxLayout(self)
        layout.setContentsMargins(4, 4, 4, 4)
        layout.addWidget(self.splitter)
        self._fit_results()

    def resizeEvent(self, event: object) -> None:  # noqa: N802 (Qt's name)
        super().resizeEvent(event)  # type: ignore[arg-type]
        self._fit_results()

    def _fit_results(self) -> None:
        """The results part as tall as its content needs, at most 40 % of the tab (it scrolls then)."""
        content = self.results_scroll.widget()
        width = self.results_scroll.viewport().width()
        layout = content.layout()
        need = (layout.totalHeightForWidth(width) if layout.hasHeightForWidth() else content.sizeHint().height()) + 4
        total = max(1, self.splitter.height())
        top = min(need, int(0.40 * total))
        self.splitter.setSizes([top, max(1, total - top)])

    # -- drawing ---------------------------------------------------------------------------------
    def clear(self, title: str = "") -> None:
        """Forget the last shot's plots (the live trend keeps running)."""
        self.view = None
        for curve in (self.pm_curve, self.reference_curve, self.response_curve, self.loss_curve, self.arx_curve):
            curve.setData([], [])
        for scatter in (self.pole_scatter, self.zero_scatter, self.dcm_scatter, self.truth_scatter):
            scatter.setData([], [])
        self.order_line.setVisible(False)
        self.mag_plot.clear_curves()
        self.accel_note.setText("")
        self.strip.clear()
        self.verdict_bar.clear()
        if title:
            self.title.setText(title)
        self._fit_results()

    def show_view(self, view: ShotView) -> None:
        """Draw a prepared shot (ShotView)."""
        self.clear()
        self.view = view
        self.title.setText(view.title or (str(view.path) if view.path else "shot"))
        if view.pm_time_s is not None and view.pm_volts is not None:
            self.pm_curve.setData(view.pm_time_s, view.pm_volts)
            self.pm_plot.getPlotItem().enableAutoRange()
        window = None
        record = view.record
        if record is not None:
            t, reference, response = record.time_s, np.asarray(record.reference), np.asarray(record.response)
            self.accel_plot.setLabel("left", "acceleration (km/s²)")
            self.reference_curve.setData(t, reference / KILO)
            self.response_curve.setData(t, response / KILO)
            window = pulse_window_s(t, reference, response)
        elif view.raw_response_v is not None and view.pm_time_s is not None:
            self.accel_plot.setLabel("left", "amplifier output", units="V")
            self.response_curve.setData(view.pm_time_s, view.raw_response_v)
        if view.analysis_error:
            self.accel_note.setText(f"not analysed: {_short(view.analysis_error)}")
            self.accel_note.setPos(0, 0)
        self.accel_plot.getPlotItem().enableAutoRange()
        if window is not None:
            self.accel_plot.setXRange(*window, padding=0)
            set_y_to_curves(self.accel_plot, reference / KILO, response / KILO)
        self._show_losses(view)
        self._show_magnitude(view)
        self._show_poles(view)
        design = view.dcm.design if view.dcm is not None else None
        if view.judgement is not None:
            self.verdict_bar.show_verdict(view.judgement.verdict)
        self.strip.show_figures(view.figures, view.compensation, (design or {}).get("ratio"), view.judgement)
        self._fit_results()

    def _show_losses(self, view: ShotView) -> None:
        def finite(values: list[float | None]) -> tuple[np.ndarray, np.ndarray]:
            orders = np.array([i + 1 for i, v in enumerate(values) if v is not None and v > 0 and math.isfinite(v)])
            losses = np.array([v for v in values if v is not None and v > 0 and math.isfinite(v)], dtype=float)
            return orders, losses

        self.loss_curve.setData(*finite(view.loss_by_order))
        self.arx_curve.setData(*finite(view.arx_loss_by_order))
        if view.order is not None and view.loss_by_order:
            self.order_line.setVisible(True)  # (an InfiniteLine's label only updates while visible)
            self.order_line.setValue(view.order)
            self.order_line.label.setFormat(f"chosen order {view.order}")
        self.loss_plot.getPlotItem().enableAutoRange()

    def _show_magnitude(self, view: ShotView) -> None:
        if view.frequency_hz is None or view.magnitude is None:
            return
        self.mag_plot.show_curves(view.frequency_hz, view.magnitude, view.compensated_magnitude, view.fbsd_hz,
                                  view.response_band)

    def _show_poles(self, view: ShotView) -> None:
        if view.model is None:
            return
        p, z = view.model.poles, view.model.zeros
        self.pole_scatter.setData(p.real, p.imag)
        self.zero_scatter.setData(z.real, z.imag)
        if view.dcm is not None:
            d = view.dcm.poles
            self.dcm_scatter.setData(d.real, d.imag)
        if view.true_poles is not None:
            t = view.true_poles
            self.truth_scatter.setData(t.real, t.imag)
        self.pz_plot.setXRange(-1.1, 1.1, padding=0)
        self.pz_plot.setYRange(-1.1, 1.1, padding=0)
