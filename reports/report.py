"""Calibration reports: campaign statistics, figures (matplotlib, Agg) and PDF/HTML writers.

A report is a `CalibrationReport`: who and what (identity), and one `ShotEntry` per shot with
its `ShotAnalysis` (analysis/shot_analysis.py). `rig.report_data` fills it from shot files or
a campaign run folder; this module only draws and writes, and computes across shots:

- spread: mean, sample standard deviation (n − 1) and coefficient of variation of the main
  mode's f_n and ζ, the FBSD (±5 %, ±10 %), the shock sensitivity and the fit;
- cross-validation (the paper's "multi-group data" check): entry [i, j] is the fit % of
  model i simulated on shot j's reference against shot j's measured response,
  100·(1 − ‖y − ŷ‖/‖y − ȳ‖), the measure `analysis.identify` reports for its own shot (the
  diagonal equals each shot's own fit). Shot j's channels are prepared as the identification
  prepared them (its baselines and input delay, stored in its results).

Pages per shot: excitation and identification (pulse, spectrum, loss by order with the
chosen order, AIC/BIC, measured vs model response); the model (magnitude with the ±5 %/±10 %
bands and the FBSD marked, phase); poles (z-plane map and the Table-1 pole analysis);
the DCM (compensated magnitude and FBSD, step responses, design). A campaign report adds a
summary (per-shot figures and spread), the cross-validation matrix and all shots' responses.

Figures are `matplotlib.figure.Figure` objects drawn on the Agg canvas (no pyplot state, so
reports can be made from any thread); PDF through `PdfPages`, HTML with PNG images embedded
as base64 and every table as text.
"""

from __future__ import annotations

import base64
import html
import io
import math
import os
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from hopkinson.analysis.dcm import step_responses as dcm_step_responses
from hopkinson.analysis.errors import AnalysisError
from hopkinson.analysis.excitation import amplitude_spectrum, pulse_width, pulse_window
from hopkinson.analysis.identify import fit_percent, remove_input_delay
from hopkinson.analysis.model import DiscreteModel
from hopkinson.analysis.resample import resample_to_rate
from hopkinson.analysis.response import (
    frequency_response,
    model_output,
    natural_frequency_damping,
    nyquist_hz,
    response_times_samples,
)
from hopkinson.analysis.shot_analysis import ShotAnalysis
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.backends.backend_pdf import PdfPages
from matplotlib.figure import Figure

G_M_S2 = 9.80665  # standard gravity: accelerations are also shown in g
A4_PORTRAIT_IN = (8.27, 11.69)
PNG_DPI = 90
BAND_LEVELS = (("5", 0.05, "tab:green"), ("10", 0.10, "tab:orange"))
FORMATS = ("pdf", "html")


# =============================================================================================
# What a report holds
# =============================================================================================


@dataclass
class ShotEntry:
    """One shot of a report: who/what/when, its analysis (None when it failed or is missing)."""

    label: str  # shot id, or the file name
    identity: dict[str, str]  # label -> text, in display order
    analysis: ShotAnalysis | None
    error: str | None = None  # why there is no analysis
    state: str = ""  # journal or shot-file state
    truth_modes: list[dict[str, Any]] | None = None  # simulation: the true modes (f_n, ζ)
    nominal_sensitivity_v_per_m_s2: float | None = None
    pressure_bar: float | None = None


@dataclass
class CalibrationReport:
    """A whole report: one shot, or a campaign of shots."""

    title: str
    identity: dict[str, str]
    shots: list[ShotEntry]
    campaign: bool = False
    notes: list[str] = field(default_factory=list)


# =============================================================================================
# Figures of merit and campaign statistics
# =============================================================================================


def identification_dict(analysis: ShotAnalysis) -> dict[str, Any]:
    """The identification as its JSON dict (it is an object after an analysis, a dict when read back)."""
    ident = analysis.identification
    return ident if isinstance(ident, dict) else ident.to_dict()


def excitation_dict(analysis: ShotAnalysis) -> dict[str, Any]:
    exc = analysis.excitation
    return exc if isinstance(exc, dict) else exc.to_dict()


def main_mode(analysis: ShotAnalysis) -> dict[str, Any] | None:
    """The sensor's main resonance: the lowest complex pole pair (else the lowest mode)."""
    modes = identification_dict(analysis).get("modes") or []
    pairs = [m for m in modes if m.get("kind", "pair") == "pair" and m.get("natural_frequency_hz")]
    if pairs:
        return min(pairs, key=lambda m: m["natural_frequency_hz"])
    return modes[0] if modes else None


QUANTITIES: tuple[tuple[str, str, str, float], ...] = (
    # key, label, unit, display scale (value / scale)
    ("natural_frequency_hz", "f_n", "kHz", 1e3),
    ("damping_ratio", "ζ", "", 1.0),
    ("fbsd_5_hz", "FBSD ±5 %", "kHz", 1e3),
    ("fbsd_10_hz", "FBSD ±10 %", "kHz", 1e3),
    ("compensated_fbsd_5_hz", "FBSD ±5 % with DCM", "kHz", 1e3),
    ("shock_sensitivity", "shock sensitivity S_sh", "× nominal", 1.0),
    ("fit_percent", "fit", "%", 1.0),
)


def figures_of_merit(entry: ShotEntry) -> dict[str, Any]:
    """A shot's key numbers (None where unknown), for tables and the spread."""
    out: dict[str, Any] = {k: None for k, *_ in QUANTITIES}
    out.update(order=None, peak_acceleration_m_s2=None, pulse_width_s=None, sensitivity_v_per_m_s2=None)
    a = entry.analysis
    if a is None:
        return out
    ident = identification_dict(a)
    mode = main_mode(a)
    if mode is not None:
        out["natural_frequency_hz"] = mode.get("natural_frequency_hz")
        out["damping_ratio"] = mode.get("damping_ratio")
    out["fbsd_5_hz"] = a.fbsd_hz.get("5")
    out["fbsd_10_hz"] = a.fbsd_hz.get("10")
    out["compensated_fbsd_5_hz"] = a.compensated_fbsd_hz.get("5")
    out["fit_percent"] = ident.get("fit_percent")
    out["order"] = a.model.order
    exc = excitation_dict(a)
    red = a.reduction or {}
    out["peak_acceleration_m_s2"] = red.get("peak_acceleration_m_s2", exc.get("peak_m_s2"))
    out["pulse_width_s"] = red.get("pulse_width_s", exc.get("pulse_width_s"))
    s = a.shock_sensitivity
    out["shock_sensitivity"] = s
    if s is not None and entry.nominal_sensitivity_v_per_m_s2:
        out["sensitivity_v_per_m_s2"] = s * entry.nominal_sensitivity_v_per_m_s2
    return out


