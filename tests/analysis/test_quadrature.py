"""Quadrature demodulation (Heydemann) against a closed-form motion with known ellipse errors."""

from __future__ import annotations

import math

import numpy as np
import pytest

from hopkinson.analysis.errors import AnalysisError
from hopkinson.analysis.quadrature import (
    Ellipse,
    demodulate_quadrature,
    fit_ellipse,
    grating_displacement_per_radian_m,
    michelson_displacement_per_radian_m,
)

FS_HZ = 50e6
K_M_PER_RAD = grating_displacement_per_radian_m(2e-6, (1, -1))  # d/(4π)


def half_sine_motion(n: int, width_s: float = 40e-6, peak_m_s2: float = 2e5, start_s: float = 20e-6):
    """Closed-form displacement and velocity of a half-sine acceleration pulse (then free flight)."""
    t = np.arange(n) / FS_HZ - start_s
    tc = np.clip(t, 0.0, width_s)
    w = math.pi / width_s
    velocity = peak_m_s2 / w * (1.0 - np.cos(w * tc))
    displacement = peak_m_s2 / w * (tc - np.sin(w * tc) / w) + np.where(t > width_s, (t - width_s) * velocity, 0.0)
    return displacement, velocity


def signals(phase: np.ndarray, p: float, q: float, r: float, g: float, alpha: float, noise: float = 0.0,
            seed: int = 1) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    u1 = p + r * np.cos(phase) + noise * rng.standard_normal(phase.size)
    u2 = q + r / g * np.sin(phase - alpha) + noise * rng.standard_normal(phase.size)
    return u1, u2


def test_ellipse_parameters_are_recovered() -> None:
    phase = np.linspace(0, 6 * np.pi, 20_000)
    truth = dict(p=0.12, q=-0.31, r=0.8, g=1.3, alpha=math.radians(12.0))
    e = fit_ellipse(*signals(phase, **truth, noise=1e-3))
    assert e.offset_1_v == pytest.approx(truth["p"], abs=2e-3)
    assert e.offset_2_v == pytest.approx(truth["q"], abs=2e-3)
    assert e.amplitude_v == pytest.approx(truth["r"], rel=3e-3)
    assert e.amplitude_ratio == pytest.approx(truth["g"], rel=3e-3)
    assert e.phase_error_rad == pytest.approx(truth["alpha"], abs=3e-3)
    c, s = e.correct(*signals(phase, **truth))
    np.testing.assert_allclose(np.unwrap(np.arctan2(s, c)), phase, atol=5e-3)


@pytest.mark.parametrize(
    ("p", "q", "g", "alpha_deg"),
    [(0.3, -0.2, 1.25, 10.0),   # offsets, unequal gains, 10° off quadrature
     (1.6, 1.2, 0.7, -15.0)],   # offsets larger than the amplitude: the origin lies outside the ellipse
)
def test_displacement_and_velocity_match_the_closed_form_motion(p: float, q: float, g: float, alpha_deg: float) -> None:
    n = 5_000
    x_true, v_true = half_sine_motion(n)
    phase_true = x_true / K_M_PER_RAD
    assert phase_true[-1] > 8 * math.pi  # several fringes
    u1, u2 = signals(phase_true, p, q, 1.0, g, math.radians(alpha_deg), noise=2e-3)
    result = demodulate_quadrature(u1, u2, 1 / FS_HZ, K_M_PER_RAD, velocity_window_samples=31)
    phase_error = result.phase_rad - (phase_true - phase_true[0])
    assert np.max(np.abs(phase_error)) < 0.02  # rad: ~1/300 of a fringe
    assert np.max(np.abs(result.displacement_m - x_true)) < 0.02 * K_M_PER_RAD
    inner = slice(50, -50)
    assert np.max(np.abs(result.velocity_m_s[inner] - v_true[inner])) < 0.01 * np.max(v_true)
    assert result.radius_spread < 0.01
    # the plain arctangent of the raw signals is far off: the correction is what makes it right
    plain = np.unwrap(np.arctan2(u2, u1))
    assert np.max(np.abs((plain - plain[0]) - (phase_true - phase_true[0]))) > 0.15


