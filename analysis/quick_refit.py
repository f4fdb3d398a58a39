"""Refits of a nominal fit: on a Monte Carlo draw's data (`QuickRefit`), and on the other
delay branches of the same order (`delay_branches`)."""

from __future__ import annotations

import math

import numpy as np

from hopkinson.analysis.frequency_fit import CAUSAL_START, RCOND, OrderFit, OrderProblem, is_stable
from hopkinson.analysis.spectral_data import SpectralData
from hopkinson.analysis.structure import DelayMode


class QuickRefit:
    """Refits of one order on perturbed data (Monte Carlo draws) started from a nominal fit.

    Simplified Gauss–Newton: the Jacobian's pseudo-inverse at the nominal optimum is kept and
    θ ← θ − J⁺·r(θ) iterated on each draw's data to convergence. Near the nominal optimum (a
    draw's data differ from the record by noise only) this converges to the same optimum as
    Levenberg–Marquardt at a fraction of its cost (no Jacobian, no factorisation per draw);
    where it does not contract, the draw falls back to Levenberg–Marquardt.
    """

    # Levenberg–Marquardt evaluations a draw that the quick iteration cannot settle may take: a
    # draw needs the optimum to the precision its noise sets, not to the last digit.
    # Known limit (docs/decisions/0014): where the data press an all-pole fit's damping beyond the
    # band under ZETA_FLOOR, the quick iteration cannot settle and the draw stops here, short of an
    # optimum; that stopping point's scatter is part of those records' intervals.
    fallback_evaluations = 20

    def __init__(self, data: SpectralData, fit: OrderFit, delay: str | float, max_delay: float) -> None:
        self.delay = delay
        self.max_delay = max_delay
        self.start = fit
        problem = OrderProblem.for_fit(data, fit, delay, max_delay)
        self.theta0 = problem.pack(fit)
        # Directions the data hardly determine (a spare pole against a zero) are left alone.
        self.step = np.linalg.pinv(problem.jacobian(self.theta0), rcond=RCOND)

    def refit(self, data: SpectralData, iterations: int = 20, exact: bool = True) -> OrderFit:
        """The optimum of `data`: fixed-Jacobian steps (halved while they do not lower the cost)
        until the cost settles, then Gauss–Newton steps with the draw's own Jacobian (the
        fixed-Jacobian iteration alone stops where J₀ᵀr = 0, a hair off the optimum Jᵀr = 0).
        `exact` False returns the best point reached instead of handing an unsettled draw to
        Levenberg–Marquardt (enough to compare costs with an order that fits far better)."""
        problem = OrderProblem.for_fit(data, self.start, self.delay, self.max_delay)
        theta = self.theta0
        r = problem.residual(theta)
        cost = 0.5 * float(r @ r)
        settle = 1e-7 * max(cost, 1.0)
        for _ in range(iterations):
            delta = self.step @ r
            improved = False
            for _ in range(4):
                trial = theta - delta
                r_trial = problem.residual(trial)
                cost_trial = 0.5 * float(r_trial @ r_trial)
                if cost_trial < cost:
                    improved = True
                    break
                delta = 0.5 * delta
            if not improved:
                break
            gain = cost - cost_trial
            theta, r, cost = trial, r_trial, cost_trial
            if gain < settle:
                break
        for _ in range(3):
            jac = problem.jacobian(theta)
            try:
                delta = np.linalg.lstsq(jac, r, rcond=RCOND)[0]
            except np.linalg.LinAlgError:
                break
            predicted = 0.5 * float(r @ r) - 0.5 * float(np.sum((r - jac @ delta) ** 2))
            if predicted < settle:  # at the optimum (to what the cost can still tell)
                return problem.fit_of(theta, cost, 0, True)
            trial = theta - delta
            r_trial = problem.residual(trial)
            cost_trial = 0.5 * float(r_trial @ r_trial)
            if not cost_trial < cost:
                break
            gain = cost - cost_trial
            theta, r, cost = trial, r_trial, cost_trial
            if gain < settle:
                return problem.fit_of(theta, cost, 0, True)
        # Not settled: Levenberg–Marquardt takes over from the best point reached.
        start = problem.fit_of(theta, cost, 0, False) if np.isfinite(cost) and cost < 1e15 else self.start
        if not exact:
            return start
        return problem.solve(start, self.fallback_evaluations, 1e-8)


# A delay branch whose optimum costs more than this above the best is left out: V is half a
# χ² sum, so a difference of 8 is beyond what a fresh noise draw of the record's level can
# overturn (half χ²₁ at 10⁻⁴); nearer branches are ties the data cannot settle.
BRANCH_COST = 8.0
BRANCH_STARTS = 8  # linear starts on the delay grid (at most; a sample apart at least: the basins are wider)


def delay_branches(data: SpectralData, fit: OrderFit, max_delay: float) -> list[OrderFit]:
    """Other local optima of the causal-delay fit of `fit`'s order whose cost is within
    BRANCH_COST of `fit`'s: the delay and B's zeros share a flat valley of the cost (a phase
    lag taken up by τ or by the zeros), and on a record whose excitation barely reaches the
    phase that tells them apart the valley holds separate minima a few samples apart (issue
    10's rehearsed piezo record: τ ≈ 0.4 and ≈ 3.1 samples, costs within 1). Found from linear
    starts on a grid of delays from 0 to a few samples past `fit`'s, each refined; optima
    whose delay lies within a sample of one already kept are the same branch. Sorted by cost
    (the best may beat `fit`: the order search started each order from one delay)."""
    problem = OrderProblem.for_fit(data, fit, DelayMode.CAUSAL, max_delay)
    top = min(float(max_delay) - CAUSAL_START, math.ceil(fit.delay) + 4.0)
    step = max(1.0, top / BRANCH_STARTS)
    found: list[OrderFit] = []

    def near_kept(delay: float) -> bool:
        """Within a sample of a kept optimum: that branch (a fit on its way there is stopped
        at once instead of iterated all the way)."""
        return any(abs(delay - f.delay) < 1.0 for f in (fit, *found))

    for tau in np.arange(0.0, top + 0.25 * step, step):
        if abs(tau - fit.delay) < 1.0:  # a start this near falls back into `fit`'s basin
            continue
        refined = problem.solve(problem.linear_start(float(tau)), 40, 1e-6, near_kept)
        if near_kept(refined.delay) or not (is_stable(refined.a) and refined.cost <= fit.cost + BRANCH_COST):
            continue
        # iterated to convergence; the valley is flat, so it may slide back to a kept optimum
        refined = problem.solve(refined, 400, 1e-11, near_kept)
        if not near_kept(refined.delay):
            found.append(refined)
    return sorted(found, key=lambda f: f.cost)
