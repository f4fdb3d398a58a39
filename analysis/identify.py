"""Identify the accelerometer's discrete model A(d⁻¹)·y(k) = B(d⁻¹)·u(k − τ) from a shock record.

Steps (paper §2.1, made well-posed for real records; README "The method"):

1. Rate: a record sampled faster than the analysis rate is low-pass filtered and resampled
   (analysis.resample; default 1 MS/s).
2. Scale: each channel is divided by its largest excursion, so nothing below depends on units
   or gains: rescaling a channel by any factor leaves order, poles, zeros, delay and FBSD as
   they are and scales the DC gain exactly (the factor is put back into B at the end).
3. Baselines and noise: each channel's pre-pulse mean is removed; a linear drift is removed
   when quiet stretches before and after the pulse pin it. The noise spectrum of each channel
   is measured where it is quiet (analysis.noise): the reference before the pulse and in
   flight after it, the response before the pulse and after its ringing has died away. A
   stretch after the pulse where both channels move together (the bar's motion: coherent,
   analysis.noise.is_motion) is not noise and is left out (issue 17).
4. Window and band: the fit uses the record from just before the pulse to where the response
   has died into its noise (a record cut short keeps a transient term, see
   analysis.frequency_fit), and only the frequencies the excitation supports: where the
   reference's spectrum stands 20 dB above its noise and within 40 dB of its maximum
   (analysis.excitation.supported_band_hz).
5. Fit of every order n = 1, 2, … in turn (analysis.frequency_fit): the errors-in-variables
   output-error cost V_n (each bin's error over its noise, reference noise included), with a
   causal fractional delay τ ≥ 0 fitted with the model. Each order starts from the order
   below (embedded with a cancelling pole and zero, so V never rises with the order) and from
   a Sanathanan–Koerner linear start, and keeps the better optimum. The chosen order's delay
   is then searched again on a grid (frequency_fit.delay_branches): the delay and B's zeros
   share a flat valley of the cost that can hold separate optima a few samples apart; the
   lowest is the estimate, the others within chance are kept for the Monte Carlo
   (analysis.uncertainty), whose draws re-run that choice. `delay_samples` is therefore the
   delay of the best branch, not a measured channel skew: what the record determines is the
   model's whole phase (delay and zeros together), which analysis.sine_comparison compares.
5b. Model error (ModelError, issue 17): the chosen order's residual beyond what the noise
   explains, per frequency, is measured; when it is significant every order is fitted again
   with it weighed as an output error of its own, and the Monte Carlo draws it. Where the
   refitted choice then holds a pole–zero doublet (a zero following a ripple), or no order with
   free zeros is stable, the orders are fitted once more in the all-pole structure (B =
   g·(1 + z⁻¹)ⁿ/2ⁿ, a pole pair at least, a delay of either sign: the reference chain's own
   delay), whose damping beyond the band is floored (frequency_fit.damping_floored); its
   resonance beyond the band is marked `shapes_band` (a DCM may cancel it for the rise it gives
   inside the band) and never reported as a measured mode.
6. Order: the smallest n that no higher order beats both beyond chance (an F test on V,
   Bonferroni-corrected over the fitted bins: an extra pole pair can sit on the largest chance
   peak of the noise anywhere in the band) and in the frequency response where the pulse has
   energy (by more than 0.1 % RMS: at high SNR a rational discrete model shows its own small
   mismatch with a continuous sensor, and a parasitic pole pair that mends it is no mode).
   The evidence (V, the F statistics, the response changes) is reported; the stability of the
   choice across resampled noise is measured by analysis.uncertainty, which also draws the
   order.
7. Claims stay inside the band: modes outside it are flagged `supported: False` (a DCM may
   only cancel supported poles; the main mode is the lowest supported complex pair; a pair
   nearly cancelled by a zero is a doublet, never a mode; an order with a real pole far below
   the lowest fitted bin, which the data cannot place, is no candidate); the
   response leading the reference, zeros outside the unit circle, a model that leaves far
   more residual than the noise explains, and a poor fit are reported.

The plain least-squares loss ||g2||² of every order (one factorisation of the augmented
information matrix of Eq. 3, analysis.loss) is reported beside V: it keeps falling with the
order and cannot choose it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING, Any

import numpy as np
from hopkinson.analysis.errors import AnalysisError
from hopkinson.analysis.excitation import pulse_width, supported_band_hz
from hopkinson.analysis.frequency_fit import (
    ZETA_FLOOR,
    OrderFit,
    OrderProblem,
    SineTerms,
    SpectralData,
    all_pole_numerator,
    delay_branches,
    predicted_bins,
    response,
)
from hopkinson.analysis.loss import arx_loss_by_order, long_dot
from hopkinson.analysis.model import DiscreteModel, complex_pairs
from hopkinson.analysis.noise import WELCH_SEGMENT, NoiseSpectrum, is_motion
from hopkinson.analysis.numerics import f_quantile, next_fast_len
from hopkinson.analysis.order_choice import (
    FRF_TOLERANCE,
    SIGNIFICANCE,
    NoiseDraws,
    Refitter,
    candidates_around,
    choose_order,
    choose_stable_order,
    fractions_text,
    order_stability,
    response_change,
)
from hopkinson.analysis.params import DEFAULT_ANALYSIS_RATE_HZ
from hopkinson.analysis.records import Record
from hopkinson.analysis.resample import estimate_delay_samples, resample_to_rate
from hopkinson.analysis.response import simulate_from_rest
from numpy import fft

if TYPE_CHECKING:
    from hopkinson.analysis.sine_comparison import SineCalibration

# Samples per model parameter below which a record is too short for an order.
MIN_SAMPLES_PER_PARAMETER = 10
# A final model with a pole this close to the unit circle sits on the stability boundary.
MARGINAL_POLE = 1e-6
# Below this fit percentage the model is reported as explaining little of the response.
POOR_FIT_PERCENT = 50.0
# (kept for the API: the relative tolerance of the old knee rule, reported)
KNEE_TOLERANCE = 0.01
# identify(stability_draws=…): noise draws that re-run the order choice to measure its
# stability, from a fixed seed (the same record always gives the same evidence); the
# uncertainty's Monte Carlo measures it anyway, so identify alone does not by default. Below
# this share of draws choosing it, the choice is reported as unstable.
STABILITY_SEED = 16_063
ORDER_STABILITY_WARNING = 0.5
# More bins than this are summed in groups of adjacent bins (same cost while G is flat there).
MAX_BINS = 512
# A response leading the reference by more than this (samples, significant) is reported.
LEAD_WARNING_SAMPLES = 0.2
# V per degree of freedom above this: the model, not the noise, dominates the residual.
MODEL_ERROR_RATIO = 2.0
# A fit whose linear start was unstable and that leaves this many times the residual the noise
# explains is taken as the data calling for an unstable model.
UNSTABLE_MODEL_ERROR = 100.0
# Model error is taken as detected when the residual exceeds this many times what the noise
# explains: the noise level itself is estimated from a short lead-in, and a simulated sensor
# with exactly known dynamics read up to ~2× (benchmarks/bench_uncertainty.py's shot: 2.1);
# PTB's record reads 8 300×, its hybrids 5–120×.
MODEL_ERROR_DETECTED = 4.0
# Model error: how its spectrum is smoothed (over ±1/6 octave about each bin, at least 5 bins).
MODEL_ERROR_OCTAVES = 1.0 / 6.0
MODEL_ERROR_MIN_BINS = 5
# A zero closer to a pole than this fraction of the pole's distance to the unit circle cancels it
# (a pole–zero doublet changes the response by at most about that fraction near the pole).
DOUBLET_DISTANCE = 0.5
FREE, ALL_POLE = "free", "all_pole"  # the model structures: B free, or B = g·(1 + z⁻¹)ⁿ/2ⁿ (no finite zeros)
# Quiet stretches shorter than this are not used for a noise spectrum.
MIN_QUIET = 32


@dataclass
class FitContext:
    """What the fit worked on (normalised units), kept for analysis.uncertainty; not serialised."""

    sample_interval_s: float
    scale_u: float  # the record's reference = scale_u × u
    scale_y: float
    u: np.ndarray  # window, normalised, baseline and drift removed
    y: np.ndarray
    window_start: int  # index of the window's first sample in the analysis-rate record
    bin_frequency_hz: np.ndarray  # frequencies of the fitted DFT bins
    u_bins: np.ndarray  # DFT of u at those bins
    y_bins: np.ndarray
    var_u: np.ndarray  # noise variance per bin, unbiased (what the Monte Carlo draws; `spectral`
    var_y: np.ndarray  # weighs by the conservative look); the response's with the model's response taken out
    group: int  # bins per group in `spectral` (1: per bin)
    spectral: SpectralData
    noise_u: NoiseSpectrum  # normalised units
    noise_y: NoiseSpectrum
    fits: dict[int, OrderFit]  # every order evaluated
    delay_mode: str | float
    significance: float
    knee_tolerance: float
    max_delay: int
    asked_order: int | None
    record: Record  # the record at the analysis rate
    model_error_ratio: float  # V / degrees of freedom of the chosen order (≈ 1: noise explains it)
    # Other near-equal optima of the chosen order's delay–zeros valley (frequency_fit.delay_branches):
    # the Monte Carlo refits each draw from every branch and keeps the lowest cost.
    branches: dict[int, list[OrderFit]] = field(default_factory=dict)
    # The model error's variance per fitted bin, included in var_y (identify.ModelError; zeros: none)
    var_model_error: np.ndarray | None = None


@dataclass
class Identification:
    """The identified model and everything that went into choosing it.

    Losses are the errors-in-variables output-error cost V (dimensionless: each fitted DFT bin
    adds its error over its noise; ≈ the number of bins for the right model); index 0 of every
    *_by_order list is order 1; NaN where an order was not evaluated.
    """

    model: DiscreteModel
    order: int
    loss_by_order: list[float]  # V_n (the order choice uses it)
    arx_loss_by_order: list[float]  # plain least-squares ||g2||², one factorisation (normalised units)
    aic_by_order: list[float]  # on V
    bic_by_order: list[float]
    fit_percent: float  # 100·(1 − ||y − ŷ|| / ||y − ȳ||) of the final model over the fitted window
    delay_samples: float  # causal fractional input delay τ ≥ 0 (samples at the analysis rate)
    modes: list[dict[str, Any]]  # per pole pair / real pole: natural_frequency_hz, damping_ratio, kind, supported
    warnings: list[str]
    converged: bool
    iterations: int
    order_selection: str  # "order_test" (chosen by the order test) or "asked" (files before: "knee")
    knee_tolerance: float  # relative gain in V a higher order must also bring
    preprocessing: dict[str, Any] = field(default_factory=dict)
    supported_band_hz: tuple[float, float] | None = None  # band the excitation supports
    noise: dict[str, Any] = field(default_factory=dict)  # reference_rms, response_rms (channel units)
    order_evidence: dict[str, Any] = field(default_factory=dict)  # why this order
    context: FitContext | None = field(default=None, repr=False, compare=False)
    sine_joint: Any = None  # analysis.sine_joint.SineJoint when fitted with a sine calibration

    @property
    def sample_interval_s(self) -> float:
        return self.model.sample_interval_s

    @property
    def poles(self) -> np.ndarray:
        return self.model.poles

    @property
    def zeros(self) -> np.ndarray:
        return self.model.zeros

    @property
    def main_mode(self) -> dict[str, Any] | None:
        """The lowest supported complex pole pair (the sensor's main resonance), or None."""
        return main_mode(self.modes)

    @property
    def resonance_above_hz(self) -> float | None:
        """With no mode inside the supported band but one beyond it: the band's top, a lower bound
        of the resonance (it lies in a null of the excitation); else None."""
        if self.main_mode is not None or self.supported_band_hz is None:
            return None
        top = self.supported_band_hz[1]
        beyond = any(m["kind"] == "complex" and not m.get("cancelled") and (m["natural_frequency_hz"] or 0.0) > top
                     for m in self.modes)
        return float(top) if beyond else None

    @property
    def nonminimum_phase_zeros(self) -> np.ndarray:
        """Zeros on or outside the unit circle (a DCM must never invert them)."""
        z = self.model.zeros
        return z[np.abs(z) >= 1.0]

    def supported_poles(self) -> np.ndarray:
        """The poles of the supported modes (both poles of a pair): what a DCM may cancel."""
        keep = [complex(*m["pole"]) for m in self.modes if m["supported"]]
        poles = [p for q in keep for p in ((q, q.conjugate()) if q.imag > 0 else (q,))]
        return np.array(poles, dtype=complex)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready fields: the model JSON (DESIGN.md) plus the fit details; inf/NaN → None."""
        out = self.model.to_dict()
        out.update(
            {
                "loss_by_order": _finite_or_none(self.loss_by_order),
                "arx_loss_by_order": _finite_or_none(self.arx_loss_by_order),
                "aic_by_order": _finite_or_none(self.aic_by_order),
                "bic_by_order": _finite_or_none(self.bic_by_order),
                "order_selection": self.order_selection,
                "knee_tolerance": self.knee_tolerance,
                "fit_percent": _finite_or_none([self.fit_percent])[0],
                "modes": [dict(m) for m in self.modes],
                "converged": self.converged,
                "iterations": self.iterations,
                "warnings": list(self.warnings),
                "preprocessing": dict(self.preprocessing),
                "main_mode": dict(self.main_mode) if self.main_mode is not None else None,
                "supported_band_hz": list(self.supported_band_hz) if self.supported_band_hz else None,
                "nonminimum_phase_zeros": complex_pairs(self.nonminimum_phase_zeros),
                "resonance_above_hz": self.resonance_above_hz,
                "noise": dict(self.noise),
                "order_evidence": _jsonable(self.order_evidence),
            }
        )
        if self.sine_joint is not None:
            out["sine_joint"] = _jsonable(self.sine_joint.to_dict())
        return out


def _finite_or_none(values: list[float]) -> list[float | None]:
    return [float(v) if v is not None and math.isfinite(v) else None for v in values]


def _jsonable(value: Any) -> Any:
    if isinstance(value, dict):
        return {str(k): _jsonable(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_jsonable(v) for v in value]
    if isinstance(value, (float, np.floating)):
        return float(value) if math.isfinite(value) else None
    if isinstance(value, np.integer):
        return int(value)
    return value


def modes_of(
    poles: np.ndarray, sample_interval_s: float, supported_band_hz: tuple[float, float] | None = None
) -> list[dict[str, Any]]:
    """Natural frequency (Hz) and damping ratio per complex pole pair or real pole (s = ln(z)/T).

    Sorted by natural frequency. `kind` is "complex" (a pair, listed once with its positive
    imaginary part) or "real". A real pole gives a damping ratio of 1 (over-damped section with
    time constant 1/(2π·f_n)); a negative real pole sits at Nyquist (an artefact of the
    discretisation: `nyquist` True, never supported); a pole at the origin has no frequency.
    `supported`: the natural frequency lies inside `supported_band_hz` (the band the excitation
    supports; None: not judged, True).
    """
    modes = []
    for p in np.asarray(poles, dtype=complex):
        if p.imag < 0:
            continue
        if p == 0:
            modes.append({"kind": "real", "pole": [0.0, 0.0], "natural_frequency_hz": None, "damping_ratio": None,
                          "nyquist": False, "supported": False})
            continue
        s = np.log(p) / sample_interval_s
        wn = float(abs(s))
        f_n = wn / (2 * np.pi)
        nyquist = bool(p.imag == 0 and p.real < 0)
        supported = not nyquist and (
            supported_band_hz is None or supported_band_hz[0] <= f_n <= supported_band_hz[1]
        )
        modes.append(
            {
                "kind": "complex" if p.imag > 0 else "real",
                "pole": [float(p.real), float(p.imag)],
                "natural_frequency_hz": f_n,
                "damping_ratio": float(-s.real / wn) if wn > 0 else None,
                "nyquist": nyquist,
                "supported": bool(supported),
            }
        )
    return sorted(modes, key=lambda m: m["natural_frequency_hz"] or 0.0)


def mark_doublets(modes: list[dict[str, Any]], zeros: np.ndarray) -> list[dict[str, Any]]:
    """Each complex mode with `cancelled` (a zero within DOUBLET_DISTANCE of the pole's distance
    to the unit circle: a pole–zero doublet, whose effect on the response is at most that
    fraction — the fit following a ripple of the data, not a resonance; issue 17's 17 kHz "main
    mode" on PTB's record was one). A cancelled mode is not supported: it is no main mode and
    no pole a DCM may cancel."""
    z = np.asarray(zeros, dtype=complex)
    out = []
    for m in modes:
        m = dict(m)
        m["cancelled"] = False
        if m["kind"] == "complex" and z.size:
            p = complex(*m["pole"])
            if float(np.min(np.abs(z - p))) < DOUBLET_DISTANCE * (1.0 - abs(p)):
                m["cancelled"], m["supported"] = True, False
        out.append(m)
    return out


def main_mode(modes: list[dict[str, Any]]) -> dict[str, Any] | None:
    """The sensor's main mode: the lowest supported complex pole pair (None if there is none)."""
    pairs = [m for m in modes if m["kind"] == "complex" and m["supported"]]
    return min(pairs, key=lambda m: m["natural_frequency_hz"]) if pairs else None


# ------------------------------------------------------------------------------ identify
def identify(
    record: Record,
    max_order: int = 12,
    order: int | None = None,
    sample_rate_hz: float | None = DEFAULT_ANALYSIS_RATE_HZ,
    *,
    knee_tolerance: float = KNEE_TOLERANCE,
    significance: float = SIGNIFICANCE,
    max_delay_samples: int = 32,
    remove_delay: bool = True,
    patience: int | None = 3,
    max_evaluations: int = 60,
    stability_draws: int = 0,
    sine: SineCalibration | None = None,
    sine_terms: SineTerms | None = None,
) -> Identification:
    """Identify a discrete model of the accelerometer from a two-channel record.

    max_order: the largest order tried. order: fit exactly this order (an error if its fit is
        unstable; a warning if the data support only a lower one); None: chosen by the order
        test (module docstring, step 6).
    sample_rate_hz: analysis rate; a faster record is resampled to it. None: the record's.
    knee_tolerance / significance: the order test's practical and statistical thresholds.
    max_delay_samples: largest input delay searched (samples at the analysis rate).
    remove_delay: False fixes the delay at 0.
    patience: stop trying higher orders once this many past the current choice gave no gain
        (their losses are NaN: not evaluated); None tries every order up to max_order.
    stability_draws: re-run the order choice on this many noise draws and report how often
        each order wins (analysis.uncertainty does so in any case).
    sine: a sinusoidal calibration of the same sensor, fitted with the shock (analysis.sine_joint:
        one model to both, each weighed by its own uncertainty; their consistency in `sine_joint`).
    sine_terms: the sine points as analysis.sine_joint weighed them (its own passes; internal).
    """
    if sine is not None:
        from hopkinson.analysis.sine_joint import identify_joint

        return identify_joint(record, sine, max_order=max_order, order=order, sample_rate_hz=sample_rate_hz,
                              knee_tolerance=knee_tolerance, significance=significance,
                              max_delay_samples=max_delay_samples, remove_delay=remove_delay, patience=patience,
                              max_evaluations=max_evaluations, stability_draws=stability_draws)
    if max_order < 1:
        raise AnalysisError(f"max_order must be at least 1, got {max_order}")
    if order is not None and order < 1:
        raise AnalysisError(f"order must be at least 1, got {order}")
    n_max = max(max_order, order or 0)
    warnings: list[str] = []
    pre: dict[str, Any] = {"record_sample_rate_hz": record.sample_rate_hz}

    rec = record if sample_rate_hz is None else resample_to_rate(record, sample_rate_hz)
    if rec is not record:
        pre["resampled_to_hz"] = rec.sample_rate_hz
    ref, resp = _checked_channels(rec)
    dt = rec.sample_interval_s
    need = MIN_SAMPLES_PER_PARAMETER * (2 * n_max + 1)
    if ref.size < need:
        what = f"order {order}" if order is not None and order >= max_order else f"max order {n_max}"
        raise AnalysisError(
            f"record too short for {what}: {ref.size} samples at the analysis rate, need at least {need} "
            f"({MIN_SAMPLES_PER_PARAMETER} per parameter)"
        )
    scale_u = _scale(ref)
    scale_y = _scale(resp)
    u_all, y_all = (ref - np.median(ref)) / scale_u, (resp - np.median(resp)) / scale_y
    prep = _prepare(u_all, y_all, dt, max_delay_samples, warnings)
    pre.update(
        {
            "reference_baseline": float(np.median(ref) + prep.baseline_u * scale_u),
            "response_baseline": float(np.median(resp) + prep.baseline_y * scale_y),
            "baseline_removed": True,
            "drift_removed": prep.drift_removed,
            # What was taken off each channel, in its own units, at time t of the record:
            # <channel>_baseline + intercept + slope_per_s · (t − origin_s): the report redoes it.
            **{f"{name}_drift": {"intercept": line[1] * scale, "slope_per_s": line[0] * scale / dt,
                                 "origin_s": rec.start_time_s}
               for (name, line), scale in zip(prep.drift_lines.items(), (scale_u, scale_y), strict=True)},
            "window_start_s": rec.start_time_s + prep.start * dt,
            "window_samples": int(prep.u.size),
            "fitted_bins": prep.spectral.bins,
            "bin_group": prep.group,
            "transient_term": prep.spectral.transient,
            "scale_reference": scale_u,
            "scale_response": scale_y,
        }
    )
    data = prep.spectral if sine_terms is None else replace(prep.spectral, sine=sine_terms)

    # Delay start: the causal delay that best fits a second-order model (a coarse grid).
    # The free structure keeps its delay causal (its zeros can take up a lead: _lead_warning); the
    # all-pole structure has no zeros to do so, and the reference chain's own delay (an
    # interferometer's demodulation and low-pass, 0.2–0.9 µs; PTB's record leads by ~0.35 µs) would
    # bias its poles (on PTB's record 45 kHz against 50.5 kHz free): its delay takes either sign.
    delay_modes: dict[str, str | float] = {FREE: "causal" if remove_delay else 0.0,
                                           ALL_POLE: "free" if remove_delay else 0.0}
    delay_mode = delay_modes[FREE]
    max_delay_samples = max(1, int(max_delay_samples))
    tau0 = _initial_delay(data, prep, min(2, n_max), max_delay_samples) if remove_delay else 0.0
    # Each order needs more real residuals (two per bin) than parameters (2n + 2, and n more
    # with a transient term); a narrow band limits the orders that can be tried.
    per_order = 3 if data.transient else 2
    allowed = (2 * data.bins - 4) // per_order
    if allowed < 1 or (order is not None and order > allowed):
        raise AnalysisError(
            f"the supported band holds only {data.bins} frequency bins: too few for "
            f"{'order ' + str(order) if order is not None else 'any model'} (a longer record or a shorter pulse)"
        )
    if n_max > allowed:
        warnings.append(f"orders above {allowed} were not tried: the supported band holds only {data.bins} "
                        "frequency bins")
        n_max = allowed

    def fit_orders(data: SpectralData, structure: str) -> tuple[dict[int, OrderFit], dict[int, int], dict[int, float],
                                                                dict[tuple[int, int], float], int | None, Any]:
        """Every order n = 1 … n_max of `structure` fitted on `data` and the order test's choice
        (step 5–6)."""
        fits: dict[int, OrderFit] = {}
        parameters: dict[int, int] = {}
        costs: dict[int, float] = {}
        tau = tau0
        previous: OrderFit | None = None
        # the all-pole structure stands for a resonance beyond the band: a pole pair at least (its
        # order 1, a real pole, is a low-pass that cannot rise towards a resonance)
        for n in range(2 if structure == ALL_POLE else 1, n_max + 1):
            shape = all_pole_numerator(n) if structure == ALL_POLE else None
            problem = OrderProblem(data, n, delay_modes[structure], max_delay_samples, numerator=shape)
            starts = [problem.linear_start(tau)]
            if abs(tau - tau0) > 0.5:
                starts.append(problem.linear_start(tau0))
            if previous is not None:
                starts.append(previous.embedded())
            best = None
            for start in starts:
                fitted = replace(problem.solve(start, max_evaluations, 1e-6), start_unstable=starts[0].start_unstable)
                if best is None or fitted.cost < best.cost:
                    best = fitted
            assert best is not None
            fits[n], parameters[n] = best, problem.size
            # an unstable or marginal order is no candidate, nor one with a real pole far below the
            # lowest fitted bin (the data cannot place it; issue 17's lobe-gain hybrid used one
            # at ~2 Hz to bend the lowest bins, and its DC gain came out negative)
            candidate = _acceptable(best, data.bins) and not _pole_below_band(best, prep.bin_hz[0], dt)
            costs[n] = best.cost if candidate else math.inf
            previous, tau = best, best.delay
            if patience is not None:
                chosen_so_far, _ = choose_order(costs, parameters, data.bins, response_change(fits, data), significance)
                if chosen_so_far is not None and n >= max(chosen_so_far + patience, order or 0):
                    break
        changes = response_change(fits, data)
        chosen_auto, comparisons = choose_order(costs, parameters, data.bins, changes, significance)
        return fits, parameters, costs, changes, chosen_auto, comparisons

    def fit_structures(data: SpectralData) -> tuple[str, tuple[Any, ...]]:
        """The free structure's orders and choice; where its choice is unstable or holds a pole–zero
        doublet (the fit following a ripple of the data: its one dynamic feature in the band is a
        smooth rise, a resonance beyond it, as on PTB's record), the all-pole structure's, whose
        zeros cannot follow a ripple (`all_pole_numerator`)."""
        found = fit_orders(data, FREE)
        chosen_free = found[4]
        if order is None and (chosen_free is None or _has_doublet(found[0][chosen_free])):
            all_pole = fit_orders(data, ALL_POLE)
            if all_pole[4] is not None:
                return ALL_POLE, all_pole
        return FREE, found

    # Model error (issue 17): a residual the noise does not explain is measured per frequency on
    # the order test's choice (iterated to convergence: the search stops each order early) and
    # weighed as an output error of its own (ModelError); the orders are then fitted again and
    # the test re-run with those weights. Once: measured again on a lower order's residual, the
    # model error would take in what that order lacks (on PTB's record it then fell to order 1).
    structure, (fits, parameters, costs, changes, chosen_auto, comparisons) = FREE, fit_orders(data, FREE)
    model_error = ModelError.none(prep.bin_hz.size)
    if chosen_auto is not None:
        pick = order if order is not None and order in fits else chosen_auto
        settled = OrderProblem(data, pick, delay_mode, max_delay_samples,
                               numerator=fits[pick].numerator).solve(fits[pick], 200, 1e-9)
        model_error = measure_model_error(prep, data, settled, parameters[pick], dt)
        if model_error.significant:
            data = with_output_variance(prep, prep.var_y + model_error.var_bins)
            if sine_terms is not None:  # the joint fit keeps its sine points (analysis.sine_joint)
                data = replace(data, sine=sine_terms)
            structure, (fits, parameters, costs, changes, chosen_auto, comparisons) = fit_structures(data)
            delay_mode = delay_modes[structure]
    evidence: dict[str, Any] = {"comparisons": comparisons, "structure": structure}
    if chosen_auto is None:
        raise AnalysisError(f"no stable model of order 1 … {n_max} fits this record (every fit was unstable)")
    if order is None and stability_draws > 0:
        # Stability across resampled noise: the test re-run on the chosen model's response with
        # fresh noise of the record's own level (a parametric bootstrap; analysis.uncertainty
        # does the same for the order's PDF and reports it). Reported as evidence; below 50 %
        # a warning.
        omega_bins = 2.0 * np.pi * prep.bin_hz * dt
        noise_draws = NoiseDraws(data, prep.u_bins, prep.y_bins, prep.draw_var_u, prep.draw_var_y, omega_bins, prep.group,
                                 STABILITY_SEED,
                                 centre_y=predicted_bins(fits[chosen_auto], data, omega_bins, prep.u_bins))
        refitter = Refitter(data, fits, delay_mode, max_delay_samples)
        candidates = [m for m in candidates_around(chosen_auto, fits) if math.isfinite(costs[m])]
        fractions, _, _ = order_stability(noise_draws, refitter, candidates, stability_draws, significance)
        evidence["stability"] = {"draws": stability_draws, "fraction_by_order": {str(m): v for m, v in fractions.items()}}
        if fractions.get(chosen_auto, 0.0) < ORDER_STABILITY_WARNING:
            warnings.append(
                f"the order choice is not stable under the record's own noise: the test chose order {chosen_auto}, "
                f"fresh noise of the same level gives {fractions_text(fractions)}; the uncertainty includes the "
                "other orders"
            )
    polished_orders: set[int] = set()

    def polished(n: int) -> OrderFit:
        """The order-n fit iterated to tight convergence (the search gave each order a short budget
        and a loose tolerance): the optimum, whatever path led to it, so rescaled channels give
        the same model to ~1e-9. A delay pressed against zero converges slowly in its bounded
        parameter: there the fit with the delay held at zero is taken when it is as good."""
        if n not in polished_orders:
            shape = fits[n].numerator
            done = OrderProblem(data, n, delay_mode, max_delay_samples, numerator=shape).solve(fits[n], 200, 1e-11)
            if delay_mode == "causal" and done.delay < 1e-2 and not done.converged:
                at_zero = OrderProblem(data, n, 0.0, max_delay_samples, numerator=shape).solve(done, 200, 1e-11)
                if at_zero.cost <= done.cost * (1 + 1e-9):
                    done = at_zero
            fits[n] = replace(done, start_unstable=fits[n].start_unstable)
            polished_orders.add(n)
        return fits[n]

    if order is None:
        chosen, selection = chosen_auto, "order_test"
        if not _acceptable(polished(chosen), data.bins):
            fallback, dropped = choose_stable_order(
                costs, parameters, data.bins, changes, lambda n: _acceptable(polished(n), data.bins), significance)
            if fallback is None and structure == FREE:
                # No stable order with free zeros (on PTB's record with its sine: the sensor's mode
                # beyond the band pressed onto the unit circle): the all-pole structure, whose
                # damping beyond the band is floored (frequency_fit.damping_floored).
                found = fit_orders(data, ALL_POLE)
                if found[4] is not None:
                    marginal = _marginal_modes_text(polished(chosen), dt)
                    structure, (fits, parameters, costs, changes, chosen_auto, comparisons) = ALL_POLE, found
                    delay_mode = delay_modes[structure]
                    polished_orders.clear()
                    evidence.update({"comparisons": comparisons, "structure": structure})
                    warnings.append("no model with free zeros is stable" + marginal + "; the all-pole model (a "
                                    "resonance beyond the band, its damping not determined) is used")
                    chosen = chosen_auto
                    fallback, dropped = (chosen, []) if _acceptable(polished(chosen), data.bins) else (None, [])
            if fallback is None:
                raise AnalysisError("no order gives a stable model for this record (every fit settles with a pole on "
                                    "or outside the unit circle" + _marginal_modes_text(polished(chosen), dt) + ")")
            if dropped:
                unstable = ", ".join(str(n) for n in dropped)
                warnings.append(f"the fit of order {unstable} became unstable when iterated to convergence; order "
                                f"{fallback} (the order test's choice among the stable orders) is used")
                evidence["unstable_when_converged"] = dropped
            chosen = fallback
    else:
        chosen, selection = order, "asked"
        if not _acceptable(polished(order), data.bins):
            why = (f"the data support only order {chosen_auto}" if chosen_auto < order
                   else "is the response really the sensor's answer to this reference?")
            raise AnalysisError(
                f"the order-{order} fit is unstable: the estimate settles with a pole on or outside the unit "
                f"circle ({why})"
            )
        if chosen_auto < order:
            drop = (costs[chosen_auto] - costs[order]) / costs[chosen_auto] if costs[chosen_auto] > 0 else 0.0
            warnings.append(
                f"order {order} was asked but the data support only order {chosen_auto}: V falls by {drop:.2%} from "
                f"order {chosen_auto} to {order}, within chance or without changing the response where the pulse has "
                "energy; the extra poles are not determined by this record (a mode beyond the excitation's band?)"
            )
    final = fits[chosen]
    # The delay–zeros valley may hold other optima (frequency_fit.delay_branches): the estimate
    # is the lowest of them (the search started each order from one delay and can miss it);
    # the others are kept for the Monte Carlo, whose draws re-run this choice.
    others = delay_branches(data, final, max_delay_samples) if delay_mode == "causal" else []
    if others and others[0].cost < final.cost and _acceptable(others[0], data.bins):
        final, others = replace(others[0], start_unstable=final.start_unstable), sorted(
            [final, *others[1:]], key=lambda f: f.cost)
        fits[chosen] = final
    branches = {chosen: others} if others else {}
    if others:
        evidence["delay_branches"] = [{"delay_samples": f.delay, "cost": f.cost} for f in [final, *others]]
    if not final.converged:
        warnings.append(f"the order-{chosen} fit stopped before converging in {final.evaluations} evaluations "
                        "(its cost was the lowest reached)")

    # The model in the record's units: the scales go back into B.
    b = final.b * (scale_y / scale_u)
    model = DiscreteModel(dt, final.a, b, float(final.delay), info={"fit_method": "eiv-frequency-oe",
                                                                       "structure": structure})
    band = prep.band
    modes = mark_doublets(modes_of(model.poles, dt, band), model.zeros)
    if structure == ALL_POLE:
        # the all-pole model's resonance beyond the band is what shapes the response inside it (its
        # rise): that effect is measured though the pole's place and damping are not, so a DCM
        # may cancel it (analysis.dcm_design; its band limit keeps it from amplifying beyond)
        modes = [{**m, "shapes_band": True} if m["kind"] == "complex" and not m["supported"] else m for m in modes]
    noise_y, var_y = _response_noise_on_residual(prep, final, dt)
    y_hat = _simulate(prep.u, final)
    residual = prep.y - y_hat
    fit = fit_percent(prep.y, y_hat)
    pre["response_offset_fitted"] = float(np.mean(residual) * scale_y)
    dof = 2 * data.bins - parameters[chosen]
    ratio = 2.0 * final.cost / dof if dof > 0 else math.inf
    warnings += _claims_warnings(modes, band, model)
    if remove_delay and structure == ALL_POLE:
        if final.delay < -LEAD_WARNING_SAMPLES:
            warnings.append(f"the response leads the reference by {-final.delay:.2g} samples ({-final.delay * dt * 1e6:.3g} "
                            "µs), fitted as a negative delay: the reference chain's own delay (an interferometer's "
                            "demodulation and low-pass) or the channels' skew (digitizer deskew, cable lengths)")
    elif remove_delay:
        warnings += _lead_warning(data, final, dt, significance)
    if model_error.significant:
        lo_hz, hi_hz = model_error.range_hz
        warnings.append(
            f"model error: the residual is {model_error.ratio:.3g}× what the measured noise explains, "
            f"{100 * model_error.rms_of_peak:.2g} % of the response's peak (RMS), mostly at "
            f"{lo_hz / 1e3:.3g}–{hi_hz / 1e3:.3g} kHz; it is weighed in the fit and drawn in the uncertainty "
            "as its own source (budget row 'model error')"
        )
    if prep.motion:
        warnings.append("the channels keep moving together after the pulse (coherence "
                        f"{max(m['coherence'] for m in prep.motion):.2f}): that motion is not taken as noise; the "
                        "noise is measured on the lead-in at rest")
    if ratio > MODEL_ERROR_RATIO:
        warnings.append(
            f"the model leaves {ratio:.1f}× the residual the measured noise explains (V per degree of freedom): "
            "the residual is mostly model error (unmodelled dynamics of the sensor or the reference chain, or "
            "noise the quiet parts of the record did not show); the uncertainty is widened by √ of that factor"
        )
    if fit < POOR_FIT_PERCENT:
        warnings.append(
            f"the model explains only {fit:.1f} % of the response (fit = 100·(1 − ‖y − ŷ‖/‖y − ȳ‖)): "
            "check that the channels belong together and that the response is not mostly noise"
        )
    loss_list = [fits[n].cost if n in fits else math.nan for n in range(1, n_max + 1)]
    aic, bic = _information_criteria(loss_list, [parameters.get(n, 0) for n in range(1, n_max + 1)], data.bins)
    shift = int(math.floor(final.delay))
    arx_u, arx_y = remove_input_delay(u_all, y_all, shift)
    try:
        arx_losses = [float(v) for v in arx_loss_by_order(arx_u, arx_y, n_max)]
    except AnalysisError:
        arx_losses = [math.nan] * n_max
    model.info.update({"loss_by_order": loss_list, "fit_percent": fit, "converged": final.converged,
                       "warnings": warnings})
    noise = {
        "reference_rms": prep.draw_noise_u.rms * scale_u if prep.draw_noise_u.samples else None,
        "response_rms": noise_y.rms * scale_y if noise_y.samples else None,
        "reference_source": prep.draw_noise_u.source,
        "response_source": noise_y.source + (" less the model's response" if noise_y is not prep.draw_noise_y else ""),
        "residual_rms": float(np.std(residual) * scale_y),
        "v_per_degree_of_freedom": ratio,
        "model_error": model_error.to_dict(),
        "motion_after_pulse": [{"start_s": rec.start_time_s + m["start_sample"] * dt,
                                "stop_s": rec.start_time_s + m["stop_sample"] * dt, "coherence": m["coherence"]}
                               for m in prep.motion],
    }
    evidence.update({
        "criterion": "the smallest order no higher order beats, both beyond chance (F test on the "
                     f"errors-in-variables cost V at {significance:.0%}, Bonferroni-corrected over the fitted bins) "
                     f"and in the excitation-weighted frequency response (by more than {FRF_TOLERANCE:.1%} RMS)",
        "chosen": chosen_auto,
        "selection": selection,
        "bins": data.bins,
        "parameters_by_order": {str(n): parameters[n] for n in sorted(parameters)},
        "cost_by_order": {str(n): fits[n].cost for n in sorted(fits)},
        "response_change_to_next_order": {str(n): changes[(n, n + 1)] for n in sorted(fits) if (n, n + 1) in changes},
    })
    context = FitContext(
        sample_interval_s=dt, scale_u=scale_u, scale_y=scale_y, u=prep.u, y=prep.y, window_start=prep.start,
        bin_frequency_hz=prep.bin_hz, u_bins=prep.u_bins, y_bins=prep.y_bins, var_u=prep.draw_var_u,
        var_y=var_y + model_error.var_bins, group=prep.group, spectral=data, noise_u=prep.draw_noise_u, noise_y=noise_y,
        fits=fits, delay_mode=delay_mode, significance=significance, knee_tolerance=knee_tolerance,
        max_delay=max_delay_samples, asked_order=order, record=rec, model_error_ratio=ratio, branches=branches,
        var_model_error=model_error.var_bins,
    )
    return Identification(
        model=model, order=chosen, loss_by_order=loss_list, arx_loss_by_order=arx_losses, aic_by_order=aic,
        bic_by_order=bic, fit_percent=fit, delay_samples=float(final.delay), modes=modes, warnings=warnings,
        converged=final.converged, iterations=final.evaluations, order_selection=selection,
        knee_tolerance=knee_tolerance, preprocessing=pre, supported_band_hz=band, noise=noise,
        order_evidence=evidence, context=context,
    )


# ------------------------------------------------------------------------------ model error
@dataclass(frozen=True)
class ModelError:
    """The residual the noise does not explain, per fitted bin (normalised units): what no
    model of the chosen order follows — a second drive path, a lobe-dependent gain, motion of
    the bar after the pulse (issue 17). It is weighed in the fit and drawn in the Monte Carlo
    like an output noise of this spectrum (a circular Gaussian per bin): an error of the model
    is not repeatable noise, but it is what the record leaves unexplained at each frequency,
    and drawing it is how its size reaches every figure's interval (the budget's "model
    error" row)."""

    var_bins: np.ndarray  # excess residual variance per fitted bin (E|R_k|² beyond the noise's)
    ratio: float  # residual over what the noise explains (V per degree of freedom of the noise alone)
    significant: bool
    rms_of_peak: float  # its RMS over the window, as a fraction of the response's peak
    response_share: float  # its RMS over the band relative to the model's response there (the order
    # test's tolerance: a higher order must change the response by more than the model error can)
    centroid_hz: float  # where in frequency it sits: its power's centroid and 10 … 90 % range
    range_hz: tuple[float, float]

    @classmethod
    def none(cls, bins: int) -> ModelError:
        return cls(np.zeros(bins), 1.0, False, 0.0, 0.0, math.nan, (math.nan, math.nan))

    def to_dict(self) -> dict[str, Any]:
        return _jsonable({"detected": self.significant, "residual_over_noise": self.ratio,
                          "rms_percent_of_peak": 100.0 * self.rms_of_peak,
                          "percent_of_response_in_band": 100.0 * self.response_share, "centroid_hz": self.centroid_hz,
                          "range_hz": list(self.range_hz)})


def measure_model_error(prep: _Prepared, data: SpectralData, fit: OrderFit, parameters: int, dt: float
                        ) -> ModelError:
    """The excess of the fit's residual over the noise, per bin: |R_k|² smoothed over
    neighbouring bins (over ±MODEL_ERROR_OCTAVES, _log_smoothed) less the noise's
    E|N_k|² (response noise plus the reference's through the model), corrected for the degrees
    of freedom the fit took. Significant when the residual exceeds MODEL_ERROR_DETECTED times the
    noise's."""
    omega = 2.0 * np.pi * prep.bin_hz * dt
    residual = prep.y_bins - predicted_bins(fit, data, omega, prep.u_bins)
    expected = prep.var_y + np.abs(response(fit, omega)) ** 2 * prep.var_u
    bins = prep.bin_hz.size
    dof = max(2 * bins - parameters, 1)
    power = np.abs(residual) ** 2 * (2.0 * bins / dof)
    ratio = float(np.sum(power / expected) / bins)
    if ratio <= MODEL_ERROR_DETECTED:
        return replace(ModelError.none(bins), ratio=ratio)
    excess = np.maximum(_log_smoothed(power - expected, prep.bin_hz), 0.0)
    length = prep.u.size
    rms = math.sqrt(2.0 * float(np.sum(excess))) / length
    share = np.cumsum(excess) / max(float(np.sum(excess)), 1e-300)
    lo, hi = (float(prep.bin_hz[min(int(np.searchsorted(share, q)), bins - 1)]) for q in (0.1, 0.9))
    centroid = float(np.sum(prep.bin_hz * excess) / max(float(np.sum(excess)), 1e-300))
    share_of_response = math.sqrt(float(np.sum(excess)) / max(float(np.sum(np.abs(prep.y_bins - residual) ** 2)),
                                                             1e-300))
    return ModelError(excess, ratio, True, rms, share_of_response, centroid, (lo, hi))


def _log_smoothed(x: np.ndarray, f_hz: np.ndarray) -> np.ndarray:
    """The mean of `x` over the bins within ±MODEL_ERROR_OCTAVES of each bin's frequency (at least
    MODEL_ERROR_MIN_BINS of them): fine where bins are few (low frequencies, where a pulse's
    nearly cancelling lobes make a small error large), coarse where they are many."""
    n = x.size
    total = np.concatenate(([0.0], np.cumsum(x)))
    lo = np.searchsorted(f_hz, f_hz * 2.0 ** -MODEL_ERROR_OCTAVES, side="left")
    hi = np.searchsorted(f_hz, f_hz * 2.0 ** MODEL_ERROR_OCTAVES, side="right")
    short = np.maximum(MODEL_ERROR_MIN_BINS - (hi - lo), 0)
    lo = np.maximum(lo - (short + 1) // 2, 0)
    hi = np.minimum(np.maximum(hi + short // 2, lo + MODEL_ERROR_MIN_BINS), n)
    lo = np.maximum(np.minimum(lo, hi - MODEL_ERROR_MIN_BINS), 0)
    return (total[hi] - total[lo]) / (hi - lo)


def with_output_variance(prep: _Prepared, var_y: np.ndarray) -> SpectralData:
    """The fitted data with another output variance per bin (per bin or grouped as prepared)."""
    data = prep.spectral
    if data.grouped:
        edges = np.arange(0, var_y.size, prep.group)
        return replace(data, var_y=np.add.reduceat(var_y, edges) / data.count)
    return replace(data, var_y=var_y)


# ------------------------------------------------------------------------------ preparation
@dataclass
class _Prepared:
    u: np.ndarray
    y: np.ndarray
    start: int
    baseline_u: float
    baseline_y: float
    drift_removed: bool
    noise_u: NoiseSpectrum
    noise_y: NoiseSpectrum
    band: tuple[float, float]
    bin_hz: np.ndarray
    u_bins: np.ndarray
    y_bins: np.ndarray
    var_u: np.ndarray
    var_y: np.ndarray
    group: int
    spectral: SpectralData
    pulse_start: int
    u_full: np.ndarray  # the whole record, normalised, baseline and drift removed
    y_full: np.ndarray
    y_segments: list[slice]  # the response's quiet stretches (its noise was measured there)
    ref_busy: np.ndarray  # where the reference carries the pulse (bool per sample)
    # The unbiased look at the noise (analysis.noise), for the uncertainty's draws; the fields
    # noise_u … var_y above are the conservative look the fit is weighted by.
    draw_noise_u: NoiseSpectrum
    draw_noise_y: NoiseSpectrum
    draw_var_u: np.ndarray
    draw_var_y: np.ndarray
    drift_lines: dict[str, tuple[float, float]]  # channel -> (slope per sample, intercept) removed, normalised
    # stretches after the pulse left out of the noise as coherent motion (start_s, stop_s, coherence; samples)
    motion: list[dict[str, float]] = field(default_factory=list)


def _scale(x: np.ndarray) -> float:
    """The channel's largest excursion from its median: the unit the fit works in."""
    return float(np.max(np.abs(x - np.median(x))))


def _prepare(u: np.ndarray, y: np.ndarray, dt: float, max_delay: int, warnings: list[str]) -> _Prepared:
    """Baselines, drift, noise spectra, the fitted window, the supported band and the DFT bins."""
    n = u.size
    try:
        pulse = pulse_width(u, dt)
    except AnalysisError as exc:
        raise AnalysisError(f"the reference has no pulse to identify from: {exc}") from None
    width = max(1, int(round(pulse.width_s / dt)))
    i_start = int(math.floor(pulse.start_s / dt))
    # Where each channel is busy: the reference above 2 % of its peak and 4× its noise floor
    # (every pulse of a train, not only the largest), the response above 4 noise RMS until it
    # stays quiet; each widened by the margins the filters and the delay need. The rest is
    # quiet: there the noise is measured.
    floor = float(np.median(np.convolve(np.abs(u), np.full(5, 0.2), mode="same")))  # the noise's level
    ref_busy = _busy(u, max(0.02 * float(np.max(np.abs(u))), 4.0 * floor), 2 * width + max_delay)
    first = int(np.argmax(ref_busy)) if np.any(ref_busy) else i_start
    pre_end = max(first, 0)
    base_u = float(np.mean(u[:pre_end])) if pre_end >= 16 else 0.0
    base_y = float(np.mean(y[:pre_end])) if pre_end >= 16 else 0.0
    u = u - base_u
    y = y - base_y
    noise_y0 = float(np.std(y[:pre_end])) if pre_end >= 16 else 0.0
    if noise_y0 == 0.0:  # no lead-in: a robust level from the record's last tenth
        tail = y[-max(n // 10, 16):]
        noise_y0 = float(1.4826 * np.median(np.abs(tail - np.median(tail))))
    resp_busy = ref_busy.copy()
    loud = _busy(y - _provisional_drift(y, pre_end, ref_busy), 4.0 * noise_y0, 0)
    for run in _runs(ref_busy):  # the response rings after each pulse until it stays quiet
        resp_busy[run.start : _settles(loud, run.start, max(50, 10 * width))] = True
    last_runs = _runs(resp_busy)
    last = last_runs[-1] if last_runs else slice(i_start, i_start + width)
    post_margin = max(20, 2 * width, (last.stop - last.start) // 4)
    end = min(n, last.stop + post_margin)
    truncated = last.stop + post_margin > n
    pre_window = max(3 * width, 32) + max_delay
    start = max(0, first - pre_window + 2 * width + max_delay) if np.any(ref_busy) else max(0, i_start - pre_window)
    cold_start = first < 16
    u_segments = [r for r in _runs(~ref_busy) if r.stop - r.start >= MIN_QUIET]
    y_segments = [r for r in _runs(~resp_busy) if r.stop - r.start >= MIN_QUIET]
    u_segments, y_segments, motion = _without_motion(u, y, dt, u_segments, y_segments, warnings)
    # A drift: the line through the quiet samples, when quiet stretches before the first and
    # after the last activity pin it.
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
        warnings.append("the reference has no quiet stretch (before the pulse or in flight after it) to measure "
                        "its noise: it is taken as noise-free, which understates the uncertainty")
    if not truncated and not cold_start:  # a window the FFT likes, from real (quiet) samples
        fast = next_fast_len(end - start)
        if start + fast <= n:
            end = start + fast
    uw, yw = u[start:end], y[start:end]
    try:
        band = supported_band_hz(u, dt, noise_psd=noise_u.at if noise_u.samples else None)
    except AnalysisError as exc:
        raise AnalysisError(f"the reference's pulse is lost in its noise: {exc}") from None
    length = uw.size
    freq = fft.rfftfreq(length, dt)
    keep = (freq >= max(band[0], freq[1] if freq.size > 1 else 0.0)) & (freq <= band[1])
    keep[0] = False
    if not np.any(keep):
        raise AnalysisError("the supported band holds no frequency bin of the fitted window (record too short)")
    u_spec = fft.rfft(uw)[keep]
    y_spec = fft.rfft(yw)[keep]
    bin_hz = freq[keep]
    omega = 2.0 * np.pi * bin_hz * dt
    var_u = noise_u.bin_variance(bin_hz, length) if noise_u.samples else np.zeros(bin_hz.size)
    if noise_y.samples == 0:
        noise_y = draw_noise_y = NoiseSpectrum.white(noise_y0, rate, "record tail (robust)", 0)
        warnings.append("the response has no quiet stretch to measure its noise: a robust level from the end of "
                        "the record is used")
    var_y = noise_y.bin_variance(bin_hz, length)
    floor = 1e-12 * float(np.mean(np.abs(y_spec) ** 2))  # a noise-free record still gets finite weights
    var_y = np.maximum(var_y, floor)
    draw_var_u = draw_noise_u.bin_variance(bin_hz, length) if draw_noise_u.samples else np.zeros(bin_hz.size)
    draw_var_y = np.maximum(draw_noise_y.bin_variance(bin_hz, length), floor)
    # The conservative look detrends each Welch segment, which empties its lowest bins: a slow
    # baseline wander (cable, thermal; below its first bins) was then weighed as if absent, and
    # a spare pole near DC 'explained' it beyond chance (DC gain off by 5 %, FBSD at 1 kHz).
    # Below the detrended segments' second bin the fit takes the larger of the two looks.
    low = bin_hz < 2.0 * rate / WELCH_SEGMENT
    var_u = np.where(low, np.maximum(var_u, draw_var_u), var_u)
    var_y = np.where(low, np.maximum(var_y, draw_var_y), var_y)
    transient = truncated or cold_start
    if truncated:
        warnings.append("the record ends before the response has died away: a transient term is fitted with the "
                        "model, and the uncertainty is larger than a complete record would give")
    if transient:
        t = np.arange(length, dtype=float)
        ramp = fft.rfft((t - t.mean()) / length)[keep]
        spectral = SpectralData.per_bin(omega, u_spec, y_spec, var_u, var_y, ramp, True)
        group = 1
    else:
        group = max(1, math.ceil(bin_hz.size / MAX_BINS))
        if group == 1:
            spectral = SpectralData.per_bin(omega, u_spec, y_spec, var_u, var_y)
        else:
            spectral = SpectralData.grouped_from(omega, u_spec, y_spec, var_u, var_y, group)
    return _Prepared(uw, yw, start, base_u, base_y, drift, noise_u, noise_y, band, bin_hz, u_spec, y_spec,
                     var_u, var_y, group, spectral, i_start, u, y, y_segments, ref_busy, draw_noise_u, draw_noise_y,
                     draw_var_u, draw_var_y, lines, motion)


def _response_noise_on_residual(prep: _Prepared, fit: OrderFit, dt: float) -> tuple[NoiseSpectrum, np.ndarray]:
    """The response's noise measured again on the same quiet stretches, with the model's
    response to the pulse taken out: a lightly damped sensor still rings below the loudness
    test's 4 RMS when its stretch after the pulse is judged quiet, and that ringing, measured
    as noise, sat at the resonance (f_n's and ζ's intervals 1.5× too wide) and raised the RMS
    ~1.5×. Frequency by frequency the lower of the two looks is kept: outside the fitted band
    the model is not measured (a spare pole near z = 1 predicts a tail the record does not
    have), and there taking it out would add power instead. Returns the spectrum and its
    variance per fitted bin (the first look's when there was no stretch to measure)."""
    if prep.draw_noise_y.samples == 0 or prep.draw_noise_y.source.startswith("record tail"):
        return prep.draw_noise_y, prep.draw_var_y
    # The model driven by the pulse alone: driven by the whole reference it would add the
    # reference's noise through G, counted as response noise (~15 % too much at 2 % each).
    residual = prep.y_full - _simulate(np.where(prep.ref_busy, prep.u_full, 0.0), fit)
    second = NoiseSpectrum.measure(residual, 1.0 / dt, prep.y_segments)
    if second.samples == 0:
        return prep.draw_noise_y, prep.draw_var_y
    noise = second.lower_of(prep.draw_noise_y)
    var_y = noise.bin_variance(prep.bin_hz, prep.u.size)
    return noise, np.maximum(var_y, 1e-12 * float(np.mean(np.abs(prep.y_bins) ** 2)))


def _initial_delay(data: SpectralData, prep: _Prepared, order: int, max_delay: int) -> float:
    """A start for the causal delay: on a grid (half a sample, or 1/8 of the span) up to just past
    the cross-correlation lag, the two best linear starts of `order` are refined and the best
    refined delay kept."""
    try:
        xcorr = estimate_delay_samples(prep.u, prep.y, max(1, min(max_delay, prep.u.size // 4)))
    except AnalysisError:
        xcorr = 0.0
    top = float(np.clip(math.ceil(xcorr) + 1, 0, max_delay))
    problem = OrderProblem(data, order, "causal", max_delay)
    step = max(0.5, top / 8.0)  # at most ~9 starts
    starts = sorted((problem.linear_start(float(tau)) for tau in np.arange(0.0, top + 0.25 * step, step)),
                    key=lambda f: f.cost)
    picked: list[OrderFit] = []
    for start in starts:
        if all(abs(start.delay - p.delay) >= 1.0 for p in picked):
            picked.append(start)
        if len(picked) == 2:
            break
    refined = [problem.solve(start, 40) for start in picked]
    return min(refined, key=lambda f: f.cost).delay if refined else 0.0


def _busy(x: np.ndarray, level: float, widen: int) -> np.ndarray:
    """Samples where a 5-sample box-car of |x| exceeds `level`, widened by `widen` each side."""
    loud = np.convolve(np.abs(x), np.full(5, 0.2), mode="same") > level
    if widen > 0 and np.any(loud):
        loud = np.convolve(loud.astype(float), np.ones(2 * widen + 1), mode="same") > 0
    return loud


def _without_motion(u: np.ndarray, y: np.ndarray, dt: float, u_segments: list[slice], y_segments: list[slice],
                    warnings: list[str]) -> tuple[list[slice], list[slice], list[dict[str, float]]]:
    """The quiet stretches with those after the pulse where the channels move together taken
    out (analysis.noise.is_motion): the bar keeps moving after the pulse (PTB's record: 1–2 %
    of the peak for > 1 ms, coherence 0.88), and that motion, taken as noise, inflated the
    reference's noise ×12, cut the band, blinded the order test and hid the model error. Noise
    is measured where a channel is at rest: the lead-in. A channel with no lead-in long enough
    keeps its stretches (with a warning)."""
    motion: list[dict[str, float]] = []
    judged: dict[tuple[int, int], bool] = {}

    def moving(r: slice) -> bool:
        key = (r.start, r.stop)
        if key not in judged:
            verdict, msc = is_motion(u[r], y[r], 1.0 / dt) if r.start > 0 else (False, math.nan)
            judged[key] = verdict
            if verdict:
                motion.append({"start_sample": r.start, "stop_sample": r.stop, "coherence": msc})
        return judged[key]

    out = []
    for name, segs in (("reference", u_segments), ("response", y_segments)):
        kept = [r for r in segs if not moving(r)]
        if len(kept) < len(segs) and not any(r.start == 0 for r in kept):
            warnings.append(f"the {name} moves coherently with the other channel after the pulse and has no "
                            "lead-in at rest: its noise is measured on that motion, which overstates it")
            kept = segs
        out.append(kept)
    return out[0], out[1], motion


def _provisional_drift(y: np.ndarray, pre_end: int, ref_busy: np.ndarray) -> np.ndarray:
    """The line through the response's pre-pulse stretch and the record's last tenth (when both
    are clear of the reference's activity), against which its loudness is judged. A drifting
    response (a charge amplifier's drift, a zero shift after the shock) never returns to its
    pre-pulse level: judged against that level it stays loud to the record's end, the record is
    taken as cut short, its drift is never removed, and the fit chases the drift with a spare
    low-frequency pole-zero pair that moves the DC gain and the FBSD. Where the response still
    rings at the end, the ringing averages to the baseline: the line stays flat and the
    ringing stays loud."""
    n = y.size
    tail = max(n // 10, MIN_QUIET)
    busy = np.flatnonzero(ref_busy)
    if pre_end < 16 or busy.size == 0 or n - tail <= busy[-1]:
        return np.zeros(n)
    idx = np.concatenate((np.arange(pre_end), np.arange(n - tail, n)))
    slope, intercept = np.polyfit(idx, y[idx], 1)
    return slope * np.arange(n) + intercept


def _settles(loud: np.ndarray, start: int, quiet: int) -> int:
    """One past the last loud sample after `start` that is followed by `quiet` quiet samples (a
    stray loud sample of the noise further on does not count)."""
    idx = np.flatnonzero(loud[start:])
    if idx.size == 0:
        return start
    gaps = np.flatnonzero(np.diff(idx) > quiet)
    last = idx[gaps[0]] if gaps.size else idx[-1]
    return int(start + last + 1)


def _runs(mask: np.ndarray) -> list[slice]:
    """The contiguous runs of True in `mask`, as slices."""
    edges = np.flatnonzero(np.diff(np.concatenate(([0], mask.astype(np.int8), [0]))))
    return [slice(int(a), int(b)) for a, b in zip(edges[::2], edges[1::2], strict=True)]


# ------------------------------------------------------------------------------ checks
def _acceptable(fit: OrderFit, bins: int) -> bool:
    """Stable with a margin, and not a fit whose linear start called for an unstable model
    while the stable optimum presses against the unit circle or leaves the data unexplained
    (a residual far beyond the noise: a growing response no stable model can follow)."""
    if fit.order == 0:
        return True
    radius = float(np.max(np.abs(np.roots(fit.a))))
    if radius >= 1.0 - MARGINAL_POLE:
        return False
    if not fit.start_unstable:
        return True
    dof = 2 * bins - fit.parameters
    unexplained = dof > 0 and 2.0 * fit.cost / dof > UNSTABLE_MODEL_ERROR
    return not (radius > 1.0 - 1e-3 or unexplained)


def _marginal_modes_text(fit: OrderFit, dt: float) -> str:
    """Where the order test's choice put its poles on or beyond the unit circle, as modes
    (e.g. ': order 2 has a mode at 58.4 kHz with ζ ≤ 1e-05, undamped'); '' when none is there."""
    roots = np.roots(fit.a) if fit.a.size > 1 else np.array([])
    marginal = roots[(np.abs(roots) >= 1.0 - MARGINAL_POLE) & (roots.imag >= 0)]
    if not marginal.size:
        return ""
    parts = []
    for z in marginal:
        s = np.log(complex(z)) / dt
        f_hz = abs(s) / (2.0 * np.pi)
        zeta = -s.real / abs(s) if abs(s) > 0 else 0.0
        parts.append(f"a mode at {f_hz / 1e3:.3g} kHz with ζ {'≤ 1e-05' if abs(zeta) <= 1e-5 else f'= {zeta:.2g}'}")
    return (f": order {fit.order} has {', '.join(parts)}, undamped: a response that rings on without a drive in "
            "the reference (a second drive path, motion the reference does not see) or a mode in a null of the "
            "excitation whose damping the data do not fix")


def _has_doublet(fit: OrderFit) -> bool:
    """Whether a complex pole pair of the fit is nearly cancelled by a zero (`mark_doublets`'s
    test; the sample interval does not enter it, so any is given)."""
    if fit.order == 0 or fit.b.size < 2:
        return False
    return any(m["cancelled"] for m in mark_doublets(modes_of(np.roots(fit.a), 1.0), np.roots(fit.b)))


def _pole_below_band(fit: OrderFit, lowest_bin_hz: float, dt: float) -> bool:
    """Whether the fit has a real pole whose frequency lies below a tenth of the lowest
    fitted bin's (undetermined by the fitted data)."""
    roots = np.roots(fit.a) if fit.a.size > 1 else np.array([])
    real = roots[(np.abs(roots.imag) < 1e-12) & (roots.real > 0)].real
    f_hz = -np.log(np.clip(real, 1e-300, None)) / (2.0 * np.pi * dt)
    return bool(np.any(f_hz < 0.1 * lowest_bin_hz))


def _claims_warnings(modes: list[dict[str, Any]], band: tuple[float, float], model: DiscreteModel) -> list[str]:
    out = []
    lo, hi = band
    for m in modes:
        f = m.get("natural_frequency_hz")
        if m.get("cancelled"):
            out.append(
                f"the pole pair at {f / 1e3:.4g} kHz (ζ = {m['damping_ratio']:.3g}) is nearly cancelled by a zero (a "
                "pole–zero doublet: the fit following a ripple of the data, not a resonance): it is not reported as "
                "a mode"
            )
        elif m.get("shapes_band") and f is not None:
            out.append(
                f"the resonance near {f / 1e3:.4g} kHz lies beyond the band the excitation supports ({lo / 1e3:.3g}–"
                f"{hi / 1e3:.3g} kHz): the all-pole model places it by the rise it gives inside the band, not by its "
                f"own peak; its frequency is an extrapolation and its damping is not determined (held ≥ "
                f"{ZETA_FLOOR:g}), so neither is reported as measured; the DCM cancels it for that rise"
            )
        elif m["kind"] == "complex" and not m["supported"] and f is not None:
            out.append(
                f"the mode at {f / 1e3:.4g} kHz (ζ = {m['damping_ratio']:.3g}) lies outside the band the excitation "
                f"supports ({lo / 1e3:.3g}–{hi / 1e3:.3g} kHz): this record cannot determine it, so it is kept out "
                "of the key figures and the DCM"
            )
    if main_mode(modes) is None:
        beyond = [m for m in modes if m["kind"] == "complex" and not m.get("cancelled")
                  and (m["natural_frequency_hz"] or 0.0) > hi]
        bound = (f"the resonance lies above {hi / 1e3:.3g} kHz, in a null of the excitation" if beyond
                 else "the sensor's natural frequency and damping are not reported")
        out.append(
            f"no resonance (complex pole pair) lies inside the supported band ({lo / 1e3:.3g}–{hi / 1e3:.3g} kHz): "
            f"{bound}; a shorter pulse would excite it"
        )
    return out


def _lead_warning(data: SpectralData, fit: OrderFit, dt: float, significance: float) -> list[str]:
    """Whether the response leads the reference. Two looks: the same order with the delay free
    to go negative fits significantly better (the causal model cannot follow the lead); or the
    causal model's whole group delay at low frequencies (delay + B's − A's) is negative. The
    second catches what the first misses: the delay and the zeros share a flat valley of the
    cost, so B's zeros take up the lead (a phase advance) as well as the free delay would,
    and the fitted delay alone says nothing. A sensor (modes above the band) lags at low
    frequencies by Σ 2ζ/ω_n: a whole lead is the channels' skew. (A lead smaller than the
    sensor's own lag cannot be told from it.)"""
    lead = _low_frequency_lead(fit)
    if fit.delay <= LEAD_WARNING_SAMPLES:
        problem = OrderProblem(data, fit.order, "free", numerator=fit.numerator)
        free = problem.solve(replace(fit, cost=math.nan), 60)
        gain = fit.cost - free.cost
        dof = 2 * data.bins - problem.size
        if free.delay < -LEAD_WARNING_SAMPLES and dof > 0 and gain > 0:
            critical = f_quantile(1.0 - significance, 1, dof)
            if (2.0 * gain) / (2.0 * free.cost / dof) > critical:
                lead = max(lead, -free.delay)
    if lead <= LEAD_WARNING_SAMPLES:
        return []
    return [
        f"the response leads the reference by about {lead:.2g} samples ({lead * dt * 1e6:.3g} µs): no sensor answers "
        "before it is excited, so the channels are skewed (digitizer deskew, cable lengths, trigger alignment); the "
        "model is kept causal (delay ≥ 0) and absorbs the lead into its zeros, which biases it — correct the skew"
    ]


def _low_frequency_lead(fit: OrderFit) -> float:
    """The causal model's lead at low frequencies, samples (0 when it lags): minus its group
    delay at DC, τ + Σk·b_k/Σb_k − Σk·a_k/Σa_k. 0 when B or A nearly vanishes at DC (a
    differentiating model: no DC group delay to judge by)."""
    def group_delay(p: np.ndarray) -> float | None:
        total = float(np.sum(p))
        if abs(total) <= 1e-6 * float(np.sum(np.abs(p))):
            return None
        return float(np.dot(np.arange(p.size), p)) / total
    gd_b, gd_a = group_delay(np.asarray(fit.b, dtype=float)), group_delay(np.asarray(fit.a, dtype=float))
    if gd_b is None or gd_a is None:
        return 0.0
    return max(0.0, -(fit.delay + gd_b - gd_a))


# ------------------------------------------------------------------------------ helpers
def _simulate(u: np.ndarray, fit: OrderFit) -> np.ndarray:
    """Model output (B/A)·u(k − τ) from rest (analysis.response.simulate_from_rest: the same
    prediction the report and delayed_model_output make)."""
    return simulate_from_rest(fit.a, fit.b, fit.delay, u)


def _information_criteria(losses: list[float], parameters: list[int], bins: int) -> tuple[list[float], list[float]]:
    """AIC and BIC on V (2K real residuals of unit variance: −2 log L = 2V + const)."""
    aic, bic = [], []
    rows = 2 * bins
    for loss, p in zip(losses, parameters, strict=True):
        if math.isfinite(loss) and loss > 0:
            aic.append(2.0 * loss + 2 * p)
            bic.append(2.0 * loss + p * math.log(rows))
        else:
            aic.append(math.nan)
            bic.append(math.nan)
    return aic, bic


def _checked_channels(rec: Record) -> tuple[np.ndarray, np.ndarray]:
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


def remove_input_delay(ref: np.ndarray, resp: np.ndarray, d: int) -> tuple[np.ndarray, np.ndarray]:
    """(u, y) with y(k) = response(k + d) against u(k) = reference(k): removes a delay of d samples."""
    if d >= 0:
        return ref[: ref.size - d], resp[d:]
    return ref[-d:], resp[: resp.size + d]


def fit_percent(measured: np.ndarray, simulated: np.ndarray) -> float:
    """100·(1 − ‖y − ŷ‖/‖y − ȳ‖): 100 is a perfect fit, 0 no better than the mean; NaN for a constant y."""
    y = np.asarray(measured, dtype=float)
    centred, error = y - np.mean(y), y - np.asarray(simulated, dtype=float)
    spread = math.sqrt(long_dot(centred, centred))
    return 100.0 * (1.0 - math.sqrt(long_dot(error, error)) / spread) if spread > 0 else float("nan")


def _excitation_warnings(u: np.ndarray, dt: float, modes: list[dict[str, Any]]) -> list[str]:
    """Warn about modes outside the band the reference `u` supports (the data cannot determine them)."""
    band = supported_band_hz(u, dt)
    flagged = modes_of(np.array([complex(*m["pole"]) for m in modes] +
                                [complex(*m["pole"]).conjugate() for m in modes if m["kind"] == "complex"]), dt,
                       band)
    out = []
    for m in flagged:
        f = m.get("natural_frequency_hz")
        if m["kind"] == "complex" and not m["supported"] and f is not None:
            out.append(f"the mode at {f / 1e3:.4g} kHz lies outside the band the reference supports "
                       f"({band[0] / 1e3:.3g}–{band[1] / 1e3:.3g} kHz): this record cannot determine it")
    return out
