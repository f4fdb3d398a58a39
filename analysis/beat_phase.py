"""The unwrapped phase of a single-channel PM beat: steps 1–3 of analysis/doppler.py's method
(the analytic signal in overlapping blocks, the phase increments summed per box-car block, and
the onset read by the fringe tracker, analysis/fringe_tracker.py)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import fft, ndimage

from hopkinson.analysis.errors import AnalysisError
from hopkinson.analysis.fringe_tracker import onset_phase
from hopkinson.analysis.full_scale import FullScale, check_not_clipped
from hopkinson.analysis.sample_counts import floor_count

# --- documented constants of the method ------------------------------------------------------
BLOCK_SAMPLES = 2**16  # FFT length of one analytic-signal block
BLOCK_OVERLAP = 2**12  # samples discarded at each end of a block (the Hilbert kernel's reach)
ANALYTIC_LOW_MIN_HZ = 20e3  # analytic band's low edge: at least this (removes DC, slow drift)
ANALYTIC_LOW_MAX_HZ = 250e3  # ... and at most this
DECIMATED_RATE_HZ = 10e6  # rate of the phase after the box-car (at least; see decimated_rate_for)
GATE_FRACTION = 0.1  # a block carries phase when its power is ≥ this × the beat power
HANDOVER_MAX_HZ = 2e6  # the fringe tracker reads the onset up to this beat frequency
MIN_SAMPLE_RATE_HZ = 5e6  # below this a PM beat record is certainly mis-sampled
MAX_BEAT_FRACTION = 0.45  # a beat above this × the sampling rate is aliased
NOISE_BAND_FRACTION = 0.46  # the band above this × the sampling rate measures the noise


@dataclass(frozen=True)
class BeatPhase:
    """Unwrapped phase of a PM beat, decimated by a box-car of `decimation` raw samples.

    phase_rad[k] is the mean phase over raw samples k·M … k·M + M − 1 (M = decimation), so
    its time is start_time_s + k·sample_interval_s with start_time_s = (M − 1)/2 raw intervals
    (relative to the raw record's first sample). Zero at rest, increasing with the motion.
    """

    sample_interval_s: float
    start_time_s: float
    phase_rad: np.ndarray
    decimation: int
    beat_peak_hz: float  # highest beat frequency of the record
    onset_time_s: float  # where the motion leaves rest (phase exceeds its rest value)
    handover_time_s: float  # where the analytic phase takes over from the fringe tracker
    snr_db: float  # beat power over the noise power of the record, estimated
    offset_v: float  # DC level of the PM beat
    amplitude_v: float  # beat amplitude near the hand-over


def beat_phase(doppler_v: np.ndarray, sample_interval_s: float, *, decimated_rate_hz: float = DECIMATED_RATE_HZ,
               source: str = "doppler channel", full_scale_v: FullScale | None = None) -> BeatPhase:
    """Unwrapped phase (rad) of a single-channel PM beat, box-car decimated to ~`decimated_rate_hz`.

    Raises AnalysisError (naming `source`) when the record is too short, sampled too slowly,
    clipped (samples at the digitizer's full scale `full_scale_v`, when given: see
    `check_not_clipped`), or carries no beat.
    """
    check_not_clipped(doppler_v, full_scale_v, source, "reduce the digitizer's gain or widen its range")
    x = np.asarray(doppler_v, dtype=np.float32).ravel()
    fs = _check_record(x, sample_interval_s, source)
    m = max(1, floor_count(fs / decimated_rate_hz))
    n_blocks = x.size // m
    if n_blocks < 64:
        raise AnalysisError(f"{source}: {x.size} samples is too short to demodulate (needs ≥ {64 * m})")
    x = x[: n_blocks * m]
    weighted, total, power, low_hz, noise_power = _phase_increments(x, sample_interval_s, m)
    beat_power = float(np.percentile(power, 99.0))
    gate = power >= GATE_FRACTION * beat_power
    if not np.any(gate) or beat_power <= 4.0 * noise_power:
        raise AnalysisError(f"{source}: no Doppler beat found (beat power not 6 dB above the noise)")
    phase = _block_mean_phase(weighted, total, gate)
    dt_m = m * sample_interval_s
    frequency_hz = np.diff(phase, prepend=phase[0]) / (2.0 * np.pi * dt_m)
    smooth_hz = ndimage.uniform_filter1d(np.where(gate, frequency_hz, 0.0), size=11, mode="nearest")
    beat_peak_hz = float(np.max(smooth_hz))
    if beat_peak_hz > MAX_BEAT_FRACTION * fs:
        raise AnalysisError(
            f"{source}: the beat reaches {beat_peak_hz / 1e6:.1f} MHz, above {MAX_BEAT_FRACTION:.0%} of the "
            f"{fs / 1e6:g} MS/s sampling rate: the record is aliased or its sample interval is wrong"
        )
    if beat_peak_hz * x.size * sample_interval_s < 10.0:
        raise AnalysisError(f"{source}: no Doppler beat found (fewer than 10 fringes in the record)")
    handover_hz = min(HANDOVER_MAX_HZ, max(0.5 * beat_peak_hz, 4.0 * low_hz))
    above = np.flatnonzero(smooth_hz >= handover_hz)
    if above.size == 0:
        raise AnalysisError(f"{source}: no Doppler beat found (the beat never rises above {handover_hz / 1e3:.0f} kHz)")
    k_h = int(above[0])
    block_means = x.reshape(-1, m) @ np.full(m, 1.0 / m, dtype=np.float32)
    offset_v = float(np.mean(block_means[smooth_hz >= handover_hz]))
    phase, k_on, amplitude_v = onset_phase(x, sample_interval_s, m, phase, k_h, handover_hz, offset_v,
                                           smooth_hz, power, noise_power, low_hz, source)
    snr_db = 10.0 * np.log10(max(beat_power - noise_power, 1e-30) / max(noise_power, 1e-30))
    return BeatPhase(dt_m, 0.5 * (m - 1) * sample_interval_s, phase - phase[0], m, beat_peak_hz,
                     (k_on + 0.5) * dt_m, (k_h + 0.5) * dt_m, float(snr_db), offset_v, amplitude_v)


def _check_record(x: np.ndarray, sample_interval_s: float, source: str) -> float:
    if not (np.isfinite(sample_interval_s) and sample_interval_s > 0):
        raise AnalysisError(f"{source}: sample interval must be positive, got {sample_interval_s!r} s")
    fs = 1.0 / sample_interval_s
    if fs < MIN_SAMPLE_RATE_HZ:
        raise AnalysisError(
            f"{source}: sampled at {fs / 1e6:g} MS/s; a PM beat needs ≥ {MIN_SAMPLE_RATE_HZ / 1e6:g} MS/s "
            f"(~100 MS/s): wrong channel or wrong sample interval?"
        )
    if x.size < 4096:
        raise AnalysisError(f"{source}: only {x.size} samples; a Doppler record needs at least 4096")
    if not np.all(np.isfinite(x)):
        raise AnalysisError(f"{source}: has a NaN or infinite sample at index {int(np.flatnonzero(~np.isfinite(x))[0])}")
    lo = float(np.min(x))
    if float(np.max(x)) == lo:
        raise AnalysisError(f"{source}: the signal is constant ({lo:g} V): no Doppler beat")
    return fs


def _phase_increments(x: np.ndarray, sample_interval_s: float, m: int
                      ) -> tuple[np.ndarray, np.ndarray, np.ndarray, float, float]:
    """Per M-sample block: the weighted and plain sums of the phase increments (the angle of
    z[n]·z*[n−1], see `_block_mean_phase`), the mean analytic power; and the low edge (Hz) of
    the analytic band used and the noise's power in the analytic signal.

    The spectra of all overlapping FFT blocks are computed first; the strongest beat frequency
    in them sets the analytic band's low edge (`_analytic_low_hz`), then the blocks go back.
    Each FFT block keeps a whole number of M-sample blocks, so the per-sample increments are
    reduced to block sums as they are made (never a 10⁷-sample array of them).
    """
    n = x.size
    keep = (BLOCK_SAMPLES - 2 * BLOCK_OVERLAP) // m * m  # kept samples per FFT block
    lead = BLOCK_OVERLAP  # discarded before the kept part (the rest of the block after it)
    n_fft_blocks = -(-n // keep)
    padded = np.empty(n_fft_blocks * keep + BLOCK_SAMPLES - keep, dtype=np.float32)
    padded[lead : lead + n] = x
    padded[:lead] = x[0]
    padded[lead + n :] = x[-1]
    freq = fft.rfftfreq(BLOCK_SAMPLES, sample_interval_s)
    frames = np.lib.stride_tricks.sliding_window_view(padded, BLOCK_SAMPLES)[::keep][:n_fft_blocks]
    spectra = fft.rfft(frames, axis=1)  # complex64 for float32 input
    low_hz = _analytic_low_hz(spectra, freq)
    gain = _analytic_gain(freq, low_hz).astype(np.float32)
    # Noise: white noise of variance σ² has E|X_k|² = N·σ² in every bin; the band above
    # NOISE_BAND_FRACTION of the rate holds no beat (it is below MAX_BEAT_FRACTION), so its bin
    # power measures the noise: the median (|X_k|² is exponential: mean = median / ln 2), which
    # a stray line (an aliased beat) does not move. Its power in the analytic signal is that
    # times Σ gain²/N².
    # Frames that are mostly padding (the record's ends) are left out.
    noise_bins = freq >= NOISE_BAND_FRACTION / sample_interval_s
    frame_start = np.arange(n_fft_blocks) * keep - lead
    data_fraction = (np.minimum(frame_start + BLOCK_SAMPLES, n) - np.maximum(frame_start, 0)) / BLOCK_SAMPLES
    medians = np.median(np.abs(spectra[:, noise_bins]) ** 2, axis=1)
    full_frames = data_fraction >= 0.9
    noise_bin_power = float(np.median(medians[full_frames]) if np.any(full_frames) else medians.max()) / np.log(2.0)
    noise_power = noise_bin_power * float(np.sum(gain.astype(float) ** 2)) / BLOCK_SAMPLES**2
    n_blocks = n // m
    weighted = np.empty(n_blocks, dtype=np.float32)
    total = np.empty(n_blocks, dtype=np.float32)
    power = np.empty(n_blocks, dtype=np.float32)
    w_mean = ((m - np.arange(m)) / m).astype(np.float32)  # weight of increment i in a block mean
    ones = np.ones(m, dtype=np.float32)
    previous = np.complex64(0)
    prod = np.empty(keep, dtype=np.complex64)
    angles = np.empty(keep, dtype=np.float32)
    batch = 16  # FFT blocks per call: low Python overhead, bounded memory
    full = np.zeros((batch, BLOCK_SAMPLES), dtype=np.complex64)
    for first in range(0, n_fft_blocks, batch):
        count = min(batch, n_fft_blocks - first)
        full[:count, : freq.size] = spectra[first : first + count] * gain
        analytic = fft.ifft(full[:count], axis=1, overwrite_x=True)
        for row in range(count):
            lo = (first + row) * keep
            length = min(keep, n - lo)
            z = analytic[row, lead : lead + length]  # a contiguous view
            p = prod[:length]
            np.multiply(z[1:], np.conj(z[:-1]), out=p[1:])
            p[0] = z[0] * np.conj(previous)
            previous = z[-1]
            a = angles[:length].reshape(-1, m)
            np.arctan2(p.imag, p.real, out=angles[:length])
            k0 = lo // m
            k1 = k0 + length // m
            np.matmul(a, w_mean, out=weighted[k0:k1])
            np.matmul(a, ones, out=total[k0:k1])
            zf = z.view(np.float32).reshape(-1, 2 * m)
            np.einsum("ij,ij->i", zf, zf, out=power[k0:k1])
        full[:count, freq.size :] = 0  # the transform may have used `full` as its output
    power /= m
    return weighted, total, power, low_hz, noise_power


def _analytic_low_hz(spectra: np.ndarray, freq_hz: np.ndarray) -> float:
    """Low edge of the analytic band: 1/8 of the highest dominant beat frequency among the
    blocks that carry a beat, within [ANALYTIC_LOW_MIN_HZ, ANALYTIC_LOW_MAX_HZ].

    The edge removes the PM's DC offset and the slow step its level makes when the grating
    leaves rest; the higher it is, the sooner that step stops disturbing the analytic phase.
    The fringe tracker covers the beat up to 4× this edge (see `beat_phase`).
    """
    first = int(np.searchsorted(freq_hz, ANALYTIC_LOW_MIN_HZ))
    block_power = np.array([np.vdot(b[first:], b[first:]).real for b in spectra])
    beating = np.flatnonzero(block_power >= 0.1 * block_power.max())
    # The strongest block and up to 15 others spread over the beating ones suffice (a long
    # flight repeats the same beat in every block) and keep this cheap for 10⁷ samples.
    chosen = np.union1d(beating[np.linspace(0, beating.size - 1, min(16, beating.size)).astype(int)],
                        [int(np.argmax(block_power))])
    psd = np.abs(spectra[chosen, first:]) ** 2
    dominant = freq_hz[first:][np.argmax(psd, axis=1)]
    return float(np.clip(dominant.max() / 8.0, ANALYTIC_LOW_MIN_HZ, ANALYTIC_LOW_MAX_HZ))


def _analytic_gain(freq_hz: np.ndarray, low_hz: float) -> np.ndarray:
    """One-sided gain of the analytic-signal filter: 2 above `low_hz` (raised-cosine edge from
    half of it), 0 at DC and below; the Nyquist bin counts once."""
    edge = np.clip((freq_hz - 0.5 * low_hz) / (0.5 * low_hz), 0.0, 1.0)
    gain = 2.0 * 0.5 * (1.0 - np.cos(np.pi * edge))
    gain[-1] *= 0.5
    return gain


def _block_mean_phase(weighted: np.ndarray, total: np.ndarray, gate: np.ndarray) -> np.ndarray:
    """Mean phase of every M-sample block from its sums of per-sample increments (gated blocks
    add none).

    Within block k (samples kM + j), φ[kM + j] = φ[kM − 1] + Σ_{i≤j} Δ[kM + i] with
    Δ[n] = φ[n] − φ[n−1], so mean_j φ = φ[kM − 1] + Σ_i Δ[kM + i]·(M − i)/M (`weighted`) and
    φ[kM + M − 1] = φ[kM − 1] + Σ_i Δ[kM + i] (`total`). Float32 block sums of ≤ M increments
    lose < 10⁻⁵ rad; the running sum is float64.
    """
    within = np.where(gate, weighted, 0.0)
    steps = np.where(gate, total, 0.0).astype(np.float64)
    start = np.concatenate([[0.0], np.cumsum(steps)[:-1]])  # φ[kM − 1] relative to the first
    return start + within


def decimated_rate_for(analysis_rate_hz: float) -> float:
    """Rate of the box-car decimated phase for an analysis rate: 10 MS/s, or 4× a faster one."""
    return max(DECIMATED_RATE_HZ, 4.0 * analysis_rate_hz)
