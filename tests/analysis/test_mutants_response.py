"""analysis.response function by function, against closed forms and scipy: the cases that kill
the mutants test_response.py lets survive (docs/mutation-testing.md)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import signal

from hopkinson.analysis.errors import AnalysisError
from hopkinson.analysis.model import DiscreteModel
from hopkinson.analysis.response import (
    BandEdge,
    band_edges,
    delayed_model_output,
    fbsd_bounds,
    fbsd_from_response,
    frequency_response,
    level_key,
    model_output,
    natural_frequency_damping,
    normalised_gain_function,
    pole_analysis,
    pole_zero_frequencies_hz,
    response_times_samples,
    simulate_from_rest,
    to_continuous,
    zpk_to_sos,
)


def test_level_keys_and_band_edge_dict() -> None:
    assert [level_key(x) for x in (0.05, 0.10, 0.025, 0.5)] == ["5", "10", "2.5", "50"]
    assert level_key(0.001234567) == "0.123457"  # six significant digits
    reached, never = BandEdge(0.05, 1234.5, "above"), BandEdge(0.1, 5e5, "none")
    assert reached.reached and not never.reached
    assert reached.to_dict() == {"level": 0.05, "frequency_hz": 1234.5, "crossing": "above",
                                 "within_band_to_limit": False}
    assert never.to_dict()["within_band_to_limit"] is True
    with pytest.raises(AttributeError):
        reached.frequency_hz = 1.0  # type: ignore[misc]


def test_frequency_response_of_a_numerator_with_several_taps_closed_form() -> None:
    """The phase too: reversing b's or a's coefficients keeps |H| on the unit circle but not H."""
    dt = 1e-5
    model = DiscreteModel(dt, [1.0, -0.5, 0.2], [0.3, 0.2, 0.1])
    f = np.array([0.0, 3_000.0, 17_000.0, 41_000.0])
    z_inv = np.exp(-2j * np.pi * f * dt)
    want = (0.3 + 0.2 * z_inv + 0.1 * z_inv**2) / (1 - 0.5 * z_inv + 0.2 * z_inv**2)
    np.testing.assert_allclose(frequency_response(model, f), want, rtol=1e-12)


@pytest.mark.parametrize("level", [0.0, 1.0, -0.05, 1.5])
def test_band_edges_refuses_a_level_outside_0_1(level: float) -> None:
    with pytest.raises(AnalysisError, match="level must be between 0 and 1"):
        band_edges(lambda f: np.ones_like(f), 1000.0, (level,))


def test_band_edges_below_one_hertz() -> None:
    assert band_edges(lambda f: 1.0 + f, 0.5, (0.05,))["5"].frequency_hz == pytest.approx(0.05, rel=1e-9)


@pytest.mark.parametrize("f_max", [0.0, -10.0])
def test_band_edges_refuses_a_non_positive_f_max(f_max: float) -> None:
    with pytest.raises(AnalysisError, match="f_max must be positive"):
        band_edges(lambda f: np.ones_like(f), f_max)


def test_band_edges_touching_the_band_is_not_leaving_it() -> None:
    """A gain of exactly 0.75 at one grid point (500 Hz of 1 kHz): on the ±25 % edge, not outside."""
    edge = band_edges(lambda f: np.where(f == 500.0, 0.75, 1.0), 1000.0, (0.25,))["25"]
    assert edge == BandEdge(0.25, 1000.0, "none")


def test_band_edges_refuses_a_gain_not_finite() -> None:
    with pytest.raises(AnalysisError, match="not finite"):
        band_edges(lambda f: np.where(f > 500.0, np.inf, 1.0), 1000.0)


def test_band_edges_refuses_a_gain_not_one_at_dc() -> None:
    with pytest.raises(AnalysisError, match="normalise it by H\\(0\\)"):
        band_edges(lambda f: np.full_like(f, 0.5), 1000.0)


def test_band_edges_starts_at_dc() -> None:
    """g = 1 + f/(1 Hz) leaves ±5 % at 0.05 Hz, below the first point of both grids above DC."""
    edges = band_edges(lambda f: 1.0 + f, 1e6, (0.05, 0.10))
    assert edges["5"].frequency_hz == pytest.approx(0.05, rel=1e-9)
    assert edges["10"].frequency_hz == pytest.approx(0.10, rel=1e-9)
    assert edges["5"].crossing == "above"


@pytest.mark.parametrize(("centre_hz", "width_hz"), [(5.0, 0.5), (1.3, 0.05)])
def test_band_edges_finds_a_narrow_bump_far_below_f_max_on_the_log_grid(centre_hz, width_hz) -> None:
    """A narrow bump a few hertz up with f_max 1 MHz (linear grid step 50 Hz): the geometric grid,
    six decades down to 1 Hz, finds it; the edge is where 1 + 0.2·exp(−((f − c)/w)²) = 1.05."""
    def gain(f: np.ndarray) -> np.ndarray:
        return 1.0 + 0.2 * np.exp(-(((f - centre_hz) / width_hz) ** 2))

    edge = band_edges(gain, 1e6, (0.05,))["5"]
    assert edge.crossing == "above"
    assert edge.frequency_hz == pytest.approx(centre_hz - width_hz * math.sqrt(math.log(4.0)), rel=1e-9)


def test_band_edges_uses_the_frequencies_of_interest_inside_the_range_only() -> None:
    """A spike 1 mHz wide at 333.3337 Hz is found only through the frequency of interest."""
    def gain(f: np.ndarray) -> np.ndarray:
        return np.where(np.abs(f - 333.3337) < 5e-4, 0.5, 1.0)

    assert band_edges(gain, 1000.0, (0.05,))["5"].crossing == "none"
    edge = band_edges(gain, 1000.0, (0.05,), (-5.0, 0.0, 333.3337, 1000.0, 2000.0))["5"]
    assert edge.crossing == "below" and abs(edge.frequency_hz - 333.3337) < 1e-3
    # below the geometric grid's six decades (1 Hz of 1 MHz): found through its frequency only
    low = band_edges(lambda f: np.where(np.abs(f - 0.4) < 1e-4, 0.5, 1.0), 1e6, (0.05,), (0.4,))["5"]
    assert low.crossing == "below" and abs(low.frequency_hz - 0.4) < 1e-3


def test_band_edges_none_is_f_max_and_each_level_on_its_own() -> None:
    edges = band_edges(lambda f: 1.0 - 0.07 * f / 1000.0, 1000.0, (0.5, 0.05))
    assert edges["50"] == BandEdge(0.5, 1000.0, "none")
    assert edges["5"].frequency_hz == pytest.approx(1000.0 * 0.05 / 0.07, rel=1e-9)


# -- fbsd_from_response ----------------------------------------------------------------------------------
@pytest.mark.parametrize(("f", "m"), [
    (np.zeros((2, 3)), np.zeros((2, 3))),
    (np.arange(4.0), np.ones(3)),
    (np.arange(3.0), np.ones(4)),
    (np.array([0.0]), np.array([1.0])),
])
def test_fbsd_from_response_refuses_bad_shapes(f, m) -> None:
    with pytest.raises(AnalysisError, match="1-D arrays of the same length"):
        fbsd_from_response(f, m)


@pytest.mark.parametrize("f", [[0.0, 1.0, 1.0, 2.0], [0.0, 2.0, 1.5, 3.0], [0.0, 2.0, 1.0, 3.0]])
def test_fbsd_from_response_refuses_frequencies_not_increasing(f) -> None:
    with pytest.raises(AnalysisError, match="increasing"):
        fbsd_from_response(np.array(f), np.ones(4))


def test_fbsd_from_response_touching_the_band_is_not_leaving_it() -> None:
    """|0.75 − 1| = 0.25 exactly (binary fractions): on the edge, not outside it."""
    edge = fbsd_from_response(np.array([0.0, 10.0, 20.0, 30.0]), np.array([1.0, 0.75, 1.0, 1.0]), (0.25,))["25"]
    assert edge == BandEdge(0.25, 30.0, "none")


def test_fbsd_from_response_takes_two_samples() -> None:
    edge = fbsd_from_response(np.array([0.0, 10.0]), np.array([1.0, 0.9]), (0.05,))["5"]
    assert edge.frequency_hz == pytest.approx(5.0, rel=1e-12) and edge.crossing == "below"


def test_fbsd_from_response_accepts_steps_under_one_hertz() -> None:
    f = np.array([0.0, 0.25, 0.5, 0.75])
    edges = fbsd_from_response(f, np.array([1.0, 1.0, 1.0, 0.9]), (0.05,))
    assert edges["5"].frequency_hz == pytest.approx(0.5 + 0.25 * 0.5)


def test_fbsd_from_response_edges_at_the_first_and_the_last_step() -> None:
    f = np.array([0.0, 10.0, 20.0, 30.0])
    first = fbsd_from_response(f, np.array([1.0, 0.9, 0.8, 0.7]), (0.05,))["5"]
    assert first.frequency_hz == pytest.approx(5.0, rel=1e-12) and first.crossing == "below"
    last = fbsd_from_response(f, np.array([1.0, 1.0, 1.0, 1.1]), (0.05,))["5"]
    assert last.frequency_hz == pytest.approx(25.0, rel=1e-12) and last.crossing == "above"
    with pytest.raises(AnalysisError, match="first magnitude sample"):
        fbsd_from_response(f, np.array([0.9, 1.0, 1.0, 1.0]))


def test_fbsd_from_response_goes_on_after_a_level_never_reached() -> None:
    f = np.array([0.0, 10.0, 20.0])
    edges = fbsd_from_response(f, np.array([1.0, 1.0, 0.9]), (0.5, 0.05))
    assert edges["50"] == BandEdge(0.5, 20.0, "none")
    assert edges["5"].frequency_hz == pytest.approx(15.0, rel=1e-12) and edges["5"].crossing == "below"


# -- gain, poles, zeros ----------------------------------------------------------------------------------
def test_normalised_gain_with_a_negative_dc_gain_and_without_a_finite_one() -> None:
    gain = normalised_gain_function(np.array([0.5]), np.array([-1.0, 0.5]), 1e-3)  # H(1) = −1
    f = np.array([0.0, 100.0, 250.0])
    z = np.exp(-2j * np.pi * f * 1e-3)
    np.testing.assert_allclose(gain(f), np.abs(0.5 / (-1.0 + 0.5 * z)), rtol=1e-12)
    gain = normalised_gain_function(np.array([0.5]), np.array([-1.5, 0.5]), 1e-3)  # Σa = −1: H(1) = −0.5
    np.testing.assert_allclose(gain(f), np.abs(0.5 / (-1.5 + 0.5 * z)) / 0.5, rtol=1e-12)
    with pytest.raises(AnalysisError, match="no finite, non-zero DC gain"):
        normalised_gain_function(np.array([1.0]), np.array([1.0, -1.0]), 1e-3)
    with pytest.raises(AnalysisError, match="no finite, non-zero DC gain"):
        normalised_gain_function(np.array([1.0, -1.0]), np.array([1.0, -0.5]), 1e-3)


def test_pole_zero_frequencies_are_the_angles() -> None:
    dt = 1e-6
    values = np.array([0.9 * np.exp(2j * np.pi * 12_345.0 * dt), 0.9 * np.exp(-2j * np.pi * 12_345.0 * dt), -0.5, 0.3])
    np.testing.assert_allclose(pole_zero_frequencies_hz(values, dt), [12_345.0, 12_345.0, 5e5, 0.0], atol=1e-6)


def test_response_times_closed_form() -> None:
    poles = np.array([0.5, -0.5, 0.9j, 0.0])
    np.testing.assert_allclose(response_times_samples(poles), [3 / math.log(2), 3 / math.log(2),
                                                               3 / math.log(1 / 0.9), 0.0], rtol=1e-12)
    with pytest.raises(AnalysisError, match=r"pole 1\.2\+0j is on or outside the unit circle"):
        response_times_samples(np.array([0.5, 1.2]))
    with pytest.raises(AnalysisError, match="outside the unit circle"):
        response_times_samples(np.array([-1.0]))


def test_pole_analysis_ratios_and_order() -> None:
    assert pole_analysis(np.array([])) == []
    rows = pole_analysis(np.array([0.5, 0.9]))
    assert [r["pole"] for r in rows] == [[0.5, 0.0], [0.9, 0.0]]
    assert rows[0]["ratio"] == pytest.approx(math.log(1 / 0.5) / math.log(1 / 0.9))
    assert rows[1]["ratio"] == 1.0
    fast = pole_analysis(np.array([0.5, 0.01]))[1]  # T'_r = 3/ln 100 = 0.65 sample: a ratio all the same
    assert fast["ratio"] == pytest.approx(math.log(100) / math.log(2), rel=1e-12)


def test_natural_frequency_and_damping_closed_form() -> None:
    dt, fn, zeta = 1e-6, 40_000.0, 0.1
    w = 2 * np.pi * fn
    s = -zeta * w + 1j * w * math.sqrt(1 - zeta**2)
    got_fn, got_zeta = natural_frequency_damping(np.array([np.exp(s * dt), np.exp(np.conj(s) * dt), -0.5]), dt)
    np.testing.assert_allclose(got_fn[:2], fn, rtol=1e-12)
    np.testing.assert_allclose(got_zeta[:2], zeta, rtol=1e-12)
    s_neg = complex(math.log(0.5), math.pi) / dt  # a negative real pole: at Nyquist
    assert got_fn[2] == pytest.approx(abs(s_neg) / (2 * np.pi))
    assert got_zeta[2] == pytest.approx(-s_neg.real / abs(s_neg))
    with pytest.raises(AnalysisError, match="pole at z = 0"):
        natural_frequency_damping(np.array([0.5, 0.0]), dt)


# -- sections and simulation ----------------------------------------------------------------------------
def test_zpk_to_sos_refuses_more_zeros_than_poles_and_handles_a_pure_gain() -> None:
    with pytest.raises(AnalysisError, match="2 zeros but only 1 poles"):
        zpk_to_sos(np.array([0.5, 0.2]), np.array([0.3]), 1.0)
    x = np.random.default_rng(3).standard_normal(50)
    np.testing.assert_allclose(signal.sosfilt(zpk_to_sos(np.array([0.5]), np.array([0.2]), 2.0), x),
                               signal.lfilter([2.0, -1.0], [1.0, -0.2], x), atol=1e-12)  # no delay unless asked
    # one pole more than zeros: (z − 0.5)/((z − 0.2)(z − 0.3)) = z⁻¹(1 − 0.5z⁻¹)/((1 − 0.2z⁻¹)(1 − 0.3z⁻¹))
    np.testing.assert_allclose(signal.sosfilt(zpk_to_sos(np.array([0.5]), np.array([0.2, 0.3]), 1.0), x),
                               signal.lfilter([0.0, 1.0, -0.5], np.poly([0.2, 0.3]), x), atol=1e-12)
    for delay in (0, 1, 2, 3):
        y = signal.sosfilt(zpk_to_sos(np.array([]), np.array([]), 2.5, delay), x)
        np.testing.assert_allclose(y, 2.5 * np.concatenate([np.zeros(delay), x[: x.size - delay]]), atol=1e-12)


def test_a_numerator_of_zeros_is_an_error() -> None:
    with pytest.raises(AnalysisError, match="all zeros"):
        model_output(DiscreteModel(1e-6, [1.0, -0.5], [0.0, 0.0]), np.ones(5))


@pytest.mark.parametrize(("a", "n"), [([1.0, -0.9], 1000), ([1.0, -1.6, 0.8], 300), ([1.0, -0.99], 200)])
def test_simulate_from_rest_is_the_linear_filter(a, n) -> None:
    """An integer delay: the output is lfilter's on the delayed input, to 1e-9 of its peak where
    the slowest pole has decayed to 1e-12 within the padding, to 1e-3 where the padding is capped
    at four record lengths (the pole at 0.99 on 200 samples: 0.99⁸⁰⁰ = 3e-4)."""
    rng = np.random.default_rng(5)
    u = rng.standard_normal(n)
    b = np.array([0.2, 0.1, -0.05])
    for delay in (0, 3):
        want = signal.lfilter(b, a, np.concatenate([np.zeros(delay), u])[:n])
        got = simulate_from_rest(np.array(a), b, float(delay), u)
        tolerance = 1e-3 if a == [1.0, -0.99] else 1e-9
        assert np.max(np.abs(got - want)) <= tolerance * np.max(np.abs(want))


def test_simulate_from_rest_pads_four_record_lengths_for_a_slow_pole() -> None:
    """An impulse in the last sample through 1/(1 − 0.99z⁻¹): the response r^k wraps past the padded
    length S into the first sample as r^(S−n+1)/(1 − r^S), at most 0.99⁸⁰¹/(1 − 0.99⁸⁰¹) with four
    record lengths of padding (3.2e-4; three would leave 2.4e-3)."""
    u = np.zeros(200)
    u[-1] = 1.0
    y = simulate_from_rest(np.array([1.0, -0.99]), np.array([1.0]), 0.0, u)
    assert y[-1] == pytest.approx(1.0, abs=1e-3)
    assert abs(y[0]) <= 0.99**801 / (1 - 0.99**801)


def test_simulate_from_rest_pads_for_a_two_tap_numerator() -> None:
    """64 samples (a fast FFT length itself): the one sample of b's tail needs the one of padding."""
    u = np.random.default_rng(7).standard_normal(64)
    for delay in (0, 3):
        want = signal.lfilter([0.2, 0.1], [1.0], np.concatenate([np.zeros(delay), u])[:64])
        got = simulate_from_rest(np.array([1.0]), np.array([0.2, 0.1]), float(delay), u)
        np.testing.assert_allclose(got, want, atol=1e-12)


