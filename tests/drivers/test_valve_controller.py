"""The valve/vacuum controller driver against the simulated controller, over Modbus TCP and
Modbus RTU on a simulated serial line (the simulator implements its side of the register
protocol on its own, drivers/sim/controller_map.py): the coils, registers and inputs and the
simulated world they move, the register map, errors and timeouts, and the trace. The link
watchdog and the controller-timed fire pulse are test_valve_controller_watchdog.py's, the fire
styles test_valve_controller_fire_styles.py's."""

from __future__ import annotations

import math
import socket
from dataclasses import replace

import pytest
from pymodbus.client import ModbusTcpClient

from hopkinson.drivers.errors import InstrumentConnectionError, InstrumentError, InstrumentTimeout
from hopkinson.drivers.registers import Register
from hopkinson.drivers.sim.controller_map import Point, default_map
from hopkinson.drivers.sim.simulated_rig import SimulatedRig
from hopkinson.drivers.valve_controller import (
    CoilMap,
    DiscreteInputMap,
    HoldingRegisterMap,
    InputRegisterMap,
    RegisterMap,
    ValveController,
)
from tests.drivers.conftest import FakeClock, charge, controller, sim_config


@pytest.mark.parametrize("transport", ["tcp", "rtu"])
def test_identity_and_coils_over_both_transports(transport: str, clock: FakeClock) -> None:
    with SimulatedRig(sim_config(modbus_transport=transport), clock=clock) as rig, controller(rig) as vc:
        a = rig.addresses
        assert vc.identity() == "Hopkinson-Sim,SIMVAC-1,1.0"
        assert vc.name == "valve controller " + (f"{a.modbus_host}:{a.modbus_port}" if transport == "tcp"
                                                  else f"{a.modbus_serial_port} unit 1")
        vc.set_vent_valve(True)
        assert rig.world.coils()["vent"] is True and vc.valves().vent_valve is True
        assert vc.valves().vent_valve_position is True


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
        with pytest.raises(ValueError, match=r"pressure set-point 70 bar: .*uint16 register holds \(0 .. 65.535\)"):
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
        states = vc.valves()
        assert states.fill_valve is True  # the coil stays as commanded ...
        assert states.fill_valve_position is False  # ... the regulating controller shut the valve
        assert states.mismatches() == []  # open-while-told-shut is what counts


def test_vent_decays_exponentially_to_ambient(rig: SimulatedRig, clock: FakeClock) -> None:
    tau = rig.config.world.pneumatics.vent_time_constant_s
    with controller(rig) as vc:
        charge(vc, clock, 5.0)
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
        charge(vc, clock, 4.0)
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
        charge(vc, clock, 2.0)
        rig.world.set_inputs(estop_healthy=False)
        vc.set_fire_valve(True)
        assert vc.valves().fire_valve is False
        assert rig.world.shots_fired == 0
        assert rig.world.fire_refusals == ["e-stop tripped"]


def test_projectile_register_selects_the_pulse_width(rig: SimulatedRig, clock: FakeClock) -> None:
    with controller(rig) as vc:
        assert vc.has_projectile_register
        vc.set_projectile(1)
        assert rig.world.projectile() == 1
        with pytest.raises(ValueError):
            vc.set_projectile(4)
        charge(vc, clock, 1.0)
        vc.set_fire_valve(True)
    assert rig.world.last_shot_truth["pulse_width_s"] == pytest.approx(120e-6)
    no_register = RegisterMap(holding_registers=HoldingRegisterMap(projectile=-1))
    vc = ValveController.tcp("127.0.0.1", 1, register_map=no_register)
    assert not vc.has_projectile_register
    with pytest.raises(InstrumentError, match="no projectile register"):
        vc.set_projectile(2)


