"""Demodulation of the differential laser Doppler interferometer's photomultiplier (PM) beat.

The beat's instantaneous frequency is Δf = v·(φ − ξ)/d (method paper, Eq. 37; grating pitch d,
diffraction orders φ, ξ; orders ±1 give 2v/d), so its unwrapped phase is 2π·(φ − ξ)/d times
the grating's displacement. The reference acceleration is the time derivative of the velocity
(Eq. 38). This module turns a PM record sampled at ~100 MS/s into velocity and acceleration
at the analysis rate (default 1 MS/s).

How (and why this way):

1. **Analytic signal in overlapping blocks** (power-of-two FFTs of 2¹⁶ samples, 2¹² of them
   discarded at each end). One FFT of a whole 10⁷-sample record costs about a second; the
   blocks cost a fraction of that. The band below a low edge (1/8 of the dominant beat,
   20–250 kHz: the PM's DC offset, drift, and the step its level makes when the grating leaves
   rest) is removed in the same step. The band above 0.46 fs, where no beat may be, measures
   the noise (the SNR is reported; a record without a beat 6 dB above it is refused).
2. **Phase increments, not a discriminator of averages**: the angle of z[n]·conj(z[n−1]) for
   every sample (|Δφ| < π since the beat stays below 0.45 fs), summed per block of M samples
   (M = raw rate / 10 MS/s). The sum telescopes to the exact unwrapped phase difference, so
   noise does not bias it (the angle of a *sum* of products does: it pulls the frequency
   towards the centre of the noise band). Each block's *mean* phase is kept: the phase passes
   the same M-sample box-car as a companion channel averaged over the same blocks (see
   analysis.reduce). Blocks without beat power (rest: only noise) add no phase.
3. **Onset** (the grating leaving rest): there the beat is slower than its own chirp and no
   linear filter gives its quadrature (a still grating leaves a constant PM level). Up to the
   hand-over frequency (half the peak beat, at most 2 MHz) the phase is read from the PM
   signal itself, low-passed and normalised: cos φ = (x − offset)/amplitude, the offset from
   the fast part of the record, the amplitude from the fringes' extremes (a parabola fitted
   at each). A Schmitt trigger (half an amplitude of hysteresis) finds the extremes, whose
   order unfolds arccos into a monotonic phase. The one ambiguity is the rest's branch: did
   the grating pass a fringe's extreme right after leaving rest? It did if the smoothed
   signal went beyond the (drifting) rest level on the rest's side before heading for the
   first far extreme; a rest too close to an extreme to tell is put on the extreme, and the
   first motion it hides (1 − cos δ stays within the noise) is continued back from where it
   shows along a power law δ = c·(t − t0)^p. Near every extreme (|cos| > 0.95) arccos is
   ill-conditioned: there the onset uses the smoothed signal and later fringes are
   interpolated in time. Past the hand-over the tracker and the analytic phase are aligned
   and cross-faded until the analytic phase has settled.
4. **Rate and differentiation**: the phase (as displacement) goes to the analysis rate with
   `analysis.resample.resample_to_rate` (`displacement_to_rate`: ends extended the way the
   motion continues, so the resampler's edge handling does not ring); velocity and
   acceleration come from a **differentiating low-pass**: a Kaiser-windowed low-pass L of
   bandwidth B (−6 dB) convolved with a Kaiser-windowed ideal differentiator (exact on ramps,
   j2πf to 4·10⁻⁶ in the band), so the acceleration is L applied to the true acceleration.
   B is chosen from the pulse (`bandwidth_for_rise_time`, ≈ 8.5/δ for a half-sine of width
   δ) unless given, and reported. A companion channel passed through `lowpass` gets the same
   L, so a model fitted between the two is not distorted.

Limits (measured on simulated half-sine shots, phases at rest over a whole fringe, SNR 20–40 dB,
see tests/analysis/test_doppler.py): velocity within 0.1 % of its peak, peak acceleration
within 0.5 %, 10 % width within 1 % while the grating moves ≥ ~80 fringes (a·δ²/π ≥ 40 µm at
d = 2 µm) during the pulse. With fewer fringes the onset's phase error (≈ 0.1 rad) is no
longer small against the pulse: 10 000 g over 20 µs (12 fringes) gives ~0.8 % velocity error.
Noise adds σ_a ≈ (d/4π)·(2π)²·√(2B⁵/5 · σ_φ²/fs) to the acceleration (σ_φ² = ½·10^(−SNR/10)):
~0.3 % of 100 000 g for a 20 µs pulse (B = 400 kHz) at 20 dB.

Sign: a single PM channel cannot tell the direction of motion (the beat of +v equals that of
−v). The object moves one way during a Hopkinson shock (the velocity rises monotonically to
its flight value for a half-sine), so the velocity is reported as positive in that direction.
A velocity history that reverses (the object comes back) cannot be demodulated from one PM.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from hopkinson.analysis.errors import AnalysisError
from hopkinson.analysis.flat_top import FLAT_TOP_FACTOR, FLAT_TOP_MIN_SAMPLES, flat_top_warnings  # noqa: F401
from hopkinson.analysis.records import Record
from hopkinson.analysis.resample import DEFAULT_ANALYSIS_RATE_HZ, resample_to_rate
from scipy import fft, ndimage, signal

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
BANDWIDTH_RISE_PRODUCT = 5.0  # B = this / (10–90 % rise time of the velocity)
MAX_BANDWIDTH_FRACTION = 0.4  # B ≤ this × the analysis rate (the low-pass must fit below Nyquist)
STOPBAND_ATTENUATION_DB = 80.0  # of the low-pass L


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


def metres_per_radian(grating_pitch_m: float, orders: tuple[int, int]) -> float:
    """Grating displacement per radian of beat phase: d / (2π·(φ − ξ)) (from Eq. 37)."""
    if not grating_pitch_m > 0:
        raise AnalysisError(f"grating pitch must be positive, got {grating_pitch_m!r} m")
    order_difference = int(orders[0]) - int(orders[1])
    if order_difference == 0:
        raise AnalysisError(f"diffraction orders {orders} must differ (φ − ξ = 0 gives no beat)")
    return grating_pitch_m / (2.0 * np.pi * abs(order_difference))


# --- stage 1-3: the beat's phase -------------------------------------------------------------
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
    m = max(1, int(fs // decimated_rate_hz))
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
    phase, k_on, amplitude_v = _onset_phase(x, sample_interval_s, m, phase, k_h, handover_hz, offset_v,
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


# The volts of a channel's lowest and highest digitizer codes (its full scale).
FullScale = tuple[float, float]
# A sample within this fraction of the span from a full-scale end sits on it (volts rebuilt
# from codes, possibly through float32: far below half a code step of any format ≤ 19 bits).
_FULL_SCALE_TOLERANCE = 1e-6


def full_scale_volts(code_range: tuple[float, float], scale_v: float, offset_v: float) -> FullScale:
    """The full scale in volts of a channel stored as codes (the shot file's /raw/<role>
    attributes code_min, code_max, scale_v, offset_v: volts = codes · scale_v + offset_v)."""
    ends = sorted((code_range[0] * scale_v + offset_v, code_range[1] * scale_v + offset_v))
    return float(ends[0]), float(ends[1])


def samples_at_full_scale(x: np.ndarray, full_scale_v: FullScale) -> int:
    """How many samples of `x` (volts) reach the digitizer's full scale (either end or beyond)."""
    lo, hi = full_scale_v
    tol = _FULL_SCALE_TOLERANCE * abs(hi - lo)
    v = np.asarray(x, dtype=float)
    return int(np.count_nonzero((v <= lo + tol) | (v >= hi - tol)))


