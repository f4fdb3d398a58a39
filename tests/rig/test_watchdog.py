"""A dead control PC leaves a safe rig: `hopkinson shot` killed with SIGKILL while it charges, or
just after it fired, against a simulator in this test's process (the simulated controller
outlives the killed shot, as a PLC outlives its PC). The controller's link watchdog lapses and
the controller itself closes fill and fire, stops the pump and vents; the fire pulse was timed
by the controller, so the fire valve is shut whatever the moment of the kill. Then the next
shot's CHECK finds the reservoir vented, or vents it first and says so.
"""

from __future__ import annotations

import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from hopkinson.rig.events import AwaitingConfirmation, RigWarning
from hopkinson.rig.sequencer import FireAuthorisation
from hopkinson.rig.sim_session import sim_session
from tests.rig.conftest import (
    REPO,
    assert_safe,
    fast_sim_config,
    read_until,
    rig_toml,
    short_timeouts_config,
)

WATCHDOG_S = 2.0  # the heartbeat beats every watchdog_s / 4: 4x margin for a loaded machine
TIME_SCALE = 10.0  # charging 6 bar takes ~1.2 s: time to kill the process while the fill is open


def _wait_for(condition, timeout_s: float) -> float:
    """Seconds until condition() held (AssertionError after timeout_s)."""
    start = time.monotonic()
    while not condition():
        assert time.monotonic() - start < timeout_s, "timed out"
        time.sleep(0.005)
    return time.monotonic() - start


@pytest.mark.parametrize("kill_when", ["charging", "fired"])
def test_a_killed_shot_leaves_the_controller_to_vent_the_rig(tmp_path: Path, kill_when: str) -> None:
    with sim_session(short_timeouts_config(), fast_sim_config(TIME_SCALE)) as session:
        world = session.world
        toml = rig_toml(session, tmp_path / "rig.toml", evacuate_s=10.0, charge_s=20.0)
        text = toml.read_text(encoding="utf-8")
        toml.write_text(re.sub(r"^watchdog_s = .*$", f"watchdog_s = {WATCHDOG_S}", text, count=1, flags=re.M))
        proc = subprocess.Popen([sys.executable, "-m", "hopkinson", "shot", "--config", str(toml), "--yes",
                                 "--pressure-bar", "6.0", "--out", str(tmp_path)], cwd=REPO, text=True,
                                stdout=subprocess.PIPE, stderr=subprocess.DEVNULL)
        read_until(proc, proc.stdout, r" CHARGE +charging:" if kill_when == "charging" else r" FIRE +fired at")
        proc.send_signal(signal.SIGKILL)
        proc.wait(timeout=10)
        if kill_when == "charging":
            assert world.coils()["fill"] is True and world.watchdog_state() == "armed"  # left filling
        # The controller trips once the heartbeat has been silent for watchdog_s ...
        trip_s = _wait_for(lambda: world.watchdog_state() == "tripped", WATCHDOG_S + 2.0)
        coils = world.coils()
        assert coils == {"fire": False, "fill": False, "vent": True, "pump": False}, coils
        assert world.valve_positions()["fill"] is False
        # ... and the reservoir vents (simulated physics at TIME_SCALE).
        vented_s = _wait_for(lambda: world.reservoir_pressure_bar() <= session.config.limits.vent_done_bar, 10.0)
        assert_safe(world, session.config, digitizer_state=None)  # the PLC's doing: the host was killed
        print(f"\nkilled while {kill_when}: watchdog tripped {trip_s:.2f} s after SIGKILL "
              f"(watchdog_s {WATCHDOG_S:g}), vented {vented_s:.2f} s later (sim {TIME_SCALE:g}x)")
        # The safety deadline: the controller must trip within watchdog_s of the last beat, and the
        # last beat came before the kill, so trip_s <= WATCHDOG_S. Margin 1 s (half the period): the
        # SIGKILL's delivery and the simulator's polling on a loaded machine.
        assert trip_s <= WATCHDOG_S + 1.0
        if kill_when == "fired":
            assert world.shots_fired == 1 and world.fire_pulses == 1


def test_check_vents_pressure_left_in_the_reservoir_first_and_says_so(rig) -> None:
    from tests.rig.test_sequencer import _leave_the_rig_charged

    _leave_the_rig_charged(rig)  # as a dead PC without a watchdog would have left it
    rig.world.set_fill_valve(False)
    outcome = rig.run(pressure_bar=1.0)
    assert outcome.final_state == "DONE" and rig.world.shots_fired == 1
    (warning,) = [e for e in rig.recorder.of(RigWarning) if "venting it first" in e.message]
    assert warning.state == "CHECK" and "before the shot" in warning.message
    assert any("venting it first" in w for w in outcome.warnings)
    rig.assert_safe()


def test_a_missed_heartbeat_while_armed_is_named_as_such(rig) -> None:
    """The PC stalls while the rig waits armed: the controller trips, vents, and the shot is
    aborted with that reason (not as a mysterious leak)."""
    valves = rig.instruments.valves
    valves.start_heartbeat()

    def stall(event: object) -> None:
        if isinstance(event, AwaitingConfirmation):
            # a short watchdog (wall seconds) from here on only: set from the start, a beat delayed
            # on a loaded machine could trip it before ARM, a second trip the test did not stage
            rig.world.set_watchdog_s(0.3)
            valves.stop_heartbeat_thread()

    rig.bus.subscribe(stall)
    try:
        outcome = rig.run(FireAuthorisation(), pressure_bar=2.0, confirm_timeout_s=10.0)
    finally:
        valves.stop_heartbeat()
    assert outcome.aborted_in == "ARM" and not outcome.fired and rig.world.shots_fired == 0
    assert "link watchdog tripped (a heartbeat was missed)" in outcome.error
    assert outcome.hint.startswith("The PC missed the controller's heartbeat")
    assert rig.world.watchdog_trips == 1
    rig.assert_safe()
