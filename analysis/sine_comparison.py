"""A shock-identified model checked against a sinusoidal calibration (ISO 16063-11/-21) of the
same sensor, and what the DCM would make of the sensor the sine data describe.

The sine file is a CSV with a header: frequency_hz, magnitude, phase_deg, and optionally
u_magnitude_rel (relative standard uncertainty of the magnitude) and u_phase_deg. Magnitudes
are compared normalised at a reference frequency (default the lowest in the file; ISO
16063-21 calibrates at e.g. 160 Hz), so the units of the sine data do not matter; the ratio
of the absolute values is reported beside (meaningful when both are in the same units).

At each frequency:
- magnitude error = |H(f)|/|H(f_ref)| ÷ (sine(f)/sine(f_ref)) − 1 (per cent);
- phase error = arg H(f) − sine phase (degrees, wrapped to ±180), H the model's whole
  response, its fitted input delay τ included; the delay that best explains the phase error
  (least-squares slope through the origin) is reported beside it: the channel skew of the
  shock record (plus any phase error of the model), which a sine calibration of the sensor
  alone does not have. The whole phase is what the shock record determines: τ and B's zeros
  share a flat valley of the fit's cost, and where the pulse barely reaches the phase that
  tells them apart the fit puts a lag of a few samples in either (docs/decisions/0010).
  The phase without τ, which moves with that split, is kept beside it as `phase_error_without_delay_deg`, with τ as `fitted_delay_s`;
  it is not a measure of the model;
- consistent: |magnitude error| ≤ 2 × u (k = 2) when the file gives u, u the relative standard
  uncertainty of the NORMALISED point sine(f)/sine(f_ref): the point's stated u and the
  reference point's, combined as independent (the file states no correlation between points),
  √(u(f)² + u(f_ref)²); 0 at the reference point itself, which is 1 by construction. The
  normaliser is a measured point like any other: PTB's 0.5 % at 500 Hz counts in every ratio
  to it, which the 0.15 % stated at 5–10 kHz alone understates three-fold;
- compensated magnitude = sine(f) × |G(f)|, normalised at f_ref: how flat the DCM would make
  the sensor the sine calibration measured (its ±5 % / ±10 % band from the sine points,
  interpolated, as far as the points reach).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from hopkinson.analysis.errors import AnalysisError
from hopkinson.analysis.model import DiscreteModel
from hopkinson.analysis.records import parse_header_cell, read_table
from hopkinson.analysis.response import fbsd_from_response, frequency_response

if TYPE_CHECKING:  # only a caller's DCM is used (the DCM's module imports scipy.signal)
    from hopkinson.analysis.dcm import DCM

SINE_KEYS = ("frequency_hz", "magnitude", "phase_deg")
SINE_UNCERTAINTY_KEYS = ("u_magnitude_rel", "u_phase_deg")


@dataclass(frozen=True)
class SineCalibration:
    """The points of a sinusoidal calibration, sorted by frequency."""

    frequency_hz: np.ndarray
    magnitude: np.ndarray
    phase_deg: np.ndarray
    u_magnitude_rel: np.ndarray | None = None
    u_phase_deg: np.ndarray | None = None
    source: str = "sine calibration"


def read_sine_calibration(path: str | Path) -> SineCalibration:
    """Read the sine CSV (module docstring); one clear AnalysisError naming the file otherwise."""
    path = Path(path)
    try:
        with path.open(encoding="utf-8-sig") as fh:
            header = fh.readline(64 * 1024)
    except FileNotFoundError:
        raise AnalysisError(f"{path}: no such file") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise AnalysisError(f"{path}: cannot be read as a sine calibration CSV ({exc})") from None
    names = {parse_header_cell(cell)[0] for cell in header.strip().split(",")}
    optional = tuple(k for k in SINE_UNCERTAINTY_KEYS if k in names)
    table = read_table(path, SINE_KEYS + optional, what="sine calibration")
    columns = dict(zip(SINE_KEYS + optional, table.columns, strict=True))
    for key, values in columns.items():
        if not np.all(np.isfinite(values)):
            raise AnalysisError(f"{path}: column '{key}' has a NaN or infinite value")
    f = columns["frequency_hz"]
    if f.size < 1 or np.any(f <= 0):
        raise AnalysisError(f"{path}: frequencies must be positive (Hz)")
    if np.unique(f).size != f.size:
        raise AnalysisError(f"{path}: a frequency is listed twice")
    if np.any(columns["magnitude"] <= 0):
        raise AnalysisError(f"{path}: magnitudes must be positive")
    for key in optional:
        if np.any(columns[key] < 0):
            raise AnalysisError(f"{path}: {key} must not be negative")
    order = np.argsort(f)
    pick = {k: v[order] for k, v in columns.items()}
    return SineCalibration(pick["frequency_hz"], pick["magnitude"], pick["phase_deg"],
                           pick.get("u_magnitude_rel"), pick.get("u_phase_deg"), str(path))


@dataclass(frozen=True)
class SineComparison:
    """The model (and DCM) against the sine points; see the module docstring."""

    frequency_hz: np.ndarray
    reference_frequency_hz: float
    sine_magnitude: np.ndarray  # normalised at the reference frequency
    model_magnitude: np.ndarray  # normalised at the reference frequency
    magnitude_error_pct: np.ndarray
    phase_error_deg: np.ndarray  # the model's whole phase (fitted delay included) − sine phase
    phase_delay_s: float  # least-squares delay of phase_error_deg (the shock record's channel skew)
    consistent: np.ndarray | None  # |error| ≤ 2u per point, None without u
    compensated_magnitude: np.ndarray | None  # sine × |G|, normalised
    compensated_fbsd_hz: dict[str, float | None] | None
    sensitivity_ratio: float  # |H(f_ref)| / sine(f_ref): model over sine, same units assumed
    u_magnitude_rel: np.ndarray | None  # of the normalised sine point (module docstring), per point
    source: str
    phase_error_without_delay_deg: np.ndarray | None = None  # the model's phase less its fitted delay − sine phase
    fitted_delay_s: float = 0.0  # the model's input delay (how the fit split its lag; not well-determined)
    u_reference_rel: float | None = None  # the stated u of the sine at the reference frequency

    @property
    def max_magnitude_error_pct(self) -> float:
        return float(np.max(np.abs(self.magnitude_error_pct)))

    def max_magnitude_error_below_pct(self, frequency_hz: float) -> float | None:
        """Largest |magnitude error| at the points up to `frequency_hz` (None if there are none)."""
        pick = self.frequency_hz <= frequency_hz
        return float(np.max(np.abs(self.magnitude_error_pct[pick]))) if np.any(pick) else None

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready (`hopkinson compare-sine --json`, a campaign report)."""
        def floats(x: np.ndarray | None) -> list[float] | None:
            return None if x is None else [float(v) for v in x]

        return {
            "source": self.source,
            "reference_frequency_hz": self.reference_frequency_hz,
            "frequency_hz": floats(self.frequency_hz),
            "sine_magnitude": floats(self.sine_magnitude),
            "model_magnitude": floats(self.model_magnitude),
            "magnitude_error_pct": floats(self.magnitude_error_pct),
            "phase_error_deg": floats(self.phase_error_deg),
            "phase_delay_s": self.phase_delay_s,
            "phase_error_without_delay_deg": floats(self.phase_error_without_delay_deg),
            "fitted_delay_s": self.fitted_delay_s,
            "u_magnitude_rel": floats(self.u_magnitude_rel),
            "u_reference_rel": self.u_reference_rel,
            "consistent": None if self.consistent is None else [bool(v) for v in self.consistent],
            "compensated_magnitude": floats(self.compensated_magnitude),
            "compensated_fbsd_hz": self.compensated_fbsd_hz,
            "sensitivity_ratio": self.sensitivity_ratio,
            "max_magnitude_error_pct": self.max_magnitude_error_pct,
        }