# -- the register map: addresses, gaps, types, word orders, scales, offsets -----------------------
def test_every_register_type_and_word_order_round_trips_through_the_simulator(clock: FakeClock) -> None:
    # Both sides written by hand: the driver's Register and the simulator's Point say the same.
    driver = RegisterMap(
        coils=CoilMap(fire_valve=40, fill_valve=17, vent_valve=3, vacuum_pump=0),
        discrete_inputs=DiscreteInputMap(door_closed=9, fixture_clamped=2, estop_healthy=30,
                                         fire_valve_open=-1, fill_valve_open=100, vent_valve_open=-1),
        holding_registers=HoldingRegisterMap(
            pressure_setpoint=Register(100, "float32", "little"), projectile=7, heartbeat=20,
            watchdog_ms=Register(21, "uint32", "little"), fire_pulse_ms=Register(30, "int16", scale=10.0)),
        input_registers=InputRegisterMap(
            reservoir_pressure=Register(205, "int32", "big", scale=1e-4, offset=-1.0),
            fixture_vacuum=Register(12, "float32", "big", scale=0.5), watchdog_state=50,
            fire_pulse_count=Register(60, "uint32", "big")))
    sim = {
        "coils": {"fire_valve": Point(40), "fill_valve": Point(17), "vent_valve": Point(3), "vacuum_pump": Point(0)},
        "discrete_inputs": {"door_closed": Point(9), "fixture_clamped": Point(2), "estop_healthy": Point(30),
                            "fill_valve_open": Point(100)},
        "holding_registers": {"pressure_setpoint": Point(100, "float32", "little"), "projectile": Point(7),
                              "heartbeat": Point(20), "watchdog_ms": Point(21, "uint32", "little"),
                              "fire_pulse_ms": Point(30, "int16", scale=10.0)},
        "input_registers": {"reservoir_pressure": Point(205, "int32", "big", scale=1e-4, offset=-1.0),
                            "fixture_vacuum": Point(12, "float32", "big", scale=0.5), "watchdog_state": Point(50),
                            "fire_pulse_count": Point(60, "uint32", "big")},
    }
    with SimulatedRig(replace(sim_config(), register_map=sim), clock=clock) as rig, \
            controller(rig, register_map=driver, watchdog_s=70_000.0 / 1000) as vc:
        vc.set_pressure_setpoint_bar(2.5)
        assert rig.world.pressure_setpoint_bar() == pytest.approx(2.5)  # float32 little word order
        vc.set_fill_valve(True)
        clock.advance(3.0)
        assert vc.reservoir_pressure_bar() == pytest.approx(1.5, abs=1e-4)  # int32 with offset -1 bar
        assert rig.world.coils() == {"fire": False, "fill": True, "vent": False, "pump": False}
        assert vc.valves().fill_valve_position is True
        rig.world.set_inputs(estop_healthy=False)
        assert vc.interlocks().problems() == ["e-stop tripped"]
        assert vc.fixture_vacuum_mbar() == pytest.approx(1013.25, abs=0.5)
        vc.start_heartbeat()  # uint32 watchdog time of 70 000 ms: beyond 16 bits
        assert rig.world.watchdog_s() == pytest.approx(70.0)
        rig.world.set_inputs(estop_healthy=True)
        vc.fire_pulse(0.25)  # int16 in 10 ms steps: 25
        assert rig.world.fire_pulses == 1 and vc.fire_pulse_count() == 1
        vc.stop_heartbeat()