def test_simulate_from_rest_with_an_unstable_pole_still_returns_the_record() -> None:
    """A fit's trial step may leave the unit circle: the padding is then capped (four record
    lengths), and the output is the record's length and finite."""
    u = np.random.default_rng(8).standard_normal(200)
    for a in ([1.0, -1.05], [1.0, -1.6, 1.1]):
        y = simulate_from_rest(np.array(a), np.array([0.1]), 0.0, u)
        assert y.shape == (200,) and np.all(np.isfinite(y))


def test_delayed_model_output_without_a_delay_is_the_filter() -> None:
    u = np.random.default_rng(9).standard_normal(300)
    model = DiscreteModel(1e-6, np.array([1.0, -1.2, 0.5]), np.array([0.1, 0.2]))
    np.testing.assert_allclose(delayed_model_output(model, u), signal.lfilter(model.b, model.a, u), atol=1e-10)


def test_simulate_from_rest_pads_for_a_long_numerator() -> None:
    """The padding holds the numerator's length too: an FIR numerator of 3 taps after a delay of 3
    wrapped its last output into the first sample."""
    u = np.random.default_rng(6).standard_normal(50)
    b = np.array([0.2, 0.1, -0.05])
    want = signal.lfilter(b, [1.0], np.concatenate([np.zeros(3), u])[:50])
    np.testing.assert_allclose(simulate_from_rest(np.array([1.0]), b, 3.0, u), want, atol=1e-12)


