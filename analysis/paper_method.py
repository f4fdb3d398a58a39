"""The paper's identification, section 2.1 as written: the reference a reader
of the paper checks against, and what the default method (analysis.identify) is compared with.

1. ARX, A(d⁻¹)·y(k) = B(d⁻¹)·u(k), by the QR decomposition of the augmented information matrix
   [Φ_n, y] (Eqs. 3–11): the loss ‖g₂‖² of every order n = 1 … max_order read off one R factor
   (analysis.loss.arx_loss_by_order with method "qr": the literal QR).
2. The order: where the trend of ‖g₂‖² over n has its second point of inflexion ("when n = 4,
   ‖g₂‖² has a second point of inflexion, and after that ‖g₂‖² remains stable"). Our reading,
   where the paper is loose: the inflexions of log ‖g₂‖²(n) are the orders at which its second
   difference changes sign; the order is the second of them. A curve with fewer than two takes
   the first order after which ‖g₂‖² falls by less than STABLE_DROP per order ("remains stable").
3. Eq. 12, the coloured-noise correction: u and y are filtered by 1/Â (Â the previous estimate's
   denominator) and the ARX model refitted, iterated until no coefficient moves by more than
   TOL (relative to the largest) or MAX_ITERATIONS passes (a Steiglitz–McBride iteration).

Literal means literal: nothing is normalised, weighted by noise or restricted to the band the
excitation supports, there is no input delay and no uncertainty. The record is only brought to
the analysis rate first, as for the default method, so that the two are compared on one footing.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy import signal

from hopkinson.analysis.errors import AnalysisError
from hopkinson.analysis.loss import arx_coefficients_by_order, arx_loss_by_order
from hopkinson.analysis.model import DiscreteModel
from hopkinson.analysis.options import DEFAULT_ANALYSIS_RATE_HZ
from hopkinson.analysis.records import Record
from hopkinson.analysis.resample import resample_to_rate

STABLE_DROP = 0.01  # ‖g₂‖² "remains stable": it falls by less than 1 % per order
TOL = 1e-9
MAX_ITERATIONS = 50


@dataclass
class PaperIdentification:
    """The paper's model of a record: the model, ‖g₂‖² by order, the inflexions, Eq. 12's passes."""

    model: DiscreteModel
    loss_by_order: np.ndarray  # ‖g₂‖², index 0 = order 1
    inflexions: list[int]  # the orders at which log ‖g₂‖² changes curvature
    order_rule: str  # "second inflexion", "stable loss" or "asked"
    iterations: int  # Eq. 12 passes
    converged: bool
    warnings: list[str] = field(default_factory=list)

    def to_dict(self) -> dict[str, Any]:
        return {"method": "paper", "model": self.model.to_dict(), "order": self.model.order,
                "loss_by_order": [float(v) for v in self.loss_by_order], "inflexions": self.inflexions,
                "order_rule": self.order_rule, "prefilter_iterations": self.iterations,
                "converged": self.converged, "warnings": list(self.warnings)}


def inflexions(loss_by_order: np.ndarray) -> list[int]:
    """The orders n at which the second difference of log ‖g₂‖²(n) changes sign."""
    curve = np.log(np.maximum(np.asarray(loss_by_order, dtype=float), np.finfo(float).tiny))
    d2 = curve[2:] - 2.0 * curve[1:-1] + curve[:-2]  # d2[k] at order k + 2
    return [k + 2 for k in range(1, d2.size) if np.sign(d2[k]) != np.sign(d2[k - 1]) and d2[k] != 0]


def paper_order(loss_by_order: np.ndarray) -> tuple[int, str]:
    """The order by the trend of ‖g₂‖² (module docstring) and the rule that gave it."""
    points = inflexions(loss_by_order)
    if len(points) >= 2:
        return points[1], "second inflexion"
    loss = np.asarray(loss_by_order, dtype=float)
    for n in range(1, loss.size):
        if loss[n] >= (1.0 - STABLE_DROP) * loss[n - 1]:
            return n, "stable loss"
    return int(loss.size), "stable loss"


def prefiltered_arx(u: np.ndarray, y: np.ndarray, order: int) -> tuple[np.ndarray, np.ndarray, int, bool]:
    """Eq. 12 iterated: (a, b, passes, converged), starting from the plain least-squares model.
    A pass whose estimate is unstable ends the iteration with the last stable estimate (not
    converged): the next 1/Â could not be applied."""
    a, b = arx_coefficients_by_order(u, y, order, method="qr")[-1]
    for passes in range(1, MAX_ITERATIONS + 1):
        if np.any(np.abs(np.roots(a)) >= 1.0):
            return a, b, passes - 1, False  # 1/Â would not be a stable filter
        uf, yf = signal.lfilter([1.0], a, u), signal.lfilter([1.0], a, y)
        a_new, b_new = arx_coefficients_by_order(uf, yf, order, method="qr")[-1]
        if np.any(np.abs(np.roots(a_new)) >= 1.0):  # the pass diverged: keep the last stable estimate
            return a, b, passes, False
        change = np.max(np.abs(np.concatenate((a_new - a, b_new - b))))
        scale = max(float(np.max(np.abs(np.concatenate((a_new, b_new))))), 1e-300)
        a, b = a_new, b_new
        if change <= TOL * scale:
            return a, b, passes, True
    return a, b, MAX_ITERATIONS, False


def paper_identify(record: Record, max_order: int = 12, order: int | None = None,
                   sample_rate_hz: float | None = DEFAULT_ANALYSIS_RATE_HZ) -> PaperIdentification:
    """Section 2.1 of the paper on a record (module docstring)."""
    if not 1 <= max_order <= 60:
        raise AnalysisError(f"max_order must be 1 .. 60, got {max_order}")
    rec = resample_to_rate(record, sample_rate_hz) if sample_rate_hz else record
    u, y = np.asarray(rec.reference, dtype=float), np.asarray(rec.response, dtype=float)
    if u.size < 4 * max_order + 8:
        raise AnalysisError(f"the record holds {u.size} samples at the analysis rate: too few for order {max_order}")
    losses = arx_loss_by_order(u, y, max_order, method="qr")
    if order is None:
        chosen, rule = paper_order(losses)
    elif not 1 <= order <= max_order:
        raise AnalysisError(f"order must be 1 .. {max_order}, got {order}")
    else:
        chosen, rule = order, "asked"
    a, b, passes, converged = prefiltered_arx(u, y, chosen)
    warnings = [] if converged else [
        f"Eq. 12's iteration did not converge: pass {passes} gave an unstable model, the last stable estimate "
        "is kept" if passes < MAX_ITERATIONS else f"Eq. 12's iteration did not converge in {MAX_ITERATIONS} passes"]
    model = DiscreteModel(rec.sample_interval_s, a, b)
    model.info["fit_method"] = "paper: ARX by QR, order by the 2nd inflexion of ||g2||^2, Eq. 12 iterated"
    return PaperIdentification(model, losses, inflexions(losses), rule, passes, converged, warnings)
