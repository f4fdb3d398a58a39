"""The stages of analysis.identify after the record is prepared, each a function with a typed
input and a frozen result carrying its own findings:

search_orders → weigh_model_error → settle → claim

Why each stage does what it does: docs/decisions/0011 (the order), 0012 (motion is not noise),
0013 (model error measured and carried).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from hopkinson.analysis.claims import claim_findings, claimed_modes, delay_findings
from hopkinson.analysis.errors import AnalysisError
from hopkinson.analysis.findings import Finding, FindingCode
from hopkinson.analysis.frequency_fit import OrderFit, OrderProblem, predicted_bins, response
from hopkinson.analysis.input_terms import ASYMMETRY, MOTION
from hopkinson.analysis.loss import long_dot
from hopkinson.analysis.model import DiscreteModel
from hopkinson.analysis.model_error import (
    MODEL_ERROR_DETECTED,
    MODEL_ERROR_WITH_DOUBLET,
    ModelError,
    measure_model_error,
)
from hopkinson.analysis.modes import Mode, has_doublet
from hopkinson.analysis.noise import NoiseSpectrum
from hopkinson.analysis.numerics import f_quantile
from hopkinson.analysis.onset_choice import onset_beyond_the_model_error, onset_fitted
from hopkinson.analysis.options import AnalysisOptions
from hopkinson.analysis.order_choice import OrderStability, choose_order
from hopkinson.analysis.order_search import (
    OrderSweep,
    SearchSetup,
    SettledOrder,
    best_delay_branch,
    fit_orders,
    fit_structures,
    order_stability_evidence,
    search_setup,
    settle_order,
)
from hopkinson.analysis.record_preparation import (
    Prepared,
    PreparedRecord,
    response_noise_on_residual,
    with_output_variance,
)
from hopkinson.analysis.response import simulate_from_rest
from hopkinson.analysis.spectral_data import SineTerms, SpectralData
from hopkinson.analysis.structure import Structure

# Below this fit percentage the model is reported as explaining little of the response.
POOR_FIT_PERCENT = 50.0
# V per degree of freedom above this: the model, not the noise, dominates the residual.
MODEL_ERROR_RATIO = 2.0
# ε and γ are fitted where the chosen order's fit sees them beyond chance (|c|/u(c) ≥ TERM_Z:
# two-sided 10⁻³) and determines them (u under UNDETERMINED_U) (docs/decisions/0013).
TERM_Z = 3.29
UNDETERMINED_U = {ASYMMETRY: 0.05, MOTION: 0.25}
# A stretch of the band past the pulse's first null is kept while the model explains it to within
# this many times what its noise explains, or the 99.9 % point of chance for a stretch of few bins.
STRETCH_EXCESS = MODEL_ERROR_DETECTED
STRETCH_CHANCE = 0.999


@dataclass(frozen=True)
class OrderSearch:
    """Stage search_orders: the free structure's orders fitted, with the onset's bumps where the
    record calls for them and ε, γ only where the fit sees them."""

    setup: SearchSetup
    prep: Prepared  # the prepared record with the input terms the search fits (`terms`, `spectral`, `unseen`)
    data: SpectralData  # the bins as fitted
    sweep: OrderSweep
    findings: tuple[Finding, ...] = ()


@dataclass(frozen=True)
class WeighedSearch:
    """Stage weigh_model_error: the model error measured on the search's choice and, where
    significant (or the choice holds a doublet), every order fitted again with it weighed and
    the structure chosen."""

    prep: Prepared  # the prepared record with the input terms fitted once the model error is weighed
    data: SpectralData  # the bins as weighed
    sweep: OrderSweep
    model_error: ModelError


@dataclass(frozen=True)
class Settlement:
    """Stage settle: the order (converged and stable), its final fit on the best delay branch,
    the other branches within chance, and the model error on the final fit."""

    setup: SearchSetup
    data: SpectralData
    settled: SettledOrder
    final: OrderFit
    others: list[OrderFit]
    model_error: ModelError
    stability: OrderStability | None = None  # the order choice re-run on noise draws (stability_draws)
    findings: tuple[Finding, ...] = ()

    @property
    def sweep(self) -> OrderSweep:
        return self.settled.sweep

    @property
    def order(self) -> int:
        return self.settled.order

    @property
    def model_error_detected(self) -> bool:
        """Whether the model error was detected (weighed in the fit, drawn by the uncertainty)."""
        return bool(np.any(self.model_error.var_bins > 0))

    @property
    def branches(self) -> dict[int, list[OrderFit]]:
        """The chosen order's other delay branches (the Monte Carlo refits each draw from all)."""
        return {self.order: self.others} if self.others else {}


