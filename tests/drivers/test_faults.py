"""Every named simulator fault gives a clear driver error (or its documented behaviour) over the
real protocol, and the instrument works again once the fault is cleared."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import pytest

from hopkinson.drivers.amplifier import BridgeAmplifier
from hopkinson.drivers.digitizer import Digitizer
from hopkinson.drivers.errors import InstrumentConnectionError, InstrumentError, InstrumentTimeout
from hopkinson.drivers.sim.faults import FAULTS
from hopkinson.drivers.sim.simulated_rig import SimulatedRig
from hopkinson.drivers.valve_controller import ValveController
from tests.drivers.conftest import FakeClock, charge, controller

CHARGE_BAR = 3.0


def check_modbus_disconnect(rig: SimulatedRig, clock: FakeClock) -> None:
    with controller(rig) as vc:
        assert vc.reservoir_pressure_bar() == 0.0
        rig.faults.inject("modbus-disconnect")
        with pytest.raises(InstrumentConnectionError, match="connection lost") as caught:
            vc.reservoir_pressure_bar()
        assert caught.value.command == "read input registers 0"
        rig.faults.clear("modbus-disconnect")
        vc.set_pressure_setpoint_bar(1.5)  # reconnects by itself
        assert vc.pressure_setpoint_bar() == pytest.approx(1.5)


def check_modbus_slow(rig: SimulatedRig, clock: FakeClock) -> None:
    with controller(rig, timeout_s=0.2) as vc:
        rig.faults.inject("modbus-slow")  # replies after 0.6 s
        with pytest.raises(InstrumentTimeout, match="no reply within 0.2 s"):
            vc.fixture_vacuum_mbar()
        rig.faults.clear("modbus-slow")
        vc.timeout_s = 2.0  # the reconnect below uses it; 0.2 s was only to provoke the timeout
        rig.world.set_pump(True)
        clock.advance(10.0)
        fresh = rig.world.fixture_vacuum_mbar()
        # A fresh connection: the late reply of the timed-out request cannot be mistaken for this one.
        assert vc.fixture_vacuum_mbar() == pytest.approx(fresh, abs=0.1)
        assert fresh < 100.0


def arm_fire_and_wait(rig: SimulatedRig, clock: FakeClock, dig: Digitizer, vc: ValveController,
                      wait_s: float) -> bool:
    charge(vc, clock, CHARGE_BAR)
    dig.arm_single()
    vc.set_fire_valve(True)
    try:
        return dig.wait_for_trigger(wait_s)
    finally:
        vc.set_fire_valve(False)


def check_visa_garbled_block(rig: SimulatedRig, clock: FakeClock) -> None:
    with controller(rig) as vc, Digitizer(rig.addresses.visa_resource, timeout_s=1.0) as dig:
        dig.configure(record_length=20_000, pre_trigger_fraction=0.1)
        assert arm_fire_and_wait(rig, clock, dig, vc, 2.0)
        rig.faults.inject("visa-garbled-block")
        with pytest.raises(InstrumentError) as caught:
            dig.fetch_waveform(2)
        assert "digitizer" in str(caught.value)
        rig.faults.clear("visa-garbled-block")
        dig.connect()  # the stream was out of step: a fresh session
        assert dig.fetch_waveform(2).volts().size == 20_000


def check_visa_endless_reply(rig: SimulatedRig, clock: FakeClock) -> None:
    with Digitizer(rig.addresses.visa_resource, timeout_s=1.0) as dig:
        rig.faults.inject("visa-endless-reply")
        assert dig.acquisition_state() == "IDLE"  # idle: it still answers
        with pytest.raises(InstrumentError, match="reply longer than 65536 bytes") as caught:
            dig.arm_single()  # armed by it, the reply to its error check streams without end: the read stops
        assert "digitizer" in str(caught.value) and not dig.connected  # the session is closed
        rig.faults.clear("visa-endless-reply")
        dig.connect()
        assert dig.acquisition_state() == "ARMED"


def check_no_trigger(rig: SimulatedRig, clock: FakeClock) -> None:
    with controller(rig) as vc, Digitizer(rig.addresses.visa_resource, timeout_s=1.0) as dig:
        dig.configure(record_length=20_000, pre_trigger_fraction=0.1)
        rig.faults.inject("no-trigger")
        assert arm_fire_and_wait(rig, clock, dig, vc, 0.2) is False
        assert rig.world.shots_fired == 1  # the shot was fired, nothing was captured
        assert dig.acquisition_state() == "ARMED"
        rig.faults.clear("no-trigger")
        assert dig.acquisition_state() == "ARMED"  # that shot is gone for good
        dig.abort()
        assert arm_fire_and_wait(rig, clock, dig, vc, 2.0) is True
        assert np.ptp(dig.fetch_waveform(2).volts()) > 0.1


def check_stuck_fill_valve(rig: SimulatedRig, clock: FakeClock) -> None:
    with controller(rig) as vc:
        rig.faults.inject("stuck-fill-valve")
        vc.set_pressure_setpoint_bar(2.0)
        vc.set_fill_valve(True)
        clock.advance(2.0)
        vc.set_fill_valve(False)  # the valve does not obey
        states = vc.valves()  # and its limit switch says so
        assert states.fill_valve is False and states.fill_valve_position is True
        assert states.mismatches() == ["fill valve commanded shut but open"] and states.is_open("fill_valve")
        clock.advance(8.0)
        assert vc.valves().fill_valve is False
        assert vc.reservoir_pressure_bar() == pytest.approx(5.0, abs=1e-3)  # 10 s at 0.5 bar/s
        rig.faults.clear("stuck-fill-valve")
        vc.set_fill_valve(False)  # now it closes
        vc.set_vent_valve(True)
        clock.advance(30.0)
        assert vc.reservoir_pressure_bar() < 0.01


def check_vacuum_leak(rig: SimulatedRig, clock: FakeClock) -> None:
    floor = rig.config.world.pneumatics.fault_leak_floor_mbar
    with controller(rig) as vc:
        rig.faults.inject("vacuum-leak")
        vc.set_vacuum_pump(True)
        clock.advance(60.0)
        assert vc.fixture_vacuum_mbar() == pytest.approx(floor, abs=0.5)
        rig.faults.clear("vacuum-leak")
        clock.advance(60.0)
        assert vc.fixture_vacuum_mbar() < 5.0


def check_door_open(rig: SimulatedRig, clock: FakeClock) -> None:
    with controller(rig) as vc:
        charge(vc, clock, CHARGE_BAR)
        rig.faults.inject("door-open")
        assert vc.interlocks().problems() == ["door/guard open"]
        vc.set_fire_valve(True)
        assert vc.valves().fire_valve is False and rig.world.shots_fired == 0
        rig.faults.clear("door-open")
        assert vc.interlocks().all_safe
        vc.set_fire_valve(True)
        assert rig.world.shots_fired == 1


def check_estop(rig: SimulatedRig, clock: FakeClock) -> None:
    with controller(rig) as vc:
        charge(vc, clock, CHARGE_BAR)
        rig.faults.inject("estop")
        assert vc.interlocks().problems() == ["e-stop tripped"]
        vc.set_fire_valve(True)
        assert rig.world.shots_fired == 0 and rig.world.fire_refusals == ["e-stop tripped"]
        rig.faults.clear("estop")
        assert vc.interlocks().estop_healthy


def check_amp_overload(rig: SimulatedRig, clock: FakeClock) -> None:
    with BridgeAmplifier(rig.addresses.serial_port, timeout_s=1.0) as amp:
        assert amp.overloaded() is False
        rig.faults.inject("amp-overload")
        assert amp.overloaded() is True
        amp.clear_overload()
        assert amp.overloaded() is True  # the cause is still there
        rig.faults.clear("amp-overload")
        assert amp.overloaded() is False


def check_serial_noise(rig: SimulatedRig, clock: FakeClock) -> None:
    with BridgeAmplifier(rig.addresses.serial_port, timeout_s=1.0, retries=1) as amp:
        rig.faults.inject("serial-noise")
        with pytest.raises(InstrumentError, match="checksum mismatch") as caught:
            amp.gain()
        assert caught.value.command == "GAIN?" and caught.value.reply
        rig.faults.clear("serial-noise")
        assert amp.gain() == rig.config.world.amplifier.gain


CHECKS: dict[str, Callable[[SimulatedRig, FakeClock], None]] = {
    "modbus-disconnect": check_modbus_disconnect,
    "modbus-slow": check_modbus_slow,
    "visa-garbled-block": check_visa_garbled_block,
    "visa-endless-reply": check_visa_endless_reply,
    "no-trigger": check_no_trigger,
    "stuck-fill-valve": check_stuck_fill_valve,
    "vacuum-leak": check_vacuum_leak,
    "door-open": check_door_open,
    "estop": check_estop,
    "amp-overload": check_amp_overload,
    "serial-noise": check_serial_noise,
}


def test_every_named_fault_has_a_check() -> None:
    assert set(CHECKS) == set(FAULTS)


@pytest.mark.parametrize("name", sorted(CHECKS))
def test_fault(name: str, rig: SimulatedRig, clock: FakeClock) -> None:
    CHECKS[name](rig, clock)
    assert rig.faults.names() == []
