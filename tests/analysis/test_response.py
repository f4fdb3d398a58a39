"""analysis.response against independent truths: the paper's Table 1, closed-form
second-order band edges, and a simulated accelerometer whose continuous model is known."""

from __future__ import annotations

import json

import numpy as np
import pytest
from scipy import signal
from scipy.optimize import brentq

from hopkinson.analysis.errors import AnalysisError
from hopkinson.analysis.model import DiscreteModel
from hopkinson.analysis.response import (
    band_edges,
    base_grid,
    continuous_tf,
    fbsd_edges,
    fbsd_from_response,
    fbsd_hz,
    fbsd_report,
    frequency_response,
    model_sos,
    natural_frequency_damping,
    pole_analysis,
    to_continuous,
)
from hopkinson.drivers.sim.accelerometer import AccelerometerTruth, Mode

TABLE1_POLES = np.array([0.9740 + 0.1396j, 0.9740 - 0.1396j, 0.8174 + 0.0518j, 0.8174 - 0.0518j])


def second_order_gain(fn_hz: float, zeta: float):
    """|H(f)| of the unit-DC-gain second-order low-pass (closed form)."""

    def gain(f: np.ndarray) -> np.ndarray:
        x = np.asarray(f, dtype=float) / fn_hz
        return 1.0 / np.sqrt((1 - x**2) ** 2 + (2 * zeta * x) ** 2)

    return gain


def analytic_edge(fn_hz: float, zeta: float, level: float) -> tuple[float, str]:
    """First x = f/fn where |H| = 1 ± level: (1−u)² + 4ζ²u = 1/g², u = x², smallest u > 0."""
    candidates = []
    for g, side in ((1 + level, "above"), (1 - level, "below")):
        roots = np.roots([1.0, 4 * zeta**2 - 2.0, 1.0 - 1.0 / g**2])
        real = [r.real for r in roots if abs(r.imag) < 1e-12 and r.real > 0]
        if real:
            candidates.append((np.sqrt(min(real)) * fn_hz, side))
    return min(candidates)


def test_table1_pole_analysis_reproduces_the_paper():
    rows = pole_analysis(TABLE1_POLES)
    assert [round(r["response_time_samples"], 2) for r in rows] == [185.45, 185.45, 15.03, 15.03]
    assert [round(r["ratio"], 2) for r in rows] == [1.0, 1.0, 12.34, 12.34]
    assert rows[0]["pole"] == [0.974, 0.1396]
    # the paper's literal formula 3/ln(cos θ/α), θ = atan(β/α), for the first pole
    a, b = 0.9740, 0.1396
    assert rows[0]["response_time_samples"] == pytest.approx(3 / np.log(np.cos(np.arctan(b / a)) / a), rel=1e-12)


def test_pole_analysis_real_pole_origin_and_unstable():
    rows = pole_analysis(np.array([0.5, 0.0]))
    assert rows[0]["response_time_samples"] == pytest.approx(3 / np.log(1 / 0.5))
    assert rows[1]["response_time_samples"] == 0.0 and rows[1]["ratio"] is None
    with pytest.raises(AnalysisError, match="outside the unit circle"):
        pole_analysis(np.array([1.01, 0.5]))


@pytest.mark.parametrize(
    ("zeta", "first_side"),
    [(0.02, "above"), (0.3, "above"), (0.6, "below"), (1.5, "below")],
)
def test_fbsd_closed_form_second_order(zeta, first_side):
    fn = 30_000.0
    edges = band_edges(second_order_gain(fn, zeta), 5 * fn, (0.05, 0.10))
    for key, level in (("5", 0.05), ("10", 0.10)):
        f_true, side = analytic_edge(fn, zeta, level)
        assert edges[key].frequency_hz == pytest.approx(f_true, rel=1e-9)
        assert edges[key].crossing == side
    assert edges["5"].crossing == first_side


def test_fbsd_lightly_damped_is_two_sided_not_a_drop():
    """A one-sided (drop-only) band would put the ±5 % edge past the resonance."""
    fn, zeta = 30_000.0, 0.05
    edge = band_edges(second_order_gain(fn, zeta), 5 * fn, (0.05,))["5"]
    assert edge.crossing == "above"
    assert edge.frequency_hz == pytest.approx(analytic_edge(fn, zeta, 0.05)[0], rel=1e-9)
    assert edge.frequency_hz < 0.25 * fn  # far below the resonance, where a drop-only band would put it


