"""What makes a simulated record look like a real one: the pulse source and the
effects a real Hopkinson-bar record shows, each with its own switch and size ([world.realism] in
config/sim.toml), all recorded in the shot's truth.

The pulse source (`PulseSource`): projectile + reservoir pressure (+ a shot-to-shot factor on the
projectile's speed) -> the acceleration of the calibrated object (`PulseShape`). `IdealPulseSource`
is the closed-form pulse of the older simulator (a half-sine, or a bipolar pulse, of the
projectile's tabulated width, peak π·Δv/(2δ), speed k·√p); `bar_source.BarPulseSource` is the
bar model of the analysis layer (`pulse_source = "bar"`).

The effects, on the simulator's internal grid (t = 0 at the pulse's start), with peak P:

- **bar motion after the pulse** (`BarRingingParams`): a sum of damped sines at 1–30 kHz
  (the bar's and the base's own modes), `amplitude_rel`·P, decaying with `decay_s` (> 1 ms),
  rising smoothly from the pulse's end; the interferometer's spot sees it whole, the sensor's
  base × `base_gain` (0.75–0.96: the end face's radial profile, rocking with the spot's offset);
- **the mount** (`MountParams`): base compliance raises the sensor's resonance by
  `frequency_ratio` over its sine-calibrated value; the sensor's gain in tension (a < 0) is
  `asymmetry_rel` lower than in compression;
- **a transverse drive** (`TransverseParams`): a lateral acceleration burst at the impact (a
  dipole: the end face rocks out and back; `lateral_width_s`, `lateral_peak_rel`·P) reaches the
  sensor's mode through its transverse sensitivity `sensitivity_rel`: a ringing the reference
  does not show;
- **the reference chain** (`ReferenceChainParams`): interferometer noise rising as f² (its rms
  `noise_rel`·P in flight, `flight_noise_factor` times less at rest), the demodulator's
  Butterworth low-pass, a delay of the reference against the response, and demodulation errors
  at the onset (phase glitches and a dip of the beat's amplitude while the object jerks away).

Pure NumPy/SciPy; part of the simulated world.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from typing import Annotated, Any, Literal, Protocol

import numpy as np
from pydantic import Field
from scipy import signal

from hopkinson.analysis.bar.geometry import MOUNTS
from hopkinson.drivers.sim.accelerometer import fractional_delay
from hopkinson.drivers.sim.config_fields import SECTION, Flag, Int, Number
from hopkinson.drivers.sim.doppler_beat import interferometer_noise_m_s2
from hopkinson.drivers.sim.shock import bipolar_m_s2, bipolar_velocity_m_s, velocity_m_s

PULSE_SOURCES = ("ideal", "bar")


Rel = Annotated[Number, Field(ge=0, le=0.5)]
Positive = Annotated[Number, Field(gt=0)]


@dataclass(frozen=True)
class BarRingingParams:
    """[world.realism.bar_ringing]: bar motion after the pulse, seen by the spot (whole) and the
    sensor's base (× base_gain)."""

    __pydantic_config__ = SECTION
    enabled: Flag = True
    amplitude_rel: Annotated[Rel, Field(description="largest value of the ringing ÷ the pulse's peak")] = 0.015
    frequencies_hz: tuple[Annotated[Number, Field(gt=0, le=1e6)], ...] = (2_300.0, 6_900.0, 12_400.0, 17_900.0,
                                                                          23_600.0)
    decay_s: Annotated[Positive, Field(description="1/e time of each mode's envelope")] = 1.5e-3
    rise_s: Annotated[Positive, Field(description="smooth start after the pulse's end")] = 20e-6
    base_gain: Annotated[Number, Field(ge=0, le=2, description="what the sensor's base sees ÷ what the spot "
                                                               "sees")] = 0.85


