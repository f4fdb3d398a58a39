"""The order search of analysis.identify_stages (search_orders, weigh_model_error, settle):
every order fitted and one chosen (docs/decisions/0011).

- `search_setup`: the delay's start and the orders the band's bins allow.
- `fit_orders`: each order n = 1 … n_max of one model structure fitted on the prepared bins
  (analysis.frequency_fit), each started from the order below and from a linear start, and the
  order test's choice (analysis.order_choice) → an `OrderSweep`.
- `fit_structures`: the free structure's sweep, or the all-pole structure's where the free
  choice holds a pole–zero doublet or is unstable (a resonance beyond the band).
- `settle_order`: the choice iterated to convergence and checked stable (falling back to a
  stable order, or to the all-pole structure), or the asked order checked.
- `best_delay_branch`: the lowest optimum of the chosen order's delay–zeros valley.
- `order_stability_evidence`: how often fresh noise of the record's level re-chooses the order.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from hopkinson.analysis.errors import AnalysisError
from hopkinson.analysis.findings import Finding, FindingCode
from hopkinson.analysis.frequency_fit import OrderFit, OrderProblem, predicted_bins
from hopkinson.analysis.model import all_pole_numerator
from hopkinson.analysis.modes import ModeKind, has_doublet, modes_of
from hopkinson.analysis.order_choice import (
    ORDER_STABILITY_WARNING,
    NoiseDraws,
    OrderStability,
    Refitter,
    candidates_around,
    choose_order,
    choose_stable_order,
    fractions_text,
    order_stability,
    pole_below_band,
    response_change,
)
from hopkinson.analysis.quick_refit import delay_branches
from hopkinson.analysis.record_preparation import Alignment, Prepared
from hopkinson.analysis.resample import estimate_delay_samples
from hopkinson.analysis.spectral_data import SpectralData
from hopkinson.analysis.structure import DelayMode, Structure

# A final model with a pole this close to the unit circle sits on the stability boundary.
MARGINAL_POLE = 1e-6
# Levenberg–Marquardt evaluations that polish the chosen order to tight convergence (a band across
# the pulse's nulls holds more bins, and the delay–zeros valley is then flatter: 200 stopped short)
POLISH_EVALUATIONS = 400
# A fit whose linear start was unstable and that leaves this many times the residual the noise
# explains is taken as the data calling for an unstable model.
UNSTABLE_MODEL_ERROR = 100.0
# identify(stability_draws=…): noise draws that re-run the order choice to measure its
# stability, from a fixed seed (the same record always gives the same evidence); the
# uncertainty's Monte Carlo measures it anyway, so identify alone does not by default
# (order_choice.ORDER_STABILITY_WARNING: the share below which the choice is reported unstable).
STABILITY_SEED = 16_063


@dataclass(frozen=True)
class SearchSetup:
    """What every order's fit shares: the orders tried, the delay's start and bounds, the
    search's budget and the order test's level."""

    n_max: int  # the largest order tried
    asked_order: int | None  # an order asked for (None: the order test chooses)
    tau0: float  # the delay's start (samples)
    remove_delay: bool  # False: the delay is held at 0
    max_delay: int
    patience: int | None  # stop once this many orders past the current choice gave no gain
    max_evaluations: int
    significance: float
    lowest_bin_hz: float
    sample_interval_s: float
    band_hz: tuple[float, float]  # the band the excitation supports
    alignment: Alignment = field(default_factory=Alignment)  # what record_preparation.realigned did
    findings: tuple[Finding, ...] = ()  # the orders capped by the band's bins

    def delay_mode(self, structure: Structure) -> DelayMode | float:
        """The free structure keeps its delay causal (its zeros can take up a lead: the lead
        warning); the all-pole structure has no zeros to do so, and the reference chain's own
        delay (an interferometer's demodulation and low-pass, 0.2–0.9 µs; PTB's record leads by
        ~0.35 µs) would bias its poles (on PTB's record 45 kHz against 50.5 kHz free): its delay
        takes either sign."""
        if not self.remove_delay:
            return 0.0
        return DelayMode.FREE if structure == Structure.ALL_POLE else DelayMode.CAUSAL


def search_setup(data: SpectralData, prep: Prepared, n_max: int, order: int | None, dt: float, *,
                 remove_delay: bool, max_delay: int, patience: int | None, max_evaluations: int,
                 significance: float, alignment: Alignment | None = None) -> SearchSetup:
    """The delay's start (the causal delay that best fits a second-order model, on a coarse grid)
    and the orders the band allows: each order needs more real residuals (two per bin) than
    parameters (2n + 2, and n more with a transient term)."""
    max_delay = max(1, int(max_delay))
    tau0 = _initial_delay(data, prep, min(2, n_max), max_delay) if remove_delay else 0.0
    per_order = 3 if data.transient else 2
    allowed = (2 * data.bins - 4 - data.input_count) // per_order
    if allowed < 1 or (order is not None and order > allowed):
        raise AnalysisError(
            f"the supported band holds only {data.bins} frequency bins: too few for "
            f"{'order ' + str(order) if order is not None else 'any model'} (a longer record or a shorter pulse)"
        )
    findings: tuple[Finding, ...] = ()
    if n_max > allowed:
        findings = (Finding(FindingCode.ORDERS_CAPPED, f"orders above {allowed} were not tried: the supported band "
                                                       f"holds only {data.bins} frequency bins"),)
        n_max = allowed
    return SearchSetup(n_max, order, tau0, remove_delay, max_delay, patience, max_evaluations, significance,
                       float(prep.bin_hz[0]), dt, prep.band, alignment or Alignment(), findings)


@dataclass(frozen=True)
class OrderSweep:
    """Every order of one structure fitted, and the order test's choice among them (frozen; its
    `polished` fits are kept in `fits`)."""

    structure: Structure
    delay_mode: DelayMode | float
    fits: dict[int, OrderFit]  # by order
    parameters: dict[int, int]
    costs: dict[int, float]  # V of each candidate order (inf: no candidate: unstable, or a pole below the band)
    changes: dict[tuple[int, int], float]  # the response's change from order n to m where the pulse has energy
    chosen: int | None  # the order test's choice (None: no candidate)
    comparisons: Any  # the order test's evidence (analysis.order_choice)
    _polished: set[int] = field(default_factory=set, repr=False)
    why: str = ""  # why this structure was chosen over the other (empty: the free one, by default)

    def polished(self, n: int, data: SpectralData, setup: SearchSetup) -> OrderFit:
        """The order-n fit iterated to tight convergence (the search gave each order a short budget
        and a loose tolerance): the optimum, whatever path led to it, so rescaled channels give
        the same model to ~1e-9. A delay pressed against zero converges slowly in its bounded
        parameter: there the fit with the delay held at zero is taken when it is as good. Kept:
        the sweep's fit of order n is replaced by it."""
        if n not in self._polished:
            fit = self.fits[n]
            done = OrderProblem.for_fit(data, fit, self.delay_mode, setup.max_delay).solve(fit, POLISH_EVALUATIONS, 1e-11)
            if self.delay_mode == DelayMode.CAUSAL and done.delay < 1e-2 and not done.converged:
                at_zero = OrderProblem.for_fit(data, fit, 0.0, setup.max_delay).solve(done, POLISH_EVALUATIONS, 1e-11)
                if at_zero.cost <= done.cost * (1 + 1e-9):
                    done = at_zero
            self.fits[n] = replace(done, start_unstable=fit.start_unstable)
            self._polished.add(n)
        return self.fits[n]

    def acceptable(self, n: int, data: SpectralData, setup: SearchSetup) -> bool:
        """Whether order n, polished, is an acceptable final model (`acceptable`)."""
        return acceptable(self.polished(n, data, setup), data.bins)


