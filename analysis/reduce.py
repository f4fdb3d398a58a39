"""Raw shot → two-channel record: the interferometer reduction and the shock quantities.

A raw shot is channels sampled together by the digitizer (~100 MS/s): the interferometer's
photodetector(s) and one or more sensors' amplifier outputs (V). `reduce_raw` gives the
record `identify` reads (time_s, reference in m/s², response) at the analysis rate:

1. Reference phase (`reference_phase`), box-car decimated by M raw samples, from either
   - the photomultiplier beat of the differential Doppler interferometer alone (method
     "pm_beat", `analysis.beat_phase.beat_phase`), or
   - a quadrature interferometer's two photodetectors 90° apart (method "quadrature", ISO
     16063-11 method 3 / 16063-13): `analysis.quadrature.demodulate_quadrature`, the
     arctangent after the Heydemann ellipse correction (offsets, unequal gains, quadrature
     error fitted on the record's samples in motion), at the raw rate, then the same M-sample
     box-car.
     The doppler channel is the first detector (∝ cos φ), doppler_quadrature the second
     (∝ sin φ). A quadrature pair tells the direction of motion; the reduction reports the
     motion positive in the direction the object leaves rest, as the single-channel beat does.
   Both give the same phase (2π·(φ − ξ)/d per metre of grating displacement), so everything
   after this step is shared.
2. Response: zero offset removed (mean of the pre-trigger part, before the motion begins),
   scaled from volts to m/s² by 1/(amplifier gain × nominal sensitivity) (both 1: stays in
   V), and box-car decimated by the same M samples as the phase.
3. Both channels go to the analysis rate together (`analysis.resample.resample_to_rate`: one
   anti-alias filter for both). The displacement becomes velocity and acceleration through the
   differentiating low-pass of bandwidth B (chosen from the pulse, reported); the response gets
   the same low-pass L, so the record relates them by the accelerometer's dynamics alone.
4. Delay of the response behind the reference: estimated by cross-correlation
   (`estimate_delay_samples`) and reported. Both channels come from one digitizer and the
   filters above are zero-phase, so what it measures is the accelerometer's (and the
   amplifier's) own group delay, which belongs to the model `identify` fits: the response is
   shifted only when `align=True` (e.g. channels from two instruments with a known skew).

Several sensors recorded with one reference (`reduce_sensors`, e.g. roles response and
response_2) share step 1 and the low-pass of step 3 (the first sensor's bandwidth), so their
records have one reference acceleration and one time axis.

Shock quantities: peak reference acceleration and pulse width at 10 % of peak (ISO 16063-22,
`analysis.excitation.pulse_width`), peak velocity change (flight velocity minus rest, 0), and
the shock sensitivity (ISO 16063-13): the response's peak ÷ the reference's peak, in the
response's units per m/s²; also in V/(m/s²) at the amplifier input. The quantities name the
interferometer method and, for a quadrature pair, the fitted ellipse.

Raw input files (`read_raw_table`): CSV with header `time_s,doppler,response` (and optionally
`doppler_quadrature`) or NPZ with those keys. The HDF5 shot file is read by the command
(rig.shotfile), which passes arrays.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from hopkinson.analysis.beat_phase import (
    DECIMATED_RATE_HZ,
    BeatPhase,
    beat_phase,
    decimated_rate_for,
)
from hopkinson.analysis.channel_content import beat_content, pulse_content
from hopkinson.analysis.differentiating_lowpass import (
    Demodulated,
    differentiate,
    displacement_to_rate,
    lowpass,
)
from hopkinson.analysis.doppler import metres_per_radian
from hopkinson.analysis.errors import AnalysisError, RecordError
from hopkinson.analysis.excitation import PulseWidth, peak_estimate, pulse_width
from hopkinson.analysis.full_scale import FullScale, check_not_clipped
from hopkinson.analysis.options import DEFAULT_GRATING_PITCH_M
from hopkinson.analysis.quadrature import demodulate_quadrature
from hopkinson.analysis.records import Record, column_names, read_columns, validated_columns
from hopkinson.analysis.resample import (
    DEFAULT_ANALYSIS_RATE_HZ,
    estimate_delay_samples,
    shift_samples,
)
from hopkinson.analysis.sample_counts import floor_count

RAW_KEYS = ("time_s", "doppler", "response")
QUADRATURE_KEY = "doppler_quadrature"  # the optional column of a quadrature interferometer
PRE_TRIGGER_MARGIN_S = 2e-6  # the zero offset is taken up to this long before the motion
MIN_PRE_TRIGGER_SAMPLES = 100  # fewer pre-trigger samples cannot give a zero offset
MAX_DELAY_S = 50e-6  # the delay search spans ±this
PM_BEAT, QUADRATURE = "pm_beat", "quadrature"  # the interferometer methods
# Quadrature onset: the phase has certainly left rest once it is half a fringe away; it left
# rest after the last block within max(ONSET_NOISE_FACTOR × its rest noise, ONSET_MIN_RAD).
ONSET_NOISE_FACTOR = 5.0
ONSET_MIN_RAD = 0.05
# The direction of motion is read where the phase has moved this many fringes from rest: an
# interferometer's phase glitches at the onset (steps of a fraction of a fringe to a few: the
# simulator's six of 2 rad reach ±12 rad) moved it half a fringe first and turned the whole
# reference over (a DC gain of −1× the truth on 17 of 40 shots), where a bar's pulse moves the
# object by tens of fringes or more (1 m/s for 20 µs: 60 fringes at 633 nm).
DIRECTION_FRINGES = 8
# One photodetector's beat gives the speed, not its sign: a velocity that falls back below this
# share of its peak after the pulse (a mount that keeps the sensor on the bar, whose velocity
# returns to rest and rings about it) may have passed through rest, where the sign is lost (a
# separating mount's stays within 3 % of its peak; a bonded one's fell to 0.0 %).
RETURN_TO_REST_SHARE = 0.5
MAX_PHASE_STEP_RAD = 0.75 * math.pi  # mean phase step per raw sample a quadrature record may reach
# The ellipse is fitted again on the samples in motion (the phase moves more than MOTION_MIN_RAD
# over MOTION_WINDOW_SAMPLES), when there are at least MIN_FIT_SAMPLES of them.
MOTION_WINDOW_SAMPLES = 64
MOTION_MIN_RAD = math.pi / 4
MIN_FIT_SAMPLES = 1000


@dataclass(frozen=True)
class RawTable:
    """A raw shot read from a table file: uniform sample interval, channels in volts."""

    sample_interval_s: float
    start_time_s: float
    doppler_v: np.ndarray
    response_v: np.ndarray
    quadrature_v: np.ndarray | None = None  # a quadrature interferometer's second photodetector


@dataclass(frozen=True)
class ReferencePhase:
    """The interferometer's phase, box-car decimated by `decimation` raw samples, and how it
    was found. phase_rad[k] is the mean over raw samples k·M … k·M + M − 1 (0 at rest,
    increasing with the motion), at start_time_s + k·sample_interval_s relative to the raw
    record's first sample."""

    method: str  # PM_BEAT or QUADRATURE
    sample_interval_s: float
    start_time_s: float
    phase_rad: np.ndarray
    decimation: int
    onset_time_s: float  # where the motion leaves rest, relative to the raw record's first sample
    peak_fringe_hz: float  # highest fringe (beat) frequency of the record
    beat: BeatPhase | None = None  # PM_BEAT: the beat's demodulation
    quadrature: dict[str, Any] | None = None  # QUADRATURE: the fitted ellipse (JSON-ready)

    def quantities(self) -> dict[str, Any]:
        return {
            "interferometer": self.method,
            "beat_peak_hz": self.peak_fringe_hz,
            "beat_snr_db": self.beat.snr_db if self.beat is not None else None,
            "quadrature": dict(self.quadrature) if self.quadrature is not None else None,
        }