@dataclass(frozen=True)
class MountParams:
    """[world.realism.mount]: the sensor's mounting: a stiffer-than-sine resonance and a
    tension/compression asymmetry."""

    __pydantic_config__ = SECTION
    enabled: Flag = True
    frequency_ratio: Annotated[Number, Field(ge=0.5, le=2, description="mounted resonance ÷ sine-calibrated "
                                                                      "resonance")] = 1.10
    asymmetry_rel: Annotated[Number, Field(ge=-0.5, le=0.5, description="relative gain lost in tension "
                                                                        "(a < 0)")] = 0.02


@dataclass(frozen=True)
class TransverseParams:
    """[world.realism.transverse]: a second drive path into the sensor's mode: lateral motion ×
    transverse sensitivity."""

    __pydantic_config__ = SECTION
    enabled: Flag = True
    sensitivity_rel: Annotated[Rel, Field(description="transverse sensitivity ÷ axial (1–5 %)")] = 0.03
    lateral_peak_rel: Annotated[Number, Field(ge=0, le=100, description="peak lateral acceleration ÷ the axial "
                                                                        "peak")] = 3.5
    lateral_width_s: Annotated[Positive, Field(description="its time scale (the velocity pulse's standard "
                                                           "deviation)")] = 3e-6
    lateral_delay_s: Annotated[Positive, Field(description="its centre after the pulse's start")] = 4e-6


@dataclass(frozen=True)
class ReferenceChainParams:
    """[world.realism.reference]: the interferometer's errors: f² noise, the demodulator's
    low-pass, a delay, onset errors."""

    __pydantic_config__ = SECTION
    noise: Flag = True
    noise_rel: Annotated[Rel, Field(description="rms of the reference's acceleration noise in flight ÷ the "
                                                "peak")] = 0.004
    flight_noise_factor: Annotated[Number, Field(ge=1, le=1000, description="in flight ÷ at rest")] = 6.0
    noise_bandwidth_hz: Positive = 2.0e6
    lowpass: Flag = True
    lowpass_hz: Positive = 200_000.0
    lowpass_order: Annotated[Int, Field(ge=1, le=8)] = 2
    delay: Flag = True
    delay_s: Annotated[Number, Field(ge=-1e-5, le=1e-5, description="the reference later than the response "
                                                                    "(0.2–0.9 µs)")] = 0.5e-6
    onset_errors: Flag = True
    onset_glitches: Annotated[Int, Field(ge=0, le=100, description="phase glitches in the first "
                                                                   "onset_window_s")] = 3
    onset_glitch_rad: Annotated[Number, Field(ge=0, le=100, description="each one's size (sign drawn)")] = 1.0
    onset_window_s: Positive = 4e-6
    onset_dip: Annotated[Number, Field(ge=0, le=0.99, description="the beat's amplitude drops by this fraction "
                                                                  "at the onset")] = 0.7


@dataclass(frozen=True)
class RealismParams:
    """[world.realism]: `enabled` false is the idealised world (closed-form pulses, no effect)."""

    __pydantic_config__ = SECTION
    enabled: Flag = False
    pulse_source: Annotated[Literal["ideal", "bar"], Field(description=(
        "ideal: the closed form of [world.launcher]; bar: the bar model of hopkinson.analysis.bar"))] = "ideal"
    bar_mount: Annotated[Literal["separating", "bonded"], Field(description=(
        "with bar: how the object sits on the bar's end (analysis.bar.geometry.MOUNTS)"))] = "bonded"
    speed_scatter_rel: Annotated[Number, Field(ge=0, le=0.2, description="shot-to-shot scatter of the "
                                                                         "projectile's speed (1σ)")] = 0.01
    bar_ringing: BarRingingParams = field(default_factory=BarRingingParams)
    mount: MountParams = field(default_factory=MountParams)
    transverse: TransverseParams = field(default_factory=TransverseParams)
    reference: ReferenceChainParams = field(default_factory=ReferenceChainParams)

    def __post_init__(self) -> None:
        if self.pulse_source not in PULSE_SOURCES:
            raise ValueError(f"pulse_source must be one of {', '.join(PULSE_SOURCES)}, got {self.pulse_source!r}")
        if self.bar_mount not in MOUNTS:
            raise ValueError(f"bar_mount must be one of {', '.join(MOUNTS)}, got {self.bar_mount!r}")

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)