def test_simulate_from_rest_fractional_delay_on_a_band_limited_pulse() -> None:
    """A Gaussian pulse (σ = 6 samples, band-limited to rounding) delayed by 2.37 samples through a
    resonance: lfilter on the pulse evaluated at k − 2.37 (closed form)."""
    k = np.arange(400.0)
    pulse = np.exp(-0.5 * ((k - 100.0) / 6.0) ** 2)
    a, b = np.array([1.0, -1.7, 0.85]), np.array([0.1, 0.05])
    want = signal.lfilter(b, a, np.exp(-0.5 * ((k - 100.0 - 2.37) / 6.0) ** 2))
    got = simulate_from_rest(a, b, 2.37, pulse)
    assert np.max(np.abs(got - want)) < 1e-8 * np.max(np.abs(want))
    model = DiscreteModel(1e-6, a, b, delay_samples=2.37)
    np.testing.assert_allclose(delayed_model_output(model, pulse), got, atol=1e-15)
    np.testing.assert_allclose(model_output(model, pulse), signal.lfilter(b, a, pulse), atol=1e-12)


# -- continuous ---------------------------------------------------------------------------------------
def test_to_continuous_refuses_an_integrator_and_a_zero_at_one() -> None:
    with pytest.raises(AnalysisError, match="integrator"):
        to_continuous(DiscreteModel(1e-6, [1.0, -1.0], [1.0]))
    with pytest.raises(AnalysisError, match="zero at z = 1"):
        to_continuous(DiscreteModel(1e-6, [1.0, -0.5], [1.0, -1.0]))