def interferometer_text(quantities: dict[str, Any]) -> str:
    """How a reduction's reference was demodulated, in words (from its `quantities()`): the
    method and, for a quadrature pair, the ellipse the Heydemann correction fitted."""
    q = quantities.get("quadrature")
    if quantities.get("interferometer") != QUADRATURE or not isinstance(q, dict):
        return "PM beat (single channel)"
    return (f"quadrature pair, Heydemann ellipse: offsets {1e3 * q['offset_1_v']:.1f} / {1e3 * q['offset_2_v']:.1f} mV, "
            f"amplitude ratio {q['amplitude_ratio']:.4f}, quadrature error {q['phase_error_deg']:.2f} deg")


@dataclass(frozen=True)
class SensorChannel:
    """One sensor's amplifier output (V) and how to scale it to m/s² (both 1: stays in V)."""

    response_v: np.ndarray
    amp_gain: float = 1.0
    sensitivity_v_per_m_s2: float = 1.0


@dataclass(frozen=True)
class Reduction:
    """The reduced shot: the record at the analysis rate and what the reduction measured."""

    record: Record  # time_s, reference (m/s²), response (m/s² or V), at the analysis rate
    velocity_m_s: np.ndarray  # grating velocity on the record's time axis
    peak_velocity_m_s: float  # by `peak_velocity` (unbiased by noise)
    peak_velocity_noise_u_m_s: float  # its standard uncertainty from the velocity's noise
    peak_acceleration_m_s2: float
    pulse_width_s: float
    delay_s: float
    aligned: bool
    shock_sensitivity: float  # response units per m/s²
    shock_sensitivity_v_per_m_s2: float  # volts at the amplifier input per m/s²
    response_unit: str  # "m/s^2" when scaled by gain and sensitivity, else "V"
    response_offset_v: float
    demodulation_bandwidth_hz: float
    onset_time_s: float  # where the grating leaves rest, on the record's time axis
    reference: ReferencePhase

    @property
    def beat(self) -> BeatPhase | None:
        """The PM beat's demodulation (None for a quadrature interferometer)."""
        return self.reference.beat

    def check_direction_known(self, source: str) -> None:
        """AnalysisError where the reference's direction of motion is not known everywhere: one
        photodetector (the PM beat) whose velocity falls back towards rest after the pulse
        (`check_speed_keeps_its_sign`). Called where figures are made from the record (the
        analysis of a raw shot, `hopkinson reduce`), not by the reduction itself, which the
        simulator's own checks read either way."""
        if self.reference.method == PM_BEAT:
            check_speed_keeps_its_sign(self.velocity_m_s, source)

    def quantities(self) -> dict[str, Any]:
        """JSON-ready shock quantities and reduction diagnostics."""
        return {
            "peak_velocity_m_s": self.peak_velocity_m_s,
            "peak_velocity_noise_u_m_s": self.peak_velocity_noise_u_m_s,
            "peak_acceleration_m_s2": self.peak_acceleration_m_s2,
            "pulse_width_s": self.pulse_width_s,
            "delay_s": self.delay_s,
            "aligned": self.aligned,
            "shock_sensitivity": self.shock_sensitivity,
            "shock_sensitivity_v_per_m_s2": self.shock_sensitivity_v_per_m_s2,
            "response_unit": self.response_unit,
            "response_offset_v": self.response_offset_v,
            "demodulation_bandwidth_hz": self.demodulation_bandwidth_hz,
            "analysis_rate_hz": self.record.sample_rate_hz,
            **self.reference.quantities(),
            "onset_time_s": self.onset_time_s,
        }