def truth_comparison(entry: ShotEntry) -> dict[str, float] | None:
    """In simulation: the identified main resonance against the true mode nearest to it.

    pole_error_percent = |s − s_true| / |s_true| · 100 for the continuous pole
    s = −ζω_n + jω_n√(1 − ζ²) (upper half plane). None without an analysis or a truth.
    """
    if entry.analysis is None or not entry.truth_modes:
        return None
    mode = main_mode(entry.analysis)
    if mode is None or not mode.get("natural_frequency_hz") or mode.get("damping_ratio") is None:
        return None
    fn, zeta = float(mode["natural_frequency_hz"]), float(mode["damping_ratio"])
    truth = min(entry.truth_modes, key=lambda m: abs(float(m["natural_frequency_hz"]) - fn))
    fn_t, zeta_t = float(truth["natural_frequency_hz"]), float(truth["damping_ratio"])

    def pole(f: float, z: float) -> complex:
        w = 2 * math.pi * f
        return complex(-z * w, w * math.sqrt(max(0.0, 1 - z * z)))

    s_t = pole(fn_t, zeta_t)
    return {
        "natural_frequency_hz": fn, "damping_ratio": zeta,
        "truth_natural_frequency_hz": fn_t, "truth_damping_ratio": zeta_t,
        "natural_frequency_error_percent": 100.0 * (fn - fn_t) / fn_t,
        "damping_error_percent": 100.0 * (zeta - zeta_t) / zeta_t if zeta_t else float("nan"),
        "pole_error_percent": 100.0 * abs(pole(fn, zeta) - s_t) / abs(s_t),
    }


def spread(values: Iterable[float | None]) -> dict[str, float | int | None]:
    """Mean, sample standard deviation (n − 1), coefficient of variation (%) and n of the known values."""
    x = np.array([v for v in values if v is not None and math.isfinite(v)], dtype=float)
    n = int(x.size)
    if n == 0:
        return {"n": 0, "mean": None, "std": None, "cv_percent": None, "min": None, "max": None}
    mean = float(np.mean(x))
    std = float(np.std(x, ddof=1)) if n > 1 else None
    cv = 100.0 * std / abs(mean) if std is not None and mean != 0 else None
    return {"n": n, "mean": mean, "std": std, "cv_percent": cv, "min": float(np.min(x)), "max": float(np.max(x))}


def model_delay_samples(analysis: ShotAnalysis) -> int:
    """The integer input delay the identification removed before fitting the model."""
    ident = identification_dict(analysis)
    return int(round(float(ident.get("delay_samples", analysis.model.delay_samples) or 0.0)))


def prepared_channels(analysis: ShotAnalysis, delay_samples: int | None = None) -> tuple[np.ndarray, np.ndarray]:
    """(u, y): the shot's reference and response as its identification fitted them.

    The record at the model's rate, each channel's lead-in baseline and the response offset
    fitted with the model subtracted (the values the identification stored), an input delay removed: y(k) = response(k + d), d = the shot's
    own delay unless `delay_samples` is given. A model is its (b, a) together with the delay it
    was fitted with, so another shot's model is tried with that model's delay.
    """
    record = analysis.record
    if record is None:
        raise AnalysisError("the shot's record is not available (no /derived/record in the shot file)")
    dt = analysis.model.sample_interval_s
    if not math.isclose(record.sample_interval_s, dt, rel_tol=1e-6):
        record = resample_to_rate(record, 1.0 / dt)
    pre = identification_dict(analysis).get("preprocessing") or {}
    u = np.asarray(record.reference, dtype=float) - float(pre.get("reference_baseline", 0.0) or 0.0)
    # The response's lead-in baseline, and the constant offset the identification fitted with
    # the model (a property of this shot's data, not of the model).
    y = (np.asarray(record.response, dtype=float) - float(pre.get("response_baseline", 0.0) or 0.0)
         - float(pre.get("response_offset_fitted", 0.0) or 0.0))
    d = model_delay_samples(analysis) if delay_samples is None else int(delay_samples)
    return remove_input_delay(u, y, d)


def cross_validation(analyses: Sequence[ShotAnalysis]) -> np.ndarray:
    """Fit % of model i (with its delay) on shot j's record: matrix [i, j]; NaN where it cannot be computed."""
    n = len(analyses)
    out = np.full((n, n), np.nan)
    for i, a in enumerate(analyses):
        d = model_delay_samples(a)
        for j, b in enumerate(analyses):
            if not math.isclose(a.model.sample_interval_s, b.model.sample_interval_s, rel_tol=1e-6):
                continue
            try:
                u, y = prepared_channels(b, d)
                out[i, j] = fit_percent(y, model_output(a.model, u))
            except AnalysisError:
                pass
    return out