def fit_orders(data: SpectralData, structure: Structure, setup: SearchSetup) -> OrderSweep:
    """Every order n = 1 … n_max of `structure` fitted on `data` (from 2 for the all-pole
    structure: it stands for a resonance beyond the band, and its order 1, a real pole, is a
    low-pass that cannot rise towards one), and the order test's choice. Each order starts from
    a linear start at the order below's delay (and at the first delay, when they differ) and
    from the order below embedded, and keeps the best optimum; an order none of whose starts
    converged within the budget is started once more at the best delay of a grid of linear
    starts (`delay_grid_starts`: the delay and the poles trade phase, so the order below's delay
    can hold it in a slow valley; a known 27 kHz sensor behind a 40 kHz amplifier low-pass: order
    4 started at order 3's 6.9 samples stopped at V 891, from 1.6 samples it settles at 165, and
    order 5 had been chosen for it). With `patience`, the sweep stops once that many orders past
    the current choice gave no gain."""
    fits: dict[int, OrderFit] = {}
    parameters: dict[int, int] = {}
    costs: dict[int, float] = {}
    tau, tau0 = setup.tau0, setup.tau0
    delay_mode = setup.delay_mode(structure)
    previous: OrderFit | None = None
    for n in range(2 if structure == Structure.ALL_POLE else 1, setup.n_max + 1):
        shape = all_pole_numerator(n) if structure == Structure.ALL_POLE else None
        problem = OrderProblem(data, n, delay_mode, setup.max_delay, numerator=shape)
        held = previous.inputs if previous is not None else None  # the input terms as the order below found them
        starts = [problem.linear_start(tau, inputs=held)]
        if abs(tau - tau0) > 0.5:
            starts.append(problem.linear_start(tau0, inputs=held))
        if previous is not None:
            starts.append(previous.embedded())
        best = None
        for start in starts:
            fitted = replace(problem.solve(start, setup.max_evaluations, 1e-6), start_unstable=starts[0].start_unstable)
            if best is None or fitted.cost < best.cost:
                best = fitted
        assert best is not None
        if not best.converged and setup.remove_delay:  # stopped on its way down a valley: try the grid's best delay
            top = min(float(setup.max_delay), math.ceil(max(tau, tau0)) + 1.0)
            for start in delay_grid_starts(problem, top, 1):
                fitted = problem.solve(start, setup.max_evaluations, 1e-6)
                if fitted.cost < best.cost:
                    best = replace(fitted, start_unstable=starts[0].start_unstable)
        fits[n], parameters[n] = best, problem.size
        costs[n] = _candidate_cost(best, data, setup)
        previous, tau = best, best.delay
        if setup.patience is not None:
            chosen_so_far, _ = choose_order(costs, parameters, data.bins, response_change(fits, data),
                                            setup.significance)
            if chosen_so_far is not None and n >= max(chosen_so_far + setup.patience, setup.asked_order or 0):
                break
    changes = response_change(fits, data)
    chosen, comparisons = choose_order(costs, parameters, data.bins, changes, setup.significance)
    return OrderSweep(structure, delay_mode, fits, parameters, costs, changes, chosen, comparisons)


