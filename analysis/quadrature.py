"""Quadrature interferometer: displacement and velocity from two photodetector signals 90° apart.

A homodyne interferometer with a quadrature output (ISO 16063-11 method 3, ISO 16063-13 for
shock) gives two signals of the interference phase φ:

    u1 = p + r·cos φ
    u2 = q + (r/G)·sin(φ − α)

Ideally p = q = 0, G = 1, α = 0, and φ = atan2(u2, u1). Real detectors have DC offsets (p, q),
unequal gains (G ≠ 1) and a quadrature error (α ≠ 0): the Lissajous figure (u1, u2) is an
ellipse, not a circle, and the plain arctangent makes a periodic phase error of up to several
per cent of a fringe. The Heydemann correction (Appl. Opt. 20, 3382, 1981) fits the ellipse
and maps each sample back onto the circle before the arctangent:

    c = u1 − p = r·cos φ
    s = ((u1 − p)·sin α + G·(u2 − q)) / cos α = r·sin φ
    φ = unwrap(atan2(s, c)),   displacement = φ · displacement_per_radian_m

The ellipse is fitted with the direct least-squares method of Fitzgibbon et al. in the
numerically stable form of Halíř and Flusser (1998): it always returns an ellipse, works when
the origin lies outside it (offsets larger than the amplitude), and is solved on centred and
scaled data. The general conic a·x² + b·xy + c·y² + d·x + e·y + f = 0 gives the Heydemann
parameters in closed form: centred, it reads X² + G²Y² + 2G·sin α·XY = r²·cos² α. Written here
by hand (no SciPy routine fits a conic); ~40 lines, checked against a closed-form truth in
tests/analysis/test_quadrature.py.

Sign. φ increases when u2 lags u1 by 90° (u1 ∝ cos φ, u2 ∝ sin φ). Swap or negate a channel
for the opposite wiring. The phase is unwrapped sample to sample, so the record must be sampled
fast enough that φ moves less than π between samples (two samples per fringe at peak speed).

Scale. `displacement_per_radian_m` converts phase to displacement:
`michelson_displacement_per_radian_m(λ)` = λ/(4π) for a double-pass Michelson,
`grating_displacement_per_radian_m(d, orders)` = d/(2π·(φ−ξ)) for the method paper's
differential grating interferometer (Δf = v·(φ − ξ)/d, Eq. 37).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from hopkinson.analysis.errors import AnalysisError

MAX_FIT_POINTS = 100_000  # the ellipse is fitted on at most this many samples (a random subset)
MIN_COVERAGE_DEG = 270.0  # the samples must cover at least this much of the ellipse
_COVERAGE_BINS = 72


@dataclass(frozen=True)
class Ellipse:
    """The Heydemann parameters of the (u1, u2) Lissajous figure.

    offset_1_v, offset_2_v: p and q; amplitude_v: r (of u1); amplitude_ratio: G = r1/r2;
    phase_error_rad: α, the departure of the two signals from 90° (α = 0: exact quadrature).
    """

    offset_1_v: float
    offset_2_v: float
    amplitude_v: float
    amplitude_ratio: float
    phase_error_rad: float

    def correct(self, u1: np.ndarray, u2: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(r·cos φ, r·sin φ): the samples mapped from the ellipse onto a circle of radius r."""
        alpha = self.phase_error_rad
        c = np.asarray(u1, dtype=float) - self.offset_1_v
        s = (c * math.sin(alpha) + self.amplitude_ratio * (np.asarray(u2, dtype=float) - self.offset_2_v)) \
            / math.cos(alpha)
        return c, s


@dataclass(frozen=True)
class QuadratureResult:
    """Demodulated motion, one value per input sample.

    phase_rad: unwrapped interference phase (0 at the first sample); displacement_m and
    velocity_m_s from it; ellipse: the fitted correction; radius_spread: RMS of the corrected
    radius relative to r (noise and any departure from the ellipse model; ~0 when clean).
    """

    phase_rad: np.ndarray
    displacement_m: np.ndarray
    velocity_m_s: np.ndarray
    ellipse: Ellipse
    radius_spread: float


def michelson_displacement_per_radian_m(wavelength_m: float) -> float:
    """λ/(4π): a double-pass (Michelson) interferometer moves one fringe per λ/2."""
    _require_positive("wavelength_m", wavelength_m)
    return wavelength_m / (4.0 * math.pi)


