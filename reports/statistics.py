"""Across the shots of a campaign: the spread of each key figure and the cross-validation matrix.

- spread: mean, sample standard deviation (n − 1) and coefficient of variation of the main
  mode's f_n and ζ, the FBSD (±5 %, ±10 %), the shock sensitivity and the fit;
- cross-validation (the paper's "multi-group data" check): entry [i, j] is the fit % of
  model i simulated on shot j's reference against shot j's measured response,
  100·(1 − ‖y − ŷ‖/‖y − ȳ‖), the measure `analysis.identify` reports for its own shot (the
  diagonal equals each shot's own fit). Shot j's channels are prepared as the identification
  prepared them (its baselines and input delay, stored in its results);
- the campaign's value of each uncertain key figure (`combine`): the mean of the shots, their
  repeatability and a combined expanded uncertainty (see `combine` for how);
- amplitude linearity (ISO 16063-22): each shot's quasi-static gain (analysis.static_gain)
  against the amplitude it is measured at with its U, and the straight line through them
  (analysis.linearity), when the shots cover two or more levels.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from hopkinson.analysis.errors import AnalysisError
from hopkinson.analysis.identify import fit_percent
from hopkinson.analysis.key_figures import Figure, KeyFigures
from hopkinson.analysis.linearity import LinearityFit, fit_linearity
from hopkinson.analysis.shot_analysis import ShotAnalysis
from hopkinson.analysis.sine_comparison import SineCalibration, SineComparison, compare_sine
from hopkinson.reports.data import (
    QUANTITIES,
    ShotEntry,
    figures_of_merit,
    model_delay_samples,
    prepared,
)


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


def cross_validation(analyses: Sequence[ShotAnalysis]) -> np.ndarray:
    """Fit % of model i (with its own delay) on shot j's prepared channels (data.prepared): matrix
    [i, j]; NaN where it cannot be computed."""
    n = len(analyses)
    out = np.full((n, n), np.nan)
    for i, a in enumerate(analyses):
        d = model_delay_samples(a)
        for j, b in enumerate(analyses):
            if not math.isclose(a.model.sample_interval_s, b.model.sample_interval_s, rel_tol=1e-6):
                continue
            try:
                shot = prepared(b, legacy_delay_samples=d)
                out[i, j] = fit_percent(shot.response, shot.model_response(a))
            except AnalysisError:
                pass
    return out


COVERAGE = 0.95
COMBINATION_NOTE = (
    "Combined across shots (GUM 5.1 and G.4): the campaign's value is the mean x̄ of the n shots; "
    "u_c(x̄)² = s²/n + ū², where s is the repeatability (standard deviation of the shots' values, n − 1), "
    "s/√n its share in the mean, and ū the root mean square of the shots' own standard uncertainties "
    "(Monte Carlo, GUM Supplement 1), taken as fully correlated between shots: the reference chain is "
    "common to all of them (the noise share of ū, already seen in s, is then counted twice: on the safe "
    "side). U = k·u_c with k from Student's t at the Welch–Satterthwaite degrees of freedom "
    "(ν = u_c⁴ / ((s²/n)² / (n − 1)); the Monte Carlo part has ν = ∞), for 95 % coverage. FBSD edges that "
    "a shot reports only as a bound are left out of the mean.")

# key, label, unit, display scale, the KeyFigures field (Figure or, for FBSD, a level)
COMBINED: tuple[tuple[str, str, str, float, str], ...] = (
    ("sensitivity", "sensitivity (model DC gain)", "× nominal", 1.0, "sensitivity"),
    ("shock_sensitivity", "shock sensitivity S_sh (ISO 16063-13)", "× nominal", 1.0, "shock_sensitivity"),
    ("natural_frequency_hz", "main mode f_n", "kHz", 1e3, "natural_frequency_hz"),
    ("damping_ratio", "main mode damping ζ", "", 1.0, "damping_ratio"),
    ("fbsd_5_hz", "FBSD ±5 %", "kHz", 1e3, "5"),
    ("fbsd_10_hz", "FBSD ±10 %", "kHz", 1e3, "10"),
)


@dataclass(frozen=True)
class Combined:
    """One key figure combined across shots (see COMBINATION_NOTE)."""

    n: int  # shots with a value
    mean: float | None
    repeatability: float | None  # s, the shots' standard deviation (n − 1); None for one shot
    u_shots: float | None  # ū, the RMS of the shots' standard uncertainties; None when none has one
    n_with_u: int
    u_combined: float | None
    dof: float | None  # effective degrees of freedom (inf: Monte Carlo only)
    k: float | None
    expanded: float | None  # U = k·u_c
    excluded_bounds: int = 0  # FBSD edges reported only as bounds

    def to_dict(self) -> dict[str, Any]:
        return {"n": self.n, "mean": self.mean, "repeatability": self.repeatability, "u_shots": self.u_shots,
                "n_with_u": self.n_with_u, "u_combined": self.u_combined,
                "dof": None if self.dof is None or math.isinf(self.dof) else self.dof, "k": self.k,
                "expanded": self.expanded, "excluded_bounds": self.excluded_bounds}

    def figure(self) -> Figure:
        """The combined value as a Figure (interval mean ± U) for formatting."""
        if self.mean is None or self.expanded is None:
            return Figure(self.mean)
        return Figure(self.mean, self.u_combined, (self.mean - self.expanded, self.mean + self.expanded))


def combine(figures: Sequence[Figure | None], excluded_bounds: int = 0) -> Combined:
    """The mean of the shots' values with its repeatability and combined expanded uncertainty
    (COMBINATION_NOTE); shots without a value are skipped."""
    from scipy.stats import t as student_t

    known = [f for f in figures if f is not None and f.value is not None and math.isfinite(f.value)]
    n = len(known)
    if n == 0:
        return Combined(0, None, None, None, 0, None, None, None, None, excluded_bounds)
    x = np.array([f.value for f in known], dtype=float)
    mean = float(np.mean(x))
    s = float(np.std(x, ddof=1)) if n > 1 else None
    us = [f.u for f in known if f.u is not None and math.isfinite(f.u)]
    u_shots = float(np.sqrt(np.mean(np.square(us)))) if us else None
    var_repeat = s * s / n if s is not None else None
    if var_repeat is None and u_shots is None:
        return Combined(n, mean, s, None, 0, None, None, None, None, excluded_bounds)
    u_c = math.sqrt((var_repeat or 0.0) + (u_shots or 0.0) ** 2)
    if var_repeat:
        dof = u_c ** 4 / (var_repeat ** 2 / (n - 1))
    else:
        dof = math.inf
    k = float(student_t.ppf(0.5 + COVERAGE / 2, dof))  # 1.960 for ν = ∞
    return Combined(n, mean, s, u_shots, len(us), u_c, dof, k, k * u_c, excluded_bounds)


def combined_figures(key_figures: Sequence[KeyFigures]) -> dict[str, Combined]:
    """Every COMBINED key figure across the shots' KeyFigures."""
    out = {}
    for key, _label, _unit, _scale, attr in COMBINED:
        if attr in ("5", "10"):
            bounded = sum(1 for kf in key_figures if attr in kf.fbsd_bounds)
            figures = [kf.fbsd_hz.get(attr) for kf in key_figures if attr not in kf.fbsd_bounds]
            out[key] = combine(figures, bounded)
        else:
            out[key] = combine([getattr(kf, attr) for kf in key_figures])
    return out