@dataclass
class CampaignStatistics:
    """Across the analysed shots: per-shot figures, their spread, the cross-validation matrix."""

    labels: list[str]  # the analysed shots, in order
    figures: list[dict[str, Any]]  # figures_of_merit per analysed shot
    spread: dict[str, dict[str, float | int | None]]  # quantity key -> spread()
    cross_validation_percent: np.ndarray  # [i, j]: model i on shot j

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready (strict JSON: a NaN or infinite figure becomes None)."""
        return _json_safe({"shots": self.labels, "figures": self.figures, "spread": self.spread,
                           "cross_validation_percent": self.cross_validation_percent.tolist(),
                           "cross_validation_note": "row i: model of shot i; column j: simulated on shot j's "
                                                    "reference; fit % = 100·(1 − ‖y − ŷ‖/‖y − ȳ‖)"})


def _json_safe(obj: Any) -> Any:
    if isinstance(obj, dict):
        return {k: _json_safe(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [_json_safe(v) for v in obj]
    if isinstance(obj, float | np.floating):
        return float(obj) if math.isfinite(obj) else None
    if isinstance(obj, np.integer):
        return int(obj)
    return obj


def campaign_statistics(entries: Sequence[ShotEntry]) -> CampaignStatistics:
    """Spread and cross-validation over the entries that have an analysis."""
    analysed = [e for e in entries if e.analysis is not None]
    figures = [figures_of_merit(e) for e in analysed]
    keys = [k for k, *_ in QUANTITIES] + ["sensitivity_v_per_m_s2", "peak_acceleration_m_s2", "pulse_width_s"]
    stats = {k: spread(f[k] for f in figures) for k in keys}
    matrix = cross_validation([e.analysis for e in analysed])  # type: ignore[misc]
    return CampaignStatistics([e.label for e in analysed], figures, stats, matrix)


# =============================================================================================
# Text helpers shared by the PDF tables and the HTML
# =============================================================================================


def _fmt(value: Any, scale: float = 1.0, digits: int = 4) -> str:
    if value is None:
        return "—"
    if isinstance(value, str):
        return value
    try:
        x = float(value) / scale
    except (TypeError, ValueError):
        return str(value)
    if not math.isfinite(x):
        return "—"
    if 10 ** digits <= abs(x) < 1e9:
        return f"{x:.0f}"  # 29980, not 2.998e+04
    return f"{x:.{digits}g}"


def _unit(unit: str) -> str:
    return f" ({unit})" if unit else ""


def results_rows(entry: ShotEntry) -> list[tuple[str, str]]:
    """The key results of one shot as (label, text) rows."""
    a = entry.analysis
    if a is None:
        return [("analysis", entry.error or "no analysis")]
    f = figures_of_merit(entry)
    ident = identification_dict(a)
    rows = [
        ("model order", f"{a.model.order} ({ident.get('order_selection', 'knee')})"),
        ("main mode f_n", f"{_fmt(f['natural_frequency_hz'], 1e3, 5)} kHz"),
        ("main mode damping ζ", _fmt(f["damping_ratio"], digits=4)),
        ("FBSD ±5 %", f"{_fmt(f['fbsd_5_hz'], 1e3)} kHz"),
        ("FBSD ±10 %", f"{_fmt(f['fbsd_10_hz'], 1e3)} kHz"),
        ("fit (measured vs model)", f"{_fmt(f['fit_percent'], digits=5)} %"),
        ("peak acceleration", f"{_fmt(f['peak_acceleration_m_s2'])} m/s² ({_fmt(f['peak_acceleration_m_s2'], G_M_S2)} g)"),
        ("pulse width (10 % of peak)", f"{_fmt(f['pulse_width_s'], 1e-6)} µs"),
    ]
    if f["shock_sensitivity"] is not None:
        text = f"{_fmt(f['shock_sensitivity'], digits=5)} × nominal"
        if f["sensitivity_v_per_m_s2"] is not None:
            text += (f" = {_fmt(f['sensitivity_v_per_m_s2'], digits=5)} V/(m/s²)"
                     f" = {_fmt(f['sensitivity_v_per_m_s2'] * G_M_S2 * 1e3, digits=5)} mV/g")
        rows.append(("shock sensitivity S_sh (ISO 16063-13)", text))
    design = a.dcm.design or {}
    rows += [
        ("DCM ratio r, damping ζ_e", f"{_fmt(design.get('ratio'))}, {_fmt(design.get('damping'))}"),
        ("FBSD ±5 % / ±10 % with DCM",
         f"{_fmt(a.compensated_fbsd_hz.get('5'), 1e3)} / {_fmt(a.compensated_fbsd_hz.get('10'), 1e3)} kHz"),
        ("rise-time ratio (10–90 %, without ÷ with DCM)", _fmt(a.rise_time_ratio)),
        ("settling-time ratio (±5 %, without ÷ with DCM)", _fmt(a.settling_time_ratio)),
    ]
    cmp = truth_comparison(entry)
    if cmp is not None:
        rows.append(("simulated truth f_n, ζ", f"{_fmt(cmp['truth_natural_frequency_hz'], 1e3, 5)} kHz, "
                                               f"{_fmt(cmp['truth_damping_ratio'])}: pole error "
                                               f"{cmp['pole_error_percent']:.3f} %"))
    for w in a.warnings:
        rows.append(("warning", w))
    return rows


def pole_rows(analysis: ShotAnalysis) -> tuple[list[str], list[list[str]]]:
    """Table 1 of the paper for the model: pole, |p|, f_n, ζ, T'_r (samples), ratio r_i."""
    header = ["pole p_i", "|p_i|", "f_n (kHz)", "ζ", "T'_r (samples)", "r_i"]
    rows = []
    dt = analysis.model.sample_interval_s
    for item in analysis.pole_analysis:
        p = complex(*item["pole"])
        if p != 0:
            fn, zeta = natural_frequency_damping(np.array([p]), dt)
            fn_text, z_text = _fmt(fn[0], 1e3, 5), _fmt(zeta[0])
        else:
            fn_text = z_text = "—"
        rows.append([f"{p.real:.5f} {'+' if p.imag >= 0 else '−'} {abs(p.imag):.5f}j", f"{abs(p):.5f}",
                     fn_text, z_text, _fmt(item["response_time_samples"], digits=5), _fmt(item.get("ratio"))])
    return header, rows


def dcm_rows(analysis: ShotAnalysis) -> list[tuple[str, str]]:
    d = analysis.dcm

    def zlist(values: np.ndarray) -> str:
        return ", ".join(f"{v.real:.4f}{v.imag:+.4f}j" for v in values) or "—"

    design = d.design or {}
    return [
        ("zeros (= model poles)", zlist(d.zeros)),
        ("poles (designed)", zlist(d.poles)),
        ("gain K (unit DC gain)", _fmt(d.gain, digits=6)),
        ("ratio r / damping ζ_e", f"{_fmt(design.get('ratio'))} / {_fmt(design.get('damping'))}"),
        ("sample interval", f"{_fmt(d.sample_interval_s, 1e-6)} µs"),
    ]


def spread_rows(stats: CampaignStatistics) -> tuple[list[str], list[list[str]]]:
    header = ["quantity", "n", "mean", "std", "CV (%)", "min", "max"]
    rows = []
    for key, label, unit, scale in QUANTITIES:
        s = stats.spread[key]
        rows.append([label + _unit(unit), str(s["n"]), _fmt(s["mean"], scale, 5), _fmt(s["std"], scale, 3),
                     _fmt(s["cv_percent"], digits=3), _fmt(s["min"], scale, 5), _fmt(s["max"], scale, 5)])
    return header, rows


def per_shot_rows(entries: Sequence[ShotEntry]) -> tuple[list[str], list[list[str]]]:
    header = ["shot", "state", "p (bar)", "peak (g)", "δ (µs)", "n", "f_n (kHz)", "ζ",
              "FBSD±5% (kHz)", "FBSD±10% (kHz)", "S_sh", "fit (%)"]
    rows = []
    for e in entries:
        f = figures_of_merit(e)
        rows.append([e.label, e.state or ("analysed" if e.analysis else "—"), _fmt(e.pressure_bar, digits=3),
                     _fmt(f["peak_acceleration_m_s2"], G_M_S2, 4), _fmt(f["pulse_width_s"], 1e-6, 3),
                     _fmt(f["order"]), _fmt(f["natural_frequency_hz"], 1e3, 5), _fmt(f["damping_ratio"], digits=3),
                     _fmt(f["fbsd_5_hz"], 1e3), _fmt(f["fbsd_10_hz"], 1e3), _fmt(f["shock_sensitivity"], digits=4),
                     _fmt(f["fit_percent"], digits=4)])
    return header, rows


# =============================================================================================
# Figures
# =============================================================================================


def _figure(title: str, subtitle: str = "") -> Figure:
    fig = Figure(figsize=A4_PORTRAIT_IN, layout="constrained")
    FigureCanvasAgg(fig)
    fig.suptitle(title + (f"\n{subtitle}" if subtitle else ""), fontsize=12, fontweight="bold")
    return fig


def _table(ax: Any, header: list[str] | None, rows: list[list[str]], fontsize: float = 8.0,
           col_widths: list[float] | None = None) -> None:
    ax.axis("off")
    if not rows:
        ax.text(0.0, 1.0, "—", va="top", transform=ax.transAxes)
        return
    t = ax.table(cellText=rows, colLabels=header, loc="upper center", cellLoc="left", colLoc="left",
                 colWidths=col_widths)
    t.auto_set_font_size(False)
    t.set_fontsize(fontsize)
    t.scale(1.0, 1.25)
    for (r, _c), cell in t.get_celld().items():
        cell.set_edgecolor("0.75")
        if header is not None and r == 0:
            cell.set_facecolor("0.9")
            cell.set_text_props(fontweight="bold")


def _wrap(text: str, width: int = 95) -> str:
    import textwrap

    return "\n".join(textwrap.fill(line, width) for line in text.splitlines())


