"""Uncertainty of a shot's key figures after GUM Supplement 1 (Monte Carlo).

Measurand: the figures `analysis.identify` and the reduction report — the DC gain (the
sensitivity), the ISO 16063-13 peak-ratio shock sensitivity, the main mode's natural frequency
and damping ratio, both FBSD edges, the input delay, and the reference's peak acceleration,
pulse width and peak velocity. Input quantities and the PDFs assigned to them (GUM-S1 §6):

- the noise of both channels: Gaussian, with the spectra measured on the record's quiet
  stretches (analysis.noise) — each draw adds a fresh noise realisation to the DFT bins the
  fit uses (circular complex Gaussian of the measured variance per bin) and, for the peak
  figures, to the samples around each peak; when the model leaves significantly more residual
  than that noise explains, the variances are widened by the ratio (a Birge-ratio correction
  for model error, reported as a warning by identify);
- the channel skew: Gaussian, standard deviation `channel_skew_s`, a fractional delay of the
  reference in each draw (the fitted causal delay absorbs it unless it sits at zero);
- the reference chain, each Gaussian with the relative standard uncertainty from rig.toml
  [uncertainty]: grating pitch and interferometer (scale the reference), amplifier gain and
  digitizer gain (scale the response);
- the order choice: discrete. On a subset of the draws the whole order choice is re-run on the
  perturbed data (the neighbouring orders refitted, the same validation rule applied); the
  fractions give its PDF, and every draw is refitted at an order drawn from it. The fractions
  are reported as the order's stability.

- the model's own error (where identify detected it): the draws are refitted on the whole
  fitted band and on 0.9 and 0.8 of its top (BAND_TOPS), a third each. A right model gives one
  answer on every part of the band its excitation supports; a model the data bend (a smooth
  structure against a rippled response) answers differently on each, and that spread is its
  uncertainty, which the residual cannot show because the fit has absorbed it. The offset's
  sign is not known (on PTB's record the truth lies above the whole-band FBSD, on a noisier
  copy of it below), so these draws are reflected about the value at even odds. Its share is
  the budget's "band part" row. On PTB's record it widens the FBSD ±5 % interval from ±4 to
  ±10 % and the largest E_n of the sine points against the response band falls from 2.6 to
  0.9–1.3; variants (other rates, a 1.2 ms capture, skews, 0.1–0.5 % more noise) all hold the
  sine's edges (tests/analysis/test_ptb_variants.py).

Each draw refits the model by the same estimator (analysis.frequency_fit, Levenberg–Marquardt
started from the nominal fit, which it is close to) — a full non-linear re-estimation, not a
linearisation; except where an all-pole fit's damping beyond the band is pressed under its
floor (PTB's record), where a draw stops after QuickRefit.fallback_evaluations short of its
optimum (a known limit, see there). That includes the delay search: the delay and B's zeros share a flat valley of
the cost, which on some records holds separate optima a few samples apart with costs within
chance (issue 10's rehearsed piezo record: τ ≈ 0.4 or ≈ 3.1 samples, the FBSD −0.6 % or
+0.2 … +0.7 % with them); identify keeps the lowest and lists the others
(`FitContext.branches`, `order_evidence["delay_branches"]`), and each draw at the chosen order
is refitted from every branch and keeps the lowest cost, so the draws land on either branch as
the noise decides, and the figures' u and intervals carry the branch spread (the budget's
"delay branch" row, present when draws changed branch). The interval reflects the draws on the
nominal branch about the value (below) and takes those on another branch as they are: a
branch is not scatter about the estimate but the other estimate the same estimator gives on
such data, offset from the truth on its own side (on the rehearsed record the FBSD ±5 %
intervals contained the truth on 24 of 24 seeds, 18 before). The standard uncertainty is the draws' standard deviation; the 95 % coverage
interval the probabilistically symmetric one (2.5 % and 97.5 % quantiles, GUM-S1 §7.7). The
value is the figure reported everywhere (the nominal analysis), not the draws' mean.

The budget is the linear decomposition GUM's uncertainty table is (its sum of squares is the
GUM-framework variance, reported beside the Monte Carlo one): the noise of each channel and
the skew propagated through the fit's Jacobian (sensitivity of each figure by finite
differences), the reference chain exactly (the figures are proportional to it), and the order
choice as the variance the order draws add to the fixed-order ones.

Validated by tests/analysis/test_uncertainty.py: on simulated sensors with a known truth, the
95 % intervals contain it in about 95 % of shots, and their width matches the spread of the
estimates over the shots.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
from hopkinson.analysis.errors import AnalysisError
from hopkinson.analysis.estimate import COVERAGE, Estimate
from hopkinson.analysis.excitation import peak_estimate, pulse_width
from hopkinson.analysis.findings import Finding, FindingCode, texts
from hopkinson.analysis.frequency_fit import (
    OrderFit,
    OrderProblem,
    SpectralData,
    is_stable,
    predicted_bins,
)
from hopkinson.analysis.identify import (
    FitContext,
    Identification,
)
from hopkinson.analysis.input_terms import ASYMMETRY, MOTION
from hopkinson.analysis.model import DiscreteModel
from hopkinson.analysis.modes import has_doublet
from hopkinson.analysis.order_choice import (
    ORDER_STABILITY_WARNING,
    NoiseDraws,
    Refitter,
    candidates_around,
    fractions_text,
    order_stability,
)
from hopkinson.analysis.params import DEFAULT_DRAWS, AnalysisParams
from hopkinson.analysis.response import fbsd_edges, frequency_response
from hopkinson.analysis.systematics import (
    MODEL_ERROR_BOUND,
    TypeB,
    fitted_shares,
    transverse_row,
    variant_bounds,
)

METHOD = "GUM Supplement 1 Monte Carlo (refit per draw)"
ORDER_DRAWS = 40  # draws that re-run the whole order choice (its PDF's resolution: 2.5 %)
FBSD_GRID = 2000
PEAK_SEGMENT = 256  # samples around a peak that get fresh noise for the peak figures
# Below this share of stable refits the draws cannot stand for the estimator.
MIN_GOOD_FRACTION = 0.9
# Where the model error is detected, the draws are refitted on the fitted band and on these
# fractions of its top (_band_variants): a right model gives one answer on every part of the band
# its excitation supports; a model that leaves error there bends towards whichever part is
# fitted, and that spread is the model's own uncertainty, which the residual cannot show (the
# fit absorbed it). Each fraction takes an equal share of the draws.
BAND_TOPS = (1.0, 0.9, 0.8)


@dataclass(frozen=True)
class UncertaintyOptions:
    """What the Monte Carlo draws and from what PDFs (see the module docstring)."""

    draws: int = DEFAULT_DRAWS
    seed: int | None = None
    u_grating_pitch_rel: float = 1e-4
    u_interferometer_rel: float = 5e-4
    u_amp_gain_rel: float = 2e-3
    u_digitizer_gain_rel: float = 2e-3
    channel_skew_s: float = 1e-9
    order_draws: int = ORDER_DRAWS
    transverse_sensitivity_rel: float = 0.05  # analysis.systematics.transverse_row
    transverse_motion_rel: float = 0.02

    @classmethod
    def from_params(cls, params: AnalysisParams) -> UncertaintyOptions:
        return cls(draws=params.draws, seed=params.seed, u_grating_pitch_rel=params.u_grating_pitch_rel,
                   u_interferometer_rel=params.u_interferometer_rel, u_amp_gain_rel=params.u_amp_gain_rel,
                   u_digitizer_gain_rel=params.u_digitizer_gain_rel, channel_skew_s=params.u_channel_skew_s,
                   transverse_sensitivity_rel=params.transverse_sensitivity_rel,
                   transverse_motion_rel=params.transverse_motion_rel)

    def chain(self) -> dict[str, tuple[float, str]]:
        """Reference-chain sources: (relative standard uncertainty, channel it scales)."""
        return {
            "grating pitch": (self.u_grating_pitch_rel, "reference"),
            "interferometer": (self.u_interferometer_rel, "reference"),
            "amplifier gain": (self.u_amp_gain_rel, "response"),
            "digitizer gain": (self.u_digitizer_gain_rel, "response"),
        }


@dataclass
class UncertaintyResult:
    """The Monte Carlo result: figures, budget, order stability; `to_dict()` is the JSON
    contract of issue 10 (plus the reference figures, the delay and the order evidence)."""

    draws: int
    coverage_probability: float
    seed: int
    dc_gain: Estimate
    shock_sensitivity: Estimate | None
    natural_frequency_hz: Estimate | None
    damping_ratio: Estimate | None
    fbsd_hz: dict[str, Estimate]
    delay_s: Estimate
    reference: dict[str, Estimate]
    budget: list[dict[str, Any]]
    order: dict[str, Any]
    findings: list[Finding] = field(default_factory=list)
    failed_draws: int = 0
    model_draws: list[DiscreteModel] = field(default_factory=list, repr=False)
    response_band: dict[str, Any] | None = None  # the model's response with its 95 % band (response_band)
    band_tops_hz: list[float] = field(default_factory=list)  # the band's tops the draws were refitted on
    input_terms: dict[str, Estimate] = field(default_factory=dict)  # ε and γ (analysis.input_terms), refitted per draw

    @property
    def warnings(self) -> list[str]:
        """The findings' texts (the results' `warnings`)."""
        return texts(self.findings)

    def to_dict(self) -> dict[str, Any]:
        main = None
        if self.natural_frequency_hz is not None and self.damping_ratio is not None:
            main = {"natural_frequency_hz": self.natural_frequency_hz.to_dict(),
                    "damping_ratio": self.damping_ratio.to_dict()}
        return {
            "method": METHOD,
            "draws": self.draws,
            "coverage_probability": self.coverage_probability,
            "dc_gain": self.dc_gain.to_dict(),
            "shock_sensitivity": self.shock_sensitivity.to_dict() if self.shock_sensitivity else None,
            "main_mode": main,
            "fbsd_hz": {k: e.to_dict() for k, e in self.fbsd_hz.items()},
            "budget": [dict(b) for b in self.budget],
            "delay_s": self.delay_s.to_dict(),
            "input_terms": {k: e.to_dict() for k, e in self.input_terms.items()},
            "reference": {k: e.to_dict() for k, e in self.reference.items()},
            "order": dict(self.order),
            "seed": self.seed,
            "failed_draws": self.failed_draws,
            "warnings": self.warnings,
            "response_band": self.response_band,
            "band_tops_hz": list(self.band_tops_hz),
        }


def evaluate(
    ident: Identification,
    options: UncertaintyOptions | None = None,
    reduction: dict[str, Any] | None = None,
) -> UncertaintyResult:
    """Monte Carlo uncertainty of `ident`'s figures (and of `reduction`'s, when given)."""
    options = UncertaintyOptions() if options is None else options
    ctx = ident.context
    if ctx is None:
        raise AnalysisError("uncertainty: the identification carries no fit context (rebuilt from a file?)")
    if options.draws < 2:
        raise AnalysisError(f"uncertainty: at least 2 draws are needed, got {options.draws}")
    seed = options.seed if options.seed is not None else int(np.random.SeedSequence().entropy % 2**63)
    rng = np.random.default_rng(seed)
    findings: list[Finding] = []
    n_hat = ident.order
    dt = ctx.sample_interval_s
    inflate = _noise_inflation(ctx, n_hat)
    chain = _chain_draws(options, options.draws, rng)
    response_factor, reference_factor = chain["response"], chain["reference"]
    gain_factor = response_factor / reference_factor

    # -- the model figures: refit per draw ------------------------------------------------
    draws = NoiseDraws(ctx.spectral, ctx.u_bins, ctx.y_bins, ctx.var_u, ctx.var_y,
                       2.0 * np.pi * ctx.bin_frequency_hz * dt, ctx.group, seed, inflate, options.channel_skew_s / dt,
                       level_u=ctx.noise_u, level_y=ctx.noise_y, bin_hz=ctx.bin_frequency_hz)
    refitter = Refitter(ctx.spectral, ctx.fits, ctx.delay_mode, ctx.max_delay, ctx.branches)
    orders = _order_assignment(ident, draws, refitter, options, rng)
    bands = _band_variants(ctx, refitter, orders["per_draw"], rng)
    fits, skews, branch = _refits(draws, bands, orders["per_draw"])
    # A draw on another delay branch is not reflected (Estimate.of_draws); one on a part of the
    # band is reflected or not at even odds: its offset is the model's, of either sign.
    reflect = np.where(bands.per_draw > 0, bands.flip, branch == 0)
    nominal_branch = branch == 0
    good = np.array([f is not None and is_stable(f.a) for f in fits])
    failed = int(np.sum(~good))
    if good.mean() < MIN_GOOD_FRACTION:
        findings.append(Finding(FindingCode.DRAWS_FAILED,
                                f"{failed} of {len(fits)} draws gave no stable refit: the uncertainty stands for "
                                "the draws that did and may understate it"))
    scale = ctx.scale_y / ctx.scale_u
    model = ident.model
    dc_draws = np.full(len(fits), np.nan)
    delay_draws = np.full(len(fits), np.nan)
    main = ident.main_mode
    main_pole = main.pole_z if main else None
    fn_draws = np.full(len(fits), np.nan)
    zeta_draws = np.full(len(fits), np.nan)
    model_draws: list[DiscreteModel] = []
    for r, f in enumerate(fits):
        if f is None or not good[r]:
            continue
        b = f.b * scale * gain_factor[r] * ctx.terms.mean_gain_factor(f.inputs)  # the mean of both directions
        dc_draws[r] = float(np.sum(b) / np.sum(f.a))
        delay_draws[r] = (ctx.model_delay(f.delay) - skews[r]) * dt
        # fitted with a sine calibration: the sine's level ÷ the model's (analysis.sine_joint)
        info = {"sine_gain_ratio": math.exp(f.sine_gain) / (scale * gain_factor[r])} if ctx.spectral.sine else {}
        model_draws.append(DiscreteModel(dt, f.a, b, ctx.model_delay(f.delay), info=info))
        if main_pole is not None:
            fn_draws[r], zeta_draws[r] = _nearest_mode(f.a, main_pole, dt)
    nominal_edges = fbsd_edges(model)
    fbsd_values = {k: e.frequency_hz for k, e in nominal_edges.items()}
    fbsd_draws = _fbsd_draws(fits, good, nominal_edges, dt)
    # The Type B inputs (analysis.systematics): each a rectangular shift added to every draw.
    shock_value = (reduction or {}).get("shock_sensitivity")
    type_b = variant_bounds(ident)
    transverse = transverse_row(model.dc_gain, shock_value, options.transverse_sensitivity_rel,
                                options.transverse_motion_rel)
    type_b += [transverse] if transverse is not None else []
    figure_draws = {"dc_gain": dc_draws, "natural_frequency_hz": fn_draws, "damping_ratio": zeta_draws,
                    **{f"fbsd_{k}_hz": fbsd_draws[k] for k in fbsd_draws}}
    added_shock = np.zeros(options.draws)
    for row in type_b:
        for figure, shift in row.draws(len(fits), rng).items():
            if figure in figure_draws:
                figure_draws[figure] += shift
            elif figure == "shock_sensitivity":
                added_shock += shift

    dc = Estimate.of_draws(model.dc_gain, dc_draws, reflect=reflect, signed=True)
    fn = Estimate.of_draws(main.natural_frequency_hz, fn_draws, reflect=reflect, positive=True) if main \
        else None
    zeta = Estimate.of_draws(main.damping_ratio, zeta_draws, reflect=reflect, positive=True) if main \
        else None
    fbsd = {k: Estimate.of_draws(fbsd_values[k], fbsd_draws[k], reflect=reflect, positive=True)
            for k in fbsd_values}
    delay = Estimate.of_draws(ident.delay_samples * dt, delay_draws, reflect=reflect)
    terms = _term_estimates(ident, fits, good, reflect)

    # -- the peak figures: fresh noise around the peaks ---------------------------------------
    peaks = _peak_figures(ctx, reduction, options, rng, inflate, reference_factor, gain_factor, added_shock)

    # -- budget -------------------------------------------------------------------------------
    nominal = {"dc_gain": model.dc_gain, "natural_frequency_hz": main.natural_frequency_hz if main else None,
               "damping_ratio": main.damping_ratio if main else None,
               **{f"fbsd_{k}_hz": v for k, v in fbsd_values.items()}}
    draws_by_figure = {"dc_gain": dc_draws, "natural_frequency_hz": fn_draws, "damping_ratio": zeta_draws,
                       **{f"fbsd_{k}_hz": fbsd_draws[k] for k in fbsd_values}}
    budget = _budget(ident, ctx, options, inflate, nominal, draws_by_figure, orders["per_draw"], good,
                     peaks.get("shares", {}), nominal_branch, bands.per_draw, type_b,
                     {**nominal, "shock_sensitivity": shock_value})
    order_info = {"chosen": n_hat, "selection": ident.order_selection, "fraction_by_order": orders["fractions"],
                  "draws": orders["decided"]}
    stability = orders["fractions"].get(str(n_hat))
    flagged = any(f.code == FindingCode.ORDER_UNSTABLE for f in ident.findings)
    if stability is not None and orders["decided"] and stability < ORDER_STABILITY_WARNING and not flagged:
        findings.append(Finding(
            FindingCode.ORDER_UNSTABLE,
            f"the order choice is not stable under the record's own noise: order {n_hat} is chosen in only "
            f"{stability:.0%} of {orders['decided']} noise draws ({fractions_text(orders['fractions'])}); the "
            "intervals include the other orders"
        ))
    return UncertaintyResult(
        draws=int(np.sum(good)), coverage_probability=COVERAGE, seed=seed, dc_gain=dc,
        shock_sensitivity=peaks.get("shock_sensitivity"), natural_frequency_hz=fn, damping_ratio=zeta,
        fbsd_hz=fbsd, delay_s=delay, reference=peaks.get("reference", {}), budget=budget, order=order_info,
        findings=findings, failed_draws=failed, model_draws=model_draws,
        response_band=response_band(model, model_draws, ident.supported_band_hz, reflect[good],
                                    systematic=[row.models for row in type_b if row.models], seed=seed),
        band_tops_hz=bands.tops_hz, input_terms=terms,
    )


def _term_estimates(ident: Identification, fits: list[OrderFit | None], good: np.ndarray, reflect: np.ndarray
                    ) -> dict[str, Estimate]:
    """ε and γ (analysis.input_terms) with their uncertainty: each draw refits them with the model."""
    out = {}
    ctx = ident.context
    assert ctx is not None
    for name in (ASYMMETRY, MOTION):
        cols = ctx.terms.columns(name)
        value = ident.input_terms.get(name)
        if not cols.size or not isinstance(value, float):
            continue
        k = int(cols[0])
        draws = np.array([f.inputs[k] if f is not None and good[r] and f.inputs.size > k else np.nan
                          for r, f in enumerate(fits)])
        out[name] = Estimate.of_draws(value, draws, reflect=reflect)
    return out


def shot_uncertainty(
    ident: Identification, params: AnalysisParams, reduction: dict[str, Any] | None
) -> tuple[dict[str, Any] | None, list[DiscreteModel], list[Finding]]:
    """The uncertainty of a shot as its JSON, its model draws and its findings; switched off, or
    failed, it is None with a finding that says so: the values stand, never silently without it."""
    if not params.uncertainty:
        return None, [], [Finding(FindingCode.UNCERTAINTY_OFF,
                                  "uncertainty switched off (--no-uncertainty): the figures carry no uncertainty")]
    try:
        result = evaluate(ident, UncertaintyOptions.from_params(params), reduction)
    except (AnalysisError, ValueError, ArithmeticError, np.linalg.LinAlgError) as exc:
        return None, [], [Finding(FindingCode.UNCERTAINTY_FAILED, f"the uncertainty could not be evaluated ({exc}): "
                                                                   "the figures are reported without it")]
    if result.order.get("draws"):  # the order choice's stability, measured by the draws
        ident.order_evidence.setdefault("stability", {"draws": result.order["draws"],
                                                      "fraction_by_order": dict(result.order["fraction_by_order"])})
    return result.to_dict(), result.model_draws, result.findings


# ------------------------------------------------------------------------------ response band
BAND_POINTS = 160


def response_band(model: DiscreteModel, draws: list[DiscreteModel], band_hz: tuple[float, float] | None,
                   reflect: np.ndarray | None = None, points: int = BAND_POINTS,
                   systematic: list[tuple[DiscreteModel, ...]] | None = None, seed: int = 0) -> dict[str, Any] | None:
    """The model's frequency response with its 95 % band, from the same Monte Carlo draws as the
    figures (issue 17): on a log grid from 100 Hz (or the band's start) to twice the supported
    band's top (at most Nyquist), the magnitude relative to the DC gain (each draw relative to
    its own: what a sine calibration normalised at a low frequency compares with) and the whole
    phase in degrees (the fitted delay included), each as value, low and high. The band is the
    draws' probabilistically symmetric interval reflected about the value, as the figures'
    (Estimate.of_draws, `reflect` one flag per draw, None: all; the magnitude on a log scale), so
    it covers the truth as they do. None without draws."""
    if len(draws) < 2 or model.dc_gain == 0:
        return None
    nyquist = 0.5 / model.sample_interval_s
    top = min(0.98 * nyquist, 2.0 * band_hz[1]) if band_hz else 0.5 * nyquist
    f = np.geomspace(max(100.0, band_hz[0]) if band_hz and band_hz[0] > 0 else 100.0, top, points)
    w = 2.0 * np.pi * f * model.sample_interval_s

    def whole(m: DiscreteModel) -> np.ndarray:
        return frequency_response(m, f) * np.exp(-1j * w * m.delay_samples) / m.dc_gain

    nominal = whole(model)
    flags = np.ones(len(draws), dtype=bool) if reflect is None else np.asarray(reflect, dtype=bool)
    usable = np.array([m.dc_gain != 0 for m in draws])
    stack = np.array([whole(m) for m, ok in zip(draws, usable, strict=True) if ok])
    sign = np.where(flags[usable], -1.0, 1.0)[:, None]  # a reflected draw's deviation counts mirrored
    tail = 50.0 * (1.0 - COVERAGE)
    centre = np.log(np.abs(nominal))
    d_mag = sign * (np.log(np.abs(stack)) - centre)
    dphase = sign * np.degrees(np.angle(stack / nominal))  # each draw's phase about the nominal, wrapped
    # The Type B rows' variants (analysis.systematics): each draw takes each row's widest variant's
    # departure from the nominal times a shared ξ ~ U(−1, 1), as the figures take its shifts.
    rng = np.random.default_rng([seed, 40])
    for variants in systematic or []:
        shapes = [whole(m) / nominal for m in variants if m.dc_gain != 0]
        if not shapes:
            continue
        widest = max(shapes, key=lambda r: float(np.max(np.abs(np.log(np.abs(r))))))
        xi = rng.uniform(-1.0, 1.0, (d_mag.shape[0], 1))
        d_mag = d_mag + xi * np.log(np.abs(widest))[None, :]
        dphase = dphase + xi * np.degrees(np.angle(widest))[None, :]
    lo_m, hi_m = np.percentile(d_mag, [tail, 100.0 - tail], axis=0)
    lo_p, hi_p = np.percentile(dphase, [tail, 100.0 - tail], axis=0)
    phase = np.degrees(np.unwrap(np.angle(nominal)))

    def floats(x: np.ndarray) -> list[float]:
        return [float(v) for v in x]

    return {"frequency_hz": floats(f), "coverage_probability": COVERAGE,
            "magnitude_rel": floats(np.exp(centre)), "magnitude_rel_low": floats(np.exp(centre + lo_m)),
            "magnitude_rel_high": floats(np.exp(centre + hi_m)),
            "phase_deg": floats(phase), "phase_low_deg": floats(phase + lo_p), "phase_high_deg": floats(phase + hi_p)}


# ------------------------------------------------------------------------------ noise
def _noise_inflation(ctx: FitContext, order: int) -> float:
    """V per degree of freedom when significantly above 1 (model error), else 1."""
    dof = 2 * ctx.spectral.bins - ctx.fits[order].parameters
    ratio = ctx.model_error_ratio
    if dof > 0 and ratio > 1.0 + 3.0 * math.sqrt(2.0 / dof):
        return float(ratio)
    return 1.0


def _chain_draws(options: UncertaintyOptions, count: int, rng: np.random.Generator) -> dict[str, np.ndarray]:
    """Scale factors of each channel per draw: Π (1 + δ_source), δ ~ N(0, u_rel²)."""
    out = {"reference": np.ones(count), "response": np.ones(count)}
    for u_rel, channel in options.chain().values():
        out[channel] = out[channel] * (1.0 + u_rel * rng.standard_normal(count))
    return out


# ------------------------------------------------------------------------------ refits
def _order_assignment(ident: Identification, draws: NoiseDraws, refitter: Refitter, options: UncertaintyOptions,
                      rng: np.random.Generator) -> dict[str, Any]:
    """The order of each draw, drawn from the order choice's own PDF: the whole choice re-run on
    `order_draws` parametric-bootstrap draws (the chosen model's response with fresh noise of
    the record's level). An asked order is kept in every draw."""
    ctx = ident.context
    assert ctx is not None
    n_hat = ident.order
    count = options.draws
    # An order whose fit holds a pole–zero doublet is no candidate (identify's own rule: the fit
    # following a ripple of the data): drawn, its sharp ripple (ζ ~ 0.002) moved the FBSD edges of
    # PTB's hybrids by half (order 4 in 42 % of the draws, the ±10 % interval 16.2–31.3 kHz).
    candidates = [m for m in candidates_around(n_hat, ctx.fits) if math.isfinite(ctx.fits[m].cost)
                  and (m == n_hat or not has_doublet(ctx.fits[m].a, ctx.fits[m].b))]
    if ident.order_selection not in ("order_test", "knee") or len(candidates) < 2:
        return {"per_draw": [n_hat] * count, "fractions": {}, "decided": 0}
    bootstrap = replace(draws, seed=draws.seed + 1, skew_sd=0.0,
                        centre_y=predicted_bins(ctx.fits[n_hat], ctx.spectral, draws.omega, ctx.u_bins))
    subset = min(options.order_draws, count)
    fractions, choices, _ = order_stability(bootstrap, refitter, candidates, subset, ctx.significance)
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


def _band_variants(ctx: FitContext, refitter: Refitter, orders: list[int], rng: np.random.Generator
                   ) -> BandVariants:
    """The band's parts each draw is refitted on: only the whole band unless the model error is
    detected (the residual then holds structure the model does not follow); a part is used when
    every order drawn can be refitted there (`_refitter_on`). Each draw takes a part at random and
    a reflection flag at even odds."""
    count = len(orders)
    omega_max, refitters = [math.inf], [refitter]
    top = float(np.max(ctx.spectral.omega))
    for fraction in BAND_TOPS[1:] if ctx.model_error_detected else ():
        part = ctx.spectral.below(fraction * top)
        prepared = _refitter_on(part, ctx, sorted(set(orders)))
        if prepared is not None:
            omega_max.append(fraction * top)
            refitters.append(prepared)
    if len(refitters) == 1:
        return BandVariants(omega_max, refitters, [], np.zeros(count, dtype=int), np.zeros(count, dtype=bool))
    tops_hz = [w / (2.0 * math.pi * ctx.sample_interval_s) for w in omega_max[1:]]
    return BandVariants(omega_max, refitters, tops_hz, rng.integers(0, len(refitters), count), rng.random(count) < 0.5)


def _refitter_on(part: SpectralData, ctx: FitContext, orders: list[int]) -> Refitter | None:
    """A refitter of `orders` on a part of the band, each order (and each of its delay branches)
    refitted there from its nominal fit; None when an order is missing, has fewer real residuals
    (two per bin) than twice its parameters there, or refits unstably."""
    fits, branches = {}, {}
    for n in orders:
        if n not in ctx.fits or part.bins < ctx.fits[n].parameters:
            return None
        refit = [OrderProblem.for_fit(part, f, ctx.delay_mode, ctx.max_delay).solve(f, 200, 1e-9)
                 for f in (ctx.fits[n], *ctx.branches.get(n, []))]
        if not all(is_stable(f.a) for f in refit):
            return None
        fits[n], branches[n] = refit[0], refit[1:]
    return Refitter(part, fits, ctx.delay_mode, ctx.max_delay, branches)


def _refits(draws: NoiseDraws, bands: BandVariants, orders: list[int]
            ) -> tuple[list[OrderFit | None], np.ndarray, np.ndarray]:
    """One refit per draw at its order, on the record with fresh noise and a skew, over its part
    of the band; each draw's skew (samples) and the delay branch it landed on (0: the nominal
    fit's)."""
    fits: list[OrderFit | None] = []
    skews = np.zeros(len(orders))
    branch = np.zeros(len(orders), dtype=int)
    for r, order in enumerate(orders):
        data, skews[r] = draws.data(r)
        v = int(bands.per_draw[r])
        if v:
            data = data.below(bands.omega_max[v])
        fit, branch[r] = bands.refitters[v].fit_branch(data, order)
        fits.append(fit)
    return fits, skews, branch


def _nearest_mode(a: np.ndarray, pole: complex, dt: float) -> tuple[float, float]:
    """(f_n, ζ) of the draw's pole nearest (s-plane) to the nominal main pole: the same mode."""
    roots = np.roots(a)
    roots = roots[roots.imag > 0]
    if roots.size == 0:
        return math.nan, math.nan
    s = np.log(roots) / dt
    target = np.log(pole) / dt
    nearest = s[int(np.argmin(np.abs(s - target)))]
    wn = abs(nearest)
    return float(wn / (2 * np.pi)), float(-nearest.real / wn)


def _fbsd_draws(fits: list[OrderFit | None], good: np.ndarray, nominal: dict, dt: float) -> dict[str, np.ndarray]:
    """Each draw's first crossing of 1 ± level by |H/H(0)| on a common grid (linear interpolation
    between grid points); the draws of one order are evaluated together."""
    reached = [e.frequency_hz for e in nominal.values() if e.reached]
    nyquist = 0.5 / dt
    f_max = min(nyquist, 2.5 * max(reached)) if reached else nyquist
    freq = np.linspace(0.0, f_max, FBSD_GRID)
    omega = 2.0 * np.pi * freq * dt
    out = {key: np.full(len(fits), np.nan) for key in nominal}
    by_size: dict[int, list[int]] = {}
    for r, f in enumerate(fits):
        if f is not None and good[r]:
            by_size.setdefault(f.a.size, []).append(r)
    for size, rows in by_size.items():
        z = np.exp(-1j * np.outer(omega, np.arange(size)))
        a = np.array([fits[r].a for r in rows]).T  # type: ignore[union-attr]
        b = np.array([np.pad(fits[r].b, (0, size - fits[r].b.size)) for r in rows]).T  # type: ignore[union-attr]
        h = (z @ b) / (z @ a)
        g = np.abs(h / h[0])  # (grid, draws)
        for key, edge in nominal.items():
            outside = np.abs(g - 1.0) > edge.level
            first = np.argmax(outside, axis=0)
            none = ~outside[first, np.arange(len(rows))] | (first == 0)
            i = np.maximum(first, 1)
            cols = np.arange(len(rows))
            gi, gp = g[i, cols], g[i - 1, cols]
            target = np.where(gi > 1.0, 1.0 + edge.level, 1.0 - edge.level)
            frac = (target - gp) / (gi - gp)
            crossing = freq[i - 1] + frac * (freq[1] - freq[0])
            out[key][rows] = np.where(none, f_max, crossing)
    return out


# ------------------------------------------------------------------------------ peak figures
def _peak_figures(
    ctx: FitContext, reduction: dict[str, Any] | None, options: UncertaintyOptions, rng: np.random.Generator,
    inflate: float, reference_factor: np.ndarray, gain_factor: np.ndarray, added_shock: np.ndarray | None = None,
) -> dict[str, Any]:
    """Shock sensitivity, peak acceleration and pulse width: the same estimators on the record
    with fresh noise around the peaks; peak velocity from the reduction's plateau fit."""
    record = ctx.record
    ref = np.asarray(record.reference, dtype=float)
    resp = np.asarray(record.response, dtype=float)
    count = options.draws
    noise_u = ctx.noise_u.scaled(ctx.scale_u)
    noise_y = ctx.noise_y.scaled(ctx.scale_y)
    dt = record.sample_interval_s
    try:
        pulse = pulse_width(ref, dt)
    except AnalysisError:
        return {}
    i_ref = int(np.argmax(np.abs(ref)))
    i_resp = int(np.argmax(np.abs(resp)))
    width = max(1, int(round(pulse.width_s / dt)))
    half = max(PEAK_SEGMENT // 2, 3 * width)
    seg_u = slice(max(0, i_ref - half), min(ref.size, i_ref + half))
    seg_y = slice(max(0, i_resp - PEAK_SEGMENT // 2), min(resp.size, i_resp + PEAK_SEGMENT // 2))
    scale_n = math.sqrt(inflate)
    nu = noise_u.draw(seg_u.stop - seg_u.start, rng, count, uncertain_level=True) * scale_n
    ny = noise_y.draw(seg_y.stop - seg_y.start, rng, count, uncertain_level=True) * scale_n
    u0, y0 = ref[seg_u], resp[seg_y]
    pu0, py0 = peak_estimate(u0)[0], peak_estimate(y0)[0]
    # Each draw's peaks keep the nominal's polarity: a response ringing at its mode, or a bar's
    # bipolar reference, has an opposite extreme nearly as large (the simulator's bonded shots:
    # +604 / −579 km/s², noise 3–8 % of it), and a draw that took it gave a ratio of the other
    # sign: bimodal draws, a u of 30–100 % (tests/analysis/test_linearity.py failed on them).
    peak_y = np.array([peak_estimate(y0 + ny[r], polarity=py0)[0] for r in range(count)])
    peak_u, widths = np.empty(count), np.full(count, np.nan)
    for r in range(count):
        u = u0 + nu[r]
        try:  # the width's own peak is the reference's peak (the same estimator on the same draw)
            drawn = pulse_width(u, dt, polarity=pu0)
            peak_u[r], widths[r] = drawn.peak_m_s2, drawn.width_s
        except AnalysisError:
            peak_u[r] = peak_estimate(u, polarity=pu0)[0]
    reduction = reduction or {}
    ss_value = reduction.get("shock_sensitivity", py0 / pu0)
    ss = peak_y / peak_u * gain_factor / (py0 / pu0) * ss_value
    if added_shock is not None:  # the Type B inputs' shifts (analysis.systematics)
        ss = ss + added_shock
    out: dict[str, Any] = {"shock_sensitivity": Estimate.of_draws(ss_value, ss, signed=True)}
    acc_value = reduction.get("peak_acceleration_m_s2", pu0)
    reference = {
        "peak_acceleration_m_s2": Estimate.of_draws(acc_value, peak_u * reference_factor / pu0 * acc_value),
        "pulse_width_s": Estimate.of_draws(reduction.get("pulse_width_s", pulse.width_s),
                                           widths / pulse.width_s * reduction.get("pulse_width_s", pulse.width_s)),
    }
    velocity = reduction.get("peak_velocity_m_s")
    if velocity is not None:
        u_noise = float(reduction.get("peak_velocity_noise_u_m_s") or 0.0)
        u_chain = abs(velocity) * math.hypot(options.u_grating_pitch_rel, options.u_interferometer_rel)
        reference["peak_velocity_m_s"] = Estimate.normal(velocity, math.hypot(u_noise, u_chain))
    out["reference"] = reference
    # Shares of each channel's noise in the shock sensitivity (for the budget).
    only_u = py0 / peak_u
    only_y = peak_y / pu0
    out["shares"] = {"shock_sensitivity": {
        "reference noise": float(np.nanstd(only_u) / abs(py0 / pu0)),
        "response noise": float(np.nanstd(only_y) / abs(py0 / pu0)),
    }}
    return out


# ------------------------------------------------------------------------------ budget
def _budget(
    ident: Identification, ctx: FitContext, options: UncertaintyOptions, inflate: float,
    nominal: dict[str, float | None], draws: dict[str, np.ndarray], orders: list[int], good: np.ndarray,
    peak_shares: dict[str, dict[str, float]], nominal_branch: np.ndarray, band_variant: np.ndarray,
    type_b: list[TypeB] | None = None, nominal_with_shock: dict[str, float | None] | None = None,
) -> list[dict[str, Any]]:
    """Relative standard uncertainty of each figure by source (see the module docstring), each
    row with its kind: "Type A" (the record's noise, the fit's scatter) or "Type B"."""
    shares = _linear_noise_shares(ident, ctx, options, inflate, nominal)
    for figure, by_source in peak_shares.items():
        for source, u_rel in by_source.items():
            shares.setdefault(source, {})[figure] = u_rel
    n_hat = ident.order

    def added(among: np.ndarray, within: np.ndarray) -> dict[str, float]:
        """Each figure's relative standard uncertainty the draws `among` hold beyond `within`."""
        out: dict[str, float] = {}
        for figure, values in draws.items():
            ref = nominal.get(figure)
            if ref is None or not ref or within.sum() < 2:
                continue
            total, inner = np.nanvar(values[among]), np.nanvar(values[within])
            out[figure] = math.sqrt(max(total - inner, 0.0)) / abs(ref) if np.isfinite(total) else math.nan
        return out

    fixed = np.array([m == n_hat for m in orders]) & good
    shares["order choice"] = added(good, fixed)
    sources = ["response noise", "reference noise", "channel skew", "order choice"]
    if ctx.model_error_detected:
        sources.insert(2, "model error")  # the residual the noise does not explain (identify.ModelError)
    if ctx.spectral.sine is not None:
        sources.insert(2, "sine calibration")
    if not nominal_branch[fixed].all():  # the delay branch: the variance the other branches add
        shares["delay branch"] = added(fixed, fixed & nominal_branch)
        sources.append("delay branch")
    if np.any(band_variant[fixed] > 0):  # the band's parts: the variance the model's bending adds (Type B)
        shares[MODEL_ERROR_BOUND] = added(fixed, fixed & (band_variant == 0))
        sources.append(MODEL_ERROR_BOUND)
    for source, (u_rel, channel) in options.chain().items():
        figures = {"dc_gain": u_rel, "shock_sensitivity": u_rel}
        if channel == "reference":
            figures["peak_acceleration_m_s2"] = u_rel
        shares[source] = figures
    sources += [source for source in shares if source.endswith("(fitted)")]
    for row in type_b or []:
        if row.shift_by_figure:  # (the band's parts' row has no shifts: the draws carry it, above)
            shares[row.source] = row.u_rel_by_figure(nominal_with_shock or nominal)
            sources.append(row.source)
    notes = {row.source: row.note for row in type_b or []}
    type_b_sources = {*notes, "grating pitch", "interferometer", "amplifier gain", "digitizer gain", "channel skew",
                      MODEL_ERROR_BOUND}
    out = []
    for source in (*sources, "grating pitch", "interferometer", "amplifier gain", "digitizer gain"):
        figures = {k: _finite(v) for k, v in shares.get(source, {}).items()}
        row = {"source": source, "u_rel": figures.get("dc_gain"), "u_rel_by_figure": figures,
               "kind": "Type B" if source in type_b_sources else "Type A"}
        if source in notes:
            row["note"] = notes[source]
        out.append(row)
    return out


def _linear_noise_shares(
    ident: Identification, ctx: FitContext, options: UncertaintyOptions, inflate: float,
    nominal: dict[str, float | None],
) -> dict[str, dict[str, float]]:
    """Each noise source and the skew through the fit's Jacobian: Cov_i = H⁻¹ Jᵀ D_i J H⁻¹ with
    D_i the share of source i in each residual's variance; u = |∂figure/∂θ|_Cov."""
    n = ident.order
    fit = ctx.fits[n]
    data = ctx.spectral
    problem = OrderProblem.for_fit(data, fit, ctx.delay_mode, ctx.max_delay)
    theta = problem.pack(fit)
    jac = problem.jacobian(theta)
    pieces = problem._pieces(theta)
    s2 = pieces["s2"]  # each residual's variance as the fit weighs it (the conservative look)
    # The variance each source really gives each residual, over the weight: the noise measured
    # without bias (what the draws add), in the fit's layout (per bin or per group of bins).
    var_u, var_y = data.in_layout(ctx.var_u), data.in_layout(ctx.var_y)
    rows = 3 if data.grouped else 2
    d_u = np.tile(np.abs(pieces["G"]) ** 2 * var_u / s2, rows)
    var_me = (np.zeros_like(var_y) if ctx.var_model_error is None
              else data.in_layout(ctx.var_model_error))
    d_y = np.tile((var_y - var_me) / s2, rows)
    d_me = np.tile(var_me / s2, rows)
    # the input terms' prior rows (frequency_fit), then a sine calibration's residuals (analysis.sine_joint), last
    sine_rows = jac.shape[0] - d_u.size - problem.n_prior
    pad = (0, problem.n_prior + sine_rows)
    d_u, d_y, d_me = np.pad(d_u, pad), np.pad(d_y, pad), np.pad(d_me, pad)
    h_inv = np.linalg.pinv(jac.T @ jac)
    proj = h_inv @ jac.T
    cov = {"reference noise": inflate * (proj * d_u) @ proj.T, "response noise": inflate * (proj * d_y) @ proj.T,
           "model error": inflate * (proj * d_me) @ proj.T}
    if sine_rows:  # each sine residual's variance under the draws: its weight² (SineTerms)
        d_s = np.concatenate((np.zeros(d_u.size - sine_rows), np.full(sine_rows, data.sine.weight ** 2)))
        cov["sine calibration"] = (proj * d_s) @ proj.T
    # The skew: the residual's change per sample of reference delay, through the same projection.
    eps = 1e-3
    shifted = _shift_data(data, eps)
    dr = (OrderProblem.for_fit(shifted, fit, ctx.delay_mode, ctx.max_delay).residual(theta) - problem.residual(theta)) / eps
    skew_step = -(proj @ dr) * (options.channel_skew_s / ctx.sample_interval_s)
    gradients = _figure_gradients(problem, theta, ctx, ident, nominal)
    out: dict[str, dict[str, float]] = {source: {} for source in (*cov, "channel skew")}
    for figure, g in gradients.items():
        ref = nominal.get(figure)
        if ref is None or not ref or g is None:
            continue
        for source, c in cov.items():
            out[source][figure] = math.sqrt(max(float(g @ c @ g), 0.0)) / abs(ref)
        out["channel skew"][figure] = abs(float(g @ skew_step)) / abs(ref)
    if problem.n_inputs:  # the fitted corrections' shares (analysis.systematics)
        out.update(fitted_shares(jac, gradients, nominal, problem._k_inputs, ctx.terms, inflate))
    return out


def _shift_data(data: SpectralData, samples: float) -> SpectralData:
    """The same data with the reference delayed by `samples` (per-bin or grouped)."""
    phase = np.exp(-1j * data.omega * samples)
    if data.grouped:
        return replace(data, syu=data.syu * np.conj(phase))
    assert data.u is not None
    u = data.u * phase
    return replace(data, u=u, syu=data.y * np.conj(u))


def _figure_gradients(
    problem: OrderProblem, theta: np.ndarray, ctx: FitContext, ident: Identification,
    nominal: dict[str, float | None],
) -> dict[str, np.ndarray | None]:
    """∂figure/∂θ by central differences (figures of the model built from θ)."""
    main = ident.main_mode
    pole = main.pole_z if main else None
    dt = ctx.sample_interval_s
    scale = ctx.scale_y / ctx.scale_u

    def figures(th: np.ndarray) -> dict[str, float]:
        a, b, tau, _, _ = problem.unpack(th)
        mean = ctx.terms.mean_gain_factor(problem.input_coefficients(th))  # the mean of both directions
        out = {"dc_gain": float(np.sum(b) * scale * mean / np.sum(a))}
        if pole is not None:
            out["natural_frequency_hz"], out["damping_ratio"] = _nearest_mode(a, pole, dt)
        try:
            for key, edge in fbsd_edges(DiscreteModel(dt, a, b * scale, ctx.model_delay(tau))).items():
                out[f"fbsd_{key}_hz"] = edge.frequency_hz
        except AnalysisError:
            pass
        return out

    grads: dict[str, list[float]] = {k: [] for k in nominal}
    for i in range(theta.size):
        h = 1e-6 * max(abs(theta[i]), 1e-3)
        up, down = theta.copy(), theta.copy()
        up[i] += h
        down[i] -= h
        fu, fd = figures(up), figures(down)
        for k in grads:
            grads[k].append((fu.get(k, math.nan) - fd.get(k, math.nan)) / (2 * h))
    return {k: (np.array(v) if np.all(np.isfinite(v)) else None) for k, v in grads.items()}


# ------------------------------------------------------------------------------ helpers
def _finite(value: float | None) -> float | None:
    return float(value) if value is not None and math.isfinite(value) else None
