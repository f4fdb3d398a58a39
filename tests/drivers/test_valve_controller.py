"""The valve/vacuum controller driver against the simulated controller, over Modbus TCP and
Modbus RTU on a simulated serial line (the simulator implements its side of the register
protocol on its own, drivers/sim/controller_map.py)."""

from __future__ import annotations

import math
import socket
import threading
import time
from dataclasses import replace

import pytest
from pymodbus.client import ModbusTcpClient

from hopkinson.drivers.base import TraceRecord
from hopkinson.drivers.errors import InstrumentConnectionError, InstrumentError, InstrumentTimeout
from hopkinson.drivers.registers import Register
from hopkinson.drivers.sim.controller_map import Point, default_map
from hopkinson.drivers.sim.simulated_rig import SimConfig, SimulatedRig
from hopkinson.drivers.valve_controller import (
    CoilMap,
    DiscreteInputMap,
    HoldingRegisterMap,
    InputRegisterMap,
    RegisterMap,
    ValveController,
)
from tests.drivers.conftest import FakeClock, controller_for, sim_config


def controller(rig: SimulatedRig, **kwargs: object) -> ValveController:
    kwargs.setdefault("timeout_s", 2.0)
    return controller_for(rig, **kwargs)


def charge(vc: ValveController, clock: FakeClock, pressure_bar: float) -> None:
    vc.set_pressure_setpoint_bar(pressure_bar)
    vc.set_fill_valve(True)
    clock.advance(4.0 * pressure_bar)
    vc.set_fill_valve(False)


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


# -- the link watchdog and the fire pulse, timed by the controller --------------------------------
@pytest.mark.parametrize("transport", ["tcp", "rtu"])
def test_the_watchdog_vents_when_the_heartbeat_stops_and_stays_tripped(transport: str, clock: FakeClock) -> None:
    with SimulatedRig(sim_config(modbus_transport=transport), clock=clock) as rig, \
            controller(rig, watchdog_s=2.0) as vc:
        charge(vc, clock, 3.0)
        vc.set_vacuum_pump(True)
        vc.set_fill_valve(True)
        vc.start_heartbeat()
        assert rig.world.watchdog_s() == 2.0 and vc.watchdog_state() == "armed"
        vc.stop_heartbeat_thread()  # the host freezes: no more beats, nobody disarms
        clock.advance(1.9)
        assert not vc.watchdog_tripped() and rig.world.coils()["fill"] is True
        clock.advance(0.2)  # 2.1 s of silence
        assert vc.watchdog_tripped()
        assert rig.world.coils() == {"fire": False, "fill": False, "vent": True, "pump": False}
        clock.advance(10.0)
        assert vc.reservoir_pressure_bar() < 0.01  # vented
        with pytest.raises(InstrumentError, match="refused by the controller: link watchdog tripped"):
            vc.set_fill_valve(True)
        with pytest.raises(InstrumentError, match="link watchdog tripped"):
            vc.fire_pulse(0.2)
        vc.write_word(vc.map.holding_registers.heartbeat, 5, "a late beat")
        assert vc.watchdog_tripped()  # a late beat does not clear the trip: only a new session
        vc.start_heartbeat()
        assert vc.watchdog_state() == "armed"
        vc.set_fill_valve(True)
        vc.stop_heartbeat()
        assert vc.watchdog_state() == "off"
        clock.advance(60.0)
        assert rig.world.watchdog_state() == "off" and rig.world.coils()["fill"] is True  # disarmed


def _count_beats(rig: SimulatedRig) -> list[int]:
    """Every value written to the heartbeat register from now on (the world's own record)."""
    beats: list[int] = []
    write = rig.world.heartbeat

    def counted(value: int) -> None:
        beats.append(value)
        write(value)

    rig.world.heartbeat = counted  # type: ignore[method-assign]
    return beats


def test_the_heartbeat_thread_keeps_the_watchdog_fed_in_real_time() -> None:
    # the wall clock; 0.8 s: a beat (every 0.2 s) delayed by a loaded machine must not trip it
    with SimulatedRig(sim_config()) as rig, controller(rig, watchdog_s=0.8) as vc:
        beats = _count_beats(rig)
        vc.start_heartbeat()
        # 13 beats written by the driver's thread (every 0.2 s: three watchdog times and more),
        # waited for as events with a generous timeout, and the watchdog never tripped meanwhile
        deadline = time.monotonic() + 60.0
        while len(beats) < 13 and time.monotonic() < deadline:
            time.sleep(0.02)
        assert len(beats) >= 13 and rig.world.watchdog_trips == 0
        assert vc.heartbeat_running and vc.watchdog_state() == "armed"
        vc.stop_heartbeat_thread()
        deadline = time.monotonic() + 10.0
        while rig.world.watchdog_state() != "tripped" and time.monotonic() < deadline:
            time.sleep(0.02)
        assert rig.world.watchdog_state() == "tripped" and rig.world.coils()["vent"] is True
        vc.start_heartbeat()
        vc.stop_heartbeat()
        assert not vc.heartbeat_running and vc.watchdog_state() == "off"


