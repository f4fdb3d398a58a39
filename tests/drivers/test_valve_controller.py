"""The valve/vacuum controller driver against the simulated controller, over Modbus TCP."""

from __future__ import annotations

import math
import socket
from dataclasses import replace

import pytest
from hopkinson.drivers.errors import InstrumentConnectionError, InstrumentError
from hopkinson.drivers.sim.simulated_rig import SimulatedRig
from hopkinson.drivers.valve_controller import (
    CoilMap,
    DiscreteInputMap,
    HoldingRegisterMap,
    InputRegisterMap,
    RegisterMap,
    ScaleMap,
    ValveController,
)

from tests.drivers.conftest import FakeClock, sim_config


def controller(rig: SimulatedRig, **kwargs: object) -> ValveController:
    a = rig.addresses
    kwargs.setdefault("timeout_s", 2.0)
    return ValveController(a.modbus_host, a.modbus_port, register_map=rig.config.register_map, **kwargs)


def test_identity_names_the_simulated_controller(rig: SimulatedRig) -> None:
    with controller(rig) as vc:
        assert vc.identity() == "Hopkinson-Sim,SIMVAC-1,1.0"


@pytest.mark.parametrize("actuator", ["fill_valve", "vent_valve", "vacuum_pump", "fire_valve"])
def test_each_coil_switches_the_world_and_reads_back(rig: SimulatedRig, actuator: str) -> None:
    world_name = {"fill_valve": "fill", "vent_valve": "vent", "vacuum_pump": "pump", "fire_valve": "fire"}[actuator]
    setter = {"fill_valve": "set_fill_valve", "vent_valve": "set_vent_valve",
              "vacuum_pump": "set_vacuum_pump", "fire_valve": "set_fire_valve"}[actuator]
    with controller(rig) as vc:
        getattr(vc, setter)(True)
        assert getattr(vc.valves(), actuator) is True
        assert rig.world.coils()[world_name] is True
        others = {k: v for k, v in rig.world.coils().items() if k != world_name}
        assert not any(others.values())
        getattr(vc, setter)(False)
        assert getattr(vc.valves(), actuator) is False
        assert rig.world.coils()[world_name] is False


def test_setpoint_round_trips_through_the_scaled_register(rig: SimulatedRig) -> None:
    with controller(rig) as vc:
        vc.set_pressure_setpoint_bar(4.321)
        assert vc.pressure_setpoint_bar() == pytest.approx(4.321, abs=1e-9)
        assert rig.world.pressure_setpoint_bar() == pytest.approx(4.321, abs=1e-9)
        with pytest.raises(ValueError, match="outside the register range"):
            vc.set_pressure_setpoint_bar(70.0)  # 70 000 counts do not fit 16 bits
        with pytest.raises(ValueError):
            vc.set_pressure_setpoint_bar(-1.0)
        assert vc.pressure_setpoint_bar() == pytest.approx(4.321, abs=1e-9)


def test_fill_ramps_at_the_fill_rate_and_the_controller_stops_at_the_setpoint(
        rig: SimulatedRig, clock: FakeClock) -> None:
    rate = rig.config.world.pneumatics.fill_rate_bar_s
    with controller(rig) as vc:
        vc.set_pressure_setpoint_bar(3.0)
        vc.set_fill_valve(True)
        clock.advance(2.0)
        assert vc.reservoir_pressure_bar() == pytest.approx(2.0 * rate, abs=1e-3)
        clock.advance(20.0)  # long past the set-point
        assert vc.reservoir_pressure_bar() == pytest.approx(3.0, abs=1e-3)
        assert vc.valves().fill_valve is True  # the coil stays as commanded


def test_vent_decays_exponentially_to_ambient(rig: SimulatedRig, clock: FakeClock) -> None:
    tau = rig.config.world.pneumatics.vent_time_constant_s
    with controller(rig) as vc:
        vc.set_pressure_setpoint_bar(5.0)
        vc.set_fill_valve(True)
        clock.advance(30.0)
        vc.set_fill_valve(False)
        p0 = vc.reservoir_pressure_bar()
        assert p0 == pytest.approx(5.0, abs=1e-3)
        vc.set_vent_valve(True)
        clock.advance(1.5)
        assert vc.reservoir_pressure_bar() == pytest.approx(p0 * math.exp(-1.5 / tau), abs=1.5e-3)
        clock.advance(20.0)
        assert vc.reservoir_pressure_bar() == pytest.approx(0.0, abs=1e-3)


