"""PM Doppler beat: the synthetic generator and its demodulation, against known velocity histories.

The truth is the simulated motion (drivers/sim: half-sine acceleration, its integral) and the
closed forms of the beat (Δf = v·(φ − ξ)/d, Eq. 37) and of a half-sine's 10 % width
(δ·(1 − 2·asin(0.1)/π)). Every case draws the beat's phase at rest from a fixed set that
includes the fringe's extremes (the hardest place for a single-channel PM to start from).
"""

from __future__ import annotations

import numpy as np
import pytest

from hopkinson.analysis import differentiating_lowpass, doppler
from hopkinson.analysis.beat_phase import beat_phase
from hopkinson.analysis.errors import AnalysisError
from hopkinson.analysis.excitation import pulse_width
from hopkinson.drivers.sim.doppler_beat import (
    DEFAULT_GRATING_PITCH_M,
    beat_frequency_hz,
    pm_beat,
    velocity_m_s_to_displacement_m,
)
from hopkinson.drivers.sim.shock import G_M_S2, half_sine_m_s2, velocity_m_s

DT = 1e-8  # 100 MS/s
START_S = 300e-6  # pre-trigger rest before the pulse
PHASES_AT_REST = (0.0, 1.0, 2.0, np.pi, 4.3, 5.76)


