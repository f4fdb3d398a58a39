"""The simulated rig fires through the bar model (`[world.realism] pulse_source = "bar"`): the
Doppler beat the simulator writes, reduced by the analysis, gives back the bar model's pulse
for that projectile, pressure and mount (peak, the velocity the object reaches and the one it
keeps), and the shot's truth says where its pulse came from."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from hopkinson.analysis.bar import PAPER_RIG, predict_shot
from hopkinson.analysis.reduce import SensorChannel, reduce_sensors
from hopkinson.drivers.sim.world import CaptureSettings, simulate_shot
from hopkinson.rig.config import load_sim_config
from tests.rig.conftest import REPO


@pytest.mark.parametrize("mount", ["separating", "bonded"])
def test_a_shot_through_the_bar_model_carries_its_pulse(mount: str) -> None:
    world = load_sim_config(REPO / "config" / "sim.toml").world
    quiet = dataclasses.replace(world.realism, pulse_source="bar", bar_mount=mount, speed_scatter_rel=0.0,
                                bar_ringing=dataclasses.replace(world.realism.bar_ringing, enabled=False),
                                mount=dataclasses.replace(world.realism.mount, enabled=False),
                                transverse=dataclasses.replace(world.realism.transverse, enabled=False),
                                reference=dataclasses.replace(world.realism.reference, noise=False, lowpass=False,
                                                              delay=False, onset_errors=False))
    params = dataclasses.replace(world, realism=quiet)
    channels, truth = simulate_shot(params, 2.5, 3, CaptureSettings(100e6, 100_000, 10_000))
    assert truth["pulse_source"] == "bar" and truth["pulse"]["shape"] == "bar_model"
    assert truth["realism"]["bar_mount"] == mount
    predicted = predict_shot(dataclasses.replace(PAPER_RIG, mount=mount), 3, pressure_bar=2.5)
    assert truth["projectile_speed_m_s"] == pytest.approx(predicted.speed_m_s)
    reduced = reduce_sensors(channels[1], {"response": SensorChannel(
        channels[2], truth["amplifier_gain"], truth["sensitivity_v_per_m_s2"])}, 1e-8, sample_rate_hz=10e6)
    record = reduced["response"].record
    reference = np.asarray(record.reference)
    # the interferometer's acceleration (phase → velocity → derivative, smoothed by the reduction)
    assert np.max(reference) == pytest.approx(predicted.peak_m_s2, rel=0.03)
    velocity = np.cumsum(reference) * record.sample_interval_s
    assert np.max(velocity) == pytest.approx(predicted.peak_velocity_m_s, rel=0.02)
    if mount == "separating":  # it flies off with what it gained
        assert velocity[-1] == pytest.approx(predicted.delta_v_m_s, rel=0.02)
    else:  # it stays on the bar's end, which comes back to rest once the wave has reflected
        assert abs(velocity[-1]) < 0.02 * predicted.peak_velocity_m_s
        assert np.min(reference) < -0.5 * np.max(reference)  # the bipolar pulse


def test_a_bar_pulse_starts_where_the_object_starts_to_move() -> None:
    """The effects timed from the pulse's start (onset errors, the lateral kick, the flight noise)
    come with the pulse, not with the model's lead before it: t = 0 is where the acceleration
    first reaches 1 % of its peak, the duration ends at its last 10 %, and the sensor's mode is
    not kicked before the reference moves."""
    from hopkinson.drivers.sim.bar_source import BarPulseSource

    pulse = BarPulseSource.mounted("bonded").pulse(3, 2.0)
    t = np.arange(-100e-6, 400e-6, 1e-8)
    a = pulse.acceleration_m_s2(t)
    first = t[np.flatnonzero(np.abs(a) > 0.01 * abs(pulse.peak_m_s2))[0]]
    last = t[np.flatnonzero(np.abs(a) > 0.1 * abs(pulse.peak_m_s2))[-1]]
    assert abs(first) <= 1e-7 and last == pytest.approx(pulse.width_s, abs=1e-7)
    world = load_sim_config(REPO / "config" / "sim.toml").world
    kicked = dataclasses.replace(world, realism=dataclasses.replace(world.realism, pulse_source="bar",
                                                                   bar_mount="bonded"))
    channels, truth = simulate_shot(kicked, 2.0, 3, CaptureSettings(100e6, 40_000, 4_000))
    reduced = reduce_sensors(channels[1], {"response": SensorChannel(
        channels[2], truth["amplifier_gain"], truth["sensitivity_v_per_m_s2"])}, 1e-8, sample_rate_hz=10e6)
    record = reduced["response"].record
    reference, response = np.asarray(record.reference), np.asarray(record.response)
    moving = int(np.flatnonzero(np.abs(reference) > 0.05 * np.max(reference))[0])
    assert np.max(np.abs(response[: moving - 20])) < 0.02 * np.max(response)
