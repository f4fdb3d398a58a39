"""Bring a record to the analysis rate and align its channels.

- `resample_to_rate`: anti-alias low-pass and resample a record sampled faster than the
  analysis rate (default 1 MS/s) with scipy.signal.resample_poly (linear-phase FIR whose
  delay resample_poly removes, so the result is zero-phase and stays aligned in time).
- `estimate_delay_samples`: delay of one channel against another from the peak of their
  cross-correlation (one dot product per lag, or by FFT for many lags), refined to a fraction of a sample.
- `shift_samples`: fractional delay of a sampled signal (band-limited, by FFT phase).
"""

from __future__ import annotations

import math
from fractions import Fraction

import numpy as np
from numpy import fft

from hopkinson.analysis.errors import AnalysisError
from hopkinson.analysis.numerics import next_fast_len
from hopkinson.analysis.options import DEFAULT_ANALYSIS_RATE_HZ
from hopkinson.analysis.records import Record

# Largest denominator of the rational resampling ratio: keeps the polyphase filter small
# while the achieved rate stays within ~0.1 % of the one asked for any sane pair of rates.
_MAX_RATIO_DENOMINATOR = 1000


def resampling_factors(source_rate_hz: float, target_rate_hz: float) -> tuple[int, int]:
    """(up, down) with up/down the rational approximation of target/source (both in Hz)."""
    if not (source_rate_hz > 0 and target_rate_hz > 0):
        raise AnalysisError(f"sample rates must be positive (source {source_rate_hz} Hz, target {target_rate_hz} Hz)")
    ratio = Fraction(target_rate_hz / source_rate_hz).limit_denominator(_MAX_RATIO_DENOMINATOR)
    if ratio.numerator == 0:
        raise AnalysisError(
            f"analysis rate {target_rate_hz:g} Hz is too far below the record's {source_rate_hz:g} Hz "
            f"(ratio below 1/{_MAX_RATIO_DENOMINATOR})"
        )
    return ratio.numerator, ratio.denominator


def resample_to_rate(record: Record, sample_rate_hz: float = DEFAULT_ANALYSIS_RATE_HZ) -> Record:
    """Low-pass and resample `record` to `sample_rate_hz` when it is sampled faster.

    A record already at or below the rate (within 0.1 %) is returned unchanged (the same
    object: `resampled is record` tells the caller nothing was done). Otherwise the rate
    becomes source·up/down, the rational approximation of the rate asked for; the first
    sample keeps its time. The anti-alias filter is resample_poly's Kaiser-windowed FIR
    (cut-off at the new Nyquist frequency); the edges are padded by a straight line so a
    constant offset (zero shift of the response) does not ring at the ends.
    """
    source_hz = record.sample_rate_hz
    if not sample_rate_hz > 0:
        raise AnalysisError(f"analysis sample rate must be positive, got {sample_rate_hz!r} Hz")
    if source_hz <= sample_rate_hz * (1 + 1e-3):
        return record
    from scipy import signal  # loaded only when a record is resampled

    up, down = resampling_factors(source_hz, sample_rate_hz)
    reference = signal.resample_poly(record.reference, up, down, padtype="line")
    response = signal.resample_poly(record.response, up, down, padtype="line")
    if reference.size < 16:
        raise AnalysisError(
            f"record of {record.n_samples} samples at {source_hz:g} Hz leaves only {reference.size} "
            f"samples at {sample_rate_hz:g} Hz"
        )
    return Record(record.sample_interval_s * down / up, reference, response, record.start_time_s)


def estimate_delay_samples(reference: np.ndarray, response: np.ndarray, max_lag: int) -> float:
    """Delay of `response` behind `reference`, in samples (negative: response leads).

    The lag of the largest |cross-correlation| within ±max_lag (a response of either sign
    is aligned), refined by a parabola through the peak and its two neighbours. Each channel's
    baseline (median) is removed first. For a dynamic system the result includes its group
    delay; it is meant for aligning channels, not for a model's pure delay.
    """
    ref = np.asarray(reference, dtype=float).ravel()
    resp = np.asarray(response, dtype=float).ravel()
    if ref.size < 2 or resp.size < 2:
        raise AnalysisError("delay estimate needs at least two samples per channel")
    if max_lag < 1:
        raise AnalysisError(f"max_lag must be at least 1, got {max_lag}")
    if not (np.all(np.isfinite(ref)) and np.all(np.isfinite(resp))):
        raise AnalysisError("delay estimate: a channel has a NaN or infinite value")
    ref = ref - np.median(ref)
    resp = resp - np.median(resp)
    lags = np.arange(-max_lag, max_lag + 1)
    corr = _correlation_at_lags(ref, resp, lags)
    if not np.any(corr):
        raise AnalysisError("delay estimate: the channels do not correlate (a flat channel?)")
    i = int(np.argmax(np.abs(corr)))
    c = corr * np.sign(corr[i])
    if 0 < i < c.size - 1:
        left, mid, right = c[i - 1], c[i], c[i + 1]
        curvature = left - 2 * mid + right
        offset = 0.5 * (left - right) / curvature if curvature < 0 else 0.0
        return float(lags[i] + np.clip(offset, -0.5, 0.5))
    return float(lags[i])


