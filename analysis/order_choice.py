"""The model order: the test that chooses it, and its stability across resampled noise.

- `choose_order`: the smallest order no higher order beats both beyond chance and in the
  frequency response where the pulse has energy (see its docstring); `choose_stable_order`:
  the same among the orders whose converged fit is stable.
- `NoiseDraws`: fresh noise on the fitted DFT bins of both channels (circular complex Gaussian
  of the measured variance per bin) and a channel skew, reproducible from (seed, draw):
  added to the record (analysis.uncertainty's Monte Carlo draws of the figures) or, for the
  order's stability, to the chosen model's response (a parametric bootstrap: noise added to a
  noisy record doubles it and would favour the lowest orders).
- `Refitter`: each order refitted on a draw from its nominal fit (quick_refit.QuickRefit).
- `order_stability`: the whole order choice re-run on draws; the fraction choosing each order.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, replace
from functools import cached_property
from typing import Any

import numpy as np

from hopkinson.analysis.frequency_fit import OrderFit, is_stable, response
from hopkinson.analysis.noise import NoiseSpectrum
from hopkinson.analysis.numerics import f_quantile
from hopkinson.analysis.options import SIGNIFICANCE
from hopkinson.analysis.quick_refit import QuickRefit
from hopkinson.analysis.spectral_data import SpectralData

# The order test: a higher order must be significant at params.SIGNIFICANCE (F test on V,
# corrected for the number of bins a pole pair could be placed at) and change the excitation-weighted frequency response by more than this (RMS, relative):
# below it, it only mends the discrete model's own approximation of a continuous sensor.
FRF_TOLERANCE = 1e-3
# Below this share of noise draws re-choosing it, the order choice is reported as not stable
# (analysis.order_search.order_stability_evidence, analysis.uncertainty).
ORDER_STABILITY_WARNING = 0.5


@dataclass(frozen=True)
class OrderStability:
    """The order choice re-run on `draws` noise draws: order (as text) -> share of the draws
    that chose it."""

    draws: int
    fraction_by_order: dict[str, float]

    def to_dict(self) -> dict[str, Any]:
        return {"draws": self.draws, "fraction_by_order": self.fraction_by_order}


def choose_order(
    costs: dict[int, float],
    parameters: dict[int, int],
    bins: int,
    change: dict[tuple[int, int], float],
    significance: float = SIGNIFICANCE,
    frf_tolerance: float = FRF_TOLERANCE,
) -> tuple[int | None, list[dict[str, Any]]]:
    """The smallest order no higher order beats, and the comparisons made. m beats n when both
    - its gain in V is beyond chance: the F statistic of the nested comparison,
      [(V_n − V_m)/(Δp/2)] / [V_m/(K − p_m/2)], exceeds F(Δp, 2K − p_m) at 1 − α/K. The
      nominal F test is Bonferroni-corrected over the K bins: an extra pole pair can sit
      anywhere in the band, on the largest chance peak of the noise among K (the nominal
      degrees of freedom do not count that freedom of place); V_m as the yardstick keeps the
      test honest when the noise level was measured a constant factor off;
    - it changes the response where the pulse has energy: `change[(n, m)]`, the excitation-
      weighted RMS of the difference of the two frequency responses relative to n's, above
      `frf_tolerance` (a high-SNR record shows even the small mismatch between a rational
      discrete model and a continuous sensor; a pole pair that only mends that is parasitic).
    An order whose cost is not finite (unstable) is no candidate.
    """
    ordered = sorted(n for n, v in costs.items() if math.isfinite(v))
    level = 1.0 - significance / max(bins, 1)
    comparisons: list[dict[str, Any]] = []
    for n in ordered:
        beaten = False
        for m in ordered:
            if m <= n:
                continue
            dp = parameters[m] - parameters[n]
            dof = 2 * bins - parameters[m]
            if dp <= 0 or dof <= 0:
                continue
            gain = costs[n] - costs[m]
            f_stat = (gain / (dp / 2.0)) / (costs[m] / (dof / 2.0)) if costs[m] > 0 else math.inf
            critical = f_quantile(level, dp, dof)
            moved = change.get((n, m), math.inf)
            better = f_stat > critical and moved > frf_tolerance
            comparisons.append({"order": n, "against": m, "f": f_stat, "f_critical": critical,
                                "response_change": moved, "beaten": bool(better)})
            if better:
                beaten = True
                break
        if not beaten:
            return n, comparisons
    return None, comparisons


def choose_stable_order(
    costs: dict[int, float],
    parameters: dict[int, int],
    bins: int,
    change: dict[tuple[int, int], float],
    stable: Callable[[int], bool],
    significance: float = SIGNIFICANCE,
) -> tuple[int | None, list[int]]:
    """`choose_order`'s choice among the orders whose converged fit is `stable`, and the orders
    dropped on the way. An order that turns out unstable is no candidate, neither to be chosen
    nor to beat a lower one, and the test is re-run without it. (Taking the stable order of
    lowest cost instead takes the highest stable one whatever the test says of it: on a real
    record, a spare low-frequency pole-zero pair that only moves the DC gain and the FBSD.)"""
    remaining = dict(costs)
    dropped: list[int] = []
    chosen, _ = choose_order(remaining, parameters, bins, change, significance)
    while chosen is not None and not stable(chosen):
        dropped.append(chosen)
        remaining[chosen] = math.inf
        chosen, _ = choose_order(remaining, parameters, bins, change, significance)
    return chosen, dropped


def response_change(fits: dict[int, OrderFit], data: SpectralData) -> dict[tuple[int, int], float]:
    """Excitation-weighted RMS relative difference of the frequency responses of every pair of
    evaluated orders (see choose_order)."""
    weight = data.suu
    responses = {n: response(f, data.omega) for n, f in fits.items()}
    out = {}
    for n, hn in responses.items():
        norm = float(np.sum(weight * np.abs(hn) ** 2))
        for m, hm in responses.items():
            if m > n:
                out[(n, m)] = math.sqrt(float(np.sum(weight * np.abs(hm - hn) ** 2)) / norm) if norm > 0 else math.inf
    return out


@dataclass(frozen=True)
class NoiseDraws:
    """Perturbed copies of the fitted spectra: the data of one noise draw each."""

    spectral: SpectralData
    u_bins: np.ndarray  # DFT of the reference at the fitted bins
    y_bins: np.ndarray
    var_u: np.ndarray  # noise variance per bin
    var_y: np.ndarray
    omega: np.ndarray  # rad/sample of each bin
    group: int
    seed: int
    inflate: float = 1.0  # noise variances × this (model error beyond the noise)
    skew_sd: float = 0.0  # channel skew, samples
    centre_y: np.ndarray | None = None  # response spectrum the noise is added to (None: the record's)
    # The measured spectra (their frequency grids and degrees of freedom) and each bin's
    # frequency: when given, each draw also draws the noise levels (NoiseSpectrum.level_factors).
    level_u: NoiseSpectrum | None = None
    level_y: NoiseSpectrum | None = None
    bin_hz: np.ndarray | None = None

    @cached_property
    def _minus_j_omega(self) -> np.ndarray:
        return -1j * self.omega

    def data(self, r: int) -> tuple[SpectralData, float]:
        """Draw r's perturbed spectra and its skew (samples). Written for long records (10⁵ bins
        and more, where a draw's arrays outweigh its refit): few temporaries, the values of
        √(var·inflate/2)·(re + j·im) and (U + N)·e^{−jωs} to the bit."""
        rng = np.random.default_rng([self.seed, 1, r])
        k = self.u_bins.size
        gauss = rng.standard_normal((4, k))
        var_u, var_y = self.var_u, self.var_y
        if self.bin_hz is not None:
            if self.level_u is not None:
                var_u = var_u * self.level_u.level_factors(self.bin_hz, rng)
            if self.level_y is not None:
                var_y = var_y * self.level_y.level_factors(self.bin_hz, rng)

        def cn(var: np.ndarray, re: np.ndarray, im: np.ndarray) -> np.ndarray:
            """√(var·inflate/2)·(re + j·im): a real scale times a complex number is its two
            parts scaled (no cross terms), so the parts are written directly."""
            scale = np.sqrt(var * self.inflate / 2.0)
            out = np.empty(k, dtype=complex)
            np.multiply(scale, re, out=out.real)
            np.multiply(scale, im, out=out.imag)
            return out

        u, y = cn(var_u, gauss[0], gauss[1]), cn(var_y, gauss[2], gauss[3])
        skew = self.skew_sd * rng.standard_normal() if self.skew_sd > 0 else 0.0
        u += self.u_bins  # the noise added to the channels (in place: the same sums)
        u *= np.exp(self._minus_j_omega * skew)
        y += self.y_bins if self.centre_y is None else self.centre_y
        data = self.spectral.perturbed(u, y, self.group)
        if data.sine is not None:  # sine points fitted with the shock: perturbed by their own uncertainty
            data = replace(data, sine=data.sine.drawn(rng))
        return data, skew


class Refitter:
    """Quick refits of each order on a draw, each prepared once at its nominal fit. Where the
    nominal search found other delay branches of an order (`branches`, frequency_fit.
    delay_branches: near-equal optima of the delay–zeros valley), each draw is refitted from
    every branch and keeps the lowest cost: the draw re-runs the delay search as the nominal
    fit ran it (GUM-S1: each draw re-runs the estimator), so it can land on either branch."""

    def __init__(self, spectral: SpectralData, fits: dict[int, OrderFit], delay: str | float, max_delay: float,
                 branches: dict[int, list[OrderFit]] | None = None, lowest_bin_cycles: float = 0.0) -> None:
        self.spectral = spectral
        self.fits = fits
        self.delay = delay
        self.max_delay = max_delay
        self.branches = branches or {}
        self.lowest_bin_cycles = lowest_bin_cycles  # the lowest fitted bin (cycles per sample; 0: not checked)
        self._quick: dict[tuple[int, int], QuickRefit] = {}

    def places(self, fit: OrderFit) -> bool:
        """Whether the data can place every real pole of `fit`: none lies far below the lowest
        fitted bin (`pole_below_band`; order_search's rule for a candidate of the order test)."""
        return not pole_below_band(fit, self.lowest_bin_cycles, 1.0)

    def fit(self, data: SpectralData, order: int, exact: bool = True) -> OrderFit | None:
        """The order's optimum on `data` (None: not fitted nominally, or unstable); `exact`
        False may stop short of it where the quick iteration does not settle."""
        return self.fit_branch(data, order, exact)[0]

    def fit_branch(self, data: SpectralData, order: int, exact: bool = True) -> tuple[OrderFit | None, int]:
        """`fit`, and the branch it landed on (0: the nominal fit's, i: `branches[order][i − 1]`)."""
        if order not in self.fits:
            return None, 0
        best: tuple[OrderFit | None, int] = (None, 0)
        for i, start in enumerate([self.fits[order], *self.branches.get(order, [])]):
            if (order, i) not in self._quick:
                self._quick[(order, i)] = QuickRefit(self.spectral, start, self.delay, self.max_delay)
            fit = self._quick[(order, i)].refit(data, exact=exact)
            if is_stable(fit.a) and (best[0] is None or fit.cost < best[0].cost):
                best = (fit, i)
        return best


def decide(refitter: Refitter, data: SpectralData, candidates: list[int], significance: float
           ) -> tuple[int | None, dict[int, OrderFit]]:
    """The order test on one draw over `candidates` (each refitted); and the refits. A refit
    with a real pole the data cannot place (`Refitter.places`) is no candidate in that draw, as
    the nominal order test has it (order_search._candidate_cost).

    Orders the quick refit cannot settle keep the best cost it reached (an upper bound): such
    an order is far from the data (an under-fit one) and loses the comparison anyway."""
    fits = {m: f for m in candidates if (f := refitter.fit(data, m, exact=False)) is not None and refitter.places(f)}
    costs = {m: f.cost for m, f in fits.items()}
    parameters = {m: f.parameters for m, f in fits.items()}
    chosen, _ = choose_order(costs, parameters, data.bins, response_change(fits, data), significance)
    return chosen, fits


def candidates_around(order: int, fits: dict[int, OrderFit]) -> list[int]:
    """The orders a choice of `order` weighed: two either side (a choice may skip one)."""
    return [m for m in range(max(1, order - 2), order + 3) if m in fits]


def order_stability(
    draws: NoiseDraws, refitter: Refitter, candidates: list[int], count: int, significance: float = SIGNIFICANCE,
) -> tuple[dict[int, float], list[int | None], list[dict[int, OrderFit]]]:
    """The order test re-run on `count` draws: fraction per order, each draw's choice and refits."""
    choices: list[int | None] = []
    refits: list[dict[int, OrderFit]] = []
    for r in range(count):
        data, _ = draws.data(r)
        chosen, fits = decide(refitter, data, candidates, significance)
        choices.append(chosen)
        refits.append(fits)
    made = [c for c in choices if c is not None]
    fractions = {m: made.count(m) / len(made) for m in sorted(set(made))} if made else {}
    return fractions, choices, refits


def modal_order(fractions: dict[int, float], fallback: int) -> int:
    """The order chosen most often (the lower one on a tie); `fallback` without draws."""
    if not fractions:
        return fallback
    best = max(fractions.values())
    return min(m for m, f in fractions.items() if f == best)


def fractions_text(fractions: dict[Any, float]) -> str:
    return ", ".join(f"order {k}: {v:.0%}" for k, v in sorted(fractions.items(), key=lambda kv: int(kv[0])))


def pole_below_band(fit: OrderFit, lowest_bin_hz: float, dt: float) -> bool:
    """Whether the fit has a real pole whose frequency lies below a tenth of the lowest
    fitted bin's (undetermined by the fitted data)."""
    roots = np.roots(fit.a) if fit.a.size > 1 else np.array([])
    real = roots[(np.abs(roots.imag) < 1e-12) & (roots.real > 0)].real
    f_hz = -np.log(np.clip(real, 1e-300, None)) / (2.0 * np.pi * dt)
    return bool(np.any(f_hz < 0.1 * lowest_bin_hz))
