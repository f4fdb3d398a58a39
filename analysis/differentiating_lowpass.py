"""Velocity and acceleration from the beat's phase (step 4 of analysis/doppler.py's method): the
displacement brought to the analysis rate, then differentiated by a differentiating low-pass
(a Kaiser-windowed low-pass L convolved with a Kaiser-windowed ideal differentiator), whose L a
companion channel gets through `lowpass`."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import signal

from hopkinson.analysis.beat_phase import BeatPhase
from hopkinson.analysis.errors import AnalysisError
from hopkinson.analysis.records import Record
from hopkinson.analysis.resample import resample_to_rate

BANDWIDTH_RISE_PRODUCT = 5.0  # B = this / (10–90 % rise time of the velocity)
MAX_BANDWIDTH_FRACTION = 0.4  # B ≤ this × the analysis rate (the low-pass must fit below Nyquist)
STOPBAND_ATTENUATION_DB = 80.0  # of the low-pass L


@dataclass(frozen=True)
class Demodulated:
    """Velocity and acceleration of the grating at the analysis rate."""

    sample_interval_s: float
    start_time_s: float
    velocity_m_s: np.ndarray
    acceleration_m_s2: np.ndarray
    bandwidth_hz: float  # −6 dB bandwidth of the differentiating low-pass
    beat: BeatPhase | None  # None: the phase came from elsewhere (a quadrature interferometer)

    @property
    def time_s(self) -> np.ndarray:
        return self.start_time_s + self.sample_interval_s * np.arange(self.velocity_m_s.size)


def bandwidth_for_rise_time(rise_time_s: float, sample_rate_hz: float) -> float:
    """Bandwidth B (Hz) of the differentiating low-pass for a velocity rising in `rise_time_s`.

    B = BANDWIDTH_RISE_PRODUCT / t_rise (10–90 %), capped at MAX_BANDWIDTH_FRACTION of the rate.
    For a half-sine of width δ, t_rise = 0.59·δ and B ≈ 8.5/δ: there the envelope of the
    pulse's spectrum, 1/(4(fδ)²), is 0.35 % of its DC value, so the low-pass changes the peak by
    < 0.05 % and the 10 %-width by < 0.5 %, while passing 8.5× less noise bandwidth than Nyquist.
    """
    if not rise_time_s > 0:
        raise AnalysisError(f"velocity rise time must be positive, got {rise_time_s!r} s")
    return float(min(BANDWIDTH_RISE_PRODUCT / rise_time_s, MAX_BANDWIDTH_FRACTION * sample_rate_hz))


def lowpass_taps(bandwidth_hz: float, sample_rate_hz: float) -> np.ndarray:
    """Odd-length linear-phase low-pass L: −6 dB at `bandwidth_hz`, transition ±B/4, 80 dB stopband."""
    nyquist = 0.5 * sample_rate_hz
    if not 0 < bandwidth_hz <= MAX_BANDWIDTH_FRACTION * sample_rate_hz * (1 + 1e-9):
        raise AnalysisError(
            f"bandwidth {bandwidth_hz:g} Hz must be positive and ≤ {MAX_BANDWIDTH_FRACTION:g} × the "
            f"analysis rate ({MAX_BANDWIDTH_FRACTION * sample_rate_hz:g} Hz)"
        )
    numtaps, beta = signal.kaiserord(STOPBAND_ATTENUATION_DB, 0.5 * bandwidth_hz / nyquist)
    numtaps |= 1
    return signal.firwin(numtaps, bandwidth_hz, window=("kaiser", beta), fs=sample_rate_hz)


def ideal_derivative_taps(sample_rate_hz: float, half_length: int = 100) -> np.ndarray:
    """Kaiser-windowed (β = 14) ideal differentiator (−1)ᵐ/m, per second, normalised so that it
    differentiates a ramp exactly; its gain is j2πf to 4·10⁻⁶ up to 0.8 × Nyquist (the window's
    side lobes set that: β = 8 over 81 taps leaves a 1.4·10⁻³ gain error in the whole band)."""
    k = np.arange(-half_length, half_length + 1)
    g = np.zeros(k.size)
    nz = k != 0
    g[nz] = np.cos(np.pi * k[nz]) / k[nz]
    g *= signal.windows.kaiser(k.size, 14.0)
    g /= -np.sum(k * g)
    return g * sample_rate_hz


def derivative_taps(bandwidth_hz: float, sample_rate_hz: float) -> np.ndarray:
    """Differentiating low-pass D = L ∗ g (per second): in L's band D equals j2πf·L to 10⁻⁵."""
    return np.convolve(lowpass_taps(bandwidth_hz, sample_rate_hz), ideal_derivative_taps(sample_rate_hz))