def compare_sine(model: DiscreteModel, sine: SineCalibration, dcm: DCM | None = None,
                 reference_frequency_hz: float | None = None) -> SineComparison:
    """Compare the model (and the DCM applied to the sine-measured sensor) with the sine points."""
    f = sine.frequency_hz
    nyquist = 0.5 / model.sample_interval_s
    if np.any(f >= nyquist):
        raise AnalysisError(f"{sine.source}: points at or above the model's Nyquist frequency ({nyquist:g} Hz)")
    f_ref = float(f[0]) if reference_frequency_hz is None else float(reference_frequency_hz)
    if not (math.isfinite(f_ref) and f_ref > 0):
        raise AnalysisError(f"reference frequency must be a positive number of Hz, got {reference_frequency_hz}")
    sine_ref = float(np.interp(f_ref, f, sine.magnitude)) if f[0] <= f_ref <= f[-1] else None
    if sine_ref is None:
        raise AnalysisError(f"{sine.source}: the reference frequency {f_ref:g} Hz lies outside the points "
                            f"({f[0]:g} … {f[-1]:g} Hz)")
    h = frequency_response(model, np.concatenate([[f_ref], f]))
    h_ref, h = h[0], h[1:]
    if h_ref == 0:
        raise AnalysisError("the model's response is zero at the reference frequency")
    sine_norm = sine.magnitude / sine_ref
    model_norm = np.abs(h) / abs(h_ref)
    error = 100.0 * (model_norm / sine_norm - 1.0)
    w = 2 * np.pi * f
    fitted_delay_s = float(model.delay_samples) * model.sample_interval_s
    without_delay = (np.degrees(np.angle(h)) - sine.phase_deg + 180.0) % 360.0 - 180.0
    phase_error = (without_delay - np.degrees(w * fitted_delay_s) + 180.0) % 360.0 - 180.0
    delay = float(-np.dot(w, np.radians(phase_error)) / np.dot(w, w))
    u_ref, u_norm = _normalised_u(sine, f_ref)
    # (+1e-9 %: the reference point's error is 0 but for rounding, and so is its u)
    consistent = None if u_norm is None else np.abs(error) <= 2 * 100.0 * u_norm + 1e-9
    compensated = band = None
    if dcm is not None:
        if abs(dcm.sample_interval_s - model.sample_interval_s) > 1e-9 * model.sample_interval_s:
            raise AnalysisError("the DCM and the model have different sample intervals")
        g = dcm.frequency_response(np.concatenate([[f_ref], f]))
        compensated = sine_norm * np.abs(g[1:]) / abs(g[0])
        band = _band_of_points(f, compensated)
    return SineComparison(f, f_ref, sine_norm, model_norm, error, phase_error, delay, consistent, compensated,
                          band, float(abs(h_ref) / sine_ref), u_norm, sine.source, without_delay,
                          fitted_delay_s, u_ref)


