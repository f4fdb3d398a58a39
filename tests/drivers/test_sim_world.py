"""The simulated world's physics against closed forms, and the servers' life cycle."""

from __future__ import annotations

import json
import math
import socket
import threading
from dataclasses import dataclass, replace

import numpy as np
import pytest

from hopkinson.drivers.digitizer import Digitizer
from hopkinson.drivers.sim.accelerometer import Mode
from hopkinson.drivers.sim.faults import FaultSet
from hopkinson.drivers.sim.shot_truth import accelerometer_truth
from hopkinson.drivers.sim.simulated_rig import SimulatedRig
from hopkinson.drivers.sim.world import AmplifierParams, LauncherParams, World, WorldParams
from hopkinson.drivers.valve_controller import ValveController
from tests.drivers.conftest import FakeClock, sim_config


@dataclass
class Settings:
    """What the simulated digitizer passes to capture()."""

    sample_rate_hz: float = 100e6
    record_length: int = 100_000
    pre_trigger_samples: int = 10_000


def charged_world(clock: FakeClock, pressure_bar: float = 4.0, params: WorldParams | None = None,
                  faults: FaultSet | None = None) -> World:
    world = World(params or WorldParams(), faults or FaultSet(), clock=clock)
    world.set_pressure_setpoint_bar(pressure_bar)
    world.set_fill_valve(True)
    clock.advance(100.0)
    world.set_fill_valve(False)
    return world


# -- time and pneumatics ------------------------------------------------------------------------
def test_time_scale_multiplies_the_wall_clock(clock: FakeClock) -> None:
    world = World(WorldParams(time_scale=20.0), clock=clock)
    clock.advance(0.5)
    assert world.sim_time_s() == pytest.approx(10.0)
    world.set_pressure_setpoint_bar(9.0)
    world.set_fill_valve(True)
    clock.advance(0.25)  # 5 simulated seconds at 0.5 bar/s
    assert world.reservoir_pressure_bar() == pytest.approx(2.5)


def test_state_does_not_depend_on_how_often_it_is_polled(clock: FakeClock) -> None:
    other = FakeClock()
    polled, idle = World(clock=clock), World(clock=other)
    for world in (polled, idle):
        world.set_pressure_setpoint_bar(3.0)
        world.set_fill_valve(True)
        world.set_vent_valve(True)  # fill against the vent: an exponential approach
        world.set_pump(True)
    for _ in range(400):
        clock.advance(0.05)
        polled.reservoir_pressure_bar()
        polled.fixture_vacuum_mbar()
    other.advance(20.0)
    assert polled.reservoir_pressure_bar() == pytest.approx(idle.reservoir_pressure_bar(), rel=1e-9)
    assert polled.fixture_vacuum_mbar() == pytest.approx(idle.fixture_vacuum_mbar(), rel=1e-9)
    # fill rate r against vent time constant tau settles at r*tau (below the set-point here)
    p = polled.params.pneumatics
    expected = p.fill_rate_bar_s * p.vent_time_constant_s * (1 - math.exp(-20.0 / p.vent_time_constant_s))
    assert polled.reservoir_pressure_bar() == pytest.approx(expected, rel=1e-6)


def test_fill_never_exceeds_the_supply(clock: FakeClock) -> None:
    world = World(WorldParams(), clock=clock)
    world.set_pressure_setpoint_bar(50.0)
    world.set_fill_valve(True)
    clock.advance(1000.0)
    assert world.reservoir_pressure_bar() == pytest.approx(world.params.pneumatics.supply_pressure_bar)


def test_stuck_fill_valve_keeps_filling_past_the_setpoint_and_after_close(clock: FakeClock) -> None:
    faults = FaultSet(["stuck-fill-valve"])
    world = World(WorldParams(), faults, clock=clock)
    world.set_pressure_setpoint_bar(2.0)
    world.set_fill_valve(True)
    clock.advance(2.0)
    world.set_fill_valve(False)
    clock.advance(6.0)  # 8 s of filling in all
    assert world.reservoir_pressure_bar() == pytest.approx(8 * 0.5)
    clock.advance(100.0)
    assert world.reservoir_pressure_bar() == pytest.approx(world.params.pneumatics.supply_pressure_bar)