def reduce_raw(
    doppler_v: np.ndarray,
    response_v: np.ndarray,
    sample_interval_s: float,
    *,
    quadrature_v: np.ndarray | None = None,
    grating_pitch_m: float = DEFAULT_GRATING_PITCH_M,
    orders: tuple[int, int] = (1, -1),
    amp_gain: float = 1.0,
    sensitivity_v_per_m_s2: float = 1.0,
    sample_rate_hz: float = DEFAULT_ANALYSIS_RATE_HZ,
    bandwidth_hz: float | None = None,
    align: bool = False,
    start_time_s: float = 0.0,
    source: str = "raw shot",
    full_scale_v: Mapping[str, FullScale] | None = None,
) -> Reduction:
    """Reduce a raw shot (interferometer and amplifier output in volts, sampled together) to the
    two-channel record at `sample_rate_hz`; see the module docstring for the steps.
    `quadrature_v`: a quadrature interferometer's second photodetector (None: `doppler_v` is a
    single-channel PM beat). `full_scale_v`: role ("doppler", "doppler_quadrature",
    "response") -> the digitizer's full scale in volts (analysis.full_scale.full_scale_volts):
    a channel with samples there is clipped and refused; a role not given is not judged."""
    return reduce_sensors(
        doppler_v, {"response": SensorChannel(response_v, amp_gain, sensitivity_v_per_m_s2)}, sample_interval_s,
        quadrature_v=quadrature_v, grating_pitch_m=grating_pitch_m, orders=orders, sample_rate_hz=sample_rate_hz,
        bandwidth_hz=bandwidth_hz, align=align, start_time_s=start_time_s, source=source, full_scale_v=full_scale_v,
    )["response"]