class _TextTables:
    """Tables drawn as text from the top of a page down (rows grow with wrapped lines).

    matplotlib's `Axes.table` gives every row one line's height, so wrapped text overflows its
    cell; a title page of tables is laid out here instead, in figure coordinates.
    """

    def __init__(self, fig: Figure, top: float = 0.93, left: float = 0.05, right: float = 0.95) -> None:
        self.fig = fig
        self.y = top
        self.left = left
        self.right = right
        self.line = 1.0 / (fig.get_figheight() * 72.0)  # one point, in figure fraction

    def heading(self, text: str, size: float = 10.5) -> None:
        self.y -= 1.2 * size * self.line
        self.fig.text(self.left, self.y, text, fontsize=size, fontweight="bold", va="baseline")
        self.y -= 0.8 * size * self.line

    def table(self, header: list[str] | None, rows: Sequence[Sequence[str]], widths: Sequence[float],
              size: float = 8.0, wrap: Sequence[int] | None = None) -> None:
        """Columns of relative `widths`; `wrap`: characters per line of each column."""
        total = float(sum(widths))
        xs = [self.left + (self.right - self.left) * sum(widths[:i]) / total for i in range(len(widths))]
        step = 1.45 * size * self.line
        if header:
            self.fig.add_artist(_band(self.fig, self.left, self.right, self.y - step * 0.35, step, "0.88"))
            for x, text in zip(xs, header, strict=True):
                self.fig.text(x + 0.004, self.y - step * 0.7, text, fontsize=size, fontweight="bold")
            self.y -= step
        for n, row in enumerate(rows):
            cells = [_wrap(str(c), wrap[i]) if wrap else str(c) for i, c in enumerate(row)]
            lines = max(c.count("\n") + 1 for c in cells)
            height = step * lines
            if n % 2:
                self.fig.add_artist(_band(self.fig, self.left, self.right, self.y - step * 0.35 - height + step,
                                              height, "0.96"))
            for x, text in zip(xs, cells, strict=True):
                self.fig.text(x + 0.004, self.y - step * 0.7, text, fontsize=size, va="baseline",
                              linespacing=1.45)
            self.y -= height
        self.y -= 0.6 * step


def _band(fig: Figure, left: float, right: float, top: float, height: float, colour: str) -> Any:
    from matplotlib.patches import Rectangle

    return Rectangle((left, top - height), right - left, height, transform=fig.transFigure, color=colour,
                     zorder=-1, lw=0)


def title_page(report: CalibrationReport, stats: CampaignStatistics | None) -> Figure:
    """Identity of the accelerometer and the rig, the key results (one shot) or per-shot table."""
    fig = Figure(figsize=A4_PORTRAIT_IN)
    FigureCanvasAgg(fig)
    fig.text(0.5, 0.97, report.title, ha="center", va="top", fontsize=13, fontweight="bold")
    fig.text(0.5, 0.945, "Hopkinson-bar shock calibration: dynamic model, band of small distortion (FBSD) "
             "and dynamic compensation model (DCM)", ha="center", va="top", fontsize=9)
    page = _TextTables(fig, top=0.925)
    page.heading("Accelerometer, rig and campaign" if report.campaign else "Accelerometer and rig")
    page.table(None, list(report.identity.items()), [0.3, 0.7], wrap=[40, 90])
    if report.campaign and stats is not None:
        page.heading("Shots")
        header, rows = per_shot_rows(report.shots)
        page.table(header, rows, [1.2, 1.6, 0.8, 0.9, 0.8, 0.4, 1.0, 0.9, 1.4, 1.5, 0.8, 0.8], size=7.0)
        page.table(None, [["δ: pulse width at 10 % of peak; n: model order; S_sh: shock sensitivity "
                           "(× nominal, ISO 16063-13); fit: measured vs model response"]], [1.0], size=6.5)
        page.heading(f"Spread across {len(stats.labels)} analysed shots (standard deviation with n − 1)")
        header, rows = spread_rows(stats)
        page.table(header, rows, [2.2, 0.4, 1.0, 1.0, 0.8, 1.0, 1.0], size=7.5)
        if stats.labels:
            m = stats.cross_validation_percent
            finite = m[np.isfinite(m)]
            if finite.size:
                page.heading("Cross-validation (each shot's model on every other shot)")
                off = m[~np.eye(m.shape[0], dtype=bool)] if m.shape[0] > 1 else finite
                off = off[np.isfinite(off)]
                text = (f"fit % of model i on shot j: lowest {np.min(finite):.3f} %, diagonal mean "
                        f"{np.nanmean(np.diag(m)):.3f} %" + (f", off-diagonal mean {np.mean(off):.3f} %" if off.size
                                                             and m.shape[0] > 1 else "") + " (matrix on the next page)")
                page.table(None, [[text]], [1.0], size=8.0)
    else:
        page.heading("Results")
        page.table(None, results_rows(report.shots[0]), [0.38, 0.62], wrap=[50, 70])
    if report.notes:
        page.heading("Notes")
        page.table(None, [[n] for n in report.notes], [1.0], wrap=[130])
    return fig


