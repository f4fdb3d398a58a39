"""Identify the accelerometer's discrete model A(d⁻¹)·y(k) = B(d⁻¹)·u(k − τ) from a shock record.

`identify(record, options)` runs the stages in turn, each a function with a typed input and a
frozen result, and returns an `Identification` that holds them:

    record_preparation.prepare_record → identify_stages.search_orders → weigh_model_error
    → settle → claim

The reference is in m/s², the response in any unit; the model's gain is in response units per
m/s², its delay τ in samples at the analysis rate. `identify_with_sine` fits one model to the
record and a sinusoidal calibration together (analysis.sine_joint). Why the method is what it
is: docs/decisions/0010 (errors-in-variables fit in the frequency domain), 0011 (the order
test), 0012 (motion after the pulse is not noise), 0013 (model error); docs/method.md.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING, Any

import numpy as np

from hopkinson.analysis.errors import AnalysisError
from hopkinson.analysis.evidence import DelayBranch, LeadIn, NoiseReport, OrderEvidence
from hopkinson.analysis.excitation import SupportedBand
from hopkinson.analysis.findings import Finding, texts
from hopkinson.analysis.identify_stages import (
    BandCut,
    Claim,
    OrderSearch,
    Settlement,
    WeighedSearch,
    claim,
    onset_band_cut,
    search_orders,
    settle,
    weigh_model_error,
)
from hopkinson.analysis.identify_stages import fit_percent as fit_percent
from hopkinson.analysis.input_terms import term_summary
from hopkinson.analysis.jsonable import jsonable
from hopkinson.analysis.loss import arx_loss_by_order
from hopkinson.analysis.model import DiscreteModel, complex_pairs
from hopkinson.analysis.model_error import ModelError
from hopkinson.analysis.modes import Mode, main_mode, resonance_above_hz
from hopkinson.analysis.options import AnalysisOptions
from hopkinson.analysis.order_choice import OrderStability
from hopkinson.analysis.preprocessing import Preprocessing
from hopkinson.analysis.record_preparation import Prepared, PreparedRecord, prepare_record
from hopkinson.analysis.records import Record
from hopkinson.analysis.spectral_data import SineTerms
from hopkinson.analysis.trail import (
    NoiseLevels,
    Trail,
    order_criterion,
    stage_trail,
    stretches_after_pulse,
)

if TYPE_CHECKING:
    from hopkinson.analysis.sine_comparison import SineCalibration

# The relative tolerance of the old knee rule: no longer applied, still written to the model JSON
# (docs/files-and-formats.md) for the readers of that format.
KNEE_TOLERANCE = 0.01


@dataclass(frozen=True)
class Identification:
    """The identified model and the stage results that chose it (analysis.identify_stages).
    Frozen: a later result (the uncertainty's order stability, the sine's consistency) gives a
    new one (`with_order_stability`, `dataclasses.replace`).

    Losses are the errors-in-variables output-error cost V (dimensionless: each fitted DFT bin
    adds its error over its noise; ≈ the number of bins for the right model); index 0 of every
    *_by_order list is order 1; NaN where an order was not evaluated.
    """

    prepared: PreparedRecord
    search: OrderSearch
    weighed: WeighedSearch
    settlement: Settlement
    claim: Claim
    findings: tuple[Finding, ...]  # what the stages found, in the order they ran
    loss_by_order: list[float]  # V_n (the order choice uses it)
    arx_loss_by_order: list[float]  # plain least-squares ||g2||², one factorisation (normalised units)
    aic_by_order: list[float]  # on V
    bic_by_order: list[float]
    trail: Trail  # what decided it, stage by stage (`hopkinson identify --explain`)
    preprocessing: Preprocessing  # how the record was prepared
    noise: NoiseReport  # the channels' noise levels (channel units), the residual, the model error
    order_evidence: OrderEvidence  # why this order
    input_terms: dict[str, Any] = field(default_factory=dict)  # what the input terms found (input_terms.term_summary)
    sine_joint: Any = None  # analysis.sine_joint.SineJoint when fitted with a sine calibration

    @property
    def model(self) -> DiscreteModel:
        return self.claim.model

    @property
    def prep(self) -> Prepared:
        """The prepared record with the input terms the model was fitted with."""
        return self.weighed.prep

    @property
    def order(self) -> int:
        return self.settlement.order

    @property
    def modes(self) -> list[Mode]:
        """Per pole pair / real pole (analysis.modes)."""
        return self.claim.modes

    @property
    def fit_percent(self) -> float:
        """100·(1 − ||y − ŷ|| / ||y − ȳ||) of the final model over the fitted window."""
        return self.claim.fit_percent

    @property
    def delay_samples(self) -> float:
        """The model's input delay τ (samples at the analysis rate; negative: the response led)."""
        return self.model.delay_samples

    @property
    def converged(self) -> bool:
        return self.settlement.final.converged

    @property
    def iterations(self) -> int:
        return self.settlement.final.evaluations

    @property
    def order_selection(self) -> str:
        """"order_test" (chosen by the order test) or "asked" (files before: "knee")."""
        return self.settlement.settled.selection

    @property
    def supported_band_hz(self) -> tuple[float, float]:
        """The band the excitation supports: (low, top), Hz, nulls included."""
        return self.prep.band

    @property
    def supported_band(self) -> SupportedBand | None:
        """Its stretches (the pulse's nulls between them are not fitted)."""
        return self.prep.support

    @property
    def sample_interval_s(self) -> float:
        return self.model.sample_interval_s

    @property
    def warnings(self) -> list[str]:
        """The findings' texts (the results' `warnings`)."""
        return texts(self.findings)

    @property
    def poles(self) -> np.ndarray:
        return self.model.poles

    @property
    def zeros(self) -> np.ndarray:
        return self.model.zeros

    @property
    def main_mode(self) -> Mode | None:
        """The lowest supported complex pole pair (the sensor's main resonance), or None."""
        return main_mode(self.modes)

    @property
    def resonance_above_hz(self) -> float | None:
        """With no mode inside the supported band but one beyond it: the band's top, a lower bound
        of the resonance (it lies in a null of the excitation); else None."""
        return resonance_above_hz(self.modes, self.supported_band_hz)

    def supported_poles(self) -> np.ndarray:
        """The poles of the supported modes (both poles of a pair): what a DCM may cancel."""
        keep = [m.pole_z for m in self.modes if m.supported]
        poles = [p for q in keep for p in ((q, q.conjugate()) if q.imag > 0 else (q,))]
        return np.array(poles, dtype=complex)

    def with_order_stability(self, draws: int, fraction_by_order: dict[str, float]) -> Identification:
        """This identification with the order choice's stability measured on `draws` noise draws
        (`fraction_by_order`: order -> share of the draws that chose it); unchanged where the
        settle stage measured it already."""
        evidence = self.order_evidence.with_stability(OrderStability(draws, dict(fraction_by_order)))
        return self if evidence is self.order_evidence else replace(self, order_evidence=evidence)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready fields: the model JSON (docs/files-and-formats.md) plus the fit details; inf/NaN → None."""
        out = self.model.to_dict()
        out.update(
            {
                "loss_by_order": jsonable(self.loss_by_order),
                "arx_loss_by_order": jsonable(self.arx_loss_by_order),
                "aic_by_order": jsonable(self.aic_by_order),
                "bic_by_order": jsonable(self.bic_by_order),
                "order_selection": self.order_selection,
                "knee_tolerance": KNEE_TOLERANCE,
                "fit_percent": jsonable(self.fit_percent),
                "modes": [m.to_dict() for m in self.modes],
                "converged": self.converged,
                "iterations": self.iterations,
                "warnings": self.warnings,
                "preprocessing": self.preprocessing.to_dict(),
                "main_mode": self.main_mode.to_dict() if self.main_mode is not None else None,
                "supported_band_hz": list(self.supported_band_hz) if self.supported_band_hz else None,
                "supported_band": self.supported_band.to_dict() if self.supported_band else None,
                "nonminimum_phase_zeros": complex_pairs(self.model.nonminimum_phase_zeros),
                "resonance_above_hz": self.resonance_above_hz,
                "noise": self.noise.to_dict(),
                "order_evidence": jsonable(self.order_evidence.to_dict()),
                "input_terms": jsonable(self.input_terms),
            }
        )
        if self.sine_joint is not None:
            out["sine_joint"] = jsonable(self.sine_joint.to_dict())
        return out


# ------------------------------------------------------------------------------ identify
def identify(record: Record, options: AnalysisOptions | None = None, *, sine_terms: SineTerms | None = None,
             **changes: Any) -> Identification:
    """Identify a discrete model of the accelerometer from a two-channel record (reference m/s²,
    response in any unit).

    options: the analysis options (analysis.options.AnalysisOptions); `changes` replace its
    fields (``identify(record, order=4)``).
    sine_terms: the sine points as analysis.sine_joint weighed them (its own passes; internal).
    Returns the Identification, which holds each stage's result.
    """
    options = replace(options or AnalysisOptions(), **changes)
    if options.max_order < 1:
        raise AnalysisError(f"max_order must be at least 1, got {options.max_order}")
    if options.order is not None and options.order < 1:
        raise AnalysisError(f"order must be at least 1, got {options.order}")
    try:
        result = _identify(record, options, sine_terms)
    except _BeyondTheFirstNull as failed:  # no model past the first null: fitted below it
        result = _cut(record, options, sine_terms, BandCut(failed.top_hz, failed.stretch_hz, math.inf,
                                                          str(failed.cause)))
    else:
        if result.claim.band_cut is not None:
            result = _cut(record, options, sine_terms, result.claim.band_cut)
    onset_cut = onset_band_cut(result.prep, result.settlement.final, result.sample_interval_s)
    if onset_cut is None:
        return result
    try:
        return _cut(record, options, sine_terms, onset_cut)
    except AnalysisError:  # no model below that top: the band as the record's reference has it
        return result


def _cut(record: Record, options: AnalysisOptions, sine_terms: SineTerms | None, cut: BandCut) -> Identification:
    """The stages again on the band below the `cut`'s top, its finding first."""
    again = _identify(record, options, sine_terms, band_top_hz=cut.top_hz)
    return replace(again, findings=(cut.finding, *again.findings),
                   preprocessing=replace(again.preprocessing, band_cut=cut))


