"""The shot's plots (pyqtgraph) and the data behind them.

`load_shot_view(path)` reads a shot file and prepares everything the plots show (pure NumPy,
run off the GUI thread); `ShotPlots.show_view(view)` draws it:

- PM beat: the raw photomultiplier channel (volts against time from the trigger), zoomable
  with the mouse (wheel / drag; right-click → "View All" resets), drawn with peak-preserving
  downsampling so a 10 M-sample record stays fluid;
- reference acceleration and the accelerometer's response (both m/s², on the analysis record)
  overlaid;
- the loss of every model order (bias-corrected and plain least squares), the chosen order marked;
- the normalised magnitude |H(f)/H(0)| of the identified model and of the model followed by the
  DCM, with the ±5 % / ±10 % bands shaded and the FBSD edges marked;
- the pole-zero map (model poles ×, zeros ○, DCM poles +; the unit circle; in simulation the
  true poles ◇);
- the live reservoir pressure and fixture vacuum (`LiveTrend`, fed by the reading events).

The analysis maths is the analysis package's (normalised_gain_function, DCM.frequency_response);
this module only samples it for drawing.
"""

from __future__ import annotations

import math
import time
from collections import deque
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pyqtgraph as pg
from hopkinson.analysis.dcm import DCM
from hopkinson.analysis.dcm_design import ShotSupport
from hopkinson.analysis.key_figures import Figure, KeyFigures
from hopkinson.analysis.model import DiscreteModel
from hopkinson.analysis.records import Record
from hopkinson.analysis.response import normalised_gain_function
from hopkinson.reports.data import G_M_S2, CompensationCheck
from pyqtgraph.util.garbage_collector import GarbageCollector
from PySide6.QtCore import Qt
from PySide6.QtWidgets import QFrame, QGridLayout, QLabel, QVBoxLayout, QWidget

LEVEL_KEYS = ("5", "10")
BAND_COLOURS = {"5": (46, 157, 67, 45), "10": (224, 160, 16, 35)}
EDGE_COLOURS = {"5": "#2e9d43", "10": "#c98a00"}
MODEL_PEN = pg.mkPen("#1f6fd1", width=2)
COMP_PEN = pg.mkPen("#d0312d", width=2, style=Qt.PenStyle.DashLine)
REF_PEN = pg.mkPen("#202124", width=2)
RESP_PEN = pg.mkPen("#1f6fd1", width=1.5)
PM_PEN = pg.mkPen("#5b3fa8", width=1)
KILO = 1e3


_GUI_THREAD_GC: GarbageCollector | None = None


def configure_pyqtgraph() -> None:
    """White plots with dark text and anti-aliasing (lab-report look); garbage collected on the GUI thread.

    Python's cycle collector runs in whichever thread happens to allocate. When that is a worker
    (the rig I/O thread, a report export), it can destroy pyqtgraph's Qt objects there while the
    GUI thread deletes widgets, and the two threads deadlock (seen in the panel's tests). pyqtgraph's
    GarbageCollector disables automatic collection and collects from a GUI-thread timer instead;
    installed once per process.
    """
    global _GUI_THREAD_GC
    pg.setConfigOptions(background="w", foreground="#202124", antialias=True)
    if _GUI_THREAD_GC is None:
        _GUI_THREAD_GC = GarbageCollector(interval=0.5)


@dataclass
class ShotView:
    """Everything the shot plots show, prepared off the GUI thread."""

    path: Path | None = None
    title: str = ""
    pm_time_s: np.ndarray | None = None
    pm_volts: np.ndarray | None = None
    record: Record | None = None  # the analysis record (reference and response in m/s²)
    raw_response_v: np.ndarray | None = None  # when there is no analysed record
    loss_by_order: list[float | None] = field(default_factory=list)
    arx_loss_by_order: list[float | None] = field(default_factory=list)
    order: int | None = None
    model: DiscreteModel | None = None
    dcm: DCM | None = None
    fbsd_hz: dict[str, float] = field(default_factory=dict)
    frequency_hz: np.ndarray | None = None
    magnitude: np.ndarray | None = None
    compensated_magnitude: np.ndarray | None = None
    true_poles: np.ndarray | None = None
    support: ShotSupport | None = None  # what the shot tells a DCM design (its modes, band)
    band_limit_hz: float | None = None  # the shot's DCM band limit (0: none)
    figures: KeyFigures | None = None  # the shot's key figures (analysis.key_figures)
    compensation: CompensationCheck | None = None  # the DCM's check on the shot, when stored
    analysis_error: str | None = None
    response_band: dict[str, Any] | None = None  # the model's response with its 95 % band (analysis.uncertainty)


