"""Whether a record's onset disturbances are fitted (analysis.input_terms: the onset's bumps), a
stage of analysis.identify's step 5.

- `onset_fitted`: the bumps where the record with them is explained better than by any order
  without them that it supports (free terms across the onset can take up a misfit of the
  sensor's dynamics, and extra poles a disturbance at the onset), and their correction stands
  well above the reference's noise.
- `onset_beyond_the_model_error`: the bumps dropped where, weighed with the model error, they
  no longer lower the cost beyond chance.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from hopkinson.analysis.frequency_fit import OrderFit, OrderProblem
from hopkinson.analysis.input_terms import ONSET
from hopkinson.analysis.numerics import f_quantile
from hopkinson.analysis.order_choice import choose_order
from hopkinson.analysis.order_search import (
    POLISH_EVALUATIONS,
    OrderSweep,
    SearchSetup,
    cost_test_fit,
    fit_orders,
)
from hopkinson.analysis.record_preparation import Prepared
from hopkinson.analysis.spectral_data import SpectralData
from hopkinson.analysis.structure import DelayMode, Structure

# The onset's bumps are kept only where the correction they make stands this many times above the
# reference's noise RMS (on a record whose residual is mostly model error, a few free bumps always
# lower the cost: PTB's record with 1 % more noise took bumps of 7× the noise, fitted noise, not a
# disturbance; the simulated bar's glitches and transverse kick stand 100–1000× above it).
ONSET_ABOVE_NOISE = 10.0
# Weighed with the model error, the bumps stay where they still lower the cost beyond chance at this
# level (an F test on V for their K parameters: `onset_beyond_the_model_error`).
ONSET_SIGNIFICANCE = 1e-3


def onset_fitted(prep: Prepared, plain: SpectralData, plain_sweep: OrderSweep, setup: SearchSetup
                 ) -> tuple[Prepared, tuple[SpectralData, OrderSweep] | None]:
    """The prepared record with the onset's bumps (analysis.input_terms) where the record calls
    for them (its `terms` and `spectral` take them on), and the data with them and every order
    fitted with them; else the prepared record with the reason in its terms, and None.

    Two accounts of the record are compared, each at its optimum and each with the order its own
    order test gives: with the bumps, the order test's choice; without them, the richest order the
    record supports (order_search.cost_test_fit: the order test on the cost alone, for the
    dynamics that a change of the response below 0.1 % does not call for can still explain what the
    bumps would take up). As between the two structures (order_search._all_pole_preferred), the
    account with fewer parameters stands unless the other beats it beyond chance (an F test on V,
    Bonferroni-corrected over the bins); of two with as many, the lower cost. Judged at one order
    instead, either explanation took the other's place: at the order test's choice without them,
    five bumps took up the misfit of order 2 against a clean 27 kHz sensor behind a 100 kHz amplifier
    low-pass (V 40 with them; order 3 alone: V 38), its FBSD ±5 % 1.2 % low inside ±0.03 %; on the
    simulated bar, a glitch at the onset drove the order without them to 11, whose poles then took
    it up (bumps F = 2 at that order) and claimed modes the sensor lacks. The bumps' correction
    must also stand ONSET_ABOVE_NOISE × above the reference's noise."""
    onset = prep.onset_terms
    if onset is None or plain_sweep.chosen is None:
        return prep, None
    trial = replace(prep.with_terms(onset), var_y=plain.var_y, sine=plain.sine)
    sweep = fit_orders(trial, Structure.FREE, setup)
    why = "no model with them is stable"
    if sweep.chosen is not None:
        chosen = sweep.fits[sweep.chosen]  # at its optimum (a copy: the sweep goes on as the search left it)
        bumped = OrderProblem.for_fit(trial, chosen, sweep.delay_mode, setup.max_delay).solve(chosen, POLISH_EVALUATIONS,
                                                                                                1e-9)
        bumps = np.zeros(onset.count)
        if bumped.inputs.size == onset.count:
            bumps[onset.columns(ONSET)] = bumped.inputs[onset.columns(ONSET)]
        size = float(np.max(np.abs(onset.correction(bumps))))
        noise = prep.noise.draw_noise_u.rms if prep.noise.draw_noise_u.samples else 0.0
        # the richest order without them is fitted only where the bumps stand above the noise
        richest = cost_test_fit(plain_sweep, plain, setup) if size > ONSET_ABOVE_NOISE * noise else None
        if richest is None:
            why = f"the correction, {size / max(noise, 1e-300):.2g}× the reference's noise, does not stand above it"
        elif _stands(bumped, richest, plain.bins, setup.significance):
            spectral = replace(prep.spectral, inputs=trial.inputs, input_prior=trial.input_prior)
            return replace(prep, terms=onset, spectral=spectral), (trial, sweep)
        else:
            why = (f"order {richest.order} without them explains the record (V {richest.cost:.4g}, "
                   f"{richest.parameters} parameters) as well as order {bumped.order} with them (V "
                   f"{bumped.cost:.4g}, {bumped.parameters})")
    terms = replace(prep.terms, not_fitted={**prep.terms.not_fitted,
                                            ONSET: f"the onset's disturbances do not show ({why})"})
    return replace(prep, terms=terms), None


