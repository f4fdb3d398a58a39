"""The simulated accelerometer truth against closed forms and scipy's own discretisation."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import signal

from hopkinson.drivers.sim.accelerometer import (
    AccelerometerTruth,
    Mode,
    coloured_noise,
    white_noise,
)


def test_single_mode_matches_second_order_closed_form():
    truth = AccelerometerTruth(modes=(Mode(30_000.0, 0.1),), sensitivity=2.0)
    f = np.array([0.0, 10_000.0, 30_000.0, 60_000.0])
    x = f / 30_000.0
    expected = 2.0 / (1 - x**2 + 2j * 0.1 * x)
    np.testing.assert_allclose(truth.frequency_response(f), expected, rtol=1e-10)


def test_discrete_poles_are_exp_sT_of_scipy_zoh():
    truth = AccelerometerTruth(modes=(Mode(27_000.0, 0.05), Mode(60_000.0, 0.3)), lowpass_hz=80_000.0)
    dt = 1e-6
    _, a = truth.discrete_tf(dt)
    np.testing.assert_allclose(np.sort_complex(np.roots(a)), np.sort_complex(truth.discrete_poles(dt)), atol=1e-9)
    assert truth.order == 6


def test_respond_has_dc_gain_sensitivity():
    truth = AccelerometerTruth(modes=(Mode(27_000.0, 0.05),), lowpass_hz=100_000.0, sensitivity=1e-3)
    y = truth.respond(np.ones(20_000), 1e-6)
    assert y[-1] == pytest.approx(1e-3, rel=1e-6)


@pytest.mark.parametrize("maker", [white_noise, coloured_noise])
def test_noise_has_requested_snr(maker):
    rng = np.random.default_rng(1)
    clean = np.sin(np.linspace(0, 200, 100_000))
    noise = maker(clean, 40.0, rng)
    snr = 10 * np.log10(np.mean(clean**2) / np.mean(noise**2))
    assert snr == pytest.approx(40.0, abs=0.3)


def test_coloured_noise_is_coloured():
    rng = np.random.default_rng(2)
    n = coloured_noise(np.ones(100_000), 20.0, rng, pole=0.9)
    lag1 = np.corrcoef(n[:-1], n[1:])[0, 1]
    assert lag1 == pytest.approx(0.9, abs=0.02)
    assert signal.welch(n)[1][1] > 10 * signal.welch(n)[1][-1]


@pytest.mark.parametrize("dt", [1e-6, 1e-8])
def test_sections_have_the_true_poles_and_gain_at_any_rate(dt):
    truth = AccelerometerTruth(modes=(Mode(27_000.0, 0.05), Mode(60_000.0, 0.3)), lowpass_hz=80_000.0, lowpass_order=3)
    sos = truth.sections(dt)
    poles = np.concatenate([np.roots(np.trim_zeros(row[3:], "b")) for row in sos])
    np.testing.assert_allclose(np.sort_complex(poles), np.sort_complex(truth.discrete_poles(dt)), rtol=1e-12, atol=1e-14)
    y = truth.respond(np.ones(int(round(2e-3 / dt))), dt)  # 2 ms of step: settled
    assert y[-1] == pytest.approx(1.0, rel=1e-6)


def test_sections_match_whole_model_zoh_at_low_rate():
    truth = AccelerometerTruth(modes=(Mode(27_000.0, 0.05),), lowpass_hz=100_000.0, lowpass_order=3)
    u = np.sin(np.linspace(0, 3, 4000)) ** 2
    b, a = truth.discrete_tf(1e-6)
    whole = signal.lfilter(b, a, u)
    np.testing.assert_allclose(truth.respond(u, 1e-6), whole, atol=2e-3 * np.max(np.abs(whole)))
