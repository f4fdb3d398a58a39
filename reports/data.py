"""What a calibration report holds: the report's model (no drawing, no files).

A report is a `CalibrationReport`: who and what (identity), and one `ShotEntry` per shot with
its `ShotAnalysis` (analysis/shot_analysis.py). `rig.report_data` fills it from shot files or
a campaign run folder. This module also gives what the pages need of one shot's data: its
identification and excitation as dicts, its main mode, its channels prepared as the
identification fitted them, and (in simulation) its error against the true accelerometer.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from hopkinson.analysis.errors import AnalysisError
from hopkinson.analysis.identify import remove_input_delay
from hopkinson.analysis.resample import resample_to_rate
from hopkinson.analysis.shot_analysis import ShotAnalysis

G_M_S2 = 9.80665  # standard gravity: accelerations are also shown in g


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
    pairs = [m for m in modes if m.get("kind", "pair") in ("complex", "pair") and m.get("natural_frequency_hz")]
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
