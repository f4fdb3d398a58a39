"""Bias-corrected transfer-function fit of one order: refined instrumental variables, then output error.

Plain least squares (ARX) is biased when the equation error is coloured — and it always is
here: output noise seen through A(d⁻¹) is coloured even when the noise itself is white.
The paper's Eq. (12) removes the bias by prefiltering the data by 1/Â and re-estimating
until the parameters converge (Steiglitz–McBride). With coloured noise that alone stays
biased (~6 % pole error measured, PAPER-NOTES.md), so the regression here also uses
instrumental variables built from the simulated noise-free output x̂ = (B̂/Â)·u, prefiltered
the same way: the simplified refined instrumental variable method (SRIV, P. C. Young),
consistent for white and coloured output noise.

SRIV converges from the (biased) least-squares start in a few iterations, but for weakly
identified poles (a heavily damped amplifier low-pass) its estimate scatters several times
more than the minimum of the output-error loss Σ (y − (B/A)·u)², which is the maximum-
likelihood fit for white output noise and stays consistent for coloured noise. So the
chosen order can be finished by minimising that loss (scipy.optimize.least_squares,
Levenberg–Marquardt, analytic Jacobian by filtering) from the SRIV estimate — identify()
does so when the SRIV iteration does not settle.

numpy/scipy have no instrumental-variable transfer-function estimator (and the packages
that do, e.g. SIPPY, are not dependencies and were measured far slower), so the SRIV
iteration is written here around scipy.signal.lfilter and analysis.loss's lagged products.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass

import numpy as np
from hopkinson.analysis.loss import lagged_cross_products, long_dot
from scipy import linalg, optimize, signal


@dataclass(frozen=True)
class TransferFit:
    """One order's bias-corrected fit: A(d⁻¹), B(d⁻¹) and how the iteration went."""

    a: np.ndarray  # a[0] = 1
    b: np.ndarray  # b_0 … b_n
    oe_loss: float  # Σ (y − offset − (B/A)·u)² from sample `order` on; inf when unstable
    iterations: int
    converged: bool
    stable: bool
    method: str  # "sriv" or "sriv+oe"
    reflected: bool = False  # the estimate had poles outside the unit circle, reflected inside
    offset: float = 0.0  # constant output offset fitted with the model (response units)
    # The iteration settled on an estimate with poles outside the unit circle: the data call
    # for an unstable model (what was returned, if anything, is a reflected stand-in).
    estimate_unstable: bool = False

    @property
    def order(self) -> int:
        return int(self.a.size - 1)


# A pole closer than this to the unit circle (a time constant over 10⁸ samples) cannot be
# told from an unstable one by any record: it counts as unstable.
STABILITY_MARGIN = 1e-8


def is_stable(a: np.ndarray) -> bool:
    """True when every root of A(d⁻¹) lies inside the unit circle (by STABILITY_MARGIN)."""
    return bool(a.size <= 1 or np.all(np.abs(np.roots(a)) < 1.0 - STABILITY_MARGIN))


def stabilised(a: np.ndarray) -> np.ndarray:
    """A(d⁻¹) with every root on or outside the unit circle reflected inside (p → 1/p̄).

    Only used for the prefilter 1/Â and the instrument model during the iteration, where an
    intermediate unstable estimate would otherwise make the filtered data explode.
    """
    if a.size <= 1:
        return a
    roots = np.roots(a)
    outside = np.abs(roots) >= 1.0 - STABILITY_MARGIN
    if not np.any(outside):
        return a
    roots[outside] = 0.999 / np.conj(roots[outside])
    return np.real(np.poly(roots))