def frequency_grid_hz(sample_interval_s: float, lowest_hz: float = 100.0, points: int = 1500) -> np.ndarray:
    """Log-spaced frequencies from `lowest_hz` to just below Nyquist."""
    nyquist = 0.5 / sample_interval_s
    return np.geomspace(lowest_hz, 0.999 * nyquist, points)


def magnitudes(model: DiscreteModel, dcm: DCM | None, frequency_hz: np.ndarray) -> tuple[np.ndarray, np.ndarray | None]:
    """|H(f)/H(0)| of the model (the gain its FBSD is found on), and of the model followed by the
    DCM (None without a DCM)."""
    model_mag = normalised_gain_function(model.b, model.a, model.sample_interval_s)(frequency_hz)
    if dcm is None:
        return model_mag, None
    return model_mag, model_mag * np.abs(dcm.frequency_response(frequency_hz)) / abs(dcm.dc_gain)


def view_from_results(results: dict[str, Any], record: Record | None = None) -> ShotView:
    """A ShotView of an analysis results dict (and its record, when known); no raw channels."""
    from hopkinson.analysis.shot_analysis import ShotAnalysis

    analysis = ShotAnalysis.from_dict(results, record)
    ident = results.get("identification", {}) or {}
    model, dcm = analysis.model, analysis.dcm
    f = frequency_grid_hz(model.sample_interval_s)
    mag, comp = magnitudes(model, dcm, f)
    figures = KeyFigures.from_results(results)
    stored_dcm = results.get("dcm") or {}
    # the shot's own band limit (0: it had none); None for results from before band limits
    band_limit_hz = float(stored_dcm["band_limit_hz"] or 0.0) if "band_limit_hz" in stored_dcm else None
    return ShotView(
        support=ShotSupport.from_dict(ident, model), band_limit_hz=band_limit_hz,
        loss_by_order=list(ident.get("loss_by_order", [])),
        arx_loss_by_order=list(ident.get("arx_loss_by_order", [])),
        order=ident.get("order", model.order),
        model=model, dcm=dcm, fbsd_hz=dict(analysis.fbsd_hz),
        frequency_hz=f, magnitude=mag, compensated_magnitude=comp, record=record,
        figures=figures, compensation=CompensationCheck.of(figures),
        response_band=(results.get("uncertainty") or {}).get("response_band"),
    )


def load_shot_view(path: str | Path) -> ShotView:
    """Read a shot file and prepare its plots (raw PM beat always; the rest when analysed)."""
    from hopkinson.rig.shotfile import read_shot

    shot = read_shot(path)
    if shot.results and shot.analysis_error is None:
        view = view_from_results(shot.results, shot.record)
    else:
        view = ShotView(analysis_error=shot.analysis_error or "the shot has not been analysed")
    view.path = Path(path)
    meta = shot.meta
    view.title = (f"{Path(path).name} — {meta.accelerometer_model or 'accelerometer'} "
                  f"{meta.accelerometer_serial}".rstrip() + f", {meta.pressure_bar:g} bar, projectile No. {meta.projectile}")
    if shot.raw is not None:
        view.pm_time_s = shot.raw.time_s
        view.pm_volts = shot.raw.volts("doppler")
        if view.record is None:
            view.raw_response_v = shot.raw.volts("response")
    truth = meta.simulated_truth
    if truth and view.model is not None:
        view.true_poles = _true_poles(truth, view.model.sample_interval_s)
    return view