STATIC_GAIN = "quasi-static gain (main pulse's direction)"
DC_GAIN = "DC gain"
LINEARITY_SENSITIVITY = {
    STATIC_GAIN: "each shot's quasi-static gain in the main pulse's direction (analysis.static_gain: the response "
                 "compensated by the model's dynamics where the sensor is quasi-static, its least-squares gain on the "
                 "reference's main lobe) at the amplitude it is measured at",
    DC_GAIN: "each shot's model DC gain at Σ|a|³/Σa² (shots analysed before the quasi-static gain: on a non-linear "
             "sensor the fit's dynamics take up part of the change, so the slope reads short; analyse them again)",
}


@dataclass(frozen=True)
class LinearityPoint:
    """One shot's sensitivity at the amplitude it is measured at, with the u (and U, 95 %) that
    differs from shot to shot: its quasi-static gain in the main pulse's direction
    (analysis.static_gain, `kind` STATIC_GAIN), or for results written before it the model's DC
    gain at analysis.excitation.gain_amplitude (`kind` DC_GAIN; KeyFigures.shot_specific_u)."""

    label: str
    peak_m_s2: float
    sensitivity: float
    u: float | None
    expanded: float | None
    kind: str = STATIC_GAIN


MIN_LEVEL_SPAN_REL = 0.05  # levels closer than this (relative) are one level: no line through them