def test_stop_heartbeat_disarms_even_after_a_failure_closed_the_link(rig: SimulatedRig) -> None:
    # A long watchdog: the beat thread (every 15 s) never runs during the test.
    with controller(rig, watchdog_s=60.0) as vc:
        vc.start_heartbeat()
        assert rig.world.watchdog_state() == "armed"
        rig.faults.inject("modbus-disconnect")
        with pytest.raises(InstrumentConnectionError):
            vc.reservoir_pressure_bar()
        rig.faults.clear("modbus-disconnect")
        assert not vc.connected  # the failure closed the link ...
        vc.stop_heartbeat()
        assert rig.world.watchdog_state() == "off"  # ... and the disarm reopened it


class _WatchedLock:
    """The driver's re-entrant lock, telling which threads wait for it."""

    def __init__(self) -> None:
        self._lock = threading.RLock()
        self.waiting: set[str] = set()

    def __enter__(self) -> None:
        name = threading.current_thread().name
        self.waiting.add(name)
        self._lock.acquire()
        self.waiting.discard(name)

    def __exit__(self, *exc: object) -> None:
        self._lock.release()


def _hold_until_waiting(lock: _WatchedLock, thread: threading.Thread) -> None:
    deadline = time.monotonic() + 10.0
    while thread.name not in lock.waiting and time.monotonic() < deadline:
        time.sleep(0.01)
    assert thread.name in lock.waiting


def test_a_beat_held_up_past_its_session_s_end_is_never_written(rig: SimulatedRig) -> None:
    # The beat thread waits for the link while another transaction holds it; the session ends
    # (the join gives up) and a new one starts. The old thread must neither beat on in the new
    # session nor write its late beat after the stop (a beat re-arms a disarmed controller).
    with controller(rig, watchdog_s=0.4, timeout_s=0.3) as vc:
        vc.lock = _WatchedLock()  # type: ignore[assignment]
        vc.start_heartbeat()
        first = vc._beat_thread
        assert first is not None
        with vc.lock:  # a slow transaction: the next beat waits for it
            _hold_until_waiting(vc.lock, first)
            vc.stop_heartbeat()  # the join gives up after 1 s; the disarm is written
            assert first.is_alive() and rig.world.watchdog_state() == "off"
        first.join(5.0)
        assert not first.is_alive()  # it ended instead of beating on
        assert rig.world.watchdog_state() == "off"  # and its late beat did not re-arm the controller
        vc.start_heartbeat()
        second = vc._beat_thread
        assert second is not None
        with vc.lock:
            _hold_until_waiting(vc.lock, second)
            vc.start_heartbeat()  # a new session while the old thread still waits
        second.join(5.0)
        assert not second.is_alive()
        assert [t for t in threading.enumerate() if t.name == f"heartbeat {vc.name}"] == [vc._beat_thread]
        vc.stop_heartbeat()


def test_a_read_only_client_neither_arms_nor_feeds_the_watchdog(rig: SimulatedRig, clock: FakeClock) -> None:
    with controller(rig, watchdog_s=1.0) as shot, controller(rig) as status:
        status.status()
        clock.advance(5.0)
        assert rig.world.watchdog_state() == "off"  # never armed by reads
        shot.start_heartbeat()
        shot.stop_heartbeat_thread()
        for _ in range(5):  # the status client polls through the silence
            clock.advance(0.3)
            status.status()
        assert status.watchdog_tripped()


@pytest.mark.parametrize("transport", ["tcp", "rtu"])
def test_the_controller_times_the_fire_pulse_and_counts_it(transport: str, clock: FakeClock) -> None:
    with SimulatedRig(sim_config(modbus_transport=transport), clock=clock) as rig, controller(rig) as vc:
        charge(vc, clock, 2.0)
        before = vc.fire_pulse_count()
        vc.fire_pulse(0.2)
        assert vc.fire_pulse_count() == before + 1 and rig.world.shots_fired == 1
        assert vc.valves().fire_valve is True  # open for the pulse ...
        clock.advance(0.19)
        assert vc.valves().fire_valve_position is True
        clock.advance(0.02)
        assert vc.valves().fire_valve is False  # ... and shut by the controller itself
        rig.world.set_inputs(door_closed=False)
        with pytest.raises(InstrumentError) as caught:
            vc.fire_pulse(0.2)
        assert "fire pulse refused by the controller: door/guard open" in str(caught.value)
        assert caught.value.command == "write register 4 (fire pulse) = [200]"
        assert vc.fire_pulse_count() == before + 1


def test_the_heartbeat_and_pulse_need_their_registers() -> None:
    bare = RegisterMap(holding_registers=HoldingRegisterMap(heartbeat=-1, fire_pulse_ms=Register()))
    vc = ValveController.tcp("127.0.0.1", 1, register_map=bare)
    with pytest.raises(InstrumentError, match="no heartbeat register"):
        vc.start_heartbeat()
    with pytest.raises(InstrumentError, match="no fire_pulse_ms register"):
        vc.fire_pulse(0.2)


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