def simulate(u: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Noise-free model output (B/A)·u from rest."""
    return signal.lfilter(b, a, u)


def output_error_loss(u: np.ndarray, y: np.ndarray, a: np.ndarray, b: np.ndarray, offset: float = 0.0) -> float:
    """Σ (y − offset − (B/A)·u)² from sample n = order on (the first n have no full history)."""
    n = a.size - 1
    with np.errstate(over="ignore", invalid="ignore"):
        e = y[n:] - offset - simulate(u, a, b)[n:]
        value = long_dot(e, e)
    return value if np.isfinite(value) else float("inf")


def _theta_to_ab(theta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Augmented θ' = [b_n, a_n, …, a_1, b_0] to (a, b)."""
    return np.concatenate(([1.0], theta[1::2][::-1])), theta[0::2][::-1]


def _iv_step(
    u: np.ndarray, y: np.ndarray, a: np.ndarray, b: np.ndarray, fit_offset: bool
) -> tuple[np.ndarray, np.ndarray, np.ndarray, float, float]:
    """One SRIV step from (a, b).

    Returns the new (a, b); the stabilised Â used for the prefilter and the instruments; the
    output offset c that best goes with (Â, b) (the residual's mean, when `fit_offset`); and
    the output-error loss of (Â, b, c) — of (a, b) itself unless a pole had to be reflected.
    The regression then uses y − c: a constant left in y would leak through the prefilter
    1/Â (gain 1/Â(1), large at fast sampling) into the estimate.
    """
    order = a.size - 1
    a_f = stabilised(a)
    u_f = signal.lfilter([1.0], a_f, u)
    x = signal.lfilter(b, [1.0], u_f)  # (B/Â)·u as the FIR B on u/Â: one recursion fewer
    e = y[order:] - x[order:]
    offset = float(np.mean(e)) if fit_offset else 0.0
    e -= offset
    loss = long_dot(e, e)
    y_f = signal.lfilter([1.0], a_f, y - offset if offset else y)
    x_f = signal.lfilter([1.0], a_f, x)
    # Augmented form (analysis.loss): columns [u_f(k−n), −y_f(k−n), …, u_f(k), −y_f(k)];
    # instruments with x̂_f in place of y_f; the last column's coefficient is fixed at 1.
    # Products of the unsigned series, then the signs of the y/x̂ rows and columns flipped.
    c = lagged_cross_products((u_f, x_f), (u_f, y_f), order)
    sign = np.tile([1.0, -1.0], order + 1)
    c *= sign[:, None] * sign[None, :]
    m = 2 * order + 1
    with warnings.catch_warnings():
        # Orders above the true one make the IV matrix near-singular (pole-zero cancellation);
        # the resulting poor fit shows in its loss, which is what the order choice judges.
        warnings.simplefilter("ignore", linalg.LinAlgWarning)
        theta = linalg.solve(c[:m, :m], -c[:m, m], check_finite=False)
    a_new, b_new = _theta_to_ab(theta)
    return a_new, b_new, a_f, offset, loss if np.isfinite(loss) else float("inf")


def refined_iv_fit(
    u: np.ndarray,
    y: np.ndarray,
    a0: np.ndarray,
    b0: np.ndarray,
    max_iterations: int = 30,
    tolerance: float = 1e-6,
    fit_offset: bool = True,
) -> TransferFit:
    """Iterate SRIV from (a0, b0) until the output-error loss stops changing.

    Converged when the relative change of the loss between iterations, or of the coefficient
    vector, falls below `tolerance` (the IV solve itself jitters at ~1e-6 on fast-sampled
    data, so a tighter test would never pass). Returns the iterate with the lowest loss.
    An iterate with poles outside the unit circle (typical of spare poles above the true
    order, which wander while they nearly cancel a zero) is judged — and may be returned —
    with those poles reflected inside (`reflected` = True); stable = False only when no
    iterate gave a finite loss. `fit_offset` fits a constant output offset with the model
    (a baseline error would otherwise be "explained" by a spurious pole near z = 1).
    """
    a, b = np.asarray(a0, dtype=float), np.asarray(b0, dtype=float)
    best: tuple[float, np.ndarray, np.ndarray, bool, float] | None = None
    previous_loss = float("inf")
    converged = False
    iterations = 0
    while iterations < max_iterations:
        iterations += 1
        try:
            a_new, b_new, a_used, offset, loss = _iv_step(u, y, a, b, fit_offset)
        except (linalg.LinAlgError, ValueError):
            break
        if np.isfinite(loss) and (best is None or loss < best[0]):
            best = (loss, a_used, b, a_used is not a, offset)
        if not (np.all(np.isfinite(a_new)) and np.all(np.isfinite(b_new))):
            break
        step = np.linalg.norm(np.concatenate((a_new - a, b_new - b)))
        size = max(np.linalg.norm(np.concatenate((a_new, b_new))), 1e-300)
        a, b = a_new, b_new
        loss_change = abs(previous_loss - loss) / loss if np.isfinite(loss) and loss > 0 else np.inf
        previous_loss = loss
        if step / size < tolerance or loss_change < tolerance:
            converged = True
            break
    if is_stable(a):
        n = a.size - 1
        with np.errstate(over="ignore", invalid="ignore"):
            e = y[n:] - simulate(u, a, b)[n:]
        offset = float(np.mean(e)) if fit_offset and np.all(np.isfinite(e)) else 0.0
        final_loss = output_error_loss(u, y, a, b, offset)
        if np.isfinite(final_loss) and (best is None or final_loss <= best[0]):
            best = (final_loss, a, b, False, offset)
    settled_unstable = converged and not is_stable(a)
    if best is None:
        return TransferFit(a, b, float("inf"), iterations, converged, False, "sriv", estimate_unstable=settled_unstable)
    loss, a_best, b_best, reflected, offset = best
    return TransferFit(
        a_best, b_best, loss, iterations, converged, True, "sriv", reflected, offset, settled_unstable
    )


def output_error_refine(
    u: np.ndarray, y: np.ndarray, fit: TransferFit, max_evaluations: int = 50, fit_offset: bool = True
) -> TransferFit:
    """Minimise Σ (y − c − (B/A)·u)² from a stable fit (Levenberg–Marquardt).

    Residual sensitivities come from filtering: ∂ŷ/∂b_i = (1/A)·u(k−i) and
    ∂ŷ/∂a_i = −(1/A)·ŷ(k−i); the offset c has sensitivity 1. Unstable trial steps are
    rejected (a huge residual). Returns `fit` unchanged if the refinement does not lower the
    loss or ends unstable.
    """
    if not fit.stable:
        return fit
    n = fit.order
    nb = fit.b.size
    rows = u.size - n

    def split(theta: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
        offset = float(theta[-1]) if fit_offset else 0.0
        return np.concatenate(([1.0], theta[:n])), theta[n : n + nb], offset

    # An unstable trial step gets a residual far above any stable model's, so the
    # Levenberg–Marquardt step control rejects it and shortens the step.
    rejected = np.full(rows, 1e3 * (float(np.max(np.abs(y))) + 1.0))

    def residual(theta: np.ndarray) -> np.ndarray:
        a, b, offset = split(theta)
        if not is_stable(a):
            return rejected
        return y[n:] - offset - simulate(u, a, b)[n:]

    def jacobian(theta: np.ndarray) -> np.ndarray:
        a, b, _ = split(theta)
        y_hat = simulate(u, a, b)
        u_f = signal.lfilter([1.0], a, u)
        yh_f = signal.lfilter([1.0], a, y_hat)
        jac = np.empty((rows, n + nb + int(fit_offset)))
        for i in range(1, n + 1):
            jac[:, i - 1] = yh_f[n - i : n - i + rows]  # ∂r/∂a_i = +(1/A)·ŷ(k−i)
        for i in range(nb):
            jac[:, n + i] = -u_f[n - i : n - i + rows]  # ∂r/∂b_i = −(1/A)·u(k−i)
        if fit_offset:
            jac[:, -1] = -1.0
        return jac

    theta0 = np.concatenate((fit.a[1:], fit.b, [fit.offset] if fit_offset else []))
    try:
        # MINPACK's Levenberg–Marquardt factorises the Jacobian with its own QR: unlike the
        # trust-region method's LAPACK SVD it never waits on BLAS threads of a busy machine.
        result = optimize.least_squares(
            residual, theta0, jac=jacobian, method="lm", x_scale="jac",
            xtol=1e-12, ftol=1e-12, gtol=1e-12, max_nfev=max_evaluations,
        )
    except (ValueError, np.linalg.LinAlgError):
        return fit
    a, b, offset = split(result.x)
    if not is_stable(a):
        return fit
    loss = output_error_loss(u, y, a, b, offset)
    if not loss < fit.oe_loss:
        return fit
    return TransferFit(
        a, b, loss, fit.iterations + int(result.nfev), result.status > 0, True, "sriv+oe", fit.reflected, offset,
        fit.estimate_unstable,
    )