def static_gain_point(label: str, gain: Figure | None, amplitude_m_s2: float | None) -> LinearityPoint | None:
    """A shot's quasi-static gain (analysis.static_gain, its u shot-specific) at the amplitude it
    is measured at, as a point of the line (`kind` STATIC_GAIN); None where it has none. The one
    source of the points a campaign's statistics and a certificate (lab.certificate) fit."""
    if gain is None or gain.value is None or not amplitude_m_s2:
        return None
    if not (math.isfinite(gain.value) and math.isfinite(amplitude_m_s2)):
        return None
    u = gain.u
    return LinearityPoint(label, abs(float(amplitude_m_s2)), float(gain.value), u,
                          None if u is None else 1.959963984540054 * u, STATIC_GAIN)


def linearity_points(labelled: Iterable[tuple[str, KeyFigures | None]]) -> list[LinearityPoint]:
    """The shots that are results, with a sensitivity and the amplitude it was measured at
    (LinearityPoint)."""
    out = []
    for label, kf in labelled:
        if kf is None or not kf.is_result:
            continue
        static = static_gain_point(label, kf.static_gain, kf.static_gain_amplitude_m_s2)
        if static is not None:
            out.append(static)
            continue
        if kf.sensitivity.value is not None and kf.static_gain_not_determined is None:
            s, kind = kf.sensitivity.value, DC_GAIN
            a = kf.gain_amplitude_m_s2
            if a is None and kf.peak_acceleration_m_s2 is not None:
                a = kf.peak_acceleration_m_s2.value
            u = kf.shot_specific_u("dc_gain")
        else:
            continue
        if a is None or not (math.isfinite(s) and math.isfinite(a)):
            continue
        out.append(LinearityPoint(label, abs(float(a)), float(s), u, None if u is None else 1.959963984540054 * u,
                                  kind))
    return out


def fitted_points(points: Sequence[LinearityPoint]) -> list[LinearityPoint]:
    """The points a line goes through: points of both kinds (shots analysed before the quasi-static
    gain among newer ones) are not one sensitivity, and only the quasi-static gains are kept."""
    if len({p.kind for p in points}) > 1:
        return [p for p in points if p.kind == STATIC_GAIN]
    return list(points)


def campaign_linearity(points: Sequence[LinearityPoint]) -> tuple[LinearityFit | None, str]:
    """The straight line through `fitted_points(points)` (analysis.linearity), or None and why not;
    the note names the shots left out."""
    notes = []
    if len({p.kind for p in points}) > 1:
        left = [p.label for p in points if p.kind != STATIC_GAIN]
        points = fitted_points(points)
        notes.append(f"amplitude linearity: {len(left)} shot(s) without a quasi-static gain (analysed before it) left "
                     f"out ({', '.join(left)}): analyse them again")
    if len(points) < 2:
        return None, "; ".join([*notes, "amplitude linearity: needs analysed shots at two or more levels"])
    peaks = np.array([p.peak_m_s2 for p in points])
    if np.ptp(peaks) < MIN_LEVEL_SPAN_REL * float(np.max(peaks)):
        return None, "; ".join([*notes, "amplitude linearity: every shot is at one level (within 5 %): fire "
                                        "several levels"])
    us = [p.u for p in points]
    known = all(u is not None and u > 0 for u in us)
    try:
        fit = fit_linearity(peaks, [p.sensitivity for p in points], us if known else None)  # type: ignore[arg-type]
    except AnalysisError as exc:
        return None, "; ".join([*notes, f"amplitude linearity: {exc}"])
    if not known:
        notes.append("amplitude linearity: some shots have no uncertainty: equal weights, u from the scatter")
    if points[0].kind != STATIC_GAIN:
        notes.append(f"amplitude linearity: fitted to {LINEARITY_SENSITIVITY[points[0].kind]}")
    return fit, "; ".join(notes)


