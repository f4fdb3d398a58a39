"""A shot's quasi-static gain at the amplitude it is measured at: what an amplitude linearity
(analysis.linearity) is fitted to.

The model's DC gain is not a sensitivity at one amplitude: a sensor whose sensitivity changes
with the amplitude, S₀(1 + c·|a|), reads on one pulse as a linear model whose fit gives part of the
change to the dynamics (poles, the asymmetry ε, the onset's input terms), and the DC gain lands
off the line S₀(1 + c·a) at any single amplitude a (on the simulated bar: −0.4 … +1.7 %).

Here the dynamics are taken out where they are small and well known, and the gain is read
directly. Over the fitted DFT bins where the identified model's unit-DC-gain response
G(f) = H(f)/H(0) (with its delay) stays within QUASI_STATIC of 1 (the sensor is quasi-static
there: a model's error in f_n or ζ moves G little), the compensated response Y/G is fitted by
least squares, weighted by its noise, as g_main·U_main + g_other·U_other: U_main the DFT of the
reference's samples of the main pulse's sign, U_other of the rest (the opposite lobe and the bar's
motion of that sign; one regressor when the opposite sign holds less than OTHER_LOBE of the
reference's energy). g_main is the gain in the main pulse's direction. For a sensor driven by a·(1 + c·|a|),
g_main = S₀(1 + c·a_s) exactly, with a_s the same least squares' coefficient of the
DFT of a_main·|a| (+ g_other/g_main times that of a_other·|a|): `amplitude_m_s2`, the amplitude
the gain is measured at, computed from the reference alone. The onset's fitted input terms are
not used (they take the reference near the pulse's foot as unknown and can take up the
non-linearity); the motion after the pulse is corrected by the fitted γ where it was fitted.

Uncertainty (shot-specific: what differs from shot to shot; the reference chain's common scale
is not in it): the least squares' own covariance from the bins' noise, scaled by the residual's
χ² per degree of freedom where above one (the model error and any non-linearity the line does not
hold); how much it leans on the model's dynamics (Type B, rectangular: half-width the change of
g_main when only the bins within QUASI_STATIC/2 of static are used: the identified dynamics may
have taken up part of a non-linearity, and the further from static, the more that moves the
gain); and the spread of g_main over the Monte Carlo model draws (analysis.uncertainty); combined
in quadrature.

Pure NumPy.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from hopkinson.analysis.excitation import glitch_window, pulse_peak_index
from hopkinson.analysis.input_terms import MOTION
from hopkinson.analysis.model import DiscreteModel

QUASI_STATIC = 0.1  # the bins used: |G(f) − 1| ≤ this (G the model's unit-DC-gain response)
MIN_BINS = 4  # fewer quasi-static bins: not determined
OTHER_LOBE = 0.01  # the reference's energy of the opposite sign, at least this share, is fitted a gain of its own


@dataclass(frozen=True)
class StaticGain:
    """One shot's quasi-static gain in the main pulse's direction (module docstring)."""

    value: float  # response units per m/s²
    u: float | None  # standard uncertainty, shot-specific
    amplitude_m_s2: float  # the amplitude the gain is measured at
    other_direction: float | None  # the gain in the opposite direction (None: no opposite lobe fitted)
    top_hz: float  # the highest bin used
    bins: int
    u_noise: float  # the least squares' own, from the bins' noise (and any excess residual)
    u_band: float  # how much it leans on the model's dynamics (the gain over half the quasi-static bins)
    u_model: float | None  # from the Monte Carlo model draws (None: no draws)

    def to_dict(self) -> dict[str, Any]:
        return {"value": self.value, "u": self.u, "amplitude_m_s2": self.amplitude_m_s2,
                "other_direction": self.other_direction, "top_hz": self.top_hz, "bins": self.bins,
                "u_noise": self.u_noise, "u_band": self.u_band, "u_model": self.u_model, "quasi_static": QUASI_STATIC,
                "definition": DEFINITION}


DEFINITION = ("the least-squares gain of the response, compensated by the identified model's dynamics, on the "
              "reference's main lobe, over the bins where the sensor is quasi-static (|H/H(0) − 1| ≤ "
              f"{QUASI_STATIC:g}): the sensitivity in the main pulse's direction at the amplitude it is measured at")


def unit_response(model: DiscreteModel, omega: np.ndarray, delay_samples: float) -> np.ndarray:
    """e^{−jωτ}·H(ω)/H(0) of `model` at `omega` (rad/sample)."""
    z = np.exp(-1j * np.asarray(omega, dtype=float))
    b, a = np.asarray(model.b, dtype=float), np.asarray(model.a, dtype=float)
    h = np.polyval(b[::-1], z) / np.polyval(a[::-1], z)
    return np.exp(-1j * omega * delay_samples) * h / (float(np.sum(b)) / float(np.sum(a)))


@dataclass(frozen=True)
class _Fitted:
    """What the quasi-static gain reads of an identification's fit (analysis.identify_stages)."""

    var_y: np.ndarray  # the response's variance per fitted bin (its noise and the model error)
    var_u: np.ndarray  # the reference's, unbiased (what the Monte Carlo draws)
    realigned_samples: float
    scale_y: float
    scale_u: float
    fits: tuple[Any, ...]  # every order's fit and the chosen order's other delay branches


