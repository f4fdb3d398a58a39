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
from pyqtgraph.util.garbage_collector import GarbageCollector
from PySide6.QtCore import Qt
from PySide6.QtWidgets import QWidget

from hopkinson.analysis.dcm import DCM
from hopkinson.analysis.dcm_design import ShotSupport
from hopkinson.analysis.key_figures import Figure, KeyFigures
from hopkinson.analysis.model import DiscreteModel
from hopkinson.analysis.records import Record
from hopkinson.analysis.response import normalised_gain_function
from hopkinson.reports.data import CompensationCheck
from hopkinson.rig.shot_verdict import ShotJudgement, judge, settings_of, shot_judgement

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
    judgement: ShotJudgement | None = None  # the verdict and the sensitivity in the sensor's unit (rig.shot_verdict)


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


def view_from_results(results: dict[str, Any], record: Record | None = None,
                      settings: dict[str, Any] | None = None) -> ShotView:
    """A ShotView of an analysis results dict (and its record, when known; the shot settings it
    was fired with, for its verdict and units); no raw channels."""
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
        judgement=judge(results, settings or {}),
    )


def load_shot_view(path: str | Path) -> ShotView:
    """Read a shot file and prepare its plots (raw PM beat always; the rest when analysed)."""
    from hopkinson.rig.shotfile import read_shot

    shot = read_shot(path)
    if shot.results and shot.analysis_error is None:
        view = view_from_results(shot.results, shot.record, settings_of(shot))
    else:
        view = ShotView(analysis_error=shot.analysis_error or "the shot has not been analysed",
                        judgement=shot_judgement(shot))
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


def set_y_to_curves(plot: pg.PlotWidget, *curves: np.ndarray) -> None:
    """Y range of the curves with a little room above and below (the legends sit under the plots)."""
    values = np.concatenate([np.asarray(c, dtype=float).ravel() for c in curves])
    values = values[np.isfinite(values)]
    if values.size == 0:
        return
    lo, hi = float(values.min()), float(values.max())
    span = hi - lo if hi > lo else 1.0
    plot.setYRange(lo - 0.05 * span, hi + 0.08 * span, padding=0)


def _true_poles(truth: dict[str, Any], sample_interval_s: float) -> np.ndarray | None:
    """The simulated accelerometer's discrete poles at the analysis interval (simulation only)."""
    try:
        from hopkinson.drivers.sim.shot_truth import accelerometer_truth

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


def legend_below(widget: pg.PlotWidget, columns: int = 2) -> pg.LegendItem:
    """A legend in its own row under the plot's x axis, never over the data: the curves and
    scatters added afterwards with a name join it (pyqtgraph's PlotItem.legend). Its width is
    part of the plot's least width: two columns of short names keep a plot narrow."""
    item = widget.getPlotItem()
    legend = pg.LegendItem(colCount=columns, labelTextSize="8pt", verSpacing=-10, horSpacing=2,
                           pen=pg.mkPen(None), brush=pg.mkBrush(None))
    legend.layout.setContentsMargins(0, 0, 0, 0)
    item.layout.addItem(legend, 4, 1)
    item.legend = legend
    return legend


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

    def __init__(self, title: str, model_name: str, compensated_name: str, edge_prefix: str = "",
                 legend_columns: int = 2) -> None:
        super().__init__(axisItems={"bottom": PlainLogAxis("bottom")})
        configure_plot(self, title, "normalised magnitude", "frequency (kHz)")
        self.setLogMode(x=True, y=False)
        legend_below(self, legend_columns)
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
        # bottom left, under the magnitude's flat start (near 1): it covers neither the resonance's rise
        # nor the FBSD edges' labels at the top
        self.peak_note = pg.TextItem("", color="#3c4043", anchor=(0, 1), fill=(255, 255, 255, 220))
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
        legend.addItem(self.band_sample, f"{100 * band.get('coverage_probability', 0.95):.0f} % band")

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
            self.peak_note.setText(f"peak ×{magnitude[i]:.1f} at {f_khz[i]:.1f} kHz\n(above the scale)")
            self.peak_note.setPos(lo, 0.02 * self.Y_MAX)
        else:
            self.peak_note.setText("")


# What the DCM's band limit is, as its tooltips say (the strip here, the DCM tab).
BAND_LIMIT_TIP = ("the cut-off (−3 dB) of its linear-phase low-pass (4th-order Butterworth magnitude); its ±5 % edge "
                  "is the top of what the shot vouches for")


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
        item.setLabel("left", "reservoir (bar)", color="#1f6fd1")
        item.setLabel("bottom", "time", units="s")
        item.setLabel("right", "vacuum (mbar)", color="#c98a00")
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