# -- the shot -------------------------------------------------------------------------------------
def test_shot_quantities_follow_pressure_and_projectile(clock: FakeClock) -> None:
    params = WorldParams(launcher=LauncherParams(projectile=2))
    world = charged_world(clock, 6.25, params)
    world.set_fire_valve(True)
    t = world.last_shot_truth
    speed = 10.0 * math.sqrt(6.25)
    assert t["projectile_speed_m_s"] == pytest.approx(speed)
    assert t["delta_velocity_m_s"] == pytest.approx(0.85 * speed)
    assert t["pulse_width_s"] == pytest.approx(75e-6)
    assert t["peak_acceleration_m_s2"] == pytest.approx(math.pi * 0.85 * speed / (2 * 75e-6))
    assert t["peak_g"] == pytest.approx(t["peak_acceleration_m_s2"] / 9.80665)
    json.dumps(t)  # JSON-ready


def test_highest_pressure_reaches_about_100_000_g_with_projectile_3(clock: FakeClock) -> None:
    world = charged_world(clock, 8.0)
    world.set_fire_valve(True)
    assert 90_000 < world.last_shot_truth["peak_g"] < 110_000


def test_launch_listeners_hear_each_launch_once_and_nothing_else(clock: FakeClock) -> None:
    world = charged_world(clock, 4.0)
    heard: list[dict] = []
    free: list[bool] = []

    def listener(truth: dict) -> None:
        heard.append(truth)
        other = threading.Thread(target=world.reservoir_pressure_bar)  # needs the world's lock
        other.start()
        other.join(5.0)
        free.append(not other.is_alive())

    world.launch_listeners.append(listener)
    world.set_inputs(door_closed=False)
    world.set_fire_valve(True)  # refused by the interlock: no launch
    world.set_inputs(door_closed=True)
    world.set_fire_valve(True)
    world.set_fire_valve(True)  # no new edge
    clock.advance(10.0)  # the open valve empties the reservoir
    world.set_fire_valve(False)
    world.set_fire_valve(True)  # an edge with nothing to fire
    assert world.shots_fired == 1 and len(heard) == 1
    assert heard[0]["shot_number"] == 1
    assert heard[0]["pressure_bar"] == pytest.approx(4.0, abs=1e-9)
    assert free == [True]  # called after the world's lock was released
    world.set_fire_valve(False)
    world.capture(Settings(record_length=1_000, pre_trigger_samples=100))
    assert "capture" in world.last_shot_truth and "capture" not in heard[0]  # the listener got a copy


def test_capture_waits_for_a_shot_fired_while_armed(clock: FakeClock) -> None:
    world = charged_world(clock)
    armed = False
    world.digitizer_armed = lambda: armed
    assert world.capture(Settings()) is None
    world.set_fire_valve(True)  # fired while not armed: the digitizer saw nothing
    assert world.shots_fired == 1
    assert world.capture(Settings()) is None
    world.set_fire_valve(False)
    world.set_pressure_setpoint_bar(4.0)
    world.set_fill_valve(True)
    clock.advance(100.0)
    armed = True
    world.set_fire_valve(True)
    channels = world.capture(Settings())
    assert channels is not None and set(channels) == {1, 2}
    assert all(v.shape == (100_000,) for v in channels.values())
    assert world.capture(Settings()) is None  # a shot is delivered once