def reduce_sensors(
    doppler_v: np.ndarray,
    sensors: Mapping[str, SensorChannel],
    sample_interval_s: float,
    *,
    quadrature_v: np.ndarray | None = None,
    grating_pitch_m: float = DEFAULT_GRATING_PITCH_M,
    orders: tuple[int, int] = (1, -1),
    sample_rate_hz: float = DEFAULT_ANALYSIS_RATE_HZ,
    bandwidth_hz: float | None = None,
    align: bool = False,
    start_time_s: float = 0.0,
    source: str = "raw shot",
    full_scale_v: Mapping[str, FullScale] | None = None,
) -> dict[str, Reduction]:
    """Reduce one reference and several sensors recorded with it (role -> SensorChannel) to one
    record per sensor; the reference is demodulated once and every record gets the first
    sensor's low-pass (module docstring). `full_scale_v` as in `reduce_raw`, by role."""
    full_scale_v = full_scale_v or {}
    if not sensors:
        raise AnalysisError(f"{source}: no sensor channel to reduce")
    n = np.asarray(doppler_v).size
    if quadrature_v is not None and np.asarray(quadrature_v).size != n:
        raise AnalysisError(f"{source}: the doppler and doppler_quadrature channels differ in length "
                            f"({n} and {np.asarray(quadrature_v).size} samples)")
    if not (np.isfinite(sample_rate_hz) and sample_rate_hz != 0):
        raise AnalysisError(f"{source}: analysis sample rate must be a finite non-zero number, got {sample_rate_hz!r}")
    responses = {role: check_sensor_channel(role, channel, n, source, full_scale_v.get(role))
                 for role, channel in sensors.items()}
    for role, response in responses.items():
        check_carries_pulse(role, response, doppler_v, source)
    reference = reference_phase(doppler_v, sample_interval_s, quadrature_v=quadrature_v,
                                decimated_rate_hz=decimated_rate_for(sample_rate_hz), source=source,
                                full_scale_v=full_scale_v)
    out: dict[str, Reduction] = {}
    for role, channel in sensors.items():
        out[role] = _reduce_sensor(reference, responses[role], channel, sample_interval_s,
                                   grating_pitch_m=grating_pitch_m, orders=orders, sample_rate_hz=sample_rate_hz,
                                   bandwidth_hz=bandwidth_hz, align=align, start_time_s=start_time_s, source=source)
        bandwidth_hz = out[role].demodulation_bandwidth_hz  # the other sensors share the first's low-pass
    return out


def check_sensor_channel(role: str, channel: SensorChannel, n: int, source: str,
                         full_scale_v: FullScale | None = None) -> np.ndarray:
    """The channel's volts as floats, or AnalysisError naming the role: a length other than the
    reference's `n`, a zero or non-finite gain or sensitivity, a non-finite sample, a sample at
    the digitizer's full scale (`full_scale_v`, when given; never judged from the record)."""
    response = np.asarray(channel.response_v, dtype=float).ravel()
    name = "" if role == "response" else f"{role} "
    if response.size != n:
        raise AnalysisError(f"{source}: the doppler and {role} channels differ in length "
                            f"({n} and {response.size} samples)")
    for what, value in (("amplifier gain", channel.amp_gain), ("sensitivity", channel.sensitivity_v_per_m_s2)):
        if not (np.isfinite(value) and value != 0):
            raise AnalysisError(f"{source}: {name}{what} must be a finite non-zero number, got {value!r}")
    if not np.all(np.isfinite(response)):
        raise AnalysisError(f"{source}: {role} channel has a NaN or infinite sample at index "
                            f"{int(np.flatnonzero(~np.isfinite(response))[0])}")
    check_not_clipped(response, full_scale_v, f"{source}: {role} channel",
                      "lower the amplifier gain or widen the digitizer's range")
    return response


def check_carries_pulse(role: str, response_v: np.ndarray, doppler_v: np.ndarray, source: str) -> None:
    """AnalysisError naming the role when its channel holds only noise while the object moves
    (analysis.channel_content: no sensor connected, or a role mapped to an empty channel)."""
    content = pulse_content(response_v, np.asarray(doppler_v).ravel(), role)
    if content is not None and content.carries_nothing:
        raise AnalysisError(f"{source}: {content.message()}")