def cost_test_fit(sweep: OrderSweep, data: SpectralData, setup: SearchSetup) -> OrderFit | None:
    """The fit of the order the cost alone calls for: the order test on the V of the choice and
    every higher order fitted, each iterated to convergence (a copy: the sweep is left as it is),
    without the test's second condition (a change of the response where the pulse has energy).
    What the richest model the record supports leaves unexplained is what no dynamics explains:
    the yardstick for input terms (onset_choice.onset_or_dynamics). The order test's choice can leave a
    misfit small in the response but far beyond the noise (a discrete order 2 of a 27 kHz sensor
    behind a 100 kHz amplifier low-pass: V 619 against order 3's 38, a 0.1 % change of the
    response), which free terms at the onset then take up as a disturbance. None without a choice."""
    if sweep.chosen is None:
        return None
    fits = dict(sweep.fits)
    costs = dict(sweep.costs)
    for n in (n for n in sweep.fits if n >= sweep.chosen):
        fit = sweep.fits[n]
        done = OrderProblem.for_fit(data, fit, sweep.delay_mode, setup.max_delay).solve(fit, POLISH_EVALUATIONS, 1e-9)
        fits[n] = replace(done, start_unstable=fit.start_unstable)
        costs[n] = _candidate_cost(fits[n], data, setup)
    richest, _ = choose_order({n: v for n, v in costs.items() if n >= sweep.chosen}, sweep.parameters, data.bins, {},
                              setup.significance)
    return fits[richest if richest is not None else sweep.chosen]


