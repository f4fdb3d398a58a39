"""A DCM applied to records: every shot's check of its own compensation, the compensated peak
with its uncertainty, and records brought to a DCM's rate.

The check compensates the shot's own response and compares both estimates of the
acceleration with the reference over the pulse window (the main pulse widened by two pulse
widths on each side, analysis.excitation.pulse_window):
- uncompensated: response ÷ DC gain, advanced by its own latency (channel delay + the model's
  delay over its ±5 % band, analysis.group_delay.passband_delay_samples), so that the comparison is
  not won by alignment alone;
- compensated: the DCM's output (analysis.dcm_stream.apply with align: the latency removed) ÷ DC gain.
Figures relative to the reference's peak: the RMS error over the window and the error of the
peak of the reference's polarity, every peak read by analysis.excitation.peak_estimate (a fit
over the peak's lobe: a noisy reference's largest sample stands up to 2 % above its peak).

Recommendation (judged on the shot itself): the DCM must have something to cancel, keep its
noise gain within the limit, widen the ±5 % band, lower the RMS error, not raise the peak error
by more than PEAK_TOLERANCE_PCT, and hold the compensated peak within ±PEAK_LIMIT_PCT of the
reference's with its uncertainty: |peak error| + U ≤ 5 %, U = 2u, u from the noise both channels
carry at the peak (the response's through the DCM's noise gain) and, with the model draws, the
spread of the compensated peak they give. The check is in-sample (the model was fitted to this shot): it
catches a compensation that makes the shot worse, it does not prove one that makes it better on
other records.

Compensated peak uncertainty: each Monte Carlo model draw H_i (analysis.uncertainty) is a
sensor the shot cannot rule out. Read with the nominal DCM G and DC gain S, a pulse u gives
the compensated peak q_i·peak(u), q_i = peak(G·H_i·u) / (S·peak(u)) (u the reference;
analysis.dcm_ratio.ShotPulse.peak_ratios). Had the sensor been H_i, the reading â (the
compensated record's peak) would stand for a pulse peak of â/q_i: the draws (â + e_i)/q_i, e_i
the white response noise after the DCM (noise gain × response noise ÷ S, drawn normally), give
u and the 95 % interval (the draws' coverage ends: analysis.estimate.coverage_ends). The value stays â, the compensated
record's own peak; two known effects are carried rather than corrected in it, each widening the
interval on its side (GUM F.2.4.5: an uncorrected known effect enlarges the interval; u adds it
as a rectangular bound):
- the DCM's own effect on this pulse (q_0 − 1 with the nominal model, "dcm_residual_pct"),
  which the draws correct: the interval holds â too;
- the model's error this shot shows in the figure ("model_error_pct"): the nominal model's
  corrected reading â/q_0 against the reference's peak. A model fitted to the shot can still
  miss what a realistic record carries (a mount's asymmetry, a transverse drive path); the draws
  span the model's fit, not such errors, and on such records missed the reference's peak 10 times
  in 30. The figure is the model's error for a pulse of this shape, carried as a systematic.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, replace
from functools import cached_property
from typing import TYPE_CHECKING, Any

import numpy as np
from scipy import signal

from hopkinson.analysis.dcm import DCM
from hopkinson.analysis.dcm_design import DcmDesign, ShotSupport, design_compensation
from hopkinson.analysis.dcm_ratio import ShotPulse
from hopkinson.analysis.dcm_stream import apply
from hopkinson.analysis.errors import AnalysisError
from hopkinson.analysis.estimate import coverage_ends
from hopkinson.analysis.excitation import PulseWidth, peak_estimate, pulse_width, pulse_window
from hopkinson.analysis.group_delay import passband_delay_samples
from hopkinson.analysis.model import DiscreteModel
from hopkinson.analysis.options import AnalysisOptions
from hopkinson.analysis.records import Record
from hopkinson.analysis.resample import resample_to_rate, resampling_factors, shift_samples
from hopkinson.analysis.response import fbsd_hz, frequency_response

if TYPE_CHECKING:
    from hopkinson.analysis.evidence import NoiseReport
    from hopkinson.analysis.identify import Identification

# A compensated peak error this much larger (percentage points) than the uncompensated one
# counts as worse: below it the difference is within what the reference's own noise moves.
PEAK_TOLERANCE_PCT = 0.5
# A DCM whose compensated peak may lie further than this from the reference's (with U) is not
# recommended (per cent of the reference's peak).
PEAK_LIMIT_PCT = 5.0
COVERAGE = 0.95


@dataclass(frozen=True)
class CompensationCheck:
    """The shot's own compensation against its reference (module docstring); percentages
    of the reference peak; (uncompensated, compensated) pairs. peak_error_u_pct: the standard
    uncertainty of the compensated peak error (None: not known, taken as 0)."""

    rms_error_pct: tuple[float, float]
    peak_error_pct: tuple[float, float]
    window_s: tuple[float, float]
    reference_peak_m_s2: float
    compensated_peak_m_s2: float
    peak_error_u_pct: float | None = None

    @property
    def improves(self) -> bool:
        return self.rms_error_pct[1] < self.rms_error_pct[0] and not self.peak_worse

    @property
    def peak_worse(self) -> bool:
        return abs(self.peak_error_pct[1]) > abs(self.peak_error_pct[0]) + PEAK_TOLERANCE_PCT

    @property
    def peak_beyond_limit(self) -> bool:
        """The compensated peak may lie beyond ±PEAK_LIMIT_PCT of the reference's: |error| + 2u."""
        return abs(self.peak_error_pct[1]) + 2.0 * (self.peak_error_u_pct or 0.0) > PEAK_LIMIT_PCT

    def reason(self) -> str | None:
        """Why compensation is not good enough on the shot (None when it is)."""
        unc, comp = self.rms_error_pct
        if comp >= unc:
            return (f"compensating this shot raises the RMS error over the pulse from {unc:.3g} % to {comp:.3g} % "
                    "of the peak")
        if self.peak_worse:
            unc, comp = self.peak_error_pct
            return f"compensating this shot moves the peak error from {unc:+.3g} % to {comp:+.3g} %"
        if self.peak_beyond_limit:
            u = self.peak_error_u_pct or 0.0
            return (f"its compensated peak is {self.peak_error_pct[1]:+.3g} % off the reference's (U = {2 * u:.2g} %): "
                    f"it may lie beyond ±{PEAK_LIMIT_PCT:g} %")
        return None

    def to_dict(self) -> dict[str, Any]:
        return {
            "rms_error_pct": {"uncompensated": self.rms_error_pct[0], "compensated": self.rms_error_pct[1]},
            "peak_error_pct": {"uncompensated": self.peak_error_pct[0], "compensated": self.peak_error_pct[1]},
            "window_s": list(self.window_s),
            "reference_peak_m_s2": self.reference_peak_m_s2,
            "compensated_peak_m_s2": self.compensated_peak_m_s2,
            "peak_error_u_pct": self.peak_error_u_pct,
        }