def pulse_window_s(time_s: np.ndarray, reference: np.ndarray, response: np.ndarray) -> tuple[float, float] | None:
    """The time span worth looking at: from a little before the pulse to where the response has
    rung down (|x| above 3 % of its peak), with margins; None for an empty record."""
    if time_s.size < 2:
        return None
    ref, resp = np.abs(reference), np.abs(response)
    if not (np.max(ref) > 0 and np.max(resp) > 0):
        return None
    pulse = np.flatnonzero(ref > 0.05 * np.max(ref))
    start = int(pulse[0])
    end = int(max(np.flatnonzero(resp > 0.03 * np.max(resp))[-1], pulse[-1]))
    span = max(time_s[end] - time_s[start], 10 * (time_s[1] - time_s[0]))
    return float(max(time_s[0], time_s[start] - 0.15 * span)), float(min(time_s[-1], time_s[end] + 0.15 * span))


def set_y_with_legend_room(plot: pg.PlotWidget, *curves: np.ndarray) -> None:
    """Y range of the curves with a third of free space on top, where the legend sits."""
    values = np.concatenate([np.asarray(c, dtype=float).ravel() for c in curves])
    values = values[np.isfinite(values)]
    if values.size == 0:
        return
    lo, hi = float(values.min()), float(values.max())
    span = hi - lo if hi > lo else 1.0
    plot.setYRange(lo - 0.05 * span, hi + 0.5 * span, padding=0)


def _true_poles(truth: dict[str, Any], sample_interval_s: float) -> np.ndarray | None:
    """The simulated accelerometer's discrete poles at the analysis interval (simulation only)."""
    try:
        from hopkinson.drivers.sim.world import accelerometer_truth

        return accelerometer_truth(truth).discrete_poles(sample_interval_s)
    except Exception:  # an older or partial truth record: the map simply goes without it
        return None


def configure_plot(widget: pg.PlotWidget, title: str, left: str, bottom: str, left_units: str | None = None,
                   bottom_units: str | None = None) -> pg.PlotWidget:
    """Title, axis labels (units in the label, or SI-prefixed by pyqtgraph when given), grid."""
    item = widget.getPlotItem()
    item.setTitle(f"<span style='font-size:10pt; font-weight:600'>{title}</span>")
    item.setLabel("left", left, units=left_units)
    item.setLabel("bottom", bottom, units=bottom_units)
    item.showGrid(x=True, y=True, alpha=0.25)
    for side, units in (("left", left_units), ("bottom", bottom_units)):
        axis = item.getAxis(side)
        axis.setTextPen("#202124")
        if units is None:  # the unit is in the label text: no "(x0.001)" scale factor
            axis.enableAutoSIPrefix(False)
        if side == "left":
            axis.setWidth(56)
    widget.setMinimumSize(200, 150)
    return widget


def _plot(title: str, left: str, bottom: str, left_units: str | None = None,
          bottom_units: str | None = None) -> pg.PlotWidget:
    return configure_plot(pg.PlotWidget(), title, left, bottom, left_units, bottom_units)


def format_khz(value: float | None) -> str:
    """A frequency in Hz as "12.34 kHz" ("—" when unknown)."""
    if value is None or not math.isfinite(value):
        return "—"
    return f"{value / KILO:.2f} kHz"


def format_figure(figure: Figure | None, scale: float = 1.0, unit: str = "", decimals: int = 2) -> str:
    """value ± U (k ≈ 2, U to two significant digits) when the figure has its uncertainty, else
    the value with `decimals` decimals; "—" when unknown."""
    if figure is None or figure.value is None or not math.isfinite(figure.value):
        return "—"
    if figure.expanded is not None:
        return figure.format(scale, unit=unit)
    return f"{figure.value / scale:.{decimals}f}" + (f" {unit}" if unit else "")


