"""What a calibration report holds: the report's model (no drawing, no files).

A report is a `CalibrationReport`: who and what (identity), and one `ShotEntry` per shot with
its `ShotAnalysis` (analysis/shot_analysis.py). `rig.report_data` fills it from shot files or
a campaign run folder. This module also gives what the pages need of one shot's data: its
identification and excitation as dicts, its main mode, its channels prepared as the
identification fitted them, and (in simulation) its error against the true accelerometer.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from functools import cached_property
from typing import Any

import numpy as np

from hopkinson.analysis.errors import AnalysisError
from hopkinson.analysis.identify import remove_input_delay
from hopkinson.analysis.key_figures import Figure, KeyFigures
from hopkinson.analysis.resample import resample_to_rate
from hopkinson.analysis.response import delayed_model_output, model_output
from hopkinson.analysis.shot_analysis import ShotAnalysis
from hopkinson.analysis.sine_comparison import SineCalibration
from hopkinson.analysis.verdict import ShotVerdict

G_M_S2 = 9.80665  # standard gravity: accelerations are also shown in g


@dataclass
class ShotEntry:
    """One shot of a report: who/what/when, its analysis (None when it failed or is missing).

    `results` is the stored results dict (a shot file's /analysis) when there is one: the key
    figures, the uncertainty and the compensation check are read from it (from the analysis
    object's own dict otherwise)."""

    label: str  # shot id, or the file name
    identity: dict[str, str]  # label -> text, in display order
    analysis: ShotAnalysis | None
    error: str | None = None  # why there is no analysis
    state: str = ""  # journal or shot-file state
    truth_modes: list[dict[str, Any]] | None = None  # simulation: the true modes (f_n, ζ)
    nominal_sensitivity_v_per_m_s2: float | None = None
    pressure_bar: float | None = None
    results: dict[str, Any] | None = None
    verdict: ShotVerdict | None = None  # ACCEPT/REPEAT with its findings (analysis.verdict), where judged

    @cached_property
    def stored(self) -> dict[str, Any]:
        """The results dict: as stored, else the analysis' own (empty without an analysis)."""
        if self.results is not None:
            return self.results
        return self.analysis.to_dict() if self.analysis is not None else {}

    @cached_property
    def key_figures(self) -> KeyFigures | None:
        """The shot's headline numbers (analysis.key_figures), None without an analysis."""
        return KeyFigures.from_results(self.stored) if self.analysis is not None else None

    @cached_property
    def compensation(self) -> CompensationCheck | None:
        """How the DCM did on the shot itself, None when the results do not say."""
        return CompensationCheck.of(self.key_figures) if self.key_figures is not None else None


@dataclass(frozen=True)
class CompensationCheck:
    """The DCM's check on its own shot, read from its KeyFigures (the results' "dcm" object):
    errors over the pulse before and with compensation, the widening aimed for and reached, the
    noise gain and its limit, the band-limiting low-pass, the latency, and whether a DCM is
    recommended."""

    recommended: bool | None
    not_recommended_reason: str | None
    rms_error_pct: tuple[float | None, float | None] | None  # (uncompensated, compensated)
    peak_error_pct: tuple[float | None, float | None] | None
    target_widening: float | None
    reached_widening: float | None
    widening_note: str | None
    noise_gain: float | None
    noise_gain_limit: float | None
    band_limit_hz: float | None
    latency_s: float | None
    compensated_peak: Figure | None

    @classmethod
    def of(cls, kf: KeyFigures) -> CompensationCheck | None:
        """From a shot's KeyFigures (its DCM figures); None when the results hold none of them."""
        present = (kf.dcm_recommended, kf.compensation_check, kf.dcm_noise_gain, kf.dcm_band_limit_hz,
                   kf.dcm_reached_widening, kf.dcm_latency_s)
        if all(v is None for v in present):
            return None
        check = kf.compensation_check or {}

        def pair(name: str) -> tuple[float | None, float | None] | None:
            d = check.get(name)
            if not isinstance(d, dict):
                return None
            return _number(d.get("uncompensated")), _number(d.get("compensated"))

        return cls(
            recommended=bool(kf.dcm_recommended) if kf.dcm_recommended is not None else None,
            not_recommended_reason=kf.dcm_not_recommended_reason,
            rms_error_pct=pair("rms_error_pct"),
            peak_error_pct=pair("peak_error_pct"),
            target_widening=kf.dcm_target_widening,
            reached_widening=kf.dcm_reached_widening,
            widening_note=kf.dcm_widening_note,
            noise_gain=kf.dcm_noise_gain,
            noise_gain_limit=kf.dcm_noise_gain_limit,
            band_limit_hz=kf.dcm_band_limit_hz,
            latency_s=kf.dcm_latency_s,
            compensated_peak=kf.compensated_peak,
        )


    @property
    def not_recommended_text(self) -> str | None:
        """Why the DCM is not recommended (a general reason when the analysis gave none); None
        when it is recommended or the results do not say."""
        if self.recommended is not False:
            return None
        return self.not_recommended_reason or "compensation does not improve this shot"

    def other_warnings(self, warnings: Sequence[str]) -> list[str]:
        """The shot's warnings less those that only repeat the not-recommended verdict, which
        the report and the panel show on a line of its own (the analysis words it up to three
        times: the verdict, "DCM not recommended for this shot: …", "DCM widening: …")."""
        reason = (self.not_recommended_reason or "").strip()
        if self.recommended is not False or not reason:
            return list(warnings)
        return [w for w in warnings if not (w.startswith("DCM") and reason in w)]


def _number(value: Any) -> float | None:
    """A finite number, else None (the key figures' own reading of a stored number)."""
    figure = Figure.of(value) if not isinstance(value, dict) else None
    return figure.value if figure is not None else None


@dataclass
class CalibrationReport:
    """A whole report: one shot, or a campaign of shots (with, when its plan names one, the
    sensor's sinusoidal calibration to compare each shot's model with)."""

    title: str
    identity: dict[str, str]
    shots: list[ShotEntry]
    campaign: bool = False
    notes: list[str] = field(default_factory=list)
    sine_calibration: SineCalibration | None = None
    # shot files that could not be reported (damaged, unreadable): {"id", "path", "reason"}
    unreadable: list[dict[str, str]] = field(default_factory=list)


def identification_dict(analysis: ShotAnalysis) -> dict[str, Any]:
    """The identification as its JSON dict (it is an object after an analysis, a dict when read back)."""
    ident = analysis.identification
    return ident if isinstance(ident, dict) else ident.to_dict()


def excitation_dict(analysis: ShotAnalysis) -> dict[str, Any]:
    exc = analysis.excitation
    return exc if isinstance(exc, dict) else exc.to_dict()


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
    """A shot's key numbers as plain values (None where unknown), for tables and the spread;
    read from its KeyFigures (analysis.key_figures), never recomputed."""
    out: dict[str, Any] = {k: None for k, *_ in QUANTITIES}
    out.update(order=None, peak_acceleration_m_s2=None, pulse_width_s=None, sensitivity_v_per_m_s2=None)
    kf = entry.key_figures
    if kf is None:
        return out

    def value(figure: Figure | None) -> float | None:
        return figure.value if figure is not None else None

    out["natural_frequency_hz"] = value(kf.natural_frequency_hz)
    out["damping_ratio"] = value(kf.damping_ratio)
    out["fbsd_5_hz"] = value(kf.fbsd_hz.get("5"))
    out["fbsd_10_hz"] = value(kf.fbsd_hz.get("10"))
    out["compensated_fbsd_5_hz"] = kf.compensated_fbsd_hz.get("5")
    out["fit_percent"] = kf.fit_percent
    out["order"] = kf.order
    out["peak_acceleration_m_s2"] = value(kf.peak_acceleration_m_s2)
    out["pulse_width_s"] = value(kf.pulse_width_s)
    s = value(kf.shock_sensitivity)
    out["shock_sensitivity"] = s
    if s is not None and entry.nominal_sensitivity_v_per_m_s2:
        out["sensitivity_v_per_m_s2"] = s * entry.nominal_sensitivity_v_per_m_s2
    return out


def truth_comparison(entry: ShotEntry) -> dict[str, float] | None:
    """In simulation: the identified main resonance against the true mode nearest to it.

    pole_error_percent = |s − s_true| / |s_true| · 100 for the continuous pole
    s = −ζω_n + jω_n√(1 − ζ²) (upper half plane). None without an analysis or a truth.
    """
    kf = entry.key_figures
    if kf is None or not entry.truth_modes or kf.natural_frequency_hz is None or kf.damping_ratio is None:
        return None
    fn, zeta = kf.natural_frequency_hz.value, kf.damping_ratio.value
    if not fn or zeta is None:
        return None
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


@dataclass(frozen=True)
class PreparedShot:
    """A shot's reference and response as its identification fitted them (see `prepared`)."""

    time_s: np.ndarray
    reference: np.ndarray  # u: baseline removed
    response: np.ndarray  # y: baseline removed (legacy results: also the fitted offset, delay removed)
    windowed: bool  # the identification's fitted window (results with `window_start_s`)

    def model_response(self, analysis: ShotAnalysis) -> np.ndarray:
        """ŷ of `analysis`' model on this shot's reference, with that model's own fractional
        input delay, computed as the identification computes its fit
        (analysis.response.delayed_model_output); for legacy results, whose channels were
        prepared with an integer delay removed, without it."""
        if not self.windowed:
            return model_output(analysis.model, self.reference)
        return delayed_model_output(analysis.model, self.reference)


def model_delay_samples(analysis: ShotAnalysis) -> int:
    """The integer input delay a legacy identification removed before fitting the model."""
    ident = identification_dict(analysis)
    return int(round(float(ident.get("delay_samples", analysis.model.delay_samples) or 0.0)))


def prepared(analysis: ShotAnalysis, legacy_delay_samples: int | None = None) -> PreparedShot:
    """The shot's channels as its identification fitted them: the record at the model's rate,
    each channel's baseline and drift line removed (the values the identification stored in
    its preprocessing: `<channel>_baseline`, `<channel>_drift`) and, when the results name it,
    only the fitted window (`window_start_s`, `window_samples`); there the model's response is
    simulated from rest at the window's start with the model's fractional delay, as the
    identification does, so a shot's own fit % comes out as it reported it (to rounding).

    Legacy results (no window): the response offset fitted with the model is also removed and
    the integer input delay taken out of the response, y(k) = response(k + d), d = the shot's
    own delay unless `legacy_delay_samples` (another shot's model is tried with its delay).
    """
    record = analysis.record
    if record is None:
        raise AnalysisError("the shot's record is not available (no /derived/record in the shot file)")
    dt = analysis.model.sample_interval_s
    if not math.isclose(record.sample_interval_s, dt, rel_tol=1e-6):
        record = resample_to_rate(record, 1.0 / dt)
    pre = identification_dict(analysis).get("preprocessing") or {}
    t = record.time_s
    u = np.asarray(record.reference, dtype=float) - _removed_line(pre, "reference", t)
    y = np.asarray(record.response, dtype=float) - _removed_line(pre, "response", t)
    if pre.get("window_start_s") is not None and pre.get("window_samples"):
        i0 = max(0, int(round((float(pre["window_start_s"]) - record.start_time_s) / dt)))
        i1 = min(u.size, i0 + int(pre["window_samples"]))
        return PreparedShot(t[i0:i1], u[i0:i1], y[i0:i1], True)
    # The constant offset the identification fitted with the model (a property of this shot's data).
    y = y - float(pre.get("response_offset_fitted", 0.0) or 0.0)
    d = model_delay_samples(analysis) if legacy_delay_samples is None else int(legacy_delay_samples)
    u, y = remove_input_delay(u, y, d)
    return PreparedShot(t[: u.size], u, y, False)


def _removed_line(pre: dict[str, Any], channel: str, time_s: np.ndarray) -> np.ndarray | float:
    """What the identification took off `channel` at each time: its baseline and, when results
    store it, its drift line (intercept + slope_per_s · (t − origin_s)); the baseline alone
    for results written before the drift was stored."""
    baseline = float(pre.get(f"{channel}_baseline", 0.0) or 0.0)
    drift = pre.get(f"{channel}_drift")
    if not isinstance(drift, dict):
        return baseline
    slope = float(drift.get("slope_per_s", 0.0) or 0.0)
    intercept = float(drift.get("intercept", 0.0) or 0.0)
    origin = float(drift.get("origin_s", 0.0) or 0.0)
    return baseline + intercept + slope * (time_s - origin)