@dataclass(frozen=True)
class _Pulse:
    """The reference pulse of a record and the response with its baseline removed."""

    pulse: PulseWidth
    window: slice
    response: np.ndarray  # baseline removed, response units


def _pulse_of(record: Record) -> _Pulse:
    dt = record.sample_interval_s
    pulse = pulse_width(record.reference, dt, record.start_time_s)
    window = pulse_window(pulse, record.n_samples, dt, record.start_time_s)
    quiet = int((pulse.start_s - pulse.width_s - record.start_time_s) / dt)
    response = np.asarray(record.response, dtype=float)
    base = float(np.mean(response[:quiet])) if quiet >= 16 else 0.0
    return _Pulse(pulse, window, response - base)


class _Shot:
    """A record at the DCM's rate with what the check and the compensated peak both read off it
    (its pulse, its reference pulse, its compensated estimate), each computed once when first
    read (a failure is raised again when read again: cached_property keeps no exception)."""

    def __init__(self, record: Record, model: DiscreteModel, dcm: DCM, pulse: ShotPulse | None = None) -> None:
        self.record, self.model, self.dcm = record, model, dcm
        if pulse is not None:
            self.shot_pulse = pulse  # the design's, already read off this record

    def same_rate(self) -> None:
        _same_rate(self.record, self.dcm)

    @cached_property
    def pulse(self) -> _Pulse:
        return _pulse_of(self.record)

    @cached_property
    def shot_pulse(self) -> ShotPulse:
        return ShotPulse.of(self.record)

    @cached_property
    def compensated(self) -> np.ndarray:
        """The DCM's output (steady start, latency removed) ÷ DC gain, m/s²."""
        return apply(self.dcm, self.pulse.response, initial="steady", align=True) / self.model.dc_gain