def test_to_continuous_maps_a_negative_real_pole_to_a_pair_at_nyquist_and_drops_sampling_zeros() -> None:
    dt = 1e-5
    model = DiscreteModel(dt, np.poly([-0.5, 0.8]), np.array([0.0, 1.0, 0.6, 0.0]))  # zeros −0.6, 0 (a delay)
    zeros_s, poles_s, gain = to_continuous(model)
    sigma = math.log(0.5) / dt
    want = sorted([complex(sigma, math.pi / dt), complex(sigma, -math.pi / dt), complex(math.log(0.8) / dt, 0.0)],
                  key=lambda v: (v.imag, v.real))
    np.testing.assert_allclose(sorted(poles_s, key=lambda v: (v.imag, v.real)), want, rtol=1e-12)
    assert zeros_s.size == 0  # −0.6 is a sampling zero; 0 a delay
    assert gain * 1.0 / np.prod(-poles_s) == pytest.approx(model.dc_gain, rel=1e-12)
    one_zero = DiscreteModel(dt, [1.0, -0.5], [1.0, -0.3])
    zeros_s, poles_s, gain = to_continuous(one_zero)
    np.testing.assert_allclose(zeros_s, [math.log(0.3) / dt], rtol=1e-12)
    assert gain * np.prod(-zeros_s) / np.prod(-poles_s) == pytest.approx(one_zero.dc_gain, rel=1e-12)


