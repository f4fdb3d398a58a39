"""`hopkinson sim` (as its own process, once) and `hopkinson status`."""

from __future__ import annotations

import contextlib
import dataclasses
import json
import os
import signal
import socket
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
import serial

from hopkinson.drivers.sim.faults import FAULTS
from hopkinson.drivers.sim.simulated_rig import SimAddresses, SimulatedRig
from hopkinson.rig.cli.main import main

ROOT = Path(__file__).resolve().parents[2]
CONFIG = ROOT / "config"


def rig_toml_for(addresses: SimAddresses | dict, tmp_path: Path, name: str = "rig.toml") -> Path:
    """config/rig-sim.toml with the addresses of a simulator started on free ports."""
    a = addresses.as_dict() if isinstance(addresses, SimAddresses) else addresses
    text = (CONFIG / "rig-sim.toml").read_text()
    replacements = {
        "port = 5020\n": f"port = {a['modbus_port']}\n",
        'resource = "TCPIP0::127.0.0.1::5025::SOCKET"': f'resource = "{a["visa_resource"]}"',
        'port = "sim:amplifier"': f'port = "{a["serial_port"]}"',
    }
    for old, new in replacements.items():
        assert old in text, old
        text = text.replace(old, new)
    path = tmp_path / name
    path.write_text(text)
    return path


