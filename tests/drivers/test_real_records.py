"""The simulated rig's realistic records (issue 19, item 2; drivers/sim/real_records.py).

Each effect is checked against a closed form or the size config/sim.toml gives it, not against
the module's own output: the reference chain's delay moves a pulse's centroid by exactly that
delay, its Butterworth low-pass passes 1/√2 at its corner, its noise rises as f² and is
flight_noise_factor times stronger in flight, each onset glitch is a displacement step Δφ/k; the
mount scales tension by 1 − asymmetry; the bar's ringing lies in 1–30 kHz and outlasts a
millisecond. End to end (one shot of the shipped config/sim.toml, reduced by the analysis
chain): the reference's spectrum has nulls deeper than −36 dB, the motion after the pulse is
1–2 % of the peak, the sensor's base sees it × base_gain, the transverse path rings the sensor
by ~10 % of the peak while the reference is untouched, and the truth records every switch.
"""

from __future__ import annotations

import dataclasses
import json
import math

import numpy as np
import pytest
from scipy import signal

from hopkinson.analysis.reduce import SensorChannel, reduce_sensors
from hopkinson.drivers.sim.real_records import (
    BarRingingParams,
    IdealPulseSource,
    MountParams,
    ReferenceChainParams,
    mounted_input_m_s2,
    reference_chain_m_s2,
    ringing_m_s2,
)
from hopkinson.drivers.sim.world import CaptureSettings, WorldParams, simulate_shot
from hopkinson.rig.config import load_sim_config
from tests.rig.conftest import REPO

DT = 1e-7  # the internal grid of the simulated world: 10 MS/s
K = 2 * math.pi * 2 / 2e-6  # the beat's wavenumber, orders ±1 on a 2 µm grating
OFF = ReferenceChainParams(noise=False, lowpass=False, delay=False, onset_errors=False)
PULSE = IdealPulseSource(10.0, 0.85, (120e-6, 75e-6, 38.6e-6)).pulse(3, 2.0)


def _grid(duration_s: float = 2e-3, lead_s: float = 0.2e-3) -> np.ndarray:
    return np.arange(int((duration_s + lead_s) / DT)) * DT - lead_s


# -- the reference chain, one effect at a time ------------------------------------------------------
def test_the_delay_moves_the_reference_by_exactly_its_size() -> None:
    t = _grid(0.3e-3)
    x = np.exp(-0.5 * ((t - 50e-6) / 3e-6) ** 2)
    out, _ = reference_chain_m_s2(t, x, 1.0, dataclasses.replace(OFF, delay=True, delay_s=0.5e-6), None, K)
    shift = np.sum(t * out) / np.sum(out) - np.sum(t * x) / np.sum(x)
    assert shift == pytest.approx(0.5e-6, abs=1e-10)


def test_the_low_pass_passes_one_over_root_two_at_its_corner() -> None:
    t = np.arange(200_000) * DT
    x = np.sin(2 * np.pi * 200e3 * t)
    out, _ = reference_chain_m_s2(t, x, 1.0, dataclasses.replace(OFF, lowpass=True), None, K)
    settled = out[100_000:]
    assert np.sqrt(2 * np.mean(settled**2)) == pytest.approx(1 / math.sqrt(2), rel=2e-3)


def test_the_noise_rises_as_f_squared_and_is_six_times_stronger_in_flight() -> None:
    t = _grid(4e-3, 4e-3)
    p = dataclasses.replace(OFF, noise=True, noise_rel=0.004)
    noise, _ = reference_chain_m_s2(t, np.zeros_like(t), 1e6, p, np.random.default_rng(1), K)
    rest, flight = noise[t < -10e-6], noise[t > 10e-6]
    assert np.std(flight) == pytest.approx(0.004 * 1e6, rel=0.05)
    assert np.std(flight) / np.std(rest) == pytest.approx(6.0, rel=0.08)
    f, psd = signal.welch(flight, fs=1 / DT, nperseg=4096)
    band = lambda lo, hi: float(np.sqrt(np.mean(psd[(f > lo) & (f < hi)])))  # noqa: E731
    # amplitude ∝ f²: four times the frequency, sixteen times the amplitude density
    assert band(380e3, 420e3) / band(95e3, 105e3) == pytest.approx(16.0, rel=0.25)


def test_each_onset_glitch_is_a_displacement_step_of_its_phase_over_k() -> None:
    t = _grid(0.2e-3)
    p = dataclasses.replace(OFF, onset_errors=True, onset_glitches=3, onset_glitch_rad=1.0, onset_dip=0.7)
    out, drawn = reference_chain_m_s2(t, np.zeros_like(t), 1e6, p, np.random.default_rng(4), K)
    displacement = np.cumsum(np.cumsum(out) * DT) * DT
    times, signs = drawn["onset_glitch_times_s"], drawn["onset_glitch_signs"]
    assert all(0 <= x <= p.onset_window_s for x in times)
    assert displacement[-1] == pytest.approx(sum(signs) * 1.0 / K, rel=1e-3, abs=1e-3 / K)
    assert np.all(out[t > p.onset_window_s + 3e-6] == pytest.approx(0.0, abs=1e-6))


def test_the_mount_loses_its_asymmetry_in_tension_and_the_sensor_its_non_linearity() -> None:
    a = np.array([4e5, -4e5, 0.0])
    out = mounted_input_m_s2(a, MountParams(asymmetry_rel=0.02), -1e-7)
    assert out == pytest.approx([4e5 * 0.96, -4e5 * 0.96 * 0.98, 0.0])
    assert mounted_input_m_s2(a, MountParams(enabled=False)) == pytest.approx(a)