def linearity_sensitivity(points: Sequence[LinearityPoint], short: bool = False) -> str:
    """Which sensitivity the line is fitted to, in words (the report says it); `short`: its name
    ("quasi-static gain", "sensitivity (DC gain)") for the summary."""
    kind = STATIC_GAIN if any(p.kind == STATIC_GAIN for p in points) else DC_GAIN
    if short:
        return "quasi-static gain" if kind == STATIC_GAIN else "sensitivity (DC gain)"
    return LINEARITY_SENSITIVITY[kind]


@dataclass
class CampaignStatistics:
    """Across the analysed shots: per-shot figures, their spread, the combined key figures and
    the cross-validation matrix."""

    labels: list[str]  # the analysed shots, in order
    figures: list[dict[str, Any]]  # figures_of_merit per analysed shot
    spread: dict[str, dict[str, float | int | None]]  # quantity key -> spread()
    cross_validation_percent: np.ndarray  # [i, j]: model i on shot j
    combined: dict[str, Combined] = field(default_factory=dict)  # COMBINED key -> combination
    sine: list[tuple[str, SineComparison]] = field(default_factory=list)  # shot -> against the sine calibration
    sine_notes: list[str] = field(default_factory=list)
    linearity_points: list[LinearityPoint] = field(default_factory=list)
    linearity: LinearityFit | None = None  # None: fewer than two levels (linearity_note says)
    linearity_note: str = ""

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready (strict JSON: a NaN or infinite figure becomes None)."""
        return json_safe({"shots": self.labels, "figures": self.figures, "spread": self.spread,
                          "combined": {k: c.to_dict() for k, c in self.combined.items()},
                          "combination_note": COMBINATION_NOTE,
                          "sine_comparison": {label: c.to_dict() for label, c in self.sine} or None,
                          "cross_validation_percent": self.cross_validation_percent.tolist(),
                          "linearity": None if self.linearity is None else {
                              **self.linearity.to_dict(), "points": [vars(p) for p in self.linearity_points]},
                          "linearity_note": self.linearity_note,
                          "cross_validation_note": "row i: model of shot i; column j: simulated on shot j's "
                                                   "reference; fit % = 100·(1 − ‖y − ŷ‖/‖y − ȳ‖)"})


def json_safe(obj: Any) -> Any:
    if isinstance(obj, dict):
        return {k: json_safe(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [json_safe(v) for v in obj]
    if isinstance(obj, float | np.floating):
        return float(obj) if math.isfinite(obj) else None
    if isinstance(obj, np.integer):
        return int(obj)
    return obj


def sine_comparisons(entries: Sequence[ShotEntry], sine: SineCalibration
                     ) -> tuple[list[tuple[str, SineComparison]], list[str]]:
    """Each analysed shot's model (and its DCM) against the sine calibration
    (analysis.sine_comparison.compare_sine); the comparisons and, for shots it cannot be done
    for, why (a note each)."""
    out, notes = [], []
    for e in entries:
        if e.analysis is None:
            continue
        try:
            out.append((e.label, compare_sine(e.analysis.model, sine, e.analysis.dcm)))
        except AnalysisError as exc:
            notes.append(f"{e.label}: not compared with the sine calibration: {exc}")
    return out, notes


def campaign_statistics(entries: Sequence[ShotEntry], sine: SineCalibration | None = None) -> CampaignStatistics:
    """Spread, combined key figures and cross-validation over the entries that have an analysis
    (and each one's model against the sine calibration, when there is one)."""
    analysed = [e for e in entries if e.analysis is not None]
    figures = [figures_of_merit(e) for e in analysed]
    keys = [k for k, *_ in QUANTITIES] + ["sensitivity_v_per_m_s2", "peak_acceleration_m_s2", "pulse_width_s"]
    stats = {k: spread(f[k] for f in figures) for k in keys}
    matrix = cross_validation([e.analysis for e in analysed])  # type: ignore[misc]
    combined = combined_figures([e.key_figures for e in analysed if e.key_figures is not None])
    comparisons, notes = sine_comparisons(analysed, sine) if sine is not None else ([], [])
    points = linearity_points((e.label, e.key_figures) for e in analysed)
    fit, note = campaign_linearity(points)
    points = fitted_points(points)  # the page tables the points the line goes through
    return CampaignStatistics([e.label for e in analysed], figures, stats, matrix, combined, comparisons, notes,
                              points, fit, note)