def excitation_page(entry: ShotEntry) -> Figure:
    """Pulse (reference, response, model), its spectrum with the band covered, loss by order, AIC/BIC."""
    a = entry.analysis
    assert a is not None
    fig = _figure(f"{entry.label}: excitation and identification")
    grid = fig.add_gridspec(3, 2)
    ax_t = fig.add_subplot(grid[0, :])
    ax_f = fig.add_subplot(grid[1, :])
    ax_l = fig.add_subplot(grid[2, 0])
    ax_c = fig.add_subplot(grid[2, 1])
    exc = excitation_dict(a)
    ident = identification_dict(a)
    mode = main_mode(a)

    rec = a.record
    if rec is not None:
        u, y = prepared_channels(a)
        d = model_delay_samples(a)
        t_us = (np.arange(u.size) * rec.sample_interval_s + rec.start_time_s) * 1e6
        y_hat = model_output(a.model, u)
        ax_t.plot(t_us, u / G_M_S2, color="0.2", lw=1.2, label="reference (laser interferometer)")
        ax_t.plot(t_us, y / G_M_S2, color="tab:blue", lw=1.0,
                  label=f"accelerometer response (shifted by its delay, {d} samples)")
        ax_t.plot(t_us, y_hat / G_M_S2, color="tab:red", lw=1.0, ls="--",
                  label=f"model response (fit {_fmt(ident.get('fit_percent'), digits=4)} %)")
        width = float(exc.get("pulse_width_s") or 0.0)
        t_peak = float(exc.get("peak_time_s") or 0.0)
        if width > 0:
            lo = (t_peak - 3 * width) * 1e6
            hi = (t_peak + 8 * width) * 1e6
            ax_t.set_xlim(max(lo, t_us[0]), min(hi, t_us[-1]))
        ax_t.legend(fontsize=7, loc="upper right")
    else:
        ax_t.text(0.5, 0.5, "record not stored", ha="center", transform=ax_t.transAxes)
    ax_t.set_xlabel("time (µs)")
    ax_t.set_ylabel("acceleration (g)")
    ax_t.set_title(f"Shock pulse: peak {_fmt(exc.get('peak_m_s2'), G_M_S2)} g, width "
                   f"{_fmt(exc.get('pulse_width_s'), 1e-6)} µs at 10 % of peak", fontsize=9)
    ax_t.grid(alpha=0.3)

    if rec is not None:
        ref = np.asarray(rec.reference, dtype=float)
        pulse = pulse_width(ref, rec.sample_interval_s, rec.start_time_s)
        seg = ref[pulse_window(pulse, ref.size, rec.sample_interval_s, rec.start_time_s)]
        f_hz, mag = amplitude_spectrum(seg, rec.sample_interval_s)
        keep = f_hz <= min(nyquist_hz(a.model), 8.0 * max(float(exc.get("band_high_hz") or 0.0), 1.0))
        norm = mag / np.max(mag)
        ax_f.plot(f_hz[keep] / 1e3, 20 * np.log10(np.maximum(norm[keep], 1e-6)), color="0.2",
                  label="|F(f)| / max (reference pulse)")
        ax_f.axhline(-3.0, color="0.5", ls=":", lw=0.8)
        lo_hz, hi_hz = float(exc.get("band_low_hz") or 0.0), float(exc.get("band_high_hz") or 0.0)
        ax_f.axvspan(lo_hz / 1e3, hi_hz / 1e3, color="tab:green", alpha=0.15,
                     label=f"band covered (−3 dB): {_fmt(lo_hz, 1e3)}–{_fmt(hi_hz, 1e3)} kHz")
        rule = exc.get("paper_rule_max_natural_frequency_hz")
        if rule:
            ax_f.axvline(rule / 1e3, color="tab:purple", ls="--", lw=1,
                         label=f"paper's rule f_n ≤ 1.06/δ = {_fmt(rule, 1e3)} kHz")
        if mode is not None and mode.get("natural_frequency_hz"):
            fn = mode["natural_frequency_hz"]
            ax_f.axvline(fn / 1e3, color="tab:red", lw=1, label=f"identified f_n = {_fmt(fn, 1e3)} kHz")
        ax_f.set_ylim(-60, 3)
        ax_f.legend(fontsize=7, loc="upper right")
    ax_f.set_xlabel("frequency (kHz)")
    ax_f.set_ylabel("amplitude spectrum (dB)")
    ax_f.set_title("Excitation spectrum", fontsize=9)
    ax_f.grid(alpha=0.3)

    losses = ident.get("loss_by_order") or []
    arx = ident.get("arx_loss_by_order") or []
    orders = np.arange(1, len(losses) + 1)
    chosen = a.model.order

    def arr(values: list[Any]) -> np.ndarray:
        return np.array([np.nan if v is None else float(v) for v in values], dtype=float)

    if losses:
        ax_l.semilogy(orders, arr(losses), "o-", color="tab:blue", ms=4, label="bias-corrected (output error)")
    if arx:
        ax_l.semilogy(np.arange(1, len(arx) + 1), arr(arx), "s--", color="0.5", ms=3, label="plain least squares")
    ax_l.axvline(chosen, color="tab:red", lw=1.2, label=f"chosen order {chosen}")
    ax_l.set_xlabel("model order n")
    ax_l.set_ylabel("loss (response units²)")
    ax_l.set_title("Loss by order", fontsize=9)
    ax_l.legend(fontsize=6.5)
    ax_l.grid(alpha=0.3)

    aic, bic = ident.get("aic_by_order") or [], ident.get("bic_by_order") or []
    if aic:
        ax_c.plot(np.arange(1, len(aic) + 1), arr(aic), "o-", ms=3, color="tab:blue", label="AIC")
    if bic:
        ax_c.plot(np.arange(1, len(bic) + 1), arr(bic), "s-", ms=3, color="tab:orange", label="BIC")
    ax_c.axvline(chosen, color="tab:red", lw=1.2, label=f"chosen order {chosen}")
    ax_c.set_xlabel("model order n")
    ax_c.set_ylabel("criterion (dimensionless)")
    ax_c.set_title("AIC / BIC (on the bias-corrected loss)", fontsize=9)
    ax_c.legend(fontsize=6.5)
    ax_c.grid(alpha=0.3)
    return fig


def _frequency_grid(model: DiscreteModel, points: int = 1200) -> np.ndarray:
    nyq = nyquist_hz(model)
    return np.logspace(np.log10(nyq / 1e4), np.log10(nyq * 0.999), points)


def _normalised(h: np.ndarray, dc: float) -> np.ndarray:
    return np.abs(h) / abs(dc)


def _bands(ax: Any, fbsd: dict[str, float], label_prefix: str = "FBSD", linestyle: str = "--",
           shade: bool = True) -> None:
    for key, level, colour in BAND_LEVELS:
        if shade:
            ax.axhspan(1 - level, 1 + level, color=colour, alpha=0.08 if key == "10" else 0.12,
                       label=f"±{key} % band")
        f = fbsd.get(key)
        if f:
            ax.axvline(f / 1e3, color=colour, ls=linestyle, lw=1.3, label=f"{label_prefix} ±{key} % = {_fmt(f, 1e3)} kHz")


def model_page(entry: ShotEntry) -> Figure:
    """Magnitude (full range in dB; normalised around the bands with the FBSD) and phase."""
    a = entry.analysis
    assert a is not None
    model = a.model
    fig = _figure(f"{entry.label}: identified model, frequency response")
    ax_db, ax_band, ax_ph = fig.subplots(3, 1, height_ratios=[1.0, 1.2, 0.9])
    f = _frequency_grid(model)
    h = frequency_response(model, f)
    dc = model.dc_gain
    mag = _normalised(h, dc)
    ax_db.semilogx(f / 1e3, 20 * np.log10(mag), color="tab:blue", label=f"model (order {model.order})")
    for key, level, colour in BAND_LEVELS:
        ax_db.axhspan(20 * np.log10(1 - level), 20 * np.log10(1 + level), color=colour, alpha=0.2,
                      label=f"±{key} % band")
    mode = main_mode(a)
    if mode is not None and mode.get("natural_frequency_hz"):
        ax_db.axvline(mode["natural_frequency_hz"] / 1e3, color="tab:red", lw=0.8, ls=":",
                      label=f"f_n = {_fmt(mode['natural_frequency_hz'], 1e3)} kHz, ζ = {_fmt(mode.get('damping_ratio'))}")
    ax_db.set_xlabel("frequency (kHz)")
    ax_db.set_ylabel("|H(f)/H(0)| (dB)")
    ax_db.set_title("Normalised magnitude, DC to Nyquist", fontsize=9)
    ax_db.grid(alpha=0.3)
    ax_db.legend(fontsize=7)

    f10 = a.fbsd_hz.get("10") or nyquist_hz(model) / 10
    fl = np.linspace(0.0, min(nyquist_hz(model), 2.5 * f10), 800)
    ml = _normalised(frequency_response(model, fl), dc)
    ax_band.plot(fl / 1e3, ml, color="tab:blue", lw=1.5, label="model")
    _bands(ax_band, a.fbsd_hz)
    ax_band.set_ylim(0.8, 1.2)
    ax_band.set_xlim(0, fl[-1] / 1e3)
    ax_band.set_xlabel("frequency (kHz)")
    ax_band.set_ylabel("|H(f)/H(0)| (ratio)")
    ax_band.set_title("Band of small distortion: first frequency where the gain leaves 1 ± 5 % / 1 ± 10 %",
                      fontsize=9)
    ax_band.grid(alpha=0.3)
    ax_band.legend(fontsize=7, loc="lower left")

    phase = np.degrees(np.unwrap(np.angle(h)))
    ax_ph.semilogx(f / 1e3, phase, color="tab:purple")
    for key, _level, colour in BAND_LEVELS:
        fb = a.fbsd_hz.get(key)
        if fb:
            ax_ph.axvline(fb / 1e3, color=colour, ls="--", lw=1.0, label=f"FBSD ±{key} %")
    ax_ph.set_xlabel("frequency (kHz)")
    ax_ph.set_ylabel("phase (degrees)")
    ax_ph.set_title("Phase (input delay not included)", fontsize=9)
    ax_ph.grid(alpha=0.3)
    ax_ph.legend(fontsize=7)
    return fig