def check_not_clipped(x: np.ndarray, full_scale_v: FullScale | None, what: str, remedy: str) -> None:
    """Raise AnalysisError naming `what` when samples of `x` sit at the digitizer's full scale.

    Clipping is judged against the instrument, never against the record itself: a quantised
    record whose extreme code repeats (a wide pulse, a slow digitizer) is not clipped. Without
    `full_scale_v` (a table file, an old shot file) nothing is judged here: the rig judged the
    shot when it was recorded (rig.shot.clipping_problems); `identify` warns of a table file's
    flat top (`flat_top_warnings`)."""
    if full_scale_v is None:
        return
    lo, hi = full_scale_v
    if not (math.isfinite(lo) and math.isfinite(hi) and hi > lo):
        raise AnalysisError(f"{what}: the digitizer's full scale must be two finite volts, low < high; got {full_scale_v!r}")
    count = samples_at_full_scale(x, full_scale_v)
    if count:
        raise AnalysisError(f"{what}: clipped: {count} samples at the digitizer's full scale ({lo:.4g} .. {hi:.4g} V): "
                            f"{remedy}")


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


# --- stage 3: the onset ------------------------------------------------------------------------
def _onset_phase(x: np.ndarray, dt: float, m: int, phase: np.ndarray, k_h: int, handover_hz: float,
                 offset_v: float, smooth_hz: np.ndarray, power: np.ndarray, noise_power: float,
                 low_hz: float, source: str) -> tuple[np.ndarray, int, float]:
    """Replace the analytic phase before the hand-over block k_h by the fringe tracker's.

    Returns the new phase (block means), the onset block and the beat amplitude used.
    """
    k_a, k_b = _onset_window(smooth_hz, k_h, handover_hz, low_hz, m * dt, phase.size, source)
    y, t_y, down = _tracker_signal(x, dt, m, k_a, k_b, offset_v, handover_hz)
    amplitude_h = float(np.sqrt(max(np.mean(power[k_h:k_b]) - noise_power, 1e-30)))
    rest = _Rest.of(y, t_y)
    turns, kinds = _turning_points(y, 0.5 * amplitude_h)
    first = _first_extreme(y, t_y, turns, kinds, rest, amplitude_h, down * dt)
    theta, rest_phase = _unfold(y, t_y, first, rest, amplitude_h)
    # Block means (the tracker phase at block centres) and the join with the analytic phase:
    # aligned on the tracker over the overlap, then cross-faded (raised cosine) so neither a
    # step nor a kink is left at the hand-over.
    centres = (np.arange(k_a, k_b) * m + 0.5 * (m - 1)) * dt
    tracked = np.interp(centres, t_y, theta)
    join = slice(k_h - k_a, k_b - k_a)
    out = phase + float(np.mean(tracked[join] - phase[k_h:k_b]))
    fade = 0.5 * (1.0 + np.cos(np.pi * np.arange(k_b - k_h) / (k_b - k_h)))
    out[k_h:k_b] = fade * tracked[join] + (1.0 - fade) * out[k_h:k_b]
    out[k_a:k_h] = tracked[: k_h - k_a]
    out[:k_a] = rest_phase
    moving = np.flatnonzero(theta > rest_phase + 0.1)
    k_on = k_a + int(np.searchsorted(centres, t_y[moving[0]])) if moving.size else k_h
    return out, k_on, amplitude_h