def _identify(record: Record, options: AnalysisOptions, sine_terms: SineTerms | None,
              band_top_hz: float | None = None) -> Identification:
    """The stages once, on the band the excitation supports (capped at `band_top_hz`)."""
    prepared = prepare_record(record, options.sample_rate_hz, options.n_max, options.order,
                              options.max_delay_samples, realign=options.remove_delay, band_top_hz=band_top_hz)
    try:
        search = search_orders(prepared, options, sine_terms)
        weighed = weigh_model_error(prepared, search, sine_terms)
        settlement = settle(prepared, search, weighed, options)
        claimed = claim(prepared, weighed, settlement, options, cut_band=band_top_hz is None)
    except AnalysisError as exc:
        support = prepared.prep.support
        stretches = support.intervals_hz if support is not None else ()
        if band_top_hz is not None or len(stretches) < 2:
            raise
        raise _BeyondTheFirstNull(exc, float(stretches[0][1]), stretches[1]) from exc
    return _identification(prepared, search, weighed, settlement, claimed)


def identify_with_sine(record: Record, sine: SineCalibration, options: AnalysisOptions | None = None,
                       **changes: Any) -> Identification:
    """One model fitted to the record and a sinusoidal calibration of the same sensor, each
    weighed by its own uncertainty (analysis.sine_joint); their consistency in `sine_joint`."""
    from hopkinson.analysis.sine_joint import identify_joint

    return identify_joint(record, sine, replace(options or AnalysisOptions(), **changes))