def apply_zero_phase(x: np.ndarray, taps: np.ndarray) -> np.ndarray:
    """Convolve with an odd-length symmetric/antisymmetric FIR, centred (no delay); the ends are
    extended by odd reflection, which continues a constant or a ramp without a jump."""
    x = np.asarray(x, dtype=float)
    half = taps.size // 2
    pad = min(half, x.size - 1)
    ext = np.pad(x, pad, mode="reflect", reflect_type="odd")
    if pad < half:
        ext = np.pad(ext, half - pad, mode="edge")
    return signal.oaconvolve(ext, taps, mode="valid")


def lowpass(x: np.ndarray, bandwidth_hz: float, sample_rate_hz: float) -> np.ndarray:
    """The low-pass L of the differentiating filter applied (zero-phase) to a companion channel."""
    return apply_zero_phase(x, lowpass_taps(bandwidth_hz, sample_rate_hz))


def rise_time_s(velocity: np.ndarray, sample_interval_s: float) -> float:
    """10–90 % rise time of a velocity rising from rest to its peak (linear interpolation)."""
    v = np.asarray(velocity, dtype=float)
    peak_index = int(np.argmax(v))
    peak = v[peak_index]
    if not peak > 0:
        raise AnalysisError("velocity never rises above zero: no motion found")
    t10 = _last_crossing_before(v, 0.1 * peak, peak_index)
    t90 = _last_crossing_before(v, 0.9 * peak, peak_index)
    return max((t90 - t10) * sample_interval_s, sample_interval_s)


def _last_crossing_before(v: np.ndarray, level: float, end: int) -> float:
    below = np.flatnonzero(v[: end + 1] < level)
    if below.size == 0:
        return 0.0
    i = int(below[-1])
    return i + (level - v[i]) / (v[i + 1] - v[i])


def displacement_to_rate(displacement_m: np.ndarray, companion: np.ndarray, sample_interval_s: float,
                         start_time_s: float, rate_hz: float) -> Record:
    """Displacement (as `reference`) and a companion channel (as `response`) brought to
    `rate_hz` together by `analysis.resample.resample_to_rate` (one anti-alias filter).

    The displacement is at rest at the start and in flight (a ramp) at the end; the resampler
    detrends by the straight line through the end points, which leaves a kink at each end
    that would ring into the record. So both ends are first extended the way the motion
    continues (constant before, the final slope after; the companion by its end values) and
    the extension is cut off again afterwards.
    """
    x = np.asarray(displacement_m, dtype=float)
    c = np.asarray(companion, dtype=float)
    pad = 400  # samples at the input rate: longer than resample_poly's filter reaches
    tail = min(pad, x.size - 1)
    slope = (x[-1] - x[-1 - tail]) / tail
    x_ext = np.concatenate([np.full(pad, x[0]), x, x[-1] + slope * np.arange(1, pad + 1)])
    c_ext = np.concatenate([np.full(pad, c[0]), c, np.full(pad, c[-1])])
    extended = Record(sample_interval_s, x_ext, c_ext, start_time_s - pad * sample_interval_s)
    out = resample_to_rate(extended, rate_hz)
    if out is extended:
        return Record(sample_interval_s, x, c, start_time_s)
    ratio = sample_interval_s / out.sample_interval_s  # output samples per input sample
    cut = int(np.ceil(pad * ratio))
    keep = slice(cut, out.n_samples - cut)
    return Record(out.sample_interval_s, out.reference[keep], out.response[keep],
                  out.start_time_s + cut * out.sample_interval_s)


def differentiate(displacement_m: np.ndarray, sample_interval_s: float, start_time_s: float,
                  beat: BeatPhase | None, bandwidth_hz: float | None = None) -> Demodulated:
    """Velocity and acceleration from displacement at the analysis rate by the differentiating
    low-pass; bandwidth chosen from the pulse when None."""
    rate = 1.0 / sample_interval_s
    if bandwidth_hz is None:
        widest = MAX_BANDWIDTH_FRACTION * rate
        first = apply_zero_phase(displacement_m, derivative_taps(widest, rate))
        bandwidth_hz = bandwidth_for_rise_time(rise_time_s(first, sample_interval_s), rate)
    d = derivative_taps(bandwidth_hz, rate)
    velocity = apply_zero_phase(displacement_m, d)
    # The velocity is already band-limited by L: a plain (wide-band) differentiator is exact on
    # it, so the acceleration is L applied to the true acceleration.
    acceleration = apply_zero_phase(velocity, ideal_derivative_taps(rate))
    return Demodulated(sample_interval_s, start_time_s, velocity, acceleration, float(bandwidth_hz), beat)
