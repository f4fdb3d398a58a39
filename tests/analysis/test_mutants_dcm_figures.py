"""The DCM's figures against closed forms: the noise gain of a known impulse response, the
compensated FBSD of a model whose resonance the DCM cancels exactly (the edge found on scipy's
freqz, not by the code under test), and the step responses, rise and settling times of
first-order systems (exact). They kill the mutants of the DCM's figures (analysis/dcm_figures.py, DCM.noise_gain) that the DCM's own
tests let survive (docs/mutation-testing.md)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import signal
from scipy.optimize import brentq

from hopkinson.analysis.dcm import DCM
from hopkinson.analysis.dcm_figures import (
    StepComparison,
    compare_steps,
    compensated_fbsd_edges,
    compensated_fbsd_hz,
    rise_time_ratio,
    rise_times_samples,
    settling_time_ratio,
    settling_times_samples,
    step_responses,
)
from hopkinson.analysis.errors import AnalysisError
from hopkinson.analysis.model import DiscreteModel

DT = 1e-6


# -- noise gain -------------------------------------------------------------------------------------------
def test_noise_gain_of_a_first_order_section_closed_form() -> None:
    """G = 3(z − 0.5)/(z − 0.2): h₀ = 3, h_k = 3(0.2 − 0.5)·0.2^(k−1); Σh² = 9(1 + 0.09/0.96)."""
    dcm = DCM(DT, np.array([0.5]), np.array([0.2]), 3.0)
    h = dcm.impulse_response()
    k = np.arange(1, h.size)
    np.testing.assert_allclose(h, np.concatenate([[3.0], 3.0 * -0.3 * 0.2 ** (k - 1)]), atol=1e-15)
    assert abs(h[-1]) <= 1e-10 * abs(h[0])  # decayed
    assert dcm.noise_gain() == pytest.approx(3.0 * math.sqrt(1 + 0.09 / 0.96), rel=1e-12)


def test_noise_gain_with_a_fir_stage_and_with_a_pole_at_the_origin() -> None:
    """With taps (c₀, c₁) after the section: Σy² = (c₀² + c₁²)Σh² + 2c₀c₁Σh_k·h_(k+1)."""
    c0, c1 = 0.7, 0.3
    dcm = DCM(DT, np.array([0.5]), np.array([0.2]), 3.0, fir=np.array([c0, c1]))
    sum_h2 = 9.0 * (1 + 0.09 / 0.96)
    sum_lag1 = 9.0 * (-0.3 + 0.09 * 0.2 / 0.96)
    assert dcm.noise_gain() == pytest.approx(math.sqrt((c0**2 + c1**2) * sum_h2 + 2 * c0 * c1 * sum_lag1), rel=1e-12)
    assert dcm.impulse_response().size == DCM(DT, np.array([0.5]), np.array([0.2]), 3.0).impulse_response().size + 1
    at_origin = DCM(DT, np.array([0.5]), np.array([0.0]), 2.0)  # h = [2, −1]
    assert at_origin.noise_gain() == pytest.approx(math.sqrt(5.0), rel=1e-12)


def test_the_impulse_response_decays_below_1e_10_of_its_start_for_a_slow_resonance() -> None:
    """impulse_response's promise, for a lightly damped pair at 0.99·e^(±0.01j): h_k is
    0.99^k·sin((k + 1)·0.01)/sin(0.01) (zeros at the origin), whose envelope is 100 times 0.99^k:
    the tail must cover the 1e-10 of the pole and the amplitude above its start, so at
    0.99^k = 1e-10 alone it still reads ~1e-8 of h₀."""
    pole = 0.99 * np.exp(0.01j)
    dcm = DCM(DT, np.array([0.0, 0.0]), np.array([pole, pole.conjugate()]), 1.0)
    h = dcm.impulse_response()
    k = np.arange(h.size)
    np.testing.assert_allclose(h, 0.99**k * np.sin((k + 1) * 0.01) / math.sin(0.01), atol=1e-9)
    assert np.max(np.abs(h[-16:])) <= 1e-10 * abs(h[0])

def test_noise_gain_of_a_pole_too_slow_is_an_error() -> None:
    with pytest.raises(AnalysisError, match="decays too slowly"):
        DCM(DT, np.array([0.5]), np.array([0.9999999]), 1.0).noise_gain()


# -- compensated FBSD ---------------------------------------------------------------------------------------
def first_edge_hz(b: np.ndarray, a: np.ndarray, level: float, near_hz: tuple[float, ...] = ()) -> tuple[float, str]:
    """The first frequency where |H(f)/H(0)| leaves 1 ± level, on scipy's freqz: a 1 Hz grid to
    Nyquist plus 0.01 Hz around each of `near_hz`, then brentq."""
    grid = np.unique(np.concatenate([np.arange(0.0, 0.5 / DT, 1.0)]
                                    + [np.arange(f - 50.0, f + 50.0, 0.01) for f in near_hz]))
    dc = abs(np.sum(b) / np.sum(a))

    def g(f: np.ndarray) -> np.ndarray:
        return np.abs(signal.freqz(b, a, worN=np.atleast_1d(f), fs=1 / DT)[1]) / dc

    values = g(grid)
    i = int(np.flatnonzero(np.abs(values - 1) > level)[0])
    target = 1 + level if values[i] > 1 else 1 - level
    edge = brentq(lambda f: g(f)[0] - target, grid[i - 1], grid[i], xtol=1e-9)
    return edge, "above" if values[i] > 1 else "below"


def resonance(fn_hz: float, zeta: float) -> np.ndarray:
    """a (powers of z⁻¹) of a discrete resonance at fn_hz with damping zeta (matched poles)."""
    w = 2 * np.pi * fn_hz
    p = np.exp((-zeta * w + 1j * w * math.sqrt(1 - zeta**2)) * DT)
    return np.real(np.poly([p, np.conj(p)]))


def test_compensated_fbsd_of_an_exactly_cancelled_resonance() -> None:
    a_model = resonance(25_000.0, 0.02)
    model = DiscreteModel(DT, a_model, np.array([0.0, np.sum(a_model)]))  # unit DC gain, one sample delay
    new_poles = np.roots(resonance(90_000.0, 0.6))
    dcm = DCM(DT, model.poles, new_poles, 1.0)
    b_total = np.convolve(model.b, dcm.b)
    a_total = np.convolve(model.a, dcm.a)
    edges = compensated_fbsd_edges(model, dcm)
    for key, level in (("5", 0.05), ("10", 0.10)):
        f_true, side = first_edge_hz(b_total, a_total, level)
        assert edges[key].frequency_hz == pytest.approx(f_true, rel=1e-7)
        assert edges[key].crossing == side
    assert compensated_fbsd_hz(model, dcm) == {k: e.frequency_hz for k, e in edges.items()}


def test_compensated_fbsd_searches_the_model_zeros_and_the_dcm_poles() -> None:
    """A notch of the model's zeros (123 456.7 Hz, off every grid) that the DCM keeps, and a narrow
    peak of the DCM's own poles (77 777.7 Hz): each found, each where freqz puts it."""
    fs = 1 / DT
    b_notch, a_notch = signal.iirnotch(123_456.7, 40_000.0, fs=fs)
    model = DiscreteModel(DT, a_notch, b_notch)
    dcm = DCM(DT, np.array([0.01]), np.array([0.0]), 1.0)  # flat to ±1 %: the notch is the model's
    edge = compensated_fbsd_edges(model, dcm, (0.05,))["5"]
    f_true, side = first_edge_hz(np.convolve(model.b, dcm.b), np.convolve(model.a, dcm.a), 0.05, (123_456.7,))
    assert edge.crossing == side == "below"
    assert edge.frequency_hz == pytest.approx(f_true, abs=1e-3)

    plain = DiscreteModel(DT, np.array([1.0]), np.array([0.0, 1.0]))  # a one-sample delay
    peak = np.roots(resonance(77_777.7, 1e-6))
    zeros = np.roots(resonance(77_777.7, 3e-6))  # a peak of height 3, within 5 % from 1 Hz off it
    dcm = DCM(DT, zeros, peak, float(np.real(np.prod(1 - peak) / np.prod(1 - zeros))))
    edge = compensated_fbsd_edges(plain, dcm, (0.05,))["5"]
    f_true, side = first_edge_hz(np.convolve(plain.b, dcm.b), np.convolve(plain.a, dcm.a), 0.05, (77_777.7,))
    assert edge.crossing == side == "above"
    assert edge.frequency_hz == pytest.approx(f_true, abs=1e-3)


