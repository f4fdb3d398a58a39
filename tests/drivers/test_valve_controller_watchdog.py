"""The valve/vacuum controller driver's link watchdog (the heartbeat that feeds it, its trip,
its arming) and the fire pulse the controller times and counts, against the simulated
controller over Modbus TCP and RTU (drivers/sim/controller_map.py)."""

from __future__ import annotations

import threading
import time

import pytest

from hopkinson.drivers.errors import InstrumentConnectionError, InstrumentError
from hopkinson.drivers.registers import Register
from hopkinson.drivers.sim.simulated_rig import SimulatedRig
from hopkinson.drivers.valve_controller import (
    HoldingRegisterMap,
    RegisterMap,
    ValveController,
)
from tests.drivers.conftest import FakeClock, charge, controller, sim_config


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
