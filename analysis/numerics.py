"""Small numerical tools the identification path needs, in NumPy and the standard library.

Why not SciPy here: docs/decisions/0022 (the start-up time of `hopkinson identify`). Each tool
below is a few lines of a textbook method, checked against SciPy's in
tests/analysis/test_numerics.py:

- `levenberg_marquardt`: Marquardt's scaled damping with Nielsen's update (as MINPACK's lmder
  is used here: analytic Jacobian, stop on relative cost or step change);
- `bracketed_root`: the Illinois (modified regula falsi) method on a sign-changing bracket;
- `f_quantile`: quantile of Fisher's F, the root of its distribution function (the regularised
  incomplete beta by its continued fraction);
- `next_fast_len`: the next 5-smooth FFT length.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from functools import lru_cache

import numpy as np


@dataclass(frozen=True)
class LeastSquaresResult:
    x: np.ndarray
    cost: float  # ½‖r‖²
    evaluations: int
    converged: bool


def levenberg_marquardt(
    fun: Callable[[np.ndarray], np.ndarray],
    jac: Callable[[np.ndarray], np.ndarray],
    x0: np.ndarray,
    max_evaluations: int = 100,
    tolerance: float = 1e-8,
    stop: Callable[[np.ndarray], bool] | None = None,
    r0: np.ndarray | None = None,
) -> LeastSquaresResult:
    """Minimise ½‖fun(x)‖² from x0. Each step solves the damped system [J; √μ·D]·h = [−r; 0]
    (D the Jacobian's column norms: scale invariance) by least squares; a step that lowers the
    cost is taken and μ relaxed by Nielsen's rule, else μ grows. Converged when a taken step
    lowered the cost, or moved x, by less than `tolerance` (relative), or when the step's
    predicted gain is below 1 % of that. `stop(x)`, checked after each step taken, ends the
    search there (not converged): the caller has seen where it is going. `r0`: fun(x0), when the
    caller has it."""
    x = np.asarray(x0, dtype=float).copy()
    r = fun(x) if r0 is None else r0
    cost = 0.5 * float(r @ r)
    evaluations = 1
    if not math.isfinite(cost):
        return LeastSquaresResult(x, cost, evaluations, False)
    j = jac(x)
    scale = np.maximum(_column_norms(j), 1e-300)
    system, rhs, gradient = _damped_system(j, r)
    diagonal = (np.arange(system.shape[0] - x.size, system.shape[0]), np.arange(x.size))
    mu, nu = 1e-3, 2.0
    while evaluations < max_evaluations:
        system[diagonal] = math.sqrt(mu) * scale
        try:
            step = np.linalg.lstsq(system, rhs, rcond=None)[0]
        except np.linalg.LinAlgError:
            break
        predicted = -float(step @ gradient) - 0.5 * float(np.sum((j @ step) ** 2))
        if predicted <= 1e-2 * tolerance * cost:  # nothing left to gain, even undamped
            return LeastSquaresResult(x, cost, evaluations, True)
        trial = x + step
        r_trial = fun(trial)
        evaluations += 1
        cost_trial = 0.5 * float(r_trial @ r_trial)
        if math.isfinite(cost_trial) and cost_trial < cost and predicted > 0:
            rho = (cost - cost_trial) / predicted
            relative = (cost - cost_trial) / max(cost, 1e-300)
            small_step = float(np.linalg.norm(step * scale)) <= tolerance * float(np.linalg.norm(x * scale))
            x, r, cost = trial, r_trial, cost_trial
            if stop is not None and stop(x):
                return LeastSquaresResult(x, cost, evaluations, False)
            if relative < tolerance or small_step:
                return LeastSquaresResult(x, cost, evaluations, True)
            j = jac(x)
            scale = np.maximum(scale, _column_norms(j))
            system, rhs, gradient = _damped_system(j, r)
            mu *= max(1.0 / 3.0, 1.0 - (2.0 * rho - 1.0) ** 3)
            nu = 2.0
        else:
            mu *= nu
            nu *= 2.0
            if mu > 1e16:
                break
    return LeastSquaresResult(x, cost, evaluations, False)


def _column_norms(j: np.ndarray) -> np.ndarray:
    """‖J[:, i]‖ of each column: np.linalg.norm(j, axis=0)'s own sum, without its copies."""
    return np.sqrt(np.add.reduce(j * j, axis=0))


def _damped_system(j: np.ndarray, r: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """[R; 0] and [−Qᵀr; 0] of the damped step's system at a Jacobian (`_triangular`; the
    damping's diagonal goes into the zero block), and the gradient Jᵀr."""
    r_j, qt_r = _triangular(j, r)
    k, p = r_j.shape
    system = np.zeros((k + p, p))
    system[:k] = r_j
    rhs = np.zeros(k + p)
    rhs[:k] = -qt_r
    return system, rhs, j.T @ r


def _triangular(j: np.ndarray, r: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """R and Qᵀr of J = QR, from one Householder QR of [J | r] (Q never formed).

    ‖J·h + r‖² = ‖R·h + Qᵀr‖² + a constant, so each damped step solves the small system
    [R; √μ·D]·h = [−Qᵀr; 0] instead of [J; √μ·D] (MINPACK's lmpar does the same): one
    factorisation of the tall Jacobian per Jacobian, not per trial μ, and a QR, not an SVD.
    """
    k = min(j.shape[0], j.shape[1])
    augmented = np.linalg.qr(np.column_stack((j, r)), mode="r")
    return augmented[:k, :-1], augmented[:k, -1]


def bracketed_root(f: Callable[[float], float], a: float, b: float, xtol: float) -> float:
    """A root of f in [a, b] (f(a), f(b) of opposite signs) by the Illinois method."""
    fa, fb = f(a), f(b)
    if fa == 0.0:
        return a
    if fb == 0.0:
        return b
    if fa * fb > 0:
        raise ValueError("bracketed_root: f(a) and f(b) have the same sign")
    side = 0
    for _ in range(200):
        c = (a * fb - b * fa) / (fb - fa)
        fc = f(c)
        if fc == 0.0 or abs(b - a) <= xtol:
            return c
        if fc * fb < 0:
            a, fa = b, fb
            b, fb = c, fc
            side = 0
        else:
            b, fb = c, fc
            fa = fa / 2.0 if side == -1 else fa
            side = -1
    return c


@lru_cache(maxsize=4096)
def f_quantile(p: float, dfn: float, dfd: float) -> float:
    """The p quantile of Fisher's F(dfn, dfd): the root of its distribution function
    I_x(dfn/2, dfd/2) = p with x = dfn·F/(dfn·F + dfd) (I the regularised incomplete beta).
    Kept per arguments: a shot's order tests ask the same few quantiles at every Monte Carlo
    draw (a realistic shot: 154 calls, 26 distinct; each a root search of ~0.6 ms)."""
    if not 0.0 < p < 1.0:
        raise ValueError(f"f_quantile: p must lie in (0, 1), got {p}")
    a, b = dfn / 2.0, dfd / 2.0
    x = bracketed_root(lambda t: _incomplete_beta(a, b, t) - p, 0.0, 1.0, 1e-15)
    x = min(max(x, 0.0), 1.0 - 1e-16)
    return dfd * x / (dfn * (1.0 - x))


def _incomplete_beta(a: float, b: float, x: float) -> float:
    """I_x(a, b) by its continued fraction (Lentz), the symmetry I_x(a,b) = 1 − I_{1−x}(b,a) taken
    where the fraction converges slowly."""
    if x <= 0.0:
        return 0.0
    if x >= 1.0:
        return 1.0
    log_front = (math.lgamma(a + b) - math.lgamma(a) - math.lgamma(b) + a * math.log(x) + b * math.log1p(-x))
    if x > (a + 1.0) / (a + b + 2.0):
        return 1.0 - _incomplete_beta(b, a, 1.0 - x)
    tiny = 1e-300
    c, d = 1.0, 1.0 - (a + b) * x / (a + 1.0)
    d = 1.0 / (d if abs(d) > tiny else tiny)
    h = d
    for m in range(1, 500):
        for numerator in (m * (b - m) * x / ((a + 2 * m - 1) * (a + 2 * m)),
                          -(a + m) * (a + b + m) * x / ((a + 2 * m) * (a + 2 * m + 1))):
            d = 1.0 + numerator * d
            d = 1.0 / (d if abs(d) > tiny else tiny)
            c = 1.0 + numerator / c
            c = c if abs(c) > tiny else tiny
            h *= d * c
        if abs(d * c - 1.0) < 1e-15:
            break
    return math.exp(log_front) * h / a


def next_fast_len(n: int) -> int:
    """The smallest 2ᵃ·3ᵇ·5ᶜ ≥ n (a length NumPy's pocketfft transforms fast)."""
    n = max(int(n), 1)
    best = 1 << (n - 1).bit_length()
    p5 = 1
    while p5 < best:
        p35 = p5
        while p35 < best:
            m = p35
            while m < n:
                m *= 2
            best = min(best, m)
            p35 *= 3
        p5 *= 5
    return best