def grating_displacement_per_radian_m(pitch_m: float, orders: tuple[int, int] = (1, -1)) -> float:
    """d/(2π·(φ − ξ)) for the differential grating interferometer of pitch d and orders (φ, ξ)."""
    _require_positive("pitch_m", pitch_m)
    difference = orders[0] - orders[1]
    if difference == 0:
        raise AnalysisError(f"orders {orders}: the two diffraction orders must differ")
    return pitch_m / (2.0 * math.pi * difference)


def fit_ellipse(u1: np.ndarray, u2: np.ndarray, max_points: int = MAX_FIT_POINTS) -> Ellipse:
    """The Heydemann parameters of the ellipse through (u1, u2) (direct least squares).

    Raises AnalysisError when the points do not define an ellipse (too few, a line, a point).
    """
    x, y = _checked_pair(u1, u2)
    if x.size > max_points:  # a random subset: a regular stride can alias with the fringes
        pick = np.random.default_rng(0).integers(0, x.size, max_points)
        x, y = x[pick], y[pick]
    if x.size < 6:
        raise AnalysisError(f"{x.size} samples cannot define an ellipse (at least 6 needed)")
    mx, my = float(np.mean(x)), float(np.mean(y))
    sx, sy = float(np.std(x)), float(np.std(y))
    if not (sx > 0 and sy > 0) or np.ptp(x) == 0 or np.ptp(y) == 0:  # (std of a constant can round above 0)
        raise AnalysisError("a quadrature channel is constant: no fringes to fit an ellipse to")
    xn, yn = (x - mx) / sx, (y - my) / sy
    a, b, c, d, e, f = _direct_ellipse_fit(xn, yn)
    # centre of the conic: gradient zero
    det = 4.0 * a * c - b * b
    pn = (b * e - 2.0 * c * d) / det
    qn = (b * d - 2.0 * a * e) / det
    f_centre = f + 0.5 * (d * pn + e * qn)
    if not (det > 0 and -f_centre / a > 0):
        raise AnalysisError("the quadrature signals do not trace an ellipse")
    sin_alpha = b / (2.0 * math.sqrt(a * c))  # invariant under the per-axis scaling
    cos_alpha = math.sqrt(max(1.0 - sin_alpha * sin_alpha, 0.0))
    if cos_alpha < 1e-6:
        raise AnalysisError("the two quadrature signals are in phase (the ellipse is a line)")
    return Ellipse(
        offset_1_v=mx + sx * pn,
        offset_2_v=my + sy * qn,
        amplitude_v=sx * math.sqrt(-f_centre / a) / cos_alpha,
        amplitude_ratio=math.sqrt(c / a) * sx / sy,
        phase_error_rad=math.asin(sin_alpha),
    )


def _direct_ellipse_fit(x: np.ndarray, y: np.ndarray) -> tuple[float, ...]:
    """Conic (a, b, c, d, e, f) of the least-squares ellipse (Halíř & Flusser 1998)."""
    d1 = np.column_stack((x * x, x * y, y * y))
    d2 = np.column_stack((x, y, np.ones_like(x)))
    s1, s2, s3 = d1.T @ d1, d1.T @ d2, d2.T @ d2
    try:
        t = -np.linalg.solve(s3, s2.T)
    except np.linalg.LinAlgError:  # the points lie on a line or a point
        raise AnalysisError("the quadrature signals do not trace an ellipse") from None
    m = s1 + s2 @ t
    m = np.array([m[2] / 2.0, -m[1], m[0] / 2.0])  # C1⁻¹·M for the constraint 4ac − b² = 1
    eigenvalues, vectors = np.linalg.eig(m)
    vectors = np.real(vectors)
    condition = 4.0 * vectors[0] * vectors[2] - vectors[1] ** 2
    candidates = np.flatnonzero(condition > 0)
    if candidates.size == 0:
        raise AnalysisError("the quadrature signals do not trace an ellipse")
    a1 = vectors[:, candidates[0]]
    conic = np.concatenate((a1, t @ a1))
    if conic[0] < 0:
        conic = -conic
    return tuple(float(v) for v in conic)


