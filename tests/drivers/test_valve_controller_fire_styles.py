"""The valve/vacuum controller driver's fire styles (drivers/fire_styles.py,
docs/plc-fire-styles.md) against the simulated controller fired in each style, over Modbus TCP
and RTU: what each style writes, that a driver in the wrong style fires nothing, how a pulse's
end is watched, and SAFE's withdrawal of a fire command left on."""

from __future__ import annotations

import threading
import time
from dataclasses import replace

import pytest

from hopkinson.drivers.base import TraceRecord
from hopkinson.drivers.errors import InstrumentError
from hopkinson.drivers.sim.controller_map import Point, default_map
from hopkinson.drivers.sim.simulated_rig import SimConfig, SimulatedRig
from hopkinson.drivers.valve_controller import (
    CoilMap,
    HoldingRegisterMap,
    RegisterMap,
)
from tests.drivers.conftest import FakeClock, charge, controller, sim_config


# -- fire styles (drivers/fire_styles.py, docs/plc-fire-styles.md) -------------------------------------
def styled_sim(style: str, transport: str = "tcp", preset_ms: float = 150.0, **coils_and_words: int) -> SimConfig:
    """A simulated controller that fires in `style`; `fire_command=...` maps a fire coil (coils)
    and `fire_command_word=...` a command word (holding registers)."""
    base = sim_config(modbus_transport=transport)
    layout = default_map()
    if "fire_command" in coils_and_words:
        layout["coils"]["fire_command"] = Point(coils_and_words["fire_command"])
    if "fire_command_word" in coils_and_words:
        layout["holding_registers"]["fire_command"] = Point(coils_and_words["fire_command_word"])
    servers = replace(base.servers, modbus_fire_style=style, modbus_fire_preset_ms=preset_ms,
                      modbus_fire_command_value=0x5AF1)
    return replace(base, servers=servers, register_map=layout)


def driver_map(fire_command: int = -1, fire_command_word: int = -1) -> RegisterMap:
    """The driver's side of `styled_sim`'s layout."""
    return RegisterMap(coils=CoilMap(fire_command=fire_command),
                       holding_registers=HoldingRegisterMap(fire_command=fire_command_word))


def assert_pulse_of(rig: SimulatedRig, clock: FakeClock, length_s: float) -> None:
    """One pulse, counted, open until `length_s` of the controller's time and shut after."""
    assert rig.world.fire_pulses == 1 and rig.world.shots_fired == 1
    assert rig.world.valve_positions()["fire"] is True
    clock.advance(length_s - 0.005)
    assert rig.world.valve_positions()["fire"] is True
    clock.advance(0.01)
    assert rig.world.valve_positions()["fire"] is False


@pytest.mark.parametrize("transport", ["tcp", "rtu"])
def test_preset_and_coil_writes_the_preset_then_switches_the_fire_coil(transport: str, clock: FakeClock) -> None:
    config = styled_sim("preset_and_coil", transport, fire_command=6)
    with SimulatedRig(config, clock=clock) as rig, \
            controller(rig, register_map=driver_map(fire_command=6), fire_style="preset_and_coil") as vc:
        charge(vc, clock, 2.0)
        vc.write_value(vc.map.holding_registers.fire_pulse_ms, 250.0, "preset alone")
        assert rig.world.fire_pulses == 0  # in this style a preset fires nothing
        assert vc.fire_pulse(0.2) is True  # read back open (position input)
        assert rig.modbus.last_written["fire_pulse_ms"] == 200.0
        assert rig.modbus.last_written["fire_command"] == 0.0  # the fire coil is off again after the pulse
        assert_pulse_of(rig, clock, 0.2)
        assert vc.fire_pulse_count() == 1


@pytest.mark.parametrize("transport", ["tcp", "rtu"])
def test_preset_and_command_word_fires_on_the_command_value(transport: str, clock: FakeClock) -> None:
    config = styled_sim("preset_and_command", transport, fire_command_word=7)
    with SimulatedRig(config, clock=clock) as rig, \
            controller(rig, register_map=driver_map(fire_command_word=7), fire_style="preset_and_command",
                       fire_command_value=0x5AF1) as vc:
        charge(vc, clock, 2.0)
        assert vc.fire_pulse(0.3) is True
        assert rig.modbus.last_written["fire_command"] == 0.0  # back to "no command"
        assert_pulse_of(rig, clock, 0.3)


@pytest.mark.parametrize("transport", ["tcp", "rtu"])
def test_plc_preset_coil_fires_for_the_plcs_own_preset_and_never_writes_it(transport: str, clock: FakeClock) -> None:
    config = styled_sim("plc_preset_coil", transport, preset_ms=120.0)  # the fire valve's coil is the fire coil
    with SimulatedRig(config, clock=clock) as rig, \
            controller(rig, fire_style="plc_preset_coil") as vc:
        charge(vc, clock, 2.0)
        writes_before = dict(rig.modbus.last_written)
        assert vc.fire_pulse(0.5) is True  # 0.5 s asked; the PLC's preset rules
        assert rig.modbus.last_written["fire_pulse_ms"] == writes_before["fire_pulse_ms"] == 120.0
        assert rig.modbus.last_written["fire_valve"] == 0.0  # the coil is off again
        assert_pulse_of(rig, clock, 0.12)