def _z_plane(ax: Any, a: ShotAnalysis, xlim: tuple[float, float], ylim: tuple[float, float],
             legend: bool) -> None:
    theta = np.linspace(0, 2 * np.pi, 720)
    ax.plot(np.cos(theta), np.sin(theta), color="0.6", lw=0.8, label="unit circle")
    poles, zeros, dp = a.model.poles, a.model.zeros, a.dcm.poles

    def inside(v: np.ndarray) -> np.ndarray:
        return v[(v.real >= xlim[0]) & (v.real <= xlim[1]) & (v.imag >= ylim[0]) & (v.imag <= ylim[1])]

    shown = inside(zeros) if zeros.size else zeros
    off = int(zeros.size - shown.size)
    ax.plot(poles.real, poles.imag, "x", color="tab:blue", ms=9, mew=2, label="model poles")
    if zeros.size:
        ax.plot(shown.real, shown.imag, "o", mfc="none", color="tab:blue", ms=8,
                label="model zeros" + (f" ({off} outside this view)" if off else ""))
    ax.plot(dp.real, dp.imag, "+", color="tab:red", ms=10, mew=2, label="DCM poles (designed)")
    ax.set_xlim(*xlim)
    ax.set_ylim(*ylim)
    ax.set_aspect("equal")
    ax.axhline(0, color="0.85", lw=0.6)
    ax.axvline(0, color="0.85", lw=0.6)
    ax.set_xlabel("Re z")
    ax.set_ylabel("Im z")
    ax.grid(alpha=0.3)
    if legend:
        ax.legend(fontsize=6.5, loc="upper left")


def poles_page(entry: ShotEntry) -> Figure:
    """z-plane map of the model's poles and zeros and the DCM's poles (whole and near z = 1);
    the Table-1 pole analysis."""
    a = entry.analysis
    assert a is not None
    fig = _figure(f"{entry.label}: poles and zeros")
    grid = fig.add_gridspec(2, 2, height_ratios=[1.4, 0.8])
    ax_z = fig.add_subplot(grid[0, 0])
    ax_zoom = fig.add_subplot(grid[0, 1])
    ax_tab = fig.add_subplot(grid[1, :])
    _z_plane(ax_z, a, (-1.3, 1.3), (-1.3, 1.3), legend=True)
    ax_z.set_title(f"z-plane (sample interval {_fmt(a.model.sample_interval_s, 1e-6)} µs)", fontsize=9)
    near = np.concatenate([a.model.poles, a.dcm.poles])
    near = near[np.abs(near) > 0.5]
    if near.size:
        half = max(float(np.max(np.abs(near - 1.0))) * 1.15, 0.05)
        _z_plane(ax_zoom, a, (1.0 - half, 1.0 + half * 0.3), (-half, half), legend=False)
    ax_zoom.set_title("near z = 1 (the slow poles)", fontsize=9)
    header, rows = pole_rows(a)
    _table(ax_tab, header, rows, fontsize=8)
    ax_tab.set_title("Pole analysis (the paper's Table 1): response time T'_r = −3/ln|p| samples, "
                     "ratio r_i = T'_r(slowest)/T'_r", loc="left", fontsize=9)
    return fig