@dataclass(frozen=True)
class Claim:
    """Stage claim: the model in the record's units, its modes and what may be said of them, and
    the residual against the noise (the response's noise measured again less the model's response)."""

    model: DiscreteModel
    modes: list[Mode]
    fit_percent: float  # 100·(1 − ‖y − ŷ‖/‖y − ȳ‖) over the fitted window
    residual: np.ndarray  # y − ŷ over the fitted window (normalised)
    v_per_dof: float  # V per degree of freedom of the final fit (≈ 1: the noise explains it)
    response_noise: NoiseSpectrum  # normalised units
    response_var: np.ndarray  # its variance per fitted bin
    band_cut: BandCut | None = None  # where the band should stop short (identify fits again)
    findings: tuple[Finding, ...] = ()

    def draw_var_y(self, model_error: ModelError) -> np.ndarray:
        """The response's variance per fitted bin the uncertainty draws: its noise and the model error."""
        return self.response_var + model_error.var_bins


# ------------------------------------------------------------------------------ search_orders
def search_orders(prepared: PreparedRecord, options: AnalysisOptions, sine_terms: SineTerms | None = None
                  ) -> OrderSearch:
    """Every order of the free structure fitted on the prepared bins (with `sine_terms`: the sine
    points of analysis.sine_joint), the onset's bumps where they stand, and ε, γ dropped where the
    chosen order's fit does not call for them (the result's `prep` holds the terms fitted)."""
    prep, dt = prepared.prep, prepared.record.sample_interval_s
    data = prep.spectral if sine_terms is None else replace(prep.spectral, sine=sine_terms)
    setup = search_setup(data, prep, options.n_max, options.order, dt, remove_delay=options.remove_delay,
                         max_delay=options.max_delay_samples, patience=options.patience,
                         max_evaluations=options.max_evaluations, significance=options.significance,
                         alignment=prepared.alignment)
    sweep = fit_orders(data, Structure.FREE, setup)
    if sweep.chosen is not None:
        prep, with_onset = onset_fitted(prep, data, sweep, setup)
        if with_onset is not None:  # the onset's disturbances are fitted with every order
            data, sweep = with_onset
        dropped = undetermined_terms_dropped(prep, data, sweep, setup)
        if dropped is not None:  # a term the record does not call for is not fitted
            prep, data = dropped
            sweep = fit_orders(data, Structure.FREE, setup)
    return OrderSearch(setup, prep, data, sweep, setup.findings)


def undetermined_terms_dropped(prep: Prepared, data: SpectralData, sweep: OrderSweep, setup: SearchSetup
                               ) -> tuple[Prepared, SpectralData] | None:
    """The prepared record and the data without the input terms ε and γ the chosen order's fit
    does not call for (TERM_Z, UNDETERMINED_U), each with the reason (the estimate and its
    standard uncertainty); None when it keeps both."""
    if sweep.chosen is None or not prep.terms.count:
        return None
    fit = sweep.fits[sweep.chosen]
    problem = OrderProblem.for_fit(data, fit, sweep.delay_mode, setup.max_delay)
    jac = problem.jacobian(problem.pack(fit))
    dof = max(problem.residual_size() - problem.size, 1)
    cov = np.linalg.pinv(jac.T @ jac) * max(2.0 * fit.cost / dof, 1.0)
    first = problem._k_inputs
    terms, unseen = prep.terms, dict(prep.unseen)
    for name, limit in UNDETERMINED_U.items():
        cols = prep.terms.columns(name)
        if not cols.size:
            continue
        k = first + int(cols[0])
        value, u = float(fit.inputs[cols[0]]), math.sqrt(max(float(cov[k, k]), 0.0))
        if not u <= limit:
            terms = terms.without(name, f"the record does not determine it ({value:+.2g}, standard uncertainty {u:.2g})")
        elif abs(value) < TERM_Z * u:
            terms = terms.without(name, f"not seen beyond chance: {value:+.2g} with a standard uncertainty of {u:.2g}")
            unseen[name] = u  # analysis.systematics bounds its effect by 2u
    if terms.count == prep.terms.count:
        return None
    prep = replace(prep, terms=terms, spectral=replace(prep.with_terms(terms), var_y=prep.spectral.var_y),
                   unseen=unseen)
    return prep, replace(prep.spectral, var_y=data.var_y, sine=data.sine)