# -- pulse sources ------------------------------------------------------------------------------
@dataclass(frozen=True)
class PulseShape:
    """The object's acceleration for one shot: summary figures and the history itself."""

    speed_m_s: float  # the projectile's speed at impact
    delta_v_m_s: float  # the object's velocity change over the pulse
    peak_m_s2: float
    width_s: float  # the pulse's duration (zero to zero; a tabulated pulse's: above 10 % of its peak)
    acceleration: Callable[[np.ndarray], np.ndarray]  # t (s from the pulse's start) -> m/s²
    velocity: Callable[[np.ndarray], np.ndarray]  # its exact integral from rest (m/s)
    shape: str = "half_sine"
    bipolar_ratio: float = 0.0

    def acceleration_m_s2(self, time_s: np.ndarray) -> np.ndarray:
        return self.acceleration(np.asarray(time_s, dtype=float))

    def velocity_m_s(self, time_s: np.ndarray) -> np.ndarray:
        return self.velocity(np.asarray(time_s, dtype=float))


class PulseSource(Protocol):
    """projectile + pressure (+ a factor on the projectile's speed) -> the object's pulse."""

    name: str

    def pulse(self, projectile: int, pressure_bar: float, speed_factor: float = 1.0) -> PulseShape: ...


@dataclass(frozen=True)
class IdealPulseSource:
    """The closed-form pulse: speed k·√p, Δv = transfer·speed, a half-sine (or bipolar) of the
    projectile's tabulated width and peak π·Δv/(2δ)."""

    speed_m_s_per_sqrt_bar: float
    velocity_transfer: float
    pulse_width_s: tuple[float, ...]
    bipolar_ratio: float = 0.0
    name: str = "ideal"

    def pulse(self, projectile: int, pressure_bar: float, speed_factor: float = 1.0) -> PulseShape:
        speed = self.speed_m_s_per_sqrt_bar * math.sqrt(pressure_bar) * speed_factor
        delta_v = self.velocity_transfer * speed
        width = self.pulse_width_s[projectile - 1]
        peak = math.pi * delta_v / (2.0 * width)
        ratio = self.bipolar_ratio
        return PulseShape(speed, delta_v, peak, width,
                          lambda t: bipolar_m_s2(t, width, peak, 0.0, ratio),
                          lambda t: bipolar_velocity_m_s(t, width, peak, 0.0, ratio),
                          "bipolar" if ratio else "half_sine", ratio)


TABULATED_WIDTH_REL = 0.1
TABULATED_START_REL = 0.01


def tabulated_pulse(time_s: np.ndarray, acceleration_m_s2: np.ndarray, speed_m_s: float,
                    shape: str = "bar_model") -> PulseShape:
    """A PulseShape from a sampled acceleration (zero outside the samples). Its start (t = 0,
    where the effects timed from the pulse's start are anchored: the onset errors, the lateral
    kick, the flight noise) is the first sample above TABULATED_START_REL of the peak; what comes
    before (a dispersed front's precursor) stays, at negative times. Its duration runs from there
    to the last sample above TABULATED_WIDTH_REL of the peak: both lobes of a bipolar pulse, not
    the bar's dispersion ripple trailing it (which is motion after the pulse, like the ringing
    added there)."""
    a = np.asarray(acceleration_m_s2, dtype=float)
    peak_index = int(np.argmax(np.abs(a)))
    level = abs(a[peak_index])
    start = int(np.flatnonzero(np.abs(a) > TABULATED_START_REL * level)[0]) if level > 0 else 0
    t = np.asarray(time_s, dtype=float) - float(time_s[start])
    v = velocity_m_s(a, float(t[1] - t[0]))
    above = np.flatnonzero(np.abs(a) > TABULATED_WIDTH_REL * level)
    width = float(t[above[-1]]) if above.size else 0.0
    return PulseShape(speed_m_s, float(v[-1]), float(a[peak_index]), width,
                      lambda x: np.interp(x, t, a, left=0.0, right=0.0),
                      lambda x: np.interp(x, t, v, left=0.0, right=float(v[-1])), shape)