def _correlation_at_lags(ref: np.ndarray, resp: np.ndarray, lags: np.ndarray) -> np.ndarray:
    """c[m] = Σ_k resp[k + m]·ref[k] at each lag m (the overlap only: no circular wrap).

    Written here because numpy.correlate and scipy.signal.correlate give every lag or none: for
    the few lags an alignment asks (±32 … ±100 samples of a 10⁵–10⁶-sample record) one dot
    product per lag costs a fifth of the three full-length FFTs, which win only beyond about
    8·log2(length) lags (measured: 2·10⁵ samples, ±64 lags, 0.02 against 0.09 s)."""
    size = next_fast_len(ref.size + resp.size)
    if lags.size > 8 * math.log2(size):
        full = fft.irfft(fft.rfft(resp, size) * np.conj(fft.rfft(ref, size)), size)
        return full[lags % size]
    out = np.empty(lags.size)
    for j, m in enumerate(lags.tolist()):
        start = max(0, -m)  # first k with k + m ≥ 0
        stop = min(ref.size, resp.size - m)  # last k + 1 with k + m < len(resp)
        out[j] = np.dot(resp[start + m:stop + m], ref[start:stop]) if stop > start else 0.0
    return out


def shift_samples(x: np.ndarray, delay_samples: float) -> np.ndarray:
    """`x` delayed by `delay_samples` (may be fractional or negative): y[k] = x[k − delay].

    Integer delays are exact index shifts. A fractional delay is applied as a linear phase in
    the frequency domain (exact for a band-limited signal, unlike spline interpolation such as
    scipy.ndimage.shift, which attenuates near Nyquist) on an extension of the signal that
    continues each end smoothly (odd reflection, joined by a raised cosine), so neither the
    circular wrap nor a non-zero end rings. Samples shifted in from outside the record by the
    whole-sample part take the nearest edge value. Same length as `x`.
    """
    x = np.asarray(x, dtype=float).ravel()
    n = x.size
    if n == 0 or delay_samples == 0:
        return x.copy()
    whole = int(np.floor(delay_samples))
    frac = float(delay_samples - whole)
    y = x
    if frac > 1e-12:
        y = _fractional_shift(x, frac)
    if whole == 0:
        return np.array(y, copy=True)
    out = np.empty(n)
    if whole > 0:
        k = min(whole, n)
        out[:k] = y[0]
        out[k:] = y[: n - k]
    else:
        k = min(-whole, n)
        out[n - k :] = y[-1]
        out[: n - k] = y[k:]
    return out


def _fractional_shift(x: np.ndarray, frac: float) -> np.ndarray:
    """Delay by 0 < frac < 1 sample via FFT phase, on a smoothly periodic extension of x.

    Each end is continued by its odd reflection (value and slope continue), then the two
    continuations are joined by a raised cosine, so the circular signal has no jump or kink
    near the record and the phase shift does not ring into it.
    """
    n = x.size
    edge = min(n - 1, 64)
    padded = np.pad(x, edge, mode="reflect", reflect_type="odd") if edge > 0 else x
    ramp = 64
    w = 0.5 * (1 - np.cos(np.pi * np.arange(1, ramp + 1) / (ramp + 1)))
    join = padded[-1] + (padded[0] - padded[-1]) * w
    ext = np.concatenate([padded, join])
    m = next_fast_len(ext.size)
    if m > ext.size:
        ext = np.concatenate([ext, np.full(m - ext.size, padded[0])])
    spec = fft.rfft(ext)
    spec *= np.exp(-2j * np.pi * frac * np.arange(spec.size) / m)
    if m % 2 == 0:  # the Nyquist bin of a real signal must stay real
        spec[-1] = spec[-1].real * np.cos(np.pi * frac)
    return fft.irfft(spec, m)[edge : edge + n]
