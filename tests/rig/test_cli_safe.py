"""`hopkinson safe`: makes the rig safe from any terminal and confirms it by reading back the
simulated controller; says when it cannot; never fights a running shot, and with
--stop-holder asks it to stop (it goes SAFE itself) before confirming the safe state."""

from __future__ import annotations

import json
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from hopkinson.rig.cli.main import main
from hopkinson.rig.lock import current_holder
from hopkinson.rig.sim_session import sim_session
from tests.rig.conftest import REPO, assert_safe, fast_sim_config, rig_toml, short_timeouts_config


def _charge(world, stuck: bool = False) -> None:
    """Leave the rig as a crashed PC without a watchdog would: filling, vent shut, pump on."""
    if stuck:
        world.faults.inject("stuck-fill-valve")
    world.set_vent_valve(False)
    world.set_pump(True)
    world.set_pressure_setpoint_bar(2.0)
    world.set_fill_valve(True)
    deadline = time.monotonic() + 5.0
    while world.reservoir_pressure_bar() < 1.0:
        assert time.monotonic() < deadline
        time.sleep(0.01)


@pytest.fixture
def sim(tmp_path: Path):
    with sim_session(short_timeouts_config(), fast_sim_config(10.0)) as session:
        yield session, rig_toml(session, tmp_path / "rig.toml", safe_s=2.0, evacuate_s=10.0, charge_s=20.0)


def test_safe_vents_a_charged_rig_and_confirms_it_by_reading_back(sim, capsys) -> None:
    session, toml = sim
    _charge(session.world)
    assert main(["safe", "--config", str(toml), "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["confirmed"] is True and report["problem"] is None
    assert report["reservoir_pressure_bar"] <= session.config.limits.vent_done_bar
    assert report["valves"]["fill_valve"] == "shut (commanded), shut (limit switch)"
    assert report["valves"]["vent_valve"] == "open (commanded), open (limit switch)"
    world = session.world
    assert_safe(world, session.config, digitizer_state=session.rig.digitizer.state)
    assert world.watchdog_state() == "off" and current_holder(session.config) is None


def test_safe_says_what_it_could_not_confirm(sim, capsys) -> None:
    session, toml = sim
    _charge(session.world, stuck=True)
    assert main(["safe", "--config", str(toml)]) == 3
    out, err = capsys.readouterr()
    assert err.count("\n") == 1 and err.startswith("hopkinson: error: SAFE NOT CONFIRMED: ")
    assert "fill valve open (commanded shut)" in err and "check the rig by hand" in err
    assert "fill valve" in out and "shut (commanded), open (limit switch)" in out
    assert_safe(session.world, session.config, digitizer_state=session.rig.digitizer.state, vented=False,
                stuck=("fill",))  # commanded shut; the valve itself is stuck


def test_stop_holder_asks_the_running_shot_to_go_safe_then_confirms(sim, tmp_path: Path, capsys) -> None:
    session, toml = sim
    shot = subprocess.Popen([sys.executable, "-m", "hopkinson", "shot", "--config", str(toml), "--yes",
                             "--pressure-bar", "6.0", "--out", str(tmp_path)], cwd=REPO, text=True,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    deadline = time.monotonic() + 60
    while not session.world.coils()["fill"]:  # the shot is charging
        assert shot.poll() is None and time.monotonic() < deadline, shot.communicate()
        time.sleep(0.02)
    assert main(["safe", "--config", str(toml)]) == 2  # never fights a running shot
    assert "--stop-holder" in capsys.readouterr().err
    assert session.world.coils()["fill"] is True  # untouched: the shot still charges
    assert main(["safe", "--config", str(toml), "--stop-holder"]) == 0
    out, err = capsys.readouterr()
    assert f"sent SIGTERM to pid {shot.pid}" in err and "rig safe: confirmed by reading back" in out
    _, shot_err = shot.communicate(timeout=30)
    assert shot.returncode == 3 and f"interrupted ({signal.SIGTERM.name})" in shot_err
    assert session.world.shots_fired == 0
    assert_safe(session.world, session.config, digitizer_state=session.rig.digitizer.state)


def test_safe_with_no_controller_listening_is_not_confirmed_exit_3(tmp_path: Path, capsys) -> None:
    # issue 18: it exited 2 ("bad input"), though nothing had confirmed the rig safe
    import socket

    text = (Path(__file__).resolve().parents[2] / "config" / "rig-sim.toml").read_text(encoding="utf-8")
    with socket.socket() as closed:  # bound, not listening: connection refused
        closed.bind(("127.0.0.1", 0))
        port = closed.getsockname()[1]
        config = tmp_path / "rig.toml"
        config.write_text(text.replace("port = 5020", f"port = {port}", 1), encoding="utf-8")
        assert f"port = {port}" in config.read_text()
        assert main(["safe", "--config", str(config)]) == 3
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("hopkinson: error: SAFE NOT CONFIRMED: the valve controller "
                                                   "cannot be reached") and "check the rig by hand" in err
