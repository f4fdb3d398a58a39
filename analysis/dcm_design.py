"""The DCM a shot supports: which poles it cancels, the automatic ratio, the band limit, the
noise-gain bound and the latency. analysis.dcm holds the paper's design itself.

- **Cancelled poles.** Only modes the excitation supports (Identification.modes[i]["supported"]);
  never a pole at the origin, a negative real pole (at Nyquist: a discretisation artefact), a
  mode within 20 % of Nyquist, or a pole that a model zero nearly cancels (a spare pole-zero
  pair of the fit: cancelling the pole alone would leave the zero as a notch). Model zeros are
  never inverted (the DCM's zeros are the cancelled poles only), so a non-minimum-phase zero
  stays what it is; the DCM's poles all lie inside the unit circle.
- **Ratio.** The paper's r (Eqs. 21-25) from the slowest cancelled pole, chosen by
  analysis.dcm_ratio: by default sized to the shot's pulse (the smallest r at which its
  compensated peak settles), capped by the band limit and the noise-gain limit; without a
  pulse, the widest band they allow; `widening` W aims for W × the model's ±5 % band instead.
  The note says why r sits where it does and, when it falls short, what stopped it.
- **Band limit.** A linear-phase FIR stage after the paper's pole-zero design (`DCM.fir`)
  whose magnitude is a 4th-order Butterworth low-pass's, unit DC gain, with its ±5 % edge at
  the top of the band the shot vouches for: the band the excitation supports (its spectrum ≥
  1 % of its peak and 20 dB above the reference noise: analysis.excitation) and, with the
  shot's record, the band where the response stands 20 dB above its own noise. So the
  compensated ±5 % band can reach that top and not pass it: beyond it the model is not
  measured, and the low-pass rolls off there. Linear phase, because a causal IIR low-pass
  bends a pulse's shape by its own phase: until stop 39 the band limit was a 2nd-order
  Butterworth IIR (poles exp(s·T)), and on PTB's shock model × DCM applied to the reference
  itself lowered its peak by 0.78 %, 0.24 % of it the phase; with this stage by 0.42 %, and
  the compensated peak error went from −1.23 % to −0.89 %. 4th order, because the same edge then
  passes the band flatter (a 2nd-order linear-phase stage: −1.05 %); its latency, half its
  length (≈ 2 × the sample rate / the edge: 71 µs at 1 MS/s and 28 kHz), is part of the
  DCM's and removed with it. (The −3 dB point at the top, as until stop 34, capped the
  compensated band at 0.57 × the top and lowered PTB's compensated peak by 3.7 %.)
- **Noise gain.** RMS amplification of white noise at the analysis rate (DCM.noise_gain),
  bounded by `noise_gain_limit` in the automatic design; an explicit ratio above the limit is
  designed as asked and reported.
- **Latency.** The identified channel delay plus the low-frequency group delay of model × DCM
  (the cancelled poles' delays cancel; what is left is the designed poles', the band limit's,
  and the model's uncancelled zeros and poles), taken as the phase slope over the compensated
  ±5 % band, where a pulse's content lies (analysis.dcm.passband_delay_samples; exactly at DC
  a slow spare pole-zero pair would move it by tens of samples while changing nothing a shock
  pulse contains): what `hopkinson compensate` removes.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from functools import lru_cache
from typing import Any

import numpy as np
from scipy import signal

from hopkinson.analysis.dcm import DCM, designed_zpk
from hopkinson.analysis.dcm_figures import compare_steps, compensated_fbsd_edges
from hopkinson.analysis.dcm_ratio import (
    FALLBACK_WIDENING,
    RatioChoice,
    ShotPulse,
    choose_ratio,
    compensated_delay_samples,
)
from hopkinson.analysis.errors import AnalysisError
from hopkinson.analysis.excitation import SUPPORT_SNR, amplitude_spectrum, pulse_width, pulse_window
from hopkinson.analysis.model import DiscreteModel, complex_pairs
from hopkinson.analysis.options import DCM_OPTIONS, DEFAULT_DCM_DAMPING, AnalysisOptions
from hopkinson.analysis.records import Record
from hopkinson.analysis.response import (
    fbsd_bounds,
    fbsd_edges,
    frequency_response,
    pole_analysis,
)

# The automatic design keeps the DCM's white-noise RMS gain at the analysis rate below
# DEFAULT_DCM_NOISE_GAIN_LIMIT (analysis.options, with the other defaults and the options'
# rules): a compensated record at most 4× (12 dB) as noisy as the raw one.
BAND_LIMIT_ORDER = 4


def _edge_fraction(order: int) -> float:
    """|H| of an order-n Butterworth is 0.95 at this fraction of its cut-off ((1/0.95² − 1)^(1/2n))."""
    return (1 / 0.95**2 - 1) ** (1 / (2 * order))


# The widest ±5 % band the band limit allows, as a fraction of its cut-off.
_BAND_LIMIT_FBSD5 = _edge_fraction(BAND_LIMIT_ORDER)
# The band limit's taps: about this many × (sample rate / its ±5 % edge), odd; its magnitude is
# then within 2e-3 of the Butterworth's up to twice its cut-off (measured at 10-60 kHz edges, 1 MS/s).
BAND_LIMIT_TAPS_PER_RATE = 4.0
# At least this many (a cut-off near Nyquist: 15 taps left it 3 % off the Butterworth), at most
# this many (an edge below 1/250 of the sample rate: 2.3 kHz at 1 MS/s passes 94 % at the edge,
# not 95 %; the compensated band reported is the DCM's own response's, so it stays true).
MIN_BAND_LIMIT_TAPS = 31
MAX_BAND_LIMIT_TAPS = 1001
NEAR_NYQUIST = 0.8  # a mode above this fraction of Nyquist is not resolved by the record
# A pole with a model zero within this fraction of its distance to the unit circle forms a
# pair that changes the model's gain by at most ~10 %: the fit's spare pole-zero pair.
DOUBLET = 0.1


@dataclass(frozen=True)
class ShotSupport:
    """What a shot tells the DCM design: its model and what the data vouch for.

    modes: Identification.modes (kind, pole, natural_frequency_hz, supported, nyquist); None
    (a bare model file): every stable mode counts as supported, the other rules still apply.
    supported_band_hz: the band the excitation supports (None: not known).
    response_band_top_hz: where the response stops standing above its noise (None: not known).
    channel_delay_samples: the identified input delay (samples at the model's rate).
    pulse: the shot's reference pulse at the model's rate (None: not known), what the automatic
    ratio sizes the DCM to (analysis.dcm_ratio).
    """

    model: DiscreteModel
    modes: list[dict[str, Any]] | None = None
    supported_band_hz: tuple[float, float] | None = None
    response_band_top_hz: float | None = None
    channel_delay_samples: float = 0.0
    pulse: ShotPulse | None = None

    @classmethod
    def from_identification(cls, ident: Any, record: Record | None = None) -> ShotSupport:
        """From an analysis.identify.Identification (and the record at the model's rate, for
        the response's own signal-to-noise band and the pulse)."""
        top = None
        rms = ident.noise.response_rms
        if record is not None and rms:
            top = response_band_top_hz(record, ident.model, float(rms))
        pulse = None if record is None else pulse_of(record)
        band = getattr(ident, "supported_band_hz", None)
        return cls(
            model=ident.model,
            modes=[dict(m) for m in ident.modes],
            supported_band_hz=tuple(band) if band else None,
            response_band_top_hz=top,
            channel_delay_samples=float(ident.delay_samples),
            pulse=pulse,
        )

    @classmethod
    def from_dict(cls, data: dict[str, Any], model: DiscreteModel) -> ShotSupport:
        """From a model JSON (`hopkinson identify -o`) or a results dict's identification."""
        modes = data.get("modes")
        valid = isinstance(modes, list) and all(isinstance(m, dict) and _is_pair(m.get("pole")) for m in modes)
        if modes is not None and not valid:
            raise AnalysisError("'modes' must be a list of objects with a 'pole': [re, im] of numbers")
        band = data.get("supported_band_hz")
        pair = (float(band[0]), float(band[1])) if isinstance(band, (list, tuple)) and len(band) == 2 else None
        return cls(
            model=model,
            modes=[dict(m) for m in modes] if valid else None,
            supported_band_hz=pair,
            response_band_top_hz=_number(data.get("response_band_top_hz")),
            channel_delay_samples=float(model.delay_samples),
        )


def pulse_of(record: Record) -> ShotPulse | None:
    """The record's reference pulse (at the model's rate), None when it has none to size to."""
    try:
        return ShotPulse.of(record)
    except AnalysisError:
        return None


@dataclass(frozen=True)
class PoleChoice:
    """The poles the DCM cancels, and every other pole with the reason it is left alone."""

    cancelled: np.ndarray
    skipped: list[dict[str, Any]]

    def to_dict(self) -> dict[str, Any]:
        return {"cancelled_poles": complex_pairs(self.cancelled), "skipped_poles": [dict(s) for s in self.skipped]}


def choose_poles(support: ShotSupport) -> PoleChoice:
    """The poles a DCM may cancel for this shot (module docstring), each conjugate pair whole."""
    model = support.model
    poles = model.poles
    unstable = poles[np.abs(poles) >= 1.0]
    if unstable.size:
        p = unstable[0]
        raise AnalysisError(f"model pole {p.real:.6g}{p.imag:+.6g}j is on or outside the unit circle: the model is unstable")
    zeros = model.zeros
    nyquist_hz = 0.5 / model.sample_interval_s
    cancelled: list[complex] = []
    skipped: list[dict[str, Any]] = []
    for mode in support.modes if support.modes is not None else _modes(poles, model.sample_interval_s):
        p = complex(*mode["pole"])
        reason = _why_not_cancelled(p, mode, zeros, nyquist_hz)
        if reason is None:
            cancelled += [p, p.conjugate()] if p.imag > 0 else [p]
        else:
            f_n = mode.get("natural_frequency_hz")
            skipped.append({"pole": [p.real, p.imag], "kind": mode.get("kind"), "natural_frequency_hz": f_n,
                            "reason": reason})
    return PoleChoice(np.array(cancelled, dtype=complex), skipped)


def _modes(poles: np.ndarray, sample_interval_s: float) -> list[dict[str, Any]]:
    """Modes of a bare model (no identification): each pole pair / real pole, judged supported."""
    out = []
    for p in poles:
        if p.imag < 0:
            continue
        f_n = float(abs(np.log(complex(p))) / (2 * np.pi * sample_interval_s)) if p != 0 else None
        out.append({"kind": "complex" if p.imag > 0 else "real", "pole": [p.real, p.imag],
                    "natural_frequency_hz": f_n, "supported": True})
    return out


def _why_not_cancelled(p: complex, mode: dict[str, Any], zeros: np.ndarray, nyquist_hz: float) -> str | None:
    if p == 0:
        return "at the origin: a pure delay, no dynamics to compensate"
    if mode.get("nyquist") or (p.imag == 0 and p.real < 0):
        return "a negative real pole (at Nyquist): an artefact of the discretisation, not a mode of the sensor"
    f_n = _number(mode.get("natural_frequency_hz"))
    if not mode.get("supported", True) and not mode.get("shapes_band"):
        where = f" (f_n = {f_n / 1e3:.4g} kHz)" if f_n is not None else ""
        return f"outside the band the excitation supports{where}: the shot cannot vouch for it"
    if f_n is not None and f_n >= NEAR_NYQUIST * nyquist_hz:
        return (f"f_n = {f_n / 1e3:.4g} kHz lies within {100 * (1 - NEAR_NYQUIST):.0f} % of Nyquist: not resolved by "
                "the record")
    if zeros.size:
        near = zeros[int(np.argmin(np.abs(zeros - p)))]
        if abs(near - p) <= DOUBLET * (1 - abs(p)):
            return (f"nearly cancelled by the model zero {near.real:.6g}{near.imag:+.6g}j (a spare pole-zero pair "
                    "of the fit): cancelling the pole alone would leave the zero as a notch")
    return None


def band_limit_fir(cutoff_hz: float, sample_interval_s: float, order: int = BAND_LIMIT_ORDER) -> np.ndarray:
    """Taps of the band limit: a linear-phase FIR whose magnitude is an order-n Butterworth
    low-pass's at `cutoff_hz`, unit DC gain. scipy.signal.firls (least squares) fits the
    magnitude sampled on a grid dense where it turns (80 steps up to 4 × the cut-off, 32 beyond);
    the taps are ≈ BAND_LIMIT_TAPS_PER_RATE × (sample rate / ±5 % edge), odd (type I: a delay of
    half the length, exactly)."""
    return np.array(_band_limit_taps(float(cutoff_hz), float(sample_interval_s), int(order)))


@lru_cache(maxsize=64)
def _band_limit_taps(cutoff_hz: float, sample_interval_s: float, order: int) -> tuple[float, ...]:
    nyquist = 0.5 / sample_interval_s
    edge = cutoff_hz * _edge_fraction(order)
    half = math.ceil(0.5 * BAND_LIMIT_TAPS_PER_RATE / (edge * sample_interval_s))
    taps = min(max(2 * half + 1, MIN_BAND_LIMIT_TAPS), MAX_BAND_LIMIT_TAPS)
    turn = min(4.0 * cutoff_hz, nyquist)
    grid = np.unique(np.concatenate([np.linspace(0.0, turn, 81), np.linspace(turn, nyquist, 33)]))
    bands = np.repeat(grid, 2)[1:-1]
    desired = 1.0 / np.sqrt(1.0 + (bands / cutoff_hz) ** (2 * order))
    h = signal.firls(taps, bands, desired, fs=2.0 * nyquist)
    return tuple(float(x) for x in h / np.sum(h))


def response_band_top_hz(record: Record, model: DiscreteModel, noise_rms: float, snr: float = SUPPORT_SNR
                         ) -> float | None:
    """Top of the band where the response stands `snr` × above its own noise: the model's
    response to the reference pulse, |H(f)·F(f)| (F over the pulse window, the main pulse ± two
    widths, as analysis.excitation uses), against the amplitude spectrum σ·√L·T that white noise
    of standard deviation σ has over the same L samples. The model's response is used rather
    than the recorded one because the window cuts the sensor's ringing, whose leakage would
    pass for signal. None when there is no pulse or no noise estimate."""
    if not noise_rms > 0:
        return None
    dt = record.sample_interval_s
    try:
        pulse = pulse_width(record.reference, dt)
    except AnalysisError:
        return None
    window = pulse_window(pulse, record.n_samples, dt)
    segment = np.asarray(record.reference[window], dtype=float)
    freq, mag = amplitude_spectrum(segment - np.median(record.reference[: max(window.start, 1)]), dt)
    response = mag * np.abs(frequency_response(model, freq))
    ok = response >= snr * noise_rms * math.sqrt(segment.size) * dt
    i_max = int(np.argmax(response))
    below = np.flatnonzero(~ok[i_max:])
    return float(freq[i_max + below[0] - 1]) if below.size else float(freq[-1])


@dataclass(frozen=True)
class BandLimit:
    """The band-limiting low-pass: cut-off (None: none) and why it sits there."""

    cutoff_hz: float | None
    reason: str

    def fir(self, sample_interval_s: float) -> np.ndarray | None:
        """Its taps (None: no band limit)."""
        return None if self.cutoff_hz is None else band_limit_fir(self.cutoff_hz, sample_interval_s)


def _cutoff_for_edge(edge_hz: float) -> float:
    """The cut-off of the band limit that passes `edge_hz` at exactly 95 % (the FIR realises the
    prototype's magnitude, band_limit_fir)."""
    return edge_hz / _BAND_LIMIT_FBSD5


def choose_band_limit(support: ShotSupport, asked_hz: float | None) -> BandLimit:
    """The band limit: a cut-off asked (> 0), none (0), or the cut-off whose ±5 % edge is the
    top of what the shot vouches for."""
    nyquist = 0.5 / support.model.sample_interval_s
    if asked_hz is not None:
        if asked_hz == 0:
            return BandLimit(None, "switched off (band_limit_hz = 0)")
        if asked_hz >= nyquist:
            raise AnalysisError(f"DCM: the band limit {asked_hz:g} Hz must lie below Nyquist ({nyquist:g} Hz)")
        return BandLimit(float(asked_hz), "as asked")
    tops = []
    if support.supported_band_hz is not None and support.supported_band_hz[1] > 0:
        tops.append((support.supported_band_hz[1], "the top of the band the excitation supports"))
    if support.response_band_top_hz is not None and support.response_band_top_hz > 0:
        tops.append((support.response_band_top_hz, "where the response stops standing 20 dB above its noise"))
    if not tops:
        return BandLimit(None, "none: the model does not say which band the shot supports")
    top, why = min(tops)
    cap = NEAR_NYQUIST * nyquist
    cutoff = _cutoff_for_edge(top)
    if cutoff > cap:
        return BandLimit(cap, f"{NEAR_NYQUIST:.0%} of Nyquist (the cut-off for ±5 % up to {why}, "
                              f"{top / 1e3:.4g} kHz, lies above it)")
    return BandLimit(float(cutoff), f"±5 % up to {top / 1e3:.4g} kHz, {why}")


@dataclass(frozen=True)
class DcmDesign:
    """A DCM designed for a shot, with the figures the results report. `ratio_choice`: how
    the automatic ratio was chosen (None: r given, or nothing to cancel)."""

    dcm: DCM
    model: DiscreteModel
    poles: PoleChoice
    band_limit: BandLimit
    options: AnalysisOptions
    fbsd_hz: dict[str, float]
    compensated_fbsd_hz: dict[str, float]
    target_widening: float | None
    reached_widening: float | None
    widening_note: str | None
    noise_gain: float
    channel_delay_samples: float
    notes: list[str] = field(default_factory=list)
    ratio_choice: RatioChoice | None = None

    @property
    def noise_gain_exceeded(self) -> bool:
        return self.noise_gain > self.options.dcm_noise_gain_limit * (1 + 1e-9)

    @property
    def widening_short(self) -> bool:
        """The automatic ratio fell short of what it aimed for (the note says what stopped it)."""
        return self.ratio_choice is not None and self.ratio_choice.short

    @property
    def latency_s(self) -> float:
        return self.dcm.latency_s

    def to_dict(self) -> dict[str, Any]:
        """The design figures of the results' "dcm" object (docs/files-and-formats.md)."""
        choice = self.ratio_choice
        error = None if choice is None or choice.peak_error is None else 100.0 * choice.peak_error
        return {
            "target_widening": self.target_widening,
            "reached_widening": self.reached_widening,
            "widening_note": self.widening_note,
            "sized_to": None if choice is None else choice.sized_to.value,
            "predicted_peak_error_pct": error,
            "noise_gain": self.noise_gain,
            "noise_gain_limit": self.options.dcm_noise_gain_limit,
            "band_limit_hz": self.band_limit.cutoff_hz,
            "band_limit_reason": self.band_limit.reason,
            "latency_s": self.latency_s,
            "compensated_fbsd_hz": dict(self.compensated_fbsd_hz),
        }


def design_compensation(support: ShotSupport, options: AnalysisOptions | None = None) -> DcmDesign:
    """Design the DCM this shot supports (module docstring)."""
    options = AnalysisOptions() if options is None else options
    options.check(DCM_OPTIONS)
    model = support.model
    choice = choose_poles(support)
    limit = choose_band_limit(support, options.dcm_band_limit_hz)
    before = {k: e.frequency_hz for k, e in fbsd_edges(model).items()}
    if choice.cancelled.size == 0:
        dcm = _assemble(model, choice, limit, None, options)
        note = "nothing to compensate: no pole of the model is one the shot supports"
        return _finish(dcm, model, choice, limit, options, before, support, note, [note])
    if options.dcm_ratio is not None:
        dcm = _assemble(model, choice, limit, options.dcm_ratio, options)
        note = f"ratio r = {options.dcm_ratio:g} given: no widening was aimed for"
        design = _finish(dcm, model, choice, limit, options, before, support, note, [])
        if design.noise_gain_exceeded:
            design.notes.append(
                f"the noise gain {design.noise_gain:.3g} exceeds the limit {options.dcm_noise_gain_limit:g} at the given r"
            )
        return design
    cap_edge = None if limit.cutoff_hz is None else _BAND_LIMIT_FBSD5 * limit.cutoff_hz
    cap = "none" if limit.cutoff_hz is None else f"at {limit.cutoff_hz / 1e3:.4g} kHz, {limit.reason}"
    nonminimum = complex_pairs(model.nonminimum_phase_zeros)
    ratio = choose_ratio(model, choice.cancelled, lambda r: _assemble(model, choice, limit, r, options, nonminimum),
                         damping=options.dcm_damping, noise_gain_limit=options.dcm_noise_gain_limit,
                         model_fbsd5_hz=before["5"], widening=options.dcm_widening, pulse=support.pulse,
                         band_known=limit.cutoff_hz is not None, cap=cap, cap_edge_hz=cap_edge)
    dcm = _assemble(model, choice, limit, ratio.ratio, options, nonminimum)
    return _finish(dcm, model, choice, limit, options, before, support, ratio.note, [], ratio)


def _assemble(model: DiscreteModel, choice: PoleChoice, limit: BandLimit, ratio: float | None,
              options: AnalysisOptions, nonminimum_phase_zeros: list[list[float]] | None = None) -> DCM:
    """Paper DCM for the cancelled poles at ratio r (None: nothing cancelled), cascaded with the
    band limit, unit DC gain (its latency is set by _finish). `nonminimum_phase_zeros`: the
    model's, as complex_pairs (None: found here; the ratio search passes them once)."""
    dt = model.sample_interval_s
    fir = limit.fir(dt)
    if ratio is None:
        zeros = poles = np.zeros(0, complex)
        gain, design = 1.0, {"method": "no compensation: nothing to cancel"}
    else:
        zeros, poles, gain, design = designed_zpk(choice.cancelled, dt, ratio, options.dcm_damping, options.extra_poles)
    design.update(choice.to_dict())
    design["band_limit"] = {"cutoff_hz": limit.cutoff_hz, "order": BAND_LIMIT_ORDER if fir is not None else 0,
                            "kind": "linear-phase FIR, Butterworth magnitude (least squares)",
                            "taps": 0 if fir is None else int(fir.size), "reason": limit.reason}
    if nonminimum_phase_zeros is None:
        nonminimum_phase_zeros = complex_pairs(model.nonminimum_phase_zeros)
    design["nonminimum_phase_zeros"] = [list(z) for z in nonminimum_phase_zeros]
    design["zeros_inverted"] = False
    return DCM(dt, zeros, poles, gain, design, fir=fir)


def _finish(dcm: DCM, model: DiscreteModel, choice: PoleChoice, limit: BandLimit, options: AnalysisOptions,
            before: dict[str, float], support: ShotSupport, note: str | None, notes: list[str],
            ratio: RatioChoice | None = None) -> DcmDesign:
    after = {k: e.frequency_hz for k, e in compensated_fbsd_edges(model, dcm).items()}
    reached = after["5"] / before["5"] if before["5"] > 0 else None
    notes = notes + [f"the compensated ±{key} % edge is {bound['reason']}: there the compensated response is the "
                     "model's extrapolation, not measured"
                     for key, bound in fbsd_bounds(after, support.supported_band_hz).items()]
    noise = dcm.noise_gain()
    dt = model.sample_interval_s
    fit_band = min(max(after["5"], before["5"]), 0.4 / dt)  # the band it passes flat
    in_band = compensated_delay_samples(model, dcm, before["5"], after["5"])
    latency = support.channel_delay_samples + in_band
    target = None if ratio is None else ratio.target_widening
    figures = {
        "target_widening": target, "reached_widening": reached, "widening_note": note,
        "sized_to": None if ratio is None else ratio.sized_to.value,
        "noise_gain": noise, "noise_gain_limit": options.dcm_noise_gain_limit,
        "latency": {
            "total_s": latency * dt,
            "channel_delay_s": support.channel_delay_samples * dt,
            "compensated_delay_s": in_band * dt,
            "fitted_up_to_hz": fit_band,
            "dcm_dc_group_delay_s": dcm.group_delay_samples * dt,
            "how": "channel delay + the delay of model × DCM over its ±5 % band (phase slope, least squares)",
        },
    }
    dcm = replace(dcm, design={**dcm.design, **figures}, latency_samples=latency)
    return DcmDesign(dcm, model, choice, limit, options, before, after, target, reached, note, noise,
                     support.channel_delay_samples, list(notes), ratio)


def design_report(poles: np.ndarray, dcm: DCM, model: DiscreteModel | None, source: str,
                  design: DcmDesign | None = None) -> dict[str, Any]:
    """The JSON result of `hopkinson dcm` (also what -o writes and the panel shows)."""
    result: dict[str, Any] = {
        "source": source,
        "sample_interval_s": dcm.sample_interval_s,
        "pole_analysis": pole_analysis(poles),
        "dcm": dcm.to_dict(),
    }
    if design is not None:
        result["dcm"].update(design.to_dict())
        result["dcm"]["notes"] = list(design.notes)
    if model is not None:
        before = fbsd_edges(model)
        after = compensated_fbsd_edges(model, dcm)
        steps = compare_steps(model, dcm)  # one step-response simulation for both times
        rt_before, rt_after = steps.rise_times_samples()
        result["fbsd_hz"] = {k: e.frequency_hz for k, e in before.items()}
        result["compensated_fbsd_hz"] = {k: e.frequency_hz for k, e in after.items()}
        result["fbsd_detail"] = {k: e.to_dict() for k, e in before.items()}
        result["compensated_fbsd_detail"] = {k: e.to_dict() for k, e in after.items()}
        result["fbsd_widening"] = {k: after[k].frequency_hz / before[k].frequency_hz for k in before}
        result["rise_time_samples"] = {"uncompensated": rt_before, "compensated": rt_after}
        result["rise_time_ratio"] = rt_before / rt_after if rt_after > 0 else None
        st_before, st_after = steps.settling_times_samples()
        result["settling_time_samples"] = {"uncompensated": st_before, "compensated": st_after}
        result["settling_time_ratio"] = steps.settling_time_ratio()
    return result


def _is_pair(value: Any) -> bool:
    return isinstance(value, (list, tuple)) and len(value) == 2 and all(_number(v) is not None for v in value)


def _number(value: Any) -> float | None:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        return None
    return float(value) if math.isfinite(value) else None


def poles_only_model(poles: Sequence[complex] | np.ndarray, sample_interval_s: float) -> DiscreteModel:
    """The unit-DC-gain all-pole model these poles describe (for a design from poles alone)."""
    p = np.atleast_1d(np.asarray(poles, dtype=complex))
    a = np.real(np.poly(p))
    return DiscreteModel(sample_interval_s, a, [float(np.sum(a))])


def ratio_for_widening(
    model: DiscreteModel,
    damping: float = DEFAULT_DCM_DAMPING,
    widening: float = FALLBACK_WIDENING,
    extra_poles: Sequence[complex] | np.ndarray = (),
) -> float:
    """The automatic r for a bare model: every stable pole cancelled, no band limit, no noise
    bound (the paper's design alone); `design_compensation` is the shot's full design."""
    options = AnalysisOptions(sample_rate_hz=None, dcm_damping=damping, dcm_widening=widening,
                              dcm_noise_gain_limit=math.inf, dcm_band_limit_hz=0.0,
                              extra_poles=tuple(complex(p) for p in np.atleast_1d(extra_poles)))
    design = design_compensation(ShotSupport(model), options)
    return float(design.dcm.design["ratio"])