def test_a_map_with_gaps_reads_only_mapped_addresses(rig: SimulatedRig) -> None:
    # The simulator maps discrete inputs 0, 1, 2, 8, 9, 10: a read of the gap is refused ...
    a = rig.addresses
    with ModbusTcpClient(a.modbus_host, port=a.modbus_port, timeout=2.0) as plain:
        assert plain.read_discrete_inputs(0, count=3, device_id=1).bits[:3] == [True, True, True]
        assert plain.read_discrete_inputs(0, count=11, device_id=1).exception_code == 2
        assert plain.read_discrete_inputs(3, count=1, device_id=1).exception_code == 2
        assert plain.read_coils(4, count=1, device_id=1).exception_code == 2  # beyond the map
        assert plain.read_input_registers(3, count=1, device_id=1).exception_code == 2
        assert plain.read_input_registers(4, count=1, device_id=1).exception_code == 2  # half a uint32
        assert plain.write_coil(4, True, device_id=1).exception_code == 2
    # ... and the driver reads each run on its own.
    with controller(rig) as vc:
        states = vc.valves()
        assert states.vent_valve_position is False and states.fill_valve_position is False


def test_a_refused_request_names_the_controller_the_command_and_the_exception(rig: SimulatedRig) -> None:
    beyond = RegisterMap(input_registers=InputRegisterMap(reservoir_pressure=Register(500)))
    with controller(rig, register_map=beyond) as vc:
        with pytest.raises(InstrumentError) as caught:
            vc.reservoir_pressure_bar()
        assert caught.value.instrument == vc.name == f"valve controller {vc.target.host}:{vc.target.port}"
        assert caught.value.command == "read input registers 500"
        assert "Modbus exception 2: illegal data address" in caught.value.problem
        assert vc.fixture_vacuum_mbar() > 1000.0  # the link is still good


@pytest.mark.parametrize("transport", ["tcp", "rtu"])
def test_the_simulator_answers_only_its_unit_id(transport: str, clock: FakeClock) -> None:
    with SimulatedRig(sim_config(modbus_transport=transport), clock=clock) as rig:
        a = rig.addresses
        with controller(rig, unit_id=7, timeout_s=0.3) as stranger:
            if transport == "tcp":  # a TCP device says the target did not answer
                with pytest.raises(InstrumentError, match="Modbus exception 11"):
                    stranger.reservoir_pressure_bar()
            else:  # an RS-485 device keeps silent for another unit
                with pytest.raises(InstrumentTimeout, match="no reply within 0.3 s"):
                    stranger.reservoir_pressure_bar()
        assert a.modbus_unit_id == 1
        with controller(rig) as right:
            assert right.reservoir_pressure_bar() == 0.0


def test_a_dead_rtu_controller_is_a_timeout_and_the_next_request_works_again(clock: FakeClock) -> None:
    with SimulatedRig(sim_config(modbus_transport="rtu"), clock=clock) as rig, controller(rig, timeout_s=0.3) as vc:
        rig.faults.inject("modbus-disconnect")  # RTU: the controller stops answering
        with pytest.raises(InstrumentTimeout, match="'read input registers 1': no reply within 0.3 s"):
            vc.fixture_vacuum_mbar()
        rig.faults.clear("modbus-disconnect")
        assert vc.fixture_vacuum_mbar() == pytest.approx(1013.2, abs=0.1)  # the port reopens by itself


def test_unreachable_controller_names_itself() -> None:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]  # bound, never listening: connections are refused
        vc = ValveController.tcp("127.0.0.1", port, timeout_s=0.5, name="valve controller (test)")
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
    assert status.watchdog == "off" and status.fire_pulse_count == 0


def test_the_default_map_matches_the_simulators_own() -> None:
    driver = RegisterMap().blocks()
    sim = default_map()
    for table, points in sim.items():
        assert set(points) == set(driver[table])
        for name, point in points.items():
            entry = driver[table][name]
            address = entry.address if isinstance(entry, Register) else entry
            assert address == point.address, f"{table}.{name}"


def test_every_exchange_is_traced(rig: SimulatedRig) -> None:
    records = []
    with controller(rig, trace=records.append) as vc:
        vc.reservoir_pressure_bar()
    assert [r.direction for r in records] == ["->", "<-"]
    assert "ReadInputRegistersRequest" in records[0].text and "address=0" in records[0].text
    assert all(r.instrument == vc.name and r.utc.endswith("+00:00") for r in records)
