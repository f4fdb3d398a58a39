"""analysis.sample_counts: whole sample counts from ratios of floats, against exact rational
arithmetic; and the interferometer's box-car decimation at digitizer rates whose sample interval
is not a binary fraction (125, 250, 500 MS/s, 1 GS/s: 1 / (1 / 250e6) is 249999999.99999997)."""

from __future__ import annotations

import math
from fractions import Fraction

import numpy as np
import pytest

from hopkinson.analysis.beat_phase import beat_phase
from hopkinson.analysis.reduce import quadrature_phase
from hopkinson.analysis.sample_counts import ceil_count, floor_count
from hopkinson.drivers.sim.doppler_beat import QuadratureOutput, pm_beat
from hopkinson.drivers.sim.shock import G_M_S2, half_sine_m_s2, velocity_m_s

DIGITIZER_RATES_HZ = (1e7, 2e7, 2.5e7, 5e7, 1e8, 1.25e8, 2e8, 2.5e8, 5e8, 1e9, 1.25e9, 2.5e9, 5e9, 1e10)
TARGET_RATES_HZ = (5e5, 1e6, 2e6, 2.5e6, 4e6, 5e6, 1e7)


@pytest.mark.parametrize("rate_hz", DIGITIZER_RATES_HZ)
def test_a_rate_over_a_rate_counts_as_exact_arithmetic_does(rate_hz: float) -> None:
    fs = 1.0 / (1.0 / rate_hz)  # as a record's sample interval gives it back
    for target in TARGET_RATES_HZ:
        exact = Fraction(int(rate_hz)) / Fraction(int(target))
        assert floor_count(fs / target) == math.floor(exact), (rate_hz, target)
        assert ceil_count(fs / target) == math.ceil(exact), (rate_hz, target)


def test_durations_over_sample_intervals_count_whole_samples() -> None:
    # 8 µs at 1 µs read 7.999999999999999 or 8.000000000000002 depending on how dt was spelt
    for dt in (1e-6, 0.9999999999999972e-6, 1.0000000000000028e-6):
        assert ceil_count(8e-6 / dt) == 8 and floor_count(8e-6 / dt) == 8
    assert ceil_count(8.5) == 9 and floor_count(8.5) == 8  # a true fraction is not rounded away
    assert ceil_count(0.0) == 0 and floor_count(0.9999) == 0


def _shot(rate_hz: float, n: int) -> tuple[float, np.ndarray]:
    dt = 1.0 / rate_hz
    t = np.arange(n) * dt
    velocity = velocity_m_s(half_sine_m_s2(t, 40e-6, 20_000 * G_M_S2, 100e-6), dt)
    return dt, velocity


@pytest.mark.parametrize("rate_hz", (2.5e8, 5e8, 1e9))
def test_the_pm_beat_is_decimated_to_exactly_10_ms_per_s_at_rates_that_are_not_binary_fractions(rate_hz: float) -> None:
    dt, velocity = _shot(rate_hz, int(rate_hz * 300e-6))
    beat = beat_phase(pm_beat(velocity, dt, snr_db=None, initial_phase_rad=1.0), dt)
    assert beat.decimation == round(rate_hz / 10e6)  # 24, 49 and 99 before: 10.4, 10.2 and 10.1 MS/s
    assert beat.sample_interval_s == pytest.approx(1e-7, rel=1e-12)


def test_the_quadrature_pair_is_decimated_to_exactly_10_ms_per_s_at_250_ms_per_s() -> None:
    dt, velocity = _shot(2.5e8, 75_000)
    u1, u2 = pm_beat(velocity, dt, snr_db=None, initial_phase_rad=1.0,
                     quadrature=QuadratureOutput(offset_v=0.1, gain_ratio=0.9, phase_error_rad=0.05))
    phase = quadrature_phase(u1, u2, dt, decimated_rate_hz=10e6)
    assert phase.decimation == 25  # 24 before
    assert phase.sample_interval_s == pytest.approx(1e-7, rel=1e-12)