# -- the effects -------------------------------------------------------------------------------
@dataclass(frozen=True)
class ShotMotion:
    """One shot's motions on the internal grid `time_s` (0 = the pulse's start)."""

    time_s: np.ndarray
    spot_m_s2: np.ndarray  # the interferometer spot's true acceleration
    base_m_s2: np.ndarray  # the sensor's base (axial)
    lateral_m_s2: np.ndarray  # the sensor's lateral acceleration (drives its mode transversely)
    measured_reference_m_s2: np.ndarray  # the spot's acceleration as the reference chain reports it
    beat_gain: np.ndarray  # the PM beat's amplitude factor (1 outside the onset)
    drawn: dict[str, Any]  # what was drawn for this shot (truth)


def ringing_m_s2(time_s: np.ndarray, pulse: PulseShape, p: BarRingingParams, rng: np.random.Generator
                 ) -> tuple[np.ndarray, dict[str, Any]]:
    """The bar's motion after the pulse at the spot, its largest value amplitude_rel·|peak|."""
    t = np.asarray(time_s, dtype=float)
    after = np.clip(t - pulse.width_s, 0.0, None)
    rise = np.where(t > pulse.width_s, 1.0 - np.exp(-after / p.rise_s), 0.0)
    phases = rng.uniform(0.0, 2 * np.pi, len(p.frequencies_hz))
    weights = rng.uniform(0.5, 1.0, len(p.frequencies_hz))
    x = sum(w * np.sin(2 * np.pi * f * after + ph) for f, w, ph in zip(p.frequencies_hz, weights, phases, strict=True))
    x = np.asarray(x) * rise * np.exp(-after / p.decay_s)
    top = float(np.max(np.abs(x))) if x.size else 0.0
    scale = p.amplitude_rel * abs(pulse.peak_m_s2) / top if top > 0 else 0.0
    return x * scale, {"phases_rad": phases.tolist(), "weights": weights.tolist()}


def lateral_m_s2(time_s: np.ndarray, pulse: PulseShape, p: TransverseParams) -> np.ndarray:
    """The lateral acceleration burst at the impact: the end face rocks out and back (a Gaussian
    velocity pulse, so a dipole of acceleration: no lateral velocity is left, no DC content)."""
    u = (np.asarray(time_s, dtype=float) - p.lateral_delay_s) / p.lateral_width_s
    return p.lateral_peak_rel * pulse.peak_m_s2 * (-u) * np.exp(0.5 * (1.0 - u * u))