def check_speed_keeps_its_sign(velocity_m_s: np.ndarray, source: str) -> None:
    """AnalysisError where a single photodetector's velocity falls back towards rest after its
    peak (RETURN_TO_REST_SHARE): its beat tells the speed, not the direction, so where the motion
    may pass through rest the reference is not known (on the simulator's bonded mount without the
    quadrature channel, 24 shots: the DC gain held its truth on 16, the FBSD on 15, and 20 claimed
    a mode the sensor lacks)."""
    v = np.asarray(velocity_m_s, dtype=float)
    if not v.size:
        return
    k = int(np.argmax(v))
    peak, lowest = float(v[k]), float(np.min(v[k:]))
    if peak > 0 and lowest < RETURN_TO_REST_SHARE * peak:
        raise AnalysisError(
            f"{source}: the object's velocity falls back to {max(lowest, 0.0) / peak:.0%} of its peak after the pulse "
            "(a mount that keeps the sensor on the bar), and one photodetector tells the speed, not its direction: "
            "where the motion passes through rest the reference is not known. Record the interferometer's "
            f"quadrature photodetector too (role {QUADRATURE_KEY})")


def _reduce_sensor(reference: ReferencePhase, response: np.ndarray, channel: SensorChannel,
                   sample_interval_s: float, *, grating_pitch_m: float, orders: tuple[int, int],
                   sample_rate_hz: float, bandwidth_hz: float | None, align: bool, start_time_s: float,
                   source: str) -> Reduction:
    """Steps 2–4 of the module docstring for one sensor against the reference's phase."""
    m = reference.decimation
    amp_gain, sensitivity = channel.amp_gain, channel.sensitivity_v_per_m_s2
    # Response: zero offset from the pre-trigger part, then volts → m/s².
    pre_end = int((reference.onset_time_s - PRE_TRIGGER_MARGIN_S) / sample_interval_s)
    if pre_end < MIN_PRE_TRIGGER_SAMPLES:
        raise AnalysisError(
            f"{source}: only {max(pre_end, 0)} samples before the pulse (need ≥ {MIN_PRE_TRIGGER_SAMPLES} "
            f"for the response's zero offset): record more pre-trigger"
        )
    offset_v = float(np.mean(response[:pre_end]))
    scale = 1.0 / (amp_gain * sensitivity)
    unit = "V" if amp_gain == 1.0 and sensitivity == 1.0 else "m/s^2"
    n_blocks = reference.phase_rad.size
    block_mean = response[: n_blocks * m].reshape(n_blocks, m) @ np.full(m, 1.0 / m)
    response_blocks = (block_mean - offset_v) * scale

    # Both channels to the analysis rate with one anti-alias filter.
    displacement = reference.phase_rad * metres_per_radian(grating_pitch_m, orders)
    at_rate = displacement_to_rate(displacement, response_blocks, reference.sample_interval_s,
                                   start_time_s + reference.start_time_s, sample_rate_hz)
    demod: Demodulated = differentiate(at_rate.reference, at_rate.sample_interval_s, at_rate.start_time_s,
                                       reference.beat, bandwidth_hz)
    rate = 1.0 / at_rate.sample_interval_s
    response_out = lowpass(at_rate.response, demod.bandwidth_hz, rate)
    acceleration = demod.acceleration_m_s2

    max_lag = max(1, int(MAX_DELAY_S * rate))
    delay_samples = estimate_delay_samples(acceleration, response_out, max_lag)
    if align:
        response_out = shift_samples(response_out, -delay_samples)
    record = Record(at_rate.sample_interval_s, acceleration, response_out, at_rate.start_time_s, unit)

    pulse = pulse_width(acceleration, record.sample_interval_s, record.start_time_s)
    shock_sensitivity = peak_estimate(response_out)[0] / pulse.peak_m_s2
    velocity, velocity_u = peak_velocity(demod.velocity_m_s, record.sample_interval_s, pulse, record.start_time_s)
    return Reduction(
        record=record,
        velocity_m_s=demod.velocity_m_s,
        peak_velocity_m_s=velocity,
        peak_velocity_noise_u_m_s=velocity_u,
        peak_acceleration_m_s2=float(pulse.peak_m_s2),
        pulse_width_s=float(pulse.width_s),
        delay_s=float(delay_samples * record.sample_interval_s),
        aligned=align,
        shock_sensitivity=float(shock_sensitivity),
        # response = V / (gain · S): volts at the amplifier input = response · S
        shock_sensitivity_v_per_m_s2=float(shock_sensitivity * sensitivity),
        response_unit=unit,
        response_offset_v=offset_v,
        demodulation_bandwidth_hz=demod.bandwidth_hz,
        onset_time_s=start_time_s + reference.onset_time_s,
        reference=reference,
    )