def figure_tooltip(figure: Figure | None, scale: float = 1.0, unit: str = "") -> str:
    """The standard uncertainty and the 95 % interval, for a tooltip ("" without them)."""
    if figure is None or figure.u is None or figure.interval is None:
        return ""
    lo, hi = figure.interval
    return (f"u = {figure.u / scale:.3g} {unit}, 95 % interval [{lo / scale:.6g}, {hi / scale:.6g}] {unit}; "
            "U = half the interval (k ≈ 2)")


class PlainLogAxis(pg.AxisItem):
    """A logarithmic axis labelled in plain numbers: 0.1, 1, 10, 100 (kHz) and 20, 50 between
    them, where pyqtgraph's own labels mix "1" with "10¹", "10²" and "2·10¹"."""

    def logTickStrings(self, values: list[float], scale: float, spacing: float) -> list[str]:  # noqa: N802 (pyqtgraph's name)
        return [f"{float(f'{10 ** float(v) * scale:.3g}'):f}".rstrip("0").rstrip(".") for v in values]


class MagnitudePlot(pg.PlotWidget):
    """Normalised magnitude on a log-frequency axis (kHz), linear gain 0 … 2 so the ±5 % and
    ±10 % bands (shaded) are readable; FBSD edges as labelled vertical lines; a resonance peak
    above the scale is noted in words (zoom out with the mouse to see it)."""

    Y_MAX = 2.0

    def __init__(self, title: str, model_name: str, compensated_name: str, edge_prefix: str = "") -> None:
        super().__init__(axisItems={"bottom": PlainLogAxis("bottom")})
        configure_plot(self, title, "normalised magnitude", "frequency (kHz)")
        self.setLogMode(x=True, y=False)
        self.addLegend(offset=(5, -5), labelTextSize="8pt")
        self.edge_prefix = edge_prefix
        for key in ("10", "5"):
            level = int(key) / 100
            band = pg.LinearRegionItem(values=(1 - level, 1 + level), orientation="horizontal",
                                       brush=pg.mkBrush(*BAND_COLOURS[key]), pen=pg.mkPen(None), movable=False)
            band.setZValue(-10)
            self.addItem(band)
        # the model's 95 % band (Monte Carlo draws), under its curve
        self.band_low = pg.PlotDataItem([], [], pen=pg.mkPen(None))
        self.band_high = pg.PlotDataItem([], [], pen=pg.mkPen(None))
        self.band_fill = pg.FillBetweenItem(self.band_low, self.band_high, brush=pg.mkBrush(31, 111, 209, 70))
        for item in (self.band_low, self.band_high, self.band_fill):
            item.setZValue(-5)
            self.addItem(item)
        # the legend's sample of the band: a filled curve never drawn (pyqtgraph's legend cannot
        # draw a FillBetweenItem's sample: it crashed in paint)
        self.band_sample = pg.PlotDataItem([], [], pen=pg.mkPen(None), fillLevel=0.0, brush=self.band_fill.brush())
        self.magnitude_curve = self.plot([], [], pen=MODEL_PEN, name=model_name)
        self.compensated_curve = self.plot([], [], pen=COMP_PEN, name=compensated_name)
        self.fbsd_lines: dict[str, pg.InfiniteLine] = {}
        for i, key in enumerate(LEVEL_KEYS):
            line = pg.InfiniteLine(angle=90, pen=pg.mkPen(EDGE_COLOURS[key], width=1.5, style=Qt.PenStyle.DashLine),
                                   label="", labelOpts={"position": 0.93 - 0.09 * i, "color": EDGE_COLOURS[key],
                                                        "fill": (255, 255, 255, 220), "anchors": [(1, 0.5), (1, 0.5)]})
            line.setVisible(False)
            self.addItem(line)
            self.fbsd_lines[key] = line
        # on a white ground: the resonance's rising curve runs through the note's corner of the plot
        self.peak_note = pg.TextItem("", color="#3c4043", anchor=(1, 1), fill=(255, 255, 255, 220))
        self.peak_note.setZValue(20)
        self.addItem(self.peak_note, ignoreBounds=True)
        self.setYRange(0, self.Y_MAX, padding=0)

    def clear_curves(self) -> None:
        self.show_band(None)
        self.magnitude_curve.setData([], [])
        self.compensated_curve.setData([], [])
        for line in self.fbsd_lines.values():
            line.setVisible(False)
        self.peak_note.setText("")

    def show_band(self, band: dict[str, Any] | None) -> None:
        """Shade the model's 95 % magnitude band (analysis.uncertainty.response_band; None: none)."""
        legend = self.getPlotItem().legend
        legend.removeItem(self.band_sample)
        if not band:
            self.band_low.setData([], [])
            self.band_high.setData([], [])
            return
        f_khz = np.asarray(band["frequency_hz"], dtype=float) / KILO
        self.band_low.setData(f_khz, np.asarray(band["magnitude_rel_low"], dtype=float))
        self.band_high.setData(f_khz, np.asarray(band["magnitude_rel_high"], dtype=float))
        legend.addItem(self.band_sample, f"{100 * band.get('coverage_probability', 0.95):.0f} % band of the model")

    def show_curves(self, frequency_hz: np.ndarray, magnitude: np.ndarray, compensated: np.ndarray | None,
                    fbsd_hz: dict[str, float], band: dict[str, Any] | None = None) -> None:
        """Draw the curves (|H/H0|), the model's 95 % band when known, and mark the FBSD edges
        (Hz per level key)."""
        self.show_band(band)
        f_khz = np.asarray(frequency_hz) / KILO
        self.magnitude_curve.setData(f_khz, magnitude)
        if compensated is None:
            self.compensated_curve.setData([], [])
        else:
            self.compensated_curve.setData(f_khz, compensated)
        show_fbsd(self.fbsd_lines, fbsd_hz, self.edge_prefix)
        lo, hi = math.log10(f_khz[0]), math.log10(f_khz[-1])
        self.setXRange(lo, hi, padding=0)
        self.setYRange(0, self.Y_MAX, padding=0)
        i = int(np.nanargmax(magnitude))
        if magnitude[i] > self.Y_MAX:
            self.peak_note.setText(f"peak ×{magnitude[i]:.1f}\nat {f_khz[i]:.1f} kHz ↑")
            self.peak_note.setPos(hi, 0.8 * self.Y_MAX)
        else:
            self.peak_note.setText("")