def test_pump_pulls_the_fixture_vacuum_down_and_it_leaks_back(rig: SimulatedRig, clock: FakeClock) -> None:
    p = rig.config.world.pneumatics
    with controller(rig) as vc:
        assert vc.fixture_vacuum_mbar() == pytest.approx(p.atmosphere_mbar, abs=0.1)
        vc.set_vacuum_pump(True)
        clock.advance(3.0)
        expected = p.pump_floor_mbar + (p.atmosphere_mbar - p.pump_floor_mbar) * math.exp(-3.0 / p.pump_time_constant_s)
        assert vc.fixture_vacuum_mbar() == pytest.approx(expected, abs=0.15)
        clock.advance(60.0)
        floor = vc.fixture_vacuum_mbar()
        assert floor == pytest.approx(p.pump_floor_mbar, abs=0.15)
        vc.set_vacuum_pump(False)
        clock.advance(10.0)
        assert vc.fixture_vacuum_mbar() == pytest.approx(floor + 10.0 * p.leak_rate_mbar_s, abs=0.15)


def test_interlock_inputs_follow_door_clamp_and_estop(rig: SimulatedRig) -> None:
    with controller(rig) as vc:
        locks = vc.interlocks()
        assert locks.all_safe and locks.problems() == []
        rig.world.set_inputs(door_closed=False, fixture_clamped=False)
        locks = vc.interlocks()
        assert (locks.door_closed, locks.fixture_clamped, locks.estop_healthy) == (False, False, True)
        assert locks.problems() == ["door/guard open", "fixture not clamped"]
        rig.world.set_inputs(door_closed=True, fixture_clamped=True, estop_healthy=False)
        assert vc.interlocks().problems() == ["e-stop tripped"]


def test_opening_the_fire_valve_launches_a_shot_from_the_reservoir_pressure(
        rig: SimulatedRig, clock: FakeClock) -> None:
    launcher = rig.config.world.launcher
    with controller(rig) as vc:
        vc.set_pressure_setpoint_bar(4.0)
        vc.set_fill_valve(True)
        clock.advance(30.0)
        vc.set_fill_valve(False)
        vc.set_fire_valve(True)
        truth = rig.world.last_shot_truth
        assert truth is not None and truth["shot_number"] == 1
        assert truth["pressure_bar"] == pytest.approx(4.0, abs=1e-9)
        delta_v = launcher.velocity_transfer * launcher.speed_m_s_per_sqrt_bar * 2.0  # sqrt(4 bar)
        assert truth["delta_velocity_m_s"] == pytest.approx(delta_v)
        assert truth["pulse_width_s"] == pytest.approx(38.6e-6)  # projectile No. 3
        assert truth["peak_acceleration_m_s2"] == pytest.approx(math.pi * delta_v / (2 * 38.6e-6))
        clock.advance(1.0)  # the open fire valve exhausts the reservoir
        assert vc.reservoir_pressure_bar() < 0.01
        vc.set_fire_valve(False)
        vc.set_fire_valve(True)  # a second edge with an empty reservoir fires nothing
        assert rig.world.shots_fired == 1


def test_the_hardware_interlock_keeps_the_fire_valve_shut(rig: SimulatedRig, clock: FakeClock) -> None:
    with controller(rig) as vc:
        vc.set_pressure_setpoint_bar(2.0)
        vc.set_fill_valve(True)
        clock.advance(10.0)
        rig.world.set_inputs(estop_healthy=False)
        vc.set_fire_valve(True)
        assert vc.valves().fire_valve is False
        assert rig.world.shots_fired == 0
        assert rig.world.fire_refusals == ["e-stop tripped"]