def test_a_compensated_gain_within_the_band_to_nyquist_reports_nyquist() -> None:
    model = DiscreteModel(DT, np.array([1.0]), np.array([0.0, 1.0]))
    edges = compensated_fbsd_edges(model, DCM(DT, np.array([0.01]), np.array([0.0]), 1.0))  # flat to ±1 %
    assert all(e.crossing == "none" and e.frequency_hz == 0.5 / DT for e in edges.values())


def test_compensated_fbsd_refuses_another_interval_and_a_zero_dc_gain() -> None:
    model = DiscreteModel(DT, np.array([1.0, -0.5]), np.array([0.5]))
    with pytest.raises(AnalysisError, match="designed for a sample interval of 2e-06 s, the model has 1e-06 s"):
        compensated_fbsd_hz(model, DCM(2e-6, np.array([0.5]), np.array([0.2]), 1.0))
    zero_dc = DiscreteModel(DT, np.array([1.0, -0.5]), np.array([0.5, -0.5]))
    with pytest.raises(AnalysisError, match="zero DC gain"):
        compensated_fbsd_hz(zero_dc, DCM(DT, np.array([0.5]), np.array([0.2]), 1.0))
    with pytest.raises(AnalysisError, match="zero DC gain"):
        step_responses(zero_dc, DCM(DT, np.array([0.5]), np.array([0.2]), 1.0))


