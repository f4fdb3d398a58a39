"""The prepare stage of analysis.identify: the record made ready for the fit (normalised units:
each channel divided by its largest excursion).

- `prepare_record` → `PreparedRecord`: the analysis rate, a response that leads realigned
  (`realigned` → `Alignment`), the channels checked and scaled, then:
- `locate_pulse` (analysis.pulse_location) → `Activity`: the pulse, each channel's baseline, the
  fitted window;
- `measure_noise` → `NoiseLooks`: the quiet stretches less the bar's motion after the pulse, a
  drift pinned by them, each channel's noise spectrum in two looks (conservative: weighs the
  fit; unbiased: what the uncertainty draws);
- `fitted_band` → `Prepared`: the supported band's DFT bins and each bin's noise variance.

Each returns its findings (analysis.findings). Why: docs/decisions/0010, 0012.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
from numpy import fft

from hopkinson.analysis.errors import AnalysisError
from hopkinson.analysis.excitation import SupportedBand, supported_band
from hopkinson.analysis.findings import Finding, FindingCode
from hopkinson.analysis.frequency_fit import OrderFit
from hopkinson.analysis.input_terms import ONSET, InputTerms, input_terms
from hopkinson.analysis.noise import (
    COHERENCE_SEGMENT,
    WELCH_SEGMENT,
    NoiseSpectrum,
    first_motion,
)
from hopkinson.analysis.numerics import next_fast_len
from hopkinson.analysis.preprocessing import DriftLine, Preprocessing
from hopkinson.analysis.pulse_location import MIN_QUIET, Activity, locate_pulse
from hopkinson.analysis.records import Record
from hopkinson.analysis.resample import estimate_delay_samples, resample_to_rate
from hopkinson.analysis.response import simulate_from_rest
from hopkinson.analysis.spectral_data import SpectralData

# Samples per model parameter below which a record is too short for an order.
MIN_SAMPLES_PER_PARAMETER = 10
# More bins than this are summed in groups of adjacent bins (same cost while G is flat there).
MAX_BINS = 512
# The band runs across the pulse's nulls up to this fraction of the Nyquist frequency at most: the
# last fifth below it holds the resampling's anti-alias transition, which no model of the sensor
# follows (a 10 µs half-sine's sidelobes reach 450 kHz at 1 MS/s).
NULLS_CROSSED_TO = 0.8
# Motion after the pulse (_without_motion): a stretch's tails are judged from its start in steps
# of MOTION_STEP samples, down to MOTION_TAIL samples (9 coherence segments: 4/K = 0.44).
MOTION_STEP = 64
MOTION_TAIL = 5 * COHERENCE_SEGMENT
# A stretch after the pulse shorter than this (16 coherence segments, where the chance level 4/K
# reaches MOTION_COHERENCE) cannot show weak motion by its coherence: while the other channel is
# still moving over it, or when motion follows it, it is not taken as at rest (PTB's record cut to
# 1.2 ms: 0.2 ms of the bar's motion after the pulse, coherence not judged, read as the
# reference's noise at 12x the lead-in's, and the model error went undetected).
MOTION_JUDGED = 17 * COHERENCE_SEGMENT // 2
# The response's mean power per bin of the fitted band, over its noise's, at or below which it is
# taken as showing no response (pure noise reads 1, ±0.2 over 50 bins; a real shot 10³–10⁹).
RESPONSE_ABOVE_NOISE = 2.0
# A response leading the reference by more than this many samples (their cross-correlation) is the
# channels' skew or the reference chain's own delay (an interferometer's demodulation and low-pass:
# microseconds), not the sensor, which cannot answer before it is excited. Neither structure follows
# such a lead from the fit's start (PTB's response shifted 7-10 µs earlier: every fit unstable), so
# the response is realigned by whole samples first (`realigned`); the model's delay keeps the lead.
SKEWED_LEAD_SAMPLES = 2.0


@dataclass(frozen=True)
class Prepared:
    """Stage "band": the record as the fit sees it (normalised units): the fitted window, its DFT
    bins in the supported band and each bin's noise variance in two looks (the conservative one
    weighs the fit, the unbiased one is what the uncertainty draws), with the stages it was made
    from. The search stages return it with the input terms they fit (`terms`, `spectral`,
    `unseen`: analysis.identify_stages), never change it."""

    activity: Activity  # where the pulse is and each channel's baseline (locate_pulse)
    noise: NoiseLooks  # each channel's noise and where it was measured (measure_noise)
    u: np.ndarray  # the fitted window [start, start + u.size), baseline and drift removed
    y: np.ndarray
    start: int
    band: tuple[float, float]  # the supported band's hull (low, top), Hz
    bin_hz: np.ndarray  # the fitted bins' frequencies
    u_bins: np.ndarray  # the window's DFT at those bins
    y_bins: np.ndarray
    var_u: np.ndarray  # each bin's noise variance, the conservative look
    var_y: np.ndarray
    draw_var_u: np.ndarray  # the unbiased look
    draw_var_y: np.ndarray
    group: int  # bins per group in `spectral` (1: per bin)
    spectral: SpectralData
    support: SupportedBand | None = None  # the supported stretches (the nulls between them are not fitted)
    bin_index: np.ndarray | None = None  # each fitted bin's index in the window's DFT
    ramp: np.ndarray | None = None  # the drift ramp's DFT at the fitted bins (with a transient term)
    # The input terms fitted (analysis.input_terms: in `spectral`), and the onset terms tried (identify)
    terms: InputTerms = field(default_factory=InputTerms)
    onset_terms: InputTerms | None = None
    terms_source: tuple = ()  # input_terms' arguments (analysis.systematics makes its variants from them)
    unseen: dict[str, float] = field(default_factory=dict)  # term not seen beyond chance -> its standard uncertainty
    findings: tuple[Finding, ...] = ()  # the band stage's (a record cut short)

    def terms_variant(self, **options: Any) -> InputTerms:
        """The candidate input terms made with other `options` (input_terms' keywords), with the same
        terms as fitted (`terms`: those not fitted left out; the onset kept only if fitted, or
        `with_onset`)."""
        with_onset = options.pop("with_onset", False)
        made = input_terms(*self.terms_source, **options)
        for name in {*made.names} - {*self.terms.names}:
            if name != ONSET or not with_onset:
                made = made.without(name, self.terms.not_fitted.get(name, ""))
        return made

    def corrected_u(self, coefficients: np.ndarray) -> np.ndarray:
        """The window's reference with the fitted input terms' correction (`terms`)."""
        if not self.terms.count:
            return self.u
        return self.u + self.terms.correction(coefficients)[self.start : self.start + self.u.size]

    def band_without_onset(self, coefficients: np.ndarray, dt: float) -> SupportedBand | None:
        """The band the reference supports with the fitted onset disturbances taken out (None where
        none are fitted): its demodulation glitches are the reference's errors, not the bar's
        motion, and their broad spectrum can stand above the reference's noise far beyond the
        pulse's own (`band_of`)."""
        columns = self.terms.columns(ONSET)
        if not columns.size or np.asarray(coefficients).size != self.terms.count:
            return None
        onset = np.zeros(self.terms.count)
        onset[columns] = np.asarray(coefficients)[columns]
        return band_of(self.noise.u + self.terms.correction(onset), dt, self.noise.noise_u)

    def with_terms(self, terms: InputTerms) -> SpectralData:
        """The fitted data with `terms`' input terms (per bin: data with input terms are never grouped)."""
        assert self.bin_index is not None and not self.spectral.grouped
        return replace(self.spectral, inputs=terms.bins(self.start, self.start + self.u.size, self.bin_index),
                       input_prior=terms.prior)


def _scale(x: np.ndarray) -> float:
    """The channel's largest excursion from its median: the unit the fit works in."""
    return float(np.max(np.abs(x - np.median(x))))


@dataclass(frozen=True)
class Alignment:
    """What `realigned` found and did: the response led the reference by `lead` samples by their
    cross-correlation (0: by no more than SKEWED_LEAD_SAMPLES) and was delayed by `shift` whole
    samples (0: not). A lead not taken lay at the edge of the search (`at_edge`: it may be
    larger) or too near the record's start for the response's lead-in to cover it."""

    shift: int = 0
    lead: float = 0.0
    at_edge: bool = False

    @property
    def not_taken(self) -> bool:
        return self.lead > 0 and self.shift == 0

    def not_taken_text(self, sample_interval_s: float) -> str:
        """The lead not taken and why, for a refusal or a warning ("" when there is none)."""
        if not self.not_taken:
            return ""
        us = self.lead * sample_interval_s * 1e6
        if self.at_edge:
            return (f"the channels' cross-correlation peaks at the edge of its search, a lead of {self.lead:.3g} "
                    f"samples ({us:.3g} µs) or more, beyond what the analysis realigns")
        return (f"the response leads the reference by about {self.lead:.3g} samples ({us:.3g} µs) by their "
                "cross-correlation, too near the record's start to be realigned")


@dataclass(frozen=True)
class PreparedRecord:
    """Stage 1–4's result: the prepared data and what the report says about how it was made."""

    record: Record  # at the analysis rate
    prep: Prepared
    scale_u: float  # the record's reference = scale_u × normalised u
    scale_y: float
    u_all: np.ndarray  # each whole channel normalised, its median removed (the ARX losses' input)
    y_all: np.ndarray
    preprocessing: Preprocessing
    alignment: Alignment = field(default_factory=Alignment)  # what `realigned` did
    findings: tuple[Finding, ...] = ()  # the noise's and the band's, in that order

    @property
    def realigned_samples(self) -> int:
        """The response was delayed by this many samples before the fit: a fitted delay τ is the
        model's τ − realigned_samples."""
        return self.alignment.shift

    def model_delay(self, fit_delay_samples: float) -> float:
        """The model's delay (samples) of a fit's (on the realigned record)."""
        return float(fit_delay_samples) - self.realigned_samples


def prepare_record(record: Record, sample_rate_hz: float | None, n_max: int, order: int | None, max_delay: int,
                   realign: bool = True, band_top_hz: float | None = None) -> PreparedRecord:
    """Resample to the analysis rate (None: the record's), realign a response that leads by
    several samples (`realigned`; not when `realign` is False: the delay held at 0;
    claims.delay_findings says so), check and scale both channels, and run the prepare, noise
    and band stages (the band capped at `band_top_hz`: identify's cut); their findings in
    `findings`."""
    rec = record if sample_rate_hz is None else resample_to_rate(record, sample_rate_hz)
    resampled_to_hz = rec.sample_rate_hz if rec is not record else None
    alignment = Alignment()
    if realign:  # (a channel with a NaN is not realigned: checked_channels below refuses it)
        rec, alignment = realigned(rec, max_delay)
    shift = alignment.shift
    ref, resp = checked_channels(rec)
    dt = rec.sample_interval_s
    need = MIN_SAMPLES_PER_PARAMETER * (2 * n_max + 1)
    if ref.size < need:
        what = f"order {order}" if order is not None and order >= n_max else f"max order {n_max}"
        raise AnalysisError(
            f"record too short for {what}: {ref.size} samples at the analysis rate, need at least {need} "
            f"({MIN_SAMPLES_PER_PARAMETER} per parameter)"
        )
    scale_u = _scale(ref)
    scale_y = _scale(resp)
    u_all, y_all = (ref - np.median(ref)) / scale_u, (resp - np.median(resp)) / scale_y
    activity = locate_pulse(u_all, y_all, dt, max_delay)
    noise = measure_noise(activity, dt)
    prep = fitted_band(activity, noise, dt, band_top_hz)
    # What was taken off each channel, in its own units, at time t of the record:
    # <channel>_baseline + intercept + slope_per_s · (t − origin_s): the report redoes it.
    # (the response, realigned, starts `shift` samples before the record: `realigned`)
    drift = {name: DriftLine(line[1] * scale, line[0] * scale / dt,
                             rec.start_time_s - (shift * dt if name == "response" else 0.0))
             for (name, line), scale in zip(prep.noise.drift_lines.items(), (scale_u, scale_y), strict=True)}
    pre = Preprocessing(
        record_sample_rate_hz=record.sample_rate_hz,
        resampled_to_hz=resampled_to_hz,
        response_lead_by_cross_correlation_samples=alignment.lead or None,
        response_realigned_samples=alignment.shift or None,
        reference_baseline=float(np.median(ref) + prep.activity.baseline_u * scale_u),
        response_baseline=float(np.median(resp) + prep.activity.baseline_y * scale_y),
        drift_removed=prep.noise.drift_removed,
        reference_drift=drift["reference"],
        response_drift=drift["response"],
        window_start_s=rec.start_time_s + prep.start * dt,
        window_samples=int(prep.u.size),
        fitted_bins=prep.spectral.bins,
        bin_group=prep.group,
        transient_term=prep.spectral.transient,
        scale_reference=scale_u,
        scale_response=scale_y,
    )
    return PreparedRecord(rec, prep, scale_u, scale_y, u_all, y_all, pre, alignment, noise.findings + prep.findings)


def realigned(rec: Record, max_delay: int) -> tuple[Record, Alignment]:
    """The record with its response delayed by S whole samples where it leads the reference by
    more than SKEWED_LEAD_SAMPLES (their cross-correlation over the whole record:
    analysis.resample.estimate_delay_samples), so that each response sample stands beside the
    reference S samples before it; and what was done (`Alignment`). The reference is kept whole,
    its lead-in at rest with it (its first S samples dropped instead, PTB's record at 0.25 MS/s
    with a 120 µs lead lost its lead-in and missed the sine); the response's last S samples are
    dropped and its first S mirrored from its own lead-in (np.pad "reflect": noise of its own
    level, continuous at the join). S is the lead rounded up: the response then lags by a
    fraction of a sample, as a causal model has it. The lag is searched within twice the longest
    delay the fit searches; a lead at the search's edge is not located and not taken, nor one the
    response's lead-in cannot mirror (its pulse within 2·S samples of its start): the refusal or
    warning that follows says so (`Alignment.not_taken_text`)."""
    reach = max(1, min(2 * int(max_delay), rec.n_samples // 4))
    try:
        lag = estimate_delay_samples(rec.reference, rec.response, reach)
    except AnalysisError:
        return rec, Alignment()
    if lag >= -SKEWED_LEAD_SAMPLES:
        return rec, Alignment()
    if -lag >= reach - 1:
        return rec, Alignment(lead=-lag, at_edge=True)
    shift = int(math.ceil(-lag))
    resp = np.asarray(rec.response, dtype=float)
    head = resp[: 2 * shift + 1]
    if np.max(np.abs(head - np.median(head))) > 0.5 * np.max(np.abs(resp - np.median(resp))):
        return rec, Alignment(lead=-lag)
    moved = np.pad(resp[: resp.size - shift], (shift, 0), mode="reflect")
    return (Record(rec.sample_interval_s, rec.reference, moved, rec.start_time_s, rec.response_unit),
            Alignment(shift, -lag))


@dataclass(frozen=True)
class NoiseLooks:
    """Stage "noise": each channel's noise, measured where it is at rest."""

    u: np.ndarray  # the whole record, baseline and drift removed
    y: np.ndarray
    u_segments: list[slice]  # where each noise was measured
    y_segments: list[slice]
    motion: list[dict[str, Any]]  # stretches after the pulse left out as motion (samples, coherence, reason)
    drift_removed: bool
    drift_lines: dict[str, tuple[float, float]]  # channel -> (slope per sample, intercept) removed
    noise_u: NoiseSpectrum  # the conservative look (weighs the fit and the order test)
    noise_y: NoiseSpectrum
    draw_noise_u: NoiseSpectrum  # the unbiased look (the uncertainty's draws)
    draw_noise_y: NoiseSpectrum
    findings: tuple[Finding, ...] = ()


def measure_noise(activity: Activity, dt: float) -> NoiseLooks:
    """The quiet stretches less the bar's coherent motion (_without_motion), a drift removed
    when quiet stretches before the first and after the last activity pin it (the line through
    the quiet samples), and each channel's noise spectrum there (analysis.noise)."""
    u, y = activity.u.copy(), activity.y.copy()
    n = u.size
    u_segments, y_segments, motion, findings = _without_motion(u, y, dt, activity.u_segments, activity.y_segments)
    drift = False
    lines = {"reference": (0.0, 0.0), "response": (0.0, 0.0)}  # (slope per sample, intercept), removed
    for name, x, segs in (("reference", u, u_segments), ("response", y, y_segments)):
        if len(segs) >= 2 and segs[0].start == 0 and segs[-1].stop == n:
            idx = np.concatenate([np.arange(r.start, r.stop) for r in segs])
            slope, intercept = np.polyfit(idx, x[idx], 1)
            x -= slope * np.arange(n) + intercept
            lines[name] = (float(slope), float(intercept))
            drift = True
    rate = 1.0 / dt
    # Two looks at the noise (analysis.noise): the conservative one weighs the fit and the
    # order test (as validated); the unbiased one is what the uncertainty's draws add.
    noise_u = NoiseSpectrum.measure(u, rate, u_segments, conservative=True)
    noise_y = NoiseSpectrum.measure(y, rate, y_segments, conservative=True)
    draw_noise_u = NoiseSpectrum.measure(u, rate, u_segments)
    draw_noise_y = NoiseSpectrum.measure(y, rate, y_segments)
    if noise_u.samples == 0:
        findings.append(Finding(FindingCode.NO_QUIET_REFERENCE,
                                "the reference has no quiet stretch (before the pulse or in flight after it) to "
                                "measure its noise: it is taken as noise-free, which understates the uncertainty"))
    if noise_y.samples == 0:
        noise_y = draw_noise_y = NoiseSpectrum.white(activity.noise_y0, rate, "record tail (robust)", 0)
        findings.append(Finding(FindingCode.NO_QUIET_RESPONSE,
                                "the response has no quiet stretch to measure its noise: a robust level from the "
                                "end of the record is used"))
    return NoiseLooks(u, y, u_segments, y_segments, motion, drift, lines, noise_u, noise_y, draw_noise_u,
                      draw_noise_y, tuple(findings))


def band_of(u: np.ndarray, dt: float, noise_u: NoiseSpectrum) -> SupportedBand:
    """The band the reference `u` supports above its noise (analysis.excitation.supported_band),
    past its first null not into the analysis rate's last fifth."""
    try:
        support = supported_band(u, dt, noise_psd=noise_u.at if noise_u.samples else None)
    except AnalysisError as exc:
        raise AnalysisError(f"the reference's pulse is lost in its noise: {exc}") from None
    if len(support.intervals_hz) > 1:
        support = support.below(NULLS_CROSSED_TO * 0.5 / dt)
    return support


def fitted_band(activity: Activity, noise: NoiseLooks, dt: float,
                band_top_hz: float | None = None) -> Prepared:
    """The band the excitation supports (where the reference's spectrum stands 20 dB above its
    noise and within 40 dB of its maximum, across the pulse's narrow spectral nulls:
    analysis.excitation.supported_band), the window's DFT bins inside it (not in its nulls) (grouped beyond MAX_BINS; per bin with a transient term when the record
    is cut short or starts cold) and each bin's noise variance."""
    u, y, n = noise.u, noise.y, noise.u.size
    start, end, truncated, cold_start = activity.start, activity.end, activity.truncated, activity.cold_start
    noise_u, noise_y = noise.noise_u, noise.noise_y
    draw_noise_u, draw_noise_y = noise.draw_noise_u, noise.draw_noise_y
    if not truncated and not cold_start:  # a window the FFT likes, from real (quiet) samples
        fast = next_fast_len(end - start)
        if start + fast <= n:
            end = start + fast
    uw, yw = u[start:end], y[start:end]
    support = band_of(u, dt, noise_u)
    if band_top_hz is not None:
        support = support.below(band_top_hz)
    band = support.hull_hz
    length = uw.size
    freq = fft.rfftfreq(length, dt)
    keep = support.contains(freq) & (freq >= (freq[1] if freq.size > 1 else 0.0))
    keep[0] = False
    if not np.any(keep):
        raise AnalysisError("the supported band holds no frequency bin of the fitted window (record too short)")
    u_spec = fft.rfft(uw)[keep]
    y_spec = fft.rfft(yw)[keep]
    bin_hz = freq[keep]
    omega = 2.0 * np.pi * bin_hz * dt
    rate = 1.0 / dt
    var_u = noise_u.bin_variance(bin_hz, length) if noise_u.samples else np.zeros(bin_hz.size)
    var_y = noise_y.bin_variance(bin_hz, length)
    floor = 1e-12 * float(np.mean(np.abs(y_spec) ** 2))  # a noise-free record still gets finite weights
    var_y = np.maximum(var_y, floor)
    draw_var_u = draw_noise_u.bin_variance(bin_hz, length) if draw_noise_u.samples else np.zeros(bin_hz.size)
    draw_var_y = np.maximum(draw_noise_y.bin_variance(bin_hz, length), floor)
    above = float(np.mean(np.abs(y_spec) ** 2 / draw_var_y))
    if above <= RESPONSE_ABOVE_NOISE:
        raise AnalysisError(
            f"the response shows nothing above its noise where the reference excites it: over "
            f"{band[0] / 1e3:.3g}–{band[1] / 1e3:.3g} kHz its power is {above:.2g}× what its noise alone gives: "
            "the channels do not belong together (a wrong channel or sensor), or the sensor was not connected")
    # The conservative look detrends each Welch segment, which empties its lowest bins: a slow
    # baseline wander (cable, thermal; below its first bins) was then weighed as if absent, and
    # a spare pole near DC 'explained' it beyond chance (DC gain off by 5 %, FBSD at 1 kHz).
    # Below the detrended segments' second bin the fit takes the larger of the two looks.
    low = bin_hz < 2.0 * rate / WELCH_SEGMENT
    var_u = np.where(low, np.maximum(var_u, draw_var_u), var_u)
    var_y = np.where(low, np.maximum(var_y, draw_var_y), var_y)
    transient = truncated or cold_start
    terms_source = (u, dt, activity.pulse_start, noise_u.rms if noise_u.samples else 0.0, activity.ref_busy,
                    band[1], any(m["reason"] == "coherent" for m in noise.motion))
    terms = input_terms(*terms_source)
    onset_terms = terms if terms.columns(ONSET).size else None
    if onset_terms is not None:  # the onset is fitted only where it shows (identify decides)
        terms = terms.without(ONSET, "")
    inputs = terms.bins(start, end, np.flatnonzero(keep))
    ramp = None
    findings: tuple[Finding, ...] = ()
    if truncated:
        findings = (Finding(FindingCode.CUT_SHORT,
                            "the record ends before the response has died away: a transient term is fitted with "
                            "the model, and the uncertainty is larger than a complete record would give"),)
    if transient:
        t = np.arange(length, dtype=float)
        ramp = fft.rfft((t - t.mean()) / length)[keep]
        spectral = replace(SpectralData.per_bin(omega, u_spec, y_spec, var_u, var_y, ramp, True, inputs),
                           input_prior=terms.prior)
        group = 1
    else:
        group = 1 if inputs is not None or onset_terms is not None else max(1, math.ceil(bin_hz.size / MAX_BINS))
        if group == 1:
            spectral = replace(SpectralData.per_bin(omega, u_spec, y_spec, var_u, var_y, inputs=inputs),
                               input_prior=terms.prior)
        else:
            spectral = SpectralData.grouped_from(omega, u_spec, y_spec, var_u, var_y, group)
    return Prepared(activity, noise, uw, yw, start, band, bin_hz, u_spec, y_spec, var_u, var_y, draw_var_u, draw_var_y,
                    group, spectral, support, np.flatnonzero(keep), ramp, terms, onset_terms, terms_source,
                    findings=findings)


def response_noise_on_residual(prep: Prepared, fit: OrderFit, dt: float) -> tuple[NoiseSpectrum, np.ndarray]:
    """The response's noise measured again on the same quiet stretches, with the model's
    response to the pulse taken out: a lightly damped sensor still rings below the loudness
    test's 4 RMS when its stretch after the pulse is judged quiet, and that ringing, measured
    as noise, sat at the resonance (f_n's and ζ's intervals 1.5× too wide) and raised the RMS
    ~1.5×. Frequency by frequency the lower of the two looks is kept: outside the fitted band
    the model is not measured (a spare pole near z = 1 predicts a tail the record does not
    have), and there taking it out would add power instead. Returns the spectrum and its
    variance per fitted bin (the first look's when there was no stretch to measure)."""
    if prep.noise.draw_noise_y.samples == 0 or prep.noise.draw_noise_y.source.startswith("record tail"):
        return prep.noise.draw_noise_y, prep.draw_var_y
    # The model driven by the pulse alone: driven by the whole reference it would add the
    # reference's noise through G, counted as response noise (~15 % too much at 2 % each).
    drive = prep.noise.u + prep.terms.correction(fit.inputs) if prep.terms.count else prep.noise.u
    residual = prep.noise.y - simulate_from_rest(fit.a, fit.b, fit.delay, np.where(prep.activity.ref_busy, drive, 0.0))
    second = NoiseSpectrum.measure(residual, 1.0 / dt, prep.noise.y_segments)
    if second.samples == 0:
        return prep.noise.draw_noise_y, prep.draw_var_y
    noise = second.lower_of(prep.noise.draw_noise_y)
    var_y = noise.bin_variance(prep.bin_hz, prep.u.size)
    return noise, np.maximum(var_y, 1e-12 * float(np.mean(np.abs(prep.y_bins) ** 2)))


def with_output_variance(prep: Prepared, var_y: np.ndarray) -> SpectralData:
    """The fitted data with another output variance per bin (per bin or grouped as prepared)."""
    return replace(prep.spectral, var_y=prep.spectral.in_layout(var_y))


def checked_channels(rec: Record) -> tuple[np.ndarray, np.ndarray]:
    """Both channels as float arrays: finite, of equal length, not flat (else an AnalysisError)."""
    ref = np.asarray(rec.reference, dtype=float).ravel()
    resp = np.asarray(rec.response, dtype=float).ravel()
    for name, x in (("reference", ref), ("response", resp)):
        if not np.all(np.isfinite(x)):
            bad = int(np.flatnonzero(~np.isfinite(x))[0])
            raise AnalysisError(f"the {name} channel has a NaN or infinite value at sample {bad}")
    if ref.size != resp.size:
        raise AnalysisError(f"the channels differ in length ({ref.size} and {resp.size} samples)")
    for name, x in (("reference", ref), ("response", resp)):
        if x.size == 0 or np.ptp(x) == 0:
            raise AnalysisError(f"the {name} channel is flat (constant): there is nothing to identify")
    return ref, resp


def _without_motion(u: np.ndarray, y: np.ndarray, dt: float, u_segments: list[slice], y_segments: list[slice]
                    ) -> tuple[list[slice], list[slice], list[dict[str, Any]], list[Finding]]:
    """The quiet stretches with those after the pulse where the channels move together taken
    out (analysis.noise.is_motion): the bar keeps moving after the pulse (PTB's record: 1–2 %
    of the peak for > 1 ms, coherence 0.88), and that motion, taken as noise, inflated the
    reference's noise ×12, cut the band, blinded the order test and hid the model error. Noise
    is measured where a channel is at rest: the lead-in, and a stretch after the pulse up to
    where its motion starts, when the other channel is at rest over that head or the head is
    long enough to be judged itself (a bonded sensor's ringing hides the bar's motion from the
    pulse on: the head held flight and motion, and set the reference's noise in the band ~10⁴
    times too high on the simulator's bonded shots). A channel with no lead-in long enough keeps
    its stretches (with a warning)."""
    motion: list[dict[str, Any]] = []
    split: dict[tuple[int, int], list[slice]] = {}

    def unjudged(r: slice, other_quiet: list[slice]) -> bool:
        """Whether stretch r is too short for its coherence to show weak motion while the other
        channel is busy over it: not at rest (recorded as motion)."""
        if r.stop - r.start < MOTION_JUDGED and _moving_over(r, other_quiet):
            motion.append({"start_sample": r.start, "stop_sample": r.stop, "coherence": None,
                           "reason": "too short to judge by coherence, the other channel not at rest"})
            return True
        return False

    def at_rest_before(head: slice, other_quiet: list[slice]) -> bool:
        """Whether the head before a stretch's moving tail is at rest. The tail's onset is where
        its coherence first clears is_motion's threshold; weak motion in the head dilutes that
        coherence, so the motion may well have begun earlier (PTB's record with 2 % of its peak
        of noise added: found at 1.06–1.19 ms, begun at ~0.87–0.98; the head taken as quiet
        read the reference's noise ×1.3–1.6 too high). A head too short for its own coherence
        to tell (MOTION_JUDGED) is not at rest."""
        length = head.stop - head.start
        if length >= MOTION_JUDGED:
            return True
        if length >= MIN_QUIET and not unjudged(head, other_quiet):  # unjudged records its own reason
            motion.append({"start_sample": head.start, "stop_sample": head.stop, "coherence": None,
                           "reason": "too short to judge by coherence, and the motion that follows may have "
                                     "begun in it"})
        return False

    def at_rest(r: slice, other_quiet: list[slice]) -> list[slice]:
        """The part of stretch r that is not motion: all of it, none, or the part before the
        longest tail that is (the sensor still ringing at the start of a stretch hides the
        motion that follows in a judgement of the whole: the tail is judged in steps of
        MOTION_STEP), that head kept only if `at_rest_before`."""
        key = (r.start, r.stop)
        if key not in split:
            split[key] = [r]
            if r.start > 0:
                onsets = [r.start, *range(r.start + MOTION_STEP, r.stop - MOTION_TAIL + 1, MOTION_STEP)]
                found = first_motion(u, y, 1.0 / dt, onsets, r.stop)  # is_motion on each tail in turn
                if found is not None:
                    onset, msc = found
                    motion.append({"start_sample": onset, "stop_sample": r.stop, "coherence": msc,
                                   "reason": "coherent"})
                    head = slice(r.start, onset)
                    split[key] = [head] if at_rest_before(head, other_quiet) else []
                elif unjudged(r, other_quiet):
                    split[key] = []
        return split[key]

    out, findings = [], []
    for name, segs, other in (("reference", u_segments, y_segments), ("response", y_segments, u_segments)):
        kept = [part for r in segs for part in at_rest(r, other)]
        if kept != segs and not any(r.start == 0 for r in kept):
            findings.append(Finding(FindingCode.NOT_AT_REST,
                                    f"the {name} is not at rest after the pulse (it moves with the other channel) "
                                    "and has no lead-in at rest: its noise is measured on that motion, which "
                                    "overstates it"))
            kept = segs
        out.append(kept)
    return out[0], out[1], motion, findings


def _moving_over(r: slice, other_quiet: list[slice]) -> bool:
    """Whether the other channel is busy (outside its own quiet stretches) over most of the
    stretch r: the bar or the sensor is still moving there."""
    quiet = sum(max(0, min(r.stop, q.stop) - max(r.start, q.start)) for q in other_quiet)
    return quiet < 0.5 * (r.stop - r.start)