def _onset_window(smooth_hz: np.ndarray, k_h: int, handover_hz: float, low_hz: float, block_s: float,
                  n_blocks: int, source: str) -> tuple[int, int]:
    """Blocks [k_a, k_b) the fringe tracker reads: from well before the motion to past the
    hand-over block k_h.

    The analytic beat frequency, coarse below the hand-over but good enough for this, falls
    below a tenth of the hand-over frequency at block k_10; the motion began less than
    (k_h − k_10) before that for any onset whose velocity grows like tᵖ with p ≤ 3, so twice
    that span (and 5 µs more) reaches into rest. After the hand-over the tracker runs on until
    the analytic phase has settled (the step the PM level makes when the grating leaves rest
    rings in the analytic band's low edge for a few of its periods) or the beat nears the
    tracker's low-pass (3× the hand-over), whichever comes first.
    """
    slow = np.flatnonzero(smooth_hz[:k_h] < 0.1 * handover_hz)
    if slow.size < max(10, int(2e-6 / block_s)):  # ≥ 2 µs of rest (not just the record's edge)
        raise AnalysisError(
            f"{source}: the record starts while the object is already moving (no rest before the pulse): "
            f"record more pre-trigger"
        )
    k_10 = int(slow[-1])
    k_a = max(0, k_10 - 2 * max(k_h - k_10, 1) - int(round(5e-6 / block_s)))
    settle = int(np.ceil(5.0 / (low_hz * block_s)))
    fast = np.flatnonzero(smooth_hz[k_h:] > 3.0 * handover_hz)
    overlap = max(4, min(settle, int(fast[0]) if fast.size else settle))
    return k_a, min(n_blocks, k_h + overlap + 1)