def step_responses(analysis: ShotAnalysis) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(time_s, model step response, model followed by the DCM), both normalised to 1 at DC."""
    model, dcm = analysis.model, analysis.dcm
    slowest = float(np.max(response_times_samples(np.concatenate([model.poles, dcm.poles]))))
    alone, both = dcm_step_responses(model, dcm, int(min(max(1.5 * slowest, 64), 20_000)))
    return np.arange(alone.size) * model.sample_interval_s, alone, both


def dcm_page(entry: ShotEntry) -> Figure:
    """The DCM: magnitudes (model, DCM, compensated) with both FBSDs, step responses, design."""
    a = entry.analysis
    assert a is not None
    model, dcm = a.model, a.dcm
    fig = _figure(f"{entry.label}: dynamic compensation model (DCM)")
    ax_m, ax_s, ax_tab = fig.subplots(3, 1, height_ratios=[1.3, 1.0, 0.6])
    comp = a.compensated_fbsd_hz
    top = max(comp.get("10") or 0.0, a.fbsd_hz.get("10") or 0.0)
    f = np.linspace(0.0, min(nyquist_hz(model), 1.6 * top if top else nyquist_hz(model)), 1000)
    h = frequency_response(model, f)
    g = dcm.frequency_response(f)
    ax_m.plot(f / 1e3, _normalised(h, model.dc_gain), color="tab:blue", lw=1.2, label="model H")
    ax_m.plot(f / 1e3, np.abs(g) / abs(dcm.dc_gain), color="0.5", lw=1.0, ls=":", label="DCM G")
    ax_m.plot(f / 1e3, _normalised(h * g, model.dc_gain * dcm.dc_gain), color="tab:red", lw=1.6,
              label="compensated H·G")
    _bands(ax_m, a.fbsd_hz, "FBSD", ":", shade=True)
    _bands(ax_m, comp, "compensated FBSD", "-", shade=False)
    ax_m.set_ylim(0.5, 1.5)
    ax_m.set_xlim(0, f[-1] / 1e3)
    ax_m.set_xlabel("frequency (kHz)")
    ax_m.set_ylabel("|H(f)/H(0)| (ratio)")
    ax_m.set_title("Compensated response: the DCM widens the band of small distortion", fontsize=9)
    ax_m.legend(fontsize=6.5, loc="upper left", ncol=2)
    ax_m.grid(alpha=0.3)

    t, alone, both = step_responses(a)
    ax_s.plot(t * 1e6, alone, color="tab:blue", label="model (uncompensated)")
    ax_s.plot(t * 1e6, both, color="tab:red", label=f"with DCM (without ÷ with: rise time {_fmt(a.rise_time_ratio, digits=3)}, "
                f"±5 % settling {_fmt(a.settling_time_ratio, digits=3)})")
    for level in (0.1, 0.9):
        ax_s.axhline(level, color="0.6", lw=0.6, ls=":")
    ax_s.axhline(1.0, color="0.3", lw=0.6)
    ax_s.set_xlabel("time (µs)")
    ax_s.set_ylabel("step response (normalised)")
    ax_s.set_title("Step responses (10 % and 90 % marked)", fontsize=9)
    ax_s.legend(fontsize=7)
    ax_s.grid(alpha=0.3)
    _table(ax_tab, None, [[k, v] for k, v in dcm_rows(a)], fontsize=7.5, col_widths=[0.25, 0.75])
    ax_tab.set_title("DCM design (Eqs. 13–25)", loc="left", fontsize=9)
    return fig


def cross_validation_page(stats: CampaignStatistics, entries: Sequence[ShotEntry]) -> Figure:
    """The cross-validation matrix and f_n / S_sh / FBSD against the shock level."""
    fig = _figure("Campaign: cross-validation and spread",
                  "row i: model identified on shot i; column j: simulated on shot j's reference")
    ax_cv, ax_fn, ax_s = fig.subplots(3, 1, height_ratios=[1.4, 1.0, 1.0])
    m = stats.cross_validation_percent
    labels = stats.labels
    if m.size:
        finite = m[np.isfinite(m)]
        low = float(np.min(finite)) if finite.size else 0.0
        im = ax_cv.imshow(m, cmap="viridis", vmin=min(low, 99.0), vmax=100.0)
        for i in range(m.shape[0]):
            for j in range(m.shape[1]):
                if np.isfinite(m[i, j]):
                    ax_cv.text(j, i, f"{m[i, j]:.2f}", ha="center", va="center", fontsize=7,
                               color="white" if m[i, j] < (low + 100) / 2 else "black")
        ax_cv.set_xticks(range(len(labels)), labels, rotation=45, ha="right", fontsize=7)
        ax_cv.set_yticks(range(len(labels)), labels, fontsize=7)
        fig.colorbar(im, ax=ax_cv, label="fit (%)", shrink=0.8)
    ax_cv.set_xlabel("shot j (reference and measured response)")
    ax_cv.set_ylabel("model of shot i")
    ax_cv.set_title("Cross-validation fit %: 100·(1 − ‖y_j − ŷ_ij‖ / ‖y_j − ȳ_j‖)", fontsize=9)

    peaks = np.array([np.nan if f["peak_acceleration_m_s2"] is None else f["peak_acceleration_m_s2"] / G_M_S2
                      for f in stats.figures])

    def series(key: str, scale: float) -> np.ndarray:
        return np.array([np.nan if f[key] is None else f[key] / scale for f in stats.figures])

    def with_spread(ax: Any, key: str, scale: float, colour: str, label: str) -> None:
        y = series(key, scale)
        s = stats.spread[key]
        if s["mean"] is None:
            ax.text(0.5, 0.5, "not available for these shots", ha="center", va="center", transform=ax.transAxes)
            return
        ax.plot(peaks, y, "o", color=colour, label=label)
        mean = s["mean"] / scale
        std = (s["std"] or 0.0) / scale
        ax.axhline(mean, color=colour, lw=1, label=f"mean {_fmt(mean, digits=5)}")
        if s["std"] is not None:
            ax.axhspan(mean - std, mean + std, color=colour, alpha=0.12, label=f"± 1 std ({_fmt(std, digits=3)})")
        # At least ±1 % of the mean in view, so a tiny spread looks tiny.
        half = max(3.0 * std, 0.01 * abs(mean), float(np.nanmax(np.abs(y - mean))) * 1.2)
        ax.set_ylim(mean - half, mean + half)
        ax.ticklabel_format(axis="y", useOffset=False)
        ax.legend(fontsize=7)

    with_spread(ax_fn, "natural_frequency_hz", 1e3, "tab:blue", "f_n per shot")
    ax_fn.set_xlabel("peak acceleration (g)")
    ax_fn.set_ylabel("natural frequency f_n (kHz)")
    ax_fn.set_title("Main resonance against the shock level", fontsize=9)
    ax_fn.grid(alpha=0.3)
    with_spread(ax_s, "shock_sensitivity", 1.0, "tab:green", "S_sh per shot")
    ax_s.set_xlabel("peak acceleration (g)")
    ax_s.set_ylabel("shock sensitivity (× nominal)")
    ax_s.set_title("Shock sensitivity (ISO 16063-13) against the shock level: linearity", fontsize=9)
    ax_s.grid(alpha=0.3)
    return fig


def campaign_responses_page(entries: Sequence[ShotEntry]) -> Figure:
    """Every shot's normalised magnitude on one plot, with the bands and each FBSD ±5 %."""
    fig = _figure("Campaign: identified responses of all shots")
    ax_db, ax_band = fig.subplots(2, 1)
    analysed = [e for e in entries if e.analysis is not None]
    colours = [f"C{i % 10}" for i in range(len(analysed))]
    top = 0.0
    for e, c in zip(analysed, colours, strict=True):
        a = e.analysis
        assert a is not None
        f = _frequency_grid(a.model, 800)
        ax_db.semilogx(f / 1e3, 20 * np.log10(_normalised(frequency_response(a.model, f), a.model.dc_gain)),
                       color=c, lw=1, label=e.label)
        top = max(top, a.fbsd_hz.get("10") or 0.0)
    for key, level, colour in BAND_LEVELS:
        ax_db.axhspan(20 * np.log10(1 - level), 20 * np.log10(1 + level), color=colour, alpha=0.2,
                      label=f"±{key} % band")
    ax_db.set_xlabel("frequency (kHz)")
    ax_db.set_ylabel("|H(f)/H(0)| (dB)")
    ax_db.set_title("Normalised magnitude of each shot's model", fontsize=9)
    ax_db.grid(alpha=0.3)
    ax_db.legend(fontsize=6.5, ncol=3)
    for e, c in zip(analysed, colours, strict=True):
        a = e.analysis
        assert a is not None
        fl = np.linspace(0.0, min(nyquist_hz(a.model), 2.5 * top if top else nyquist_hz(a.model)), 600)
        ax_band.plot(fl / 1e3, _normalised(frequency_response(a.model, fl), a.model.dc_gain), color=c, lw=1,
                     label=e.label)
        f5 = a.fbsd_hz.get("5")
        if f5:
            ax_band.axvline(f5 / 1e3, color=c, ls="--", lw=0.8)
    for key, level, colour in BAND_LEVELS:
        ax_band.axhspan(1 - level, 1 + level, color=colour, alpha=0.1, label=f"±{key} % band")
    ax_band.set_ylim(0.8, 1.2)
    ax_band.set_xlabel("frequency (kHz)")
    ax_band.set_ylabel("|H(f)/H(0)| (ratio)")
    ax_band.set_title("Around the bands (dashed: each shot's FBSD ±5 %)", fontsize=9)
    ax_band.grid(alpha=0.3)
    ax_band.legend(fontsize=6.5, ncol=3, loc="lower left")
    return fig


def failed_shot_page(entry: ShotEntry) -> Figure:
    fig = _figure(f"{entry.label}: no analysis")
    ax = fig.subplots(1, 1)
    rows = [[k, _wrap(v, 70)] for k, v in entry.identity.items()]
    rows.append(["state", entry.state or "—"])
    rows.append(["analysis", _wrap(entry.error or "no analysis stored", 70)])
    _table(ax, None, rows, col_widths=[0.3, 0.7])
    return fig


def shot_pages(entry: ShotEntry) -> list[tuple[str, Figure]]:
    """(caption, figure) of every page of one shot."""
    if entry.analysis is None:
        return [(f"{entry.label}: no analysis", failed_shot_page(entry))]
    return [
        (f"{entry.label}: excitation and identification", excitation_page(entry)),
        (f"{entry.label}: model frequency response, FBSD", model_page(entry)),
        (f"{entry.label}: poles and zeros", poles_page(entry)),
        (f"{entry.label}: dynamic compensation model", dcm_page(entry)),
    ]


