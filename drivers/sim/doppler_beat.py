"""The photomultiplier (PM) beat of the differential laser Doppler interferometer (simulated truth).

The grating on the calibrated object moves at velocity v(t); two beams diffracted in orders
φ and ξ interfere on the PM, whose signal beats at Δf = v·(φ − ξ)/d (method paper, Eq. 37;
orders ±1 give Δf = 2v/d). The phase of the beat is therefore 2π·(φ − ξ)/d times the
displacement of the grating. On top of the beat the PM shows a DC offset, a slow amplitude
fluctuation (speckle, alignment) and white noise. A quadrature interferometer has a second
photodetector 90° from the first (`pm_beat(..., quadrature=...)`, ISO 16063-11 method 3): same phase and
fluctuation, its own offset, gain and a few degrees of quadrature error (the ellipse the
Heydemann correction undoes).

`raw_shot` builds a whole raw shot (time, Doppler channel, amplifier output) from an
acceleration history and an `AccelerometerTruth`: tests and the simulated rig both use it.

Pure NumPy/SciPy: this module is part of "the world" and imports nothing of analysis or rig.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from hopkinson.drivers.sim import shock
from hopkinson.drivers.sim.accelerometer import AccelerometerTruth, white_noise

# Grating pitch d of the simulated interferometer: 2 µm (500 lines/mm). With orders ±1 the
# beat is 2v/d = 1 MHz per m/s: 25 m/s (100 000 g over the 38.6 µs pulse of projectile
# No. 3) beats at 25 MHz and the rig's ceiling of ~30 m/s at 30 MHz, i.e. 30 % of a
# 100 MS/s digitizer, safely below the 40 % the anti-alias margin allows.
DEFAULT_GRATING_PITCH_M = 2.0e-6
DEFAULT_ORDERS = (1, -1)
DEFAULT_SAMPLE_INTERVAL_S = 1.0e-8  # 100 MS/s


def beat_frequency_hz(velocity_m_s: np.ndarray | float, grating_pitch_m: float = DEFAULT_GRATING_PITCH_M,
                      orders: tuple[int, int] = DEFAULT_ORDERS) -> np.ndarray | float:
    """Doppler beat frequency Δf = v·(φ − ξ)/d in Hz (Eq. 37), signed like the velocity."""
    return np.asarray(velocity_m_s) * (orders[0] - orders[1]) / grating_pitch_m


@dataclass(frozen=True)
class QuadratureOutput:
    """The second photodetector of a quadrature interferometer, against the first (the PM beat).

    u1 = p + r·e(t)·cos φ (the PM beat), u2 = q + gain_ratio·r·e(t)·sin(φ − α): offset_v = q,
    gain_ratio = its amplitude ÷ the first's (Heydemann's G = 1/gain_ratio), phase_error_rad = α
    (0: exactly 90° apart). Real detectors: offsets of 0.1 V, gains a few to 15 % apart, a few
    degrees of quadrature error (ISO 16063-11, method 3).
    """

    offset_v: float = 0.12
    gain_ratio: float = 0.85
    phase_error_rad: float = float(np.deg2rad(4.0))


def pm_beat(
    velocity_m_s: np.ndarray,
    sample_interval_s: float,
    grating_pitch_m: float = DEFAULT_GRATING_PITCH_M,
    orders: tuple[int, int] = DEFAULT_ORDERS,
    *,
    amplitude_v: float = 0.4,
    dc_offset_v: float = 0.15,
    fluctuation: float = 0.1,
    fluctuation_hz: float = 1_000.0,
    snr_db: float | None = 30.0,
    initial_phase_rad: float | None = None,
    rng: np.random.Generator | None = None,
    quadrature: QuadratureOutput | None = None,
    quadrature_rng: np.random.Generator | None = None,
) -> np.ndarray:
    """The PM signal in volts for a sampled velocity history (m/s) of the grating.

    phase(t) = φ0 + 2π·(φ − ξ)/d·∫v dt (cumulative trapezoid, exact for piecewise-linear v);
    signal = dc_offset_v + amplitude_v·(1 + fluctuation·sin(2π·fluctuation_hz·t + θ))·cos(phase)
    plus white noise `snr_db` below the power of the beat (None: no noise).
    `initial_phase_rad` is the beat's phase at rest (None: drawn uniformly from `rng`);
    θ is drawn from `rng` too. `rng` None uses a fresh unseeded generator.

    With `quadrature` (a quadrature interferometer): a (2, n) array, the PM signal (the same as
    without, for the same `rng`) and its quadrature partner (`QuadratureOutput`): same phase
    and fluctuation, its own white noise at the same SNR against its own beat power, drawn
    from `quadrature_rng` (None: a fresh generator). `u1, u2 = pm_beat(..., quadrature=...)`.
    """
    if sample_interval_s <= 0:
        raise ValueError("sample_interval_s must be positive")
    if grating_pitch_m <= 0:
        raise ValueError("grating_pitch_m must be positive")
    if orders[0] == orders[1]:
        raise ValueError("the two diffraction orders must differ")
    rng = np.random.default_rng() if rng is None else rng
    v = np.asarray(velocity_m_s, dtype=float)
    wavenumber_rad_m = 2.0 * np.pi * (orders[0] - orders[1]) / grating_pitch_m
    displacement_m = velocity_m_s_to_displacement_m(v, sample_interval_s)
    phi0 = rng.uniform(0.0, 2.0 * np.pi) if initial_phase_rad is None else float(initial_phase_rad)
    theta = rng.uniform(0.0, 2.0 * np.pi)
    t = sample_interval_s * np.arange(v.size)
    envelope = amplitude_v * (1.0 + fluctuation * np.sin(2.0 * np.pi * fluctuation_hz * t + theta))
    phase = phi0 + wavenumber_rad_m * displacement_m
    beat = envelope * np.cos(phase)
    # Noise relative to the beat's own power (A²/2), not to the DC offset.
    noise_rms = 0.0 if snr_db is None else float(np.sqrt(np.mean(np.square(envelope)) / 2.0 / 10 ** (snr_db / 10)))
    if snr_db is not None:
        beat = beat + rng.standard_normal(v.size) * noise_rms
    if quadrature is None:
        return dc_offset_v + beat
    second = quadrature.gain_ratio * envelope * np.sin(phase - quadrature.phase_error_rad)
    if snr_db is not None:
        q_rng = np.random.default_rng() if quadrature_rng is None else quadrature_rng
        second = second + q_rng.standard_normal(v.size) * (noise_rms * quadrature.gain_ratio)
    return np.stack((dc_offset_v + beat, quadrature.offset_v + second))


def velocity_m_s_to_displacement_m(velocity_m_s: np.ndarray, sample_interval_s: float) -> np.ndarray:
    """Displacement (m) from rest: the cumulative trapezoid of shock.velocity_m_s, one level up."""
    return shock.velocity_m_s(velocity_m_s, sample_interval_s)


@dataclass(frozen=True)
class RawShot:
    """A simulated raw shot at the digitizer's rate, with the truth it was made from.

    doppler_v: PM beat (V); response_v: bridge-amplifier output (V) =
    amp_gain · sensitivity_v_per_m_s2 · (accelerometer dynamics applied to the acceleration).
    """

    sample_interval_s: float
    doppler_v: np.ndarray
    response_v: np.ndarray
    acceleration_m_s2: np.ndarray  # true reference acceleration
    velocity_m_s: np.ndarray  # true grating velocity
    grating_pitch_m: float
    orders: tuple[int, int]
    amp_gain: float
    sensitivity_v_per_m_s2: float
    truth: AccelerometerTruth

    @property
    def time_s(self) -> np.ndarray:
        return self.sample_interval_s * np.arange(self.doppler_v.size)


def raw_shot(
    acceleration_m_s2: np.ndarray,
    truth: AccelerometerTruth,
    sample_interval_s: float = DEFAULT_SAMPLE_INTERVAL_S,
    *,
    amp_gain: float = 100.0,
    sensitivity_v_per_m_s2: float = 1.0e-8,
    grating_pitch_m: float = DEFAULT_GRATING_PITCH_M,
    orders: tuple[int, int] = DEFAULT_ORDERS,
    doppler_snr_db: float | None = 30.0,
    response_snr_db: float | None = 50.0,
    rng: np.random.Generator | None = None,
    **beat_options: float,
) -> RawShot:
    """A raw shot from a sampled acceleration history (m/s², object at rest at the start).

    The response is `truth` (its modes, low-pass, zero shift; its own `sensitivity` is taken
    as a dimensionless shape factor, normally 1) times the nominal sensitivity (V per m/s²,
    default 10 nV/(m/s²) ≈ 0.1 µV/g, a piezoresistive 100 000 g sensor) times the amplifier
    gain, plus white noise `response_snr_db` below it. `beat_options` go to `pm_beat`.
    """
    rng = np.random.default_rng() if rng is None else rng
    acc = np.asarray(acceleration_m_s2, dtype=float)
    vel = shock.velocity_m_s(acc, sample_interval_s)
    doppler = pm_beat(vel, sample_interval_s, grating_pitch_m, orders, snr_db=doppler_snr_db, rng=rng,
                      **beat_options)
    response = truth.respond(acc, sample_interval_s) * sensitivity_v_per_m_s2 * amp_gain
    if response_snr_db is not None:
        response = response + white_noise(response, response_snr_db, rng)
    return RawShot(sample_interval_s, doppler, response, acc, vel, grating_pitch_m, tuple(orders),
                   amp_gain, sensitivity_v_per_m_s2, truth)


def interferometer_noise_m_s2(n: int, sample_interval_s: float, rms_m_s2: float, bandwidth_hz: float,
                              rng: np.random.Generator | None = None) -> np.ndarray:
    """The noise an interferometer reference carries in acceleration: white phase (displacement)
    noise differentiated twice — its spectrum rises as f² — up to the demodulation low-pass of
    `bandwidth_hz` (brick-wall), scaled to `rms_m_s2`."""
    rng = np.random.default_rng() if rng is None else rng
    spec = np.fft.rfft(rng.standard_normal(n))
    f = np.fft.rfftfreq(n, sample_interval_s)
    spec *= (f / bandwidth_hz) ** 2 * (f <= bandwidth_hz)
    x = np.fft.irfft(spec, n)
    return x * (rms_m_s2 / max(float(np.std(x)), 1e-300))