def _candidate_cost(fit: OrderFit, data: SpectralData, setup: SearchSetup) -> float:
    """V of an order that is a candidate for the order test, else inf: an unstable or marginal
    order is none, nor one with a real pole far below the lowest fitted bin (the data cannot
    place it; docs/decisions/0011)."""
    candidate = acceptable(fit, data.bins) and not pole_below_band(fit, setup.lowest_bin_hz, setup.sample_interval_s)
    return fit.cost if candidate else math.inf


def fit_structures(data: SpectralData, setup: SearchSetup) -> OrderSweep:
    """Both structures' sweeps and the one chosen, its reason in `why` (empty: free). The
    all-pole structure (model.all_pole_numerator: no zero can follow a ripple) where the
    free choice is unstable or holds a pole–zero doublet (the fit following a ripple of the data:
    its one dynamic feature in the band is a smooth rise, a resonance beyond it, as on PTB's
    record), or claims no mode in the band while every higher order of it is unstable (the rise
    towards a resonance beyond the band, which free zeros follow only by pressing a pole onto the
    unit circle: PTB's record with 0.5 % more noise); otherwise the order test between the two
    choices decides (`_all_pole_preferred`). Where the free choice is sound (stable, no doublet),
    an all-pole choice that is unstable once converged is not taken (a growing oscillation's
    record: free order 1 claimed no mode in the band, every higher order unstable, and the
    all-pole order 2 settled on the unit circle). An asked order keeps the free structure, as
    does an all-pole sweep with no stable order."""
    free = fit_orders(data, Structure.FREE, setup)
    if setup.asked_order is not None:
        return free
    all_pole = fit_orders(data, Structure.ALL_POLE, setup)
    if all_pole.chosen is None:
        return free
    why = ""
    if free.chosen is None:
        why = "no model with free zeros is stable"
    elif has_doublet(free.fits[free.chosen].a, free.fits[free.chosen].b):
        why = "the model with free zeros followed a ripple with a pole–zero doublet"
    elif not all_pole.acceptable(all_pole.chosen, data, setup):
        pass  # the free choice is sound and the all-pole one unstable once converged: nothing to prefer
    elif _exhausted_without_mode(free, setup):
        why = "the model with free zeros claims no mode in the band and every higher order of it is unstable"
    elif _all_pole_preferred(free, all_pole, data, setup):
        why = (f"it fits as well as free zeros do, or better (V {all_pole.costs[all_pole.chosen]:.4g} with "
               f"{all_pole.parameters[all_pole.chosen]} parameters against {free.costs[free.chosen]:.4g} "
               f"with {free.parameters[free.chosen]}: the order test between the two)")
    return replace(all_pole, why=why) if why else free


def _all_pole_preferred(free: OrderSweep, all_pole: OrderSweep, data: SpectralData, setup: SearchSetup) -> bool:
    """The order test between the two structures' choices: the one with fewer parameters stands
    unless the other beats it beyond chance and in the response (order_choice.choose_order). A
    free choice of fewer parameters that the all-pole model beats is a low order that could not
    follow the rise (PTB's record with 0.2 % more noise: free order 1, V 95.5, against all-pole
    order 2, V 30.1); an all-pole model of fewer parameters that free zeros do not beat is the
    simpler account of the same data. Of two with as many parameters the lower cost stands: there
    is no parameter for the order test to weigh, and the free one stood by default (PTB's record
    with 2 % more noise, seed 5: free order 1, V 23.8, a real pole at 14.9 kHz and the response's
    lead absorbed into its zero, against all-pole order 2, V 10.5, both with 4; its FBSD ±10 % edge
    then lay beyond the band, its interval [12, 18 600] kHz)."""
    free_fit, pole_fit = free.fits[free.chosen], all_pole.fits[all_pole.chosen]
    if free_fit.parameters == pole_fit.parameters:
        return pole_fit.cost < free_fit.cost
    fits = sorted([free_fit, pole_fit], key=lambda f: f.parameters)
    chosen, _ = choose_order({0: fits[0].cost, 1: fits[1].cost}, {0: fits[0].parameters, 1: fits[1].parameters},
                             data.bins, response_change({0: fits[0], 1: fits[1]}, data), setup.significance)
    winner = fits[chosen if chosen is not None else 0]
    return winner is all_pole.fits[all_pole.chosen]


