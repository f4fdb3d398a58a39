"""The independent truth for an analytic Jacobian: central differences of the residual."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np


def central_differences(residual: Callable[[np.ndarray], np.ndarray], theta: np.ndarray,
                        relative_step: float) -> np.ndarray:
    """∂residual/∂θ by central differences, each step `relative_step`·max(1, |θᵢ|)."""
    columns = []
    for i in range(theta.size):
        h = relative_step * max(1.0, abs(theta[i]))
        up, down = theta.copy(), theta.copy()
        up[i] += h
        down[i] -= h
        columns.append((residual(up) - residual(down)) / (2 * h))
    return np.column_stack(columns)