@contextlib.contextmanager
def sim_process(args: list[str], addresses_json: Path) -> Iterator[tuple[subprocess.Popen[str], dict[str, Any]]]:
    """`hopkinson sim ARGS --addresses-json PATH` as its own process, with its addresses once it
    has written them; a process still running when the block ends is killed."""
    process = subprocess.Popen([sys.executable, "-m", "hopkinson", "sim", *args, "--addresses-json", str(addresses_json)],
                               cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        deadline = time.monotonic() + 30.0
        while not addresses_json.exists():
            assert process.poll() is None, process.communicate()
            assert time.monotonic() < deadline, "the simulator did not write its addresses"
            time.sleep(0.05)
        yield process, json.loads(addresses_json.read_text())
    finally:
        if process.poll() is None:
            process.kill()
            process.communicate()


def stop_with_ctrl_c(process: subprocess.Popen[str]) -> tuple[str, str]:
    """SIGINT, then the process's stdout and stderr once it has ended."""
    process.send_signal(signal.SIGINT)
    return process.communicate(timeout=15)


def test_list_faults_prints_one_line_per_fault(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["sim", "--list-faults"]) == 0
    lines = capsys.readouterr().out.strip().splitlines()
    assert len(lines) == len(FAULTS)
    for line, (name, text) in zip(lines, FAULTS.items(), strict=True):
        assert line.split()[0] == name and line.endswith(text)


def test_unknown_fault_and_bad_config_are_one_line_errors(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["sim", "--fault", "gremlins"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "unknown fault 'gremlins'" in err and "modbus-slow" in err
    bad = tmp_path / "sim.toml"
    bad.write_text("[world]\ntime_scale = -1\n")
    assert main(["sim", "--config", str(bad)]) == 2
    err = capsys.readouterr().err
    assert err == f"hopkinson: error: {bad}: world.time_scale: must be greater than 0, got -1\n"


def test_sim_process_serves_status_and_stops_cleanly_on_ctrl_c(
        tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch) -> None:
    runtime = tmp_path / "runtime"  # this test's own private runtime folder (xdist-safe)
    runtime.mkdir(mode=0o700)
    monkeypatch.setenv("XDG_RUNTIME_DIR", str(runtime))
    sim_toml = tmp_path / "sim.toml"
    sim_toml.write_text("[servers]\nmodbus_port = 0\ndigitizer_port = 0\n")
    addresses_json = tmp_path / "addresses.json"
    folder = runtime / "hopkinson"
    with sim_process(["--config", str(sim_toml), "--fault", "door-open"], addresses_json) as (process, addresses):
        link = folder / f"sim-{process.pid}-amplifier"
        assert addresses["pid"] == process.pid
        assert json.loads((folder / "sim-addresses.json").read_text()) == addresses
        assert os.path.realpath(link) == addresses["serial_port"]
        assert (folder.stat().st_mode & 0o777) == 0o700
        state = json.loads(Path(addresses["state_file"]).read_text())
        assert state["fill_valve_open"] is False and state["watchdog"] == "off"
        # config/rig-sim.toml's "sim:amplifier" is found through the runtime folder's addresses
        config = rig_toml_for({**addresses, "serial_port": "sim:amplifier"}, tmp_path)
        assert main(["status", "--config", str(config), "--json"]) == 0
        report = json.loads(capsys.readouterr().out)
        assert report["ok"] is True and report["held_by"] is None
        assert report["valve_controller"]["identity"] == "Hopkinson-Sim,SIMVAC-1,1.0"
        assert report["valve_controller"]["interlock_problems"] == ["door/guard open"]  # --fault door-open
        assert report["digitizer"]["identity"].startswith("Hopkinson-Sim,SIMDIG")
        assert report["amplifier"]["identity"].startswith("Hopkinson-Sim,SIMAMP")
        assert report["amplifier"]["address"] == "sim:amplifier"
        out, err = stop_with_ctrl_c(process)
    assert process.returncode == 0, err
    assert f"modbus  tcp {addresses['modbus']} (unit 1)\n" in out
    assert f"visa    {addresses['visa_resource']}\n" in out
    assert f"serial  {addresses['serial_port']} (link {link})\n" in out
    assert "faults  door-open" in out and out.endswith("simulated rig stopped\n")
    assert "Traceback" not in err
    assert not link.exists() and not (folder / "sim-addresses.json").exists()
    assert not Path(addresses["state_file"]).exists()
    for port in (addresses["modbus_port"], int(addresses["visa_resource"].split("::")[2])):
        with socket.socket() as s:
            assert s.connect_ex(("127.0.0.1", port)) != 0


def test_a_sim_port_without_a_running_simulator_is_a_clear_error(
        tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("XDG_RUNTIME_DIR", str(tmp_path))
    with SimulatedRig() as sim:
        config = rig_toml_for({**sim.addresses.as_dict(), "serial_port": "sim:amplifier"}, tmp_path)
        assert main(["status", "--config", str(config), "--json"]) == 1
    report = json.loads(capsys.readouterr().out)
    assert report["valve_controller"]["ok"] and report["digitizer"]["ok"]
    assert "no `hopkinson sim` is running for this user" in report["amplifier"]["error"]


def test_status_reports_every_instrument_of_an_in_process_rig(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    with SimulatedRig() as sim:
        sim.world.set_pressure_setpoint_bar(2.5)
        config = rig_toml_for(sim.addresses, tmp_path)
        assert main(["status", "--config", str(config)]) == 0
        text = capsys.readouterr().out
        assert main(["status", "--config", str(config), "--json"]) == 0
        report = json.loads(capsys.readouterr().out)
    assert "valve/vacuum controller" in text and "(set-point 2.500 bar)" in text
    assert "interlocks         all safe" in text and "all instruments answered" in text
    assert report["valve_controller"]["pressure_setpoint_bar"] == pytest.approx(2.5)
    assert report["valve_controller"]["fixture_vacuum_mbar"] == pytest.approx(1013.2, abs=0.1)
    assert report["valve_controller"]["valves"] == {
        "fire_valve": False, "fill_valve": False, "vent_valve": False, "vacuum_pump": False,
        "fire_valve_position": False, "fill_valve_position": False, "vent_valve_position": False}
    assert report["valve_controller"]["watchdog"] == "off" and report["valve_controller"]["fire_pulse_count"] == 0
    assert report["digitizer"]["state"] == "IDLE"
    assert report["amplifier"]["gain"] == 10.0 and report["amplifier"]["overloaded"] is False
    assert report["amplifier"]["source"] == "read back"


def test_status_shows_a_stuck_valve_and_a_tripped_watchdog(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    with SimulatedRig(faults=["stuck-fill-valve"]) as sim:
        sim.world.set_pressure_setpoint_bar(2.0)
        sim.world.set_fill_valve(True)
        sim.world.set_fill_valve(False)  # stuck: stays open
        sim.world.heartbeat(1)
        sim.world.set_watchdog_s(0.2)
        time.sleep(0.3)
        config = rig_toml_for(sim.addresses, tmp_path)
        assert main(["status", "--config", str(config)]) == 0
    text = capsys.readouterr().out
    assert "fill shut (really open)" in text
    assert "link watchdog      tripped, 0 fire pulses" in text
    assert "WARNING            fill valve commanded shut but open" in text


def test_status_while_the_rig_is_held_reads_only_the_shared_controller(
        tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch) -> None:
    from hopkinson.rig.config import load_rig_config
    from hopkinson.rig.lock import LOCK_DIR_ENV, RigLock

    monkeypatch.setenv(LOCK_DIR_ENV, str(tmp_path / "locks"))
    with SimulatedRig() as sim:
        config = rig_toml_for(sim.addresses, tmp_path)
        with RigLock.acquire(load_rig_config(config), "hopkinson shot --sim"), \
                serial.Serial(sim.addresses.serial_port, exclusive=True):  # the shot's amplifier line
            assert main(["status", "--config", str(config)]) == 0
            text = capsys.readouterr().out
            assert main(["status", "--config", str(config), "--json"]) == 0
            report = json.loads(capsys.readouterr().out)
        served = sim.amplifier.lines_served
    assert report["held_by"]["pid"] == os.getpid() and report["held_by"]["command"] == "hopkinson shot --sim"
    assert report["valve_controller"]["identity"].startswith("Hopkinson-Sim")  # Modbus TCP: shared
    assert report["amplifier"]["skipped"].startswith(f"not asked: the rig is held by pid {os.getpid()}")
    assert "skipped" in report["digitizer"]
    assert served == 0  # the held serial line was never touched
    assert f"the rig is held by pid {os.getpid()} (hopkinson shot --sim" in text
    # issue 18: it said "all instruments answered" though two were not asked
    assert "all instruments answered" not in text and "not asked: digitizer, amplifier" in text


def test_probe_reads_every_signal_and_says_what_to_fix(
        tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch) -> None:
    with SimulatedRig() as sim:
        good = rig_toml_for(sim.addresses, tmp_path)
        assert main(["probe", "--config", str(good)]) == 0
        text = capsys.readouterr().out
        monkeypatch.setattr("hopkinson.rig.cli.probe.visa_resources", lambda library: {"library": library,
                                                                                       "resources": []})
        wrong = tmp_path / "wrong.toml"
        wrong.write_text(good.read_text().replace('fire_pulse_count = { address = 4, type = "uint32" }',
                                                  'fire_pulse_count = { address = 6, type = "uint32" }'))
        assert main(["probe", "--config", str(wrong), "--json"]) == 1
        report = json.loads(capsys.readouterr().out)
    assert "VISA resources (@py):" in text and "serial ports:" in text
    assert "  ok    input_registers.fixture_vacuum (input registers 1, uint16 big, x0.1): 1013.2" in text
    assert "  ok    discrete_inputs.fill_valve_open (discrete input 9): False" in text
    assert "  ok    holding_registers.projectile (holding register 1): 3" in text
    assert "  ok    identity: Hopkinson-Sim,SIMAMP-1" in text
    assert "  ok    acquisition and channel settings: {'sample_rate_hz'" in text
    assert "  ok    settings against rig.toml: " in text
    assert "FAIL" not in text and text.rstrip().endswith("failed: the rig answers as configured")
    steps = report["instruments"]["valve_controller"]["steps"]
    (failed,) = [s for s in steps if not s["ok"]]
    assert failed["step"] == "input_registers.fire_pulse_count (input registers 6..7, uint32 big)"
    assert "'read input registers 6..7': Modbus exception 2: illegal data address" in failed["error"]
    assert "register map" in failed["fix"]
    assert all(s["ok"] for s in report["instruments"]["amplifier"]["steps"])


def test_probe_names_the_fix_for_an_unreachable_rig(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                                    monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr("hopkinson.rig.cli.probe.visa_resources", lambda library: {"library": library,
                                                                                   "error": "no VISA here"})
    with socket.socket() as a, socket.socket() as b:
        a.bind(("127.0.0.1", 0))
        b.bind(("127.0.0.1", 0))
        addresses = {"modbus_port": a.getsockname()[1],
                     "visa_resource": f"TCPIP0::127.0.0.1::{b.getsockname()[1]}::SOCKET",
                     "serial_port": str(tmp_path / "no-such-tty")}
        assert main(["probe", "--config", str(rig_toml_for(addresses, tmp_path))]) == 1
    text = capsys.readouterr().out
    assert "VISA resources (@py): cannot list: no VISA here" in text
    assert "  FAIL  open: valve controller 127.0.0.1:" in text
    assert "fix: check host and port in rig.toml" in text
    assert f"  FAIL  open: bridge amplifier {tmp_path / 'no-such-tty'}: 'open': cannot open serial port" in text
    assert "fix: the port does not exist" in text


def test_status_reports_missing_instruments_without_crashing(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    with socket.socket() as a, socket.socket() as b:  # bound, not listening: connection refused
        a.bind(("127.0.0.1", 0))
        b.bind(("127.0.0.1", 0))
        addresses = {"modbus_port": a.getsockname()[1],
                     "visa_resource": f"TCPIP0::127.0.0.1::{b.getsockname()[1]}::SOCKET",
                     "serial_port": str(tmp_path / "no-such-tty")}
        config = rig_toml_for(addresses, tmp_path)
        assert main(["status", "--config", str(config), "--json"]) == 1
    captured = capsys.readouterr()
    report = json.loads(captured.out)
    assert report["ok"] is False
    for key in ("valve_controller", "digitizer", "amplifier"):
        assert report[key]["ok"] is False and report[key]["error"]
    assert "'connect': could not connect" in report["valve_controller"]["error"]
    assert "digitizer" in report["digitizer"]["error"]
    assert "no-such-tty" in report["amplifier"]["error"]
    assert captured.err == ""


def test_status_with_a_bad_config_is_exit_2(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    bad = tmp_path / "rig.toml"
    bad.write_text((CONFIG / "rig.toml").read_text().replace("retries = 0", "retries = many"))
    assert main(["status", "--config", str(bad)]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"hopkinson: error: {bad}: not valid TOML") and err.count("\n") == 1
    binary = tmp_path / "binary.toml"
    binary.write_bytes(bytes(range(256)) * 4)
    for command in ("status", "probe"):
        assert main([command, "--config", str(binary)]) == 2
        err = capsys.readouterr().err
        assert err == f"hopkinson: error: {binary}: not UTF-8 text (byte 128): is it a binary file?\n"


def test_sim_on_a_busy_port_is_a_clear_error(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    with socket.socket() as busy:
        busy.bind(("127.0.0.1", 0))
        busy.listen()
        port = busy.getsockname()[1]
        sim_toml = tmp_path / "sim.toml"
        sim_toml.write_text(f'[servers]\nmodbus_port = 0\ndigitizer_port = {port}\n')
        assert main(["sim", "--config", str(sim_toml)]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"hopkinson: error: cannot start the simulated rig ({sim_toml}):")
    assert err.count("\n") == 1 and "Address already in use" in err


@pytest.mark.parametrize(("dialect", "maker"), [("lecroy", "LECROY"), ("keysight", "KEYSIGHT TECHNOLOGIES")])
def test_probe_names_the_dialect_of_a_digitizer_that_does_not_speak_the_configured_one(
        tmp_path: Path, dialect: str, maker: str) -> None:
    # A rig.toml left at the generic dialect, wired to another maker's scope: the open fails on
    # the generic commands; a plain *IDN? (which every dialect answers) names the dialect to set.
    from hopkinson.drivers.sim.faults import FaultSet
    from hopkinson.drivers.sim.scpi_digitizer import SimDigitizerServer
    from hopkinson.rig.cli.probe import _probe_digitizer
    from hopkinson.rig.config import load_rig_config

    server = SimDigitizerServer(lambda settings: None, FaultSet(), dialect=dialect)
    server.start()
    try:
        path = rig_toml_for({"modbus_port": 1, "visa_resource": server.resource, "serial_port": "/dev/null"}, tmp_path)
        config = load_rig_config(path)
        config = dataclasses.replace(config, digitizer=dataclasses.replace(config.digitizer, timeout_s=0.5))
        assert config.digitizer.dialect == "generic"
        steps = _probe_digitizer(config).steps
    finally:
        server.stop()
    opened = next(s for s in steps if s["step"] == "open")
    assert not opened["ok"] and f'set [digitizer] dialect = "{dialect}" in rig.toml (it is "generic")' in opened["fix"]
    plain = steps[-1]
    assert plain["ok"] and plain["step"].startswith("identity by a plain *IDN?") and plain["value"].startswith(maker)


def test_probe_reports_each_recorded_channels_state_and_names_an_off_channel_in_its_fix(tmp_path: Path) -> None:
    # A Keysight scope after power-on: channel 1 alone on. Another program took a record without
    # turning channel 2 on; the probe says which recorded channel is off, and its transfer (an
    # empty block) gets a fix naming the channel.
    import pyvisa

    from hopkinson.drivers.sim.faults import FaultSet
    from hopkinson.drivers.sim.scpi_digitizer import SimDigitizerServer
    from hopkinson.rig.cli.probe import _probe_digitizer
    from hopkinson.rig.config import load_rig_config
    from tests.drivers.digitizer_world import World

    world = World()
    server = SimDigitizerServer(world, FaultSet(), dialect="keysight")
    server.start()
    try:
        inst = pyvisa.ResourceManager("@py").open_resource(server.resource, read_termination="\n",
                                                           write_termination="\n", timeout=2000)
        try:
            for command in (":ACQ:POIN 4000", ":TIM:REF LEFT", ":TIM:POS -4E-6", ":TRIG:EDGE:SOUR CHAN1",
                            ":TRIG:EDGE:LEV 0.05", ":SING"):
                inst.write(command)
            world.fire()
            assert inst.query("*OPC?") == "1"
        finally:
            inst.close()
        path = rig_toml_for({"modbus_port": 1, "visa_resource": server.resource, "serial_port": "/dev/null"}, tmp_path)
        config = load_rig_config(path)
        digitizer = dataclasses.replace(config.digitizer, dialect="keysight", timeout_s=2.0,
                                        channels={"doppler": "CHAN1", "response": "CHAN2"},
                                        ranges_v={role: config.digitizer.ranges_v[role] for role in ("doppler", "response")},
                                        trigger_source="doppler")
        steps = {s["step"]: s for s in _probe_digitizer(dataclasses.replace(config, digitizer=digitizer)).steps}
    finally:
        server.stop()
    states = steps["recorded channels on"]
    assert states["ok"] and states["value"].startswith("CHAN1 on (doppler), CHAN2 off (response)")
    assert steps["transfer of CHAN1 (doppler)"]["value"] == "4000 samples"
    failed = steps["transfer of CHAN2 (response)"]
    assert not failed["ok"] and "CHAN2 is off on the instrument" in failed["error"]
    assert failed["fix"].startswith("turn CHAN2 on at the instrument")


def test_probe_says_once_that_the_link_was_lost_not_once_per_register(
        tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch) -> None:
    # issue 18: after the link was lost, every register repeated a failure and a generic fix
    monkeypatch.setattr("hopkinson.rig.cli.probe.visa_resources", lambda library: {"library": library,
                                                                                   "resources": []})
    with SimulatedRig() as sim:
        sim.faults.inject("modbus-disconnect")
        assert main(["probe", "--config", str(rig_toml_for(sim.addresses, tmp_path)), "--json"]) == 1
    report = json.loads(capsys.readouterr().out)
    steps = report["instruments"]["valve_controller"]["steps"]
    failed = [s for s in steps if s["ok"] is False]
    assert len(failed) == 1 and "connection lost" in failed[0]["error"] and failed[0]["fix"]
    rest = steps[steps.index(failed[0]) + 1:]
    assert rest and all(s["ok"] is None and s["value"].startswith("not tried: the link was lost at ") for s in rest)


def test_a_killed_sims_files_are_cleared_by_the_next_one(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    # issue 18: a `hopkinson sim` killed with SIGKILL left its pty link, state and address files
    runtime = tmp_path / "runtime"
    runtime.mkdir(mode=0o700)
    monkeypatch.setenv("XDG_RUNTIME_DIR", str(runtime))
    folder = runtime / "hopkinson"
    sim_toml = tmp_path / "sim.toml"
    sim_toml.write_text("[servers]\nmodbus_port = 0\ndigitizer_port = 0\n")
    with sim_process(["--config", str(sim_toml)], tmp_path / "a1.json") as (first, _):
        first.kill()  # SIGKILL: no clean-up of its own
        first.communicate()
    left = sorted(p.name for p in folder.iterdir())
    assert f"sim-{first.pid}-state.json" in left and "sim-addresses.json" in left  # what it left
    with sim_process(["--config", str(sim_toml)], tmp_path / "a2.json") as (second, _):
        names = sorted(p.name for p in folder.iterdir())
        assert not [n for n in names if n.startswith(f"sim-{first.pid}-")]
        assert json.loads((folder / "sim-addresses.json").read_text())["pid"] == second.pid
        stop_with_ctrl_c(second)
    assert sorted(p.name for p in folder.iterdir()) == []  # and the second cleans up after itself