def _exhausted_without_mode(sweep: OrderSweep, setup: SearchSetup) -> bool:
    """Whether the sweep's choice has no complex pole pair inside the band and every higher order
    it fitted is no candidate (unstable, marginal or with a pole below the band)."""
    chosen = sweep.chosen
    if chosen is None:
        return False
    higher = [n for n in sweep.costs if n > chosen]
    if not higher or any(math.isfinite(sweep.costs[n]) for n in higher):
        return False
    fit = sweep.fits[chosen]
    modes = modes_of(np.roots(fit.a) if fit.a.size > 1 else np.zeros(0), setup.sample_interval_s, setup.band_hz)
    return not any(m.kind == ModeKind.COMPLEX and m.supported for m in modes)


@dataclass(frozen=True)
class SettledOrder:
    """Stage "order choice": the sweep the order came from (the all-pole one after a fallback),
    the order, how it was chosen, and the orders dropped as unstable once converged."""

    sweep: OrderSweep
    order: int
    selection: str  # "order_test" or "asked"
    unstable_when_converged: list[int]
    findings: tuple[Finding, ...] = ()


def settle_order(sweep: OrderSweep, data: SpectralData, setup: SearchSetup) -> SettledOrder:
    """The order test's choice (or the asked order) iterated to convergence and checked stable.

    An unstable choice falls back to the test's choice among the stable orders; with none, from
    the free structure to the all-pole one (on PTB's record with its sine: the sensor's mode
    beyond the band pressed onto the unit circle; its damping beyond the band is floored,
    order_fit.damping_floored). An asked order that is unstable is an error; one above
    what the data support is a warning."""
    dt = setup.sample_interval_s
    order = setup.asked_order
    if sweep.chosen is None:
        raise AnalysisError(f"no stable model of order 1 … {setup.n_max} fits this record (every fit was unstable)"
                            + _lead_hint(setup))
    if order is not None:
        if not sweep.acceptable(order, data, setup):
            why = (f"the data support only order {sweep.chosen}" if sweep.chosen < order
                   else "is the response really the sensor's answer to this reference?")
            raise AnalysisError(
                f"the order-{order} fit is unstable: the estimate settles with a pole on or outside the unit "
                f"circle ({why})"
            )
        if sweep.chosen < order:
            low, costs = sweep.chosen, sweep.costs
            drop = (costs[low] - costs[order]) / costs[low] if costs[low] > 0 else 0.0
            return SettledOrder(sweep, order, "asked", [], (Finding(
                FindingCode.ASKED_ORDER_UNSUPPORTED,
                f"order {order} was asked but the data support only order {low}: V falls by {drop:.2%} from "
                f"order {low} to {order}, within chance or without changing the response where the pulse has "
                "energy; the extra poles are not determined by this record (a mode beyond the excitation's band?)"
            ),))
        return SettledOrder(sweep, order, "asked", [])
    chosen = sweep.chosen
    if sweep.acceptable(chosen, data, setup):
        return SettledOrder(sweep, chosen, "order_test", [])
    fallback, dropped = choose_stable_order(sweep.costs, sweep.parameters, data.bins, sweep.changes,
                                            lambda n: sweep.acceptable(n, data, setup), setup.significance)
    # A stable free order that holds a pole–zero doublet is the fit following a ripple: the same
    # rule as fit_structures' (PTB's record cut at 0.75 ms: orders 1–2 unstable once converged,
    # order 4 a doublet at 16.8 kHz, FBSD ±5 % 13.3 kHz against the sine's 11.4 kHz).
    findings = []
    doublet = fallback is not None and has_doublet(sweep.fits[fallback].a, sweep.fits[fallback].b)
    if (fallback is None or doublet) and sweep.structure == Structure.FREE and setup.asked_order is None:
        all_pole = fit_orders(data, Structure.ALL_POLE, setup)
        if all_pole.chosen is not None and all_pole.acceptable(all_pole.chosen, data, setup):
            if doublet:
                why = (f"the stable orders with free zeros hold a pole–zero doublet (order {fallback}, after "
                       f"order {', '.join(str(n) for n in dropped)} became unstable when iterated to convergence)")
            else:
                why = "no model with free zeros is stable" + marginal_modes_text(sweep.polished(chosen, data, setup), dt)
            sweep, chosen = replace(all_pole, why=why), all_pole.chosen
            findings.append(Finding(FindingCode.ALL_POLE_FALLBACK,
                                    why + "; the all-pole model (a resonance beyond the band, its damping not "
                                    "determined) is used"))
            fallback, dropped = chosen, []
    if fallback is None:
        raise AnalysisError("no order gives a stable model for this record (every fit settles with a pole on "
                            "or outside the unit circle" + marginal_modes_text(sweep.polished(chosen, data, setup), dt)
                            + ")" + _lead_hint(setup))
    if dropped:
        unstable = ", ".join(str(n) for n in dropped)
        findings.append(Finding(FindingCode.UNSTABLE_WHEN_CONVERGED,
                                f"the fit of order {unstable} became unstable when iterated to convergence; order "
                                f"{fallback} (the order test's choice among the stable orders) is used"))
    return SettledOrder(sweep, fallback, "order_test", list(dropped), tuple(findings))