def test_doppler_channel_beats_at_2v_over_d_after_the_pulse(clock: FakeClock) -> None:
    world = charged_world(clock, 4.0)
    world.set_fire_valve(True)
    s = Settings(record_length=100_000, pre_trigger_samples=10_000)
    doppler = world.capture(s)[1]
    t = world.last_shot_truth
    expected_hz = 2 * t["delta_velocity_m_s"] / t["grating_pitch_m"]  # orders +1, -1
    tail = doppler[-65_536:] - doppler[-65_536:].mean()  # the object flies at constant speed
    spectrum = np.abs(np.fft.rfft(tail * np.hanning(tail.size)))
    peak_hz = np.argmax(spectrum) * s.sample_rate_hz / tail.size
    assert peak_hz == pytest.approx(expected_hz, abs=2 * s.sample_rate_hz / tail.size)
    before = doppler[: s.pre_trigger_samples - 100]  # at rest: no beat, DC + noise only
    assert abs(np.mean(before) - world.params.signals.pm_dc_offset_v) < world.params.signals.pm_amplitude_v * 1.2


def test_response_channel_area_is_gain_times_sensitivity_times_delta_v(clock: FakeClock) -> None:
    # The accelerometer and filter have unit DC gain: the time integral of the response equals
    # gain * sensitivity * integral of the acceleration = gain * sensitivity * delta-v.
    params = WorldParams(amplifier=AmplifierParams(gain=5.0))
    world = charged_world(clock, 4.0, params)
    world.amp_auto_zero()
    world.set_fire_valve(True)
    s = Settings(record_length=200_000, pre_trigger_samples=20_000)  # 2 ms: the ringing dies out
    response = world.capture(s)[2]
    t = world.last_shot_truth
    area = np.sum(response) / s.sample_rate_hz
    expected = t["amplifier_gain"] * t["sensitivity_v_per_m_s2"] * t["delta_velocity_m_s"]
    assert area == pytest.approx(expected, rel=0.01)
    assert np.max(np.abs(response[: s.pre_trigger_samples])) < 0.01 * np.max(response)  # quiet before


def test_response_rings_at_the_true_resonance(clock: FakeClock) -> None:
    mode = Mode(40_000.0, 0.02)
    base = WorldParams()
    params = replace(base, accelerometer=replace(base.accelerometer, modes=(mode,)),
                     signals=replace(base.signals, response_white_snr_db=0.0, response_coloured_snr_db=0.0))
    world = charged_world(clock, 4.0, params)
    world.set_amp_lowpass_hz(0.0)
    world.amp_auto_zero()
    world.set_fire_valve(True)
    s = Settings(sample_rate_hz=10e6, record_length=10_000, pre_trigger_samples=0)
    response = world.capture(s)[2]
    ringing = response[1000:6000]  # 100-600 us: after the 38.6 us pulse, free ringing about zero
    crossings = np.flatnonzero(np.diff(np.signbit(ringing)))
    frequency_hz = (crossings.size - 1) / 2 / ((crossings[-1] - crossings[0]) / s.sample_rate_hz)
    damped_hz = mode.natural_frequency_hz * math.sqrt(1 - mode.damping_ratio**2)
    assert frequency_hz == pytest.approx(damped_hz, rel=0.01)
    truth = accelerometer_truth(world.last_shot_truth)
    assert truth.modes == (mode,) and truth.lowpass_hz == 0.0


def test_reference_truth_is_the_integral_of_the_half_sine(clock: FakeClock) -> None:
    world = charged_world(clock, 4.0)
    world.set_fire_valve(True)
    world.capture(Settings())
    ref = world.last_shot_truth["reference"]
    t = np.asarray(ref["time_s"])
    v = np.asarray(ref["velocity_m_s"])
    a = np.asarray(ref["acceleration_m_s2"])
    assert t.size == 1000  # 1 ms at 1 MS/s
    trapezoid = np.concatenate([[0.0], np.cumsum(0.5 * (a[1:] + a[:-1]) * np.diff(t))])
    assert np.max(np.abs(v - trapezoid)) < 0.01 * v[-1]
    assert v[-1] == pytest.approx(world.last_shot_truth["delta_velocity_m_s"])


def test_same_seed_same_waveforms(clock: FakeClock) -> None:
    out = []
    for _ in range(2):
        world = charged_world(FakeClock(), 3.0)
        world.set_fire_valve(True)
        out.append(world.capture(Settings(record_length=20_000, pre_trigger_samples=2_000)))
    assert np.array_equal(out[0][1], out[1][1]) and np.array_equal(out[0][2], out[1][2])