# ------------------------------------------------------------------------------ the reference
def reference_phase(doppler_v: np.ndarray, sample_interval_s: float, *, quadrature_v: np.ndarray | None = None,
                    decimated_rate_hz: float = DECIMATED_RATE_HZ, source: str = "raw shot",
                    full_scale_v: Mapping[str, FullScale] | None = None) -> ReferencePhase:
    """The interferometer's phase, box-car decimated to ~`decimated_rate_hz`: from the PM beat
    alone, or from the quadrature pair when `quadrature_v` is given (module docstring, step 1).
    `full_scale_v`: role -> the digitizer's full scale (see `reduce_raw`)."""
    full_scale_v = full_scale_v or {}
    if quadrature_v is not None:
        return quadrature_phase(doppler_v, quadrature_v, sample_interval_s, decimated_rate_hz=decimated_rate_hz,
                                source=f"{source}: quadrature interferometer", full_scale_v=full_scale_v)
    beat = beat_phase(np.asarray(doppler_v).ravel(), sample_interval_s,  # beat_phase takes it to float32 itself
                      decimated_rate_hz=decimated_rate_hz, source=f"{source}: doppler channel",
                      full_scale_v=full_scale_v.get("doppler"))
    return ReferencePhase(PM_BEAT, beat.sample_interval_s, beat.start_time_s, beat.phase_rad, beat.decimation,
                          beat.onset_time_s, beat.beat_peak_hz, beat=beat)


def quadrature_phase(u1_v: np.ndarray, u2_v: np.ndarray, sample_interval_s: float, *,
                     decimated_rate_hz: float = DECIMATED_RATE_HZ,
                     source: str = "quadrature interferometer",
                     full_scale_v: Mapping[str, FullScale] | None = None) -> ReferencePhase:
    """The phase of a quadrature interferometer (u1 ∝ cos φ on the doppler channel, u2 ∝ sin φ on
    doppler_quadrature): Heydemann-corrected arctangent at the raw rate, then box-car decimated.

    Raises AnalysisError (naming `source`) for a clipped record (samples at the full scale
    `full_scale_v` gives for role doppler / doppler_quadrature) or a too short one, fringes close to
    half a fringe per sample (beyond that they alias, which no check on the record can see: the
    digitizer's rate must exceed twice the highest fringe frequency), a pair that traces no
    ellipse, or no motion."""
    if not (np.isfinite(sample_interval_s) and sample_interval_s > 0):
        raise AnalysisError(f"{source}: sample interval must be positive, got {sample_interval_s!r} s")
    for role, u in (("doppler", u1_v), (QUADRATURE_KEY, u2_v)):
        check_not_clipped(u, (full_scale_v or {}).get(role), f"{source}: {role} channel",
                          "reduce the digitizer's gain or widen its range")
    content = beat_content(np.asarray(u2_v).ravel(), np.asarray(u1_v).ravel(), QUADRATURE_KEY)
    if content is not None and content.carries_nothing:  # one photodetector, its partner's role mapped: say so
        raise AnalysisError(f"{source}: {content.message()}")
    m = max(1, floor_count(1.0 / sample_interval_s / decimated_rate_hz))
    n_blocks = np.asarray(u1_v).size // m
    if n_blocks < 64:
        raise AnalysisError(f"{source}: {np.asarray(u1_v).size} samples is too short to demodulate "
                            f"(needs ≥ {64 * m})")
    try:
        q = demodulate_quadrature(u1_v, u2_v, sample_interval_s, 1.0)  # phase in radians
        moving = _moving_samples(q.phase_rad)
        if MIN_FIT_SAMPLES <= np.count_nonzero(moving) < moving.size:  # the rest's spot left out of the fit
            q = demodulate_quadrature(u1_v, u2_v, sample_interval_s, 1.0, fit_samples=moving)
    except AnalysisError as exc:
        raise AnalysisError(f"{source}: {exc}") from None
    steps = np.abs(np.diff(q.phase_rad))
    window = min(16, steps.size)
    fastest = float(np.max(np.convolve(steps, np.full(window, 1.0 / window), mode="valid"))) if window else 0.0
    if fastest > MAX_PHASE_STEP_RAD:
        raise AnalysisError(f"{source}: the fringes move {fastest / (2 * math.pi):.2f} of a fringe per sample "
                            f"(at most {MAX_PHASE_STEP_RAD / (2 * math.pi):.3g} is followed safely): sample faster")
    dt_m = m * sample_interval_s
    phase = q.phase_rad[: n_blocks * m].reshape(n_blocks, m) @ np.full(m, 1.0 / m)
    k_on, rest_rad, direction = _quadrature_onset(phase, source)
    phase = direction * (phase - rest_rad)
    fringe_hz = np.convolve(np.diff(phase), np.full(11, 1.0 / 11), mode="same") / (2.0 * math.pi * dt_m)
    ellipse = q.ellipse
    details = {"offset_1_v": ellipse.offset_1_v, "offset_2_v": ellipse.offset_2_v,
               "amplitude_v": ellipse.amplitude_v, "amplitude_ratio": ellipse.amplitude_ratio,
               "phase_error_deg": math.degrees(ellipse.phase_error_rad), "radius_spread": q.radius_spread,
               "direction": direction}
    return ReferencePhase(QUADRATURE, dt_m, 0.5 * (m - 1) * sample_interval_s, phase, m, (k_on + 0.5) * dt_m,
                          float(np.max(np.abs(fringe_hz))), quadrature=details)