def best_delay_branch(sweep: OrderSweep, order: int, data: SpectralData, setup: SearchSetup
                      ) -> tuple[OrderFit, list[OrderFit]]:
    """The chosen order's final fit and the other optima of its delay–zeros valley
    (quick_refit.delay_branches): the estimate is the lowest of them (the search started each
    order from one delay and can miss it); the others are kept for the Monte Carlo, whose draws
    re-run this choice. Only a causal delay has branches. The sweep keeps the final fit."""
    final = sweep.fits[order]
    others = delay_branches(data, final, setup.max_delay) if sweep.delay_mode == DelayMode.CAUSAL else []
    if others and others[0].cost < final.cost and acceptable(others[0], data.bins):
        final, others = replace(others[0], start_unstable=final.start_unstable), sorted(
            [final, *others[1:]], key=lambda f: f.cost)
        sweep.fits[order] = final
    return final, others


def order_stability_evidence(prep: Prepared, data: SpectralData, sweep: OrderSweep, setup: SearchSetup, draws: int
                             ) -> tuple[OrderStability, tuple[Finding, ...]]:
    """Stability of the order test's choice across resampled noise: the test re-run on the chosen
    model's response with fresh noise of the record's own level (a parametric bootstrap;
    analysis.uncertainty does the same for the order's PDF and reports it). Below
    ORDER_STABILITY_WARNING a finding. Returns the evidence and the findings."""
    assert sweep.chosen is not None
    chosen = sweep.chosen
    omega_bins = 2.0 * np.pi * prep.bin_hz * setup.sample_interval_s
    noise_draws = NoiseDraws(data, prep.u_bins, prep.y_bins, prep.draw_var_u, prep.draw_var_y, omega_bins, prep.group,
                             STABILITY_SEED,
                             centre_y=predicted_bins(sweep.fits[chosen], data, omega_bins, prep.u_bins))
    refitter = Refitter(data, sweep.fits, sweep.delay_mode, setup.max_delay,
                        lowest_bin_cycles=setup.lowest_bin_hz * setup.sample_interval_s)
    candidates = [m for m in candidates_around(chosen, sweep.fits) if math.isfinite(sweep.costs[m])]
    fractions, _, _ = order_stability(noise_draws, refitter, candidates, draws, setup.significance)
    findings: tuple[Finding, ...] = ()
    if fractions.get(chosen, 0.0) < ORDER_STABILITY_WARNING:
        findings = (Finding(
            FindingCode.ORDER_UNSTABLE,
            f"the order choice is not stable under the record's own noise: the test chose order {chosen}, "
            f"fresh noise of the same level gives {fractions_text(fractions)}; the uncertainty includes the "
            "other orders"
        ),)
    return OrderStability(draws, {str(m): v for m, v in fractions.items()}), findings


