"""One model from a shock record and a sinusoidal calibration of the same sensor, and how well
the two agree (`hopkinson identify RECORD --sine SINE.csv`).

The fit. The sine points join the shock's frequency-domain fit as extra residuals of the same
model (spectral_data.SineTerms): at each point the complex log-error of κ·H(f)·e^{j2πfτ_s}
against S·e^{jφ}, its real part (the magnitude's relative error) over σ_mag and its imaginary
part (the phase error) over σ_phase. κ is a free relative gain and τ_s a free skew: the sine
constrains the model's shape only; the DC gain (the sensitivity) stays the shock's, and
κ — the ratio of the sine's absolute level to the shock model's — is reported with its
consistency (the units of the two may differ; when they agree, the ratio should be 1 within
the sensitivity's uncertainty). τ_s takes up the shock record's channel skew (a lag of the
response channel against the reference), which a sine calibration of the sensor alone has
not.

Weights: each data set by its own uncertainty.
- The shock's residuals are weighed by its measured noise (analysis.identify); where the model
  leaves significantly more residual than that noise explains (model error: V per degree of
  freedom R² > 1, judged as analysis.uncertainty judges it), the sine residuals are multiplied
  by R, which is the same as dividing the shock's by R: the shock then counts with its model
  error, not with its noise alone.
- The sine points' σ² = u² + s²: u the stated standard uncertainty, s an extra scatter — a
  variance component estimated from the sine residuals of the joint model (Paule–Mandel: the
  smallest s ≥ 0 with Σ e²/(u² + s²) = ν, separately for magnitude and phase, ν the points less
  the free parameter each has, κ or τ_s). A variance component and not a Birge ratio (which
  would scale every u by one factor): the sine data's ripple (±1.7 % on PTB's, against stated
  u of 0.15–0.5 %) does not follow the stated u, which change with the band; a scale factor
  would leave the 0.15 % points ten times over-weighted against the 0.5 % ones. The Birge
  ratio at the stated u is reported beside s. Both weights depend on the joint model, so the
  fit is iterated: from the shock-only model's (R, s) — an over-estimate of s, the sine
  counting less — to the joint model's, twice.

Each Monte Carlo draw (analysis.uncertainty) perturbs the sine points by their σ as it
perturbs the shock's bins by their noise (order_choice.NoiseDraws), and refits κ and τ_s with
the model. (The order's parametric bootstrap centres the shock's bins on the model but
perturbs the measured sine points: their scatter about the model counts twice there, which
can only favour the lower orders a little.)

Why τ_s is free: a sine calibration's phase is the sensor's own; the shock model's includes
the record's channel skew. Tied to zero (τ_s = 0) the sine's phase would also fix the model's
delay and, through it, the damping of a resonance beyond the band; on the simulated records
(whose sensor is discretised with a zero-order hold, a 0.05 µs lag) that biased f_n (coverage
10 of 12 seeds, against 39–40 of 40 free).

The consistency. At each sine point the joint model's error against the point, over the
expanded (k = 2) uncertainty of the difference, E_n = |e| / (2·√(u² + u_model²)), u the
point's STATED uncertainty (the extra scatter s is what the disagreement costs, not part of
the yardstick) and u_model the joint model's shape uncertainty there (the standard deviation
of the Monte Carlo draws' response, relative to their DC gain; 0 without draws); per point
the larger of the magnitude's and the phase's. The verdict: consistent when χ² = Σ (e/√(u² +
u_model²))² over both parts stays within its 95 % quantile (ν = 2P − 2); else inconsistent,
with the points beyond E_n = 1 and the extra scatter it took to reconcile them.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from hopkinson.analysis.errors import AnalysisError
from hopkinson.analysis.findings import Finding, FindingCode
from hopkinson.analysis.frequency_fit import OrderProblem
from hopkinson.analysis.model import DiscreteModel
from hopkinson.analysis.numerics import bracketed_root
from hopkinson.analysis.sine_comparison import SineCalibration
from hopkinson.analysis.spectral_data import SineTerms

# Paule–Mandel re-estimates of the weights (shock's R, sine's s) after the shock-only start.
WEIGHT_ITERATIONS = 2
# The sine's stated u, where the file gives none: magnitude (relative) and phase (degrees).
DEFAULT_U_MAGNITUDE_REL = 0.005
DEFAULT_U_PHASE_DEG = 0.5
CONSISTENCY_LEVEL = 0.95
# κ is compared with 1 (same units assumed) only when within this factor of it.
SAME_UNITS_FACTOR = 2.0


@dataclass(frozen=True)
class JointWeights:
    """The weights of the joint fit (module docstring)."""

    shock_ratio: float  # R² the sine residuals are multiplied by R for (1: noise explains the shock)
    scatter_mag_rel: float  # s of the magnitudes (relative)
    scatter_phase_deg: float  # s of the phases (degrees)


@dataclass
class SineJoint:
    """The sine calibration fitted with the shock, and their consistency (to_dict: the JSON's
    `sine_joint`)."""

    sine: SineCalibration
    weights: JointWeights
    birge_ratio: float  # √(χ²/ν) at the stated u, model uncertainty included
    chi2: float
    dof: int
    p_value: float
    error_mag_pct: np.ndarray  # joint model (× κ) ÷ sine − 1, per point
    error_phase_deg: np.ndarray  # joint model (with τ_s) − sine phase
    u_model_mag_pct: np.ndarray
    u_model_phase_deg: np.ndarray
    e_n: np.ndarray  # per point, the larger of magnitude's and phase's
    gain_ratio: float  # κ: sine's absolute level ÷ the shock model's
    gain_ratio_u: float | None  # from the Monte Carlo draws (None without)
    skew_s: float  # τ_s: the shock record's channel skew as the sine sees it
    draws: int  # model draws behind u_model (0: none)

    @property
    def consistent(self) -> bool:
        return self.p_value >= 1.0 - CONSISTENCY_LEVEL

    def verdict(self) -> str:
        beyond = int(np.sum(self.e_n > 1.0))
        where = ""
        if beyond:
            worst = int(np.argmax(self.e_n))
            where = (f"; {beyond} of {self.e_n.size} points have E_n > 1, the largest {self.e_n[worst]:.3g} at "
                     f"{self.sine.frequency_hz[worst] / 1e3:.4g} kHz")
        scatter = (f"an extra scatter of {100 * self.weights.scatter_mag_rel:.2g} % in magnitude and "
                   f"{self.weights.scatter_phase_deg:.2g}° in phase")
        if self.consistent:
            return (f"consistent: the sine points agree with the joint model within their stated uncertainty "
                    f"(χ² = {self.chi2:.3g} for ν = {self.dof}, Birge ratio {self.birge_ratio:.2f}){where}")
        return (f"inconsistent: the sine points scatter about the joint model beyond their stated uncertainty "
                f"(χ² = {self.chi2:.3g} for ν = {self.dof}, Birge ratio {self.birge_ratio:.2f}, p = "
                f"{self.p_value:.2g}){where}; the fit weighed them with {scatter} (a variance component)")

    def gain_text(self) -> str:
        text = f"sine ÷ shock level {self.gain_ratio:.5g}"
        if self.gain_ratio_u is not None:
            text += f" (u {self.gain_ratio_u:.2g})"
        e_n = self.gain_e_n
        if e_n is not None:
            text += f", {100 * (self.gain_ratio - 1):+.2f} % in the same units (E_n {e_n:.2g})"
        return text

    @property
    def gain_e_n(self) -> float | None:
        """E_n of κ against 1 (same units assumed) with its u and the sine's stated u at its
        lowest point; None when κ is far from 1 (other units) or has no u."""
        if self.gain_ratio_u is None or not (1 / SAME_UNITS_FACTOR < self.gain_ratio < SAME_UNITS_FACTOR):
            return None
        u_sine = float(_stated(self.sine)[0][0])
        return abs(self.gain_ratio - 1.0) / (2.0 * math.hypot(self.gain_ratio_u, u_sine * self.gain_ratio))

    def to_dict(self) -> dict[str, Any]:
        def floats(x: np.ndarray) -> list[float]:
            return [float(v) for v in x]

        return {
            "source": self.sine.source,
            "frequency_hz": floats(self.sine.frequency_hz),
            "magnitude_error_pct": floats(self.error_mag_pct),
            "phase_error_deg": floats(self.error_phase_deg),
            "u_model_magnitude_pct": floats(self.u_model_mag_pct),
            "u_model_phase_deg": floats(self.u_model_phase_deg),
            "e_n": floats(self.e_n),
            "points_beyond_e_n_1": int(np.sum(self.e_n > 1.0)),
            "chi2": self.chi2,
            "dof": self.dof,
            "p_value": self.p_value,
            "birge_ratio": self.birge_ratio,
            "consistent": self.consistent,
            "verdict": self.verdict(),
            "scatter_magnitude_rel": self.weights.scatter_mag_rel,
            "scatter_phase_deg": self.weights.scatter_phase_deg,
            "shock_weight_ratio": self.weights.shock_ratio,
            "gain_ratio": self.gain_ratio,
            "gain_ratio_u": self.gain_ratio_u,
            "gain_ratio_e_n": self.gain_e_n,
            "skew_s": self.skew_s,
            "model_draws": self.draws,
        }


def identify_joint(record: Any, sine: SineCalibration, options: Any = None) -> Any:
    """`analysis.identify.identify` on the record and the sine points together (module docstring);
    `options`: analysis.options.AnalysisOptions."""
    from hopkinson.analysis.identify import identify

    shock = identify(record, options)
    dt = shock.sample_interval_s
    nyquist = 0.5 / dt
    if np.any(sine.frequency_hz >= nyquist):
        raise AnalysisError(f"{sine.source}: points at or above the analysis's Nyquist frequency ({nyquist:g} Hz)")
    weights = _reweighted(shock, sine, None)
    ident, used = None, weights
    for _ in range(WEIGHT_ITERATIONS):
        try:
            ident, used = identify(record, options, sine_terms=sine_terms(sine, dt, weights)), weights
        except AnalysisError as exc:
            if ident is None:
                raise AnalysisError(f"the fit of one model to the record and {sine.source} failed: {exc}") from None
            failed = Finding(FindingCode.SINE_REWEIGHING_FAILED,
                             f"the joint fit with the sine's re-estimated weights failed ({exc}); "
                             "the previous weights are kept")
            ident = replace(ident, findings=(*ident.findings, failed))
            break
        weights = _reweighted(ident, sine, weights)
    assert ident is not None
    model = replace(ident.model, info={**ident.model.info, "fit_method": "eiv-frequency-oe + sine calibration"})
    return replace(ident, claim=replace(ident.claim, model=model), sine_joint=consistency(ident, sine, used))


def sine_terms(sine: SineCalibration, dt: float, weights: JointWeights) -> SineTerms:
    """The sine points as SineTerms at the analysis interval `dt`, weighed by `weights`."""
    u_mag, u_phase = _stated(sine)
    return SineTerms(
        omega=2.0 * np.pi * sine.frequency_hz * dt,
        log_target=np.log(sine.magnitude) + 1j * np.radians(sine.phase_deg),
        sigma_mag=np.hypot(u_mag, weights.scatter_mag_rel),
        sigma_phase=np.radians(np.hypot(u_phase, weights.scatter_phase_deg)),
        weight=math.sqrt(weights.shock_ratio),
    )


def consistency(ident: Any, sine: SineCalibration, weights: JointWeights,
                model_draws: list[DiscreteModel] | None = None) -> SineJoint:
    """E_n per point, χ² and the verdict of the joint model `ident` (module docstring); the
    model's shape uncertainty from `model_draws` (analysis.uncertainty's) when given."""
    error, gain, skew = _joint_error(ident)
    u_mag, u_phase = _stated(sine)
    dt = ident.sample_interval_s
    omega = 2.0 * np.pi * sine.frequency_hz * dt
    draws = [m for m in (model_draws or []) if np.isfinite(m.dc_gain) and m.dc_gain != 0]
    if len(draws) >= 2:
        shapes = np.array([_log_shape(m, omega) for m in draws])
        um_mag = np.std(shapes.real, axis=0, ddof=1)
        um_phase = np.std(_without_linear_phase(shapes.imag, omega), axis=0, ddof=1)
        ratios = np.array([m.info.get("sine_gain_ratio", math.nan) for m in draws], dtype=float)
        gain_u = float(np.nanstd(ratios, ddof=1)) if np.sum(np.isfinite(ratios)) >= 2 else None
    else:
        um_mag = um_phase = np.zeros(omega.size)
        gain_u = None
    z_mag = error.real / np.hypot(u_mag, um_mag)
    z_phase = error.imag / np.hypot(np.radians(u_phase), um_phase)
    chi2 = float(np.sum(z_mag ** 2) + np.sum(z_phase ** 2))
    dof = max(2 * omega.size - 2, 1)
    # imported here, not at the top: `hopkinson identify` without a sine loads no SciPy
    from scipy.special import chdtrc

    return SineJoint(
        sine=sine, weights=weights, birge_ratio=math.sqrt(chi2 / dof), chi2=chi2, dof=dof,
        p_value=float(chdtrc(dof, chi2)), error_mag_pct=100.0 * np.expm1(error.real),
        error_phase_deg=np.degrees(error.imag), u_model_mag_pct=100.0 * um_mag, u_model_phase_deg=np.degrees(um_phase),
        e_n=0.5 * np.maximum(np.abs(z_mag), np.abs(z_phase)), gain_ratio=gain, gain_ratio_u=gain_u,
        skew_s=skew * dt, draws=len(draws),
    )


def with_draws(ident: Any, model_draws: list[DiscreteModel]) -> Any:
    """`ident` with its consistency redone with the Monte Carlo model draws (their shape
    uncertainty joins each point's E_n, their κ the gain ratio's u); `ident` itself without a
    sine calibration or draws."""
    joint = getattr(ident, "sine_joint", None)
    if joint is None or not model_draws:
        return ident
    return replace(ident, sine_joint=consistency(ident, joint.sine, joint.weights, model_draws))


def gain_ratio_of(fit: Any, scale: float) -> float:
    """κ of a fit in the record's units: the sine's level ÷ the model's (`scale` = the record's
    response scale ÷ its reference scale, times any chain factor of a draw)."""
    return math.exp(fit.sine_gain) / scale if math.isfinite(fit.sine_gain) else math.nan


# ------------------------------------------------------------------------------ helpers
def _stated(sine: SineCalibration) -> tuple[np.ndarray, np.ndarray]:
    """The stated standard uncertainties: magnitude (relative) and phase (degrees)."""
    n = sine.frequency_hz.size
    u_mag = sine.u_magnitude_rel if sine.u_magnitude_rel is not None else np.full(n, DEFAULT_U_MAGNITUDE_REL)
    u_phase = sine.u_phase_deg if sine.u_phase_deg is not None else np.full(n, DEFAULT_U_PHASE_DEG)
    # a stated u of zero would make a weight infinite: a hundredth of the smallest non-zero one
    u_mag = np.where(u_mag > 0, u_mag, 0.01 * np.min(u_mag[u_mag > 0], initial=DEFAULT_U_MAGNITUDE_REL))
    u_phase = np.where(u_phase > 0, u_phase, 0.01 * np.min(u_phase[u_phase > 0], initial=DEFAULT_U_PHASE_DEG))
    return np.asarray(u_mag, dtype=float), np.asarray(u_phase, dtype=float)


def _joint_error(ident: Any) -> tuple[np.ndarray, float, float]:
    """The chosen fit's complex log-error at the sine points (SineTerms), κ in the record's
    units and τ_s (samples; on the record's own alignment, as the model's delay)."""
    fitted, prepared = ident.settlement, ident.prepared
    if fitted.data.sine is None:
        raise AnalysisError("the identification was not fitted with a sine calibration")
    fit = fitted.sweep.fits[fitted.order]
    problem = OrderProblem.for_fit(fitted.data, fit, fitted.sweep.delay_mode, fitted.setup.max_delay)
    error = problem._sine_error(problem.pack(fit))
    return error, gain_ratio_of(fit, prepared.scale_y / prepared.scale_u), prepared.model_delay(fit.sine_skew)


def _shock_only_error(ident: Any, sine: SineCalibration) -> np.ndarray:
    """A shock-only model's log-error at the sine points, with κ and τ_s at their best."""
    dt = ident.sample_interval_s
    omega = 2.0 * np.pi * sine.frequency_hz * dt
    terms = sine_terms(sine, dt, JointWeights(1.0, 0.0, 0.0))
    g = _response(ident.model, omega)
    log_gain, skew = terms.start(g)
    e = np.log(g) + log_gain + 1j * omega * skew - terms.log_target
    return e.real + 1j * ((e.imag + np.pi) % (2.0 * np.pi) - np.pi)


