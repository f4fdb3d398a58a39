"""The noise of a channel, measured where the channel carries no signal, as a spectrum.

Both channels of a shock record are noisy: the response (sensor, amplifier, digitizer) and
the reference (for an interferometer, phase noise differentiated twice: it rises with
frequency up to the demodulation low-pass; for a reference accelerometer, its own noise).
The identification weighs each frequency by the noise there (errors-in-variables), and the
uncertainty draws noise records with these spectra, so a single RMS is not enough.

- `quiet_segments`: the stretches of a record before the pulse and after the signal has
  died away (the response's ringing below a few noise RMS).
- `NoiseSpectrum.measure`: Welch's averaged periodogram (`welch`, linear detrend per segment,
  so a slow drift does not pass for noise) over those stretches; where they
  disagree (an interferometer is quiet at rest but noisy in flight) the larger level is kept.
- `NoiseSpectrum.bin_variance`: E|N_k|² of the DFT N_k = Σ n(t)·e^{−jω_k t} of a window of
  L samples: L·S(f_k)·f_s/2 with S the one-sided PSD.
- `NoiseSpectrum.draw`: noise records with the measured spectrum (white Gaussian noise shaped
  in the frequency domain).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy import fft

# Shortest quiet stretch worth a spectrum, and the Welch segment length (frequency resolution
# f_s / WELCH_SEGMENT: 4 kHz at 1 MS/s); at most MAX_QUIET_SAMPLES of a stretch are used (the
# spectrum's scatter is then ~3 %: more adds time, not knowledge).
MIN_QUIET_SAMPLES = 32
WELCH_SEGMENT = 256
MAX_QUIET_SAMPLES = 32_768


def welch(x: np.ndarray, sample_rate_hz: float, segment: int) -> tuple[np.ndarray, np.ndarray]:
    """One-sided PSD by Welch's method: Hann-windowed segments, half overlapping, each with its
    least-squares line removed (a drift is not noise); the DC bin, which that empties, takes its
    neighbour's level. Written out with NumPy because scipy.signal.welch (ShortTimeFFT since
    SciPy 1.15) costs tens of milliseconds per call on these short records, NumPy ~1 ms."""
    x = np.asarray(x, dtype=float)
    segment = max(4, min(segment, x.size))
    segment -= segment % 2
    step = max(1, segment // 2)
    starts = np.arange(0, x.size - segment + 1, step)
    blocks = x[starts[:, None] + np.arange(segment)[None, :]]
    t = np.arange(segment) - (segment - 1) / 2.0
    blocks = blocks - blocks.mean(axis=1, keepdims=True)
    blocks = blocks - np.outer(blocks @ t / (t @ t), t)
    window = 0.5 - 0.5 * np.cos(2.0 * np.pi * np.arange(segment) / segment)  # periodic Hann
    spectra = np.abs(fft.rfft(blocks * window, axis=1)) ** 2
    psd = spectra.mean(axis=0) / (sample_rate_hz * float(window @ window))
    psd[1:-1] *= 2.0  # one-sided (the segment is even: DC and Nyquist once)
    if psd.size > 1:
        psd[0] = psd[1]
    return fft.rfftfreq(segment, 1.0 / sample_rate_hz), psd


@dataclass(frozen=True)
class NoiseSpectrum:
    """One-sided noise PSD (channel units²/Hz) on `frequency_hz`, and where it came from."""

    frequency_hz: np.ndarray
    psd: np.ndarray
    sample_rate_hz: float
    samples: int  # quiet samples it was estimated from (0: not measured)
    source: str  # "quiet segments", "residual", "none"

    @property
    def rms(self) -> float:
        """Standard deviation of the noise (∫ S df)."""
        if self.frequency_hz.size < 2:
            return float(np.sqrt(max(self.psd[0], 0.0) * self.sample_rate_hz / 2)) if self.psd.size else 0.0
        return float(np.sqrt(max(np.trapezoid(self.psd, self.frequency_hz), 0.0)))

    def at(self, frequency_hz: np.ndarray) -> np.ndarray:
        """The one-sided PSD at arbitrary frequencies (linear interpolation, ends held)."""
        return np.interp(np.abs(frequency_hz), self.frequency_hz, self.psd)

    def bin_variance(self, frequency_hz: np.ndarray, window_samples: int) -> np.ndarray:
        """E|N_k|² of the unnormalised DFT of `window_samples` samples of this noise."""
        return window_samples * self.at(frequency_hz) * self.sample_rate_hz / 2.0

    def scaled(self, factor: float) -> NoiseSpectrum:
        """The same spectrum for the channel multiplied by `factor` (PSD by factor²)."""
        return NoiseSpectrum(self.frequency_hz, self.psd * factor * factor, self.sample_rate_hz, self.samples,
                             self.source)

    def draw(self, n: int, rng: np.random.Generator, count: int | None = None) -> np.ndarray:
        """Noise records of `n` samples with this spectrum: shape (n,) or (count, n)."""
        shape = (n,) if count is None else (count, n)
        white = rng.standard_normal(shape)
        if not np.any(self.psd > 0):
            return np.zeros(shape)
        spec = fft.rfft(white, axis=-1)
        f = fft.rfftfreq(n, 1.0 / self.sample_rate_hz)
        spec *= np.sqrt(self.at(f) * self.sample_rate_hz / 2.0)
        return fft.irfft(spec, n, axis=-1)

    @classmethod
    def white(cls, rms: float, sample_rate_hz: float, source: str, samples: int = 0) -> NoiseSpectrum:
        """Flat spectrum of standard deviation `rms`."""
        level = 2.0 * rms * rms / sample_rate_hz
        return cls(np.array([0.0, sample_rate_hz / 2]), np.array([level, level]), sample_rate_hz, samples, source)

    @classmethod
    def measure(cls, x: np.ndarray, sample_rate_hz: float, segments: Sequence[slice]) -> NoiseSpectrum:
        """Welch spectrum over the quiet `segments` of `x`.

        The stretch at the record's start (before any activity) and the others (after the pulse,
        between the pulses of a train) are averaged apart, each weighted by length, and the
        larger level is kept where they disagree: an interferometer is quiet at rest (no beat,
        no phase noise) but noisy in flight, and the flight is what the pulse sees. Segments
        shorter than MIN_QUIET_SAMPLES are skipped, and at most MAX_QUIET_SAMPLES are used per
        group; with none left the spectrum is zero and `samples` is 0."""
        x = np.asarray(x, dtype=float)
        groups: dict[bool, list[tuple[np.ndarray, np.ndarray, int]]] = {True: [], False: []}
        budget = {True: MAX_QUIET_SAMPLES, False: MAX_QUIET_SAMPLES}
        used = 0
        for seg in segments:
            piece = x[seg]
            lead = seg.start == 0
            take = min(piece.size, budget[lead])
            if take < MIN_QUIET_SAMPLES:
                continue
            f, p = welch(piece[-take:], sample_rate_hz, min(WELCH_SEGMENT, take))
            groups[lead].append((f, p, take))
            budget[lead] -= take
            used += take
        spectra = [s for s in groups.values() if s]
        if not spectra:
            return cls(np.array([0.0, sample_rate_hz / 2]), np.zeros(2), sample_rate_hz, 0, "none")
        grid = max((f for group in spectra for f, _, _ in group), key=lambda f: f.size)
        levels = [sum(np.interp(grid, f, p) * w for f, p, w in group) / sum(w for _, _, w in group)
                  for group in spectra]
        return cls(grid, np.max(levels, axis=0), sample_rate_hz, used, "quiet segments")