def test_projectile_register_selects_the_pulse_width(rig: SimulatedRig, clock: FakeClock) -> None:
    with controller(rig) as vc:
        vc.set_projectile(1)
        assert rig.world.projectile() == 1
        with pytest.raises(ValueError):
            vc.set_projectile(4)
        vc.set_pressure_setpoint_bar(1.0)
        vc.set_fill_valve(True)
        clock.advance(10.0)
        vc.set_fire_valve(True)
    assert rig.world.last_shot_truth["pulse_width_s"] == pytest.approx(120e-6)
    no_register = RegisterMap(holding_registers=HoldingRegisterMap(projectile=-1))
    with pytest.raises(InstrumentError, match="no projectile register"):
        ValveController("127.0.0.1", 1, register_map=no_register).set_projectile(2)


def test_register_numbers_and_scales_come_from_the_map(clock: FakeClock) -> None:
    custom = RegisterMap(
        coils=CoilMap(fire_valve=40, fill_valve=17, vent_valve=3, vacuum_pump=0),
        discrete_inputs=DiscreteInputMap(door_closed=9, fixture_clamped=2, estop_healthy=30),
        holding_registers=HoldingRegisterMap(pressure_setpoint=100, projectile=7),
        input_registers=InputRegisterMap(reservoir_pressure=205, fixture_vacuum=12),
        scales=ScaleMap(pressure_bar_per_count=0.01, vacuum_mbar_per_count=1.0),
    )
    config = replace(sim_config(), register_map=custom)
    with SimulatedRig(config, clock=clock) as sim:
        a = sim.addresses
        with ValveController(a.modbus_host, a.modbus_port, register_map=custom, timeout_s=2.0) as vc:
            vc.set_pressure_setpoint_bar(2.5)
            vc.set_fill_valve(True)
            clock.advance(3.0)
            assert vc.reservoir_pressure_bar() == pytest.approx(1.5, abs=0.01)
            assert sim.world.coils() == {"fire": False, "fill": True, "vent": False, "pump": False}
            sim.world.set_inputs(estop_healthy=False)
            assert vc.interlocks().problems() == ["e-stop tripped"]
            assert vc.fixture_vacuum_mbar() == pytest.approx(1013.0, abs=1.0)
        # The default map reads input register 0 of this controller: not the gauge.
        with ValveController(a.modbus_host, a.modbus_port, timeout_s=2.0) as wrong:
            assert wrong.reservoir_pressure_bar() == 0.0


def test_a_refused_request_names_the_controller_the_command_and_the_exception(rig: SimulatedRig) -> None:
    beyond = RegisterMap(input_registers=InputRegisterMap(reservoir_pressure=500, fixture_vacuum=1))
    a = rig.addresses
    with ValveController(a.modbus_host, a.modbus_port, register_map=beyond, timeout_s=2.0) as vc:
        with pytest.raises(InstrumentError) as caught:
            vc.reservoir_pressure_bar()
        assert caught.value.instrument == f"valve controller {a.modbus_host}:{a.modbus_port}"
        assert caught.value.command == "read input registers 500"
        assert "Modbus exception code 2" in caught.value.problem  # illegal data address
        assert vc.fixture_vacuum_mbar() > 1000.0  # the connection is still good


def test_unreachable_controller_names_itself() -> None:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]  # bound, never listening: connections are refused
        vc = ValveController("127.0.0.1", port, timeout_s=0.5, name="valve controller (test)")
        with pytest.raises(InstrumentConnectionError, match=r"valve controller \(test\): 'connect'"):
            vc.connect()
    with pytest.raises(InstrumentConnectionError, match="not connected"):
        vc.reservoir_pressure_bar()


def test_status_reads_everything_at_once(rig: SimulatedRig, clock: FakeClock) -> None:
    with controller(rig) as vc:
        vc.set_pressure_setpoint_bar(1.25)
        vc.set_fill_valve(True)
        vc.set_vacuum_pump(True)
        rig.world.set_inputs(fixture_clamped=False)
        clock.advance(1.0)
        status = vc.status()
    assert status.reservoir_pressure_bar == pytest.approx(0.5, abs=1e-3)
    assert status.pressure_setpoint_bar == pytest.approx(1.25)
    assert status.fixture_vacuum_mbar == pytest.approx(rig.world.fixture_vacuum_mbar(), abs=0.1)
    assert (status.valves.fill_valve, status.valves.vacuum_pump, status.valves.fire_valve) == (True, True, False)
    assert status.interlocks.problems() == ["fixture not clamped"]