# What the DCM's band limit is, as its tooltips say (the strip here, the DCM tab).
BAND_LIMIT_TIP = ("the cut-off (−3 dB) of its linear-phase low-pass (4th-order Butterworth magnitude); its ±5 % edge "
                  "is the top of what the shot vouches for")


class ResultsStrip(QFrame):
    """The shot's key figures (analysis.key_figures): FBSD before and with the DCM, model,
    resonance, sensitivities and pulse, each as value ± U (k ≈ 2) when the shot carries its
    uncertainty; the DCM's check on the shot and, when it is not recommended, why."""

    FIELDS = (
        ("fbsd_5", "FBSD ±5 %"),
        ("fbsd_10", "FBSD ±10 %"),
        ("resonance", "Resonance"),
        ("comp_5", "DCM ±5 %"),
        ("comp_10", "DCM ±10 %"),
        ("damping", "Damping ζ"),
        ("model", "Model"),
        ("sensitivity", "Sensitivity"),
        ("shock", "Shock sens."),
        ("peak", "Peak"),
        ("pulse", "Pulse width"),
        ("band_limit", "DCM low-pass"),
        ("check_rms", "DCM RMS error"),
        ("check_peak", "DCM peak error"),
        ("noise_gain", "DCM noise gain"),
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
        self.verdict = QLabel("")
        self.verdict.setWordWrap(True)
        self.verdict.setStyleSheet("color: #b3261e; font-size: 9pt; font-weight: 700;")
        self.verdict.setVisible(False)
        layout.addWidget(self.verdict, rows, 0, 1, 2 * self.COLUMNS)
        self.warnings = QLabel("")
        self.warnings.setWordWrap(True)
        self.warnings.setStyleSheet("color: #8a5a00; font-size: 9pt;")
        self.warnings.setVisible(False)
        layout.addWidget(self.warnings, rows + 1, 0, 1, 2 * self.COLUMNS)

    def clear(self) -> None:
        for label in self.values.values():
            label.setText("—")
            label.setToolTip("")
        for label in (self.verdict, self.warnings):
            label.setText("")
            label.setVisible(False)

    def _set(self, key: str, text: str, tooltip: str = "") -> None:
        self.values[key].setText(text)
        self.values[key].setToolTip(tooltip)

    def show_figures(self, kf: KeyFigures | None, check: CompensationCheck | None = None,
                     dcm_ratio: float | None = None) -> None:
        """Show a shot's key figures (and the DCM's check on it, when stored)."""
        self.clear()
        if kf is None:
            return
        for level in LEVEL_KEYS:
            bound = kf.fbsd_bounds.get(level)
            figure = kf.fbsd_hz.get(level)
            if bound is not None:
                self._set(f"fbsd_{level}", f"> {bound.lower_bound_hz / KILO:.1f} kHz", bound.reason)
            else:
                self._set(f"fbsd_{level}", format_figure(figure, KILO, "kHz"), figure_tooltip(figure, KILO, "kHz"))
            self._set(f"comp_{level}", format_khz(kf.compensated_fbsd_hz.get(level)),
                      f"DCM r = {dcm_ratio:.3g}" if dcm_ratio else "")
        self._set("model", f"order {kf.order}" + (f", fit {kf.fit_percent:.1f} %" if kf.fit_percent is not None else "")
                  if kf.order is not None else "—", "model order; fit = 100·(1 − ‖y − ŷ‖/‖y − ȳ‖)")
        self._set("resonance", format_figure(kf.natural_frequency_hz, KILO, "kHz"),
                  "main mode: the lowest supported complex pole pair; "
                  + figure_tooltip(kf.natural_frequency_hz, KILO, "kHz"))
        self._set("damping", format_figure(kf.damping_ratio, decimals=3), figure_tooltip(kf.damping_ratio))
        per = "× nominal" if kf.response_unit == "m/s^2" else "V/(m/s²)" if kf.response_unit == "V" else ""
        self._set("sensitivity", format_figure(kf.sensitivity, unit=per, decimals=4),
                  "DC gain of the model; " + figure_tooltip(kf.sensitivity, unit=per))
        self._set("shock", format_figure(kf.shock_sensitivity, unit=per, decimals=4),
                  "ISO 16063-13 peak ratio; " + figure_tooltip(kf.shock_sensitivity, unit=per))
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
        self.warnings.setText("⚠ " + "; ".join(warnings) if warnings else "")
        self.warnings.setVisible(bool(warnings))
        self._share_width()

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


class ShotPlots(QWidget):
    """The last shot: results strip over a 2 × 3 grid of plots (module docstring)."""

    def __init__(self, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.view: ShotView | None = None
        self.title = QLabel("No shot yet — set up the shot and press ARM.")
        self.title.setStyleSheet("font-size: 10pt; color: #3c4043;")
        self.title.setWordWrap(True)
        self.strip = ResultsStrip()

        self.pm_plot = _plot("PM beat (Doppler channel)", "PM signal", "time from trigger", "V", "s")
        self.pm_curve = self.pm_plot.plot([], [], pen=PM_PEN)
        self.pm_curve.setDownsampling(auto=True, method="peak")
        self.pm_curve.setClipToView(True)
        self.pm_plot.setMouseEnabled(x=True, y=False)

        self.accel_plot = _plot("Reference and response", "acceleration (km/s²)", "time", None, "s")
        self.accel_plot.addLegend(offset=(-5, 5), labelTextSize="8pt")
        self.response_curve = self.accel_plot.plot([], [], pen=RESP_PEN, name="accelerometer response")
        self.reference_curve = self.accel_plot.plot([], [], pen=REF_PEN, name="reference (interferometer)")
        self.reference_curve.setZValue(5)
        self.accel_note = pg.TextItem("", color="#b3261e", anchor=(0, 0))
        self.accel_plot.addItem(self.accel_note, ignoreBounds=True)

        self.loss_plot = _plot("Loss by model order", "loss (response units²)", "model order")
        self.loss_plot.setLogMode(x=False, y=True)
        self.loss_plot.addLegend(offset=(-5, 5), labelTextSize="8pt")
        self.loss_curve = self.loss_plot.plot([], [], pen=pg.mkPen("#1f6fd1", width=2), symbol="o", symbolSize=6,
                                              symbolBrush="#1f6fd1", name="bias-corrected (order choice)")
        self.arx_curve = self.loss_plot.plot([], [], pen=pg.mkPen("#9aa0a6", width=1.5), symbol="t", symbolSize=6,
                                             symbolBrush="#9aa0a6", name="plain least squares")
        self.order_line = pg.InfiniteLine(angle=90, pen=pg.mkPen("#d0312d", width=2),
                                          label="chosen order",
                                          labelOpts={"position": 0.12, "color": "#d0312d", "fill": (255, 255, 255, 200)})
        self.order_line.setVisible(False)
        self.loss_plot.addItem(self.order_line)

        self.mag_plot = MagnitudePlot("Magnitude |H(f)/H(0)|", "identified model", "with DCM")
        self.fbsd_lines = self.mag_plot.fbsd_lines

        self.pz_plot = _plot("Pole-zero map (z-plane)", "imaginary", "real")
        self.pz_plot.setAspectLocked(True)
        self.pz_plot.addLegend(offset=(5, 5), labelTextSize="8pt")
        theta = np.linspace(0, 2 * np.pi, 721)
        self.pz_plot.plot(np.cos(theta), np.sin(theta), pen=pg.mkPen("#9aa0a6", width=1))
        self.pole_scatter = pg.ScatterPlotItem(symbol="x", size=11, pen=pg.mkPen("#1f6fd1", width=2),
                                               brush=pg.mkBrush("#1f6fd1"), name="model poles")
        self.zero_scatter = pg.ScatterPlotItem(symbol="o", size=9, pen=pg.mkPen("#1f6fd1", width=1.5),
                                               brush=pg.mkBrush(None), name="model zeros")
        self.dcm_scatter = pg.ScatterPlotItem(symbol="+", size=11, pen=pg.mkPen("#d0312d", width=2),
                                              brush=pg.mkBrush("#d0312d"), name="DCM poles")
        self.truth_scatter = pg.ScatterPlotItem(symbol="d", size=10, pen=pg.mkPen("#2e9d43", width=1.5),
                                                brush=pg.mkBrush(None), name="true poles (sim.)")
        for item in (self.pole_scatter, self.zero_scatter, self.dcm_scatter, self.truth_scatter):
            self.pz_plot.addItem(item)

        self.trend = LiveTrend()

        grid = QGridLayout()
        grid.setSpacing(6)
        grid.addWidget(self.pm_plot, 0, 0)
        grid.addWidget(self.accel_plot, 0, 1)
        grid.addWidget(self.trend, 0, 2)
        grid.addWidget(self.loss_plot, 1, 0)
        grid.addWidget(self.mag_plot, 1, 1)
        grid.addWidget(self.pz_plot, 1, 2)
        for column in range(3):
            grid.setColumnStretch(column, 1)
        layout = QVBoxLayout(self)
        layout.setContentsMargins(4, 4, 4, 4)
        layout.setSpacing(4)
        layout.addWidget(self.title)
        layout.addWidget(self.strip)
        layout.addLayout(grid, 1)

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
        if title:
            self.title.setText(title)

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
            set_y_with_legend_room(self.accel_plot, reference / KILO, response / KILO)
        self._show_losses(view)
        self._show_magnitude(view)
        self._show_poles(view)
        design = view.dcm.design if view.dcm is not None else None
        self.strip.show_figures(view.figures, view.compensation, (design or {}).get("ratio"))

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


def show_fbsd(lines: dict[str, pg.InfiniteLine], fbsd_hz: dict[str, float], prefix: str = "") -> None:
    """Put the FBSD edge lines (log-frequency axis in kHz) at their frequencies with labels."""
    for key, line in lines.items():
        value = fbsd_hz.get(key)
        if value is None or not math.isfinite(value) or value <= 0:
            line.setVisible(False)
            continue
        line.setVisible(True)  # (an InfiniteLine's label only updates while visible)
        line.setValue(math.log10(value / KILO))
        line.label.setFormat(f"{prefix}±{key} %: {value / KILO:.1f} kHz")


def _short(text: str, limit: int = 90) -> str:
    return text if len(text) <= limit else text[: limit - 1] + "…"


class LiveTrend(pg.PlotWidget):
    """Reservoir pressure (bar, left axis) and fixture vacuum (mbar, right axis, log) over the
    last `span_s` seconds, fed by reading events."""

    def __init__(self, span_s: float = 60.0, parent: QWidget | None = None) -> None:
        super().__init__(parent, axisItems={"right": PlainLogAxis("right")})  # 10, 100, 1000 mbar, not 10¹, 10², 10³
        self.span_s = span_s
        self._t0 = time.monotonic()
        self.samples: deque[tuple[float, float, float]] = deque(maxlen=4000)
        item = self.getPlotItem()
        item.setTitle("<span style='font-size:10pt; font-weight:600'>Live gauges</span>")
        item.setLabel("left", "reservoir pressure (bar)", color="#1f6fd1")
        item.setLabel("bottom", "time", units="s")
        item.setLabel("right", "fixture vacuum (mbar)", color="#c98a00")
        item.showGrid(x=True, y=True, alpha=0.25)
        item.getAxis("left").setWidth(56)
        item.getAxis("left").enableAutoSIPrefix(False)
        item.getAxis("right").enableAutoSIPrefix(False)
        self.pressure_curve = item.plot([], [], pen=pg.mkPen("#1f6fd1", width=2))
        self.vacuum_box = pg.ViewBox()
        item.scene().addItem(self.vacuum_box)
        item.getAxis("right").linkToView(self.vacuum_box)
        item.getAxis("right").setLogMode(True)
        self.vacuum_box.setXLink(item)
        self.vacuum_box.setLogMode = None  # a bare ViewBox: the curve below holds log10 values
        self.vacuum_curve = pg.PlotDataItem([], [], pen=pg.mkPen("#c98a00", width=2))
        self.vacuum_box.addItem(self.vacuum_curve)
        item.vb.sigResized.connect(self._sync_views)
        self.setMinimumSize(200, 150)

    def _sync_views(self) -> None:
        self.vacuum_box.setGeometry(self.getPlotItem().vb.sceneBoundingRect())
        self.vacuum_box.linkedViewChanged(self.getPlotItem().vb, self.vacuum_box.XAxis)

    def add_reading(self, pressure_bar: float | None, vacuum_mbar: float | None) -> None:
        """Append one reading (None values are skipped)."""
        if pressure_bar is None or vacuum_mbar is None:
            return
        now = time.monotonic() - self._t0
        self.samples.append((now, float(pressure_bar), float(vacuum_mbar)))
        while self.samples[0][0] < now - self.span_s:  # oldest first: forget what left the window
            self.samples.popleft()
        data = np.array(self.samples)
        t = data[:, 0] - now
        self.pressure_curve.setData(t, data[:, 1])
        self.vacuum_curve.setData(t, np.log10(np.maximum(data[:, 2], 1e-3)))
        self.getPlotItem().setXRange(-self.span_s, 0, padding=0.01)
        top = max(1.0, float(np.max(data[:, 1])) * 1.15)
        self.getPlotItem().setYRange(0.0, top, padding=0)
        self.vacuum_box.setYRange(0.0, math.log10(2000.0), padding=0)
