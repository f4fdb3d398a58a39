"""The true accelerometer of the simulated rig: modes, amplifier low-pass, noise.

A continuous-time model (resonances plus an optional Butterworth amplifier low-pass) whose
discrete poles at sample interval T are exactly exp(s·T). Tests use it as the independent
truth that identification must recover; the simulator uses it to make the response channel.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Annotated

import numpy as np
from pydantic import Field
from scipy import signal

from hopkinson.drivers.sim.config_fields import SECTION, Number


@dataclass(frozen=True)
class Mode:
    """One lightly damped mechanical resonance: natural frequency (Hz) and damping ratio.

    The bounds are those of a sim.toml's [[world.*.modes]] (checked on load only)."""

    __pydantic_config__ = SECTION
    natural_frequency_hz: Annotated[Number, Field(gt=0, le=1e7)]
    damping_ratio: Annotated[Number, Field(gt=0, le=10)]


@dataclass(frozen=True)
class AccelerometerTruth:
    """Known accelerometer + amplifier dynamics, unit DC gain times `sensitivity`.

    modes: mechanical resonances (each a unit-DC-gain second-order low-pass).
    lowpass_hz / lowpass_order: the bridge amplifier's Butterworth filter (0 = none).
    sensitivity: DC gain, response units per m/s² (1.0 for a normalised model).
    """

    modes: tuple[Mode, ...] = (Mode(27_000.0, 0.05),)
    lowpass_hz: float = 0.0
    lowpass_order: int = 2
    sensitivity: float = 1.0
    zero_shift: float = 0.0  # constant offset added to the response (units of the response)

    def continuous_zpk(self) -> tuple[np.ndarray, np.ndarray, float]:
        """Zeros, poles (rad/s) and gain of the continuous model H(s)."""
        poles: list[complex] = []
        gain = self.sensitivity
        for m in self.modes:
            wn = 2 * np.pi * m.natural_frequency_hz
            z = m.damping_ratio
            wd = wn * np.sqrt(max(1 - z * z, 0.0))
            if z < 1:
                poles += [complex(-z * wn, wd), complex(-z * wn, -wd)]
            else:
                r = wn * np.sqrt(z * z - 1)
                poles += [complex(-z * wn + r, 0), complex(-z * wn - r, 0)]
            gain *= wn * wn
        if self.lowpass_hz > 0:
            _, p, k = signal.butter(self.lowpass_order, 2 * np.pi * self.lowpass_hz, analog=True, output="zpk")
            poles += list(p)
            gain *= float(np.real(k))
        return np.array([], dtype=complex), np.array(poles, dtype=complex), float(gain)

    @property
    def order(self) -> int:
        return len(self.continuous_zpk()[1])

    def discrete_poles(self, sample_interval_s: float) -> np.ndarray:
        """The poles exp(s·T) every discretisation of this model shares."""
        return np.exp(self.continuous_zpk()[1] * sample_interval_s)

    def frequency_response(self, frequency_hz: np.ndarray) -> np.ndarray:
        """Complex H(j2πf) of the continuous model."""
        z, p, k = self.continuous_zpk()
        _, h = signal.freqs_zpk(z, p, k, worN=2 * np.pi * np.asarray(frequency_hz, dtype=float))
        return h

    def discrete_tf(self, sample_interval_s: float, method: str = "zoh") -> tuple[np.ndarray, np.ndarray]:
        """Discrete (b, a) in powers of z⁻¹ by scipy's cont2discrete.

        The model is discretised in time units of one sample (s·T), which keeps the state
        matrices O(1); in seconds a 6th-order model's coefficients span ~30 decades and the
        discrete poles come out ~1e-5 off exp(s·T).
        """
        z, p, k = self.continuous_zpk()
        order = len(p)
        scaled = signal.zpk2ss(z * sample_interval_s, p * sample_interval_s, k * sample_interval_s ** (order - len(z)))
        ad, bd, cd, dd, _ = signal.cont2discrete(scaled, 1.0, method=method)
        b, a = signal.ss2tf(ad, bd, cd, dd)
        b = np.atleast_1d(np.squeeze(b))
        return np.real(b) / a[0], np.real(a) / a[0]

    def sections(self, sample_interval_s: float, method: str = "zoh") -> np.ndarray:
        """Second-order sections (scipy `sos`) of the discretised model, one per mode/pair.

        Each continuous section (unit DC gain) is discretised on its own, in time units of one
        sample, so the cascade stays well conditioned at any rate (a 6th-order transfer
        function at 100 MS/s does not: its poles sit within 1e-4 of z = 1). The cascade has
        exactly the poles exp(s·T); it differs from discretising the whole model at once only
        by the hold between sections, O((ωT)²).
        """
        _, poles, _ = self.continuous_zpk()
        rows = []
        remaining = list(poles * sample_interval_s)
        while remaining:
            p = remaining.pop(0)
            if abs(p.imag) > 0:
                partner = min(range(len(remaining)), key=lambda i: abs(remaining[i] - np.conj(p)))
                remaining.pop(partner)
                den = np.real(np.poly([p, np.conj(p)]))
            else:
                real_partner = next((i for i, q in enumerate(remaining) if abs(q.imag) == 0), None)
                pair = [p] if real_partner is None else [p, remaining.pop(real_partner)]
                den = np.real(np.poly(pair))
            num = np.array([den[-1]])  # unit DC gain
            bd, ad, _ = signal.cont2discrete((num, den), 1.0, method=method)
            bd = np.atleast_1d(np.squeeze(bd)) / ad[0]
            ad = ad / ad[0]
            bd = np.pad(bd, (0, 3 - bd.size))  # a first-order section: [b0, b1, 0] over [1, a1, 0]
            ad = np.pad(ad, (0, 3 - ad.size))
            rows.append(np.r_[bd, ad])
        sos = np.array(rows)
        sos[0, :3] *= self.sensitivity
        return sos

    def respond(self, excitation: np.ndarray, sample_interval_s: float, method: str = "zoh") -> np.ndarray:
        """Noise-free response to a sampled excitation (m/s²) starting at rest."""
        sos = self.sections(sample_interval_s, method)
        return signal.sosfilt(sos, np.asarray(excitation, dtype=float)) + self.zero_shift


