"""The uncertainty budget (GUM's table): each figure's relative standard uncertainty by source,
from the fit's Jacobian, the reference chain, and the variance each discrete choice adds to the
Monte Carlo draws (analysis.uncertainty; docs/decisions/0014)."""

from __future__ import annotations

import math
from dataclasses import replace
from typing import Any

import numpy as np

from hopkinson.analysis.errors import AnalysisError
from hopkinson.analysis.frequency_fit import OrderFit, OrderProblem
from hopkinson.analysis.identify import Identification
from hopkinson.analysis.model import DiscreteModel
from hopkinson.analysis.options import AnalysisOptions
from hopkinson.analysis.response import edge_gradient, fbsd_edges
from hopkinson.analysis.spectral_data import SpectralData
from hopkinson.analysis.structure import DelayMode
from hopkinson.analysis.systematics import MODEL_ERROR_BOUND, TypeB, fitted_shares


def nearest_mode(a: np.ndarray, pole: complex, dt: float) -> tuple[float, float]:
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


def budget(
    ident: Identification, options: AnalysisOptions, inflate: float,
    nominal: dict[str, float | None], draws: dict[str, np.ndarray], orders: list[int], good: np.ndarray,
    peak_shares: dict[str, dict[str, float]], nominal_branch: np.ndarray, band_variant: np.ndarray,
    type_b: list[TypeB] | None = None, nominal_with_shock: dict[str, float | None] | None = None,
) -> list[dict[str, Any]]:
    """Relative standard uncertainty of each figure by source (see the module docstring), each
    row with its kind: "Type A" (the record's noise, the fit's scatter) or "Type B"."""
    shares = _linear_noise_shares(ident, options, inflate, nominal)
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
    if ident.settlement.model_error_detected:
        sources.insert(2, "model error")  # the residual the noise does not explain (identify.ModelError)
    if ident.settlement.data.sine is not None:
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
    ident: Identification, options: AnalysisOptions, inflate: float,
    nominal: dict[str, float | None],
) -> dict[str, dict[str, float]]:
    """Each noise source and the skew through the fit's Jacobian: Cov_i = H⁻¹ Jᵀ D_i J H⁻¹ with
    D_i the share of source i in each residual's variance; u = |∂figure/∂θ|_Cov."""
    n = ident.order
    fit = ident.settlement.sweep.fits[n]
    data = ident.settlement.data
    problem = OrderProblem.for_fit(data, fit, ident.settlement.sweep.delay_mode, ident.settlement.setup.max_delay)
    theta = problem.pack(fit)
    jac, proj, d_u, d_y, d_me, d_s = _noise_projection(ident, problem, theta)
    cov = {"reference noise": inflate * (proj * d_u) @ proj.T, "response noise": inflate * (proj * d_y) @ proj.T,
           "model error": inflate * (proj * d_me) @ proj.T}
    if d_s is not None:
        cov["sine calibration"] = (proj * d_s) @ proj.T
    # The skew: the residual's change per sample of reference delay, through the same projection.
    eps = 1e-3
    shifted = _shift_data(data, eps)
    dr = (OrderProblem.for_fit(shifted, fit, ident.settlement.sweep.delay_mode, ident.settlement.setup.max_delay).residual(theta) - problem.residual(theta)) / eps
    skew_step = -(proj @ dr) * (options.u_channel_skew_s / ident.sample_interval_s)
    gradients = _figure_gradients(problem, theta, ident, nominal)
    out: dict[str, dict[str, float]] = {source: {} for source in (*cov, "channel skew")}
    for figure, g in gradients.items():
        ref = nominal.get(figure)
        if ref is None or not ref or g is None:
            continue
        for source, c in cov.items():
            out[source][figure] = math.sqrt(max(float(g @ c @ g), 0.0)) / abs(ref)
        out["channel skew"][figure] = abs(float(g @ skew_step)) / abs(ref)
    if problem.n_inputs:  # the fitted corrections' shares (analysis.systematics)
        out.update(fitted_shares(jac, gradients, nominal, problem._k_inputs, ident.prep.terms, inflate))
    return out


def noise_variances(ident: Identification, data: SpectralData, fit: OrderFit, inflate: float,
                    nominal: dict[str, float | None], terms: Any = None,
                    delay_mode: DelayMode | float | None = None) -> dict[str, float]:
    """Each figure's variance under the noise the Monte Carlo draws (both channels, the model
    error, a sine calibration; × `inflate` as the draws), linearised at `fit` on `data` with its
    input `terms` (None: the identification's): what a fit's figures scatter by from the record's
    noise alone (analysis.systematics subtracts it from a variant's shift). `delay_mode`: the one
    the fit was made in (None: the identification's)."""
    mode = ident.settlement.sweep.delay_mode if delay_mode is None else delay_mode
    problem = OrderProblem.for_fit(data, fit, mode, ident.settlement.setup.max_delay)
    theta = problem.pack(fit)
    _, proj, d_u, d_y, d_me, d_s = _noise_projection(ident, problem, theta)
    cov = inflate * (proj * (d_u + d_y + d_me)) @ proj.T
    if d_s is not None:
        cov = cov + (proj * d_s) @ proj.T
    return {k: float(g @ cov @ g) for k, g in _figure_gradients(problem, theta, ident, nominal, terms).items()
            if g is not None}