def _stands(fit: OrderFit, other: OrderFit, bins: int, significance: float) -> bool:
    """Whether `fit` stands against `other` (`onset_fitted`'s comparison of two accounts)."""
    if fit.parameters == other.parameters:
        return fit.cost <= other.cost
    fits = sorted([fit, other], key=lambda f: f.parameters)
    chosen, _ = choose_order({0: fits[0].cost, 1: fits[1].cost}, {0: fits[0].parameters, 1: fits[1].parameters},
                             bins, {}, significance)
    return fits[chosen if chosen is not None else 0] is fit


def onset_beyond_the_model_error(prep: Prepared, data: SpectralData, fit: OrderFit, delay_mode: DelayMode | float,
                                 setup: SearchSetup) -> tuple[Prepared, SpectralData]:
    """The prepared record and the data weighed with the model error, without the onset's terms
    where, so weighed, they no longer lower the cost beyond chance: the F test that kept them read a residual that was
    mostly model error, which a few free bumps always lower (PTB's record with 1 % more noise: bumps
    of 2 % of its peak, and its FBSD ±5 % interval half as wide again)."""
    cols = prep.terms.columns(ONSET)
    if not cols.size or fit.inputs.size != prep.terms.count:
        return prep, data
    with_bumps = OrderProblem.for_fit(data, fit, delay_mode, setup.max_delay).solve(replace(fit, cost=math.nan), 200,
                                                                                   1e-9)
    kept = prep.terms.without(ONSET, "")
    without = replace(prep.with_terms(kept), var_y=data.var_y, sine=data.sine)
    start = replace(with_bumps, inputs=np.delete(with_bumps.inputs, cols), cost=math.nan)
    plain = OrderProblem.for_fit(without, start, delay_mode, setup.max_delay).solve(start, 200, 1e-9)
    problem = OrderProblem.for_fit(data, with_bumps, delay_mode, setup.max_delay)
    dof = problem.residual_size() - problem.size
    statistic = ((plain.cost - with_bumps.cost) / cols.size) / (with_bumps.cost / dof) if dof > 0 else math.inf
    if statistic > f_quantile(1.0 - ONSET_SIGNIFICANCE, cols.size, max(dof, 1)):
        return prep, data
    terms = replace(kept, not_fitted={**prep.terms.not_fitted, ONSET: (
        f"the onset's disturbances do not show beyond the model error (F = {statistic:.2g} for {cols.size} terms)")})
    return replace(prep, terms=terms, spectral=replace(prep.with_terms(kept), var_y=prep.spectral.var_y)), without