def test_the_bar_rings_at_1_to_30_khz_for_more_than_a_millisecond_after_the_pulse() -> None:
    t = _grid(3e-3)
    ring, _ = ringing_m_s2(t, PULSE, BarRingingParams(), np.random.default_rng(2))
    assert np.all(ring[t <= PULSE.width_s] == 0.0)
    assert np.max(np.abs(ring)) == pytest.approx(0.015 * PULSE.peak_m_s2, rel=1e-9)
    late = np.abs(ring[(t > 1.0e-3) & (t < 1.2e-3)])
    assert np.max(late) > 0.005 * PULSE.peak_m_s2  # still a third of its size a millisecond on
    spec = np.abs(np.fft.rfft(ring)) ** 2
    f = np.fft.rfftfreq(ring.size, DT)
    assert np.sum(spec[(f >= 1e3) & (f <= 30e3)]) > 0.95 * np.sum(spec)


# -- one shot of the shipped simulator, end to end ---------------------------------------------------
@pytest.fixture(scope="module")
def shots() -> dict[str, tuple[dict, dict]]:
    world = load_sim_config(REPO / "config" / "sim.toml").world
    assert world.realism.enabled and world.realism.transverse.enabled
    no_transverse = dataclasses.replace(world, realism=dataclasses.replace(
        world.realism, transverse=dataclasses.replace(world.realism.transverse, enabled=False)))
    out = {}
    for name, params in (("shipped", world), ("no transverse", no_transverse)):
        channels, truth = simulate_shot(params, 2.0, 3, CaptureSettings(100e6, 220_000, 20_000))
        reduced = reduce_sensors(channels[1], {"response": SensorChannel(
            channels[2], truth["amplifier_gain"], truth["sensitivity_v_per_m_s2"])}, 1e-8, sample_rate_hz=10e6)
        record = reduced["response"].record
        out[name] = (truth, {"t": np.asarray(record.time_s) - 200e-6, "ref": np.asarray(record.reference),
                             "resp": np.asarray(record.response)})
    return out


def test_the_truth_records_every_switch_and_size(shots) -> None:
    truth, _ = shots["shipped"]
    world = load_sim_config(REPO / "config" / "sim.toml").world
    realism = truth["realism"]
    for key in ("bar_ringing", "mount", "transverse", "reference"):
        assert json.loads(json.dumps(realism[key])) == json.loads(json.dumps(dataclasses.asdict(getattr(world.realism,
                                                                                                       key))))
    assert realism["enabled"] and truth["pulse_source"] == world.realism.pulse_source
    assert realism["speed_factor"] != 1.0 and "onset_glitch_times_s" in realism["drawn"]["reference"]
    mounted = truth["accelerometer"]["modes"][0]["natural_frequency_hz"]
    sine = truth["accelerometer_sine_calibrated"]["modes"][0]["natural_frequency_hz"]
    assert mounted == pytest.approx(1.10 * sine) and sine == 27_000.0
    assert "realism" not in simulate_shot(WorldParams(), 1.0, settings=CaptureSettings(100e6, 20_000, 2_000))[1]


def test_the_reference_spectrum_has_deep_nulls(shots) -> None:
    _, rec = shots["shipped"]
    spec = np.abs(np.fft.rfft(rec["ref"]))
    f = np.fft.rfftfreq(rec["ref"].size, 1e-7)
    db = 20 * np.log10(spec / spec.max())
    assert np.min(db[(f > 20e3) & (f < 60e3)]) < -36.0


def test_after_the_pulse_the_bar_moves_by_1_to_2_percent_and_the_base_sees_less(shots) -> None:
    truth, rec = shots["shipped"]
    t, ref, resp = rec["t"], rec["ref"], rec["resp"]
    peak = truth["peak_acceleration_m_s2"]
    after = (t > truth["pulse_width_s"] + 0.1e-3) & (t < t[-1] - 0.05e-3)
    assert after.sum() * 1e-7 > 1.5e-3  # more than a millisecond of it
    # filtered after the pulse only: a filter over the whole record would smear the pulse into it
    band = signal.butter(4, [1e3, 30e3], btype="bandpass", fs=1e7, output="sos")
    ringing = signal.sosfiltfilt(band, ref[after])
    assert 0.01 < np.max(np.abs(ringing)) / peak < 0.02
    assert np.max(np.abs(ringing[-2000:])) / peak > 0.002  # still there at the record's end
    # the sensor (|H| = 1.006 at the lowest ringing frequency) on its base against the spot
    f_low = truth["realism"]["bar_ringing"]["frequencies_hz"][0]
    window = np.hanning(after.sum())
    f = np.fft.rfftfreq(after.sum(), 1e-7)
    i = int(np.argmin(np.abs(f - f_low)))
    gain = abs(np.fft.rfft(resp[after] * window)[i]) / abs(np.fft.rfft(ref[after] * window)[i])
    assert gain == pytest.approx(truth["realism"]["bar_ringing"]["base_gain"] * 1.006, rel=0.03)


def test_the_transverse_path_rings_the_sensor_by_about_ten_percent_the_reference_not_at_all(shots) -> None:
    truth, on = shots["shipped"]
    _, off = shots["no transverse"]
    peak = truth["peak_acceleration_m_s2"]
    assert np.max(np.abs(on["ref"] - off["ref"])) == 0.0
    extra = (on["resp"] - off["resp"])[(on["t"] > 10e-6) & (on["t"] < 0.3e-3)]
    assert 0.05 < np.max(np.abs(extra)) / peak < 0.2