def estimates(record: Record, model: DiscreteModel, dcm: DCM, channel_delay_samples: float
              ) -> tuple[slice, np.ndarray, np.ndarray]:
    """(pulse window, uncompensated, compensated) estimates of the acceleration (m/s²), both
    aligned with the reference; the record at the DCM's rate."""
    return _estimates(_Shot(record, model, dcm), channel_delay_samples)


def _estimates(shot: _Shot, channel_delay_samples: float, model_fbsd5_hz: float | None = None
               ) -> tuple[slice, np.ndarray, np.ndarray]:
    """`estimates`; `model_fbsd5_hz`: the model's ±5 % edge when known (None: found here)."""
    shot.same_rate()
    p = shot.pulse
    model = shot.model
    gain = model.dc_gain
    dt = model.sample_interval_s
    f5 = fbsd_hz(model, (0.05,))["5"] if model_fbsd5_hz is None else model_fbsd5_hz
    own = channel_delay_samples + passband_delay_samples(lambda f: frequency_response(model, f), min(f5, 0.4 / dt), dt)
    uncompensated = shift_samples(p.response / gain, -own)
    return p.window, uncompensated, shot.compensated


def check_compensation(record: Record, model: DiscreteModel, dcm: DCM, channel_delay_samples: float
                       ) -> CompensationCheck:
    """Compensate the shot's own response and compare with its reference (module docstring)."""
    return _check(_Shot(record, model, dcm), channel_delay_samples)


def _check(shot: _Shot, channel_delay_samples: float, model_fbsd5_hz: float | None = None) -> CompensationCheck:
    record = shot.record
    window, uncompensated, compensated = _estimates(shot, channel_delay_samples, model_fbsd5_hz)
    ref = np.asarray(record.reference, dtype=float)[window]
    peak = peak_estimate(ref)[0]

    def figures(est: np.ndarray) -> tuple[float, float, float]:
        e = est[window]
        rms = 100.0 * math.sqrt(float(np.mean((e - ref) ** 2))) / abs(peak)
        top = peak_estimate(e, peak)[0]
        return rms, 100.0 * (top - peak) / peak, top

    rms_u, peak_u, _ = figures(uncompensated)
    rms_c, peak_c, top_c = figures(compensated)
    t0 = record.start_time_s + window.start * record.sample_interval_s
    t1 = record.start_time_s + (window.stop - 1) * record.sample_interval_s
    return CompensationCheck((rms_u, rms_c), (peak_u, peak_c), (t0, t1), float(peak), top_c)


def recommendation(design: DcmDesign, check: CompensationCheck | None) -> tuple[bool | None, str | None]:
    """(recommended, reason) for a DcmDesign (analysis.dcm_design) and its check on the shot.
    None: not judged (no check and nothing against the design)."""
    if design.poles.cancelled.size == 0:
        return False, "nothing to compensate: no pole of the model is one the shot supports"
    if design.noise_gain_exceeded:
        return False, (f"its noise gain {design.noise_gain:.3g} exceeds the limit {design.options.dcm_noise_gain_limit:g}: "
                       "it amplifies the record's noise more than allowed")
    if design.reached_widening is not None and design.reached_widening <= 1.0:
        return False, f"it does not widen the ±5 % band (×{design.reached_widening:.2f})"
    if check is None:
        return None, None
    reason = check.reason()
    if reason is not None and check.peak_beyond_limit and design.widening_short:
        reason += f" ({design.widening_note})"
    return reason is None, reason


def peak_error_u_pct(check: CompensationCheck, dcm: DCM, gain: float, noise: NoiseReport | None,
                     peak: dict[str, Any] | None) -> float:
    """Standard uncertainty (% of the reference peak) of the check's compensated peak error: the
    noise both channels carry at the peak (the reference's; the response's through the DCM's
    noise gain, ÷ the DC gain) and, with the model draws, the compensated peak's relative u from
    their spread (not the model error the check itself measures), in quadrature."""
    ref = float((noise.reference_rms if noise is not None else None) or 0.0)
    resp = float((noise.response_rms if noise is not None else None) or 0.0) * dcm.noise_gain() / abs(gain)
    draws = 0.0 if not peak else float(peak["u_draws"]) / abs(float(peak["value"]))
    return 100.0 * math.sqrt((ref / check.reference_peak_m_s2) ** 2 + (resp / check.reference_peak_m_s2) ** 2
                             + draws**2)