def test_to_continuous_keeps_complex_zeros_left_of_the_axis_and_a_zero_outside_the_circle() -> None:
    """−0.5 ± 0.5j is no sampling zero (those lie on the negative real axis); a zero at 1.5 (non-
    minimum phase) maps to s = ln 1.5/T > 0, and the DC gain still matches."""
    dt = 1e-5
    zeros = np.array([-0.5 + 0.5j, -0.5 - 0.5j])
    model = DiscreteModel(dt, np.real(np.poly([0.3, 0.4, 0.6])), np.real(np.poly(zeros)))
    zeros_s, _, _ = to_continuous(model)
    np.testing.assert_allclose(np.sort_complex(zeros_s), np.sort_complex(np.log(zeros) / dt), rtol=1e-12)
    outside = DiscreteModel(dt, [1.0, -0.5], [1.0, -1.5])
    zeros_s, poles_s, gain = to_continuous(outside)
    np.testing.assert_allclose(zeros_s, [math.log(1.5) / dt], rtol=1e-12)
    assert gain * np.prod(-zeros_s) / np.prod(-poles_s) == pytest.approx(outside.dc_gain, rel=1e-12)


def test_to_continuous_maps_complex_poles_beyond_a_quarter_of_the_rate_and_drops_poles_at_the_origin() -> None:
    dt = 1e-6
    p = 0.9 * np.exp(2j * np.pi * 0.3)  # a negative real part: not a negative real pole
    model = DiscreteModel(dt, np.real(np.poly([p, np.conj(p), 0.0])), np.array([1.0]))
    _, poles_s, _ = to_continuous(model)
    want = np.log(np.array([p, np.conj(p)])) / dt
    np.testing.assert_allclose(np.sort_complex(poles_s), np.sort_complex(want), rtol=1e-12)


def test_fbsd_bounds_above_the_supported_band() -> None:
    edges = {"5": 40_000.0, "10": 81_250.0, "20": 62_500.0}
    assert fbsd_bounds(edges, None) == {}
    bounds = fbsd_bounds(edges, (1_000.0, 62_500.0))
    assert bounds == {"10": {"lower_bound_hz": 62_500.0,
                             "reason": "unsupported by the excitation (the pulse supports up to 62.5 kHz; the model "
                                       "puts the edge at 81.2 kHz)"}}
    # 100.6 kHz shows as 101 kHz (three significant digits of the kHz)
    assert fbsd_bounds({"30": 100_600.0}, (1_000.0, 62_500.0))["30"]["reason"].endswith("puts the edge at 101 kHz)")