def test_fbsd_of_discrete_model_matches_continuous_truth():
    """ZOH model of a 27 kHz, ζ = 0.05 accelerometer at 1 MS/s: within 0.2 % of the analytic edge."""
    truth = AccelerometerTruth(modes=(Mode(27_000.0, 0.05),))
    b, a = truth.discrete_tf(1e-6)
    model = DiscreteModel(1e-6, a, b)
    got = fbsd_hz(model)
    for key, level in (("5", 0.05), ("10", 0.10)):
        f_true, _ = analytic_edge(27_000.0, 0.05, level)
        assert got[key] == pytest.approx(f_true, rel=2e-3)


def test_fbsd_never_leaving_band_reports_nyquist_json_safe():
    model = DiscreteModel(1e-6, [1.0], [2.5])
    report = fbsd_report(model)
    assert report["5"]["frequency_hz"] == pytest.approx(500_000.0)
    assert report["5"]["crossing"] == "none" and report["5"]["within_band_to_limit"] is True
    json.dumps(report, allow_nan=False)
    assert fbsd_hz(model) == {"5": pytest.approx(5e5), "10": pytest.approx(5e5)}


def notch_edge_hz(b: np.ndarray, a: np.ndarray, f0_hz: float, level: float, fs_hz: float) -> float:
    """The notch's lower band edge: |H(f)/H(0)| = 1 − level just below f0, found on scipy's
    freqz (not on the code under test) by bisection between f0 − 1 kHz and f0."""
    dc = abs(np.sum(b) / np.sum(a))

    def offset(f: float) -> float:
        return abs(signal.freqz(b, a, worN=[f], fs=fs_hz)[1][0]) / dc - (1.0 - level)

    return brentq(offset, f0_hz - 1_000.0, f0_hz, xtol=1e-9)


@pytest.mark.parametrize("f0_hz", [100_010.0, 123_456.7])
def test_fbsd_finds_a_notch_narrower_than_the_grid(f0_hz):
    """A notch ~3 Hz wide, off the 25 Hz search grid (Nyquist / 20 000): found only because the
    zeros' angles are searched too; the edge is the notch's own, to a millihertz."""
    fs = 1e6
    assert (f0_hz / (0.5 * fs / 20_000)) % 1 > 0.1  # not on a grid point
    b, a = signal.iirnotch(f0_hz, 30_000.0, fs=fs)
    model = DiscreteModel(1 / fs, a, b)
    f_grid = np.linspace(0.0, 0.5 * fs, 20_001)
    assert np.all(np.abs(np.abs(signal.freqz(b, a, worN=f_grid, fs=fs)[1]) - 1) < 0.05)  # the grid alone misses it
    edge = fbsd_report(model)["5"]
    assert edge["crossing"] == "below"
    assert edge["frequency_hz"] == pytest.approx(notch_edge_hz(b, a, f0_hz, 0.05, fs), abs=1e-3)


def test_one_grid_shared_by_several_models_finds_each_models_own_edge():
    """The budget builds `base_grid` once for all its models: each model's edges are still its own
    (its zeros' angles join the shared grid per call), the narrow notches of both to a millihertz."""
    fs = 1e6
    grid = base_grid(0.5 * fs)
    for f0_hz in (123_456.7, 100_010.0):
        b, a = signal.iirnotch(f0_hz, 30_000.0, fs=fs)
        edge = fbsd_edges(DiscreteModel(1 / fs, a, b), grid=grid)["5"]
        assert edge.crossing == "below"
        assert edge.frequency_hz == pytest.approx(notch_edge_hz(b, a, f0_hz, 0.05, fs), abs=1e-3)


def test_fbsd_from_sampled_response_is_exact_for_a_linear_gain():
    """Linear interpolation between the bracketing samples is exact where the gain is linear:
    g(f) = 1 − f/F leaves 1 − L at f = L·F, here between grid points."""
    f = np.linspace(0.0, 10_000.0, 201)  # 50 Hz steps; the edges at 537.5 and 1 075 Hz fall between
    edges = fbsd_from_response(f, 1.0 - f / 10_750.0)
    assert edges["5"].frequency_hz == pytest.approx(0.05 * 10_750.0, abs=1e-9)
    assert edges["10"].frequency_hz == pytest.approx(0.10 * 10_750.0, abs=1e-9)
    assert edges["5"].crossing == edges["10"].crossing == "below"