def half_sine_shot(peak_g: float, width_s: float, snr_db: float | None, phase_at_rest: float, seed: int = 0,
                   n: int = 200_000, **beat_options: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """time, true acceleration, true velocity and PM beat of a half-sine shot."""
    t = np.arange(n) * DT
    acc = half_sine_m_s2(t, width_s, peak_g * G_M_S2, START_S)
    vel = velocity_m_s(acc, DT)
    beat = pm_beat(vel, DT, snr_db=snr_db, initial_phase_rad=phase_at_rest, rng=np.random.default_rng(seed),
                   **beat_options)
    return t, acc, vel, beat


def width_10_percent(width_s: float) -> float:
    """Closed form: a half-sine of base width δ is above 10 % of its peak for δ·(1 − 2·asin(0.1)/π)."""
    return width_s * (1.0 - 2.0 * np.arcsin(0.1) / np.pi)


# --------------------------------------------------------------------------- the generator
def test_beat_frequency_is_v_times_order_difference_over_pitch() -> None:
    n = 100_000
    for orders, factor in (((1, -1), 2), ((2, -1), 3)):
        x = pm_beat(np.full(n, 5.0), DT, orders=orders, snr_db=None, fluctuation=0.0, dc_offset_v=0.0,
                    initial_phase_rad=0.0)
        spectrum = np.abs(np.fft.rfft(x * np.hanning(n)))
        peak_hz = np.fft.rfftfreq(n, DT)[np.argmax(spectrum)]
        expected = factor * 5.0 / DEFAULT_GRATING_PITCH_M
        assert beat_frequency_hz(5.0, orders=orders) == pytest.approx(expected)
        assert peak_hz == pytest.approx(expected, abs=2.0 / (n * DT))


def test_beat_phase_integrates_the_velocity() -> None:
    # Constant acceleration a from rest: displacement a·t²/2, phase 4π/d times it (orders ±1).
    a = 2.0e5
    t = np.arange(50_000) * DT
    x = pm_beat(a * t, DT, snr_db=None, fluctuation=0.0, dc_offset_v=0.0, amplitude_v=1.0, initial_phase_rad=0.3)
    expected = np.cos(0.3 + 4.0 * np.pi / DEFAULT_GRATING_PITCH_M * 0.5 * a * t**2)
    assert np.max(np.abs(x - expected)) < 1e-6
    assert velocity_m_s_to_displacement_m(a * t, DT)[-1] == pytest.approx(0.5 * a * t[-1] ** 2, rel=1e-6)


def test_beat_noise_offset_and_fluctuation() -> None:
    n = 400_000
    x = pm_beat(np.full(n, 10.0), DT, snr_db=20.0, amplitude_v=0.4, dc_offset_v=0.15, fluctuation=0.0,
                rng=np.random.default_rng(3))
    clean = pm_beat(np.full(n, 10.0), DT, snr_db=None, amplitude_v=0.4, dc_offset_v=0.15, fluctuation=0.0,
                    rng=np.random.default_rng(3))
    assert np.mean(x) == pytest.approx(0.15, abs=2e-3)
    snr = 10 * np.log10(np.mean((clean - 0.15) ** 2) / np.mean((x - clean) ** 2))
    assert snr == pytest.approx(20.0, abs=0.1)
    slow = pm_beat(np.full(n, 10.0), DT, snr_db=None, fluctuation=0.1, fluctuation_hz=1000.0, dc_offset_v=0.0,
                   amplitude_v=1.0, rng=np.random.default_rng(4))
    envelope = np.abs(slow).reshape(-1, 1000).max(axis=1)  # 10 µs windows hold 100 beat periods
    assert 0.95 * 0.2 < envelope.max() - envelope.min() < 0.2 + 1e-9  # ±10 % over its 1 ms period


# --------------------------------------------------------------------------- demodulation
ACCURACY_CASES = [
    # peak g, pulse width, SNR dB: the paper's shot, the shortest, the widest/softest and
    # others in between, 20 dB to 40 dB. The grating moves ≥ 78 fringes during each pulse
    # (a·δ²/π over d/2); see analysis.doppler's notes for shots with fewer.
    (100_000, 38.6e-6, 20.0),
    (100_000, 20e-6, 40.0),
    (1_000, 200e-6, 20.0),
    (10_000, 100e-6, 20.0),
    (10_000, 50e-6, 40.0),
    (50_000, 50e-6, 30.0),
    (20_000, 200e-6, 20.0),
]


@pytest.mark.parametrize(("peak_g", "width_s", "snr_db"), ACCURACY_CASES)
def test_demodulated_velocity_peak_and_width_against_the_truth(peak_g: float, width_s: float, snr_db: float) -> None:
    for k, phase in enumerate(PHASES_AT_REST):
        t, acc, vel, beat = half_sine_shot(peak_g, width_s, snr_db, phase, seed=k)
        d = doppler.demodulate(beat, DT, DEFAULT_GRATING_PITCH_M)
        assert d.sample_interval_s == pytest.approx(1e-6)
        true_v = np.interp(d.time_s, t, vel)
        inner = slice(60, -60)  # the differentiating low-pass' reach at the record's ends
        v_error = np.max(np.abs(d.velocity_m_s - true_v)[inner]) / vel.max()
        assert v_error <= 1e-3, f"phase at rest {phase}: velocity error {v_error:.2%} of the peak"
        pulse = pulse_width(d.acceleration_m_s2, d.sample_interval_s, d.start_time_s)
        assert pulse.peak_m_s2 == pytest.approx(peak_g * G_M_S2, rel=5e-3)
        assert pulse.width_s == pytest.approx(width_10_percent(width_s), rel=1e-2)


def test_velocity_is_zero_at_rest_and_the_flight_velocity_after() -> None:
    t, acc, vel, beat = half_sine_shot(100_000, 38.6e-6, 20.0, 2.0)
    d = doppler.demodulate(beat, DT, DEFAULT_GRATING_PITCH_M)
    rest = d.time_s < START_S - 20e-6
    flight = d.time_s > START_S + 38.6e-6 + 20e-6
    peak_v = vel.max()
    assert np.max(np.abs(d.velocity_m_s[rest])) < 1e-4 * peak_v
    assert np.max(np.abs(d.acceleration_m_s2[rest])) < 1e-3 * acc.max()
    assert np.mean(d.velocity_m_s[flight][10:-60]) == pytest.approx(peak_v, rel=2e-4)
    assert d.beat.onset_time_s == pytest.approx(START_S, abs=3e-6)


def test_robust_to_large_dc_offset_and_faster_fluctuation() -> None:
    t, acc, vel, beat = half_sine_shot(100_000, 38.6e-6, 30.0, 1.0, dc_offset_v=-1.2, fluctuation=0.2,
                                       fluctuation_hz=3000.0)
    d = doppler.demodulate(beat, DT, DEFAULT_GRATING_PITCH_M)
    assert np.max(np.abs(d.velocity_m_s - np.interp(d.time_s, t, vel))[60:-60]) < 1e-3 * vel.max()
    assert d.beat.offset_v == pytest.approx(-1.2, abs=5e-3)


def test_other_orders_and_pitch_scale_the_velocity() -> None:
    t = np.arange(200_000) * DT
    vel = velocity_m_s(half_sine_m_s2(t, 50e-6, 20_000 * G_M_S2, START_S), DT)
    beat = pm_beat(vel, DT, 4e-6, (2, -1), snr_db=30.0, initial_phase_rad=1.0, rng=np.random.default_rng(5))
    d = doppler.demodulate(beat, DT, 4e-6, (2, -1))
    assert np.max(np.abs(d.velocity_m_s - np.interp(d.time_s, t, vel))[60:-60]) < 1e-3 * vel.max()


def test_bandwidth_is_chosen_from_the_pulse_and_can_be_given() -> None:
    for width_s in (38.6e-6, 100e-6):
        t, acc, vel, beat = half_sine_shot(20_000, width_s, 30.0, 1.0)
        d = doppler.demodulate(beat, DT, DEFAULT_GRATING_PITCH_M)
        # Half-sine: 10–90 % velocity rise time 0.59·δ, so B = 5/(0.59·δ) ≈ 8.5/δ.
        rise = width_s * (np.arccos(-0.8) - np.arccos(0.8)) / np.pi
        assert d.bandwidth_hz == pytest.approx(differentiating_lowpass.BANDWIDTH_RISE_PRODUCT / rise, rel=0.03)
    given = doppler.demodulate(beat, DT, DEFAULT_GRATING_PITCH_M, bandwidth_hz=50e3)
    assert given.bandwidth_hz == 50e3
    capped = differentiating_lowpass.bandwidth_for_rise_time(1e-7, 1e6)
    assert capped == pytest.approx(differentiating_lowpass.MAX_BANDWIDTH_FRACTION * 1e6)


def test_differentiating_lowpass_is_the_derivative_of_the_lowpass() -> None:
    # On a band-limited signal D = j2πf·L: the derivative taps applied to sin equal 2πf·cos
    # scaled by L's gain, which is 1 in the pass band and falls in the stop band.
    rate, bandwidth = 1e6, 200e3
    t = np.arange(4000) / rate
    d_taps = differentiating_lowpass.derivative_taps(bandwidth, rate)
    for f in (5e3, 50e3, 120e3):
        x = np.sin(2 * np.pi * f * t)
        dx = differentiating_lowpass.apply_zero_phase(x, d_taps)
        expected = 2 * np.pi * f * np.cos(2 * np.pi * f * t)
        assert np.max(np.abs(dx - expected)[300:-300]) < 2e-4 * 2 * np.pi * f
    x = np.sin(2 * np.pi * 330e3 * t)  # well into the stop band (L: −6 dB at B, stop from 1.25·B)
    assert np.max(np.abs(differentiating_lowpass.apply_zero_phase(x, d_taps))[300:-300]) < 1e-3 * 2 * np.pi * 330e3
    ramp = 3.0 * t
    assert np.allclose(differentiating_lowpass.apply_zero_phase(ramp, d_taps), 3.0, rtol=1e-9)  # ends included


# --------------------------------------------------------------------------- bad input
def test_no_beat_is_a_clear_error() -> None:
    noise = np.random.default_rng(0).standard_normal(200_000) * 0.01
    with pytest.raises(AnalysisError, match="no Doppler beat"):
        beat_phase(noise + 0.2, DT)


def test_clipped_signal_is_a_clear_error() -> None:
    """Clipped = samples at the digitizer's full scale (given), never the record's own extremes."""
    t, acc, vel, beat = half_sine_shot(100_000, 38.6e-6, 30.0, 1.0)
    with pytest.raises(AnalysisError, match=r"clipped: \d+ samples at the digitizer's full scale \(-0.5 .. 0.4 V\)"):
        beat_phase(np.clip(beat, -0.5, 0.4), DT, full_scale_v=(-0.5, 0.4))
    # The same beat inside a wider full scale is demodulated.
    assert beat_phase(beat, DT, full_scale_v=(-2.0, 2.0)).phase_rad.size > 0


def test_wrong_sample_rate_is_a_clear_error() -> None:
    t, acc, vel, beat = half_sine_shot(100_000, 38.6e-6, 30.0, 1.0)
    with pytest.raises(AnalysisError, match="sampled at 1 MS/s"):
        beat_phase(beat[::100], 1e-6)
    # A beat above 45 % of the rate is (about to be) aliased: 23.5 m/s at 2 µm pitch beats at
    # 23.5 MHz, 47 % of 50 MS/s.
    fast = pm_beat(np.concatenate([np.zeros(20_000), np.linspace(0, 23.5, 2_000), np.full(78_000, 23.5)]), 2e-8,
                   snr_db=30.0, rng=np.random.default_rng(1))
    with pytest.raises(AnalysisError, match="aliased"):
        beat_phase(fast, 2e-8)


def test_too_short_and_no_rest_are_clear_errors() -> None:
    t, acc, vel, beat = half_sine_shot(100_000, 38.6e-6, 30.0, 1.0)
    with pytest.raises(AnalysisError, match="only 1000 samples"):
        beat_phase(beat[:1000], DT)
    moving = pm_beat(np.full(200_000, 10.0), DT, snr_db=30.0, rng=np.random.default_rng(2))
    with pytest.raises(AnalysisError, match="no rest before the pulse"):
        beat_phase(moving, DT)


def test_bad_grating_or_orders_are_clear_errors() -> None:
    with pytest.raises(AnalysisError, match="orders"):
        doppler.metres_per_radian(2e-6, (1, 1))
    with pytest.raises(AnalysisError, match="pitch"):
        doppler.metres_per_radian(0.0, (1, -1))


def test_benchmark_script_smoke() -> None:
    # benchmarks/bench_doppler.py on a small record: runs, ends with one JSON line, and our
    # demodulation is at least as accurate as the hilbert+gradient baseline (no timing asserted).
    import json
    import subprocess
    import sys
    from pathlib import Path

    script = Path(__file__).resolve().parents[2] / "benchmarks" / "bench_doppler.py"
    done = subprocess.run([sys.executable, str(script), "--samples", "200000", "--repeats", "1"],
                          capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    result = json.loads(done.stdout.strip().splitlines()[-1])
    assert result["samples"] == 200_000
    assert result["velocity_max_error_rel"] < 1e-3
    assert result["velocity_max_error_rel"] <= result["baseline_velocity_max_error_rel"]
