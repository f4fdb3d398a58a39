"""kill -9 of the process that controls the rig, mid-charge: the simulated controller's link
watchdog notices the silent heartbeat and makes the rig safe by itself (over real Modbus TCP)."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

from hopkinson.drivers.sim.simulated_rig import SimulatedRig
from tests.drivers.conftest import sim_config

CONTROLLER = textwrap.dedent("""
    import sys, time
    from hopkinson.drivers.valve_controller import ValveController
    vc = ValveController.tcp("127.0.0.1", int(sys.argv[1]), watchdog_s=0.5)
    vc.connect()
    vc.set_pressure_setpoint_bar(5.0)
    vc.set_vacuum_pump(True)
    vc.set_fill_valve(True)
    vc.start_heartbeat()
    print("charging", flush=True)
    time.sleep(600)
""")


def test_a_killed_controlling_process_leaves_the_rig_vented(tmp_path: Path) -> None:
    script = tmp_path / "controller.py"
    script.write_text(CONTROLLER)
    with SimulatedRig(sim_config(time_scale=20.0)) as rig:
        beats: list[int] = []
        write = rig.world.heartbeat
        rig.world.heartbeat = lambda value: (beats.append(value), write(value))  # type: ignore[method-assign]
        child = subprocess.Popen([sys.executable, str(script), str(rig.addresses.modbus_port)],
                                 stdout=subprocess.PIPE, text=True)
        try:
            assert child.stdout is not None and child.stdout.readline().strip() == "charging"
            # the child charging, its heartbeat (every 0.125 s) keeping it armed: events, waited for
            deadline = time.monotonic() + 60.0
            while not (rig.world.reservoir_pressure_bar() > 1.0 and len(beats) >= 9) and time.monotonic() < deadline:
                time.sleep(0.02)
            assert rig.world.reservoir_pressure_bar() > 1.0 and len(beats) >= 9  # 9 beats: two watchdog times and more
            assert rig.world.watchdog_trips == 0 and rig.world.watchdog_state() == "armed" and rig.world.coils()["fill"] is True
            os.kill(child.pid, signal.SIGKILL)  # no SAFE, no close: the process is just gone
            child.wait(10.0)
        finally:
            if child.poll() is None:
                child.kill()
                child.wait()
        deadline = time.monotonic() + 20.0
        while rig.world.watchdog_state() != "tripped" and time.monotonic() < deadline:
            time.sleep(0.05)
        assert rig.world.watchdog_state() == "tripped"
        assert rig.world.coils() == {"fire": False, "fill": False, "vent": True, "pump": False}
        while rig.world.reservoir_pressure_bar() > 0.05 and time.monotonic() < deadline:
            time.sleep(0.05)
        state = rig.state()
    assert state["reservoir_pressure_bar"] <= 0.05 and state["fill_valve_open"] is False
    assert state["watchdog_trips"] == 1