# ------------------------------------------------------------------------------ weigh_model_error
def weigh_model_error(prepared: PreparedRecord, search: OrderSearch, sine_terms: SineTerms | None = None
                      ) -> WeighedSearch:
    """The model error measured on the search's choice (iterated to convergence; a choice that took
    more than half the real residuals is replaced by the order test's choice among those that
    leave half) and, when significant, weighed as an output error of its own with every order
    fitted again; the structure chosen where it is significant or the choice holds a doublet
    (docs/decisions/0013)."""
    prep, setup, data, sweep = search.prep, search.setup, search.data, search.sweep
    model_error = ModelError.none(prep.bin_hz.size)
    if sweep.chosen is None and setup.asked_order is None:
        # no order with free zeros is a candidate (each presses a pole onto the unit circle: a
        # resonance beyond the band whose damping free zeros leave undetermined): the all-pole
        # structure, whose damping beyond the band is floored, as settle_order falls back from an
        # unstable free choice (the same rule as order_search.fit_structures', without refitting
        # the free sweep this search has just made)
        all_pole = fit_orders(data, Structure.ALL_POLE, setup)
        if all_pole.chosen is not None:
            sweep = replace(all_pole, why="no model with free zeros is stable")
    if sweep.chosen is None:
        return WeighedSearch(prep, data, sweep, model_error)
    order = setup.asked_order
    pick = order if order is not None and order in sweep.fits else sweep.chosen
    if order is None and sweep.parameters[pick] > data.bins:  # measured on a choice that leaves half
        within = {n: v for n, v in sweep.costs.items() if sweep.parameters[n] <= data.bins}
        kept, _ = choose_order(within, sweep.parameters, data.bins, sweep.changes, setup.significance)
        pick = kept if kept is not None else pick
    converged = OrderProblem.for_fit(data, sweep.fits[pick], sweep.delay_mode, setup.max_delay).solve(
        sweep.fits[pick], 200, 1e-9)
    doublet = has_doublet(converged.a, converged.b)
    threshold = MODEL_ERROR_WITH_DOUBLET if doublet else MODEL_ERROR_DETECTED
    model_error = measure_model_error(prep, data, converged, sweep.parameters[pick], setup.sample_interval_s,
                                      threshold)
    if model_error.significant:
        data = with_output_variance(prep, prep.var_y + model_error.var_bins)
        if sine_terms is not None:  # the joint fit keeps its sine points (analysis.sine_joint)
            data = replace(data, sine=sine_terms)
        prep, data = onset_beyond_the_model_error(prep, data, converged, sweep.delay_mode, setup)
    if model_error.significant or doublet:  # a doublet can take the model error in: its residual reads as noise
        sweep = fit_structures(data, setup)
    return WeighedSearch(prep, data, sweep, model_error)


# ------------------------------------------------------------------------------ settle
def settle(prepared: PreparedRecord, search: OrderSearch, weighed: WeighedSearch, options: AnalysisOptions
           ) -> Settlement:
    """The order's stability on noise draws (options.stability_draws), the order settled
    (order_search.settle_order), the best delay branch, and the model error's size on the final
    fit (its detection stays with weigh_model_error)."""
    prep, setup, data, sweep = weighed.prep, search.setup, weighed.data, weighed.sweep
    findings: list[Finding] = []
    stability = None
    if options.order is None and options.stability_draws > 0 and sweep.chosen is not None:
        stability, found = order_stability_evidence(prep, data, sweep, setup, options.stability_draws)
        findings += found
    settled = settle_order(sweep, data, setup)
    findings += settled.findings
    final, others = best_delay_branch(settled.sweep, settled.order, data, setup)
    model_error = weighed.model_error
    if model_error.significant:
        model_error = measure_model_error(prep, data, final, settled.sweep.parameters[settled.order],
                                          setup.sample_interval_s, threshold=0.0)
    if not final.converged:
        findings.append(Finding(FindingCode.NOT_CONVERGED,
                                f"the order-{settled.order} fit stopped before converging in {final.evaluations} "
                                "evaluations (its cost was the lowest reached)"))
    return Settlement(setup, data, settled, final, others, model_error, stability, tuple(findings))