def _moving_samples(phase_rad: np.ndarray) -> np.ndarray:
    """Samples after which the phase moves more than MOTION_MIN_RAD within MOTION_WINDOW_SAMPLES."""
    w = min(MOTION_WINDOW_SAMPLES, phase_rad.size - 1)
    moving = np.zeros(phase_rad.size, dtype=bool)
    if w > 0:
        moving[:-w] = np.abs(phase_rad[w:] - phase_rad[:-w]) > MOTION_MIN_RAD
    return moving


def _quadrature_onset(phase: np.ndarray, source: str) -> tuple[int, float, int]:
    """(first block in motion, rest phase, direction ±1) of a block-mean quadrature phase: the
    motion certainly began before the phase is half a fringe (π) from its start; it began after
    the last block within the rest's noise band (ONSET_* constants). The direction is read where
    the phase has first moved DIRECTION_FRINGES from rest (else at half a fringe)."""
    moved = np.flatnonzero(np.abs(phase - phase[0]) > math.pi)
    if moved.size == 0:
        raise AnalysisError(f"{source}: the phase never moves half a fringe: no motion in the record")
    k1 = int(moved[0])
    rest = phase[: max(k1 // 2, 1)]
    rest_rad = float(np.median(rest))
    noise = 1.4826 * float(np.median(np.abs(rest - rest_rad)))
    far = np.flatnonzero(np.abs(phase - rest_rad) > DIRECTION_FRINGES * 2.0 * math.pi)
    k_dir = int(far[0]) if far.size else k1  # where the motion, not an onset glitch, has moved the phase
    direction = 1 if phase[k_dir] > rest_rad else -1
    away = direction * (phase[:k1] - rest_rad) > max(ONSET_NOISE_FACTOR * noise, ONSET_MIN_RAD)
    still = np.flatnonzero(~away)
    return (int(still[-1]) + 1 if still.size else 0), rest_rad, direction


# A velocity after the pulse that stays within this fraction of its peak is a flight plateau.
PLATEAU_FRACTION = 0.02


def peak_velocity(
    velocity_m_s: np.ndarray, sample_interval_s: float, pulse: PulseWidth, start_time_s: float = 0.0
) -> tuple[float, float]:
    """The velocity change the pulse imparts, by an estimator noise does not bias, and its
    standard uncertainty from the noise.

    After a unipolar pulse the object flies off: a straight line fitted over that plateau (from
    two pulse widths after the pulse to the record's end) and read at the pulse's end averages
    the noise out (the maximum of a noisy velocity is biased high: +0.16 % on a 5 MHz beat at
    30 dB). Its uncertainty is the line's standard error, widened by the integrated
    autocorrelation time of the residual (the velocity's noise is low-passed, so neighbouring
    samples are not independent). Without a plateau (a bipolar pulse brings the object back),
    the velocity's extreme by `peak_estimate`, with the scatter of its residual as uncertainty.
    """
    v = np.asarray(velocity_m_s, dtype=float)
    dt = sample_interval_s
    width = max(1, int(round(pulse.width_s / dt)))
    end = int(round((pulse.end_s - start_time_s) / dt))
    first = min(v.size, end + 2 * width)
    plateau = v[first:]
    top = float(np.max(np.abs(v)))
    if plateau.size >= 16 and top > 0 and abs(np.mean(plateau)) >= (1 - PLATEAU_FRACTION) * top:
        t = (np.arange(first, v.size) - end).astype(float)
        slope, intercept = np.polyfit(t, plateau, 1)
        residual = plateau - (slope * t + intercept)
        sigma = float(np.std(residual, ddof=2))
        design = np.column_stack((np.ones(t.size), t))
        se = sigma * math.sqrt(float(np.linalg.inv(design.T @ design)[0, 0]))
        return float(intercept), se * math.sqrt(_correlation_time(residual))
    value, _ = peak_estimate(v)
    i = int(np.argmax(np.abs(v)))
    window = v[max(0, i - width) : i + width + 1]
    scatter = float(np.std(np.diff(window))) / math.sqrt(2.0) if window.size > 2 else 0.0
    return float(value), scatter / math.sqrt(max(window.size, 1))


def _correlation_time(x: np.ndarray) -> float:
    """Integrated autocorrelation time 1 + 2 Σ ρ_k of a residual, summed up to the first
    negative ρ (samples; 1 for white noise)."""
    x = np.asarray(x, dtype=float) - np.mean(x)
    n = x.size
    spec = np.fft.rfft(x, 2 * n)
    acf = np.fft.irfft(np.abs(spec) ** 2)[:n]
    if acf[0] <= 0:
        return 1.0
    rho = acf / acf[0]
    negative = np.flatnonzero(rho[1:] < 0)
    stop = int(negative[0]) + 1 if negative.size else n
    return float(max(1.0, 1.0 + 2.0 * np.sum(rho[1:stop])))


# ------------------------------------------------------------------------------ raw tables
def read_raw_table(path: str | Path) -> RawTable:
    """Read a raw shot from CSV (header time_s,doppler,response[,doppler_quadrature]) or NPZ
    (same keys); the doppler_quadrature column is a quadrature interferometer's second detector.

    Raises RecordError naming the file and the problem (missing key, ragged or non-uniform
    time axis, non-finite values).
    """
    path = Path(path)
    if path.suffix.lower() not in (".csv", ".npz"):
        raise RecordError(f"{path}: unknown raw shot format '{path.suffix}' (use .csv, .npz or an .h5 shot file)")
    keys = RAW_KEYS + ((QUADRATURE_KEY,) if QUADRATURE_KEY in column_names(path) else ())
    columns = read_columns(path, keys, what="raw shot")
    step, (time_s, doppler, response, *quadrature) = validated_columns(columns, keys, str(path), min_samples=2)
    return RawTable(step, float(time_s[0]), doppler, response, quadrature[0] if quadrature else None)


def write_raw_table(path: str | Path, time_s: np.ndarray, doppler_v: np.ndarray, response_v: np.ndarray,
                    quadrature_v: np.ndarray | None = None) -> Path:
    """Write a raw shot as NPZ or CSV (by suffix) with the keys time_s, doppler, response (and
    doppler_quadrature when given)."""
    path = Path(path)
    keys = RAW_KEYS + ((QUADRATURE_KEY,) if quadrature_v is not None else ())
    values = (time_s, doppler_v, response_v) + ((quadrature_v,) if quadrature_v is not None else ())
    arrays = {k: np.asarray(v, float) for k, v in zip(keys, values, strict=True)}
    if path.suffix.lower() == ".npz":
        np.savez(path, **arrays)
    elif path.suffix.lower() == ".csv":
        np.savetxt(path, np.column_stack(list(arrays.values())), delimiter=",", header=",".join(keys),
                   comments="", fmt="%.10g")
    else:
        raise RecordError(f"{path}: unknown raw shot format '{path.suffix}' (use .csv or .npz)")
    return path