def test_a_shot_too_big_for_the_gain_clips_and_latches_overload(clock: FakeClock) -> None:
    world = charged_world(clock, 8.0)
    world.set_amp_gain(1000)
    world.set_fire_valve(True)
    response = world.capture(Settings())[2]
    limit = world.params.amplifier.output_limit_v
    assert np.max(response) == pytest.approx(limit)
    assert world.amp_overloaded()
    world.amp_auto_zero()
    assert not world.amp_overloaded()


# -- servers: free ports, whole rig, clean stop ------------------------------------------------------
def _refused(host: str, port: int) -> bool:
    with socket.socket() as s:
        s.settimeout(1.0)
        return s.connect_ex((host, port)) != 0


def test_two_rigs_run_side_by_side_on_free_ports_and_stop_cleanly() -> None:
    before = {t.name for t in threading.enumerate()}
    first, second = SimulatedRig(sim_config()), SimulatedRig(sim_config())
    with first, second:
        a, b = first.addresses, second.addresses
        ports = {a.modbus_port, b.modbus_port, int(a.visa_resource.split("::")[2]), int(b.visa_resource.split("::")[2])}
        assert len(ports) == 4 and 0 not in ports
        assert a.serial_port != b.serial_port
        with ValveController.tcp(a.modbus_host, a.modbus_port) as vc, Digitizer(b.visa_resource, timeout_s=2.0) as dig:
            assert vc.identity().startswith("Hopkinson-Sim")
            assert dig.identity().startswith("Hopkinson-Sim")
    for addr in (a, b):
        assert _refused(addr.modbus_host, addr.modbus_port)
        assert _refused(addr.modbus_host, int(addr.visa_resource.split("::")[2]))
    assert {t.name for t in threading.enumerate()} - before == set()


def test_fire_over_modbus_is_captured_by_the_digitizer(rig: SimulatedRig, clock: FakeClock) -> None:
    a = rig.addresses
    with ValveController.tcp(a.modbus_host, a.modbus_port, timeout_s=2.0) as vc, \
            Digitizer(a.visa_resource, timeout_s=5.0) as dig:
        dig.configure(sample_rate_hz=100e6, record_length=100_000, pre_trigger_fraction=0.1,
                      ch1_range_v=1.0, ch2_range_v=10.0)
        vc.set_pressure_setpoint_bar(5.0)
        vc.set_fill_valve(True)
        clock.advance(30.0)
        vc.set_fill_valve(False)
        vc.set_fire_valve(True)  # not armed yet: this shot is lost
        assert rig.world.shots_fired == 1 and dig.acquisition_state() == "IDLE"
        vc.set_fire_valve(False)
        vc.set_fill_valve(True)
        clock.advance(30.0)
        vc.set_fill_valve(False)
        dig.arm_single()
        assert dig.acquisition_state() == "ARMED"
        vc.set_fire_valve(True)
        assert dig.wait_for_trigger(2.0)
        beat, response = dig.fetch_waveform(1), dig.fetch_waveform(2)
    truth = rig.world.last_shot_truth
    assert truth["shot_number"] == 2 and truth["capture"]["record_length"] == 100_000
    assert beat.volts().size == response.volts().size == 100_000
    # the digitizer triggered where the response crossed its level (0.1 V, rising), shortly
    # after the pulse began
    assert beat.trigger_index == response.trigger_index == 10_000
    assert response.volts()[9_999] < 0.1 <= response.volts()[10_000]
    assert 0 < 10_000 - truth["capture"]["pulse_start_index"] < 0.5 * truth["pulse_width_s"] * 100e6
    peak_v = truth["amplifier_gain"] * truth["sensitivity_v_per_m_s2"] * truth["peak_acceleration_m_s2"]
    assert 0.9 * peak_v < np.max(response.volts()) < 2.0 * peak_v  # resonance overshoot stays below 2x
