"""Amplitude linearity (ISO 16063-22 §9, ISO 16063-13): a sensitivity against the amplitude over a
campaign's levels, a straight line fitted with each point's uncertainty.

Model: S(a) = S₀·(1 + c·a), S one shot's sensitivity and a the amplitude it is measured at (m/s²).
The campaign (reports.statistics) gives each shot's quasi-static gain in the main pulse's
direction at the amplitude it is measured at (analysis.static_gain): a sensitivity that means the
same at every level, where a peak ratio S_sh reads the resonance's ringing on pulses that excite it
and a model's DC gain gives part of a non-linearity to the fitted dynamics (docs/decisions/0023). Fitted as S = β₀ + β₁·a by weighted least squares with weights 1/u(S)²
(each shot's standard uncertainty); c = β₁/β₀ with its standard uncertainty by first-order
propagation through the fit's covariance. When the points scatter more than their
uncertainties say (Birge ratio R = √(χ²/(n − 2)) > 1, e.g. a repeatability the shots' own Monte
Carlo does not hold), the covariance is scaled by R² (never shrunk). The expanded uncertainty
uses Student's t at n − 2 degrees of freedom when so scaled, else k = 1.96 (95 %).

The linearity deviation is the fitted relative change of the sensitivity over the range
covered, D = c·(a_max − a_min) (e.g. −0.08 for 8 % less at the top than at the bottom), with
U(D) = U(c)·(a_max − a_min). A share of u(S) common to all shots (the reference chain's scale)
moves β₀ and β₁ together and leaves c unchanged; the fit counts it as independent, on the safe
side.

Pure NumPy/SciPy.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

from hopkinson.analysis.errors import AnalysisError

COVERAGE = 0.95
PER_100_KM_S2 = 1.0e5  # the unit the slope is shown in: relative change per 100 km/s²


@dataclass(frozen=True)
class LinearityFit:
    """The straight line through the shots' shock sensitivities (module docstring)."""

    n: int
    reference_sensitivity: float  # S₀, the line at a = 0
    u_reference_sensitivity: float
    slope_rel_per_m_s2: float  # c
    u_slope_rel_per_m_s2: float
    k: float  # coverage factor of the expanded uncertainties
    peak_min_m_s2: float
    peak_max_m_s2: float
    birge_ratio: float | None  # None for two points
    residuals_rel: tuple[float, ...]  # S_i / S(a_i) − 1, per point in the given order

    @property
    def expanded_slope_rel_per_m_s2(self) -> float:
        return self.k * self.u_slope_rel_per_m_s2

    @property
    def deviation_rel(self) -> float:
        """D = c·(a_max − a_min): the fitted relative change of S over the range."""
        return self.slope_rel_per_m_s2 * (self.peak_max_m_s2 - self.peak_min_m_s2)

    @property
    def expanded_deviation_rel(self) -> float:
        return self.expanded_slope_rel_per_m_s2 * (self.peak_max_m_s2 - self.peak_min_m_s2)

    def sensitivity_at(self, peak_m_s2: np.ndarray | float) -> np.ndarray:
        return self.reference_sensitivity * (1.0 + self.slope_rel_per_m_s2 * np.asarray(peak_m_s2, dtype=float))

    def text(self) -> str:
        """'−1.02 ± 0.31 % per 100 km/s² (deviation −6.1 ± 1.9 % over 49–980 km/s², n = 6)'."""
        return (f"{100 * PER_100_KM_S2 * self.slope_rel_per_m_s2:.3g} ± "
                f"{100 * PER_100_KM_S2 * self.expanded_slope_rel_per_m_s2:.2g} % per 100 km/s² (deviation "
                f"{100 * self.deviation_rel:.3g} ± {100 * self.expanded_deviation_rel:.2g} % over "
                f"{self.peak_min_m_s2 / 1e3:.4g}–{self.peak_max_m_s2 / 1e3:.4g} km/s², n = {self.n})")

    def to_dict(self) -> dict[str, Any]:
        out = asdict(self)
        out["residuals_rel"] = list(self.residuals_rel)
        out.update(expanded_slope_rel_per_m_s2=self.expanded_slope_rel_per_m_s2, deviation_rel=self.deviation_rel,
                   expanded_deviation_rel=self.expanded_deviation_rel, coverage=COVERAGE)
        return out


def fit_linearity(peaks_m_s2: Sequence[float], sensitivities: Sequence[float],
                  u_sensitivities: Sequence[float] | None = None) -> LinearityFit:
    """The weighted straight line S(a) = S₀(1 + c·a) through the shots (module docstring).
    `u_sensitivities` None (or any missing): equal weights and the scatter's own variance.
    AnalysisError with fewer than two distinct levels."""
    from scipy.stats import t as student_t

    a = np.asarray(peaks_m_s2, dtype=float)
    s = np.asarray(sensitivities, dtype=float)
    if a.shape != s.shape or a.ndim != 1:
        raise AnalysisError("linearity: peaks and sensitivities must be two lists of the same length")
    ok = np.isfinite(a) & np.isfinite(s)
    u = np.ones_like(s) if u_sensitivities is None else np.asarray(u_sensitivities, dtype=float)
    known_u = u_sensitivities is not None and bool(np.all(np.isfinite(u[ok]) & (u[ok] > 0)))
    if not known_u:
        u = np.ones_like(s)
    a, s, u = a[ok], s[ok], u[ok]
    n = int(a.size)
    if n < 2 or np.ptp(np.abs(a)) <= 0:
        raise AnalysisError(f"linearity: needs shots at two or more peak levels (got {n} shot(s))")
    a = np.abs(a)
    x = np.column_stack((np.ones(n), a))
    w = 1.0 / u**2
    xtw = x.T * w
    cov = np.linalg.inv(xtw @ x)
    beta = cov @ (xtw @ s)
    resid = s - x @ beta
    dof = n - 2
    birge = math.sqrt(float(np.sum(w * resid**2)) / dof) if dof > 0 else None
    scaled = not known_u or (birge is not None and birge > 1.0)
    if scaled and birge is not None:
        cov = cov * birge**2
    k = float(student_t.ppf(0.5 + COVERAGE / 2, dof)) if scaled and dof > 0 else 1.959963984540054
    b0, b1 = float(beta[0]), float(beta[1])
    if b0 == 0:
        raise AnalysisError("linearity: the fitted sensitivity at zero acceleration is zero")
    c = b1 / b0
    grad = np.array([-b1 / b0**2, 1.0 / b0])  # ∂c/∂β₀, ∂c/∂β₁
    u_c = math.sqrt(max(float(grad @ cov @ grad), 0.0))
    fitted = x @ beta
    return LinearityFit(n, b0, math.sqrt(float(cov[0, 0])), c, u_c, k, float(a.min()), float(a.max()),
                        birge, tuple(float(r) for r in s / fitted - 1.0))