def report_pages(report: CalibrationReport, stats: CampaignStatistics | None = None) -> list[tuple[str, Figure]]:
    """Every page of the report in order: title, campaign pages (if any), then each shot's."""
    if report.campaign and stats is None:
        stats = campaign_statistics(report.shots)
    pages = [("Summary", title_page(report, stats))]
    if report.campaign and stats is not None and stats.labels:
        pages.append(("Campaign: cross-validation and spread", cross_validation_page(stats, report.shots)))
        pages.append(("Campaign: responses of all shots", campaign_responses_page(report.shots)))
    for entry in report.shots:
        pages.extend(shot_pages(entry))
    for _caption, fig in pages:
        _freeze_layout(fig)
    return pages


def _freeze_layout(fig: Figure) -> None:
    """Run the constrained layout once and keep it: every later save (PDF page, PNG) then
    draws the figure once instead of laying it out again (about half the time per save)."""
    engine = fig.get_layout_engine()
    if engine is not None:
        engine.execute(fig)
        fig.set_layout_engine("none")


# =============================================================================================
# Writers
# =============================================================================================


def _atomic(path: Path, write: Any) -> Path:
    """Write through `<path>.tmp` and rename, so a report is whole or absent."""
    tmp = path.with_name(path.name + ".tmp")
    try:
        write(tmp)
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    return path


def _write_pdf(path: Path, report: CalibrationReport, pages: list[tuple[str, Figure]]) -> None:
    def write(tmp: Path) -> None:
        with PdfPages(tmp, metadata={"Title": report.title, "Subject": "Hopkinson-bar shock calibration report",
                                     "Keywords": " ".join(e.label for e in report.shots),
                                     "Creator": "hopkinson"}) as pdf:
            for _caption, fig in pages:
                pdf.savefig(fig)

    _atomic(path, write)


def _png_base64(fig: Figure) -> str:
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=PNG_DPI)
    return base64.b64encode(buf.getvalue()).decode("ascii")


def _html_table(header: list[str] | None, rows: Iterable[Sequence[str]], cls: str = "") -> str:
    out = [f'<table class="{cls}">' if cls else "<table>"]
    if header:
        out.append("<thead><tr>" + "".join(f"<th>{html.escape(h)}</th>" for h in header) + "</tr></thead>")
    out.append("<tbody>")
    for row in rows:
        out.append("<tr>" + "".join(f"<td>{html.escape(str(c))}</td>" for c in row) + "</tr>")
    out.append("</tbody></table>")
    return "".join(out)


_CSS = """
body { font-family: DejaVu Sans, Arial, sans-serif; margin: 2em auto; max-width: 60em; color: #222; }
h1 { font-size: 1.6em; } h2 { border-bottom: 1px solid #ccc; margin-top: 2em; } h3 { margin-top: 1.5em; }
table { border-collapse: collapse; margin: 0.5em 0 1em 0; font-size: 0.9em; }
td, th { border: 1px solid #ccc; padding: 0.2em 0.6em; text-align: left; vertical-align: top; }
th { background: #eee; } table.kv td:first-child { font-weight: bold; white-space: nowrap; }
figure { margin: 1em 0; } figure img { max-width: 100%; border: 1px solid #ddd; }
figcaption { font-size: 0.85em; color: #555; } .error { color: #a00; }
"""


def _write_html(path: Path, report: CalibrationReport, pages: list[tuple[str, Figure]],
                stats: CampaignStatistics | None) -> None:
    e = html.escape
    parts = [f"<!DOCTYPE html><html lang='en'><head><meta charset='utf-8'><title>{e(report.title)}</title>"
             f"<style>{_CSS}</style></head><body>", f"<h1>{e(report.title)}</h1>",
             "<p>Hopkinson-bar shock calibration: dynamic model, band of small distortion (FBSD, ±5 % and ±10 %) "
             "and dynamic compensation model (DCM).</p>",
             "<h2>Accelerometer and rig</h2>", _html_table(None, report.identity.items(), "kv")]
    by_caption = dict(pages)
    if report.campaign and stats is not None:
        parts.append("<h2>Shots</h2>")
        parts.append(_html_table(*per_shot_rows(report.shots)))
        parts.append(f"<h2>Spread across {len(stats.labels)} analysed shots</h2>")
        parts.append(_html_table(*spread_rows(stats)))
        parts.append("<h2>Cross-validation</h2><p>Row i: the model identified on shot i; column j: its response "
                     "simulated on shot j's reference, compared with shot j's measured response: fit % = "
                     "100·(1 − ‖y − ŷ‖/‖y − ȳ‖).</p>")
        m = stats.cross_validation_percent
        rows = [[stats.labels[i]] + [_fmt(v, digits=5) for v in m[i]] for i in range(len(stats.labels))]
        parts.append(_html_table(["model \\ shot"] + stats.labels, rows, "cv"))
        for caption in ("Campaign: cross-validation and spread", "Campaign: responses of all shots"):
            if caption in by_caption:
                parts.append(_html_figure(caption, by_caption[caption]))
    for entry in report.shots:
        parts.append(f"<h2 id='shot-{e(entry.label)}'>Shot {e(entry.label)}</h2>")
        parts.append(_html_table(None, list(entry.identity.items()) + [("state", entry.state or "—")], "kv"))
        if entry.analysis is None:
            parts.append(f"<p class='error'>No analysis: {e(entry.error or 'none stored')}</p>")
            continue
        parts.append("<h3>Results</h3>" + _html_table(None, results_rows(entry), "kv"))
        for caption, fig in [(c, f) for c, f in pages if c.startswith(f"{entry.label}: ")]:
            parts.append(_html_figure(caption, fig))
            if caption.endswith("poles and zeros"):
                parts.append("<h3>Pole analysis (Table 1)</h3>" + _html_table(*pole_rows(entry.analysis)))
            if caption.endswith("dynamic compensation model"):
                parts.append("<h3>DCM</h3>" + _html_table(None, dcm_rows(entry.analysis), "kv"))
    if report.notes:
        parts.append("<h2>Notes</h2><ul>" + "".join(f"<li>{e(n)}</li>" for n in report.notes) + "</ul>")
    parts.append("</body></html>\n")
    text = "\n".join(parts)
    _atomic(path, lambda tmp: tmp.write_text(text, encoding="utf-8"))


def _html_figure(caption: str, fig: Figure) -> str:
    return (f"<figure><img alt='{html.escape(caption)}' src='data:image/png;base64,{_png_base64(fig)}'>"
            f"<figcaption>{html.escape(caption)}</figcaption></figure>")


def write_report(report: CalibrationReport, paths: Sequence[str | Path]) -> list[Path]:
    """Write the report to each path; the format comes from the suffix (.pdf or .html).

    The pages are drawn once for all formats. Each file is written under a temporary name and
    renamed. AnalysisError for an unknown suffix or a report without shots.
    """
    targets = [Path(p) for p in paths]
    for p in targets:
        if p.suffix.lower().lstrip(".") not in FORMATS:
            raise AnalysisError(f"{p}: a report is .pdf or .html")
        if not p.parent.is_dir():
            raise AnalysisError(f"{p}: folder {p.parent} does not exist")
    if not report.shots:
        raise AnalysisError(f"report {report.title!r}: no shots to report")
    stats = campaign_statistics(report.shots) if report.campaign else None
    pages = report_pages(report, stats)
    for p in targets:
        if p.suffix.lower() == ".pdf":
            _write_pdf(p, report, pages)
        else:
            _write_html(p, report, pages, stats)
    return targets