# ------------------------------------------------------------------------------ claim
def claim(prepared: PreparedRecord, weighed: WeighedSearch, settlement: Settlement, options: AnalysisOptions,
          cut_band: bool = True) -> Claim:
    """The model in the record's units (the scales back into B, the mean of both directions'
    gains: analysis.input_terms), its modes and their claims, the delay's, the residual against
    the noise, and (`cut_band`) where the band past the pulse's first null stops being explained."""
    prep, rec, data, final = weighed.prep, prepared.record, settlement.data, settlement.final
    dt, structure = rec.sample_interval_s, settlement.sweep.structure
    mean = prep.terms.mean_gain_factor(final.inputs)
    model = DiscreteModel(dt, final.a, final.b * (mean * prepared.scale_y / prepared.scale_u),
                          float(final.delay) - prepared.realigned_samples,
                          info={"fit_method": "eiv-frequency-oe", "structure": structure.value})
    band_cut = stretches_beyond_the_model(prep, data, final, dt) if cut_band else None
    modes = claimed_modes(model, prep.band, structure)
    findings = claim_findings(modes, prep.band)
    if options.remove_delay:
        findings += delay_findings(data, final, structure, dt, options.significance, prepared.realigned_samples)
        if prepared.alignment.at_edge:
            findings.append(Finding(FindingCode.SKEW_NOT_TAKEN,
                                    f"{prepared.alignment.not_taken_text(dt)}: if the channels are skewed by that "
                                    "much, this model is not the sensor's; correct the skew and analyse again"))
    noise_y, var_y = response_noise_on_residual(prep, final, dt)
    y_hat = simulate_from_rest(final.a, final.b, final.delay, prep.corrected_u(final.inputs))
    residual = prep.y - y_hat
    fit = fit_percent(prep.y, y_hat)
    dof = 2 * data.bins - settlement.sweep.parameters[settlement.order]
    ratio = 2.0 * final.cost / dof if dof > 0 else math.inf
    findings += _residual_findings(settlement.model_error, prep, ratio, fit)
    return Claim(model, modes, fit, residual, ratio, noise_y, var_y, band_cut, tuple(findings))


def _residual_findings(model_error: ModelError, prep: Prepared, ratio: float, fit: float) -> list[Finding]:
    """What the residual says: model error measured, motion left out of the noise, a residual far
    beyond the noise, a poor fit."""
    out = []
    if model_error.significant:
        lo_hz, hi_hz = model_error.range_hz
        out.append(Finding(
            FindingCode.MODEL_ERROR,
            f"model error: the residual is {model_error.ratio:.3g}× what the measured noise explains, "
            f"{100 * model_error.rms_of_peak:.2g} % of the response's peak (RMS), mostly at "
            f"{lo_hz / 1e3:.3g}–{hi_hz / 1e3:.3g} kHz; it is weighed in the fit and drawn in the uncertainty "
            "as its own source (budget row 'model error')"
        ))
    coherent = [m["coherence"] for m in prep.noise.motion if m["coherence"] is not None]
    if coherent and prep.activity.lead_in:  # without a lead-in the motion is the noise (record_preparation's finding)
        out.append(Finding(FindingCode.MOTION_LEFT_OUT,
                           "the channels keep moving together after the pulse (coherence "
                           f"{max(coherent):.2f}): that motion is not taken as noise; the noise is measured on the "
                           "lead-in at rest"))
    if ratio > MODEL_ERROR_RATIO:
        out.append(Finding(
            FindingCode.RESIDUAL_BEYOND_NOISE,
            f"the model leaves {ratio:.1f}× the residual the measured noise explains (V per degree of freedom): "
            "the residual is mostly model error (unmodelled dynamics of the sensor or the reference chain, or "
            "noise the quiet parts of the record did not show); the uncertainty is widened by √ of that factor"
        ))
    if fit < POOR_FIT_PERCENT:
        out.append(Finding(
            FindingCode.POOR_FIT,
            f"the model explains only {fit:.1f} % of the response (fit = 100·(1 − ‖y − ŷ‖/‖y − ȳ‖)): "
            "check that the channels belong together and that the response is not mostly noise"
        ))
    return out


