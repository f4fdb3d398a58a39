"""Fixtures that run the simulated rig in-process (loopback TCP and a pty) and stop it after."""

from __future__ import annotations

import threading
from collections.abc import Iterator
from dataclasses import replace

import pytest

from hopkinson.drivers.sim.simulated_rig import SimConfig, SimulatedRig
from hopkinson.drivers.sim.world import WorldParams
from hopkinson.drivers.valve_controller import ModbusTarget, ValveController


class FakeClock:
    """A wall clock the test moves by hand: the world's state depends only on `advance`."""

    def __init__(self) -> None:
        self.now_s = 1000.0

    def __call__(self) -> float:
        return self.now_s

    def advance(self, seconds: float) -> None:
        self.now_s += seconds


def sim_config(time_scale: float = 1.0, slow_delay_s: float = 0.6, modbus_transport: str = "tcp",
               **world: object) -> SimConfig:
    """A simulator config on free ports (RTU: a fast 115 200 baud line)."""
    base = SimConfig()
    return replace(base, world=replace(WorldParams(time_scale=time_scale), **world),
                   servers=replace(base.servers, modbus_slow_delay_s=slow_delay_s, modbus_transport=modbus_transport,
                                   modbus_baudrate=115200))


def controller_for(rig: SimulatedRig, **kwargs: object) -> ValveController:
    """A (not connected) driver for the rig's simulated controller, over its transport;
    `unit_id` overrides the unit."""
    a = rig.addresses
    target = ModbusTarget(a.modbus_transport, host=a.modbus_host, port=a.modbus_port,
                          serial_port=a.modbus_serial_port, baudrate=a.modbus_baudrate, parity=a.modbus_parity,
                          stopbits=a.modbus_stopbits, unit_id=int(kwargs.pop("unit_id", a.modbus_unit_id)))
    return ValveController(target, **kwargs)  # type: ignore[arg-type]


def controller(rig: SimulatedRig, **kwargs: object) -> ValveController:
    """`controller_for` with a 2 s timeout unless told otherwise."""
    kwargs.setdefault("timeout_s", 2.0)
    return controller_for(rig, **kwargs)


def charge(vc: ValveController, clock: FakeClock, pressure_bar: float) -> None:
    """Charge the reservoir to `pressure_bar`: the fill valve open on `clock` for twice what the
    default fill rate (0.5 bar/s) needs; the controller stops the fill at the set-point."""
    vc.set_pressure_setpoint_bar(pressure_bar)
    vc.set_fill_valve(True)
    clock.advance(4.0 * pressure_bar)
    vc.set_fill_valve(False)


def _sim_threads() -> list[str]:
    return [t.name for t in threading.enumerate() if t.name.startswith("sim-")]


@pytest.fixture
def clock() -> FakeClock:
    return FakeClock()


@pytest.fixture
def rig(clock: FakeClock) -> Iterator[SimulatedRig]:
    """The whole simulated rig on free loopback ports and a pty, its time moved by `clock`."""
    before = set(_sim_threads())
    with SimulatedRig(sim_config(), clock=clock) as sim:
        yield sim
    leftover = set(_sim_threads()) - before
    assert not leftover, f"simulator threads left running: {leftover}"
