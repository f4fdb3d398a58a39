"""A channel mapped to a role that carries nothing (analysis/channel_content.py): a quadrature
role on an interferometer with one photodetector, a sensor role with no sensor. Judged against
simulated shots whose truth is known (drivers/sim: the world makes a quadrature partner, or
not), and named as such at analysis instead of "the reference's pulse is lost in its noise"."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from hopkinson.analysis.channel_content import EMPTY_RISE_DB, beat_content, pulse_content
from hopkinson.analysis.errors import AnalysisError
from hopkinson.analysis.options import AnalysisOptions
from hopkinson.analysis.shot_analysis import analyse_raw_shot
from hopkinson.drivers.sim.world import CaptureSettings, SignalParams, WorldParams, simulate_shot

CAPTURE = CaptureSettings(sample_rate_hz=100e6, record_length=200_000, pre_trigger_samples=20_000)


@pytest.fixture(scope="module", params=["bonded", "separating"])
def shot(request) -> dict[int, np.ndarray]:
    """A realistic simulated shot with a quadrature interferometer (channels 1 and 3) and the
    accelerometer on channel 2; both mounts (bonded: the velocity comes back through zero)."""
    from hopkinson.rig.config import load_sim_config

    world = load_sim_config(Path(__file__).resolve().parents[2] / "config" / "sim.toml").world
    world = dataclasses.replace(world, realism=dataclasses.replace(world.realism, bar_mount=request.param))
    channels, _ = simulate_shot(world, 2.0, settings=CAPTURE)
    return channels


def noise(n: int, rms_v: float, offset_v: float = 0.0, seed: int = 3) -> np.ndarray:
    """A digitizer input with nothing on it: its own noise about an offset."""
    return offset_v + rms_v * np.random.default_rng(seed).standard_normal(n)


def test_a_quadrature_partner_carries_the_beat_and_noise_does_not(shot) -> None:
    real = beat_content(shot[3], shot[1])
    assert real is not None and not real.carries_nothing and real.rise_db > 20  # as high as the doppler's own
    assert abs(real.rise_db - real.reference_rise_db) < 3
    for rms_v in (0.0005, 0.004, 0.05):  # a quiet input, the beat's own noise level, a loud one
        empty = beat_content(noise(shot[1].size, rms_v, 0.12), shot[1])
        assert empty.carries_nothing and empty.rise_db < EMPTY_RISE_DB, (rms_v, empty)
        message = empty.message()
        assert message.startswith("the doppler_quadrature channel carries no beat (holds only noise: its power rises")
        assert "unmap the quadrature channel (digitizer.channels.doppler_quadrature" in message
    flat = beat_content(np.full(shot[1].size, 0.12), shot[1])
    assert flat.carries_nothing and "it is constant" in flat.message()


def test_a_sensor_channel_carries_the_pulse_and_noise_does_not(shot) -> None:
    real = pulse_content(shot[2], shot[1])
    assert not real.carries_nothing and real.rise_db > 40
    empty = pulse_content(noise(shot[1].size, 0.001, 0.002), shot[1], "response_2")
    assert empty.carries_nothing
    assert "the response_2 channel carries no pulse" in empty.message()
    assert "unmap the channel (digitizer.channels.response_2" in empty.message()


def test_nothing_is_judged_without_motion() -> None:
    rest = noise(200_000, 0.004, 0.15)
    assert beat_content(noise(200_000, 0.004, 0.1, seed=4), rest) is None
    assert pulse_content(noise(200_000, 0.001, seed=5), rest) is None


def test_the_analysis_names_an_empty_quadrature_channel_not_a_lost_pulse() -> None:
    """The issue's case: an interferometer with one photodetector (the simulated world makes no
    partner), its quadrature role mapped to an input that holds only noise."""
    world = WorldParams(signals=SignalParams(quadrature=False))
    channels, _ = simulate_shot(world, 2.0, settings=CAPTURE)
    assert 3 not in channels
    params = AnalysisOptions(amp_gain=10.0, sensitivity_v_per_m_s2=2e-7, uncertainty=False, max_order=6)
    with pytest.raises(AnalysisError) as caught:
        analyse_raw_shot(channels[1], channels[2], 1e-8, params, quadrature_v=noise(channels[1].size, 0.004, 0.12))
    text = str(caught.value)
    assert "the doppler_quadrature channel carries no beat" in text and "unmap the quadrature channel" in text
    assert "lost in its noise" not in text
    # Unmapped, the same shot is analysed from its PM beat.
    analysed = analyse_raw_shot(channels[1], channels[2], 1e-8, params)
    assert analysed.record is not None


def test_an_empty_second_sensor_is_named_and_the_first_still_analysed(shot) -> None:
    params = AnalysisOptions(amp_gain=10.0, sensitivity_v_per_m_s2=2e-7, uncertainty=False, max_order=6)
    analysis = analyse_raw_shot(shot[1], shot[2], 1e-8, params, quadrature_v=shot[3],
                                more_sensors={"response_2": (noise(shot[1].size, 0.001), params)})
    assert analysis.record is not None and "response_2" not in analysis.sensors
    assert "the response_2 channel carries no pulse" in analysis.sensor_errors["response_2"]
    assert any(w.startswith("sensor response_2 not analysed: ") for w in analysis.warnings)
    with pytest.raises(AnalysisError, match="the response channel carries no pulse .*is the accelerometer connected"):
        analyse_raw_shot(shot[1], noise(shot[1].size, 0.001), 1e-8, params, quadrature_v=shot[3])