def test_michelson_scale_and_sign() -> None:
    wavelength = 632.8e-9
    k = michelson_displacement_per_radian_m(wavelength)
    t = np.arange(4_000) / FS_HZ
    x_true = 3e-6 * np.sin(2 * np.pi * 20e3 * t)  # ±3 µm: ±9.5 fringes, forward and back
    u1, u2 = signals(x_true / k, 0.05, 0.02, 0.5, 1.1, math.radians(5.0))
    result = demodulate_quadrature(u1, u2, 1 / FS_HZ, k)
    np.testing.assert_allclose(result.displacement_m, x_true - x_true[0], atol=wavelength / 500)
    # the same motion with the channels' roles swapped runs backwards
    reverse = demodulate_quadrature(u2, u1, 1 / FS_HZ, k)
    assert np.corrcoef(reverse.displacement_m, result.displacement_m)[0, 1] < -0.99


def test_grating_scale_follows_the_beat_frequency_law() -> None:
    # Δf = v·(φ − ξ)/d: one beat period per d/(φ − ξ) of travel, i.e. 2π rad
    d = 2e-6
    assert grating_displacement_per_radian_m(d, (1, -1)) * 2 * math.pi == pytest.approx(d / 2)
    assert grating_displacement_per_radian_m(d, (1, 0)) * 2 * math.pi == pytest.approx(d)
    with pytest.raises(AnalysisError, match="orders"):
        grating_displacement_per_radian_m(d, (1, 1))


def test_too_little_motion_is_refused() -> None:
    phase = np.linspace(0, 0.8 * np.pi, 2_000)  # under half a fringe: an arc, not an ellipse
    u1, u2 = signals(phase, 0.1, 0.1, 1.0, 1.1, 0.1, noise=1e-3)
    with pytest.raises(AnalysisError, match="cover"):
        demodulate_quadrature(u1, u2, 1e-8, K_M_PER_RAD)


@pytest.mark.parametrize(
    ("u1", "u2", "words"),
    [(np.zeros(10), np.zeros(11), "differ in length"),
     (np.array([0.0, np.nan] * 10), np.ones(20), "NaN"),
     (np.ones(100), np.linspace(0, 1, 100), "constant")],
)
def test_bad_signals_are_named(u1: np.ndarray, u2: np.ndarray, words: str) -> None:
    with pytest.raises(AnalysisError, match=words):
        demodulate_quadrature(u1, u2, 1e-8, K_M_PER_RAD)


def test_bad_options_are_named() -> None:
    phase = np.linspace(0, 6 * np.pi, 1_000)
    u1, u2 = signals(phase, 0, 0, 1, 1, 0)
    with pytest.raises(AnalysisError, match="velocity_window_samples"):
        demodulate_quadrature(u1, u2, 1e-8, K_M_PER_RAD, velocity_window_samples=4)
    with pytest.raises(AnalysisError, match="sample_interval_s"):
        demodulate_quadrature(u1, u2, 0.0, K_M_PER_RAD)
    with pytest.raises(AnalysisError, match="displacement_per_radian_m"):
        demodulate_quadrature(u1, u2, 1e-8, float("nan"))


def test_ellipse_correct_is_the_inverse_of_the_model() -> None:
    e = Ellipse(offset_1_v=0.2, offset_2_v=-0.1, amplitude_v=2.0, amplitude_ratio=0.8, phase_error_rad=0.3)
    phase = np.linspace(-3, 3, 50)
    u1 = 0.2 + 2.0 * np.cos(phase)
    u2 = -0.1 + 2.0 / 0.8 * np.sin(phase - 0.3)
    c, s = e.correct(u1, u2)
    np.testing.assert_allclose(c, 2.0 * np.cos(phase), atol=1e-12)
    np.testing.assert_allclose(s, 2.0 * np.sin(phase), atol=1e-12)


def test_a_fringe_rate_commensurate_with_the_sampling_does_not_fool_the_fit() -> None:
    # exactly 20 samples per fringe: any regular subset of every 20th sample sits at one phase
    phase = 2 * np.pi * np.arange(40_000) / 20.0
    u1, u2 = signals(phase, 0.2, -0.1, 1.0, 1.25, 0.2, noise=1e-3)
    result = demodulate_quadrature(u1, u2, 1e-8, K_M_PER_RAD, max_fit_points=1_000)
    assert result.ellipse.amplitude_ratio == pytest.approx(1.25, rel=0.01)
    assert np.max(np.abs(result.phase_rad - phase)) < 0.02
