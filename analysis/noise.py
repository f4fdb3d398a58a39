"""The noise of a channel, measured where the channel carries no signal, as a spectrum.

Both channels of a shock record are noisy: the response (sensor, amplifier, digitizer) and
the reference (for an interferometer, phase noise differentiated twice: it rises with
frequency up to the demodulation low-pass; for a reference accelerometer, its own noise).
The identification weighs each frequency by the noise there (errors-in-variables), and the
uncertainty draws noise records with these spectra, so a single RMS is not enough.

- `quiet_segments`: the stretches of a record before the pulse and after the signal has
  died away (the response's ringing below a few noise RMS).
- `NoiseSpectrum.measure`: Welch's averaged periodogram (`welch`) over those stretches, the
  record's baseline and drift line having been removed first (analysis.identify), so no
  segment is detrended again: that would empty the lowest bins, where the DC gain is decided.
  The stretch before the pulse and those after it are pooled unless their levels differ
  beyond chance (an interferometer is quiet at rest but noisy in flight): then the louder is
  kept.
- `NoiseSpectrum.bin_variance`: E|N_k|² of the DFT N_k = Σ n(t)·e^{−jω_k t} of a window of
  L samples: L·S(f_k)·f_s/2 with S the one-sided PSD.
- `NoiseSpectrum.draw`: noise records with the measured spectrum (white Gaussian noise shaped
  in the frequency domain).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from itertools import pairwise

import numpy as np
from numpy import fft

# Shortest quiet stretch worth a spectrum, and the longest Welch segment (frequency resolution
# f_s / WELCH_SEGMENT: 4 kHz at 1 MS/s); at most MAX_QUIET_SAMPLES of a stretch are used (the
# spectrum's scatter is then ~3 %: more adds time, not knowledge).
MIN_QUIET_SAMPLES = 32
WELCH_SEGMENT = 256
MAX_QUIET_SAMPLES = 32_768
# Segments are made shorter (coarser in frequency, down to MIN_QUIET_SAMPLES) until the quiet
# samples give about this many half-overlapping segments: with 3 (500 quiet samples in 256-
# sample segments) each frequency's level scattered by ±60 %, and an interval resting on a
# few bins' levels was too narrow as often as not.
MIN_WELCH_AVERAGES = 16
# Equivalent degrees of freedom of a Welch average of K Hann segments at 50 % overlap:
# 2K / (1 + 2·0.167²) for large K (Percival & Walden 1993, §6.17).
HANN_OVERLAP_DOF = 2.0 / (1.0 + 2.0 * 0.167**2)


def welch(x: np.ndarray, sample_rate_hz: float, segment: int, detrend: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """One-sided PSD by Welch's method: Hann-windowed segments, half overlapping. Not detrended
    by default (the caller removes the record's baseline and drift: removing each segment's
    own mean and line as well takes the noise's own low-frequency content with it, −29 % at
    the first bin for white noise, and the lowest fitted bins decide the DC gain); `detrend`
    removes each segment's line (the conservative look, see NoiseSpectrum.measure). Written
    out with NumPy because scipy.signal.welch (ShortTimeFFT since SciPy 1.15) costs tens of
    milliseconds per call on these short records, NumPy ~1 ms."""
    x = np.asarray(x, dtype=float)
    segment = max(4, min(segment, x.size))
    segment -= segment % 2
    step = max(1, segment // 2)
    starts = np.arange(0, x.size - segment + 1, step)
    blocks = x[starts[:, None] + np.arange(segment)[None, :]]
    if detrend:
        t = np.arange(segment) - (segment - 1) / 2.0
        blocks = blocks - blocks.mean(axis=1, keepdims=True)
        blocks = blocks - np.outer(blocks @ t / (t @ t), t)
    window = 0.5 - 0.5 * np.cos(2.0 * np.pi * np.arange(segment) / segment)  # periodic Hann
    spectra = np.abs(fft.rfft(blocks * window, axis=1)) ** 2
    psd = spectra.mean(axis=0) / (sample_rate_hz * float(window @ window))
    psd[1:-1] *= 2.0  # one-sided (the segment is even: DC and Nyquist once)
    if psd.size > 1:  # the DC bin measures the segments' means, which the baseline and drift took
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
    dof: float = math.inf  # equivalent degrees of freedom of each frequency's level (inf: taken as known)

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
                             self.source, self.dof)

    def level_factors(self, frequency_hz: np.ndarray, rng: np.random.Generator, count: int | None = None
                      ) -> np.ndarray:
        """Draws of the true level over the measured one at `frequency_hz`: ν/χ²_ν at each
        frequency of the spectrum (ν = `dof`; independent from one to the next), interpolated.
        The level is itself estimated from a few quiet samples; drawing it as well (GUM-S1
        6.4.9: the variance of a Type A quantity from ν degrees of freedom) turns each
        figure's PDF into the Student-t-like one an estimated noise level calls for. Ones when
        the level is taken as known. Shape (len(frequency_hz),) or (count, len(...))."""
        shape = (self.frequency_hz.size,) if count is None else (count, self.frequency_hz.size)
        if not math.isfinite(self.dof):
            return np.ones(shape[:-1] + (np.size(frequency_hz),))
        factors = self.dof / rng.chisquare(self.dof, shape)
        f = np.abs(np.asarray(frequency_hz, dtype=float))
        if count is None:
            return np.interp(f, self.frequency_hz, factors)
        return np.array([np.interp(f, self.frequency_hz, row) for row in factors])

    def draw(self, n: int, rng: np.random.Generator, count: int | None = None, *, uncertain_level: bool = False
             ) -> np.ndarray:
        """Noise records of `n` samples with this spectrum: shape (n,) or (count, n).
        `uncertain_level`: each record's spectrum drawn as well (`level_factors`)."""
        shape = (n,) if count is None else (count, n)
        white = rng.standard_normal(shape)
        if not np.any(self.psd > 0):
            return np.zeros(shape)
        spec = fft.rfft(white, axis=-1)
        f = fft.rfftfreq(n, 1.0 / self.sample_rate_hz)
        level = self.at(f) * self.sample_rate_hz / 2.0
        if uncertain_level:
            level = level * self.level_factors(f, rng, count)
        spec *= np.sqrt(level)
        return fft.irfft(spec, n, axis=-1)

    def lower_of(self, other: NoiseSpectrum) -> NoiseSpectrum:
        """Frequency by frequency the lower of this spectrum and `other` (on this one's grid)."""
        return NoiseSpectrum(self.frequency_hz, np.minimum(self.psd, other.at(self.frequency_hz)), self.sample_rate_hz,
                             self.samples, self.source, self.dof)

    @classmethod
    def white(cls, rms: float, sample_rate_hz: float, source: str, samples: int = 0) -> NoiseSpectrum:
        """Flat spectrum of standard deviation `rms`."""
        level = 2.0 * rms * rms / sample_rate_hz
        return cls(np.array([0.0, sample_rate_hz / 2]), np.array([level, level]), sample_rate_hz, samples, source)

    @classmethod
    def measure(cls, x: np.ndarray, sample_rate_hz: float, segments: Sequence[slice], *, conservative: bool = False
                ) -> NoiseSpectrum:
        """Welch spectrum over the quiet `segments` of `x`.

        `conservative`: the look the identification weighs its fit by (unchanged since the fit
        was validated with it): 256-sample segments each detrended, the two groups' larger
        level frequency by frequency. It errs high where a short stretch scatters and low in
        the lowest bins, so the uncertainty's draws use the unbiased look described next.

        The stretch at the record's start (before any activity) and the others (after the pulse,
        between the pulses of a train) are averaged apart, each weighted by length. Where their
        mean levels differ beyond chance (`_levels_differ`) the louder is kept: an
        interferometer is quiet at rest (no beat, no phase noise) but noisy in flight, and the
        flight is what the pulse sees. Otherwise they are pooled: the larger of two estimates of
        one level, taken frequency by frequency, is biased upwards (by ~16 % in RMS with a short
        lead-in). Segments shorter than MIN_QUIET_SAMPLES are skipped, and at most
        MAX_QUIET_SAMPLES are used per group; with none left the spectrum is zero and `samples`
        is 0. The segment length is the longest (up to WELCH_SEGMENT) that still gives about
        MIN_WELCH_AVERAGES segments; `dof` is the level's equivalent degrees of freedom."""
        x = np.asarray(x, dtype=float)
        pieces = _quiet_pieces(x, segments)
        if conservative:
            return cls._conservative(pieces, sample_rate_hz)
        if not pieces:
            return cls(np.array([0.0, sample_rate_hz / 2]), np.zeros(2), sample_rate_hz, 0, "none")
        used = sum(p.size for _, p in pieces)
        segment = int(np.clip(2 * used // (MIN_WELCH_AVERAGES + 1), MIN_QUIET_SAMPLES, WELCH_SEGMENT))
        groups: dict[bool, list[tuple[np.ndarray, np.ndarray, int, int]]] = {True: [], False: []}
        for lead, piece in pieces:
            f, p = welch(piece, sample_rate_hz, min(segment, piece.size))
            length = min(segment, piece.size) - min(segment, piece.size) % 2
            averages = (piece.size - length) // max(1, length // 2) + 1
            groups[lead].append((f, p, piece.size, averages))
        spectra = [s for s in groups.values() if s]
        grid = max((f for group in spectra for f, _, _, _ in group), key=lambda f: f.size)
        weights = [sum(w for _, _, w, _ in group) for group in spectra]
        dofs = [sum(max(2.0, k * HANN_OVERLAP_DOF) for _, _, _, k in group) for group in spectra]
        levels = [sum(np.interp(grid, f, p) * w for f, p, w, _ in group) / total
                  for group, total in zip(spectra, weights, strict=True)]
        if len(levels) == 1:
            psd, dof = levels[0], dofs[0]
        elif _levels_differ(float(np.mean(levels[0])), float(np.mean(levels[1])), dofs[0], dofs[1]):
            louder = int(np.argmax([float(np.mean(p)) for p in levels]))
            psd, dof = levels[louder], dofs[louder]
        else:
            psd = (levels[0] * weights[0] + levels[1] * weights[1]) / (weights[0] + weights[1])
            dof = dofs[0] + dofs[1]
        return cls(grid, psd, sample_rate_hz, used, "quiet segments", float(dof))

    @classmethod
    def _conservative(cls, pieces: list[tuple[bool, np.ndarray]], sample_rate_hz: float) -> NoiseSpectrum:
        """The fit's weighting look (see `measure`)."""
        groups: dict[bool, list[tuple[np.ndarray, np.ndarray, int]]] = {True: [], False: []}
        used = 0
        for lead, piece in pieces:
            f, p = welch(piece, sample_rate_hz, min(WELCH_SEGMENT, piece.size), detrend=True)
            groups[lead].append((f, p, piece.size))
            used += piece.size
        spectra = [s for s in groups.values() if s]
        if not spectra:
            return cls(np.array([0.0, sample_rate_hz / 2]), np.zeros(2), sample_rate_hz, 0, "none")
        grid = max((f for group in spectra for f, _, _ in group), key=lambda f: f.size)
        levels = [sum(np.interp(grid, f, p) * w for f, p, w in group) / sum(w for _, _, w in group)
                  for group in spectra]
        return cls(grid, np.max(levels, axis=0), sample_rate_hz, used, "quiet segments (conservative)")


def _quiet_pieces(x: np.ndarray, segments: Sequence[slice]) -> list[tuple[bool, np.ndarray]]:
    """(starts the record, samples) of each quiet stretch long enough for a spectrum: at most
    MAX_QUIET_SAMPLES per group (the lead-in; the rest), the latest samples of a stretch kept."""
    budget = {True: MAX_QUIET_SAMPLES, False: MAX_QUIET_SAMPLES}
    pieces: list[tuple[bool, np.ndarray]] = []
    for seg in segments:
        piece = x[seg]
        lead = seg.start == 0
        take = min(piece.size, budget[lead])
        if take < MIN_QUIET_SAMPLES:
            continue
        pieces.append((lead, piece[-take:]))
        budget[lead] -= take
    return pieces


def _levels_differ(p1: float, p2: float, dof1: float, dof2: float) -> bool:
    """Two mean noise levels, each from a Welch average of dof1 / dof2 degrees of freedom per
    frequency, differ beyond chance: |ln(p1/p2)| above four standard deviations of the log of
    such estimates (√(2/ν) each). Counting one frequency's degrees of freedom (not the band's)
    keeps a short lead-in of strongly coloured noise — a few independent samples — from
    passing for a different level; pooling such a stretch moves the level by its small weight
    only."""
    if p1 <= 0.0 or p2 <= 0.0:
        return p1 != p2
    return abs(math.log(p1 / p2)) > 4.0 * math.sqrt(2.0 / dof1 + 2.0 / dof2)


# Power-weighted magnitude-squared coherence above which a stretch after the pulse carries motion
# of the bar seen by both channels, not noise (docs/decisions/0012). Independent noise gives ≈ 1/K over K averaged segments; the threshold is also at least 4/K.
MOTION_COHERENCE = 0.25
COHERENCE_SEGMENT = 64


def coherence(x: np.ndarray, y: np.ndarray, sample_rate_hz: float, segment: int = COHERENCE_SEGMENT
              ) -> tuple[float, int]:
    """Magnitude-squared coherence of x and y weighted by their power, Σ|S_xy|² / Σ S_xx·S_yy
    over the frequencies above DC (Welch, Hann, half-overlapping, each segment's mean removed),
    and the number of segments averaged. Weighted by power, it reads the coherence where the
    channels carry something (motion lives at a few kHz, the rest of the band is noise); for
    independent noise it is ≈ 1/K."""
    x, y = np.asarray(x, dtype=float), np.asarray(y, dtype=float)
    segment = max(8, min(segment, x.size))
    segment -= segment % 2
    step = segment // 2
    starts = np.arange(0, x.size - segment + 1, step)
    window = 0.5 - 0.5 * np.cos(2.0 * np.pi * np.arange(segment) / segment)

    def spectra(z: np.ndarray) -> np.ndarray:
        blocks = z[starts[:, None] + np.arange(segment)[None, :]]
        return fft.rfft((blocks - blocks.mean(axis=1, keepdims=True)) * window, axis=1)

    fx, fy = spectra(x), spectra(y)
    sxy = np.abs(np.mean(fx * np.conj(fy), axis=0)) ** 2
    sxx, syy = np.mean(np.abs(fx) ** 2, axis=0), np.mean(np.abs(fy) ** 2, axis=0)
    power = sxx[1:] * syy[1:]
    if not np.any(power > 0):
        return 0.0, int(starts.size)
    return float(np.sum(sxy[1:]) / np.sum(power)), int(starts.size)


def is_motion(x: np.ndarray, y: np.ndarray, sample_rate_hz: float) -> tuple[bool, float]:
    """Whether a stretch both channels share is coherent motion rather than noise: (verdict,
    mean coherence). A stretch too short for 4 segments is not judged (False)."""
    if x.size < 2.5 * COHERENCE_SEGMENT:
        return False, math.nan
    msc, k = coherence(x, y, sample_rate_hz)
    return msc > _motion_threshold(k), msc


def _motion_threshold(segments: int) -> float:
    return max(MOTION_COHERENCE, 4.0 / segments)


# A tail whose coherence from the shared segments lies within this of its threshold is judged
# again by `is_motion` itself. The two sum the same products in another order: they differ by at
# most ~2·K·ε (K segments, ε = 2.2e-16), below 1e-10 for any record under 10⁸ samples.
_SCAN_MARGIN = 1e-8
# Segments transformed at once by `first_motion` (its memory: ~17 kB each).
_SCAN_CHUNK = 4096


def first_motion(x: np.ndarray, y: np.ndarray, sample_rate_hz: float, onsets: Sequence[int], stop: int
                 ) -> tuple[int, float] | None:
    """The first onset in `onsets` (increasing) from which x[onset:stop] and y[onset:stop] are
    motion by `is_motion`, with its coherence; None when no tail is. The same verdicts and
    coherence as `is_motion` on each tail in turn, in time linear in stop − onsets[0]: the
    Welch segments of every tail lie on one grid when the onsets are half-segments apart, so
    each segment is transformed once and each tail's averages are sums over the segments
    from its onset on (summed from the end). A tail near its threshold, and the one found,
    are judged by `is_motion` itself, so the verdicts and the coherence are exactly its."""
    onsets = [int(o) for o in onsets if int(stop) - int(o) >= 2.5 * COHERENCE_SEGMENT]
    if not onsets:
        return None
    step = COHERENCE_SEGMENT // 2
    if any((o - onsets[0]) % step for o in onsets) or any(b <= a for a, b in pairwise(onsets)):
        for onset in onsets:  # not on one grid: tail by tail
            verdict, msc = is_motion(x[onset:stop], y[onset:stop], sample_rate_hz)
            if verdict:
                return onset, msc
        return None
    shared, segments = _tail_coherences(x, y, onsets, stop)
    thresholds = np.maximum(MOTION_COHERENCE, 4.0 / segments)  # _motion_threshold of each tail
    for i in np.flatnonzero(shared > thresholds - _SCAN_MARGIN):
        verdict, msc = is_motion(x[onsets[i]:stop], y[onsets[i]:stop], sample_rate_hz)
        if verdict:
            return onsets[i], msc
    return None


def _tail_coherences(x: np.ndarray, y: np.ndarray, onsets: list[int], stop: int) -> tuple[np.ndarray, np.ndarray]:
    """The power-weighted coherence and the number of segments of each tail x[onset:stop], y[onset:stop], from
    one transform per segment of the grid the tails share (`coherence`'s segments: Hann, half
    overlapping, each one's mean removed), the sums running from the last segment back."""
    segment, step = COHERENCE_SEGMENT, COHERENCE_SEGMENT // 2
    first = onsets[0]
    count = (stop - first - segment) // step + 1  # segments of the longest tail
    window = 0.5 - 0.5 * np.cos(2.0 * np.pi * np.arange(segment) / segment)
    wanted = np.array([(o - first) // step for o in onsets])
    carry = [np.zeros(segment // 2, dtype=complex), np.zeros(segment // 2), np.zeros(segment // 2)]
    msc = np.empty(wanted.size)
    for high in range(count, 0, -_SCAN_CHUNK):
        low = max(0, high - _SCAN_CHUNK)
        spectra = []
        for z in (x, y):
            part = np.asarray(z[first + step * low:first + step * (high - 1) + segment], dtype=float)
            blocks = np.lib.stride_tricks.sliding_window_view(part, segment)[::step]
            spectra.append(fft.rfft((blocks - blocks.mean(axis=1, keepdims=True)) * window, axis=1)[:, 1:])
        fx, fy = spectra
        terms = (fx * np.conj(fy), fx.real**2 + fx.imag**2, fy.real**2 + fy.imag**2)
        tails = [np.cumsum(t[::-1], axis=0)[::-1] + c for t, c in zip(terms, carry, strict=True)]
        here = (wanted >= low) & (wanted < high)
        rows = wanted[here] - low
        cross, xx, yy = (t[rows] for t in tails)
        power = np.sum(xx * yy, axis=1)
        coherent = np.sum(cross.real**2 + cross.imag**2, axis=1)
        msc[here] = np.divide(coherent, power, out=np.zeros_like(power), where=power > 0)
        carry = [t[0] for t in tails]
    return msc, count - wanted