# -- step responses, rise and settling times ------------------------------------------------------------
def first_order_pair() -> tuple[DiscreteModel, DCM]:
    """Model 0.1/(1 − 0.9z⁻¹) and a DCM 5(z − 0.9)/(z − 0.5): model then DCM is 0.5/(1 − 0.5z⁻¹).
    Normalised step responses 1 − 0.9^(k+1) and 1 − 0.5^(k+1)."""
    return DiscreteModel(DT, np.array([1.0, -0.9]), np.array([0.1])), DCM(DT, np.array([0.9]), np.array([0.5]), 5.0)


def test_step_responses_of_first_order_systems() -> None:
    model, dcm = first_order_pair()
    alone, both = step_responses(model, dcm)
    # 4 response times of the slowest pole (−3/ln 0.9 = 28.47 samples) + b + the DCM's order + 64
    assert alone.size == both.size == math.ceil(4 * 3 / math.log(1 / 0.9)) + 1 + 1 + 64
    k = np.arange(alone.size)
    np.testing.assert_allclose(alone, 1 - 0.9 ** (k + 1), atol=1e-12)
    np.testing.assert_allclose(both, 1 - 0.5 ** (k + 1), atol=1e-12)
    alone, both = step_responses(model, dcm, n_samples=10)
    assert alone.size == both.size == 10


def test_the_step_responses_are_normalised_by_both_dc_gains() -> None:
    """A DCM with twice the gain (DC gain 2) gives the same normalised steps."""
    model, dcm = first_order_pair()
    doubled = DCM(DT, dcm.zeros, dcm.poles, 2 * dcm.gain)
    assert doubled.dc_gain == pytest.approx(2.0)
    for got, want in zip(step_responses(model, doubled), step_responses(model, dcm), strict=True):
        np.testing.assert_allclose(got, want, atol=1e-12)


def test_a_model_of_negative_dc_gain_has_the_same_normalised_steps() -> None:
    """A sensor read with inverted polarity: each response normalised by its own final value."""
    model, dcm = first_order_pair()
    inverted = DiscreteModel(DT, model.a, -model.b)
    for got, want in zip(step_responses(inverted, dcm), step_responses(model, dcm), strict=True):
        np.testing.assert_allclose(got, want, atol=1e-12)