def peak_noise_rng(seed: int | None) -> np.random.Generator:
    """The compensated peak's noise draws' generator: a stream of its own ([seed, 41]), since
    default_rng(seed) is the Monte Carlo's (uncertainty.evaluate), whose normals it would repeat."""
    return np.random.default_rng(None if seed is None else [seed, 41])


def compensated_peak(record: Record, model: DiscreteModel, dcm: DCM, channel_delay_samples: float,
                     draws: Sequence[DiscreteModel], response_noise_rms: float | None,
                     seed: int | None = None) -> dict[str, Any] | None:
    """The compensated peak (m/s²) of the shot with the uncertainty of the model draws
    (module docstring): {"value", "u", "interval", "u_draws" (the draws' part of u),
    "dcm_residual_pct", "model_error_pct"}; None without draws."""
    return _compensated_peak(_Shot(record, model, dcm), channel_delay_samples, draws, response_noise_rms, seed)


def _compensated_peak(shot: _Shot, channel_delay_samples: float, draws: Sequence[DiscreteModel],
                      response_noise_rms: float | None, seed: int | None) -> dict[str, Any] | None:
    if not draws:
        return None
    shot.same_rate()
    model, dcm = shot.model, shot.dcm
    p = shot.pulse
    pulse = shot.shot_pulse
    gain = model.dc_gain
    measured = shot.compensated
    value = peak_estimate(measured[p.window], pulse.peak_m_s2)[0]
    # a draw's simulated response has no channel delay: remove only the rest of the latency
    ratios = pulse.peak_ratios((model, *draws), dcm, dcm.latency_s / dcm.sample_interval_s - channel_delay_samples)
    nominal, ratios = float(ratios[0]), ratios[1:]
    if not np.all(np.isfinite(ratios)) or np.any(ratios <= 0) or not nominal > 0:
        raise AnalysisError("compensated peak: a model draw gives no peak of the reference's polarity")
    rng = peak_noise_rng(seed)
    noise = (dcm.noise_gain() * response_noise_rms / abs(gain)) if response_noise_rms else 0.0
    truths = (value + noise * rng.standard_normal(ratios.size)) / ratios
    lo, hi = coverage_ends(truths, COVERAGE)
    shown = value / nominal - pulse.peak_m_s2  # the model's error this shot shows in the figure
    spread = float(np.std(truths, ddof=1))
    return {"value": value, "u": math.sqrt(spread**2 + shown**2 / 3.0), "u_draws": spread,
            "interval": [float(min(lo, value, lo - shown)), float(max(hi, value, hi - shown))],
            "dcm_residual_pct": 100.0 * (nominal - 1.0), "model_error_pct": 100.0 * shown / pulse.peak_m_s2}


def to_rate(record: Record, sample_rate_hz: float) -> tuple[Record, str | None]:
    """The record at `sample_rate_hz` (within 0.1 %) and what was done (None: nothing).

    Faster records go through analysis.resample.resample_to_rate (anti-alias low-pass, as
    `identify` does); slower ones are interpolated with scipy.signal.resample_poly (band-limited:
    nothing appears above the record's own Nyquist frequency).
    """
    source = record.sample_rate_hz
    if abs(source - sample_rate_hz) <= 1e-3 * sample_rate_hz:
        return record, None
    if source > sample_rate_hz:
        out = replace(resample_to_rate(record, sample_rate_hz), response_unit=record.response_unit)
        how = "low-pass filtered and resampled"
    else:
        up, down = resampling_factors(source, sample_rate_hz)
        out = replace(
            record,
            sample_interval_s=record.sample_interval_s * down / up,
            reference=signal.resample_poly(record.reference, up, down, padtype="line"),
            response=signal.resample_poly(record.response, up, down, padtype="line"),
        )
        how = "interpolated (band-limited)"
    if abs(out.sample_rate_hz - sample_rate_hz) > 1e-3 * sample_rate_hz:
        raise AnalysisError(
            f"cannot bring a record at {source:g} Hz to {sample_rate_hz:g} Hz (the nearest rational rate is "
            f"{out.sample_rate_hz:g} Hz)"
        )
    return out, f"{how} from {source:g} Hz to {out.sample_rate_hz:g} Hz, the DCM's rate"