def test_host_timed_coil_needs_the_labs_word_and_a_heartbeat(clock: FakeClock) -> None:
    config = styled_sim("host_timed_coil")
    with SimulatedRig(config, clock=clock) as rig:
        charge_with = controller(rig, fire_style="host_timed_coil")
        with charge_with as refused:
            charge(refused, clock, 2.0)
            with pytest.raises(InstrumentError, match="the lab has not allowed it"):
                refused.fire_pulse(0.2)
        with controller(rig, fire_style="host_timed_coil", host_timed_fire_allowed=True, watchdog_s=2.0) as vc:
            with pytest.raises(InstrumentError, match="no heartbeat runs, so the watchdog cannot back it"):
                vc.fire_pulse(0.2)
            assert rig.world.shots_fired == 0 and rig.world.coils()["fire"] is False
            vc.start_heartbeat()
            started = time.monotonic()
            assert vc.fire_pulse(0.2) is True  # seen open on the position input, then shut by the host
            assert time.monotonic() - started >= 0.2  # the host held it (no upper bound asserted)
            assert rig.world.shots_fired == 1 and rig.world.coils()["fire"] is False
            vc.stop_heartbeat()


def test_a_host_timed_valve_the_host_cannot_close_is_left_to_the_watchdog(clock: FakeClock) -> None:
    """The link drops mid-pulse: the close cannot be written, so the driver stops beating and
    the controller's watchdog (which backs this style) closes the valve."""
    config = styled_sim("host_timed_coil")
    with SimulatedRig(config, clock=clock) as rig, \
            controller(rig, fire_style="host_timed_coil", host_timed_fire_allowed=True, watchdog_s=2.0,
                       timeout_s=0.2) as vc:
        charge(vc, clock, 2.0)
        vc.start_heartbeat()
        threading.Timer(0.05, rig.faults.inject, args=("modbus-disconnect",)).start()
        with pytest.raises(InstrumentError, match="the controller's watchdog closes it within 2 s"):
            vc.fire_pulse(0.2)
        assert not vc.heartbeat_running and rig.world.coils()["fire"] is True  # still open: the link is gone
        clock.advance(2.1)
        assert rig.world.watchdog_state() == "tripped" and rig.world.coils()["fire"] is False


def test_a_driver_in_the_wrong_style_fires_nothing_and_says_the_valve_stayed_shut(clock: FakeClock) -> None:
    """The PLC wants preset-then-coil; the host writes the preset only (today's default style)."""
    config = styled_sim("preset_and_coil", fire_command=6)
    with SimulatedRig(config, clock=clock) as rig, controller(rig, register_map=driver_map(fire_command=6)) as vc:
        charge(vc, clock, 2.0)
        assert vc.fire_style == "pulse_register"
        assert vc.fire_pulse(0.2) is False  # watched through the pulse: the valve never opened
        assert rig.world.fire_pulses == 0 and rig.world.shots_fired == 0 and vc.fire_pulse_count() == 0
        assert "holding register 4 and expects that write to start the pulse" in vc.how_it_fires()


def _fire_a_pulse_over_before_its_first_read_back(clock: FakeClock, also_counted: int = 0) -> tuple[bool | None, int]:
    """A 0.2 s pulse whose controller time runs past its end as soon as the write that starts it
    is answered (as on a simulator faster than the wall clock), `also_counted` further pulses
    counted meanwhile (another program's); returns what `fire_pulse` said and how many times it
    read the fire valve's position."""
    with SimulatedRig(sim_config(), clock=clock) as rig, controller(rig) as vc:
        charge(vc, clock, 2.0)
        position_reads = []

        def trace(record: TraceRecord) -> None:
            if record.direction == "<-" and record.text.startswith("WriteSingleRegisterResponse") \
                    and "address=4," in record.text:
                clock.advance(0.25)
                rig.world.fire_pulses += also_counted
            if record.direction == "->" and record.text.startswith("ReadDiscreteInputsRequest") \
                    and "address=8," in record.text:
                position_reads.append(record)

        vc.trace = trace
        seen_open = vc.fire_pulse(0.2)
        assert rig.world.shots_fired == 1 and vc.fire_pulse_count() == 1 + also_counted
        assert rig.world.valve_positions()["fire"] is False
        return seen_open, len(position_reads)


def test_a_pulse_the_controller_counted_and_shut_ends_the_watch_at_once(clock: FakeClock) -> None:
    """The pulse was over before the first read-back: the counter moved by one, the position
    input and the PLC's fire output read shut, so the watch ends there (not after the pulse's
    time and its margin), and says what it read: never open."""
    seen_open, reads = _fire_a_pulse_over_before_its_first_read_back(clock)
    assert seen_open is False and reads == 1


def test_a_counter_that_jumps_does_not_end_the_watch(clock: FakeClock) -> None:
    """Two pulses counted for one: the counter is not trusted, the valve is watched through
    the pulse's time and its margin."""
    seen_open, reads = _fire_a_pulse_over_before_its_first_read_back(clock, also_counted=1)
    assert seen_open is False and reads > 1


def test_safe_withdraws_a_fire_command_left_on(clock: FakeClock) -> None:
    config = styled_sim("preset_and_command", fire_command_word=7)
    with SimulatedRig(config, clock=clock) as rig, \
            controller(rig, register_map=driver_map(fire_command_word=7), fire_style="preset_and_command",
                       fire_command_value=0x5AF1) as vc:
        vc.write_word(7, 0x5AF1, "a command left on by another program")
        vc.set_fire_valve(False)
        assert rig.modbus.last_written["fire_command"] == 0.0