def _lead_hint(setup: SearchSetup) -> str:
    """The cause, when the response leads the reference by more than the analysis realigned
    (record_preparation.realigned): no sensor answers before it is excited, and neither
    structure follows such a lead (PTB's response shifted 10 µs earlier, before the realignment:
    every fit unstable)."""
    why = setup.alignment.not_taken_text(setup.sample_interval_s)
    return (f"; {why}: the channels are skewed (digitizer deskew, trigger alignment, cable lengths); correct the "
            "skew and analyse again") if why else ""


def _initial_delay(data: SpectralData, prep: Prepared, order: int, max_delay: int) -> float:
    """A start for the causal delay: on a grid (half a sample, or 1/8 of the span) up to just past
    the cross-correlation lag, the two best linear starts of `order` are refined and the best
    refined delay kept."""
    try:
        xcorr = estimate_delay_samples(prep.u, prep.y, max(1, min(max_delay, prep.u.size // 4)))
    except AnalysisError:
        xcorr = 0.0
    top = float(np.clip(math.ceil(xcorr) + 1, 0, max_delay))
    problem = OrderProblem(data, order, DelayMode.CAUSAL, max_delay)
    refined = [problem.solve(start, 40) for start in delay_grid_starts(problem, top, 2)]
    return min(refined, key=lambda f: f.cost).delay if refined else 0.0


def delay_grid_starts(problem: OrderProblem, top: float, count: int) -> list[OrderFit]:
    """The `count` best linear starts on a grid of delays from 0 to `top` samples (steps of half a
    sample, or 1/8 of the span: at most ~9 starts), at least a sample apart."""
    step = max(0.5, top / 8.0)
    starts = sorted((problem.linear_start(float(tau)) for tau in np.arange(0.0, top + 0.25 * step, step)),
                    key=lambda f: f.cost)
    picked: list[OrderFit] = []
    for start in starts:
        if all(abs(start.delay - p.delay) >= 1.0 for p in picked):
            picked.append(start)
        if len(picked) == count:
            break
    return picked


def acceptable(fit: OrderFit, bins: int) -> bool:
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


def marginal_modes_text(fit: OrderFit, dt: float) -> str:
    """Where the order test's choice put its poles on or beyond the unit circle, as modes
    (e.g. ': order 2 has a mode at 58.4 kHz with ζ ≤ 1e-05, undamped'); '' when none is there."""
    roots = np.roots(fit.a) if fit.a.size > 1 else np.array([])
    marginal = modes_of(roots[np.abs(roots) >= 1.0 - MARGINAL_POLE], dt)
    if not marginal:
        return ""
    parts = []
    for m in marginal:
        f_hz, zeta = m["natural_frequency_hz"] or 0.0, m["damping_ratio"] or 0.0
        parts.append(f"a mode at {f_hz / 1e3:.3g} kHz with ζ {'≤ 1e-05' if abs(zeta) <= 1e-5 else f'= {zeta:.2g}'}")
    return (f": order {fit.order} has {', '.join(parts)}, undamped: a response that rings on without a drive in "
            "the reference (a second drive path, motion the reference does not see) or a mode in a null of the "
            "excitation whose damping the data do not fix")