@dataclass(frozen=True)
class BandCut:
    """Where the band stops short of the excitation's support: past the pulse's first null, the
    first stretch the model does not explain to within the noise, and how far it departs."""

    top_hz: float  # the band's new top (the last stretch kept ends there)
    stretch_hz: tuple[float, float]  # the first stretch dropped
    ratio: float  # its residual per bin over what the noise explains (inf: no model was stable there; nan: by_onset)
    failure: str = ""  # why no model fitted the stretches past the first null (ratio inf)
    by_onset: bool = False  # the band above top_hz stood above the noise only by the fitted onset disturbances

    @property
    def finding(self) -> Finding:
        lo, hi = self.stretch_hz
        if self.by_onset:
            return Finding(FindingCode.BAND_CUT,
                           f"the band stops at {self.top_hz / 1e3:.3g} kHz: the reference stood above its noise up to "
                           f"{hi / 1e3:.3g} kHz only by its onset disturbances (fitted: demodulation glitches, errors of "
                           "the reference, not the bar's motion); without them the pulse supports the band below "
                           f"{self.top_hz / 1e3:.3g} kHz, and the model is fitted there")
        if self.failure:
            return Finding(FindingCode.BAND_CUT,
                           f"the band stops at the pulse's first null, {self.top_hz / 1e3:.3g} kHz: across the nulls "
                           f"(from {lo / 1e3:.3g} kHz) no model fitted ({self.failure}); the model is fitted below it")
        return Finding(FindingCode.BAND_CUT,
                       f"the band stops at {self.top_hz / 1e3:.3g} kHz: past the pulse's first null the stretch "
                       f"{lo / 1e3:.3g}–{hi / 1e3:.3g} kHz leaves {self.ratio:.3g}× the residual its noise explains, so "
                       "the response there is not the sensor's answer to the reference alone (a drive the reference "
                       "does not show, or dynamics beyond the model), which the pulse's weak sidelobes cannot "
                       "outweigh; the model is fitted on the stretches below it")

    def to_dict(self) -> dict[str, Any]:
        return {"top_hz": self.top_hz, "stretch_hz": list(self.stretch_hz),
                "residual_over_noise": self.ratio if math.isfinite(self.ratio) else None, "failure": self.failure,
                "by_onset": self.by_onset}


# The band is judged again without the fitted onset disturbances where its top falls below this
# share of the band fitted: the simulator's shot 60 of 200 (projectile No. 3, 1.8 bar) had its top at
# 204 kHz with the reference's glitches, 81 kHz without them (the planner's: 112 kHz), and its fit
# claimed a light pole pair at 171 kHz among bins where the response is mostly noise.
ONSET_BAND_SHARE = 0.9


def onset_band_cut(prep: Prepared, fit: OrderFit, dt: float) -> BandCut | None:
    """The band's cut where the fitted onset disturbances alone held the reference above its noise
    at its top (`ONSET_BAND_SHARE`), or None (also where the reference without them stands nowhere
    above its noise: the band as fitted then stands, as it did before this judgement)."""
    try:
        support = prep.band_without_onset(fit.inputs, dt)
    except AnalysisError:
        return None
    top = prep.band[1]
    if support is None or not support.top_hz < ONSET_BAND_SHARE * top:
        return None
    return BandCut(float(support.top_hz), (float(support.top_hz), float(top)), math.nan, by_onset=True)


def stretches_beyond_the_model(prep: Prepared, data: SpectralData, fit: OrderFit, dt: float) -> BandCut | None:
    """The band's cut (`BandCut`), or None: the stretches past the first null are kept up to the
    first whose residual per bin exceeds STRETCH_EXCESS × what its noise explains (and chance)."""
    support = prep.support
    if support is None or len(support.intervals_hz) < 2:
        return None
    omega = 2.0 * np.pi * prep.bin_hz * dt
    g = response(fit, omega)
    residual = prep.y_bins - predicted_bins(fit, data, omega, prep.u_bins, g)
    expected = prep.draw_var_y + np.abs(g) ** 2 * prep.draw_var_u
    for k, (lo, hi) in enumerate(support.intervals_hz[1:], start=1):
        inside = (prep.bin_hz >= lo) & (prep.bin_hz <= hi)
        bins = int(np.sum(inside))
        if bins == 0:
            continue
        ratio = float(np.mean(np.abs(residual[inside]) ** 2 / expected[inside]))
        chance = f_quantile(STRETCH_CHANCE, 2 * bins, 1e6)
        if ratio > max(STRETCH_EXCESS, chance):
            return BandCut(float(support.intervals_hz[k - 1][1]), (float(lo), float(hi)), ratio)
    return None


def fit_percent(measured: np.ndarray, simulated: np.ndarray) -> float:
    """100·(1 − ‖y − ŷ‖/‖y − ȳ‖): 100 is a perfect fit, 0 no better than the mean; NaN for a constant y."""
    y = np.asarray(measured, dtype=float)
    centred, error = y - np.mean(y), y - np.asarray(simulated, dtype=float)
    spread = math.sqrt(long_dot(centred, centred))
    return 100.0 * (1.0 - math.sqrt(long_dot(error, error)) / spread) if spread > 0 else float("nan")
