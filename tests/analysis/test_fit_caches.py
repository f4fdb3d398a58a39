"""The frequency-domain fit's speed-ups (issue 43) keep its values: the shock Jacobian, built
column block by column block in real arithmetic, against central differences of the residual;
and the residuals an OrderProblem keeps for the θ's it last evaluated, which must never be
another point's or another record's."""

from __future__ import annotations

import numpy as np
import pytest

from hopkinson.analysis.frequency_fit import OrderFit, OrderProblem
from hopkinson.analysis.model import all_pole_numerator
from hopkinson.analysis.spectral_data import SineTerms, SpectralData
from hopkinson.analysis.structure import DelayMode
from tests.analysis.numeric_jacobian import central_differences

BINS = 40


def spectra(seed: int, grouped: bool = False, inputs: int = 2) -> SpectralData:
    """A second-order sensor's spectra with noise on both channels, a ramp, a transient term,
    `inputs` input terms (the first with a prior), or grouped by 3 bins."""
    rng = np.random.default_rng(seed)
    omega = np.linspace(0.02, 0.6, BINS)
    z = np.exp(-1j * omega)
    g = 0.9 * (1 + 0.4 * z) / (1 - 1.2 * z + 0.5 * z**2) * np.exp(-1j * omega * 1.3)
    u = (1 + 0.3 * rng.standard_normal(BINS)) * np.exp(1j * rng.uniform(0, 6.3, BINS))
    var_u, var_y = np.full(BINS, 1e-3), np.full(BINS, 2e-3)
    y = g * u + 0.03 * (rng.standard_normal(BINS) + 1j * rng.standard_normal(BINS))
    if grouped:
        return SpectralData.grouped_from(omega, u, y, var_u, var_y, 3)
    terms = (rng.standard_normal((BINS, inputs)) + 1j * rng.standard_normal((BINS, inputs))) if inputs else None
    data = SpectralData.per_bin(omega, u, y, var_u, var_y, ramp=1.0 / (1 - z), transient=True, inputs=terms)
    prior = np.zeros(inputs)
    prior[:1] = 3.0
    return data if not inputs else SpectralData(**{**data.__dict__, "input_prior": prior})


def start(order: int, numerator: np.ndarray | None = None) -> OrderFit:
    a = np.concatenate(([1.0, -1.1, 0.45], np.full(order - 2, 0.01)))
    b = np.linspace(0.8, 0.2, order + 1) if numerator is None else 0.9 * numerator
    return OrderFit(a, b, 1.1, np.full(order, 0.02), 0.05, float("nan"), 0, 0, False, False,
                    numerator=numerator, inputs=np.array([0.01, -0.02]))


def with_sine(data: SpectralData) -> SpectralData:
    """`data` with five sine points of the same sensor (analysis.sine_joint's terms)."""
    omega = np.linspace(0.05, 0.4, 5)
    z = np.exp(-1j * omega)
    g = 0.9 * (1 + 0.4 * z) / (1 - 1.2 * z + 0.5 * z**2)
    sine = SineTerms(omega, np.log(g) + 0.01, np.full(5, 0.01), np.full(5, 0.01))
    return SpectralData(**{**data.__dict__, "sine": sine})


@pytest.mark.parametrize("case", ["causal", "free", "fixed", "all-pole", "grouped", "no inputs", "sine"])
def test_the_shock_jacobian_is_the_residuals_derivative(case: str) -> None:
    order = 3
    numerator = all_pole_numerator(order) if case == "all-pole" else None
    delay = {"free": DelayMode.FREE, "fixed": 1.3}.get(case, DelayMode.CAUSAL)
    data = spectra(1, grouped=case == "grouped", inputs=0 if case == "no inputs" else 2)
    data = with_sine(data) if case == "sine" else data
    problem = OrderProblem(data, order, delay, 8.0, numerator=numerator)
    theta = problem.pack(start(order, numerator))
    jac = problem.jacobian(theta)
    numeric = central_differences(problem.residual, theta, 1e-6)
    assert jac.shape == (problem.residual_size(), problem.size)
    np.testing.assert_allclose(jac, numeric, rtol=1e-5, atol=1e-6 * np.max(np.abs(numeric)))


def test_kept_residuals_are_each_points_own() -> None:
    """Residuals asked again in another order, on two records in one process, equal a fresh
    problem's: the kept ones are keyed by θ and live in their own problem."""
    first, second = spectra(2), spectra(3)
    a, b = OrderProblem(first, 3), OrderProblem(second, 3)
    thetas = [a.pack(start(3)) * (1 + 0.01 * k) for k in range(3)]

    def fresh(data: SpectralData, theta: np.ndarray) -> np.ndarray:
        return OrderProblem(data, 3).residual(theta)

    for theta in [*thetas, thetas[0], thetas[2], thetas[1], thetas[1]]:
        got_a, got_b = a.residual(theta), b.residual(theta)
        np.testing.assert_array_equal(got_a, fresh(first, theta))
        np.testing.assert_array_equal(got_b, fresh(second, theta))
        assert not np.array_equal(got_a, got_b)
        np.testing.assert_array_equal(a.jacobian(theta), OrderProblem(first, 3).jacobian(theta))


def test_a_solve_gives_the_same_fit_whatever_was_solved_before() -> None:
    """Two records solved in turn on problems that kept their last points give the fits each
    gives alone."""
    first, second = spectra(4), spectra(5)
    alone = [OrderProblem(d, 3).solve(start(3), 60, 1e-8) for d in (first, second)]
    p, q = OrderProblem(first, 3), OrderProblem(second, 3)
    for problem, expected in [(q, alone[1]), (p, alone[0]), (q, alone[1])]:
        got = problem.solve(start(3), 60, 1e-8)
        np.testing.assert_array_equal(got.a, expected.a)
        np.testing.assert_array_equal(got.b, expected.b)
        assert got.cost == expected.cost and got.delay == expected.delay
    assert not np.array_equal(alone[0].a, alone[1].a)
