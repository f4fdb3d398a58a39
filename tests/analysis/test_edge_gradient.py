"""response.edge_gradient (the FBSD edge's derivative by implicit differentiation) against closed
forms and against central differences of the located edge."""

from __future__ import annotations

import math

import numpy as np
import pytest

from hopkinson.analysis.model import DiscreteModel
from hopkinson.analysis.response import edge_gradient, fbsd_edges
from tests.analysis.numeric_jacobian import central_differences

DT = 1e-6


def first_order_edge_hz(a1: float, level: float) -> float:
    """The −level edge of H = b0/(1 + a1·z⁻¹) (a low-pass for a1 < 0), in closed form:
    |H(ω)/H(0)|² = (1 + a1)²/(1 + 2·a1·cos ω + a1²) = (1 − level)²."""
    cos_w = ((1.0 + a1) ** 2 / (1.0 - level) ** 2 - 1.0 - a1 * a1) / (2.0 * a1)
    return math.acos(cos_w) / (2.0 * math.pi * DT)


@pytest.mark.parametrize("a1", [-0.9, -0.97, -0.995])
def test_first_order_edge_derivative_is_the_closed_forms(a1: float) -> None:
    model = DiscreteModel(DT, np.array([1.0, a1]), np.array([0.3]), 0.0)
    for key, edge in fbsd_edges(model).items():
        level = edge.level
        assert edge.frequency_hz == pytest.approx(first_order_edge_hz(a1, level), rel=1e-9)
        d_a, d_b = edge_gradient(model, edge)
        h = 1e-7
        closed = (first_order_edge_hz(a1 + h, level) - first_order_edge_hz(a1 - h, level)) / (2 * h)
        assert d_a[0] == pytest.approx(closed, rel=1e-6), key
        assert d_b == pytest.approx([0.0], abs=1e-6 * abs(closed))  # the edge does not depend on the gain


def test_resonant_model_edges_against_central_differences() -> None:
    """A lightly damped resonance with a zero (the edges cross above 1 + level): every
    coefficient's derivative against central differences of the located edge."""
    pole = 0.97 * np.exp(1j * 2 * np.pi * 40e3 * DT)
    a = np.real(np.poly([pole, np.conj(pole), 0.5]))
    b = np.array([0.2, 0.1, -0.05, 0.01])
    model = DiscreteModel(DT, a, b, 0.0)
    edges = fbsd_edges(model)
    assert all(e.crossing == "above" for e in edges.values())
    for key, edge in edges.items():
        d_a, d_b = edge_gradient(model, edge)

        def edge_hz(a_tail: np.ndarray, b_: np.ndarray, key: str = key) -> np.ndarray:
            return np.array([fbsd_edges(DiscreteModel(DT, np.concatenate([[1.0], a_tail]), b_, 0.0))[key].frequency_hz])

        numeric_a = central_differences(lambda t: edge_hz(t, b), a[1:], 1e-7)[0]
        numeric_b = central_differences(lambda t: edge_hz(a[1:], t), b, 1e-8)[0]
        assert d_a == pytest.approx(numeric_a, rel=1e-4), key
        assert d_b == pytest.approx(numeric_b, rel=1e-4, abs=1e-6 * np.max(np.abs(d_a))), key


def test_an_edge_not_reached_does_not_move() -> None:
    model = DiscreteModel(DT, np.array([1.0, -0.04]), np.array([0.8]), 0.0)  # |H/H(0)| ≥ 0.96/1.04 to Nyquist
    edge = fbsd_edges(model)["10"]
    assert not edge.reached
    d_a, d_b = edge_gradient(model, edge)
    assert not np.any(d_a) and not np.any(d_b)
