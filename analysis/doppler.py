"""Demodulation of the differential laser Doppler interferometer's photomultiplier (PM) beat.

The beat's instantaneous frequency is Δf = v·(φ − ξ)/d (method paper, Eq. 37; grating pitch d,
diffraction orders φ, ξ; orders ±1 give 2v/d), so its unwrapped phase is 2π·(φ − ξ)/d times
the grating's displacement. The reference acceleration is the time derivative of the velocity
(Eq. 38). This module turns a PM record sampled at ~100 MS/s into velocity and acceleration
at the analysis rate (default 1 MS/s) with `demodulate`.

How (and why this way); steps 1–3 are analysis/beat_phase.py's (the onset's fringe tracker,
step 3, analysis/fringe_tracker.py's), step 4 analysis/differentiating_lowpass.py's:

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

import numpy as np

from hopkinson.analysis.beat_phase import beat_phase, decimated_rate_for
from hopkinson.analysis.differentiating_lowpass import (
    Demodulated,
    differentiate,
    displacement_to_rate,
)
from hopkinson.analysis.errors import AnalysisError
from hopkinson.analysis.flat_top import FLAT_TOP_FACTOR, FLAT_TOP_MIN_SAMPLES, flat_top_warnings  # noqa: F401
from hopkinson.analysis.resample import DEFAULT_ANALYSIS_RATE_HZ


def metres_per_radian(grating_pitch_m: float, orders: tuple[int, int]) -> float:
    """Grating displacement per radian of beat phase: d / (2π·(φ − ξ)) (from Eq. 37)."""
    if not grating_pitch_m > 0:
        raise AnalysisError(f"grating pitch must be positive, got {grating_pitch_m!r} m")
    order_difference = int(orders[0]) - int(orders[1])
    if order_difference == 0:
        raise AnalysisError(f"diffraction orders {orders} must differ (φ − ξ = 0 gives no beat)")
    return grating_pitch_m / (2.0 * np.pi * abs(order_difference))


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

    `bandwidth_hz` None: chosen from the pulse by
    `analysis.differentiating_lowpass.bandwidth_for_rise_time`.
    """
    beat = beat_phase(doppler_v, sample_interval_s, decimated_rate_hz=decimated_rate_for(analysis_rate_hz))
    displacement = beat.phase_rad * metres_per_radian(grating_pitch_m, orders)
    at_rate = displacement_to_rate(displacement, np.zeros(displacement.size), beat.sample_interval_s,
                                   beat.start_time_s, analysis_rate_hz)
    return differentiate(at_rate.reference, at_rate.sample_interval_s, at_rate.start_time_s, beat, bandwidth_hz)