def reference_chain_m_s2(time_s: np.ndarray, spot_m_s2: np.ndarray, peak_m_s2: float, p: ReferenceChainParams,
                         rng: np.random.Generator, wavenumber_rad_m: float) -> tuple[np.ndarray, dict[str, Any]]:
    """The spot's acceleration as the interferometer reports it: delayed, low-passed, with the
    f² noise (flight_noise_factor times stronger once the object moves) and onset glitches (a
    phase glitch of Δφ is a displacement step Δφ/k, k = `wavenumber_rad_m` of the beat)."""
    t = np.asarray(time_s, dtype=float)
    dt = float(t[1] - t[0])
    out = np.asarray(spot_m_s2, dtype=float).copy()
    drawn: dict[str, Any] = {}
    if p.delay and p.delay_s:
        out = fractional_delay(out, p.delay_s / dt)
    if p.lowpass and p.lowpass_hz > 0:
        sos = signal.butter(p.lowpass_order, p.lowpass_hz, fs=1.0 / dt, output="sos")
        out = signal.sosfilt(sos, out)
    if p.onset_errors and p.onset_glitches > 0:
        # A phase glitch of Δφ is a displacement step Δφ/k of the grating: here a velocity
        # impulse of the step's size, i.e. an acceleration doublet (a spike and its recoil).
        times = np.sort(rng.uniform(0.0, p.onset_window_s, p.onset_glitches))
        signs = rng.choice([-1.0, 1.0], p.onset_glitches)
        drawn["onset_glitch_times_s"] = times.tolist()
        drawn["onset_glitch_signs"] = signs.tolist()
        width = 0.3e-6  # three samples of the internal grid: a glitch as fast as it can show
        for t0, sign in zip(times, signs, strict=True):
            u = (t - t0) / width
            step_m = sign * p.onset_glitch_rad / wavenumber_rad_m
            # d²/dt² of a smooth displacement step step_m·Φ(u): a doublet, -u·φ(u)/width²
            out += step_m * (-u) * np.exp(-0.5 * u * u) / math.sqrt(2 * math.pi) / width**2
    if p.noise and p.noise_rel > 0:
        noise = interferometer_noise_m_s2(t.size, dt, 1.0, min(p.noise_bandwidth_hz, 0.5 / dt), rng)
        moving = np.clip(t / 2e-6, 0.0, 1.0)  # from rest to flight over the first 2 µs
        envelope = (1.0 + (p.flight_noise_factor - 1.0) * moving) / p.flight_noise_factor
        out += noise * envelope * p.noise_rel * abs(peak_m_s2)
    return out, drawn


def onset_beat_gain(time_s: np.ndarray, p: ReferenceChainParams) -> np.ndarray:
    """The PM beat's amplitude factor: a dip of onset_dip over the onset window."""
    t = np.asarray(time_s, dtype=float)
    if not (p.onset_errors and p.onset_dip > 0):
        return np.ones_like(t)
    centre, width = 0.5 * p.onset_window_s, 0.35 * p.onset_window_s
    return 1.0 - p.onset_dip * np.exp(-0.5 * ((t - centre) / width) ** 2)


def shot_motion(time_s: np.ndarray, pulse: PulseShape, params: RealismParams, rng: np.random.Generator,
                wavenumber_rad_m: float) -> ShotMotion:
    """Every motion of one shot on `time_s` (the pulse starts at 0), with the effects switched on."""
    t = np.asarray(time_s, dtype=float)
    clean = pulse.acceleration_m_s2(t)
    spot, base = clean.copy(), clean.copy()
    drawn: dict[str, Any] = {}
    if params.bar_ringing.enabled:
        ring, drawn["bar_ringing"] = ringing_m_s2(t, pulse, params.bar_ringing, rng)
        spot += ring
        base += params.bar_ringing.base_gain * ring
    lateral = lateral_m_s2(t, pulse, params.transverse) if params.transverse.enabled else np.zeros_like(t)
    measured, drawn["reference"] = reference_chain_m_s2(t, spot, pulse.peak_m_s2, params.reference, rng,
                                                        wavenumber_rad_m)
    return ShotMotion(t, spot, base, lateral, measured, onset_beat_gain(t, params.reference), drawn)


def mounted_input_m_s2(base_m_s2: np.ndarray, mount: MountParams, nonlinearity_per_m_s2: float = 0.0
                       ) -> np.ndarray:
    """What the sensor's seismic mass is driven by: the base's acceleration with the sensor's
    amplitude non-linearity (sensitivity × (1 + c·|a|)) and the mount's tension loss."""
    a = np.asarray(base_m_s2, dtype=float)
    out = a * (1.0 + nonlinearity_per_m_s2 * np.abs(a)) if nonlinearity_per_m_s2 else a
    if mount.enabled and mount.asymmetry_rel:
        out = np.where(a < 0, out * (1.0 - mount.asymmetry_rel), out)
    return out
