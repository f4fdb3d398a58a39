"""The simulator's hard parts of real records (issue 10): bipolar pulses, interferometer noise,
channel skew, baseline drift — each against a closed form."""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
import pytest

from hopkinson.drivers.sim.accelerometer import baseline_drift, fractional_delay
from hopkinson.drivers.sim.doppler_beat import interferometer_noise_m_s2
from hopkinson.drivers.sim.faults import FaultSet
from hopkinson.drivers.sim.shock import bipolar_m_s2, bipolar_velocity_m_s, velocity_m_s
from hopkinson.drivers.sim.world import SignalParams, World, WorldParams
from tests.drivers.conftest import FakeClock


def test_bipolar_pulse_velocity_is_its_exact_integral() -> None:
    dt = 1e-8
    t = np.arange(20_000) * dt
    a = bipolar_m_s2(t, 20e-6, 5e5, 10e-6, ratio=0.6, second_width_s=30e-6)
    v = bipolar_velocity_m_s(t, 20e-6, 5e5, 10e-6, ratio=0.6, second_width_s=30e-6)
    assert np.max(np.abs(velocity_m_s(a, dt) - v)) < 1e-6 * np.max(v)
    assert v[-1] == pytest.approx(5e5 * 2 / np.pi * (20e-6 - 0.6 * 30e-6), rel=1e-9)
    assert np.min(a) == pytest.approx(-0.6 * 5e5, rel=1e-3) and np.min(v) >= 0.0


def test_fractional_delay_shifts_a_band_limited_signal_exactly() -> None:
    k = np.arange(600, dtype=float)
    pulse = np.exp(-0.5 * ((k - 300.0) / 12.0) ** 2)
    for delay in (0.37, -0.25, 3.5):
        exact = np.exp(-0.5 * ((k - 300.0 - delay) / 12.0) ** 2)
        assert np.max(np.abs(fractional_delay(pulse, delay) - exact)) < 1e-9


def test_interferometer_noise_rises_as_f_squared_up_to_its_bandwidth() -> None:
    n, dt = 2**16, 1e-6
    x = interferometer_noise_m_s2(n, dt, 3.0, 200e3, np.random.default_rng(1))
    assert np.std(x) == pytest.approx(3.0, rel=1e-9)
    power = np.abs(np.fft.rfft(x)) ** 2
    f = np.fft.rfftfreq(n, dt)
    band = (f > 10e3) & (f < 180e3)
    slope = np.polyfit(np.log(f[band]), np.log(power[band]), 1)[0]
    assert slope == pytest.approx(4.0, abs=0.15)  # amplitude ∝ f², power ∝ f⁴
    assert np.max(power[f > 210e3]) < 1e-20 * np.max(power)


def test_baseline_drift_is_its_slope_plus_a_bounded_wander() -> None:
    t = np.arange(10_000) * 1e-6
    assert np.allclose(baseline_drift(10_000, 1e-6, 2.0), 2.0 * t)
    d = baseline_drift(10_000, 1e-6, 2.0, wander_rms=1e-3, rng=np.random.default_rng(0))
    wander = d - 2.0 * t
    assert np.std(wander) == pytest.approx(1e-3, rel=1e-9)
    assert np.std(np.diff(wander)) < 0.05 * np.std(wander)  # slow: low-passed at 200 Hz


@dataclass
class Settings:
    sample_rate_hz: float = 100e6
    record_length: int = 60_000
    pre_trigger_samples: int = 10_000


def _fired(signals: SignalParams) -> tuple[dict[int, np.ndarray], dict]:
    clock = FakeClock()
    params = replace(WorldParams(), signals=signals)
    world = World(params, FaultSet(), clock=clock)
    world.set_pressure_setpoint_bar(4.0)
    world.set_fill_valve(True)
    clock.advance(100.0)
    world.set_fill_valve(False)
    world.set_fire_valve(True)
    channels = world.capture(Settings())
    assert channels is not None
    return channels, world.last_shot_truth


def test_world_shot_carries_skew_drift_and_a_bipolar_pulse_and_records_them() -> None:
    quiet = SignalParams(pm_snr_db=0.0, response_white_snr_db=0.0, response_coloured_snr_db=0.0)
    plain, _ = _fired(quiet)
    skew_s, drift = 3.3e-8, 0.5
    hard, truth = _fired(replace(quiet, channel_skew_s=skew_s, response_drift_v_per_s=drift, pulse_bipolar_ratio=0.5))
    assert truth["channel_skew_s"] == skew_s and truth["response_drift_v_per_s"] == drift
    assert truth["pulse"]["shape"] == "bipolar" and truth["pulse"]["bipolar_ratio"] == 0.5
    skewed, _ = _fired(replace(quiet, channel_skew_s=skew_s))
    t = (np.arange(60_000) - 10_000) / 100e6
    # The skewed response is the plain one 3.3 ns later (linear interpolation of a 10 MS/s model).
    expected = np.interp(t - skew_s, t, plain[2])
    assert np.max(np.abs(skewed[2] - expected)) < 1e-3 * np.max(np.abs(plain[2]))
    # The drift adds drift·t; the bipolar pulse's acceleration goes negative in the truth.
    acc = np.array(truth["reference"]["acceleration_m_s2"])
    assert np.min(acc) < -0.4 * truth["peak_acceleration_m_s2"]
    assert np.mean(hard[2][-1000:]) > np.mean(plain[2][-1000:]) + 0.5 * drift * 5e-4
