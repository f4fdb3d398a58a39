"""The Monte Carlo's draws (GUM-S1 §6; why: docs/decisions/0014): every input's PDF sampled
once, before any refit — the reference chain's scale factors, fresh noise on the fitted bins
and the channel skew, the order of each draw from the order choice's own PDF, and the part of
the band each draw is refitted on where the model error was detected. analysis.uncertainty
then re-runs the settle stage (the refit at the drawn order, from every delay branch) per draw.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from hopkinson.analysis.frequency_fit import OrderProblem, is_stable, predicted_bins
from hopkinson.analysis.identify import Identification
from hopkinson.analysis.modes import has_doublet
from hopkinson.analysis.options import AnalysisOptions
from hopkinson.analysis.order_choice import NoiseDraws, Refitter, candidates_around, order_stability
from hopkinson.analysis.spectral_data import SpectralData

# Where the model error is detected, the draws are refitted on the fitted band and on these
# fractions of its top (_band_variants), each fraction an equal share of the draws.
BAND_TOPS = (1.0, 0.9, 0.8)


@dataclass(frozen=True)
class Draws:
    """The samples of every input, one per Monte Carlo draw (the refits come after)."""

    noise: NoiseDraws  # fresh noise on the fitted bins and a skew, per draw
    inflate: float  # the noise's variance factor (V per degree of freedom where the model error shows)
    chain: dict[str, np.ndarray]  # each channel's scale factor per draw (the reference chain)
    refitter: Refitter  # the settle stage's refit, from every delay branch of each order
    orders: dict[str, Any]  # per_draw: the order of each draw; fractions, decided: its PDF's evidence
    bands: BandVariants  # the part of the band each draw is refitted on


def draw(ident: Identification, options: AnalysisOptions, seed: int, rng: np.random.Generator) -> Draws:
    """Every input's draws for `options.draws` Monte Carlo trials of `ident` (the noise from
    `seed`, the rest from `rng`, in a fixed order)."""
    prep, fitted = ident.prep, ident.settlement
    dt = ident.sample_interval_s
    inflate = _noise_inflation(ident)
    chain = _chain_draws(options, options.draws, rng)
    noise = NoiseDraws(fitted.data, prep.u_bins, prep.y_bins, prep.draw_var_u, ident.claim.draw_var_y(fitted.model_error),
                       2.0 * np.pi * prep.bin_hz * dt, prep.group, seed, inflate, options.u_channel_skew_s / dt,
                       level_u=prep.noise.draw_noise_u, level_y=ident.claim.response_noise, bin_hz=prep.bin_hz)
    refitter = Refitter(fitted.data, fitted.sweep.fits, fitted.sweep.delay_mode, fitted.setup.max_delay,
                        fitted.branches, _lowest_bin_cycles(ident))
    orders = _order_assignment(ident, noise, refitter, options, rng)
    bands = _band_variants(ident, refitter, orders["per_draw"], rng)
    return Draws(noise, inflate, chain, refitter, orders, bands)


def _noise_inflation(ident: Identification) -> float:
    """V per degree of freedom when significantly above 1 (model error), else 1."""
    dof = 2 * ident.settlement.data.bins - ident.settlement.sweep.fits[ident.order].parameters
    ratio = ident.claim.v_per_dof
    if dof > 0 and ratio > 1.0 + 3.0 * math.sqrt(2.0 / dof):
        return float(ratio)
    return 1.0


def _chain_draws(options: AnalysisOptions, count: int, rng: np.random.Generator) -> dict[str, np.ndarray]:
    """Scale factors of each channel per draw: Π (1 + δ_source), δ ~ N(0, u_rel²)."""
    out = {"reference": np.ones(count), "response": np.ones(count)}
    for u_rel, channel in options.chain().values():
        out[channel] = out[channel] * (1.0 + u_rel * rng.standard_normal(count))
    return out


# ------------------------------------------------------------------------------ refits
def _order_assignment(ident: Identification, draws: NoiseDraws, refitter: Refitter, options: AnalysisOptions,
                      rng: np.random.Generator) -> dict[str, Any]:
    """The order of each draw, drawn from the order choice's own PDF: the whole choice re-run on
    `order_draws` parametric-bootstrap draws (the chosen model's response with fresh noise of
    the record's level). An asked order is kept in every draw."""
    n_hat = ident.order
    count = options.draws
    # An order whose fit holds a pole–zero doublet is no candidate (identify's own rule: the fit
    # following a ripple of the data): drawn, its sharp ripple (ζ ~ 0.002) moved the FBSD edges of
    # PTB's hybrids by half (order 4 in 42 % of the draws, the ±10 % interval 16.2–31.3 kHz). A
    # real pole cancelled by a zero as well (modes.has_doublet's `real`): the hybrids' order 3 is
    # order 2 plus such a pair at 250–440 Hz, below the lowest bin (606 Hz); refitted on a draw's
    # noise its pole and zero part (68 and 46 Hz), H(0) drops by a third and the draw's FBSD edges
    # fall to 20–50 Hz: 3–5 such draws of 60 made the ±5 % interval [11.7, 244] kHz.
    fits = ident.settlement.sweep.fits
    candidates = [m for m in candidates_around(n_hat, fits) if math.isfinite(fits[m].cost)
                  and (m == n_hat or not has_doublet(fits[m].a, fits[m].b, real=True))]
    if ident.order_selection not in ("order_test", "knee") or len(candidates) < 2:
        return {"per_draw": [n_hat] * count, "fractions": {}, "decided": 0}
    bootstrap = replace(draws, seed=draws.seed + 1, skew_sd=0.0,
                        centre_y=predicted_bins(ident.settlement.sweep.fits[n_hat], ident.settlement.data, draws.omega, ident.prep.u_bins))
    subset = min(options.order_draws, count)
    fractions, choices, _ = order_stability(bootstrap, refitter, candidates, subset, ident.settlement.setup.significance)
    decided = [c if c is not None else n_hat for c in choices]
    values = np.array(sorted(set(decided)))
    weights = np.array([decided.count(int(v)) for v in values], dtype=float)
    per_draw = rng.choice(values, size=count, p=weights / weights.sum())
    return {"per_draw": [int(m) for m in per_draw], "fractions": {str(m): f for m, f in fractions.items()},
            "decided": subset}


@dataclass
class BandVariants:
    """The parts of the fitted band the draws are refitted on (BAND_TOPS): variant 0 is the whole
    band; each has its top (rad/sample) and a refitter prepared at the nominal fit on that part."""

    omega_max: list[float]
    refitters: list[Refitter]
    tops_hz: list[float]  # the tops of the variants beyond the whole band (empty: none drawn)
    per_draw: np.ndarray  # the variant of each draw
    flip: np.ndarray  # a variant draw reflected (even odds)


def _band_variants(ident: Identification, refitter: Refitter, orders: list[int], rng: np.random.Generator
                   ) -> BandVariants:
    """The band's parts each draw is refitted on: only the whole band unless the model error is
    detected (the residual then holds structure the model does not follow); a part is used when
    every order drawn can be refitted there (`_refitter_on`). Each draw takes a part at random and
    a reflection flag at even odds."""
    count = len(orders)
    omega_max, refitters = [math.inf], [refitter]
    top = float(np.max(ident.settlement.data.omega))
    for fraction in BAND_TOPS[1:] if ident.settlement.model_error_detected else ():
        part = ident.settlement.data.below(fraction * top)
        prepared = _refitter_on(part, ident, sorted({*orders, ident.order}))  # (a draw may fall back to it)
        if prepared is not None:
            omega_max.append(fraction * top)
            refitters.append(prepared)
    if len(refitters) == 1:
        return BandVariants(omega_max, refitters, [], np.zeros(count, dtype=int), np.zeros(count, dtype=bool))
    tops_hz = [w / (2.0 * math.pi * ident.sample_interval_s) for w in omega_max[1:]]
    return BandVariants(omega_max, refitters, tops_hz, rng.integers(0, len(refitters), count), rng.random(count) < 0.5)


def _refitter_on(part: SpectralData, ident: Identification, orders: list[int]) -> Refitter | None:
    """A refitter of `orders` on a part of the band, each order (and each of its delay branches)
    refitted there from its nominal fit; None when an order is missing, has fewer real residuals
    (two per bin) than twice its parameters there, or refits unstably."""
    fits, branches = {}, {}
    for n in orders:
        if n not in ident.settlement.sweep.fits or part.bins < ident.settlement.sweep.fits[n].parameters:
            return None
        refit = [OrderProblem.for_fit(part, f, ident.settlement.sweep.delay_mode, ident.settlement.setup.max_delay).solve(f, 200, 1e-9)
                 for f in (ident.settlement.sweep.fits[n], *ident.settlement.branches.get(n, []))]
        if not all(is_stable(f.a) for f in refit):
            return None
        fits[n], branches[n] = refit[0], refit[1:]
    return Refitter(part, fits, ident.settlement.sweep.delay_mode, ident.settlement.setup.max_delay, branches,
                    _lowest_bin_cycles(ident))


def _lowest_bin_cycles(ident: Identification) -> float:
    """The lowest fitted bin in cycles per sample (Refitter.places)."""
    return ident.settlement.setup.lowest_bin_hz * ident.settlement.setup.sample_interval_s
