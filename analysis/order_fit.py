"""One order's fitted model (`OrderFit`) and what is asked of any model A, B: is it stable
(`is_stable`), its unstable poles reflected inside (`stabilised`), its damping beyond the band
floored (`damping_floored`), its response e^{−jωτ}·B/A (`response`). The fit itself:
analysis.frequency_fit."""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np

from hopkinson.analysis.model import all_pole_numerator

# A pole this close to the unit circle is on the stability boundary (treated as unstable).
STABILITY_MARGIN = 1e-8


@dataclass(frozen=True)
class OrderFit:
    """One order's fit: A, B (a[0] = 1), delay τ (samples), transient and drift terms, cost V."""

    a: np.ndarray
    b: np.ndarray
    delay: float
    transient: np.ndarray
    drift: float
    cost: float  # V(θ): Σ over bins of |error|² / noise variance (≈ bins at the truth)
    parameters: int
    evaluations: int
    converged: bool
    delay_fixed: bool
    start_unstable: bool = False  # its linear start settled with poles outside the unit circle
    sine_gain: float = math.nan  # ln κ of the sine terms (SineTerms; NaN: not fitted with a sine)
    sine_skew: float = 0.0  # τ_s of the sine terms, samples
    sine_cost: float = 0.0  # the sine terms' share of `cost`
    numerator: np.ndarray | None = None  # B's fixed shape (B = g·shape, `all_pole_numerator`); None: B free
    inputs: np.ndarray = field(default_factory=lambda: np.zeros(0))  # the input terms' coefficients c

    @property
    def order(self) -> int:
        return int(self.a.size - 1)

    @property
    def stable(self) -> bool:
        return is_stable(self.a)

    def embedded(self) -> OrderFit:
        """The same transfer function as an order n + 1 model (a pole and a zero at z = 0); with a
        fixed numerator shape, the next order's shape at the same DC gain (a start, not the same
        transfer function: its cost is not this fit's, and is left to be evaluated; carried over, a
        solve that could not lower the start's true cost returned the start with this fit's cost, and
        PTB's record at 0.25 MS/s read all-pole orders 3 and 4 at order 2's V 50.9 while their own
        were 498 and 1771: the order-4 'variant' moved the FBSD ±5 % by 30 %)."""
        if self.numerator is not None:
            shape = all_pole_numerator(self.order + 1)
            return replace(self, a=np.append(self.a, 0.0), b=float(np.sum(self.b)) * shape, numerator=shape,
                           transient=np.append(self.transient, 0.0) if self.transient.size else self.transient,
                           cost=math.nan, converged=False)
        return replace(self, a=np.append(self.a, 0.0), b=np.append(self.b, 0.0),
                       transient=np.append(self.transient, 0.0) if self.transient.size else self.transient)


# The least damping the all-pole structure gives a resonance beyond the band (`damping_floored`):
# its phase at half the resonance is < 0.4°, its magnitude change there < 0.02 %.
ZETA_FLOOR = 0.005


def damping_floored(a: np.ndarray, omega_top: float) -> np.ndarray | None:
    """A with each complex pole pair beyond the band (normalised frequency |ln p| above
    `omega_top`, rad/sample) damped at least ZETA_FLOOR; None when none is below it. A record does
    not determine the damping of a resonance beyond its band: in the band it trades with the
    channels' skew (both a phase slope, 2ζ/ω_n against τ) and the fit presses it onto the unit
    circle (ζ → 0) or past it whenever the model error favours a little more phase. The floor
    is part of the estimator (every Monte Carlo draw re-runs it) and changes the response in the
    band by less than any calibration's uncertainty; the damping is not reported as measured."""
    poles = np.roots(a).astype(complex) if a.size > 1 else np.zeros(0, dtype=complex)
    pair = np.abs(poles.imag) > 1e-12
    if not np.any(pair):
        return None
    s = np.log(np.where(pair, poles, 1.0))  # s·dt of each pole
    wn = np.abs(s)
    zeta = np.where(pair, -s.real / np.where(wn > 0, wn, 1.0), 1.0)
    low = pair & (zeta < ZETA_FLOOR) & (wn > omega_top)
    if not np.any(low):
        return None
    s[low] = wn[low] * (-ZETA_FLOOR + 1j * np.sign(s[low].imag) * math.sqrt(1.0 - ZETA_FLOOR**2))
    return np.real(np.poly(np.where(pair, np.exp(s), poles)))


def stabilised(a: np.ndarray) -> np.ndarray:
    """A(d⁻¹) with every root on or outside the unit circle reflected inside (p → 0.999/p̄): a
    linear start that wandered unstable is brought back before the fit takes over."""
    if a.size <= 1:
        return a
    roots = np.roots(a)
    outside = np.abs(roots) >= 1.0 - STABILITY_MARGIN
    if not np.any(outside):
        return a
    roots[outside] = 0.999 / np.conj(roots[outside])
    return np.real(np.poly(roots))


def response(fit: OrderFit, omega: np.ndarray) -> np.ndarray:
    """e^{−jωτ}·B/A of a fit at `omega` (rad/sample)."""
    z = np.exp(-1j * np.outer(omega, np.arange(fit.a.size)))
    return np.exp(-1j * omega * fit.delay) * (z[:, : fit.b.size] @ fit.b) / (z @ fit.a)


def is_stable(a: np.ndarray, margin: float = STABILITY_MARGIN) -> bool:
    """Every root of A(z⁻¹) inside the circle of radius 1 − margin.

    The Schur–Cohn step-down recursion (reflection coefficients |k| < 1) on A(ρz⁻¹)/…, i.e. on
    a_i/ρ^i: O(n²) arithmetic, several times faster than the roots for the small orders here.
    Written on Python floats: the fits call it at every trial step, and for these few
    coefficients NumPy's per-call overhead is most of its cost (the same IEEE operations).
    """
    n = a.size - 1
    if n <= 0:
        return True
    rho = 1.0 - margin
    p = [float(x) / rho**i for i, x in enumerate(np.asarray(a, dtype=float).tolist())]
    p0 = p[0]
    p = [x / p0 for x in p]
    for m in range(n, 0, -1):
        k = p[m]
        if not abs(k) < 1.0:
            return False
        d = 1.0 - k * k
        p = [(p[i] - k * p[m - i]) / d for i in range(m)]
    return True