def _noise_projection(ident: Identification, problem: OrderProblem, theta: np.ndarray
                      ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray | None]:
    """The fit's Jacobian J, the projection (JᵀJ)⁺Jᵀ, and each source's variance per residual over
    its weight: the reference's noise, the response's (less the model error), the model error, and
    a sine calibration's (None without one)."""
    data = problem.data
    jac = problem.jacobian(theta)
    pieces = problem._pieces(theta)
    s2 = pieces["s2"]  # each residual's variance as the fit weighs it (the conservative look)
    # The variance each source really gives each residual, over the weight: the noise measured
    # without bias (what the draws add), in the fit's layout (per bin or per group of bins).
    var_u, var_y = data.in_layout(ident.prep.draw_var_u), data.in_layout(ident.claim.draw_var_y(ident.settlement.model_error))
    rows = 3 if data.grouped else 2
    d_u = np.tile(np.abs(pieces["G"]) ** 2 * var_u / s2, rows)
    var_me = (np.zeros_like(var_y) if ident.settlement.model_error.var_bins is None
              else data.in_layout(ident.settlement.model_error.var_bins))
    d_y = np.tile((var_y - var_me) / s2, rows)
    d_me = np.tile(var_me / s2, rows)
    # the input terms' prior rows (frequency_fit), then a sine calibration's residuals (analysis.sine_joint), last
    sine_rows = jac.shape[0] - d_u.size - problem.n_prior
    pad = (0, problem.n_prior + sine_rows)
    d_u, d_y, d_me = np.pad(d_u, pad), np.pad(d_y, pad), np.pad(d_me, pad)
    h_inv = np.linalg.pinv(jac.T @ jac)
    proj = h_inv @ jac.T
    d_s = None
    if sine_rows:  # each sine residual's variance under the draws: its weight² (SineTerms)
        d_s = np.concatenate((np.zeros(d_u.size - sine_rows), np.full(sine_rows, data.sine.weight ** 2)))
    return jac, proj, d_u, d_y, d_me, d_s


def _shift_data(data: SpectralData, samples: float) -> SpectralData:
    """The same data with the reference delayed by `samples` (per-bin or grouped)."""
    phase = np.exp(-1j * data.omega * samples)
    if data.grouped:
        return replace(data, syu=data.syu * np.conj(phase))
    assert data.u is not None
    u = data.u * phase
    return replace(data, u=u, syu=data.y * np.conj(u))


def _figure_gradients(
    problem: OrderProblem, theta: np.ndarray, ident: Identification,
    nominal: dict[str, float | None], terms: Any = None,
) -> dict[str, np.ndarray | None]:
    """∂figure/∂θ: the DC gain and the main mode's f_n and ζ by central differences (figures of
    the model built from θ), the FBSD edges by implicit differentiation (response.edge_gradient;
    the edges depend on A's and B's parameters only)."""
    main = ident.main_mode
    pole = main.pole_z if main else None
    dt = ident.sample_interval_s
    scale = ident.prepared.scale_y / ident.prepared.scale_u

    def figures(th: np.ndarray) -> dict[str, float]:
        a, b, _, _, _ = problem.unpack(th)
        mean = (terms or ident.prep.terms).mean_gain_factor(problem.input_coefficients(th))  # the mean of both directions
        out = {"dc_gain": float(np.sum(b) * scale * mean / np.sum(a))}
        if pole is not None:
            out["natural_frequency_hz"], out["damping_ratio"] = nearest_mode(a, pole, dt)
        return out

    grads: dict[str, list[float]] = {k: [] for k in nominal if not k.startswith("fbsd_")}
    for i in range(theta.size):
        h = 1e-6 * max(abs(theta[i]), 1e-3)
        up, down = theta.copy(), theta.copy()
        up[i] += h
        down[i] -= h
        fu, fd = figures(up), figures(down)
        for k in grads:
            grads[k].append((fu.get(k, math.nan) - fd.get(k, math.nan)) / (2 * h))
    out: dict[str, np.ndarray | None] = dict.fromkeys(nominal)
    out.update({k: np.array(v) if np.all(np.isfinite(v)) else None for k, v in grads.items()})
    a, b, tau, _, _ = problem.unpack(theta)
    model = DiscreteModel(dt, a, b * scale, ident.prepared.model_delay(tau))
    try:
        edges = fbsd_edges(model)
    except AnalysisError:
        edges = {}
    for k in nominal:
        if not k.startswith("fbsd_"):
            continue
        edge = edges.get(k.removeprefix("fbsd_").removesuffix("_hz"))
        if edge is None:
            continue
        d_a, d_b = edge_gradient(model, edge)
        g = np.zeros(theta.size)
        g[: problem.n] = d_a
        g[problem.n : problem.k_delay] = (d_b * scale) @ problem.b_map
        out[k] = g if np.all(np.isfinite(g)) else None
    return out


# ------------------------------------------------------------------------------ helpers
def _finite(value: float | None) -> float | None:
    return float(value) if value is not None and math.isfinite(value) else None