def test_settling_times_closed_form() -> None:
    """1 − p^(k+1) stays within 5 % from the first k with p^(k+1) ≤ 0.05: k = 28 for 0.9, 4 for 0.5
    (0.9²⁹ = 0.047, 0.9²⁸ = 0.052; 0.5⁵ = 0.031, 0.5⁴ = 0.0625)."""
    model, dcm = first_order_pair()
    assert settling_times_samples(model, dcm) == (28.0, 4.0)
    assert settling_time_ratio(model, dcm) == 7.0
    # within 10 %: 0.9²² = 0.098 (k = 21), 0.5⁴ = 0.0625 (k = 3)
    assert settling_times_samples(model, dcm, 0.10) == (21.0, 3.0)
    assert compare_steps(model, dcm).settling_time_ratio(0.10) == 7.0


def test_a_linear_phase_fir_stage_is_a_delay_the_times_leave_out() -> None:
    """A FIR stage [0, 0, 1, 0, 0] (a pure delay of 2 samples, linear phase): step_responses and
    the settling time remove it; the same times as without it."""
    model, dcm = first_order_pair()
    delayed = DCM(DT, dcm.zeros, dcm.poles, dcm.gain, fir=np.array([0.0, 0.0, 1.0, 0.0, 0.0]))
    alone, both = step_responses(model, delayed)
    k = np.arange(alone.size)
    np.testing.assert_allclose(both, 1 - 0.5 ** (k + 1), atol=1e-12)
    np.testing.assert_allclose(alone, 1 - 0.9 ** (k + 1), atol=1e-12)
    steps = compare_steps(model, delayed)
    assert steps.lead == 2 and steps.both.size == alone.size + 2
    assert alone.size == both.size == step_responses(model, dcm)[0].size  # n samples from the step either way
    assert steps.settling_times_samples() == (28.0, 4.0)


def test_an_even_length_fir_stage_leaves_its_half_sample() -> None:
    """Taps [0, 0, ½, ½, 0, 0]: a delay of 2.5 samples, of which the whole 2 are removed; the
    compensated step is then ½(y[k] + y[k−1]) = 1 − 0.75·0.5^k (closed form)."""
    model, dcm = first_order_pair()
    even = DCM(DT, dcm.zeros, dcm.poles, dcm.gain, fir=np.array([0.0, 0.0, 0.5, 0.5, 0.0, 0.0]))
    _, both = step_responses(model, even)
    np.testing.assert_allclose(both, 1 - 0.75 * 0.5 ** np.arange(both.size), atol=1e-12)
    assert compare_steps(model, even).lead == 2


def test_rise_times_interpolate_linearly_between_samples() -> None:
    """A ramp k/37 crosses 10 % at 3.7 and 90 % at 33.3 samples: rise 29.6. The first-order pair:
    each crossing between the two samples that bracket it, closed form."""
    ramp = np.minimum(np.arange(60) / 37.0, 1.0)
    fast = np.minimum(np.arange(60) / 7.4, 1.0)  # 0.74 → 6.66: 5.92
    steps = StepComparison(ramp, fast)
    assert steps.rise_times_samples() == (pytest.approx(29.6, rel=1e-12), pytest.approx(5.92, rel=1e-12))
    assert steps.rise_time_ratio() == pytest.approx(5.0, rel=1e-12)

    def crossing(p: float, level: float) -> float:
        k = math.ceil(math.log(1 - level) / math.log(p) - 1)  # first sample at or above the level
        y0, y1 = 1 - p**k, 1 - p ** (k + 1)  # y0 = 0 at k = 0: the rest before the step
        return (k - 1) + (level - y0) / (y1 - y0)

    model, dcm = first_order_pair()
    want = tuple(crossing(p, 0.9) - crossing(p, 0.1) for p in (0.9, 0.5))
    assert rise_times_samples(model, dcm) == pytest.approx(want, rel=1e-9)
    assert rise_time_ratio(model, dcm) == pytest.approx(want[0] / want[1], rel=1e-9)