def _fitted(identification: Any) -> _Fitted:
    settlement, prepared = identification.settlement, identification.prepared
    return _Fitted(var_y=identification.claim.draw_var_y(settlement.model_error),
                   var_u=identification.prep.draw_var_u, realigned_samples=float(prepared.realigned_samples),
                   scale_y=prepared.scale_y, scale_u=prepared.scale_u,
                   fits=(*settlement.sweep.fits.values(), *(f for group in settlement.branches.values() for f in group)))


def static_gain(identification: Any, draws: Sequence[DiscreteModel] = ()) -> tuple[StaticGain | None, str]:
    """The shot's quasi-static gain (module docstring) from its identification (its stages'
    results) and the Monte Carlo model draws; None and why where the shot does not determine it."""
    prep = getattr(identification, "prep", None)
    if prep is None or prep.y_bins is None or prep.bin_hz.size == 0:
        return None, "the identification's fitted bins are not at hand"
    ctx = _fitted(identification)
    if not (np.size(ctx.var_y) == np.size(ctx.var_u) == prep.bin_hz.size == prep.y_bins.size):
        return None, "the fitted bins' noise is not given bin by bin"
    try:
        return _static_gain(identification, ctx, prep, draws)
    except (np.linalg.LinAlgError, ValueError, ZeroDivisionError) as exc:
        return None, f"the least squares on the quasi-static bins failed: {exc}"