def _tracker_signal(x: np.ndarray, dt: float, m: int, k_a: int, k_b: int, offset_v: float,
                    handover_hz: float) -> tuple[np.ndarray, np.ndarray, int]:
    """The PM signal of blocks [k_a, k_b) minus its offset, low-passed (zero-phase Kaiser FIR,
    ends padded with their edge value) at 5× the hand-over frequency and sampled at ~10× that
    cut-off; with its raw-record times and the down-sampling factor."""
    fs = 1.0 / dt
    cutoff_hz = 5.0 * handover_hz
    down = max(1, int(fs // (10.0 * cutoff_hz)))
    taps = signal.firwin(int(8 * fs / cutoff_hz) | 1, cutoff_hz, window=("kaiser", 8.0), fs=fs)
    raw = x[k_a * m : k_b * m].astype(float) - offset_v
    y = signal.oaconvolve(np.pad(raw, taps.size // 2, mode="edge"), taps, mode="valid")[::down]
    return y, (k_a * m + np.arange(y.size) * down) * dt, down


@dataclass(frozen=True)
class _Rest:
    """The rest at the start of the tracker's window (its first quarter): level and noise.

    The level drifts with the slow amplitude fluctuation (A·cos φ0 changes with A): over a rest
    of ≥ 20 µs a straight line through it is extrapolated; a shorter one is taken flat at the
    median of its second half (nearest the motion). The noise is y's robust spread there.
    """

    n: int  # samples of y in the rest
    line: np.ndarray  # polynomial (numpy.polyval order) in time since t0
    t0: float
    noise: float

    @classmethod
    def of(cls, y: np.ndarray, t_y: np.ndarray) -> _Rest:
        n = max(8, y.size // 4)
        if t_y[n - 1] - t_y[0] >= 20e-6:
            line = np.polyfit(t_y[:n] - t_y[0], y[:n], 1)
        else:
            line = np.array([0.0, float(np.median(y[n // 2 : n]))])
        noise = 1.4826 * float(np.median(np.abs(y[:n] - np.median(y[:n]))))
        return cls(n, line, float(t_y[0]), noise)

    def level(self, t: np.ndarray | float) -> np.ndarray | float:
        return np.polyval(self.line, np.asarray(t) - self.t0)


@dataclass(frozen=True)
class _FirstExtreme:
    """The fringe extremes from the rest on, after the decision about the rest's branch."""

    turns: np.ndarray  # indices into y
    kinds: np.ndarray  # +1 maximum, −1 minimum
    far: int  # index of the first extreme far from the rest level (the onset ends there)
    rest_on_extreme: bool  # the rest is put on turns[0], an extreme too close to tell
    y_smooth: np.ndarray
    noise: float  # what the smoothed signal must move to be seen (3 σ + 1 % of the amplitude)
    rest_level: float  # the rest level at the decision


def _first_extreme(y: np.ndarray, t_y: np.ndarray, turns: np.ndarray, kinds: np.ndarray, rest: _Rest,
                   amplitude_h: float, sample_s: float) -> _FirstExtreme:
    """Decide whether the grating passed a fringe's extreme right after leaving rest.

    The trigger's extremes before the first one far (≥ half an amplitude) from the rest level
    may be the rest's own noisy highs and lows. Between the rest and that far extreme the
    grating turned at most once, on the rest's side (a "near" extreme: the rest sat just short
    of a fringe's extreme). If it did, the signal reached that extreme shortly before it last
    crossed the rest level towards the far one; if not, it only left the rest level there. The
    peak of the signal, smoothed over a quarter of the first half-fringe, in the two
    half-fringes before that crossing decides: beyond the rest level by more than twice the
    noise, a near extreme; else none, unless the rest itself is that close to the extreme, in
    which case the rest is put on the extreme (in doubt this costs at most the small distance
    to it, instead of twice it).
    """
    width = max(1, int(0.25e-6 / sample_s)) | 1
    rest_level = float(rest.level(t_y[0]))
    far = np.flatnonzero(np.abs(y[turns] - rest.level(t_y[turns])) >= 0.5 * amplitude_h) if turns.size \
        else np.zeros(0, int)
    if not (far.size and far[0] + 1 < turns.size):
        return _FirstExtreme(turns, kinds, y.size, False, _boxcar(y, width),
                             _smoothed_noise(rest.noise, width) + 0.01 * amplitude_h, rest_level)
    j = int(far[0])
    big = int(turns[j])
    near_kind = -int(kinds[j])
    half_fringe = int(turns[j + 1] - big)
    width = max(1, half_fringe // 4) | 1
    y_smooth = _boxcar(y, width)
    near_side = np.flatnonzero((y_smooth[:big] - rest.level(t_y[:big])) * near_kind >= 0)
    crossing = int(near_side[-1]) if near_side.size else big
    search = np.arange(max(0, crossing - 2 * half_fringe), crossing + 1)
    best = int(search[np.argmax(y_smooth[search] * near_kind)])
    extreme = float(_parabolic_extreme(np.abs(y), turns[j : j + 1])[0])  # fringe amplitude
    noise = _smoothed_noise(rest.noise, width) + 0.01 * extreme
    rest_level = float(rest.level(t_y[best]))
    excursion = float(y_smooth[best]) * near_kind - rest_level * near_kind
    turns, kinds = turns[j:], kinds[j:]
    on_extreme = excursion <= 2.0 * noise and extreme - abs(rest_level) <= 2.0 * noise + 0.01 * extreme
    if on_extreme or excursion > 2.0 * noise:
        turns = np.concatenate([[best], turns])
        kinds = np.concatenate([[near_kind], kinds])
    return _FirstExtreme(turns, kinds, big, on_extreme, y_smooth, noise, rest_level)


def _unfold(y: np.ndarray, t_y: np.ndarray, first: _FirstExtreme, rest: _Rest,
            amplitude_h: float) -> tuple[np.ndarray, float]:
    """Monotonic phase θ of y = A·cos θ from the extremes' order, and the rest phase."""
    turns, kinds = first.turns, first.kinds
    idx = np.arange(y.size)
    # Amplitude through the extremes (each one's distance from the offset, a parabola fitted
    # around it), held before the first one and after the last one (a slow fluctuation changes
    # it by well under 1 % over an onset; extrapolating a slope from a few noisy extremes is
    # worse). A rest put on an extreme gives the amplitude there.
    if turns.size:
        amplitude = np.interp(t_y, t_y[turns], _parabolic_extreme(np.abs(y), turns))
        if first.rest_on_extreme:
            amplitude[: turns[1] if turns.size > 1 else y.size] = abs(first.rest_level)
    else:
        amplitude = np.full(y.size, amplitude_h)
    # Near a fringe's extreme (|cos θ| > 0.95) arccos amplifies noise (dθ = dc / sin θ). Before
    # the first far extreme (the onset, slow fringes) α is taken there from the smoothed signal;
    # later, where the fringes are fast and regular, θ is interpolated in time (below).
    alpha = np.arccos(np.clip(y / amplitude, -1.0, 1.0))
    ill = np.abs(y / amplitude) > 0.95
    early = ill & (idx < first.far)
    alpha[early] = np.arccos(np.clip(first.y_smooth / amplitude, -1.0, 1.0))[early]
    # Branch of each sample: after a maximum the fringe falls (θ = α), after a minimum it rises
    # (θ = 2π − α); before the first extreme, the branch that leads into it.
    if kinds.size:
        kind_next = np.concatenate([kinds, [-kinds[-1]]])[np.searchsorted(turns, idx, side="left")]
    else:  # no extreme: one direction throughout, taken from the trend of y
        kind_next = np.full(y.size, 1 if y[-1] > y[rest.n] else -1)
    theta = np.where(kind_next > 0, 2.0 * np.pi - alpha, alpha)
    theta += 2.0 * np.pi * np.searchsorted(turns[kinds > 0], idx, side="left")
    # Departure from rest: the last sample before the first real extreme (the far one when the
    # rest was put on an extreme) at which the smoothed signal is still within the noise of the
    # rest level. Up to there the phase is held at the rest phase: that of the rest level on the
    # branch leading into the first extreme (from the level, not from a median of noisy arccos
    # values, which are biased near an extreme), or the extreme's own phase.
    end = first.far if first.rest_on_extreme else (int(turns[0]) if turns.size else y.size)
    at_rest = np.flatnonzero(np.abs(first.y_smooth[:end] - rest.level(t_y[:end])) <= first.noise)
    held = max(int(at_rest[-1]) + 1 if at_rest.size else 0, rest.n // 2)
    if first.rest_on_extreme:
        rest_phase = float(theta[turns[0]])
    else:
        k = min(held, y.size - 1)
        alpha_rest = float(np.arccos(np.clip(rest.level(t_y[k]) / amplitude[k], -1.0, 1.0)))
        rest_phase = (2.0 * np.pi - alpha_rest if kind_next[k] > 0 else alpha_rest) \
            + 2.0 * np.pi * int(np.searchsorted(turns[kinds > 0], k, side="left"))
    theta[:held] = rest_phase
    good = ~ill | early
    good[:held] = True
    theta[~good] = np.interp(idx[~good], idx[good], theta[good])
    theta = np.maximum(theta, rest_phase)
    if first.rest_on_extreme:
        # On an extreme the signal hides the first part of the motion (1 − cos δ ≈ δ²/2 stays
        # within the noise): the phase there is continued back from where it is observable
        # along a power law δ = c·(t − t0)^p (any onset whose velocity grows like a power of
        # time; a half-sine gives p = 3).
        visible = float(np.sqrt(2.0 * first.noise / max(abs(first.rest_level), 1e-30)))
        _extrapolate_onset(theta, t_y, rest_phase, first.far, visible)
    return theta, rest_phase


def _extrapolate_onset(theta: np.ndarray, t: np.ndarray, rest_phase: float, end: int, visible: float) -> None:
    """In place: replace θ between the rest and the first sample where it has moved 1.5×
    `visible` from `rest_phase` by the power law δ = c·(t − t0)^p (1 ≤ p ≤ 4) fitted to the
    part that moved between 1.5× `visible` and π/2 (fit in log-log for each start t0 on a grid;
    the best one wins)."""
    delta = theta[:end] - rest_phase
    fit_range = np.flatnonzero((delta >= 1.5 * visible) & (delta <= 0.5 * np.pi))
    if fit_range.size < 8:
        return
    first = int(fit_range[0])
    t_first = t[first]
    span = t[fit_range[-1]] - t_first
    best: tuple[float, float, float, float] | None = None
    for t0 in t_first - span * np.linspace(0.05, 3.0, 60):
        if t0 < t[0]:
            break
        lt = np.log(t[fit_range] - t0)
        ld = np.log(delta[fit_range])
        p, logc = np.polyfit(lt, ld, 1)
        if not 1.0 <= p <= 4.0:
            continue
        err = float(np.sum((ld - (p * lt + logc)) ** 2))
        if best is None or err < best[0]:
            best = (err, float(t0), float(p), float(logc))
    if best is None:
        return
    _, t0, p, logc = best
    bridge = np.arange(max(0, int(np.searchsorted(t, t0))), first)
    theta[bridge] = rest_phase + np.exp(logc) * (t[bridge] - t0) ** p
    theta[: bridge[0] if bridge.size else first] = np.minimum(theta[: bridge[0] if bridge.size else first],
                                                              rest_phase)


def _boxcar(y: np.ndarray, width: int) -> np.ndarray:
    """Moving mean over `width` (odd) samples, ends padded with their edge value."""
    return np.convolve(np.pad(y, width // 2, mode="edge"), np.ones(width) / width, mode="valid")


def _smoothed_noise(noise_y: float, width: int) -> float:
    """Three standard deviations of y's noise after a `width`-sample boxcar (y is sampled at
    10× its low-pass cut-off, so ~5 consecutive samples are correlated)."""
    return 3.0 * noise_y / np.sqrt(max(width / 5.0, 1.0))


def _parabolic_extreme(y: np.ndarray, at: np.ndarray) -> np.ndarray:
    """Height of the peaks of `y` (≥ 0 near them) at the indices `at`: the vertex of a parabola
    fitted by least squares to the contiguous samples within 10 % of the peak sample (cos θ
    within 0.45 rad of its extreme; the quartic term costs < 0.2 %). Using many samples keeps
    the noise of single samples, and the upward bias of picking the largest, out of it."""
    heights = np.empty(len(at))
    for j, i in enumerate(np.asarray(at, dtype=int)):
        level = 0.9 * y[i]
        lo = i
        while lo > 0 and y[lo - 1] >= level:
            lo -= 1
        hi = i
        while hi < y.size - 1 and y[hi + 1] >= level:
            hi += 1
        if hi - lo < 2:
            lo, hi = max(0, i - 1), min(y.size - 1, i + 1)
        k = np.arange(lo, hi + 1) - i
        c2, c1, c0 = np.polyfit(k, y[lo : hi + 1], 2)
        heights[j] = c0 - 0.25 * c1 * c1 / c2 if c2 < 0 else y[i]
    return heights


def _turning_points(y: np.ndarray, hysteresis: float) -> tuple[np.ndarray, np.ndarray]:
    """Indices and kinds (+1 maximum, −1 minimum) of the extremes of `y` confirmed by a move of
    more than `hysteresis` away from them (a Schmitt trigger; noise smaller than that is ignored).

    A sequential scan (a few thousand samples of the onset window): numpy has no vector form
    of a hysteresis comparator.
    """
    idx: list[int] = []
    kinds: list[int] = []
    hi_i = lo_i = 0
    state = 0  # 0: undecided, +1: rising (looking for a maximum), −1: falling
    for i in range(1, y.size):
        v = y[i]
        if state >= 0 and v > y[hi_i]:
            hi_i = i
        if state <= 0 and v < y[lo_i]:
            lo_i = i
        if state >= 0 and v < y[hi_i] - hysteresis:
            idx.append(hi_i)
            kinds.append(1)
            state, lo_i = -1, i
        elif state <= 0 and v > y[lo_i] + hysteresis:
            idx.append(lo_i)
            kinds.append(-1)
            state, hi_i = 1, i
    return np.asarray(idx, dtype=int), np.asarray(kinds, dtype=int)


# --- stage 4: bandwidth, filters, differentiation ---------------------------------------------
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


def demodulate(
    doppler_v: np.ndarray,
    sample_interval_s: float,
    grating_pitch_m: float,
    orders: tuple[int, int] = (1, -1),
    *,
    analysis_rate_hz: float = DEFAULT_ANALYSIS_RATE_HZ,
    bandwidth_hz: float | None = None,
) -> Demodulated:
    """Velocity (m/s) and acceleration (m/s²) of the grating from a PM beat, at the analysis rate.

    `bandwidth_hz` None: chosen from the pulse by `bandwidth_for_rise_time`.
    """
    beat = beat_phase(doppler_v, sample_interval_s, decimated_rate_hz=decimated_rate_for(analysis_rate_hz))
    displacement = beat.phase_rad * metres_per_radian(grating_pitch_m, orders)
    at_rate = displacement_to_rate(displacement, np.zeros(displacement.size), beat.sample_interval_s,
                                   beat.start_time_s, analysis_rate_hz)
    return differentiate(at_rate.reference, at_rate.sample_interval_s, at_rate.start_time_s, beat, bandwidth_hz)


def decimated_rate_for(analysis_rate_hz: float) -> float:
    """Rate of the box-car decimated phase for an analysis rate: 10 MS/s, or 4× a faster one."""
    return max(DECIMATED_RATE_HZ, 4.0 * analysis_rate_hz)


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
