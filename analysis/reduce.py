"""Raw shot → two-channel record: the interferometer reduction and the shock quantities.

A raw shot is two channels sampled together by the digitizer (~100 MS/s): the photomultiplier
beat of the Doppler interferometer and the bridge amplifier's output (V). `reduce_raw` gives
the record `identify` reads (time_s, reference in m/s², response) at the analysis rate:

1. Reference: `analysis.doppler` demodulates the beat into the grating's phase (displacement),
   box-car decimated by M raw samples.
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

Shock quantities: peak reference acceleration and pulse width at 10 % of peak (ISO 16063-22,
`analysis.excitation.pulse_width`), peak velocity change (flight velocity minus rest, 0), and
the shock sensitivity (ISO 16063-13): the response's peak ÷ the reference's peak, in the
response's units per m/s²; also in V/(m/s²) at the amplifier input.

Raw input files (`read_raw_table`): CSV with header `time_s,doppler,response` or NPZ with
those keys. The HDF5 shot file is read by the command (rig.shotfile), which passes arrays.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from hopkinson.analysis.doppler import (
    BeatPhase,
    Demodulated,
    FullScale,
    beat_phase,
    check_not_clipped,
    decimated_rate_for,
    differentiate,
    displacement_to_rate,
    lowpass,
    metres_per_radian,
)
from hopkinson.analysis.errors import AnalysisError, RecordError
from hopkinson.analysis.excitation import PulseWidth, peak_estimate, pulse_width
from hopkinson.analysis.params import DEFAULT_GRATING_PITCH_M
from hopkinson.analysis.records import Record, read_columns, validated_columns
from hopkinson.analysis.resample import (
    DEFAULT_ANALYSIS_RATE_HZ,
    estimate_delay_samples,
    shift_samples,
)

RAW_KEYS = ("time_s", "doppler", "response")
PRE_TRIGGER_MARGIN_S = 2e-6  # the zero offset is taken up to this long before the motion
MIN_PRE_TRIGGER_SAMPLES = 100  # fewer pre-trigger samples cannot give a zero offset
MAX_DELAY_S = 50e-6  # the delay search spans ±this


@dataclass(frozen=True)
class RawTable:
    """A raw shot read from a table file: uniform sample interval, channels in volts."""

    sample_interval_s: float
    start_time_s: float
    doppler_v: np.ndarray
    response_v: np.ndarray


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
    beat: BeatPhase

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
            "beat_peak_hz": self.beat.beat_peak_hz,
            "beat_snr_db": self.beat.snr_db,
            "onset_time_s": self.onset_time_s,
        }


def reduce_raw(
    doppler_v: np.ndarray,
    response_v: np.ndarray,
    sample_interval_s: float,
    *,
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
    """Reduce a raw shot (PM beat and amplifier output in volts, sampled together) to the
    two-channel record at `sample_rate_hz`; see the module docstring for the steps.
    `full_scale_v`: role ("doppler", "response") -> the digitizer's full scale in volts
    (analysis.doppler.full_scale_volts): a channel with samples there is clipped and refused;
    a role not given is not judged (never from the record's own extremes)."""
    full_scale_v = full_scale_v or {}
    doppler = np.asarray(doppler_v).ravel()  # beat_phase takes it to float32 itself
    response = np.asarray(response_v, dtype=float).ravel()
    if doppler.size != response.size:
        raise AnalysisError(f"{source}: the doppler and response channels differ in length "
                            f"({doppler.size} and {response.size} samples)")
    for name, value in (("amplifier gain", amp_gain), ("sensitivity", sensitivity_v_per_m_s2),
                        ("analysis sample rate", sample_rate_hz)):
        if not (np.isfinite(value) and value != 0):
            raise AnalysisError(f"{source}: {name} must be a finite non-zero number, got {value!r}")
    if not np.all(np.isfinite(response)):
        raise AnalysisError(f"{source}: response channel has a NaN or infinite sample at index "
                            f"{int(np.flatnonzero(~np.isfinite(response))[0])}")
    check_not_clipped(response, full_scale_v.get("response"), f"{source}: response channel",
                      "lower the amplifier gain or widen the digitizer's range")
    beat = beat_phase(doppler, sample_interval_s, decimated_rate_hz=decimated_rate_for(sample_rate_hz),
                      source=f"{source}: doppler channel", full_scale_v=full_scale_v.get("doppler"))
    m = beat.decimation

    # Response: zero offset from the pre-trigger part, then volts → m/s².
    pre_end = int((beat.onset_time_s - PRE_TRIGGER_MARGIN_S) / sample_interval_s)
    if pre_end < MIN_PRE_TRIGGER_SAMPLES:
        raise AnalysisError(
            f"{source}: only {max(pre_end, 0)} samples before the pulse (need ≥ {MIN_PRE_TRIGGER_SAMPLES} "
            f"for the response's zero offset): record more pre-trigger"
        )
    offset_v = float(np.mean(response[:pre_end]))
    scale = 1.0 / (amp_gain * sensitivity_v_per_m_s2)
    unit = "V" if amp_gain == 1.0 and sensitivity_v_per_m_s2 == 1.0 else "m/s^2"
    n_blocks = beat.phase_rad.size
    block_mean = response[: n_blocks * m].reshape(n_blocks, m) @ np.full(m, 1.0 / m)
    response_blocks = (block_mean - offset_v) * scale

    # Both channels to the analysis rate with one anti-alias filter.
    displacement = beat.phase_rad * metres_per_radian(grating_pitch_m, orders)
    at_rate = displacement_to_rate(displacement, response_blocks, beat.sample_interval_s,
                                   start_time_s + beat.start_time_s, sample_rate_hz)
    demod: Demodulated = differentiate(at_rate.reference, at_rate.sample_interval_s, at_rate.start_time_s,
                                       beat, bandwidth_hz)
    rate = 1.0 / at_rate.sample_interval_s
    response_out = lowpass(at_rate.response, demod.bandwidth_hz, rate)
    reference = demod.acceleration_m_s2

    max_lag = max(1, int(MAX_DELAY_S * rate))
    delay_samples = estimate_delay_samples(reference, response_out, max_lag)
    if align:
        response_out = shift_samples(response_out, -delay_samples)
    record = Record(at_rate.sample_interval_s, reference, response_out, at_rate.start_time_s)

    pulse = pulse_width(reference, record.sample_interval_s, record.start_time_s)
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
        shock_sensitivity_v_per_m_s2=float(shock_sensitivity * sensitivity_v_per_m_s2),
        response_unit=unit,
        response_offset_v=offset_v,
        demodulation_bandwidth_hz=demod.bandwidth_hz,
        onset_time_s=start_time_s + beat.onset_time_s,
        beat=beat,
    )


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
    """Read a raw shot from CSV (header time_s,doppler,response) or NPZ (same keys).

    Raises RecordError naming the file and the problem (missing key, ragged or non-uniform
    time axis, non-finite values).
    """
    path = Path(path)
    if path.suffix.lower() not in (".csv", ".npz"):
        raise RecordError(f"{path}: unknown raw shot format '{path.suffix}' (use .csv, .npz or an .h5 shot file)")
    columns = read_columns(path, RAW_KEYS, what="raw shot")
    step, (time_s, doppler, response) = validated_columns(columns, RAW_KEYS, str(path), min_samples=2)
    return RawTable(step, float(time_s[0]), doppler, response)


def write_raw_table(path: str | Path, time_s: np.ndarray, doppler_v: np.ndarray, response_v: np.ndarray) -> Path:
    """Write a raw shot as NPZ or CSV (by suffix) with the keys time_s, doppler, response."""
    path = Path(path)
    arrays = dict(zip(RAW_KEYS, (np.asarray(time_s, float), np.asarray(doppler_v, float),
                                 np.asarray(response_v, float)), strict=True))
    if path.suffix.lower() == ".npz":
        np.savez(path, **arrays)
    elif path.suffix.lower() == ".csv":
        np.savetxt(path, np.column_stack(list(arrays.values())), delimiter=",", header=",".join(RAW_KEYS),
                   comments="", fmt="%.10g")
    else:
        raise RecordError(f"{path}: unknown raw shot format '{path.suffix}' (use .csv or .npz)")
    return path