def test_fbsd_from_sampled_response_interpolates():
    """On the closed-form second-order gain sampled every 50 Hz, each edge is within the linear
    interpolation's error bound h²·max|g''| / (8·|g'|) over its bracket (~0.1 Hz here), far
    inside one grid step, so an edge read one sample off fails."""
    fn, zeta = 30_000.0, 0.05
    h = 50.0
    f = np.arange(0.0, 100_000.0 + h, h)
    gain = second_order_gain(fn, zeta)
    edges = fbsd_from_response(f, gain(f))
    for key, level in (("5", 0.05), ("10", 0.10)):
        f_true, side = analytic_edge(fn, zeta, level)
        fine = np.linspace(f_true - h, f_true + h, 2001)
        slope = np.gradient(gain(fine), fine)
        curvature = np.gradient(slope, fine)
        bound = h**2 * np.max(np.abs(curvature)) / (8 * np.min(np.abs(slope)))
        assert bound < 0.01 * h
        assert abs(edges[key].frequency_hz - f_true) <= bound
        assert edges[key].crossing == side


def test_frequency_response_first_order_closed_form():
    p, dt = 0.9, 1e-5
    model = DiscreteModel(dt, [1.0, -p], [1 - p])
    f = np.array([0.0, 1_000.0, 20_000.0, 50_000.0])
    z_inv = np.exp(-2j * np.pi * f * dt)
    np.testing.assert_allclose(frequency_response(model, f), (1 - p) / (1 - p * z_inv), rtol=1e-12)


def test_to_continuous_recovers_the_true_poles_and_response():
    truth = AccelerometerTruth(modes=(Mode(27_000.0, 0.05), Mode(61_000.0, 0.02)), lowpass_hz=150_000.0)
    dt = 1e-6
    b, a = truth.discrete_tf(dt)
    model = DiscreteModel(dt, a, b)
    zeros_s, poles_s, gain = to_continuous(model)
    _, true_p, _ = truth.continuous_zpk()
    np.testing.assert_allclose(np.sort_complex(poles_s), np.sort_complex(true_p), rtol=1e-8)
    fn, zeta = natural_frequency_damping(model.poles, dt)
    assert sorted(np.round(fn[zeta < 0.5], 3)) == [27_000.0, 27_000.0, 61_000.0, 61_000.0]
    # ZOH sampling zeros are dropped; the DC gain is matched; magnitudes agree in band
    assert np.all(np.abs(zeros_s.imag) < np.pi / dt)
    num, den = continuous_tf(model)
    f = np.linspace(0, 40_000, 41)
    _, h = signal.freqs(num, den, worN=2 * np.pi * f)
    np.testing.assert_allclose(np.abs(h), np.abs(truth.frequency_response(f)), rtol=0.02)
    assert abs(h[0]) == pytest.approx(1.0, rel=1e-9)


def test_model_sos_handles_delay_and_short_numerator():
    x = np.random.default_rng(1).standard_normal(200)
    a = [1.0, -1.5, 0.7]
    cases = [(a, b) for b in ([0.0, 0.1, 0.2], [0.0, 0.0, 0.1], [0.1, 0.2], [0.3, 0.1, 0.2, 0.05], [0, 0, 0, 0.1], [0.5])]
    cases += [([1.0], [0.0, 0.0, 0.0, 2.0]), ([1.0, -0.5], [0.0, 1.0])]
    for a_, b in cases:
        model = DiscreteModel(1e-6, a_, b)
        np.testing.assert_allclose(signal.sosfilt(model_sos(model), x), signal.lfilter(b, a_, x), atol=1e-12)


def test_band_edges_rejects_bad_input():
    with pytest.raises(AnalysisError, match="normalise"):
        band_edges(lambda f: np.full_like(f, 2.0), 1000.0)
    with pytest.raises(AnalysisError, match="DC gain"):
        fbsd_hz(DiscreteModel(1e-6, [1.0, -0.5], [1.0, -1.0]))
