"""Resampling to the analysis rate and channel alignment, against closed-form signals."""

from __future__ import annotations

import numpy as np
import pytest

from hopkinson.analysis.errors import AnalysisError
from hopkinson.analysis.records import Record
from hopkinson.analysis.resample import (
    DEFAULT_ANALYSIS_RATE_HZ,
    estimate_delay_samples,
    resample_to_rate,
    resampling_factors,
    shift_samples,
)
from hopkinson.drivers.sim.shock import gaussian_velocity_m_s2


def _gauss(t_s: np.ndarray, centre_s: float, sigma_s: float) -> np.ndarray:
    return gaussian_velocity_m_s2(t_s, sigma_s, 1.0, centre_s)


def test_record_at_or_below_rate_is_returned_unchanged() -> None:
    t = np.arange(1000) * 1e-6
    rec = Record(1e-6, _gauss(t, 3e-4, 1e-5), _gauss(t, 3e-4, 1e-5))
    assert resample_to_rate(rec) is rec
    slow = Record(2e-6, rec.reference, rec.response)
    assert resample_to_rate(slow, DEFAULT_ANALYSIS_RATE_HZ) is slow


def test_10_ms_per_s_record_resampled_to_analysis_rate_matches_the_signal() -> None:
    # 10 MS/s: a smooth pulse (in band) plus a 3 MHz tone (far above the new 500 kHz Nyquist).
    dt = 1e-7
    t = 5e-6 + np.arange(20_000) * dt
    pulse = _gauss(t, 1e-3, 8e-6) + 0.3 * np.sin(2 * np.pi * 40e3 * t)
    tone = 0.5 * np.sin(2 * np.pi * 3e6 * t)
    rec = Record(dt, pulse + tone, 2.0 * pulse + 1.0, start_time_s=5e-6)
    out = resample_to_rate(rec, 1e6)
    assert out.sample_interval_s == pytest.approx(1e-6, rel=1e-12)
    assert out.start_time_s == rec.start_time_s
    assert out.n_samples == 2000
    truth = _gauss(out.time_s, 1e-3, 8e-6) + 0.3 * np.sin(2 * np.pi * 40e3 * out.time_s)
    inner = slice(50, -50)  # away from the filter's edge transients
    # The tone is removed (anti-aliased) and the in-band pulse kept, with no time shift.
    assert np.max(np.abs(out.reference - truth)[inner]) < 2e-3
    assert np.max(np.abs(out.response - (2.0 * truth + 1.0))) < 2e-2  # constant offset: no edge ringing
    assert np.max(np.abs(out.response - (2.0 * truth + 1.0))[inner]) < 2e-3


def test_non_integer_ratio_uses_exact_rational_factors() -> None:
    assert resampling_factors(12.5e6, 1e6) == (2, 25)
    assert resampling_factors(10e6, 1e6) == (1, 10)
    dt = 1 / 12.5e6
    t = np.arange(25_000) * dt
    x = _gauss(t, 1e-3, 1e-5)
    out = resample_to_rate(Record(dt, x, x), 1e6)
    assert out.sample_rate_hz == pytest.approx(1e6, rel=1e-12)
    assert np.max(np.abs(out.reference - _gauss(out.time_s, 1e-3, 1e-5))) < 1e-3


@pytest.mark.parametrize("delay", [3.0, 3.3, -2.6, 0.45])
def test_delay_estimate_recovers_a_known_offset(delay: float) -> None:
    n = np.arange(4000)
    ref = np.exp(-0.5 * ((n - 2000) / 12.0) ** 2)
    resp = -1.7 * np.exp(-0.5 * ((n - 2000 - delay) / 12.0) ** 2) + 0.2  # inverted, offset
    est = estimate_delay_samples(ref, resp, max_lag=20)
    assert est == pytest.approx(delay, abs=0.02)


def test_delay_estimate_rejects_flat_channel() -> None:
    with pytest.raises(AnalysisError, match="flat"):
        estimate_delay_samples(np.ones(100), np.ones(100), max_lag=5)


@pytest.mark.parametrize("delay", [4.0, 2.25, -3.7, 0.5])
def test_shift_samples_matches_the_analytically_shifted_pulse(delay: float) -> None:
    n = np.arange(3000, dtype=float)
    x = 0.5 + np.exp(-0.5 * ((n - 1500) / 6.0) ** 2)  # non-zero ends: must not ring
    y = shift_samples(x, delay)
    truth = 0.5 + np.exp(-0.5 * ((n - 1500 - delay) / 6.0) ** 2)
    assert y.shape == x.shape
    assert np.max(np.abs(y - truth)) < 1e-6


@pytest.mark.parametrize("delay", [0.37, 1.37, -2.63])
def test_shift_samples_of_band_limited_noise_matches_the_analytic_shift(delay: float) -> None:
    # A sum of random sinusoids below 0.3 cycles/sample with non-periodic ends: the shifted
    # signal is known in closed form at every sample.
    rng = np.random.default_rng(1)
    omega = 2 * np.pi * rng.uniform(0.01, 0.3, 20)
    phase = rng.uniform(0, 2 * np.pi, 20)

    def tones(k: np.ndarray) -> np.ndarray:
        return np.sum(np.sin(np.outer(k, omega) + phase), axis=1)

    k = np.arange(4000, dtype=float)
    err = np.abs(shift_samples(tones(k), delay) - tones(k - delay))
    assert np.max(err[100:-100]) < 1e-3 * np.max(np.abs(tones(k)))