def _reweighted(ident: Any, sine: SineCalibration, previous: JointWeights | None) -> JointWeights:
    """The weights from a fit: the shock's R² (its own residual) and the sine's s (Paule–Mandel)."""
    data, fit = ident.settlement.data, ident.settlement.sweep.fits[ident.order]
    error = _shock_only_error(ident, sine) if previous is None else _joint_error(ident)[0]
    shock_bins = data.bins - (data.sine.size if data.sine is not None else 0)
    shock_params = fit.parameters - (2 if data.sine is not None else 0)
    dof = 2 * shock_bins - shock_params
    ratio = 2.0 * (fit.cost - fit.sine_cost) / dof if dof > 0 else 1.0
    # model error as analysis.uncertainty judges it: significantly above 1, else the noise explains it
    shock_ratio = ratio if dof > 0 and ratio > 1.0 + 3.0 * math.sqrt(2.0 / dof) else 1.0
    u_mag, u_phase = _stated(sine)
    n = sine.frequency_hz.size
    s_mag = paule_mandel(error.real, u_mag, n - 1)
    s_phase = math.degrees(paule_mandel(error.imag, np.radians(u_phase), n - 1))
    return JointWeights(shock_ratio, s_mag, s_phase)


def paule_mandel(residual: np.ndarray, u: np.ndarray, dof: int) -> float:
    """The smallest s ≥ 0 with Σ r²/(u² + s²) ≤ dof (0 when the stated u already explain r)."""
    r2 = np.asarray(residual, dtype=float) ** 2
    u2 = np.asarray(u, dtype=float) ** 2
    if dof <= 0 or float(np.sum(r2 / u2)) <= dof:
        return 0.0

    def excess(s: float) -> float:
        return float(np.sum(r2 / (u2 + s * s))) - dof

    top = math.sqrt(float(np.max(r2))) * math.sqrt(r2.size / dof) + float(np.max(np.sqrt(u2)))
    return bracketed_root(excess, 0.0, top, 1e-6 * top)


def _response(model: DiscreteModel, omega: np.ndarray) -> np.ndarray:
    """e^{−jωτ}·B/A at `omega` (rad/sample)."""
    z = np.exp(-1j * np.outer(omega, np.arange(max(model.a.size, model.b.size))))
    return (np.exp(-1j * omega * model.delay_samples) * (z[:, : model.b.size] @ model.b)
            / (z[:, : model.a.size] @ model.a))


def _log_shape(model: DiscreteModel, omega: np.ndarray) -> np.ndarray:
    """ln(H(ω)/H(0)) of a model (its shape; the phase continuous from 0)."""
    log_h = np.log(_response(model, omega) / model.dc_gain)
    return log_h.real + 1j * np.unwrap(log_h.imag)


def _without_linear_phase(phase: np.ndarray, omega: np.ndarray) -> np.ndarray:
    """Each row's phase less its least-squares line through the origin (τ_s takes that up)."""
    slope = (phase @ omega) / float(omega @ omega)
    return phase - np.outer(slope, omega)


__all__ = ["JointWeights", "SineJoint", "consistency", "identify_joint", "paule_mandel", "sine_terms",
           "with_draws"]
