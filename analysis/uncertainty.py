"""GUM Supplement 1 Monte Carlo uncertainty of a shot's key figures.

`evaluate(ident, options)` draws every input once (analysis.uncertainty_draws: noise on the
fitted bins, the skew, the reference chain, the order, the band's part), re-runs the settle
stage per draw (a refit at the drawn order from every delay branch), and gives each figure an
`Estimate` (value: the nominal figure; u: the draws' standard deviation; the probabilistically
symmetric 95 % interval reflected about the value), the budget (analysis.uncertainty_budget)
and the model's response band. Figures: the DC gain, the ISO 16063-13 shock sensitivity, the
main mode's f_n (Hz) and ζ, both FBSD edges (Hz), the delay (s), the reference's peak
acceleration (m/s²), pulse width (s) and peak velocity (m/s).

Why: docs/decisions/0014; the inputs, PDFs and measured coverage: docs/method.md#uncertainty.
Validated by coverage over many seeds against known truths (tests/analysis/test_uncertainty.py).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from hopkinson.analysis.errors import AnalysisError
from hopkinson.analysis.estimate import COVERAGE, Estimate, coverage_ends
from hopkinson.analysis.excitation import (
    glitch_window,
    peak_estimate,
    pulse_peak_index,
    pulse_width,
)
from hopkinson.analysis.findings import Finding, FindingCode, texts
from hopkinson.analysis.frequency_fit import OrderFit, is_stable
from hopkinson.analysis.identify import (
    Identification,
)
from hopkinson.analysis.input_terms import ASYMMETRY, MOTION
from hopkinson.analysis.model import DiscreteModel
from hopkinson.analysis.options import AnalysisOptions
from hopkinson.analysis.order_choice import (
    ORDER_STABILITY_WARNING,
    NoiseDraws,
    fractions_text,
)
from hopkinson.analysis.response import fbsd_edges, frequency_response

if TYPE_CHECKING:
    from hopkinson.analysis.uncertainty_draws import BandVariants

METHOD = "GUM Supplement 1 Monte Carlo (refit per draw)"
FBSD_GRID = 2000
PEAK_SEGMENT = 256  # samples around a peak that get fresh noise for the peak figures
# Below this share of stable refits the draws cannot stand for the estimator.
MIN_GOOD_FRACTION = 0.9


@dataclass
class UncertaintyResult:
    """The Monte Carlo result: figures, budget, order stability; `to_dict()` is the results'
    "uncertainty" object (docs/files-and-formats.md)."""

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
    options: AnalysisOptions | None = None,
    reduction: dict[str, Any] | None = None,
) -> UncertaintyResult:
    """Monte Carlo uncertainty of `ident`'s figures (and of `reduction`'s, when given)."""
    # Imported here, not at the top: `hopkinson identify --no-uncertainty` never evaluates, and these
    # modules (the systematic rows, the draws, the budget) are a sixth of the analysis' import time.
    from hopkinson.analysis.input_terms import ASYMMETRY
    from hopkinson.analysis.systematics import one_direction_row, transverse_row, variant_bounds
    from hopkinson.analysis.uncertainty_budget import budget, nearest_mode
    from hopkinson.analysis.uncertainty_draws import draw

    options = AnalysisOptions() if options is None else options
    if options.draws < 2:
        raise AnalysisError(f"uncertainty: at least 2 draws are needed, got {options.draws}")
    seed = options.seed if options.seed is not None else int(np.random.SeedSequence().entropy % 2**63)
    rng = np.random.default_rng(seed)
    findings: list[Finding] = []
    n_hat = ident.order
    dt = ident.sample_interval_s
    drawn = draw(ident, options, seed, rng)
    inflate, orders, bands = drawn.inflate, drawn.orders, drawn.bands
    response_factor, reference_factor = drawn.chain["response"], drawn.chain["reference"]
    gain_factor = response_factor / reference_factor

    # -- the model figures: the settle stage re-run per draw ---------------------------------
    fits, skews, branch, per_draw = _refits(drawn.noise, bands, orders["per_draw"], n_hat)
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
    scale = ident.prepared.scale_y / ident.prepared.scale_u
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
        b = f.b * scale * gain_factor[r] * ident.prep.terms.mean_gain_factor(f.inputs)  # the mean of both directions
        dc_draws[r] = float(np.sum(b) / np.sum(f.a))
        delay_draws[r] = (ident.prepared.model_delay(f.delay) - skews[r]) * dt
        # fitted with a sine calibration: the sine's level ÷ the model's (analysis.sine_joint)
        info = {"sine_gain_ratio": math.exp(f.sine_gain) / (scale * gain_factor[r])} if ident.settlement.data.sine else {}
        model_draws.append(DiscreteModel(dt, f.a, b, ident.prepared.model_delay(f.delay), info=info))
        if main_pole is not None:
            fn_draws[r], zeta_draws[r] = nearest_mode(f.a, main_pole, dt)
    nominal_edges = fbsd_edges(model)
    fbsd_values = {k: e.frequency_hz for k, e in nominal_edges.items()}
    fbsd_draws = _fbsd_draws(fits, good, nominal_edges, dt)
    # The Type B inputs (analysis.systematics): each a rectangular shift added to every draw.
    shock_value = (reduction or {}).get("shock_sensitivity")
    type_b = variant_bounds(ident, inflate)
    transverse = transverse_row(model.dc_gain, shock_value, options.transverse_sensitivity_rel,
                                options.transverse_motion_rel)
    type_b += [transverse] if transverse is not None else []
    if ASYMMETRY in ident.prep.terms.not_fitted and ASYMMETRY not in ident.prep.unseen:  # one direction driven
        one_direction = one_direction_row(model.dc_gain, shock_value, options.asymmetry_bound_rel)
        type_b += [one_direction] if one_direction is not None else []
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
    peaks = _peak_figures(ident, reduction, options, rng, inflate, reference_factor, gain_factor, added_shock)

    # -- budget -------------------------------------------------------------------------------
    nominal = {"dc_gain": model.dc_gain, "natural_frequency_hz": main.natural_frequency_hz if main else None,
               "damping_ratio": main.damping_ratio if main else None,
               **{f"fbsd_{k}_hz": v for k, v in fbsd_values.items()}}
    draws_by_figure = {"dc_gain": dc_draws, "natural_frequency_hz": fn_draws, "damping_ratio": zeta_draws,
                       **{f"fbsd_{k}_hz": fbsd_draws[k] for k in fbsd_values}}
    figure_budget = budget(ident, options, inflate, nominal, draws_by_figure, per_draw, good,
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
        fbsd_hz=fbsd, delay_s=delay, reference=peaks.get("reference", {}), budget=figure_budget, order=order_info,
        findings=findings, failed_draws=failed, model_draws=model_draws,
        response_band=response_band(model, model_draws, ident.supported_band_hz, reflect[good],
                                    systematic=[row.models for row in type_b if row.models],
                                    systematic_scales=[row.band_scale for row in type_b if row.models], seed=seed),
        band_tops_hz=bands.tops_hz, input_terms=terms,
    )


def _term_estimates(ident: Identification, fits: list[OrderFit | None], good: np.ndarray, reflect: np.ndarray
                    ) -> dict[str, Estimate]:
    """ε and γ (analysis.input_terms) with their uncertainty: each draw refits them with the model."""
    out = {}
    for name in (ASYMMETRY, MOTION):
        cols = ident.prep.terms.columns(name)
        value = ident.input_terms.get(name)
        if not cols.size or not isinstance(value, float):
            continue
        k = int(cols[0])
        draws = np.array([f.inputs[k] if f is not None and good[r] and f.inputs.size > k else np.nan
                          for r, f in enumerate(fits)])
        out[name] = Estimate.of_draws(value, draws, reflect=reflect)
    return out


def shot_uncertainty(
    ident: Identification, params: AnalysisOptions, reduction: dict[str, Any] | None
) -> tuple[dict[str, Any] | None, list[DiscreteModel], list[Finding]]:
    """The uncertainty of a shot as its JSON, its model draws and its findings; switched off, or
    failed, it is None with a finding that says so: the values stand, never silently without it."""
    if not params.uncertainty:
        return None, [], [Finding(FindingCode.UNCERTAINTY_OFF,
                                  "uncertainty switched off (--no-uncertainty): the figures carry no uncertainty")]
    try:
        result = evaluate(ident, params, reduction)
    except (AnalysisError, ValueError, ArithmeticError, np.linalg.LinAlgError) as exc:
        return None, [], [Finding(FindingCode.UNCERTAINTY_FAILED, f"the uncertainty could not be evaluated ({exc}): "
                                                                   "the figures are reported without it")]
    return result.to_dict(), result.model_draws, result.findings


# ------------------------------------------------------------------------------ response band
BAND_POINTS = 160


def response_band(model: DiscreteModel, draws: list[DiscreteModel], band_hz: tuple[float, float] | None,
                   reflect: np.ndarray | None = None, points: int = BAND_POINTS,
                   systematic: list[tuple[DiscreteModel, ...]] | None = None, seed: int = 0,
                   systematic_scales: list[float] | None = None) -> dict[str, Any] | None:
    """The model's frequency response with its 95 % band, from the same Monte Carlo draws as the
    figures: on a log grid from 100 Hz (or the band's start) to twice the supported
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
    centre = np.log(np.abs(nominal))
    d_mag = sign * (np.log(np.abs(stack)) - centre)
    dphase = sign * np.degrees(np.angle(stack / nominal))  # each draw's phase about the nominal, wrapped
    # The Type B rows' variants (analysis.systematics): each draw takes each row's widest variant's
    # departure from the nominal times a shared ξ ~ U(−1, 1), as the figures take its shifts.
    rng = np.random.default_rng([seed, 40])
    scales = systematic_scales if systematic_scales is not None else [1.0] * len(systematic or [])
    for variants, scale in zip(systematic or [], scales, strict=True):
        shapes = [whole(m) / nominal for m in variants if m.dc_gain != 0]
        if not shapes:
            continue
        widest = max(shapes, key=lambda r: float(np.max(np.abs(np.log(np.abs(r))))))
        xi = scale * rng.uniform(-1.0, 1.0, (d_mag.shape[0], 1))  # × 1.0 is exact: a row drawn whole is unchanged
        d_mag = d_mag + xi * np.log(np.abs(widest))[None, :]
        dphase = dphase + xi * np.degrees(np.angle(widest))[None, :]
    lo_m, hi_m = coverage_ends(d_mag, COVERAGE, axis=0)
    lo_p, hi_p = coverage_ends(dphase, COVERAGE, axis=0)
    phase = np.degrees(np.unwrap(np.angle(nominal)))

    def floats(x: np.ndarray) -> list[float]:
        return [float(v) for v in x]

    return {"frequency_hz": floats(f), "coverage_probability": COVERAGE,
            "magnitude_rel": floats(np.exp(centre)), "magnitude_rel_low": floats(np.exp(centre + lo_m)),
            "magnitude_rel_high": floats(np.exp(centre + hi_m)),
            "phase_deg": floats(phase), "phase_low_deg": floats(phase + lo_p), "phase_high_deg": floats(phase + hi_p)}


def _refits(draws: NoiseDraws, bands: BandVariants, orders: list[int], chosen: int
            ) -> tuple[list[OrderFit | None], np.ndarray, np.ndarray, list[int]]:
    """One refit per draw at its order, on the record with fresh noise and a skew, over its part
    of the band; each draw's skew (samples), the delay branch it landed on (0: the nominal
    fit's) and the order it was refitted at. A draw whose order is not the `chosen` one and whose
    refit there has a real pole the data cannot place (Refitter.places) is refitted at the chosen
    order: the order test would not choose such a fit (order_search._candidate_cost), and its
    pole near DC takes the DC gain anywhere (a 70 kHz sensor behind PTB's pulse: poles at 0–3 Hz,
    the lowest bin at 606 Hz, DC gains −37 … +330× the truth in 7 of 100 draws)."""
    fits: list[OrderFit | None] = []
    skews = np.zeros(len(orders))
    branch = np.zeros(len(orders), dtype=int)
    used = list(orders)
    for r, order in enumerate(orders):
        data, skews[r] = draws.data(r)
        v = int(bands.per_draw[r])
        if v:
            data = data.below(bands.omega_max[v])
        refitter = bands.refitters[v]
        fit, branch[r] = refitter.fit_branch(data, order)
        if order != chosen and fit is not None and not refitter.places(fit):
            used[r] = chosen
            fit, branch[r] = refitter.fit_branch(data, chosen)
        fits.append(fit)
    return fits, skews, branch, used


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
    ident: Identification, reduction: dict[str, Any] | None, options: AnalysisOptions, rng: np.random.Generator,
    inflate: float, reference_factor: np.ndarray, gain_factor: np.ndarray, added_shock: np.ndarray | None = None,
) -> dict[str, Any]:
    """Shock sensitivity, peak acceleration and pulse width: the same estimators on the record
    with fresh noise around the peaks; peak velocity from the reduction's plateau fit."""
    record = ident.prepared.record
    ref = np.asarray(record.reference, dtype=float)
    resp = np.asarray(record.response, dtype=float)
    count = options.draws
    noise_u = ident.prep.noise.draw_noise_u.scaled(ident.prepared.scale_u)
    noise_y = ident.claim.response_noise.scaled(ident.prepared.scale_y)
    dt = record.sample_interval_s
    try:
        pulse = pulse_width(ref, dt)
    except AnalysisError:
        return {}
    i_ref = pulse_peak_index(ref, glitch_window(dt))
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