def demodulate_quadrature(
    u1: np.ndarray,
    u2: np.ndarray,
    sample_interval_s: float,
    displacement_per_radian_m: float,
    *,
    velocity_window_samples: int | None = None,
    max_fit_points: int = MAX_FIT_POINTS,
    fit_samples: np.ndarray | None = None,
) -> QuadratureResult:
    """Displacement and velocity from the two quadrature signals (Heydemann-corrected arctangent).

    u1, u2: the two photodetector signals (any units, same length), u2 lagging u1 by ~90°.
    sample_interval_s: their sample interval. displacement_per_radian_m: phase → displacement
    (see the helpers above). velocity_window_samples: None = central differences; an odd
    number ≥ 5 = Savitzky–Golay derivative (quadratic) over that many samples, a low-pass
    against the noise that differencing amplifies. fit_samples: fit the ellipse on these
    samples only (a boolean mask or indices; None: all), e.g. those in motion: a still grating
    piles its samples on one spot of the ellipse, and a slow amplitude drift meanwhile smears
    that spot along the radius, which pulls the fit (offsets and quadrature error by ~1 %).
    Raises AnalysisError for bad input or signals that cover less than MIN_COVERAGE_DEG of
    their ellipse (a motion of under about one fringe cannot be corrected).
    """
    _require_positive("sample_interval_s", sample_interval_s)
    if not (isinstance(displacement_per_radian_m, int | float) and math.isfinite(displacement_per_radian_m)
            and displacement_per_radian_m != 0):
        raise AnalysisError(f"displacement_per_radian_m must be a finite non-zero number, "
                            f"got {displacement_per_radian_m!r}")
    x, y = _checked_pair(u1, u2)
    ellipse = fit_ellipse(x, y, max_fit_points) if fit_samples is None else \
        fit_ellipse(x[fit_samples], y[fit_samples], max_fit_points)
    c, s = ellipse.correct(x, y)
    wrapped = np.arctan2(s, c)
    coverage = _coverage_deg(wrapped)
    if coverage < MIN_COVERAGE_DEG:
        raise AnalysisError(f"the quadrature signals cover {coverage:.0f}° of their ellipse; the Heydemann "
                            f"correction needs at least {MIN_COVERAGE_DEG:.0f}° (about one fringe of motion)")
    phase = _unwrapped_from_first(wrapped)
    displacement = phase * float(displacement_per_radian_m)
    velocity = _derivative(displacement, float(sample_interval_s), velocity_window_samples)
    radius = np.hypot(c, s) / ellipse.amplitude_v
    return QuadratureResult(
        phase_rad=phase,
        displacement_m=displacement,
        velocity_m_s=velocity,
        ellipse=ellipse,
        radius_spread=float(np.sqrt(np.mean((radius - 1.0) ** 2))),
    )


def _unwrapped_from_first(wrapped: np.ndarray) -> np.ndarray:
    """The phase from sample to sample (each step taken into (-π, π]), 0 at the first sample:
    np.unwrap's result less its first value, in fewer passes over a long record."""
    steps = np.diff(wrapped)
    steps += math.pi
    np.mod(steps, 2.0 * math.pi, out=steps)
    steps -= math.pi
    phase = np.empty_like(wrapped)
    phase[0] = 0.0
    np.cumsum(steps, out=phase[1:])
    return phase


def _derivative(values: np.ndarray, dt_s: float, window: int | None) -> np.ndarray:
    if window is None:
        return np.gradient(values, dt_s) if values.size > 1 else np.zeros_like(values)
    if not (isinstance(window, int) and window >= 5 and window % 2 == 1):
        raise AnalysisError(f"velocity_window_samples must be an odd integer >= 5, got {window!r}")
    if window > values.size:
        raise AnalysisError(f"velocity_window_samples = {window} exceeds the record ({values.size} samples)")
    from scipy.signal import savgol_filter

    return savgol_filter(values, window, polyorder=2, deriv=1, delta=dt_s, mode="interp")


def _coverage_deg(wrapped: np.ndarray) -> float:
    """How much of the circle the corrected samples span: 360° less the widest gap between
    visited 5° bins (discrete phases a few degrees apart still span it all)."""
    bins = ((wrapped + math.pi) * (_COVERAGE_BINS / (2.0 * math.pi))).astype(np.intp)
    visited = np.flatnonzero(np.bincount(np.clip(bins, 0, _COVERAGE_BINS - 1), minlength=_COVERAGE_BINS))
    gaps = np.diff(visited, append=visited[0] + _COVERAGE_BINS)
    return 360.0 * (_COVERAGE_BINS - int(gaps.max()) + 1) / _COVERAGE_BINS


def _checked_pair(u1: np.ndarray, u2: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    x = np.asarray(u1, dtype=float).ravel()
    y = np.asarray(u2, dtype=float).ravel()
    if x.shape != y.shape:
        raise AnalysisError(f"the quadrature signals differ in length ({x.size} and {y.size} samples)")
    if not (np.all(np.isfinite(x)) and np.all(np.isfinite(y))):
        raise AnalysisError("a quadrature signal holds NaN or infinite samples")
    return x, y


def _require_positive(name: str, value: object) -> None:
    if not (isinstance(value, int | float) and not isinstance(value, bool) and math.isfinite(value) and value > 0):
        raise AnalysisError(f"{name} must be a positive finite number, got {value!r}")
