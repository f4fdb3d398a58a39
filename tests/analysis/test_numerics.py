"""analysis.numerics against SciPy's own routines (the identification path avoids importing them)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import fft, optimize, special

from hopkinson.analysis.numerics import (
    bracketed_root,
    f_quantile,
    levenberg_marquardt,
    next_fast_len,
)


@pytest.mark.parametrize("p", [0.5, 0.99, 1 - 0.01 / 512])
@pytest.mark.parametrize(("dfn", "dfd"), [(1, 30), (2, 100), (3, 1000), (6, 5000), (31, 60_000)])
def test_f_quantile_matches_scipy(p: float, dfn: int, dfd: int) -> None:
    assert f_quantile(p, dfn, dfd) == pytest.approx(special.fdtri(dfn, dfd, p), rel=1e-9)


def test_next_fast_len_matches_scipy() -> None:
    for n in (1, 7, 97, 1000, 1023, 197_001, 123_457):
        assert next_fast_len(n) == fft.next_fast_len(n, real=True)


def test_root_and_least_squares_agree_with_scipy() -> None:
    assert bracketed_root(lambda x: np.cos(x) - x, 0.0, 1.0, 1e-14) == pytest.approx(
        optimize.brentq(lambda x: np.cos(x) - x, 0.0, 1.0), abs=1e-12)
    t = np.linspace(0, 1, 50)
    y = 2.0 * np.exp(-3.0 * t) + 0.5

    def fun(x: np.ndarray) -> np.ndarray:
        return x[0] * np.exp(-x[1] * t) + x[2] - y

    def jac(x: np.ndarray) -> np.ndarray:
        e = np.exp(-x[1] * t)
        return np.column_stack((e, -x[0] * t * e, np.ones_like(t)))

    ours = levenberg_marquardt(fun, jac, np.array([1.0, 1.0, 0.0]), 200, 1e-12)
    theirs = optimize.least_squares(fun, [1.0, 1.0, 0.0], jac=jac, method="lm", xtol=1e-12)
    assert ours.converged and np.allclose(ours.x, theirs.x, rtol=1e-8) and np.allclose(ours.x, [2.0, 3.0, 0.5])


def test_levenberg_marquardt_stops_where_the_caller_says() -> None:
    # Rosenbrock from (-1.2, 1): the search crosses x0 = 0 on its way to (1, 1); a stop there
    # ends it at the first step taken past it, not converged, with fewer evaluations.
    def residual(x: np.ndarray) -> np.ndarray:
        return np.array([10.0 * (x[1] - x[0] ** 2), 1.0 - x[0]])

    def jacobian(x: np.ndarray) -> np.ndarray:
        return np.array([[-20.0 * x[0], 10.0], [-1.0, 0.0]])

    full = levenberg_marquardt(residual, jacobian, np.array([-1.2, 1.0]), 200, 1e-12)
    assert full.converged and np.allclose(full.x, 1.0, atol=1e-6)
    stopped = levenberg_marquardt(residual, jacobian, np.array([-1.2, 1.0]), 200, 1e-12, stop=lambda x: x[0] > 0.0)
    assert not stopped.converged and stopped.x[0] > 0.0 and stopped.evaluations < full.evaluations