class _BeyondTheFirstNull(AnalysisError):
    """No model fits the band across the pulse's nulls (identify fits below the first one)."""

    def __init__(self, cause: AnalysisError, top_hz: float, stretch_hz: tuple[float, float]) -> None:
        super().__init__(str(cause))
        self.cause, self.top_hz, self.stretch_hz = cause, top_hz, stretch_hz


def _identification(prepared: PreparedRecord, search: OrderSearch, weighed: WeighedSearch, settlement: Settlement,
                    claimed: Claim) -> Identification:
    """The Identification: the stage results and the report made of them (losses by order, the
    noise and where it was measured, the order's evidence, the input terms)."""
    prep, setup, data = weighed.prep, settlement.setup, settlement.data
    sweep, final, n_max = settlement.sweep, settlement.final, setup.n_max
    pre = replace(prepared.preprocessing, response_offset_fitted=float(np.mean(claimed.residual) * prepared.scale_y))
    loss_list = [sweep.fits[n].cost if n in sweep.fits else math.nan for n in range(1, n_max + 1)]
    aic, bic = _information_criteria(loss_list, [sweep.parameters.get(n, 0) for n in range(1, n_max + 1)], data.bins)
    arx_u, arx_y = remove_input_delay(prepared.u_all, prepared.y_all, int(math.floor(final.delay)))
    try:
        arx_losses = [float(v) for v in arx_loss_by_order(arx_u, arx_y, n_max)]
    except AnalysisError:
        arx_losses = [math.nan] * n_max
    info = {"loss_by_order": loss_list, "fit_percent": claimed.fit_percent, "converged": final.converged}
    claimed = replace(claimed, model=replace(claimed.model, info={**claimed.model.info, **info}))
    evidence = OrderEvidence(
        comparisons=sweep.comparisons,
        structure=sweep.structure,
        structure_reason=sweep.why,
        criterion=order_criterion(setup.significance),
        chosen=sweep.chosen,
        selection=settlement.settled.selection,
        bins=data.bins,
        parameters_by_order={n: sweep.parameters[n] for n in sorted(sweep.parameters)},
        cost_by_order={n: sweep.fits[n].cost for n in sorted(sweep.fits)},
        response_change_to_next_order={n: sweep.changes[(n, n + 1)] for n in sorted(sweep.fits)
                                       if (n, n + 1) in sweep.changes},
        settled_stability=settlement.stability,
        unstable_when_converged=tuple(settlement.settled.unstable_when_converged),
        delay_branches=tuple(DelayBranch(f.delay - prepared.realigned_samples, f.cost)
                             for f in [final, *settlement.others]) if settlement.others else (),
    )
    findings = (*prepared.findings, *search.findings, *settlement.findings, *claimed.findings)
    levels = NoiseLevels.of(prepared, claimed.response_noise)
    trail = stage_trail(prepared, settlement, claimed, levels,
                        resonance_above_hz(claimed.modes, prep.band))
    return Identification(
        prepared, search, weighed, settlement, claimed, findings, loss_by_order=loss_list,
        arx_loss_by_order=arx_losses, aic_by_order=aic, bic_by_order=bic, trail=trail, preprocessing=pre,
        noise=_noise_report(prepared, levels, claimed, settlement.model_error),
        order_evidence=evidence, input_terms=term_summary(prep.terms, final.inputs, prepared.scale_u),
    )


def _noise_report(prepared: PreparedRecord, levels: NoiseLevels, claimed: Claim, model_error: ModelError
                  ) -> NoiseReport:
    """The noise levels (channel units) and where they were measured, the residual, the model
    error and the motion left out of the noise."""
    prep, rec = prepared.prep, prepared.record
    dt = rec.sample_interval_s
    lead_in = LeadIn(rec.start_time_s, rec.start_time_s + prep.activity.lead_in * dt,
                     prep.activity.lead_in_to_foot) if prep.activity.lead_in else None
    return NoiseReport(levels, float(np.std(claimed.residual) * prepared.scale_y), claimed.v_per_dof, model_error,
                       lead_in, tuple(stretches_after_pulse(prepared)))


# ------------------------------------------------------------------------------ helpers
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


def remove_input_delay(ref: np.ndarray, resp: np.ndarray, d: int) -> tuple[np.ndarray, np.ndarray]:
    """(u, y) with y(k) = response(k + d) against u(k) = reference(k): removes a delay of d samples."""
    if d >= 0:
        return ref[: ref.size - d], resp[d:]
    return ref[-d:], resp[: resp.size + d]