def _same_rate(record: Record, dcm: DCM) -> None:
    if abs(record.sample_interval_s - dcm.sample_interval_s) > 1e-3 * dcm.sample_interval_s:
        raise AnalysisError(
            f"the record is sampled every {record.sample_interval_s:g} s, the DCM was designed for "
            f"{dcm.sample_interval_s:g} s (bring it to the DCM's rate first: analysis.compensation.to_rate)"
        )


@dataclass(frozen=True)
class ShotCompensation:
    """A shot's DCM design, its check on the shot and the verdict (the results' "dcm" extras)."""

    design: DcmDesign
    check: CompensationCheck | None
    recommended: bool | None
    not_recommended_reason: str | None
    compensated_peak: dict[str, Any] | None
    warnings: tuple[str, ...] = ()

    def to_dict(self) -> dict[str, Any]:
        """The keys of the results' "dcm" object this check gives (docs/files-and-formats.md)."""
        return {
            **self.design.to_dict(),
            "recommended": self.recommended,
            "not_recommended_reason": self.not_recommended_reason,
            "check": None if self.check is None else self.check.to_dict(),
            "compensated_peak": self.compensated_peak,
        }


    def with_draws(self, identification: Identification, record: Record, draws: Sequence[DiscreteModel],
                   seed: int | None = None) -> ShotCompensation:
        """The same, with the compensated peak's interval from the uncertainty's model draws
        (UncertaintyResult.model_draws); a failure is a warning, never a failed shot."""
        if not draws:
            return self
        model = identification.model
        rec, _ = to_rate(record, 1.0 / model.sample_interval_s)
        return self._with_peak(_Shot(rec, model, self.design.dcm), identification, draws, seed)

    def _with_peak(self, shot: _Shot, identification: Identification, draws: Sequence[DiscreteModel],
                   seed: int | None) -> ShotCompensation:
        """`with_draws` on the shot at the model's rate (`shot`: what the check read off it, shared)."""
        if not draws:
            return self
        noise = identification.noise.response_rms
        try:
            peak = _compensated_peak(shot, float(identification.delay_samples), draws, noise, seed)
        except AnalysisError as exc:
            return replace(self, warnings=(*self.warnings, f"DCM: no interval for the compensated peak ({exc})"))
        return replace(self, compensated_peak=peak)


def compensate_shot(identification: Identification, record: Record, options: AnalysisOptions,
                    draws: Sequence[DiscreteModel] = (), seed: int | None = None) -> ShotCompensation:
    """Design the DCM the shot supports, check it on the shot, give the compensated peak its
    interval (with model draws) and judge it. A failed check is a warning, never a failed shot."""
    model = identification.model
    rec, _ = to_rate(record, 1.0 / model.sample_interval_s)
    support = ShotSupport.from_identification(identification, rec)
    design = design_compensation(support, options)
    warnings: list[str] = []
    if design.widening_short and options.dcm_ratio is None:
        warnings.append(f"DCM widening: {design.widening_note}")
    check = None
    shot = _Shot(rec, model, design.dcm, support.pulse)  # read once for the check and the compensated peak
    try:
        check = _check(shot, support.channel_delay_samples, design.fbsd_hz["5"])
    except AnalysisError as exc:
        warnings.append(f"DCM: the compensation could not be checked on the shot ({exc})")
    result = ShotCompensation(design, check, None, None, None, tuple(warnings))._with_peak(
        shot, identification, draws, seed)
    if check is not None:
        u = peak_error_u_pct(check, design.dcm, model.dc_gain, identification.noise, result.compensated_peak)
        check = replace(check, peak_error_u_pct=u)
    recommended, reason = recommendation(design, check)
    more = (f"DCM not recommended for this shot: {reason}",) if recommended is False else ()
    return replace(result, check=check, recommended=recommended, not_recommended_reason=reason,
                   warnings=(*result.warnings, *more))
