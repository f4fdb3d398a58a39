"""DiscreteModel: poles, zeros and DC gain against closed forms; JSON round trip."""

from __future__ import annotations

import json

import numpy as np
import pytest

from hopkinson.analysis.errors import AnalysisError
from hopkinson.analysis.model import DiscreteModel, load_model


def test_poles_zeros_gain_of_known_polynomials():
    p = np.array([0.974 + 0.1396j, 0.974 - 0.1396j, 0.8174 + 0.0518j, 0.8174 - 0.0518j])
    a = np.real(np.poly(p))
    b = 0.3 * np.real(np.poly([0.5, -0.2]))
    m = DiscreteModel(1e-6, a, np.r_[b, 0.0, 0.0])
    np.testing.assert_allclose(np.sort_complex(m.poles), np.sort_complex(p), atol=1e-12)
    np.testing.assert_allclose(np.sort(m.zeros.real), [-0.2, 0.5], atol=1e-12)
    assert m.dc_gain == pytest.approx(0.3 * 0.5 * 1.2 / np.prod(np.abs(1 - p)), rel=1e-12)
    assert m.order == 4 and m.is_stable


@pytest.mark.parametrize("order", [2, 4, 6])
def test_the_all_pole_numerators_zeros_sit_at_nyquist_and_are_not_non_minimum_phase(order):
    """B ∝ (1 + d⁻¹)ⁿ has an n-fold zero at z = −1 exactly (np.roots scatters it up to 3e-3 off the
    circle at n = 6, which used to be listed as zeros outside the unit circle); a real zero
    outside the circle beside it is still listed."""
    from math import comb

    a = np.real(np.poly([0.9 + 0.3j, 0.9 - 0.3j]))
    m = DiscreteModel(1e-6, a, 0.02 * np.array([comb(order, i) for i in range(order + 1)]))
    assert np.all(m.zeros == -1.0) and m.zeros.size == order
    assert m.nonminimum_phase_zeros.size == 0
    other = DiscreteModel(1e-6, a, 0.02 * np.real(np.poly([-0.5, 1.5])))
    np.testing.assert_allclose(other.nonminimum_phase_zeros, [1.5], atol=1e-9)


def test_a0_is_normalised():
    m = DiscreteModel(1e-6, [2.0, -1.0], [1.0])
    assert m.a[0] == 1.0 and m.b[0] == 0.5


def test_json_round_trip(tmp_path):
    m = DiscreteModel(1e-6, [1.0, -1.5, 0.7], [0.1, 0.1], delay_samples=2.0)
    path = tmp_path / "model.json"
    path.write_text(json.dumps(m.to_dict()))
    back = load_model(path)
    np.testing.assert_array_equal(back.a, m.a)
    np.testing.assert_array_equal(back.b, m.b)
    assert back.delay_samples == 2.0 and back.sample_interval_s == 1e-6


def test_bad_model_file_is_named(tmp_path):
    path = tmp_path / "m.json"
    path.write_text('{"a": [1, 0.5]}')
    with pytest.raises(AnalysisError, match=r"m\.json: missing key 'sample_interval_s'"):
        load_model(path)
    path.write_text("not json")
    with pytest.raises(AnalysisError, match="not a JSON model"):
        load_model(path)


def test_nested_coefficients_are_a_clear_error(tmp_path):
    path = tmp_path / "nested.json"
    path.write_text('{"sample_interval_s": 1e-6, "a": [[1, 0.5], [0.1, 0.2]], "b": [1]}')
    with pytest.raises(AnalysisError, match="flat lists"):
        load_model(path)