def test_rise_time_from_the_first_sample_and_its_errors() -> None:
    """A response at 50 % from its first sample crosses 10 % at −0.8, interpolated from the rest
    before the step (as from the zeros a FIR stage's delay puts before it: the time does not
    depend on that delay); one that never reaches 90 % has no rise time; one complete at its
    first sample rises in 0.8 sample."""
    slow = np.minimum(np.arange(40) / 20.0, 1.0)
    half = np.concatenate([[0.5], np.ones(39)])
    assert StepComparison(half, half).rise_times_samples() == (pytest.approx(1.6), pytest.approx(1.6))
    jump = np.concatenate([[0.95], np.ones(39)])  # 10 % at −1 + 0.1/0.95, 90 % at −1 + 0.9/0.95
    with pytest.raises(AnalysisError, match="never reaches 90 %"):
        StepComparison(np.full(40, 0.8), slow).rise_times_samples()
    # complete at its first sample: 0.8 sample from the rest before it (until issue 45's fix: 0,
    # refused as "rises within one sample")
    assert StepComparison(slow, np.ones(40)).rise_time_ratio() == pytest.approx(16.0 / 0.8, rel=1e-12)
    # a compensated rise of 0.8/0.95 sample (under one, above none) still gives its ratio
    assert StepComparison(slow, jump).rise_time_ratio() == pytest.approx(16.0 / (0.8 / 0.95), rel=1e-12)


def test_a_response_that_rests_on_a_level_crosses_it_where_it_first_reaches_it() -> None:
    """The first crossing is the first sample at or above the level (docstring: first crossings):
    a response that sits at exactly 10 % for two samples crosses 10 % at sample 0 (from the rest
    before it: −1 + 0.1/0.1), not where it leaves the level; 90 % between 0.1 and 1 at
    1 + 0.8/0.9."""
    resting = np.concatenate([[0.1, 0.1], np.ones(38)])
    assert StepComparison(resting, resting).rise_times_samples()[0] == pytest.approx(1.0 + 0.8 / 0.9, rel=1e-12)

def test_touching_the_tolerance_is_settled() -> None:
    """|1.25 − 1| = 0.25 exactly (binary fractions): on the ±25 % line, not outside it."""
    steps = StepComparison(np.array([1.25, 0.75, 1.0, 1.0]), np.ones(4))
    assert steps.settling_times_samples(0.25) == (0.0, 0.0)


def test_a_step_response_whose_fir_delay_passes_the_limit_is_refused() -> None:
    """n + lead samples are simulated: a pole that needs 4 000 000 − 1 samples with a 5-tap stage
    (lead 2) passes the 4 000 000 limit."""
    n_wanted = 4_000_000 - 1
    response_time = (n_wanted - 1 - 1 - 64 - 0.5) / 4  # n = ceil(4·T'_r) + b.size + order + 64
    p = math.exp(-3.0 / response_time)
    model = DiscreteModel(DT, np.array([1.0, -p]), np.array([1 - p]))
    dcm = DCM(DT, np.array([0.5]), np.array([0.2]), 1.0, fir=np.array([0.0, 0.0, 1.0, 0.0, 0.0]))
    with pytest.raises(AnalysisError, match="too slow to simulate"):
        step_responses(model, dcm)


def test_settling_time_ratio_with_a_compensated_response_settled_at_once() -> None:
    ringing = 1 + 0.2 * (-0.8) ** np.arange(50)  # outside 5 % while 0.2·0.8^k > 0.05: k ≤ 6
    steps = StepComparison(ringing, np.ones(50))
    assert steps.settling_times_samples() == (7.0, 0.0)
    assert steps.settling_time_ratio() == 7.0  # divided by at least one sample


def test_a_step_response_too_long_to_simulate_is_an_error() -> None:
    model = DiscreteModel(DT, np.array([1.0, -0.9999999]), np.array([1e-7]))
    with pytest.raises(AnalysisError, match="too slow to simulate"):
        step_responses(model, DCM(DT, np.array([0.5]), np.array([0.2]), 1.0))
