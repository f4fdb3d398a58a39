"""DCM design: the response-time ratio r, the damping ζₑ of the new poles and extra poles as
controls; the compensated magnitude (with FBSD), the step responses and the shot's
compensated record follow every change. Export of the DCM (JSON, the `hopkinson dcm -o`
format that `hopkinson compensate --dcm` reads) and of the shot's calibration report.

The design and the figures come from analysis.dcm_design (`design_compensation` for the shot's
support: the poles it may cancel, its band limit; `design_report`: the same numbers `hopkinson
dcm` prints); this tab only draws them. With the shot's own ratio, damping and band limit it
designs the shot's own DCM. The shot compensated is drawn with the DCM's latency removed
(aligned with the reference). A change is applied after a short pause (DEBOUNCE_MS) so that
dragging the slider stays smooth; one redesign takes a few milliseconds.
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pyqtgraph as pg
from PySide6.QtCore import Qt, QTimer
from PySide6.QtWidgets import (
    QFileDialog,
    QFormLayout,
    QGridLayout,
    QHBoxLayout,
    QLabel,
    QLineEdit,
    QPushButton,
    QSlider,
    QVBoxLayout,
    QWidget,
)

from hopkinson.analysis.dcm import DCM
from hopkinson.analysis.dcm_design import (
    ShotSupport,
    design_compensation,
    design_report,
)
from hopkinson.analysis.dcm_figures import step_responses
from hopkinson.analysis.dcm_stream import apply
from hopkinson.analysis.errors import AnalysisError
from hopkinson.analysis.model import DiscreteModel
from hopkinson.analysis.options import DCM_OPTIONS, AnalysisOptions, OptionError, declared
from hopkinson.analysis.pole_checks import format_complex, parse_poles
from hopkinson.analysis.records import Record
from hopkinson.analysis.response import response_times_samples
from hopkinson.fileio import atomic_write, check_output_path
from hopkinson.ui.inputs import UnitSpinBox
from hopkinson.ui.plots import (
    BAND_LIMIT_TIP,
    COMP_PEN,
    KILO,
    LEVEL_KEYS,
    MODEL_PEN,
    REF_PEN,
    RESP_PEN,
    MagnitudePlot,
    _plot,
    format_khz,
    frequency_grid_hz,
    legend_below,
    magnitudes,
    pulse_window_s,
    set_y_to_curves,
)
from hopkinson.ui.widgets import TEXT_COLOURS, plain_message, section_title

DEBOUNCE_MS = 60
RATIO_RANGE = (0.1, 200.0)
SLIDER_STEPS = 1000
MAX_STEP_SAMPLES = 20_000


@dataclass
class DcmDesign:
    """One design and its figures (what the tab shows)."""

    dcm: DCM
    report: dict[str, Any]
    frequency_hz: np.ndarray
    magnitude: np.ndarray
    compensated_magnitude: np.ndarray
    step_time_s: np.ndarray
    step_model: np.ndarray
    step_compensated: np.ndarray
    compensated_record: np.ndarray | None


def compute_design(model: DiscreteModel, ratio: float, damping: float, extra_poles: np.ndarray,
                   record: Record | None = None, support: ShotSupport | None = None,
                   band_limit_hz: float | None = None) -> DcmDesign:
    """Design the DCM for the shot's support (the model alone when None: every stable mode
    counts as supported) and sample what the plots show (AnalysisError for an impossible design).
    band_limit_hz: the band limit (None: chosen from the support; 0: none)."""
    try:  # the model's own rate bounds the band limit (the design checks it)
        options = AnalysisOptions(sample_rate_hz=None, dcm_ratio=ratio, dcm_damping=damping,
                                  dcm_band_limit_hz=band_limit_hz,
                                  extra_poles=tuple(complex(p) for p in np.asarray(extra_poles, dtype=complex).ravel()))
        options.check(DCM_OPTIONS)
    except OptionError as exc:
        raise AnalysisError(f"DCM: {exc.option} must be {exc.need}") from None
    design = design_compensation(support or ShotSupport(model), options)
    dcm = design.dcm
    report = design_report(design.poles.cancelled, dcm, model, "panel", design)
    f = frequency_grid_hz(model.sample_interval_s)
    mag, comp = magnitudes(model, dcm, f)
    slowest = float(np.max(response_times_samples(np.concatenate([model.poles, dcm.poles]))))
    n = int(min(MAX_STEP_SAMPLES, max(64, math.ceil(3 * slowest) + dcm.order + model.b.size)))
    alone, both = step_responses(model, dcm, n)
    compensated = None
    if record is not None and record.n_samples > 0 and abs(record.sample_interval_s - model.sample_interval_s) <= \
            1e-9 * model.sample_interval_s:
        compensated = apply(dcm, np.asarray(record.response, dtype=float), initial="steady", align=True)
    return DcmDesign(dcm, report, f, mag, comp, np.arange(n) * model.sample_interval_s, alone, both, compensated)


class DcmTab(QWidget):
    """The DCM design tab (module docstring). `set_model` gives it a shot's model."""

    def __init__(self, parent: QWidget | None = None,
                 export_report: Callable[[Path], None] | None = None) -> None:
        super().__init__(parent)
        self.model: DiscreteModel | None = None
        self.support: ShotSupport | None = None
        self.band_limit_hz: float | None = None
        self.record: Record | None = None
        self.source = ""
        self.shot_path: Path | None = None
        self.design: DcmDesign | None = None
        self.error: str | None = None
        self._record_kilo: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None  # t, reference, response (10³)
        self._record_window: tuple[float, float] | None = None
        self._initial: tuple[float, float, str] = (1.0, declared("dcm_damping"), "")
        self._export_report = export_report
        self._syncing = False

        self.ratio = UnitSpinBox("Ratio r", "", RATIO_RANGE, 1.0, decimals=3, step=0.5,
                                 tip="r: how many times faster than the slowest model pole the compensated system "
                                     "decays (paper Eq. 40)")
        self.ratio_slider = QSlider(Qt.Orientation.Horizontal)
        self.ratio_slider.setRange(0, SLIDER_STEPS)
        self.ratio_slider.setFocusPolicy(Qt.FocusPolicy.StrongFocus)
        self.damping = UnitSpinBox("Damping ζₑ", "", (0.01, 1.0), declared("dcm_damping"), decimals=3, step=0.05,
                                   tip="damping of the DCM's new poles")
        self.extra = QLineEdit()
        self.extra.setPlaceholderText("e.g. 0.6+0.1j, 0.6-0.1j (both of a pair)")
        self.reset_button = QPushButton("Reset to the shot's DCM")
        self.export_dcm_button = QPushButton("Export DCM (JSON)…")
        self.export_report_button = QPushButton("Export report…")
        self.export_report_button.setToolTip("the shot's calibration report (PDF or HTML) as analysed, "
                                             "like `hopkinson report`; export the tuned DCM with Export DCM")
        self.message = QLabel("")
        self.message.setWordWrap(True)
        self.message_level = "idle"
        self.verdict = QLabel("")  # the analysis' verdict on the shot's own DCM (the Shot tab says it too)
        self.verdict.setWordWrap(True)
        self.verdict.setStyleSheet("color: #b3261e; font-weight: 700;")
        self.verdict.setVisible(False)

        self.model_fbsd = {k: QLabel("—") for k in LEVEL_KEYS}
        self.compensated_fbsd = {k: QLabel("—") for k in LEVEL_KEYS}
        self.widening = {k: QLabel("—") for k in LEVEL_KEYS}
        self.rise_label = QLabel("—")
        self.noise_label = QLabel("—")
        self.noise_label.setWordWrap(True)
        self.noise_label.setToolTip("noise gain: RMS amplification of white noise at the analysis rate; band limit: "
                                    f"{BAND_LIMIT_TIP}; latency: removed when compensating "
                                    "(`hopkinson compensate`, the plot on the right)")
        self.poles_label = QLabel("—")
        self.poles_label.setWordWrap(True)
        self.poles_label.setTextInteractionFlags(Qt.TextInteractionFlag.TextSelectableByMouse)
        for label in self.compensated_fbsd.values():
            label.setStyleSheet("font-size: 11pt; font-weight: 700; color: #b3261e;")
        for label in (*self.model_fbsd.values(), *self.widening.values()):
            label.setStyleSheet("font-size: 10pt; font-weight: 600;")
        self.rise_label.setStyleSheet("font-size: 10pt;")
        self.rise_label.setWordWrap(True)

        controls = QVBoxLayout()
        controls.setSpacing(4)
        self.source_label = QLabel("No model yet: fire or open a shot.")
        self.source_label.setWordWrap(True)
        self.source_label.setStyleSheet("color: #3c4043;")
        controls.addWidget(section_title("Design"))
        controls.addWidget(self.source_label)
        controls.addWidget(self.verdict)
        form = QFormLayout()
        form.addRow("Ratio r", self.ratio)
        form.addRow("", self.ratio_slider)
        form.addRow("Damping ζₑ", self.damping)
        form.addRow("Extra poles", self.extra)
        controls.addLayout(form)
        controls.addWidget(self.reset_button)
        controls.addWidget(self.message)
        controls.addSpacing(8)
        controls.addWidget(section_title("Figures"))
        figures = QGridLayout()
        figures.setHorizontalSpacing(10)
        figures.addWidget(QLabel(""), 0, 0)
        for col, text in enumerate(("model", "with DCM", "×"), start=1):
            head = QLabel(text)
            head.setStyleSheet("color: #5f6368;")
            figures.addWidget(head, 0, col)
        for row, key in enumerate(LEVEL_KEYS, start=1):
            figures.addWidget(QLabel(f"FBSD ±{key} %"), row, 0)
            figures.addWidget(self.model_fbsd[key], row, 1)
            figures.addWidget(self.compensated_fbsd[key], row, 2)
            figures.addWidget(self.widening[key], row, 3)
        controls.addLayout(figures)
        controls.addWidget(QLabel("Step response rise time (10–90 %):"))
        controls.addWidget(self.rise_label)
        controls.addWidget(QLabel("Noise gain, band limit, latency:"))
        controls.addWidget(self.noise_label)
        controls.addSpacing(4)
        controls.addWidget(QLabel("DCM poles:"))
        controls.addWidget(self.poles_label)
        controls.addStretch(1)
        controls.addWidget(self.export_dcm_button)
        controls.addWidget(self.export_report_button)
        left = QWidget()
        left.setLayout(controls)
        left.setFixedWidth(330)

        self.mag_plot = MagnitudePlot("Compensated magnitude", "model", "with DCM", edge_prefix="DCM ")
        self.fbsd_lines = self.mag_plot.fbsd_lines

        self.step_plot = _plot("Step response", "normalised output", "time", None, "s")
        legend_below(self.step_plot)
        self.step_model_curve = self.step_plot.plot([], [], pen=MODEL_PEN, name="model")
        self.step_comp_curve = self.step_plot.plot([], [], pen=COMP_PEN, name="with DCM")
        for level in (0.1, 0.9, 1.0):
            self.step_plot.addItem(pg.InfiniteLine(pos=level, angle=0, pen=pg.mkPen("#bdc1c6", width=1,
                                                                                    style=Qt.PenStyle.DotLine)))

        self.record_plot = _plot("The shot, compensated", "acceleration (km/s²)", "time", None, "s")
        legend_below(self.record_plot)
        self.resp_curve = self.record_plot.plot([], [], pen=RESP_PEN, name="response")
        self.ref_curve = self.record_plot.plot([], [], pen=REF_PEN, name="reference")
        self.comp_record_curve = self.record_plot.plot([], [], pen=COMP_PEN, name="compensated")
        self.ref_curve.setZValue(5)
        self.comp_record_curve.setZValue(6)

        plots = QGridLayout()
        plots.setSpacing(6)
        plots.addWidget(self.mag_plot, 0, 0, 1, 2)
        plots.addWidget(self.step_plot, 1, 0)
        plots.addWidget(self.record_plot, 1, 1)
        plots.setRowStretch(0, 1)
        plots.setRowStretch(1, 1)

        layout = QHBoxLayout(self)
        layout.setContentsMargins(6, 6, 6, 6)
        layout.addWidget(left)
        layout.addLayout(plots, 1)

        self.update_timer = QTimer(self)
        self.update_timer.setSingleShot(True)
        self.update_timer.setInterval(DEBOUNCE_MS)
        self.update_timer.timeout.connect(self.redesign)
        self.ratio.value_accepted.connect(self._ratio_changed)
        for spin in (self.ratio, self.damping):
            spin.refused.connect(lambda text: self.say("warning", f"Not taken: {text}."))
        self.ratio_slider.valueChanged.connect(self._slider_changed)
        self.damping.value_accepted.connect(self._schedule)
        self.extra.textChanged.connect(self._schedule)
        self.reset_button.clicked.connect(self.reset)
        self.export_dcm_button.clicked.connect(self.export_dcm_dialog)
        self.export_report_button.clicked.connect(self._export_report_clicked)
        self._set_slider(self.ratio.value())
        self._enable(False)

    # -- input ----------------------------------------------------------------------------------
    def set_model(self, model: DiscreteModel, ratio: float, damping: float, extra_poles: np.ndarray | list = (),
                  record: Record | None = None, source: str = "", shot_path: Path | None = None,
                  support: ShotSupport | None = None, band_limit_hz: float | None = None,
                  not_recommended_reason: str | None = None) -> None:
        """Design for `model`, starting from the shot's own DCM settings (its support and band
        limit when given: the shot's own DCM is then designed again). `not_recommended_reason`:
        the analysis found the shot's DCM not recommended, and why (shown above the design, where
        the DCM is exported)."""
        self.model, self.record, self.source, self.shot_path = model, record, source, shot_path
        self.verdict.setText("" if not_recommended_reason is None else
                             f"The shot's DCM is NOT RECOMMENDED: {not_recommended_reason}")
        self.verdict.setVisible(not_recommended_reason is not None)
        self.support, self.band_limit_hz = support, band_limit_hz
        extra_text = ", ".join(format_complex(p) for p in np.asarray(extra_poles, dtype=complex).ravel())
        self._initial = (float(ratio), float(damping), extra_text)
        self.source_label.setText(f"Model of {source or 'the shot'}: order {model.order}, "
                                  f"{1 / model.sample_interval_s / 1e3:g} kS/s")
        self._draw_record()
        self._enable(True)
        self.reset()

    def show_shot(self, view: Any) -> None:
        """Design for a shot shown (ui.plots.ShotView) from its own DCM settings; nothing without a model."""
        if view.model is None or view.dcm is None:
            return
        design = view.dcm.design or {}
        self.set_model(view.model, design.get("ratio", 1.0), design.get("damping", declared("dcm_damping")),
                       [complex(*p) for p in design.get("extra_poles", [])], view.record,
                       source=view.path.name if view.path else "", shot_path=view.path, support=view.support,
                       band_limit_hz=view.band_limit_hz,
                       not_recommended_reason=view.compensation.not_recommended_text if view.compensation else None)

    def _draw_record(self) -> None:
        """The shot's reference and response, drawn once per model (a redesign only changes the
        compensated curve)."""
        self.comp_record_curve.setData([], [])
        record = self.record
        if record is None:
            self._record_kilo = self._record_window = None
            self.ref_curve.setData([], [])
            self.resp_curve.setData([], [])
            return
        t, reference, response = record.time_s, np.asarray(record.reference), np.asarray(record.response)
        reference_kilo, response_kilo = reference / KILO, response / KILO
        self.ref_curve.setData(t, reference_kilo)
        self.resp_curve.setData(t, response_kilo)
        self._record_kilo = (t, reference_kilo, response_kilo)
        self._record_window = pulse_window_s(t, reference, response)

    def reset(self) -> None:
        """Back to the shot's own design."""
        ratio, damping, extra = self._initial
        self._syncing = True
        try:
            self.ratio.setValue(min(max(ratio, RATIO_RANGE[0]), RATIO_RANGE[1]))
            self._set_slider(self.ratio.value())
            self.damping.setValue(damping)
            self.extra.setText(extra)
        finally:
            self._syncing = False
        self.redesign()

    def _enable(self, on: bool) -> None:
        for w in (self.ratio, self.ratio_slider, self.damping, self.extra, self.reset_button,
                  self.export_dcm_button):
            w.setEnabled(on)
        self.export_report_button.setEnabled(on and self._export_report is not None)

    def _ratio_changed(self, value: float) -> None:
        if not self._syncing:
            self._syncing = True
            try:
                self._set_slider(value)
            finally:
                self._syncing = False
        self._schedule()

    def _slider_changed(self, position: int) -> None:
        if self._syncing:
            return
        lo, hi = (math.log10(v) for v in RATIO_RANGE)
        value = 10 ** (lo + (hi - lo) * position / SLIDER_STEPS)
        self._syncing = True
        try:
            self.ratio.setValue(round(value, 3))
        finally:
            self._syncing = False
        self._schedule()

    def _set_slider(self, value: float) -> None:
        lo, hi = (math.log10(v) for v in RATIO_RANGE)
        self.ratio_slider.setValue(round((math.log10(value) - lo) / (hi - lo) * SLIDER_STEPS))

    def _schedule(self, *_args: object) -> None:
        if not self._syncing:
            self.update_timer.start()

    # -- the design -----------------------------------------------------------------------------
    def redesign(self) -> None:
        """Design with the current controls and show it (an impossible design shows why)."""
        self.update_timer.stop()
        if self.model is None:
            return
        try:
            extra = parse_poles(self.extra.text(), "extra poles") if self.extra.text().strip() else np.array([])
            design = compute_design(self.model, self.ratio.value(), self.damping.value(), extra, self.record,
                                    self.support, self.band_limit_hz)
        except AnalysisError as exc:
            self.error = str(exc)
            self.say("error", f"Cannot design this DCM: {plain_message(str(exc))}")
            self.export_dcm_button.setEnabled(False)
            return
        self.error = None
        self.say("idle", "")
        self.export_dcm_button.setEnabled(True)
        self.design = design
        self._show(design)

    def _show(self, d: DcmDesign) -> None:
        rep = d.report
        for key in LEVEL_KEYS:
            before, after = rep["fbsd_hz"][key], rep["compensated_fbsd_hz"][key]
            self.model_fbsd[key].setText(format_khz(before))
            self.compensated_fbsd[key].setText(format_khz(after))
            self.widening[key].setText(f"×{after / before:.2f}" if before > 0 else "—")
            narrower = before > 0 and after < before
            self.widening[key].setStyleSheet("font-size: 10pt; font-weight: 600;" +
                                             (" color: #b3261e;" if narrower else " color: #1e6b2e;"))
            self.widening[key].setToolTip("the DCM NARROWS the band with this design" if narrower else "")
            if rep["compensated_fbsd_detail"][key].get("within_band_to_limit"):
                self.compensated_fbsd[key].setToolTip("never leaves the band below Nyquist")
        rt, ratio = rep["rise_time_samples"], rep["rise_time_ratio"]
        dt_us = self.model.sample_interval_s * 1e6 if self.model else 1.0
        verdict = "" if ratio is None else (f", ×{ratio:.2f} faster" if ratio > 1 else f", ×{1 / ratio:.2f} SLOWER")
        st = rep["settling_time_samples"]
        self.rise_label.setText(f"{rt['uncompensated'] * dt_us:.1f} µs → {rt['compensated'] * dt_us:.1f} µs{verdict}; "
                                f"±5 % settling {st['uncompensated'] * dt_us:.0f} µs → {st['compensated'] * dt_us:.0f} µs")
        self.poles_label.setText(", ".join(format_complex(p) for p in d.dcm.poles))
        figures = rep["dcm"]
        noise, limit = figures.get("noise_gain"), figures.get("noise_gain_limit")
        band, latency = figures.get("band_limit_hz"), figures.get("latency_s")
        self.noise_label.setText(
            ("—" if noise is None else f"×{noise:.3g}" + (f" (limit ×{limit:.3g})" if limit else ""))
            + "; " + ("no band limit" if band is None else f"low-pass {band / KILO:.1f} kHz")
            + ("" if latency is None else f"; {latency * 1e6:.1f} µs"))
        self.mag_plot.show_curves(d.frequency_hz, d.magnitude, d.compensated_magnitude, rep["compensated_fbsd_hz"])
        self.step_model_curve.setData(d.step_time_s, d.step_model)
        self.step_comp_curve.setData(d.step_time_s, d.step_compensated)
        self.step_plot.getPlotItem().enableAutoRange()
        self.record_plot.getPlotItem().enableAutoRange()
        if self._record_kilo is None:
            return
        t, reference, response = self._record_kilo
        curves = [reference, response]
        if d.compensated_record is not None:
            curves.append(d.compensated_record / KILO)
            self.comp_record_curve.setData(t, curves[-1])
        if self._record_window is not None:
            self.record_plot.setXRange(*self._record_window, padding=0)
            set_y_to_curves(self.record_plot, *curves)

    def say(self, level: str, text: str) -> None:
        """A message under the design, in its level's colour (every message sets its own:
        an error after a successful export is red, never the export's green)."""
        self.message_level = level
        self.message.setStyleSheet(f"color: {TEXT_COLOURS[level]};")
        self.message.setText(text)

    def compensated_fbsd_hz(self) -> dict[str, float] | None:
        """The current design's compensated FBSD (Hz per level), None without a design."""
        return None if self.design is None else dict(self.design.report["compensated_fbsd_hz"])

    # -- export -----------------------------------------------------------------------------------
    def export_dcm(self, path: Path) -> Path:
        """Write the current design as JSON (`hopkinson compensate --dcm` reads it)."""
        if self.design is None or self.model is None:
            raise AnalysisError("no DCM designed yet")
        check_output_path(path, [p for p in (self.shot_path, self.source) if p], what="DCM export")  # never over a shot file
        data = dict(self.design.report)
        data["source"] = str(self.shot_path or self.source or "panel")
        data["model"] = self.model.to_dict()
        return atomic_write(path, json.dumps(data, indent=2, allow_nan=False) + "\n")

    def export_dcm_dialog(self) -> None:
        name, _ = QFileDialog.getSaveFileName(self, "Export the DCM", str(_default_name(self.shot_path, "-dcm.json")),
                                              "DCM JSON (*.json)")
        if name:
            try:
                self.export_dcm(Path(name))
                self.say("ok", f"DCM written to {name}")
            except (OSError, AnalysisError, ValueError) as exc:
                self.say("error", f"DCM not written: {plain_message(str(exc))}")

    def _export_report_clicked(self) -> None:
        if self._export_report is None:
            return
        name, _ = QFileDialog.getSaveFileName(self, "Export the calibration report",
                                              str(_default_name(self.shot_path, "-report.pdf")),
                                              "PDF report (*.pdf);;HTML report (*.html)")
        if name:
            self._export_report(Path(name))


def _default_name(shot_path: Path | None, suffix: str) -> Path:
    if shot_path is None:
        return Path(f"shot{suffix}")
    return shot_path.with_name(shot_path.stem + suffix)