def white_noise(clean: np.ndarray, snr_db: float, rng: np.random.Generator) -> np.ndarray:
    """White Gaussian noise with power `snr_db` below the power of `clean`."""
    power = float(np.mean(np.square(clean)))
    return rng.standard_normal(clean.shape) * np.sqrt(power / 10 ** (snr_db / 10))


def coloured_noise(
    clean: np.ndarray, snr_db: float, rng: np.random.Generator, pole: float = 0.9
) -> np.ndarray:
    """Low-pass coloured noise (white through 1/(1 − pole·z⁻¹)), scaled to `snr_db` below `clean`."""
    raw = signal.lfilter([1.0], [1.0, -pole], rng.standard_normal(clean.shape))
    power = float(np.mean(np.square(clean)))
    return raw * np.sqrt(power / 10 ** (snr_db / 10) / float(np.mean(np.square(raw))))


def fractional_delay(x: np.ndarray, delay_samples: float) -> np.ndarray:
    """`x` delayed by `delay_samples` (any sign, fractional): a channel skew of the digitizer.

    A linear phase on the FFT of `x` padded with its edge values (records start and end at
    rest, so the circular wrap carries nothing); exact for a band-limited signal.
    """
    x = np.asarray(x, dtype=float)
    pad = int(np.ceil(abs(delay_samples))) + 64
    ext = np.concatenate((np.full(pad, x[0]), x, np.full(pad, x[-1])))
    spec = np.fft.rfft(ext)
    k = np.arange(spec.size)
    spec *= np.exp(-2j * np.pi * k * delay_samples / ext.size)
    if ext.size % 2 == 0:
        spec[-1] = spec[-1].real * np.cos(np.pi * delay_samples)
    return np.fft.irfft(spec, ext.size)[pad : pad + x.size]


def baseline_drift(n: int, sample_interval_s: float, slope_per_s: float, wander_rms: float = 0.0,
                   wander_hz: float = 200.0, rng: np.random.Generator | None = None) -> np.ndarray:
    """A baseline that drifts: a straight line of `slope_per_s` (units per second) plus a slow
    random wander of `wander_rms` (white noise low-passed at `wander_hz`), e.g. thermal drift
    of a bridge or the discharge of a charge amplifier."""
    t = np.arange(n) * sample_interval_s
    out = slope_per_s * t
    if wander_rms > 0:
        rng = np.random.default_rng() if rng is None else rng
        sos = signal.butter(2, wander_hz, fs=1.0 / sample_interval_s, output="sos")
        wander = signal.sosfilt(sos, rng.standard_normal(n))
        out = out + wander * (wander_rms / max(float(np.std(wander)), 1e-300))
    return out