def _static_gain(identification: Any, ctx: _Fitted, prep: Any, draws: Sequence[DiscreteModel]
                 ) -> tuple[StaticGain | None, str]:
    model = identification.model
    dt = model.sample_interval_s
    n = prep.u.size
    index = prep.bin_index if prep.bin_index is not None else np.rint(prep.bin_hz * n * dt).astype(int)
    omega = 2.0 * math.pi * prep.bin_hz * dt
    shift = float(ctx.realigned_samples)
    g_nominal = unit_response(model, omega, model.delay_samples + shift)
    keep = _quasi_static_bins(g_nominal, QUASI_STATIC)
    if keep.size < MIN_BINS:
        return None, (f"fewer than {MIN_BINS} fitted bins where the sensor is quasi-static (its response within "
                      f"{QUASI_STATIC:.0%} of its DC gain)")
    u = prep.u
    terms = prep.terms
    polarity = terms.polarity if terms.count else (1.0 if u[pulse_peak_index(u, glitch_window(dt))] >= 0 else -1.0)
    motion = np.zeros(n)
    fitted = _fitted_inputs(identification, ctx)
    cols = terms.columns(MOTION)
    if cols.size and fitted is not None:
        motion = float(fitted[cols[0]]) * terms.signals[cols[0]][prep.start : prep.start + n]
    opposite = np.where(polarity * u > 0, 0.0, u)
    split = float(opposite @ opposite) >= OTHER_LOBE * float(u @ u)
    corrected = u + motion
    main = np.where(polarity * u > 0, corrected, 0.0) if split else corrected
    spectra = np.column_stack([np.fft.rfft(c)[index] for c in [main] + ([corrected - main] if split else [])])
    main_only = np.where(polarity * u > 0, u, 0.0) if split else u
    distortion = np.column_stack([np.fft.rfft(c * np.abs(u))[index] for c in [main_only] + ([u - main_only] if split else [])])
    scale = ctx.scale_y / ctx.scale_u  # normalised gain → response units per m/s²
    g_norm = model.dc_gain / scale

    def solve(g: np.ndarray, keep: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """The gains (normalised), the weighted regressors and their weights' roots, the residual."""
        weight = 2.0 / (ctx.var_y[keep] / np.abs(g) ** 2 + g_norm**2 * ctx.var_u[keep])  # per real, imaginary part
        root = np.sqrt(np.concatenate([weight, weight]))
        x = spectra[keep]
        xr = np.vstack([x.real, x.imag]) * root[:, None]
        yc = prep.y_bins[keep] / g
        target = np.concatenate([yc.real, yc.imag]) * root
        coef, *_ = np.linalg.lstsq(xr, target, rcond=None)
        return coef, xr, root, target - xr @ coef

    coef, xr, root, resid = solve(g_nominal[keep], keep)
    dof = xr.shape[0] - xr.shape[1]
    chi2 = float(resid @ resid) / dof if dof > 0 else math.inf
    cov = np.linalg.inv(xr.T @ xr) * max(1.0, chi2)
    if not (np.isfinite(coef[0]) and coef[0] != 0 and np.all(np.isfinite(cov))):
        return None, "the least squares on the quasi-static bins gave no finite gain"
    u_noise = math.sqrt(float(cov[0, 0])) * abs(scale)
    ratio = float(coef[1] / coef[0]) if split and coef[0] else 0.0
    d = distortion[keep, 0] + (ratio * distortion[keep, 1] if split else 0.0)
    beta, *_ = np.linalg.lstsq(xr, np.concatenate([d.real, d.imag]) * root, rcond=None)
    amplitude = abs(float(beta[0]) * ctx.scale_u)
    # how much the result leans on the model's dynamics: the same gain over the bins half as far from static
    narrow = _quasi_static_bins(g_nominal, 0.5 * QUASI_STATIC)
    u_band = 0.0
    if narrow.size >= MIN_BINS:
        u_band = abs(float(solve(g_nominal[narrow], narrow)[0][0]) - float(coef[0])) * abs(scale) / math.sqrt(3.0)
    values = []
    for draw in draws:
        try:
            c = solve(unit_response(draw, omega[keep], draw.delay_samples + shift), keep)[0]
        except (np.linalg.LinAlgError, ValueError, ZeroDivisionError):
            continue
        if np.isfinite(c[0]):
            values.append(float(c[0]) * scale)
    u_model = float(np.std(values, ddof=1)) if len(values) >= 2 else None
    u = math.sqrt(u_noise**2 + u_band**2 + (u_model or 0.0) ** 2)
    return StaticGain(float(coef[0]) * scale, u, amplitude, float(coef[1]) * scale if split else None,
                      float(prep.bin_hz[keep[-1]]), int(keep.size), u_noise, u_band, u_model), ""


def _quasi_static_bins(g: np.ndarray, limit: float) -> np.ndarray:
    """The fitted bins from the band's bottom up to the first where |G − 1| exceeds `limit`."""
    inside = np.abs(g - 1.0) <= limit
    return np.arange(int(np.argmin(inside)) if not np.all(inside) else inside.size)


def _fitted_inputs(identification: Any, ctx: _Fitted) -> np.ndarray | None:
    """The final fit's input-term coefficients (the order fit whose A is the model's)."""
    a = np.asarray(identification.model.a, dtype=float)
    for fit in ctx.fits:
        if fit.a.size == a.size and np.allclose(fit.a, a, rtol=0.0, atol=1e-12):
            return np.asarray(fit.inputs, dtype=float)
    return None