def _normalised_u(sine: SineCalibration, f_ref_hz: float) -> tuple[float | None, np.ndarray | None]:
    """(the stated u at the reference frequency, the u of each normalised point); see the module
    docstring. Between two points the reference's u is interpolated."""
    if sine.u_magnitude_rel is None:
        return None, None
    u = np.asarray(sine.u_magnitude_rel, dtype=float)
    u_ref = float(np.interp(f_ref_hz, sine.frequency_hz, u))
    u_norm = np.where(sine.frequency_hz == f_ref_hz, 0.0, np.hypot(u, u_ref))
    return u_ref, u_norm


def _band_of_points(f: np.ndarray, magnitude: np.ndarray) -> dict[str, float | None] | None:
    """±5 % / ±10 % edges of sampled magnitudes (from the first point up); None for an edge the
    points never leave (it lies beyond the last point)."""
    if f.size < 2:
        return None
    try:
        edges = fbsd_from_response(f, magnitude)
    except AnalysisError:  # the first point already outside the band (normalised elsewhere)
        return None
    return {k: (e.frequency_hz if e.reached else None) for k, e in edges.items()}


def band_consistency(comparison: SineComparison, band: dict[str, Any]) -> dict[str, Any]:
    """The sine points against the model's 95 % response band (analysis.uncertainty.response_band,
    magnitudes relative to the DC gain, renormalised here at the comparison's reference
    frequency): per point the band's limits and E_n = |model − sine| / √(U_model² + U_sine²),
    U_model the band's half on the sine's side, U_sine = 2·u (k = 2), u the normalised point's
    (module docstring: the reference point's stated u included); E_n ≤ 1: consistent. Points
    outside the band's frequencies get None. Issue 17: the model's uncertainty, not only its
    value, is what a sine calibration can confirm."""
    f_band = np.asarray(band["frequency_hz"], dtype=float)
    f = comparison.frequency_hz
    inside = (f >= f_band[0]) & (f <= f_band[-1])

    def at(key: str, x: np.ndarray) -> np.ndarray:
        return np.interp(np.log(x), np.log(f_band), np.asarray(band[key], dtype=float))

    f_ref = np.clip(comparison.reference_frequency_hz, f_band[0], f_band[-1])
    norm = float(at("magnitude_rel", np.array([f_ref]))[0])
    value, low, high = (at(k, np.clip(f, f_band[0], f_band[-1])) / norm
                        for k in ("magnitude_rel", "magnitude_rel_low", "magnitude_rel_high"))
    sine = comparison.sine_magnitude
    u_model = np.where(sine >= value, high - value, value - low)
    u_sine = (np.zeros_like(sine) if comparison.u_magnitude_rel is None
              else 2.0 * comparison.u_magnitude_rel * sine)
    e_n = np.abs(value - sine) / np.maximum(np.hypot(u_model, u_sine), 1e-300)

    def listed(x: np.ndarray) -> list[float | None]:
        return [float(v) if ok else None for v, ok in zip(x, inside, strict=True)]

    worst = float(np.max(e_n[inside])) if np.any(inside) else None
    return {"band_low": listed(low), "band_high": listed(high), "e_n": listed(e_n), "max_e_n": worst,
            "consistent": None if worst is None else bool(worst <= 1.0),
            "coverage_probability": band.get("coverage_probability")}
